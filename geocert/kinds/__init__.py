"""The problem kinds served: one line each (see base.py for what a kind is)."""

import geocert.verify.checks  # noqa: F401 (installs the solvers' self-check: GEOCERT_SELF_VERIFY=1)
from geocert.kinds.autocalibration import KIND as AUTOCALIBRATION
from geocert.kinds.bilinear import KIND as BILINEAR
from geocert.kinds.base import ProblemKind, Registry, default_options, options_from
from geocert.kinds.resection_homography import HOMOGRAPHY, RESECTION
from geocert.kinds.reconstruction import KIND as RECONSTRUCTION
from geocert.kinds.stereo_lines import KIND as STEREO_LINES
from geocert.kinds.triangulation import KIND as TRIANGULATION

KINDS = Registry(
    TRIANGULATION,
    RESECTION,
    HOMOGRAPHY,
    AUTOCALIBRATION,
    BILINEAR,
    STEREO_LINES,
    RECONSTRUCTION,
)
get_kind = KINDS.get

__all__ = ["KINDS", "ProblemKind", "Registry", "default_options", "get_kind", "options_from"]
