"""The determinacy estimates a result returns beside its claims, tied to the data.

A track's, map's or bilinear frame's ``determinacy`` (its intervals, ``determined``, level, redundancy and
warnings) proves nothing: it is the local curvature estimate (Gauss-Newton) at the solution the
item returns. It is still a claim about the data ("determined: true", "x within [lo, hi]", no
"near_coplanar_points" warning), so a result verified with its certificate states exactly the
estimate the kind's writer (``fractional.determinacy.track`` and ``map_``,
``bilinear.determinacy.frame``, numpy only) computes from the certificate's data at the returned
solution, cost and lower bound: an interval
narrowed, a value moved, ``determined`` flipped or a warning dropped is refused (check
``returned``). Numbers agree to 1e-6 of the interval's width and 1e-9 of the value (another
machine's rounding of the same sums); a track's x, y and z values are its returned point's
coordinates exactly, and its ends are read as offsets from their value, to the width and the ends'
own rounding (END_OFFSET_ULPS), whatever the value's size; a far homography's (its cost one a float
evaluation could move, exact.needs_exact) likewise, its value the exact centroid image to an ulp
(its writer, fractional.homography_estimate, computes one float on every machine); an end the
data leave open (null) must be null. An
analysis the solver stopped at its time limit (a single ``time_limit`` warning, no interval) or
left out (null) claims nothing and is accepted as it is. Autocalibration's estimates (their plane
family refitted with scipy by their writer): check_determined, check_intrinsics and
check_redundancy tie what the data and the returned K give without a refit, and
autocalibration_estimates walks the writer's numpy walks again and judges the motion again.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geocert.core.determinacy import (FEWEST_DEGREES, NO_REDUNDANCY_FORM, OWN_SCALE_FORM, STUDENT_FORM, Determinacy,
                                      certified_gap, cost_increase as level_of, fixes, form, level_sigmas, safely)
from geocert.core import proven_reasons
from geocert.core.geometry import is_number, normalised_cameras
from geocert.core.warning_codes import MOTION_CODES
from geocert.core.strict import Invalid, same
from geocert.formulations.fractional import determinacy as estimate

NOT_ANALYSED = ("time_limit", "not_analysed")  # core.determinacy.not_analysed's codes
NUMBER_SLACK = 1e-6  # of an interval's width: another machine's eigendecomposition of the same J'J
VALUE_SLACK = 1e-9  # of a value: its own rounding
MAX_COST_SPREAD = 1e-6  # the most a map's cost spread may move its estimate, relative (far-off data)
# Of a map estimate's interval width, what an end may lie from the verifier's: the width is the
# level over the curvature J'J of far-off data (coordinates of 1e6), which another machine's
# kernels round otherwise beyond NUMBER_SLACK (measured: 9e-6 of the width under OpenBLAS's
# Prescott kernels on the stored far-off homography). Today's writers read the estimate in
# normalised coordinates (1.2e-10 of the width between kernels); documents of the writers before
# read it in the world's, some 3e-11 of the width apart per unit of the data's offset over their
# spread, and this slack keeps them checkable to a ratio of about 2e7 (world coordinates of 6.4e6 m
# over a spread of 1 m) while an interval narrowed by more than a thousandth is refused. Read on
# the width only, never the value.
MAP_WIDTH_SLACK = 1e-3
# Of a value's size: how far a stated interval's end may lie on the wrong side of the stated value.
# Every writer's interval holds its value (the ends are the value less and plus distances at least
# 0, or the least and greatest of samples the value is among, or clipped toward it), which the
# document's own numbers show whatever machine wrote them; read against the verifier's own, an end
# may differ by VALUE_SLACK of the value (a far resection's centre, an SVD's, rounds at 1e-10 of
# itself), which without this let an interval 4e-9 wide at 1e6 px move 1.5e-3 px off its value
# (review 34) and a value 134 widths off its interval (review 35).
END_ROUNDING = 64 * float(np.finfo(float).eps)
# A map estimate's value against the verifier's, in units in the last place of the value and of
# the data's largest coordinate: measured at most 2 ulps of the value apart between OpenBLAS's
# Haswell and Prescott kernels (resections 1e5 to 1e8 off the origin, exact and noisy; a centroid
# mapped to the origin), where 1e-9 of a value 1e6 off let an interval collapse onto its value or
# move 7,000 widths with it (review 36).
MAP_VALUE_ROUNDING = 8 * float(np.finfo(float).eps)
# A track interval's end, read as its offset from the value (end - value): the writer states
# fl(value -+ half), so each side's end is off its half-width by half an ulp of itself, and the two
# offsets differ by at most an ulp of the end besides the half-widths' own difference (NUMBER_SLACK
# of the width). Measured: the estimate recomputed from the returned point is bit for bit the
# writer's under OpenBLAS's Haswell and Prescott kernels (far tracks at offsets 0, 1e3 and 1e6,
# exact and 1e-6 px of noise: every end's offset, value and level equal), for intervals 4e-10 to
# 2.5e-7 wide at 1e6 (3 to 2,000 ulps of the value). Twice the ulp: the stated end may lie a binade
# above the verifier's.
END_OFFSET_ULPS = 2.0
# Of a track interval's width, what its end's offset may differ by besides NUMBER_SLACK: the writer
# (tracks_many: batched einsum and eigh) and the verifier (track: one J'J) reach the half-width by
# different sums; on hostile scenes (testing.hostile_triangulation, seeds 1 and 2, 400 tracks, L2L2,
# cameras scaled by 1e-6 to 1e6) the offsets differ by up to 5.8e-7 of the width, under either
# kernel alike. Far below a width: a collapsed or narrowed interval moves an end by a share of it.
TRACK_WIDTH_SLACK = 1e-5
# A far homography's value against the exact centroid image the verifier computes by the writer's
# function (core.exact.exact_centroid_image), in units in its last place: 0 ulps apart
# between writers' kernels (offsets 0 to 1e7, exact to 1 px of noise).
HOMOGRAPHY_VALUE_ULPS = 1.0
TRACK_POINT = ("x", "y", "z")  # the track estimate's intervals whose value is the returned point's coordinate
# Not ``determined``: check_determined derives it from the stated intervals, whose ends are held
# to the verifier's within their slack; an interval whose half-width sits at its tolerance reads
# fixed on one side of that slack and not on the other (the writer's batched eigh and the
# verifier's single J'J: 1e-13 of the width apart), and compared exactly a genuine track was
# refused on its writer's machine (review 40).
COMPARED = ("method", "level", "redundancy")


def check(kind: Any, result: dict, certificate: dict, earlier: bool = True) -> None:
    """Every returned track's or map's determinacy estimate is the writer's (module docstring).
    ``earlier``: whether the document's form lets an estimate be of the earlier form (its
    intervals stating no tolerance, ``determined`` meaning bounded: a problem hash without the
    estimates' form, core.determinacy.ESTIMATES_FORM); a document of the current form states
    every interval's tolerance, so it cannot choose that reading by leaving them out."""
    if certificate.get("kind") == "triangulation":
        _check_tracks(kind, result, certificate, earlier)
    elif certificate.get("kind") in ("resection", "homography"):
        _check_maps(kind, result, certificate, earlier)
    elif certificate.get("kind") == "bilinear":
        _check_frames(kind, result, certificate, earlier)


