"""The problem kinds served: one line each (see base.py for what a kind is). Each is named with the
module that defines it and imported on first use (KINDS.get, or iterating KINDS), so that solving
one kind does not import every kind's solvers."""

import geocert.verify.checks  # noqa: F401 (installs the solvers' self-check: GEOCERT_SELF_VERIFY=1)
from geocert.kinds.base import ProblemKind, Registry, default_options, options_from

KINDS = Registry(
    triangulation="geocert.kinds.triangulation:KIND",
    resection="geocert.kinds.resection_homography:RESECTION",
    homography="geocert.kinds.resection_homography:HOMOGRAPHY",
    autocalibration="geocert.kinds.autocalibration:KIND",
    bilinear="geocert.kinds.bilinear:KIND",
    stereo_lines="geocert.kinds.stereo_lines:KIND",
    reconstruction="geocert.kinds.reconstruction:KIND",
)
get_kind = KINDS.get

__all__ = ["KINDS", "ProblemKind", "Registry", "default_options", "get_kind", "options_from"]
