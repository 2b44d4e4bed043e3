"""Options of the bilinear kind: a plain dataclass with defaults, ranges stated once in
its options' declarations (core.declared_options.option: check() applies them; the API's model
is built from them)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from geocert.core.declared_options import option, redeclared
from geocert.core.geometry import InputError
from geocert.formulations.fractional.options import CERTIFICATE_MODES, JobLimit, SearchOptions, _describe, _within

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

    norm: str = option("L2L2", choices=NORMS, description="L1L1: sum of absolute coordinate residuals "
                                                          "(an LP relaxation); L2L2: sum of squares (SOCP)")
    coefficients: str = option("convex", choices=COEFFICIENTS, description=(
        "convex: alpha >= 0, sum alpha = 1; affine: sum alpha = 1, |alpha_i| <= coefficient_bound"))
    camera: str = option("affine", choices=CAMERAS, description="a 2x4 affine camera [M | t] per frame")
    coefficient_bound: float = option(10.0, ge=1, le=1e6, description="affine coefficients' bound (the scope)")
    camera_bound: float | None = option(None, gt=0, le=1e12, description=(
        "the scope's camera box |M_rk| <= camera_bound (image units per shape unit); default: per frame, "
        "4 times the incumbent's largest entry rounded up to a power of two (stated in each certificate)"))
    rel_gap: float = redeclared(SearchOptions, "rel_gap")
    abs_gap: float = redeclared(SearchOptions, "abs_gap", 1e-9, bounds={"ge": 0, "le": MAX_ABS_GAP})
    max_nodes: int = redeclared(SearchOptions, "max_nodes", 5000, description="per frame")
    time_limit_s: float = redeclared(SearchOptions, "time_limit_s", 60.0, description="per frame")
    job_time_limit_s: float = redeclared(JobLimit, "job_time_limit_s", description=(
        "the job in all: its frames share this one clock (past it the frame running stops with its best answer, "
        "status time_limit, and the frames not started read time_limit, not started)"))
    certificate: str = redeclared(SearchOptions, "certificate", description=(
        "full: every bound's proof (dual vectors), checkable without a conic solver"))

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