def check_determined(determinacy: dict, where: str, earlier: bool = True) -> None:
    """An estimate no check recomputes (autocalibration's stages: its writer refits with scipy)
    still says ``determined`` only as its writer (core.determinacy.Determinacy.document) does:
    true exactly when every interval fixes its quantity (bounded, within its tolerance of its
    value) and no warning is stated; and no bounded interval has its lower end above its upper.
    Unless ``earlier`` (the document's form lets its estimates be of the earlier form: check),
    every interval states its tolerance (null where its quantity has no scale), as the writer's
    core.determinacy.interval does: an interval stating none would read as bounded suffices."""
    intervals, warnings = determinacy.get("intervals"), determinacy.get("warnings")
    if not isinstance(intervals, list) or not all(isinstance(i, dict) for i in intervals):
        return  # typed by verify.notes
    if not earlier:
        missing = [number for number, i in enumerate(intervals) if "tolerance" not in i]
        if missing:
            raise Invalid("returned", f"{where}/intervals/{missing[0]} states no tolerance: a document of this form "
                                      "(its problem_sha256 covers the estimates' form) states every interval's "
                                      "tolerance, and without it determined would be read as bounded")
    try:
        expected = all(fixes(i) for i in intervals) and not warnings
    except (TypeError, KeyError):
        raise Invalid("returned", f"{where}/intervals: each states lower and upper, and lower, upper, value and "
                                  "tolerance are numbers or null") from None
    reason = determinacy.get("proven_reason")
    if reason is not None:  # an autocalibration stage's, checked (check_proven_reason) and removed before this
        raise Invalid("returned", f"{where}/proven_reason is {reason!r:.60}: its writer states a reason only for an "
                                  "autocalibration stage whose proven intervals the options asked for")
    if determinacy.get("determined") is not expected:
        raise Invalid("returned", f"{where}/determined is {determinacy.get('determined')!r:.20}, its intervals and "
                                  f"warnings give {expected!r} (every interval bounded within its tolerance of its "
                                  "value, and no warning)")
    for number, found in enumerate(intervals):
        lower, upper = found.get("lower"), found.get("upper")
        if lower is not None and upper is not None and not lower <= upper:
            raise Invalid("returned", f"{where}/intervals/{number}: lower {lower!r:.30} above upper {upper!r:.30}")


def check_proven_reason(determinacy: Any, where: str, asked: bool, keys: tuple[str, ...], full: bool,
                        proved: bool, status: Any, own: dict | None = None) -> None:
    """A stage's ``proven_reason`` (why its proven intervals, asked for, are null) is its writer's:
    stated only where the options asked for a proof (``asked``: the stratified metric stage's with a
    full certificate, kinds.autocalibration; the direct stage's with prove_focal_interval or
    prove_intrinsics_intervals), beside a null proven_intervals, in one of the writer's forms of
    words (core.proven_reasons, ``keys`` the stage's): where the certificate is not full, or the
    stage has no proof (``proved``: certified with a proof), exactly the one
    autocalibration_stages.unproven gives (the stage's own status); else one of the proof's own.
    A text reading as a proof ("proven: every intrinsic within 0.01%") is refused (review 63
    class 2). A reason left out is not required (documents written before it was stated). ``own``:
    what the stage's options and figures give of a proof's reason (check_reason_fields)."""
    reason = determinacy.get("proven_reason") if isinstance(determinacy, dict) else None
    if reason is None:
        return
    if not asked:
        raise Invalid("returned", f"{where}/proven_reason is {reason!r:.60}: the options asked for no proven "
                                  "interval, so its writer states no reason why none was proven")
    if not isinstance(reason, str) or determinacy.get("proven_intervals") is not None:
        raise Invalid("returned", f"{where}/proven_reason is {reason!r:.60}: a reason is a text, stated only where "
                                  "proven_intervals is null (why nothing was proven)")
    if not full:
        expected = (proven_reasons.reason("not_full"),)
    elif not proved:
        expected = (proven_reasons.reason("not_certified", status=status),) if isinstance(status, str) else ()
    else:
        expected = None
    key = None if expected is not None else proven_reasons.is_reason(
        reason, tuple(k for k in keys if k not in ("not_full", "not_certified")))
    if expected is not None and reason not in expected or expected is None and key is None:
        raise Invalid("returned", f"{where}/proven_reason is {reason!r:.80}: not its writer's reason for this stage "
                                  "(core.proven_reasons: a full certificate's certified stage states why its proof "
                                  "found nothing; any other stage, why there is no proof to read)")
    if key is not None and own is not None:
        check_reason_fields(reason, key, own, where)


def check_reason_fields(reason: str, key: str, own: dict, where: str) -> None:
    """A proof's reason says of its proof only what the options and the stage give (review 64): the
    proof it names (``what``: each view's focal length exactly with varying_focal) and whether the
    other intrinsics' proofs were asked for (``after``: prove_intrinsics_intervals, one K), words
    its writer takes from the options; its seconds no more than the search could have (``seconds``:
    the stratified search's least of the time limit and METRIC_PROOF_S, the direct proof's time
    limit and grace, to the rounding of "{:.3g}"); and ``metric_no_level`` only where the stage
    states no cost or no cost increase (``level``: it states both), its writer's condition."""
    found = proven_reasons.fields(reason, key)
    for name in ("what", "after"):
        if name in found and name in own and found[name] != own[name]:
            raise Invalid("returned", f"{where}/proven_reason names {found[name]!r:.80} where its writer, from the "
                                      f"options, names {own[name]!r:.80}")
    if "seconds" in found and "seconds" in own and not float(found["seconds"]) <= own["seconds"] * (1.0 + 5e-3):
        raise Invalid("returned", f"{where}/proven_reason states {found['seconds']} s; its proof ran at most "
                                  f"{own['seconds']:.6g} s under the options")
    if key == "metric_no_level" and own.get("level"):
        raise Invalid("returned", f"{where}/proven_reason says the stage states no cost or no cost increase; it "
                                  "states both")


