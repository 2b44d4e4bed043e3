"""Autocalibration (thesis chapters 6 and 7): the stratified method's two searches, the plane at
infinity from the modulus constraints (affine) and then the DIAC (metric, metric_sublevel), each to
certified global optimality (stratified runs both, sharing cuts), and the direct method's solve
(direct_solve), on the programs and proofs of geocert.formulations.autocalibration."""
