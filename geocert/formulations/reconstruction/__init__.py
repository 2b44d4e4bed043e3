"""A reconstruction's claims, the part the pipeline and the verifier share: what makes a camera,
a calibration, a motion or a depth reversal claim (camera_claim, calibration_claim, motion_claim,
depth_reversal_claim), what ties an embedded certificate to the result carrying it
(calibration_tie), the centred fit and the run controls' words (run_control)."""