INTRINSICS = ("focal_x", "focal_y", "skew", "principal_u", "principal_v")  # autocalibration.determinacy.NAMES
RELATIVE_WIDTH = 0.1  # core.determinacy.RELATIVE_WIDTH: the tolerance of a quantity of its scale


def check_redundancy(determinacy: Any, expected: int, where: str) -> None:
    """An autocalibration stage's estimate counts the residuals beyond its parameters as its
    writer does (autocalibration.determinacy: the affine stage's modulus constraints, one a view
    but the reference's, less the plane's 3; a K stage's 5 informative DIAC entries a view but
    the reference's, less K's 5): ``expected``, from the number of views."""
    if not isinstance(determinacy, dict) or stopped(determinacy):
        return
    if not same(determinacy.get("redundancy"), expected):
        raise Invalid("returned", f"{where}/redundancy is {determinacy.get('redundancy')!r:.30}; the stage's "
                                  f"residuals beyond its parameters number {expected!r}")
    check_few_degrees(determinacy, expected, where)


def check_few_degrees(determinacy: dict, redundancy: int, where: str) -> None:
    """In today's form (STUDENT_FORM on) a stage whose level is read off fewer than FEWEST_DEGREES
    degrees of freedom of its own (the affine stage's modulus constraints of five views) states
    ``few_degrees_of_freedom``, as its writer does (core.determinacy.few_degrees, from every
    curvature estimate): without it the stage could claim ``determined`` from a noise estimated
    from one residual (review 64: five views at 0.001, the affine stage restated determined)."""
    if form() < STUDENT_FORM or not 0 < redundancy < FEWEST_DEGREES:
        return
    warnings = determinacy.get("warnings")
    codes = [w.get("code") for w in warnings if isinstance(w, dict)] if isinstance(warnings, list) else []
    if "few_degrees_of_freedom" not in codes:
        raise Invalid("returned", f"{where}/warnings state no few_degrees_of_freedom: the stage's level is read off "
                                  f"{redundancy} degree of freedom, which its writer warns of")


def check_no_redundancy(determinacy: Any, redundancy: int, where: str) -> None:
    """In a document of today's form (NO_REDUNDANCY_FORM on), an autocalibration stage whose cost
    has no residual beyond its parameters (``redundancy``, from the number of views, at most 0:
    the affine stage's modulus constraints of four views, and the metric or direct K stage whose
    plane is that exact fit) states the ``no_redundancy`` warning, as its writer
    (autocalibration.determinacy.no_redundancy) does: without it the stage could claim
    ``determined`` from an exact fit whatever the noise. An analysis stopped or left out claims
    nothing (stopped). Documents of earlier forms were not required to state it."""
    if form() < NO_REDUNDANCY_FORM or redundancy > 0 or not isinstance(determinacy, dict) or stopped(determinacy):
        return
    warnings = determinacy.get("warnings")
    codes = [w.get("code") for w in warnings if isinstance(w, dict)] if isinstance(warnings, list) else []
    if "no_redundancy" not in codes:
        raise Invalid("returned", f"{where}/warnings state no no_redundancy: the stage's cost has {redundancy} "
                                  "residuals beyond its parameters (an exact fit whatever the noise), which its writer "
                                  "warns of")


def check_intrinsics(determinacy: Any, K: Any, where: str, side: float | None = None) -> None:
    """An autocalibration K stage's estimate (autocalibration.determinacy.metric_stage) is about
    the K the result returns: its intervals name the five intrinsics in order, each ``value`` the
    returned K's entry (to 1e-8 of the focal length: the writer reads K back through omega), and
    each ``tolerance`` a tenth of its scale (the focal lengths their own; skew and principal point
    ``side``, core.determinacy.image_scale of the data and ranges, in a document of today's form,
    and the focal lengths' mean in one of a form before OWN_SCALE_FORM), so that ``determined``
    (check_determined) is judged at the writer's width, not one the document chose."""
    if not isinstance(determinacy, dict) or stopped(determinacy) or not isinstance(K, list):
        return
    try:
        K = np.asarray(K, dtype=float).reshape(3, 3)
    except (TypeError, ValueError):
        return  # typed by the returned check of K
    values = (K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2])
    mean = 0.5 * (abs(K[0, 0]) + abs(K[1, 1]))
    own = side if side is not None and form() >= OWN_SCALE_FORM else mean
    scales = (K[0, 0], K[1, 1], own, own, own)
    intervals = determinacy.get("intervals")
    if not isinstance(intervals, list) or [i.get("name") if isinstance(i, dict) else None
                                           for i in intervals] != list(INTRINSICS):
        raise Invalid("returned", f"{where}/intervals name {', '.join(INTRINSICS)}, in that order (the K returned)")
    earlier = not any("tolerance" in i for i in intervals)  # written before intervals stated one (_compare)
    for number, (found, value, scale) in enumerate(zip(intervals, values, scales)):
        given, tolerance = found.get("value"), found.get("tolerance")
        if not _close(given, float(value), 0.0, 1e-8 * mean):
            raise Invalid("returned", f"{where}/intervals/{number}/value is {given!r:.30}, the K returned gives "
                                      f"{float(value)!r:.30}")
        if not earlier and not _close(tolerance, RELATIVE_WIDTH * abs(float(scale)), 0.0, 1e-8 * mean):
            raise Invalid("returned", f"{where}/intervals/{number}/tolerance is {tolerance!r:.30}, a tenth of its "
                                      f"scale is {RELATIVE_WIDTH * abs(float(scale))!r:.30}")


FOCAL_SLACK = 1e-9  # of the focal length: the writer states f0 * (f / f0), the returned focal length rounded


