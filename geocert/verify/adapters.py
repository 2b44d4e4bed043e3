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

from geocert.verify.autocalibration import STAGES
from geocert.verify.bilinear import FRAMES
from geocert.core import records
from geocert.core.strict import Invalid
from geocert.formulations.fractional.options import MapOptions, TriangulationOptions
from geocert.verify import reconstruction_stages as stage_checks
from geocert.verify.fractional import TRACKS, MapItems, TrackItems
from geocert.verify.reconstruction import RECONSTRUCTION
from geocert.verify.verification import Verification

# The fractional kinds' adapters (verify/fractional.py) do not subclass Verification; they are its
# virtual subclasses, and the verifier reads their hooks through verification.hook, with
# Verification's defaults.
Verification.register(TrackItems)
Verification.register(MapItems)

NOT_CERTIFIED = ("stereo_lines results are estimates (RANSAC around algebraic solvers), never certified: there is "
                 "no certificate to verify")


class NoCertificates(Verification):
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
    # The members its result may hold, and those of each object (or list's objects) it nests one
    # level down: ((where, names), ...), where "" is the result itself. Exactly the kind's result
    # model's (geocert.kinds checks the two agree when it registers the kind): a member no kind
    # writes is refused, never carried unread (verify.check_members).
    members: tuple[tuple[str, tuple[str, ...]], ...] = ()


def _members(**nested: tuple[str, ...]) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """A result's members (``nested[""]``, the certificates added) and its nested objects'."""
    own = nested.pop("result") + ("certificate",)
    return (("", tuple(sorted(own + tuple(nested)))),) + tuple(
        (where, tuple(sorted(names))) for where, names in sorted(nested.items()) if names)


# What every item (track, map, frame) reports about its solve, and a job's counts.
OUTCOME = ("cost", "lower_bound", "gap", "status", "certified", "nodes", "elapsed_s", "reason", "certificate",
           "determinacy")
STATS = ("items", "certified", "nodes", "solve_s", "elapsed_s", "statuses")
TRACK = OUTCOME + ("point", "at_infinity")
MAP_MEMBERS = _members(result=("kind", "norm"), maps=OUTCOME + ("matrix", "residuals"), stats=STATS)


VERIFIED_KINDS: dict[str, VerifiedKind] = {kind.name: kind for kind in (
    VerifiedKind("triangulation", "tracks", ("point", "at_infinity"), TRACKS, TriangulationOptions,
                 members=_members(result=("kind", "norm"), tracks=TRACK, stats=STATS)),
    VerifiedKind("resection", "maps", ("matrix",), MapItems("resection", {(3, 2)}), MapOptions, members=MAP_MEMBERS),
    VerifiedKind("homography", "maps", ("matrix",), MapItems("homography", {(2, 2), (3, 3)}), MapOptions,
                 members=MAP_MEMBERS),
    VerifiedKind("autocalibration", "stages", ("plane_at_infinity", "K", "dual_absolute_quadric"), STAGES,
                 members=_members(
                     result=("kind", "method", "status", "reason", "plane_at_infinity", "K", "Ks",
                             "dual_absolute_quadric", "upgrade", "points", "intrinsics"),
                     stages=OUTCOME + ("name", "plane_at_infinity", "K", "dual_absolute_quadric"),
                     cameras=("K", "R", "t", "center"), baseline=("method", "K", "psd", "cost"), stats=STATS)),
    VerifiedKind("bilinear", "frames", ("camera", "coefficients"), FRAMES, members=_members(
        result=("kind", "norm", "coefficients"),
        frames=OUTCOME + ("camera", "coefficients", "shape", "residuals", "baseline"), stats=STATS)),
    VerifiedKind("stereo_lines", "pairs", ("R", "t"), NoCertificates(), certifies=False),
    VerifiedKind("reconstruction", "points", ("point", "at_infinity"), RECONSTRUCTION, members=_members(
        result=("kind", "norm", "stages", "summary", "images", "camera_certificate", "calibration_certificate"),
        points=TRACK + ("track", "observations"),
        cameras=("view", "name", "registered", "reason", "image_size", "K", "R", "t", "center", "P", "k1",
                 "distortion_centre", "cost", "lower_bound", "gap", "optimal_cost", "certified", "status",
                 "bound_reason", "points", "degrees_of_freedom", "tolerance", "searched", "pose_determined",
                 "mirror_rotation_deg", "set_aside", "free_camera"),
        stats=STATS)),
)}


# The records each kind's result nests below the objects VerifiedKind.members closes, closed to
# their writers' members (core.records): ((where, {member: record}), ...) as records.check_nested
# reads them, "" the result itself.
def _item_records(key: str, summary: records.Record, **more) -> tuple:
    return ((key, {"certificate": summary, "determinacy": records.DETERMINACY, **more}),)


MAP_RECORDS = _item_records("maps", records.MAP_SUMMARY)
NESTED_RECORDS: dict[str, tuple] = {
    "triangulation": _item_records("tracks", records.TRACK_SUMMARY),
    "resection": MAP_RECORDS,
    "homography": MAP_RECORDS,
    "autocalibration": _item_records("stages", records.STAGE_SUMMARY) + (("", {"intrinsics": records.INTRINSIC_RANGES}),),
    "bilinear": _item_records("frames", records.FRAME_SUMMARY,
                              baseline=records.record("method", "camera", "coefficients", "cost")),
    "reconstruction": _item_records("points", records.TRACK_SUMMARY) + (
        ("", {"summary": stage_checks.RECONSTRUCTION_SUMMARY, "images": stage_checks.IMAGES}),),
}


def register(kind: VerifiedKind) -> VerifiedKind:
    """Add a kind's contract (a kind the verifier does not list), or confirm a listed one's."""
    if not isinstance(kind.verification, Verification):
        raise TypeError(f"kind {kind.name!r}: its verification adapter {kind.verification!r} is not a "
                        "geocert.verify.verification.Verification")
    known = VERIFIED_KINDS.get(kind.name)
    if known is None:
        VERIFIED_KINDS[kind.name] = kind
        return kind
    if known != kind:
        raise ValueError(f"kind {kind.name!r}: the verifier checks it as {known}, not {kind}")
    return known
