"""The verifier's own registry of the kinds a certificate may name: for each, where its items sit,
the options class its options are checked with (the kinds whose cost is a norm of residuals; the
others check their own), the fields an item claims as its solution, and the numpy-only adapter
that reads and checks its items. verify.py reads only this, never the service's kinds
(geocert/kinds). The kinds served are listed here; a kind added elsewhere (the kinds' registry, one
line) registers its contract here through ``register``, and a served kind registered again must
state the same contract (the service and the verifier cannot disagree about it)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from geocert.solvers.autocalibration.verification import STAGES
from geocert.solvers.bilinear.verification import FRAMES
from geocert.solvers.core.strict import Invalid
from geocert.solvers.fractional.items import TRACKS, MapItems
from geocert.solvers.fractional.options import MapOptions, TriangulationOptions
from geocert.solvers.reconstruction.verification import RECONSTRUCTION

NOT_CERTIFIED = ("stereo_lines results are estimates (RANSAC around algebraic solvers), never certified: there is "
                 "no certificate to verify")


class NoCertificates:
    """The adapter of a kind that issues no certificate: any document claiming one for this kind
    is refused, saying why."""

    domain = "none: stereo_lines issues estimates, not certificates"

    def checked_options(self, options: Any) -> dict:
        raise Invalid("format", NOT_CERTIFIED)

    def read(self, data: Any, index: int):
        raise Invalid("format", NOT_CERTIFIED)

    def item(self, arrays, norm):  # pragma: no cover - read refuses first
        raise Invalid("format", NOT_CERTIFIED)


@dataclass(frozen=True)
class VerifiedKind:
    name: str
    item_key: str  # where items sit in data and result
    solution_fields: tuple[str, ...]  # what of an item its certificate claims as the solution
    verification: Any  # the adapter (read, item, domain, proofs, and optional hooks)
    options_type: type | None = None  # for kinds whose cost is a norm of residuals (verify.residual_options)
    certifies: bool = True


VERIFIED_KINDS: dict[str, VerifiedKind] = {kind.name: kind for kind in (
    VerifiedKind("triangulation", "tracks", ("point", "at_infinity"), TRACKS, TriangulationOptions),
    VerifiedKind("resection", "maps", ("matrix",), MapItems("resection", {(3, 2)}), MapOptions),
    VerifiedKind("homography", "maps", ("matrix",), MapItems("homography", {(2, 2), (3, 3)}), MapOptions),
    VerifiedKind("autocalibration", "stages", ("plane_at_infinity", "K", "dual_absolute_quadric"), STAGES),
    VerifiedKind("bilinear", "frames", ("camera", "coefficients"), FRAMES),
    VerifiedKind("stereo_lines", "pairs", ("R", "t"), NoCertificates(), certifies=False),
    VerifiedKind("reconstruction", "points", ("point", "at_infinity"), RECONSTRUCTION),
)}


def register(kind: VerifiedKind) -> VerifiedKind:
    """Add a kind's contract (a kind the verifier does not list), or confirm a listed one's."""
    known = VERIFIED_KINDS.get(kind.name)
    if known is None:
        VERIFIED_KINDS[kind.name] = kind
        return kind
    if known != kind:
        raise ValueError(f"kind {kind.name!r}: the verifier checks it as {known}, not {kind}")
    return known