def check_focal_lengths(determinacy: Any, Ks: Any, where: str) -> None:
    """The direct stage's estimate with one focal length a view (autocalibration.determinacy.
    varying_focal_stage) is about the Ks the result returns, as a K stage's is about its K
    (check_intrinsics): its intervals name focal[0] .. focal[m-1] in order, one a returned K,
    each ``value`` that K's focal length (to FOCAL_SLACK of it) and each ``tolerance`` a tenth of
    it (its scale); its redundancy is the writer's, 5 DIAC residuals a view but the reference's
    less the m focal lengths and the plane's 3."""
    if not isinstance(determinacy, dict) or stopped(determinacy) or not isinstance(Ks, list):
        return
    try:
        focal = [float(np.asarray(K, dtype=float).reshape(3, 3)[0, 0]) for K in Ks]
    except (TypeError, ValueError) as exc:
        raise Invalid("returned", f"{where} estimates the focal lengths of Ks, which are not all 3x3 "
                                  f"matrices") from exc
    names = [f"focal[{k}]" for k in range(len(focal))]
    intervals = determinacy.get("intervals")
    if not isinstance(intervals, list) or [i.get("name") if isinstance(i, dict) else None
                                           for i in intervals] != names:
        raise Invalid("returned", f"{where}/intervals name focal[0] .. focal[{len(focal) - 1}], in that order "
                                  "(the Ks returned)")
    earlier = not any("tolerance" in i for i in intervals)  # written before intervals stated one (_compare)
    for number, (found, value) in enumerate(zip(intervals, focal)):
        given, tolerance = found.get("value"), found.get("tolerance")
        if not _close(given, value, 0.0, FOCAL_SLACK * abs(value)):
            raise Invalid("returned", f"{where}/intervals/{number}/value is {given!r:.30}, Ks[{number}] gives "
                                      f"{value!r:.30}")
        if not earlier and not _close(tolerance, RELATIVE_WIDTH * abs(value), 0.0, FOCAL_SLACK * abs(value)):
            raise Invalid("returned", f"{where}/intervals/{number}/tolerance is {tolerance!r:.30}, a tenth of its "
                                      f"focal length is {RELATIVE_WIDTH * abs(value)!r:.30}")
    check_redundancy(determinacy, 5 * (len(focal) - 1) - (len(focal) + 3), where)


PLANE = tuple(f"plane_at_infinity[{k}]" for k in range(4))  # autocalibration.determinacy.affine_stage's names
PLANE_SLACK = 1e-9  # of the plane's largest coordinate: the writer states the returned plane's own


def check_plane(determinacy: Any, plane: Any, where: str) -> None:
    """The affine stage's estimate (autocalibration.determinacy.affine_stage) is about the plane
    the stage returns, as a K stage's is about its K (check_intrinsics): its intervals name
    plane_at_infinity[0] .. [3] in order, each ``value`` the returned plane's coordinate (to
    PLANE_SLACK of the plane's largest: the writer reads the plane back through the normalised
    frame, so a coordinate near 0 differs from the stated one by the others' rounding), and each ``tolerance`` null as the writer writes it (a plane has no scale
    of its own: bounded suffices). A document written before intervals stated a tolerance states
    none on every interval (_compare's earlier form), and is read so."""
    if not isinstance(determinacy, dict) or stopped(determinacy):
        return
    try:
        plane = np.asarray(plane, dtype=float).reshape(4)
    except (TypeError, ValueError):
        return  # typed by the returned check of the plane (and check_claims)
    intervals = determinacy.get("intervals")
    if not isinstance(intervals, list) or [i.get("name") if isinstance(i, dict) else None
                                           for i in intervals] != list(PLANE):
        raise Invalid("returned", f"{where}/intervals name {', '.join(PLANE)}, in that order (the plane returned)")
    scale = float(np.max(np.abs(plane)))
    for number, (found, coordinate) in enumerate(zip(intervals, plane)):
        given = found.get("value")
        if not _close(given, float(coordinate), 0.0, PLANE_SLACK * scale):
            raise Invalid("returned", f"{where}/intervals/{number}/value is {given!r:.30}, the plane returned gives "
                                      f"{float(coordinate)!r:.30}")
        if found.get("tolerance", None) is not None:
            raise Invalid("returned", f"{where}/intervals/{number}/tolerance is {found['tolerance']!r:.30}; a plane "
                                      "coordinate's is null (bounded suffices), as its writer states it")


def check_contains(determinacy: Any, where: str) -> None:
    """An autocalibration stage's intervals hold their own value: each bounded end on its side of
    ``value`` (to VALUE_SLACK of it), as the writer's are (autocalibration.determinacy: the ends are
    the value less and plus the walked distances, each at least 0; the affine stage's the range
    of the planes reached with its own; a clip to the scope moves an end toward the value only,
    the value inside the scope the stage certifies). An interval beside its value says the data
    fix the quantity away from the answer returned; a bounded interval stating no numeric value
    (null or absent) would hold nothing, and is refused (the writer's value is the returned
    answer's, always a number)."""
    if not isinstance(determinacy, dict) or stopped(determinacy) or not isinstance(determinacy.get("intervals"), list):
        return
    for number, found in enumerate(determinacy["intervals"]):
        if not isinstance(found, dict):
            continue
        value, lower, upper = found.get("value"), found.get("lower"), found.get("upper")
        if not is_number(value):
            if is_number(lower) or is_number(upper):  # the writer's value is the answer's, always finite
                raise Invalid("returned", f"{where}/intervals/{number} bounds its quantity but states no numeric "
                                          f"value ({value!r:.20}): an interval holds the value the stage returns")
            continue
        slack = VALUE_SLACK * abs(value)
        if (is_number(lower) and lower > value + slack) or (is_number(upper) and upper < value - slack):
            raise Invalid("returned", f"{where}/intervals/{number} [{lower!r:.20}, {upper!r:.20}] does not hold its "
                                      f"value {value!r:.20}")


# An autocalibration stage's estimate, in its writer's words (core.determinacy.Determinacy.document,
# the only writer of a stage's determinacy, analysed or stopped): its method and level sentence.
STAGE_WORDS = {name: Determinacy().document()[name] for name in ("method", "level")}


def check_stage_words(determinacy: Any, where: str) -> None:
    """An autocalibration stage's ``method`` and ``level`` are its writer's words (STAGE_WORDS), as a
    track's, map's or frame's are compared with theirs (COMPARED): they say what the intervals are,
    and other words ("proven", the proven intervals' level) would have a curvature estimate read as
    intervals a proof covers (reviews 49 and 50)."""
    if not isinstance(determinacy, dict):
        return
    check_pool(determinacy, where)
    for name, words in STAGE_WORDS.items():
        if determinacy.get(name) != words:
            raise Invalid("returned", f"{where}/{name} is {determinacy.get(name)!r:.60}; a stage's estimate states "
                                      f"its writer's {words!r:.60}")


