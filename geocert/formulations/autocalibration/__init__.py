"""Autocalibration (thesis chapters 6 and 7, appendix B), the part the solvers and the verifier
share: the problem, its frames and readers (problem, frames), the stratified stages' relaxations
and envelopes (affine_relaxation, metric_relaxation, envelopes) and proofs (proofs, plane_sublevel),
the direct method's moment relaxation, setup and proven intervals (direct_relaxation, direct,
direct_sublevel, direct_intrinsics), and the determinacy estimates."""
