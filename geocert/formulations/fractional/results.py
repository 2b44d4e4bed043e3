"""What a fractional solve returns: one result base for every item (scipy.optimize's pattern of
one result type), the track's and the map's solution fields on top, and the search's certificate.
Plain dataclasses, no solver imports."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class SearchCertificate:
    """A search's certificate, what a finished search proves (shown as the item's certificate
    summary, geocert.kinds.documents): the scope, the root region the search covered (in the
    caller's coordinates: ``lower <= (F u) / (d . u) <= upper`` for the kind's unknown u), the
    tolerance and whether it was met, and the number of leaves."""

    scope: str
    reference: int  # the observation whose depth is fixed to 1
    functionals: list[list[float]]
    denominator: list[float]
    lower: list[float]
    upper: list[float]
    tolerance: float
    tolerance_met: bool
    leaves: int
    proof: dict | None = None  # with options.certificate == "full": certificates.encode's form
    sublevel: dict | None = None  # a proven interval, as LocalCertificate's


@dataclass
class LocalCertificate:
    """A certificate with no search: a bound proven at the solution itself (the convexity
    bound of fractional.convexity: the cost is convex on a ball of ``radius`` around the
    solution that holds every point costing as little), the scope, the tolerance met."""

    scope: str
    tolerance: float
    radius: float
    proof: dict | None = None  # with options.certificate == "full": {"type": "convexity", "radius": R}
    tolerance_met: bool = True
    leaves: int = 0
    # A proven interval: {"cost_increase": delta, "radius": R', "intervals": [[lo, hi]] * 3}, every
    # point of the scope costing at most the optimum plus delta within R' of the solution.
    sublevel: dict | None = None
    note: str | None = None  # what proved the bound, when not the convexity bound


@dataclass
class ItemResult:
    """One item's outcome: status (optimal, node_limit, time_limit, cancelled, not_certified,
    infeasible, degenerate), whether it is certified, its cost (recomputed from the raw data at the
    solution returned), the proven lower bound and the gap, and why it is not certified."""

    status: str
    certified: bool
    cost: float | None = None
    lower_bound: float | None = None
    gap: float | None = None
    nodes: int = 0
    elapsed_s: float = 0.0
    reason: str | None = None
    certificate: SearchCertificate | LocalCertificate | None = None


@dataclass
class TrackResult(ItemResult):
    point: list[float] | None = None  # [x, y, z], or a homogeneous 4-vector when at infinity
    at_infinity: bool = False
    residuals: list[list[float]] = field(default_factory=list)


@dataclass
class MapResult(ItemResult):
    matrix: list[list[float]] | None = None  # Frobenius norm 1, reference depth positive
    residuals: list[list[float]] = field(default_factory=list)


def proof_of(result: ItemResult) -> dict | None:
    """The proof member of a solved item: its search's, or the trivial bound's."""
    if result.certificate is not None and result.certificate.proof is not None:
        return result.certificate.proof
    return {"type": "trivial"} if result.certified and result.certificate is None else None


def claim_of(result: ItemResult, **solution) -> dict:
    """What a certificate document says of one item (index 0), from a solver's result."""
    return {"index": 0, "status": result.status, "certified": result.certified, "cost": result.cost,
            "lower_bound": result.lower_bound, "gap": result.gap, **solution, "proof": proof_of(result)}