def check_defeated(determinacy: Any, where: str) -> None:
    """An autocalibration stage stated not analysed because the data defeated its linear algebra
    (a ``not_analysed`` first warning, no interval) is its writer's only beside the critical
    motion it judged at the returned K (autocalibration.determinacy.with_motion): a failed analysis
    with no motion to state is written null. Without one, the reason is no writer's, and it hid a
    determined stage's intervals and warnings (review 64 class 5: a metric stage of five views so
    restated verified)."""
    if not isinstance(determinacy, dict) or not stopped(determinacy):
        return
    if determinacy["warnings"][0].get("code") == "not_analysed" and len(determinacy["warnings"]) == 1:
        raise Invalid("returned", f"{where} is stated not analysed (the data defeated its linear algebra) with no "
                                  "critical motion after it: its writer states that only beside the motion it judged, "
                                  "and null otherwise")


def check_pool(determinacy: Any, where: str) -> None:
    """An estimate no writer pools (a map's, a frame's, an autocalibration stage's: only a
    triangulation track's level is pooled over the job's tracks) names no pooled_tracks: one would
    say its level is the residual variance of tracks the document does not have, and no check
    reads it (review 51)."""
    if isinstance(determinacy, dict) and determinacy.get("pooled_tracks") is not None:
        raise Invalid("returned", f"{where}/pooled_tracks is {determinacy['pooled_tracks']!r:.60}; only a "
                                  "triangulation track's level is pooled over tracks (its writer names none here)")


def check_stage_level(determinacy: Any, cost: Any, lower_bound: Any, where: str) -> None:
    """A stratified stage's ``cost_increase`` is the writer's level (core.determinacy.
    cost_increase): the squared quantile of the document's form (level_sigmas) times the stage's
    cost over its redundancy, at least its certified
    gap (cost - lower_bound), from figures the document states (the writer's residuals are those
    of the stage's own cost: the modulus cost at the plane, the metric cost at omega). The direct
    stage's estimate is of another cost (its DIAC residuals, not its certified objective), and is
    not read here."""
    if not isinstance(determinacy, dict) or stopped(determinacy) or not is_number(cost):
        return
    redundancy = determinacy.get("redundancy")
    if type(redundancy) is not int:
        return  # (check_redundancy)
    gap = certified_gap(float(cost), float(lower_bound)) if is_number(lower_bound) else None
    expected = level_of(float(cost), redundancy, gap)
    if not _close(determinacy.get("cost_increase"), expected, 0.0, NUMBER_SLACK * abs(expected)):
        raise Invalid("returned", f"{where}/cost_increase is {determinacy.get('cost_increase')!r:.30}; the stage's "
                                  f"cost {cost!r:.20} over its redundancy {redundancy}, times "
                                  f"{level_sigmas(redundancy):.6g}^2 (the document's form's quantile), at least its "
                                  f"certified gap, gives {expected!r:.30}")


def stopped(determinacy: dict) -> bool:
    """An analysis stopped at its deadline or defeated by the data (core.determinacy.not_analysed):
    no interval, a time_limit or not_analysed warning first, nothing determined; it claims nothing
    of the intervals. An autocalibration stage's states after it the critical motion judged at
    its returned K (autocalibration.determinacy.with_motion), which autocalibration_estimates
    judges again."""
    warnings = determinacy.get("warnings")
    return (determinacy.get("intervals") == [] and determinacy.get("determined") is False
            and determinacy.get("proven") is False and determinacy.get("proven_intervals") is None
            and isinstance(warnings, list) and len(warnings) >= 1
            and all(isinstance(w, dict) for w in warnings) and warnings[0].get("code") in NOT_ANALYSED
            and all(w.get("code") in MOTION_CODES for w in warnings[1:]))


def _check_tracks(kind, result: dict, certificate: dict, earlier: bool = True) -> None:
    data = certificate["data"]
    cameras = normalised_cameras(data["cameras"])  # as the writer reads them: raw, entries near 2^1023 overflow
    for index, item in enumerate(result.get("tracks") or []):
        determinacy = item.get("determinacy") if isinstance(item, dict) else None
        if not isinstance(determinacy, dict):
            continue
        where = f"tracks/{index}/determinacy"
        if stopped(determinacy):
            # a not_analysed is no_level's, which says the residuals at the point returned are not
            # finite; a time_limit no writer of tracks states (no clock stops a track's analysis)
            _refuse_clock(where, determinacy, "a track's")
            views = data["tracks"][index]["views"]
            _check_no_level(where, item, cameras[views], np.asarray(data["tracks"][index]["points"], dtype=float))
            continue
        if item.get("point") is None:
            raise Invalid("returned", f"{where} is stated for a track returning no point (its writer states none)")
        views = data["tracks"][index]["views"]
        points = np.asarray(data["tracks"][index]["points"], dtype=float)
        dof = estimate.pooled_dof(determinacy.get("level"))
        pooled = None
        if dof is not None:  # read at the level stated (checked against its pooled floor: fractional._check_pooled)
            level = determinacy.get("cost_increase")
            pooled = (float(level), dof) if isinstance(level, (int, float)) and not isinstance(level, bool) else None
        expected = safely(estimate.track, cameras[views], points, item["point"], item.get("at_infinity") is True,
                          item.get("cost"), item.get("lower_bound"), None, pooled)
        _check_point_values(where, determinacy, item["point"])
        # the ends as offsets from the value, to the width (review 37 class 2): VALUE_SLACK of a
        # value 1e6 off the origin is 1e-3 px, thousands of widths, so the x, y and z intervals
        # collapsed onto their values, or moved with them off the returned point, verified
        _compare(where, determinacy, expected, earlier, width_slack=TRACK_WIDTH_SLACK, offsets=True, pooled=True)


def _refuse_clock(where: str, determinacy: dict, whose: str) -> None:
    """A stopped estimate's ``time_limit`` (core.determinacy.within: its clock ran out) is an
    autocalibration stage's only: no clock stops a track's, map's or frame's analysis, so the code
    there hides the estimate's intervals and warnings behind a false reason (review 64 class 3:
    a determined track, map or frame so restated verified)."""
    if determinacy["warnings"][0].get("code") == "time_limit":
        raise Invalid("returned", f"{where} is stated stopped by its clock (time_limit): no clock stops {whose} "
                                  "analysis, and its writer states its intervals")


# A projection's depth this close to 0, relative to the sum of its terms' sizes, another order of
# the same sum (the writer's batched einsum, the verifier's matmul) may round to 0 or not: the
# residuals are then finite for one and not for the other, and a no_level track is not judged.
DEPTH_ROUNDING = 1e-8
# Of the largest float: a level or squared residual below this is finite under any rounding of
# the same sums (a few ulps), where the writer's own may overflow only far above it.
LEVEL_ROOM = 1e-6


