"""Every warning code geocert writes (a determinacy's warnings, a reconstruction summary's, an
autocalibration stage's motion warnings), in one place: the verifier refuses a warning of any other
code (records.WARNING), which no check reads and a reader would take for the product's word (a
"reconstruction_certified" warning beside a rig 4 of whose 6 cameras are certified).
tests/verify/test_records.py collects the codes the source writes and checks they are listed here."""

from __future__ import annotations

# Determinacy: how well the data fix an item's answer (docs/kinds.md, "Determinacy").
DETERMINACY_CODES = ("not_analysed", "at_infinity", "near_zero_parallax", "near_coplanar_points", "near_collinear_points",
                     "near_critical_configuration", "near_dependent_basis", "near_parallel_lines",
                     # autocalibration's stages: an interval the scope cut, a cost with no redundancy
                     "at_range_edge", "no_redundancy",
                     # a level estimated from fewer than core.determinacy.FEWEST_DEGREES degrees of freedom
                     "few_degrees_of_freedom")
# Motions for which constant intrinsics are not fixed (autocalibration.determinacy.motion_name).
MOTION_CODES = ("pure_translation", "orbital_motion", "rotation_about_one_axis", "critical_motion")
# A reconstruction's summary (pipelines.reconstruction.claims, kinds.reconstruction).
RECONSTRUCTION_CODES = ("views_not_registered", "certificates_conditional_on_k1", "no_metric_upgrade",
                        "camera_dropped", "camera_fit_beyond_tolerance", "points_dropped", "reconstruction_doubtful",
                        "poses_not_determined", "depth_reversed_twin_returned", "returned_K_not_certified",
                        "certified_K_of_calibrated_cameras", "certified_K_on_range_edge", "time_limit")

WARNING_CODES = frozenset(DETERMINACY_CODES + MOTION_CODES + RECONSTRUCTION_CODES)
