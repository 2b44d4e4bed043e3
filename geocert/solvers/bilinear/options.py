"""Options of the bilinear kind: a plain dataclass with defaults, ranges stated once in
OPTION_RANGES (check() applies them; the API's model is built from them)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from geocert.solvers.core.geometry import InputError
from geocert.solvers.fractional.options import CERTIFICATE_MODES, MAX_REL_GAP, JobLimit, _describe, _within

NORMS = ("L1L1", "L2L2")
# abs_gap's cap, in the cost's units (image units, squared for L2L2): a frame's cost sums its
# points' residuals (1.3 to 3.9 on the stored frames), and at abs_gap 1 a frame costing below 1 was
# "certified optimal" by the trivial bound at 3.8 times its optimum. 1e-4 is a hundredth of a
# pixel, squared; the default is 1e-9 (fractional.options.MAX_ABS_GAP says why a report names the
# items certified through it).
MAX_ABS_GAP = 1e-4
COEFFICIENTS = ("convex", "affine")
CAMERAS = ("affine",)


@dataclass
class BilinearOptions(JobLimit):
    """``norm``: L1L1 (sum of absolute coordinate residuals: an LP relaxation, thesis 8.7) or L2L2
    (sum of squared residuals: an SOCP, 8.9). ``coefficients``: convex (alpha >= 0, sum 1) or
    affine (sum 1, |alpha_i| <= coefficient_bound). ``camera_bound``: the scope's camera box,
    |M_rk| <= camera_bound for the 2x3 part M of the camera, in image units per shape unit; None
    derives it per frame from the incumbent (4 times its largest entry, see search.root_box). The
    translation is never bounded by the scope (any translation: see docs/certificate.md)."""

    norm: str = "L2L2"
    coefficients: str = "convex"
    camera: str = "affine"
    coefficient_bound: float = 10.0
    camera_bound: float | None = None
    rel_gap: float = 1e-3
    abs_gap: float = 1e-9
    max_nodes: int = 5000
    time_limit_s: float = 60.0
    certificate: str = "summary"

    OPTION_RANGES = {"rel_gap": {"ge": 0, "le": MAX_REL_GAP}, "abs_gap": {"ge": 0, "le": MAX_ABS_GAP},
                     "max_nodes": {"ge": 1, "le": 1_000_000},
                     "time_limit_s": {"gt": 0, "le": 3600}, "coefficient_bound": {"ge": 1, "le": 1e6},
                     "camera_bound": {"gt": 0, "le": 1e12}}

    def check(self) -> None:
        for name, allowed in (("norm", NORMS), ("coefficients", COEFFICIENTS), ("camera", CAMERAS),
                              ("certificate", CERTIFICATE_MODES)):
            if getattr(self, name) not in allowed:
                raise InputError(f"options/{name}", f"must be one of {', '.join(allowed)}")
        self.check_job_limit()
        for name in ("rel_gap", "abs_gap", "time_limit_s", "max_nodes", "coefficient_bound", "camera_bound"):
            value = getattr(self, name)
            if name == "camera_bound" and value is None:
                continue
            if not (isinstance(value, (int, float)) and math.isfinite(value) and _within(value, self.OPTION_RANGES[name])):
                raise InputError(f"options/{name}", f"must be a finite number {_describe(self.OPTION_RANGES[name])}")