def _check_no_level(where: str, item: dict, cameras: np.ndarray, points: np.ndarray) -> None:
    """A track stated not analysed (fractional.determinacy.no_level: "its residuals at the point
    returned are not finite") claims nothing, so the reason must hold: its writer states it only
    where the track's level at the returned point (tracks_many's and track's delta: 3^2 times the
    squared residuals over 2n - 3, at least the pooled level and the certified gap) is not finite.
    Refused where the residuals at the point returned, their squares and that level are surely
    finite (every depth off 0 beyond its rounding, each well inside float range): the track's
    intervals hidden behind a false reason (review 63 class 3). A point at infinity's writer
    states at_infinity, and no point at all no determinacy: neither states this."""
    point = item.get("point")
    if point is None or item.get("at_infinity") is True:
        raise Invalid("returned", f"{where} is stated not analysed for a track returning "
                                  f"{'no point' if point is None else 'a point at infinity'} (its writer states "
                                  f"{'none' if point is None else 'at_infinity'})")
    try:
        X = np.append(np.asarray(point, dtype=float), 1.0)
        with np.errstate(all="ignore"):
            proj = cameras @ X
            reach = np.abs(cameras[:, 2, :]) @ np.abs(X)
            if not (np.all(np.isfinite(proj)) and np.all(np.abs(proj[:, 2]) > DEPTH_ROUNDING * reach)):
                return  # a depth at 0 (a point on a camera's centre) or one rounding may make 0: not judged
            residuals = (proj[:, :2] / proj[:, 2:3] - points).ravel()
            squares = residuals * residuals
            cost = float(squares.sum())
    except (TypeError, ValueError):
        return  # (typed by the returned check)
    redundancy = 2 * len(points) - 3
    level = estimate.SIGMAS ** 2 * cost / redundancy if redundancy > 0 else 0.0
    stated = item.get("cost"), item.get("lower_bound")
    gap = certified_gap(float(stated[0]), float(stated[1])) if all(is_number(v) for v in stated) else None
    room = LEVEL_ROOM * float(np.finfo(float).max)
    if np.all(np.isfinite(squares)) and float(squares.max(initial=0.0)) < room and math.isfinite(level) \
            and level < room and (gap is None or gap < room):
        raise Invalid("returned", f"{where} is stated not analysed, its residuals at the point returned not finite; "
                                  f"they are finite (their squares sum to {cost:.6g}, its level {level:.6g}): its "
                                  "writer analyses such a track and states its intervals")


def _check_point_values(where: str, determinacy: dict, point: Any) -> None:
    """A track's x, y and z intervals state the returned point's coordinates as their values, bit
    for bit (the writer, fractional.determinacy.track and tracks_many, states float(X[k]) of the
    point it returns): the value is no estimate, and an interval read from it cannot move with it."""
    intervals = determinacy.get("intervals")
    if not isinstance(intervals, list) or not isinstance(point, list):
        return  # typed by _compare (against the estimate's) and the returned check
    for number, (found, coordinate, name) in enumerate(zip(intervals, point, TRACK_POINT)):
        if not isinstance(found, dict) or found.get("name") != name:
            continue  # named against the estimate's by _compare
        value = found.get("value")
        if not (is_number(value) and is_number(coordinate) and float(value) == float(coordinate)):
            raise Invalid("returned", f"{where}/intervals/{number}/value is {value!r:.40}, the returned point's {name} "
                                      f"is {coordinate!r:.40} (its value, exactly)")


def _check_maps(kind, result: dict, certificate: dict, earlier: bool = True) -> None:
    read = kind.verification.read
    for index, item in enumerate(result.get("maps") or []):
        determinacy = item.get("determinacy") if isinstance(item, dict) else None
        where = f"maps/{index}/determinacy"
        if isinstance(determinacy, dict) and stopped(determinacy):
            _refuse_clock(where, determinacy, "a map's")
            raise Invalid("returned", f"{where} is stated not analysed: no writer of a map's estimate states that "
                                      "(map_ states its intervals, or none where the data defeat it)")
        if not isinstance(determinacy, dict):
            continue
        if item.get("matrix") is None:
            raise Invalid("returned", f"{where} is stated for a map returning no matrix (its writer states none)")
        source, target = read(certificate["data"], index)
        expected = safely(estimate.map_, source, target, item["matrix"], item.get("cost"), item.get("lower_bound"))
        spread = _map_cost_spread(source, target, item["matrix"])
        # the width is read in normalised coordinates (fractional.normalisation), the same wherever
        # the data sit: no slack grows with their offset, which 1e8 off the origin over a spread of
        # 1e-3 let every interval collapse (review 59 class 6)
        width_slack = MAP_WIDTH_SLACK + spread
        if np.asarray(item["matrix"]).shape != (3, 4) and _far(source, target, item["matrix"], certificate):
            # far off, today's writer computes a homography's estimate in a fixed order (fractional.
            # homography_estimate: bit for bit the verifier's under either kernel) and its value
            # exactly: the value held to an ulp, each end read as its offset from it (as a track's,
            # review 37 class 2), so an interval collapsed onto its value or moved with it is refused
            # (review 37 class 3). The width keeps its slack for documents of the writer before
            # (exact value and cost, estimate through BLAS: the stored homography_far_from_origin's
            # ends 7.4e-6 of the width from today's); a writer's before the exact value stated a
            # float cost too, which the objective check holds to the exact one here
            # (checks._check_residual_claim)
            _check_exact_values(where, determinacy, expected)
            _compare(where, determinacy, expected, earlier, spread, width_slack, 0.0, 0.0, offsets=True)
            continue
        # a resection's centre, measured within 2 ulps between kernels, is held to MAP_VALUE_ROUNDING;
        # a homography's centroid image nearer the origin keeps VALUE_SLACK of itself, for documents
        # of earlier writers (computed through the normalisers, some 300 ulps apart between kernels
        # at 1e6 off the origin, review 37), which bear no mark of the form
        # (a resection's centre is in the source's units: its floor is read off the source alone, as the
        # centre is computed, Ts^-1 of a null vector; the targets' pixels, of another unit and any size
        # up to COORDINATE_LIMIT, gave a centre in kilometres a floor wider than its interval: review 58;
        # a homography's centroid image is in the target's units, its floor read off the target alone,
        # Tt^-1 of the normalised image: a source in a finer unit than its targets, 2.8e8 beside
        # 2.5e-8, gave it a floor of 4.9e-7 beside intervals 1.3e-10 wide: review 59)
        # A resection's ends are read as offsets from its value (the writer states each as the value
        # less and plus a half-width): read as numbers, each took the value's floor too, which 1e8
        # off over an exact fit exceeds the width (review 61 class 1: intervals collapsed verified)
        resection = np.asarray(item["matrix"]).shape == (3, 4)
        floor = _map_value_floor(source) if resection else _map_value_floor(target)
        _compare(where, determinacy, expected, earlier, spread, width_slack, floor,
                 MAP_VALUE_ROUNDING if resection else VALUE_SLACK, offsets=resection)


