"""Options of the fractional kinds, as plain dataclasses composed of what any search takes
(SearchOptions) and what fixes the cost and its scope (ResidualOptions). Ranges are stated once,
with each option's declaration (core.declared_options.option): check() applies them, and the API's
models are built from the same declarations."""

from __future__ import annotations

import math
from dataclasses import dataclass

from geocert.core.declared_options import DeclaredRange, DeclaredRanges, option, redeclared
from geocert.core.geometry import InputError
from geocert.formulations.fractional.relaxation import NORMS

# The gaps a certificate may be asked for: at rel_gap near 1, or an abs_gap as large as the costs,
# "certified optimal" would hold of a solution whatever it costs (a triangulation asked abs_gap
# 1e300 called points 35,000 times their optimum's cost optimal; at abs_gap 1, a point of a track
# observed with 0.05 px of noise costing 662 times its optimum, 0.41 px^2). rel_gap is relative:
# one cap for every kind. abs_gap is in the cost's units, so each kind caps it in its own: here the
# residual kinds' (squared pixels for L2L2, pixels for the L1 norms), where 1e-4 is a hundredth of
# a pixel, squared; the default is 1e-7. (Bilinear and autocalibration state theirs.) A document
# chooses its coordinates' units (normalised image coordinates make 1e-4 a residual of 0.01
# radian), so the verifier's report also names each item certified only through abs_gap.
MAX_REL_GAP = 0.5
MAX_ABS_GAP = 1e-4
CERTIFICATE_MODES = ("summary", "full")  # the option certificate: the proof returned or not
# The option detail: "brief" items carry the solution and its bounds only (no certificate summary
# and no determinacy, which is then not computed): a large job's result about a sixth of the size.
DETAIL_MODES = ("full", "brief")


@dataclass
class SearchOptions:
    """How far a branch and bound goes, and what it returns (every kind's search)."""

    rel_gap: float = option(1e-3, ge=0, le=MAX_REL_GAP, description="stop when gap <= rel_gap * cost ...")
    # In the cost's units (squared for L2L2). Below about 1e-7 the conic solves cannot resolve
    # the bound (measured on a Dinosaur track whose optimum is 1e-6 px).
    abs_gap: float = option(1e-7, ge=0, le=MAX_ABS_GAP, description="... or gap <= abs_gap (cost units)")
    max_nodes: int = option(2000, ge=1, le=1_000_000, description="per item")
    time_limit_s: float = option(30.0, gt=0, le=3600, description="per item")
    # "full": every bound's proof, checkable by geocert.verify.checks
    certificate: str = option("summary", choices=CERTIFICATE_MODES, description=(
        "full: every bound's proof (dual vectors), checkable without a conic solver; see GET /v1/jobs/{id}/certificate"))

    OPTION_RANGES = DeclaredRanges()

    def check(self) -> None:
        for name in ("rel_gap", "abs_gap", "time_limit_s", "max_nodes"):
            value = getattr(self, name)
            if not (math.isfinite(value) and _within(value, self.OPTION_RANGES[name])):
                raise InputError(f"options/{name}", f"must be a finite number {_describe(self.OPTION_RANGES[name])}")
        if self.certificate not in CERTIFICATE_MODES:
            raise InputError("options/certificate", f"must be one of {', '.join(CERTIFICATE_MODES)}")


@dataclass
class ResidualOptions:
    """The cost (norm of the reprojection residuals) and its scope (max_residual)."""

    norm: str = option("L2L2", choices=NORMS)
    # the kind's residual units (its description names them); narrows the certificate's scope
    max_residual: float | None = option(None, gt=0, description="narrows the certificate's scope")

    OPTION_RANGES = DeclaredRanges()

    def check(self) -> None:
        if self.norm not in NORMS:
            raise InputError("options/norm", f"must be one of {', '.join(NORMS)}")
        if self.max_residual is not None and not (math.isfinite(self.max_residual) and self.max_residual > 0):
            raise InputError("options/max_residual", "must be a finite number > 0")


@dataclass
class FractionalOptions(ResidualOptions, SearchOptions):
    """Options every fractional-program kind shares (each kind sets its own defaults)."""

    # what each item's document carries (DETAIL_MODES); never what is proven
    detail: str = option("full", choices=DETAIL_MODES, description=(
        "brief: each item carries its solution, bounds and status only (certificate and determinacy null, "
        "determinacy not computed): for large jobs; what is proven is the same"))

    def check(self) -> None:
        ResidualOptions.check(self)
        SearchOptions.check(self)
        if self.detail not in DETAIL_MODES:
            raise InputError("options/detail", f"must be one of {', '.join(DETAIL_MODES)}")


@dataclass
class JobLimit:
    """A many-item job's time limit in all, beside its items' own (per item): the items share one
    clock from when the job starts (batch.solve_items), so a job of any size ends near it, its
    items not started by then reading ``time_limit``."""

    job_time_limit_s: float = option(600.0, gt=0, le=86400, description=(
        "the job in all, from when it starts: its items share this one clock; past it the item running stops "
        "with its best answer (status time_limit) and the items not started read time_limit, not started"))

    OPTION_RANGES = DeclaredRanges()
    JOB_LIMIT_RANGE = DeclaredRange("job_time_limit_s")

    def check_job_limit(self) -> None:
        value = self.job_time_limit_s
        if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                and _within(value, self.JOB_LIMIT_RANGE)):
            raise InputError("options/job_time_limit_s", f"must be a finite number {_describe(self.JOB_LIMIT_RANGE)}")


@dataclass
class TriangulationOptions(FractionalOptions, JobLimit):
    """Residuals in pixels; limits per track (and job_time_limit_s for the job)."""

    max_residual: float | None = redeclared(ResidualOptions, "max_residual",
                                            description="pixels; narrows the certificate's scope")

    def check(self) -> None:
        FractionalOptions.check(self)
        self.check_job_limit()


@dataclass
class MapOptions(FractionalOptions, JobLimit):
    """Residuals in target units; limits per map (larger than a track's: more unknowns), and
    job_time_limit_s for the job."""

    max_nodes: int = redeclared(SearchOptions, "max_nodes", 5000)
    time_limit_s: float = redeclared(SearchOptions, "time_limit_s", 60.0)
    max_residual: float | None = redeclared(ResidualOptions, "max_residual",
                                            description="target units; narrows the certificate's scope")

    def check(self) -> None:
        FractionalOptions.check(self)
        self.check_job_limit()


def _within(value: float, bounds: dict) -> bool:
    return (value >= bounds.get("ge", -math.inf) and value > bounds.get("gt", -math.inf)
            and value <= bounds.get("le", math.inf))


def _describe(bounds: dict) -> str:
    words = {"ge": ">=", "gt": ">", "le": "<="}
    return " and ".join(f"{words[key]} {value:g}" for key, value in bounds.items())
