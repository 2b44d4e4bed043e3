"""Review 55: the stratified frame's world scale (commit 4899b9b4: frames.world_ratio,
world_unit_scale, world_scale_fits, earlier_world_readable; proofs.check_reference,
check_earlier_frame; the verifier's _proof_frame, _stated_frame, FRAMES).

Tried:

- Outvoting the median. world_ratio is the median over the other cameras of ||a_j|| / ||A_j|| in
  the reference frame, so a forger who adds more views than the scene has other cameras decides
  it. The views added are genuine: the stored stratified scene (tests/data/certificates/
  autocalibration_stratified.json, six cameras, true K [[1000, 0, 500], [0, 1000, 500], [0, 0, 1]])
  upgraded by its own returned upgrade, its reference (camera 4) centre moved to the origin
  (review 54's _reposed, k = 1), and n copies of the reference camera translated by 2^e scene
  units in random directions (the same K and rotation: images of the same scene, consistent with
  the true K, each a pure translation of the reference, whose modulus constraint is flat in the
  plane, cost O((a.p)^3) squared).
- Exact duplicates of the reference (ratio 0, cost 0 for every plane: they add nothing to either
  stage) so the median is 0 and world_ratio falls back to 1 (world_scale 2^-6), the scene's
  fourth coordinate times 2^30 and 2^31 to leave the far cameras far.
- The earlier writer's frame (proofs stating reference_scale and no world_scale, read in the world
  as given where the ratio lies in [2^-20, 2^8)): the same near views, the scene's fourth
  coordinate times 2^28 (review 54's 397 px case), a writer posing the stages in the world as
  given (self-check off).
- world_scale_fits at the octave's edges (pure checks).

Found:

1. (hole, fixed) Six near views (one more than the scene's five other cameras) at 2^-36:
   world_ratio 7.7e-12 (the near views' median), world_scale 2^31, which puts the scene's five real
   cameras at ratio about 2^18.7 in the frame, review 54's failure reached through the median.
   Both stages certified (affine cost 6.2e-13, "within abs_gap" 1e-12; metric 6.0), in 2.5 s,
   K focal 632.3 and 600.7 at (546.0, 593.4) with skew 10, 399 px off the truth, status optimal, no
   warning, and verify_any valid. At 2^-33 (world_scale 2^28): the metric stage at its clock
   (K 235 px off, uncertified: no false claim). Five near views (not a majority of the eleven
   others, the median between the groups): world_scale 2^6, K within 3e-4 px of the truth
   (control below). Six near views, the scene's cameras' ratio in the frame: 2^-25, 2^10.2:
   K within 0.003 px, certified; 2^-28, 2^13.2: the metric stage at its clock (0.13 px off);
   2^-30, 2^15.2: at its clock (61 px off); 2^-36, 2^18.7: certified 399 px off. The far cameras
   behave as the uniform scene's did in the world as given (review 54: exact to 301, moving from
   1.2e3), so a guard refusing (or leaving uncertified) a frame whose farthest camera lies beyond
   2^8 (world_scale * frames.world_ratio_highest) would refuse this; one far view alone (a copy of
   camera 0 translated 2^15, ratio 2^18 in the frame, the median unmoved) left both stages at their
   clocks (K 98 px off, uncertified: nothing false), 2^22 was refused as rank-deficient.
   Fixed: the frame is used only where every other camera lies below 2^8 in it
   (frames.world_frame_bounded: world_scale times the farthest ratio, frames.world_ratio_highest,
   the earlier writers' limit); the kind's check_options refuses other data for the stratified
   method (422 naming data/cameras; here the farthest at 3.2e6), a reconstruction's upgrade
   (solvers/reconstruction/upgrade.autocalibrate) does not run the stratified search on such
   registered views ("auto": the direct method), and proofs.check_reference refuses
   a proof stating world_scale for them (a forger's writer without the check: K 399 px off, refused).
   A maximum alone in place of the median would be outvoted the other way (one far view). The
   price: data the solver got right are refused too (the near views at 2^-25, the scene's cameras
   at 2^10.2: K exact before, now a 422), as is the one far view above (uncertified before).

2. (hole, fixed) The earlier writer's limit (frames.earlier_world_readable) read the median only:
   the scene's fourth coordinate times 2^28 (its five other cameras at ratio 2^18.2, review 54's
   case) with six near views translated 2^6 from the reference (median 34, inside [2^-20, 2^8)),
   solved by the writer before world_scale (unit reference frame, world as given: proofs stating
   reference_scale only): both stages certified (affine 5.0e-15, metric 6.07), K focal 633.0 and
   601.3 at (544.2, 591.8), skew 10, 398.7 px off, and verify_any valid. (Near views at 2^-14,
   median 2^-14.9: the metric stage at its clock, nothing false.) Fixed: Normalised carries
   world_ratio_highest (frames.world_ratio_highest, the farthest other camera), and a proof
   stating no world_scale is read in the world as given only where that, too, lies below
   2^EARLIER_WORLD_HIGHEST; the stored stratified documents (stored scene, five views) stay read.

Held:

- Duplicates of the reference at ratio 0 (the fallback to 1): the far cameras cannot be taken far
  enough; at 2^30 and 2^31 the data are refused as rank-deficient (frames.check_reconstruction,
  a camera's translation 1e9 times its left block); at 2^28 (the scene's cameras at 2^18.2, times
  world_scale 2^-6: 2^12.2 in the frame) the fix's bound refuses the frame. world_ratio's fallback
  is checked below.
- The earlier writer's frame with near views at 2^-20: the median (2^-20.9) lies below
  EARLIER_WORLD_LOWEST and the document is refused.
- world_scale_fits: the data's power of two and, on an octave's edge only, its neighbour are taken;
  a neighbour 1e-8 inside the octave, a non-power of two, 0, inf, nan and negative are refused.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored
from tests.verify.test_forgeries_review54 import TRUTH, _reposed, _solve
from tests.verify.test_forgeries_review54 import _earlier_world_writer as earlier_world_writer

pytestmark = pytest.mark.filterwarnings("ignore")


def _valid(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


def _with_near_views(exponent: float, count: int, k: float = 1.0) -> tuple[dict, dict]:
    """The stored stratified scene upgraded, its reference's centre at the origin and its fourth
    coordinate times ``k``, with ``count`` views of the same K and rotation as the reference,
    translated by 2^``exponent`` in random directions (genuine views of the scene)."""
    document = stored("autocalibration_stratified")
    certificate = document["certificate"]
    options = certificate["options"]
    data = _reposed(certificate["data"], options, k, np.asarray(document["upgrade"]))
    P = np.asarray(data["cameras"], dtype=float)
    reference = autocalibration_problem.prepare(P, np.asarray(data["points"]), tuple(data["image_size"]),
                                                {}).norm.reference
    M = P[reference, :, :3]
    rng = np.random.default_rng(0)
    extra = []
    for _ in range(count):
        d = rng.normal(size=3)
        d *= 2.0 ** exponent / np.linalg.norm(d)
        extra.append(np.hstack([M, (-M @ d)[:, None]]))
    data["cameras"] = np.concatenate([P, np.array(extra).reshape(-1, 3, 4)]).tolist()
    return data, options


def _norm(data: dict, **frame):
    return autocalibration_problem.prepare(np.asarray(data["cameras"]), np.asarray(data["points"]),
                                           tuple(data["image_size"]), {}, **frame).norm


def _false_claim(result: dict) -> bool:
    """Both stages certified, the document valid, K more than 10 px off the truth, no warning."""
    return (all(stage["certified"] for stage in result["stages"]) and result["status"] == "optimal"
            and not result.get("warnings") and np.abs(np.asarray(result["K"]) - TRUTH).max() > 10.0
            and _valid(result))


# Found: views near the reference, a majority, decide the median and the frame

def test_views_near_the_reference_outvoting_the_median_are_refused_by_the_writer():
    from geocert.core.geometry import InputError
    from geocert.jobs.runner import solve_job

    data, options = _with_near_views(-36.0, 6)
    norm = _norm(data)
    assert norm.world_scale == 2.0 ** 31  # the near views' median
    assert norm.world_scale * norm.world_ratio_highest > 2.0 ** 18
    with pytest.raises(InputError, match="spread too far") as raised:
        solve_job({"kind": "autocalibration", "data": data, "options": options})
    assert raised.value.field == "data/cameras"


def test_views_near_the_reference_outvoting_the_median_do_not_certify_a_false_K(monkeypatch):
    """A forger's writer without the data check (and its self-check): K 399 px off, certified by
    both stages (as today's writer did before the fix), is refused by the verifier."""
    data, options = _with_near_views(-36.0, 6)
    monkeypatch.delenv("GEOCERT_SELF_VERIFY", raising=False)
    with monkeypatch.context() as patched:
        patched.setattr(frames, "world_frame_bounded", lambda norm: True)
        result = _solve(data, options)
    if all(stage["certified"] for stage in result["stages"]):
        assert np.abs(np.asarray(result["K"]) - TRUTH).max() > 10.0  # the false claim refused below
    assert not _false_claim(result), (result["K"], [s["cost"] for s in result["stages"]])
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid and "world_frame_bounded" in report.first_failure["detail"]


@pytest.mark.parametrize("exponent, bounded", [(-36.0, False), (-25.0, False), (-20.0, True)])
def test_the_frame_is_bounded_only_where_every_camera_lies_within_2_to_the_8(exponent, bounded):
    norm = _norm(_with_near_views(exponent, 6)[0])
    assert frames.world_frame_bounded(norm) is bounded
    assert (norm.world_scale * norm.world_ratio_highest < 2.0 ** 8) is bounded


def test_near_views_not_a_majority_leave_the_frame_and_K():
    """Control: five near views (the median between the groups): the true K certified."""
    data, options = _with_near_views(-36.0, 5)
    assert _norm(data).world_scale == 64.0
    result = _solve(data, options)
    assert all(stage["certified"] for stage in result["stages"]) and _valid(result)
    assert np.abs(np.asarray(result["K"]) - TRUTH).max() < 0.01


# Held: the fallback, and the edges of the octave

def test_duplicates_of_the_reference_make_the_median_zero_and_the_ratio_one():
    data, _ = _with_near_views(-36.0, 0)
    P = np.asarray(data["cameras"])
    reference = _norm(data).reference
    data["cameras"] = np.concatenate([P, np.repeat(P[reference:reference + 1], 6, axis=0)]).tolist()
    norm = _norm(data)
    assert norm.world_ratio == 1.0 and norm.world_scale == 2.0 ** -6 and frames.world_frame_bounded(norm)
    document = stored("autocalibration_stratified")
    data = _reposed(document["certificate"]["data"], document["certificate"]["options"], 2.0 ** 28,
                    np.asarray(document["upgrade"]))
    P = np.asarray(data["cameras"])
    data["cameras"] = np.concatenate([P, np.repeat(P[reference:reference + 1], 6, axis=0)]).tolist()
    norm = _norm(data)
    assert norm.world_scale == 2.0 ** -6 and not frames.world_frame_bounded(norm)


@pytest.mark.parametrize("exponent", [30, 31])
def test_duplicates_of_the_reference_cannot_hold_the_scene_far_the_rank_check_refuses(exponent):
    from geocert.core.geometry import InputError

    document = stored("autocalibration_stratified")
    certificate = document["certificate"]
    data = _reposed(certificate["data"], certificate["options"], 2.0 ** exponent)
    with pytest.raises(InputError):
        frames.check_reconstruction(np.asarray(data["cameras"]))


@pytest.mark.parametrize("ratio, scale, fits", [
    (2.0 ** -6, 1.0, True), (2.0 ** -6, 2.0, True),  # on the edge: the neighbour is taken
    (2.0 ** -6 * (1 - 1e-12), 2.0, True), (2.0 ** -6 * (1 - 1e-12), 1.0, True),
    (2.0 ** -6 * (1 + 1e-8), 2.0, False), (2.0 ** -6 * (1 - 1e-8), 1.0, False),
    (0.3, 2.0 ** -4, True), (0.3, 2.0 ** -3, False), (0.3, 2.0 ** -5, False), (0.3, 1.5 * 2.0 ** -4, False),
    (0.3, 0.0, False), (0.3, -(2.0 ** -4), False), (0.3, float("inf"), False), (0.3, float("nan"), False)])
def test_a_stated_world_scale_fits_only_the_datas_octave(ratio, scale, fits):
    assert frames.world_scale_fits(scale, ratio) is fits
    if fits and scale * ratio >= 2.0 ** -6:
        assert frames.world_unit_scale(ratio) in (scale, scale / 2, scale * 2)


# Found and fixed: the earlier writer's limit read the median only

def _earlier_world_writer(monkeypatch, data: dict, options: dict) -> dict:
    """``data`` solved by the writer before world_scale (the unit reference frame, the world as
    given: proofs stating reference_scale only), its self-check off (review 54's writer)."""
    return earlier_world_writer(monkeypatch, data, options, unit_reference=True)


def test_an_earlier_writers_proof_with_near_views_outvoting_the_median_is_refused(monkeypatch):
    """The scene's fourth coordinate times 2^28 (its cameras at ratio 2^18.2 from the reference),
    six views translated 2^6 from the reference (the median 34, inside [2^-20, 2^8)): the earlier
    writer certified K 398.7 px off (focal 633.0 and 601.3 at (544.2, 591.8), skew 10), which
    verified before the fix. Every camera must now lie below 2^8."""
    data, options = _with_near_views(6.0, 6, 2.0 ** 28)
    norm = _norm(data, unit_reference=True, world=False)
    assert 2.0 ** -20 <= norm.world_ratio < 2.0 ** 8 and norm.world_ratio_highest > 2.0 ** 18
    assert not frames.earlier_world_readable(norm)
    result = _earlier_world_writer(monkeypatch, data, options)
    assert all(set(item["proof"]) & {"reference_scale", "world_scale"} == {"reference_scale"}
               for item in result["certificate"]["items"])
    if all(stage["certified"] for stage in result["stages"]):
        assert np.abs(np.asarray(result["K"]) - TRUTH).max() > 10.0  # the false claim the fix refuses
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid and "world_scale" in (report.first_failure or {}).get("detail", "")


def test_an_earlier_writers_proof_on_the_scene_as_given_is_still_read(monkeypatch):
    """Control: the same writer on the scene with its reference's centre at the origin (k = 1): read."""
    data, options = _with_near_views(6.0, 0)
    assert frames.earlier_world_readable(_norm(data, unit_reference=True, world=False))
    result = _earlier_world_writer(monkeypatch, data, options)
    assert all(stage["certified"] for stage in result["stages"]) and _valid(result)
    assert np.abs(np.asarray(result["K"]) - TRUTH).max() < 0.01


@pytest.mark.parametrize("name", ["autocalibration_stratified", "autocalibration_five_views"])
def test_stored_earlier_documents_are_read_and_lie_within_the_limit(name):
    document = stored(name)
    data = document["certificate"]["data"]
    norm = autocalibration_problem.prepare(np.asarray(data["cameras"]), np.asarray(data["points"]),
                                           tuple(data["image_size"]),
                                           dict(document["certificate"]["options"].get("intrinsics") or {}),
                                           unit_reference=True, world=False).norm
    assert norm.world_ratio_highest < 2.0 ** frames.EARLIER_WORLD_HIGHEST and _valid(document)


def test_a_reconstructions_stratified_upgrade_is_not_run_on_such_views():
    from geocert.solvers.reconstruction import upgrade

    data, options = _with_near_views(-36.0, 6)
    cameras = [np.asarray(P) for P in data["cameras"]]
    out = upgrade.autocalibrate(cameras, np.asarray(data["points"]), tuple(data["image_size"]), {},
                                autocalibration_problem.AutocalibrationOptions(), 100, method="stratified")
    assert out.reason and "world_frame_bounded" in out.reason and not out.stages


def test_auto_runs_the_direct_method_alone_on_such_views():
    """"auto": no stratified stage is run, only the direct method's (and, where it finds no upgrade
    either, the reason says the stratified frame was not run and why)."""
    from geocert.solvers.reconstruction import upgrade

    data, options = _with_near_views(-36.0, 6)
    cameras = [np.asarray(P) for P in data["cameras"]]
    out = upgrade.autocalibrate(cameras, np.asarray(data["points"]), tuple(data["image_size"]), {},
                                autocalibration_problem.AutocalibrationOptions(), 100, method="auto")
    assert out.stages and all(stage["name"] not in ("affine", "metric") for stage in out.stages), out.stages
    assert out.K is not None or "stratified: not run" in out.reason