def _check_exact_values(where: str, determinacy: dict, expected: dict | None) -> None:
    """Each stated value is the estimate's to HOMOGRAPHY_VALUE_ULPS of it (the rest is _compare's)."""
    intervals = determinacy.get("intervals")
    if expected is None or not isinstance(intervals, list):
        return  # (_compare)
    for number, (found, own) in enumerate(zip(intervals, expected["intervals"])):
        value = found.get("value") if isinstance(found, dict) else None
        if own["value"] is not None and is_number(value) and not abs(
                float(value) - own["value"]) <= HOMOGRAPHY_VALUE_ULPS * math.ulp(own["value"]):
            raise Invalid("returned", f"{where}/intervals/{number}/value is {value!r:.40}, the exact centroid image "
                                      f"is {own['value']!r:.40}")


def _far(source: np.ndarray, target: np.ndarray, matrix: Any, certificate: dict) -> bool:
    """Whether a float evaluation's rounding could move the map's cost (exact.needs_exact, as the
    objective check decides it): where it could, its writer states the exact cost, and today's."""
    from geocert.core import exact
    from geocert.core.certificates import OBJECTIVE_TOLERANCE
    from geocert.core.geometry import norm_cost
    from geocert.formulations.fractional.items import MapItem

    norm = (certificate.get("options") or {}).get("norm")
    try:
        M = np.asarray(matrix, dtype=float)
        item = MapItem((source, target), norm, chart=False)
        with np.errstate(all="ignore"):
            floats, _, _ = item.raw_residuals(M)
            return bool(exact.needs_exact(floats, item.residual_uncertainty(M), norm_cost(floats, norm), norm,
                                          OBJECTIVE_TOLERANCE))
    except (TypeError, ValueError, KeyError, ArithmeticError):
        return False


def _check_frames(kind, result: dict, certificate: dict, earlier: bool = True) -> None:
    from geocert.formulations.bilinear import determinacy as frame_estimate

    read = kind.verification.read
    for index, item in enumerate(result.get("frames") or []):
        determinacy = item.get("determinacy") if isinstance(item, dict) else None
        where = f"frames/{index}/determinacy"
        if isinstance(determinacy, dict) and stopped(determinacy):
            _refuse_clock(where, determinacy, "a frame's")
            raise Invalid("returned", f"{where} is stated not analysed: no writer of a frame's estimate states that "
                                      "(bilinear.determinacy.frame states its intervals, or none where the data "
                                      "defeat it)")
        if not isinstance(determinacy, dict):
            continue
        if item.get("camera") is None or item.get("coefficients") is None:
            raise Invalid("returned", f"{where} is stated for a frame returning no camera (its writer states none)")
        basis, points = read(certificate["data"], index)
        expected = safely(frame_estimate.frame, basis, points, item["camera"], item["coefficients"], item.get("cost"),
                          item.get("lower_bound"))
        _compare(where, determinacy, expected, earlier)


def _map_cost_spread(source: np.ndarray, target: np.ndarray, matrix: Any) -> float:
    """How far the data determine a map's cost, relative to it (the objective check's spread,
    checks._check_residual_claim): far-off data make each residual a difference of numbers far
    larger than itself, which another machine's kernels round otherwise, and the estimate's level
    (a multiple of the cost, where its certified gap sets it) moves with it."""
    from geocert.core.geometry import cost_rounding
    from geocert.formulations.fractional.proof import residual_uncertainty

    try:
        M = np.asarray(matrix, dtype=float)
        homogeneous = np.hstack([source, np.ones((len(source), 1))])
        proj = homogeneous @ M.T
        with np.errstate(all="ignore"):
            residuals = target - proj[:, :-1] / proj[:, -1:]
            spread = cost_rounding(residuals, residual_uncertainty(proj, np.abs(homogeneous) @ np.abs(M).T), "L2L2")
            cost = float((residuals * residuals).sum())
            # a float cost of 0 with any spread is not determined at all: the cap, not a division by 0
            relative = 2.0 * spread / cost if cost > 0 else (math.inf if spread > 0 else 0.0)
    except (TypeError, ValueError):
        return 0.0
    # capped: a cost the data barely determine (a near-exact map far off) must not let the level and
    # interval ends move by multiples of themselves
    return min(relative, MAX_COST_SPREAD) if relative >= 0 else 0.0


def _compare(where: str, given: dict, expected: dict | None, earlier_form: bool = True,
             cost_spread: float = 0.0, width_slack: float = 0.0, value_floor: float = 0.0,
             value_slack: float = VALUE_SLACK, offsets: bool = False, pooled: bool = False) -> None:
    """``given`` is ``expected`` but for its proven intervals (checked against the proof) and the
    pool a pooled level names (checked against the data), to the module's slack; read as written
    before intervals stated a tolerance only where ``earlier_form`` allows it (check). A value
    (and an end with it) may differ by ``value_slack`` of itself and ``value_floor``; with
    ``offsets``, an end is read as its offset from its own interval's value (end - value) against
    the estimate's, to NUMBER_SLACK and ``width_slack`` of the width and END_OFFSET_ULPS of the end,
    whatever the value's size. ``pooled``: whether the estimate may be read at a level pooled over
    the job's tracks (a triangulation track's, whose pooled_tracks fractional._check_pooled checks
    against the data); no other writer names a pool (check_pool)."""
    if not pooled:
        check_pool(given, where)
    if given.get("proven_over_planes") is not None:  # a stratified metric stage's only (verify.autocalibration)
        raise Invalid("returned", f"{where}/proven_over_planes: intervals proven over the planes at infinity are a "
                                  "metric stage's; no proof of a track's, map's or frame's carries them")
    if expected is None:
        raise Invalid("returned", f"{where} is stated where the estimate is not defined on the data (its writer "
                                  "states none)")
    check_determined(given, where, earlier_form)
    intervals = given.get("intervals")
    earlier = earlier_form and isinstance(intervals, list) and bool(intervals) and not any(
        isinstance(i, dict) and "tolerance" in i for i in intervals)
    if earlier:  # written before intervals stated their tolerance: fixed meant bounded (check_determined)
        expected = {**expected, "determined": given.get("determined"),
                    "intervals": [{k: v for k, v in i.items() if k != "tolerance"} for i in expected["intervals"]]}
    for name in COMPARED:
        if given.get(name) != expected.get(name):
            raise Invalid("returned", f"{where}/{name} is {given.get(name)!r:.60}, the estimate at the solution "
                                      f"returned gives {expected.get(name)!r:.60}")
    level = expected.get("cost_increase")
    # relative only (_close adds VALUE_SLACK of the level): the level is a multiple of the claimed
    # cost, which may be 1e-17 (a near-exact fit), so an absolute slack let it be stated any size
    if not _close(given.get("cost_increase"), level, 0.0, cost_spread * abs(level) if is_number(level) else 0.0):
        raise Invalid("returned", f"{where}/cost_increase is {given.get('cost_increase')!r:.40}, the estimate's level "
                                  f"is {expected.get('cost_increase')!r:.40}")
    warnings = given.get("warnings")
    if not isinstance(warnings, list) or [w.get("code") if isinstance(w, dict) else None for w in warnings] != [
            w["code"] for w in expected["warnings"]]:
        raise Invalid("returned", f"{where}/warnings are not the estimate's at the solution returned (codes "
                                  f"{[w['code'] for w in expected['warnings']]!r:.80})")
    if not isinstance(intervals, list) or len(intervals) != len(expected["intervals"]):
        raise Invalid("returned", f"{where}/intervals are not the estimate's ({len(expected['intervals'])} of them)")
    for number, (stated, own) in enumerate(zip(intervals, expected["intervals"])):
        at = f"{where}/intervals/{number}"
        if not isinstance(stated, dict) or stated.get("name") != own["name"]:
            raise Invalid("returned", f"{at}/name is not the estimate's {own['name']!r}")
        width = own["upper"] - own["lower"] if own["lower"] is not None and own["upper"] is not None else 0.0
        scale = abs(own["value"]) if own["value"] is not None else 0.0
        for name in ("value", "lower", "upper", "tolerance")[:3 if earlier else 4]:
            # the value is the returned solution's own, to ``value_slack`` of itself; an end moves with
            # it, and by ``width_slack`` of the width with the level and the curvature (each slack
            # read once: review 34 found the value's twice); that the ends hold the stated value is
            # _check_holds'; the tolerance is a share of the quantity's scale (a distance the data
            # give, to VALUE_SLACK of itself: a centre at the origin has a value of the rounding)
            absolute = (value_slack if name != "tolerance" else VALUE_SLACK) * scale \
                + (width_slack * abs(width) if name in ("lower", "upper") else 0.0) \
                + (value_floor if name != "tolerance" else 0.0)
            if offsets and name in ("lower", "upper") and own["value"] is not None:
                _check_offset(at, name, stated, own, width, width_slack)
                continue
            if not _close(stated.get(name), own[name], width, absolute, VALUE_SLACK if name == "tolerance" else 0.0):
                raise Invalid("returned", f"{at}/{name} is {stated.get(name)!r:.40}, the estimate at the solution "
                                          f"returned gives {own[name]!r:.40}")
    _check_holds(intervals, where)


def _check_offset(at: str, name: str, stated: dict, own: dict, width: float, width_slack: float) -> None:
    """The stated end's offset from the stated value is the estimate's (_compare's ``offsets``);
    the stated value is the estimate's already (compared before its ends)."""
    given, value = stated.get(name), stated.get("value")
    if own[name] is None or given is None:
        if given is None and own[name] is None:
            return
    elif is_number(given) and is_number(value):
        offset, expected = float(given) - float(value), own[name] - own["value"]
        rounding = END_OFFSET_ULPS * math.ulp(max(abs(own["value"]), abs(own[name])))
        allowed = (NUMBER_SLACK + width_slack) * abs(width) + rounding
        if math.isfinite(expected) and math.isfinite(allowed) and abs(offset - expected) <= allowed:
            return
    raise Invalid("returned", f"{at}/{name} is {given!r:.40}, the estimate at the solution returned gives "
                              f"{own[name]!r:.40} (its offset from the value {own['value']!r:.40})")


def _map_value_floor(coordinates: Any) -> float:
    """What a map estimate's value and ends may differ by whatever their own size:
    MAP_VALUE_ROUNDING of the largest of ``coordinates`` (a homography's target, the units
    of its centroid image; a resection's source, the units of its centre). The value (a homography's image of the
    centroid, a resection's centre) is computed from terms of the data's size through the
    normalisers, so where it is near 0 (a centroid mapped to the origin) it is their rounding, not
    a number to a few ulps of itself (review 35 class 2: 1.03e-13 stated, 9.76e-14 recomputed, from
    terms of 200 px)."""
    coordinates = np.asarray(coordinates, dtype=float)
    return MAP_VALUE_ROUNDING * (float(np.max(np.abs(coordinates))) if coordinates.size else 0.0)


def _check_holds(intervals: list, where: str) -> None:
    """Each stated interval holds its stated value, to END_ROUNDING of the value's size: a writer's
    always does (END_ROUNDING's note), so this reads the document's own numbers and no machine's."""
    for number, found in enumerate(intervals):
        value, lower, upper = found.get("value"), found.get("lower"), found.get("upper")
        if not is_number(value):
            continue  # read against the writer's by _compare
        slack = END_ROUNDING * abs(value)
        if (is_number(lower) and lower > value + slack) or (is_number(upper) and upper < value - slack):
            raise Invalid("returned", f"{where}/intervals/{number} [{lower!r:.24}, {upper!r:.24}] does not hold its "
                                      f"value {value!r:.24}")


def _close(given: Any, expected: float | None, width: float, absolute: float, relative: float = VALUE_SLACK) -> bool:
    """Whether ``given`` is ``expected`` (None is None) to NUMBER_SLACK of ``width``, ``absolute``
    and ``relative`` (VALUE_SLACK) of its own size."""
    if expected is None or given is None:
        return given is None and expected is None
    if not is_number(given):  # a finite float or an int within float range (10**400 raised OverflowError: review 59)
        return False
    allowed = NUMBER_SLACK * abs(width) + absolute + relative * abs(expected)
    # an expected value, width or slack that overflowed (or is NaN) matches nothing: |x - inf| <= inf
    # held for any stated x (review 57's class, in this module's comparison: review 58)
    if not (math.isfinite(expected) and math.isfinite(allowed)):
        return False
    return abs(given - expected) <= allowed
