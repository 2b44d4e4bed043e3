"""An eighteenth hostile review of the verifier (issue 33), aimed at review 17's three checks: an
uncertified item's summary root_region and scope (fractional._uncertified_region, _check_scope_words),
a reconstruction's adjustment model tied to the options, and the cameras returned tied to that
model's calibration (reconstruction_members._check_adjustment_model). First genuine results, to
find false refusals; then forgeries, edited from genuine solves as a forger would, rehashed where
an edit touches what the hashes cover. Scenes are synthetic (synthetic.scene: 8 views 640x480,
focal 800, noise 0.3 px, seed 6, 100 points unless said), so each result takes a second or two.

Found (each verified; fixed after the review but the last, each test failing on the code before):

- A done adjustment whose ``model`` is removed (or null) is read by no model check
  (test_a_done_adjustment_without_its_model_is_refused): the camera_model "varying" run (each view
  its own focal length) or "full" run (aspect and skew free), its options.camera_model removed
  (read as "simple") and rehashed, its bundle_adjustment stage still status "done" with model
  removed or null: verifies. The hash then matches a request for the simple model (one focal
  length, square pixels) while the cameras returned have 8 focal lengths (varying) or skew and
  aspect (full). _check_adjustment_model returns when ``model`` is None ("the adjustment did not
  run"), which the stage's status "done" (and its started_from, starts, rms figures) contradicts.
- A simple adjustment restated as "full" or "varying" verifies
  (test_a_simple_adjustment_restated_as_another_model_is_refused): the default run, options.
  camera_model and the stage's model both "full" (or "varying"), rehashed, verifies, its cameras
  sharing one K with exactly square pixels, zero skew and the image-centre-free principal point of
  the simple model, and (with "full") its ``principal_point`` test record, which the pipeline
  writes for the simple model only, left in place. The check asks that the cameras fit the model's
  calibration, and the simple model's is a special case of every other's; a genuine full
  adjustment's K has skew and aspect other than exactly 0 and 1, a genuine varying one focal
  lengths that differ, and no model but simple writes the principal_point record. (Whether this
  is false or merely weaker is the lead's call: the hash matches a request whose adjustment never
  ran; at the least the simple-only record beside "full" is checkable.)
- An uncertified item's root region's chart is not read
  (test_an_uncertified_regions_chart_is_read): on the homography run (3 maps, the example's and
  twice the example with 3 px noise on its targets, L1L1, max_nodes 1: maps 1 and 2 node_limit with
  a root_region), map 1's region with ``functionals`` the string "anything", ``reference_point`` 999
  (the map has 6 points), ``denominator`` all 0, or lower/upper of 1 entry (its functionals have 2
  rows) verifies; on the triangulation example (L1L1, max_residual 20, max_nodes 1: track 1
  node_limit), track 1's region with lower/upper of 5 entries (its functionals have 1 row), or
  functionals all 0, verifies. _uncertified_region checks the words, lower <= upper, finiteness,
  "one length" of lower and upper (each other's, not the chart's) and a track's reference view,
  and nothing of the chart the box is stated in. The same on a reconstruction's points
  (test_an_uncertified_points_region_chart_is_read: L1L1, max_residual 20, max_nodes 1, 40 points:
  point 0's functionals a string verified; a box of 3 entries matched its 3 functional rows, so the
  test now states a box an entry longer than its functionals). The box's numbers themselves, with
  no proof to rebuild them from, stay unchecked.

- An uncertified item's summary ``leaves`` and ``tolerance`` are read by nothing
  (test_an_uncertified_summarys_typed_members_are_read): on the triangulation run above, track 1's
  summary with leaves -5 or "many", or tolerance "x", verifies; docs/certificate.md says every
  informational field "must be null or of its type", and a certified item's are checked against its
  proof and options (track 0's leaves -5 is refused: "its proof has 1").
- An uncertified item's scope is read only beside a root region
  (test_an_uncertified_scope_without_a_region_is_read): track 1's summary with root_region null,
  or removed, and scope "every point of space, proven optimal" verifies (fractional._check_scope_words
  returns: "without a search (no root box) the words claim nothing"). The solver writes an
  uncertified search's summary with its root region; a scope stated without one could be required
  to be the kind's words too (or absent). Not fixed, by choice: the words of a summary no search
  backs, beside an item that says it is not certified, claim nothing; the test was dropped.

Fixed after the review: a done adjustment states its model; the principal point's test records sit
beside the simple model only; an uncertified region's functionals are finite, none all zero, one a
row of its box, its denominator (not all zero) and reference (view or point) its chart's; an
uncertified summary's leaves a count and tolerance a number at least 0 (fractional._uncertified_summary,
_uncertified_region; reconstruction_members._check_adjustment_model).

False refusal found, then fixed:

- A genuine run whose principal point is 36 px off the image centre was refused by the calibration
  tie (test_a_genuine_run_with_its_principal_point_off_centre_verifies): synthetic.scene(views=8,
  points=200, seed=6, noise_px=0.3, spread_degrees=50) with every pixel shifted by (+30, -20) px,
  options {"certificate": "full"} (defaults: camera_model simple, principal_point auto; the
  principal point test estimates (349.2, 219.8)) or camera_model "full": "the calibration
  certificate's reconstruction fits the 1600 observations it shares with the result at a cost of
  535.5 px^2, the returned cameras at 227.3 (at most 514.4: twice theirs plus 3 standard
  deviations ...)"; (-30, +20) at 515.0 (506 allowed); (-60, +45) 5.06 px from the returned
  cameras' images (3.87 allowed). The cause: the default registration (incremental) builds the
  certificate's cameras as K [R | t] with the principal point at the image's centre, and the tie
  held that model to the returned cameras, whose principal point is estimated: the centred model
  genuinely fits the tracks worse, by what holding the principal point there costs (about 0.23
  px^2 per px^2 of offset here), which no noise allowance covers. Fixed: a certificate whose
  cameras are built so (one focal length, square pixels, no skew, each image's centre) is held to
  the returned reconstruction re-adjusted in that model (calibration_tie._centred_reference,
  centred_fit: 530 px^2 at (+30, -20), 511 at (-30, +20), 1365 at (-60, +45)). Still refused, by
  the same checks: shifts of (-90, +70) and (+90, -70) px (114 px off): the pipeline's centred
  adjustment (a Huber round, then least squares on the observations within the threshold) lies
  farther from that model's least-squares fit than the noise allows (3315 px^2 against 2919; an
  observation 5.55 px from the re-adjusted reconstruction's image, 3.9 allowed).
  test_a_certificate_reposed_with_another_K_beside_an_off_centre_run_is_refused: a certificate
  re-posed with another focal length or principal point gains nothing from the model's allowance.
  Fixed since (issue 35): the registration builds its cameras at the principal point the data fix
  (stages.projective.principal_point), held to the returned reconstruction re-adjusted with one K,
  its principal point free; (-90, +70), (+150, -110) and (-150, +110) verify in the defaults and
  the full model (test_a_genuine_run_with_its_principal_point_off_centre_verifies).

Genuine results that verify (test_genuine_results_verify and the fixtures'; all with certificate
"full"): camera_model simple, varying, full; K known, with and without merge_components, and with
views of two image sizes (640x480 and 800x600); two image sizes with intrinsics ranges in the
simple, varying and full models, registration projective and incremental, and principal_point
per_view; principal_point auto, centre and per_view (each view's principal point shifted up to
15 px, 200 points; also with incremental registration); radial_distortion on and auto (pixels
distorted by k1 = -0.15, incremental registration, k1 -0.153 kept and stated) in the simple,
varying and full models and with K known; registration incremental in the three models;
bundle_adjustment false (simple and varying); detail brief; cancels in the adjustment stage (the
stop asked at the adjustment's first iterations: the stage "cancelled", no model stated, the
cameras "adjusted as far as the adjustment went"; or later, in the depth-reversal check: model
stated, the adjusted cameras kept) in the simple, varying, full, per-view and incremental runs (a
K-known run cancelled there certifies nothing and is refused as such, correctly); the job's clock
reaches the adjustment through the same report (run_control), so a cancel stands for it; the
depth-reversal twin adopted (pipeline.adjust_best made to return the adjusted mirror of its rig,
so that ambiguity.check adopts the twin's twin: a 6-view turntable at focal 3300) in the simple,
varying and full models (by hand: also the per-view scene with principal_point per_view, the
(+10, -5)-shifted scene with auto, and two image sizes in the varying model; there the test run on
the worse twin keeps no principal point, so adoption beside an estimated one was not reached); the same turntable with seeds 0 and 1 in every model, K known and
incremental; reconstruction points uncertified (L1L1, max_residual 20, max_nodes 1: all 40 points
node_limit with root regions; also brief, varying, and L2L2 with time_limit_s 0.01); triangulation
with one track uncertified (L1L1 max_nodes 1, with and without max_residual; L2L2 max_nodes 1;
brief); homography with two maps uncertified (L1L1 max_nodes 1; L2L1 max_nodes 2). Single-item
resection and homography jobs stopped by max_nodes or time_limit_s are refused as "no certified
item to check", as they should be. Real data (run by hand, not in this file, 5-7 s each): the
Oxford Model House's 672 tracks over 10 views (768x576, its VGG corners) in the simple, varying and
full models, with incremental registration, and with principal_point per_view: each verifies.

Tried and refused (correctly): the stage's model "fixed" with K unknown (the options ask for
"simple"); options.intrinsics.K set to the run's adjusted K with model "fixed", rehashed
(started_from 'linear' is not the calibrated start); a varying or full run restated simple with its
model kept (model is not the options'); a camera's stated K given skew 1e-3 or aspect 1 + 1e-7
with P kept (K [R | t] is not its P); one certified camera's P first row scaled by 1 + 5e-7 (not
the cameras the points are certified in); an uncertified map's region given reference_view 99 or
another member (its writer never writes it), lower of booleans, the scope with a trailing space,
tolerance_met true; an uncertified reconstruction point's reference_view another view, or the
map's words; a K-known run's options.intrinsics.K changed (focal 900, 800.001, or skew 5) and
rehashed ("the returned cameras' K is not the options' intrinsics/K"; a K-known run with
camera_model "full" or "varying", or principal_point per_view, genuinely adjusts "fixed" and
verifies); an uncertified track's reference_view the track's other view, or 0.0 for 0;
its scope dropping "with every residual <= 20.0". Accepted and harmless: an uncertified map's box
widened to +-1e300, or lower = upper, or its scope removed (states less; the box cannot be
checked without its proof).
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.solvers.reconstruction import synthetic
from geocert.formulations.reconstruction import calibration_tie
from geocert.verify.checks import verify_any
from tests.support import refused as _refused, searched_tracks_job, stage as _stage, verified as _verifies
from tests.verify.test_forgeries import rehash

K800 = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]
MIXED = [[640, 480]] * 4 + [[800, 600]] * 4
RANGES = {"focal": [240.0, 4000.0], "aspect": [0.95, 1.05], "skew": [-8.0, 8.0],
          "principal_point": [[160.0, 480.0], [120.0, 360.0]]}
PER_VIEW_SHIFT = np.random.default_rng(1).uniform(-15, 15, (8, 2))


def _scene_job(options: dict, points: int = 100, sizes=None, shift=None, k1: float = 0.0) -> dict:
    scene = synthetic.scene(views=8, points=points, seed=6, noise_px=0.3, spread_degrees=50.0)
    tracks = []
    for views, pixels in scene.tracks:
        pixels = np.asarray(pixels, dtype=float)
        if shift is not None:
            pixels = pixels + np.asarray(shift)[np.asarray(views)]
        if k1:
            n = (pixels - [320.0, 240.0]) / 800.0
            pixels = [320.0, 240.0] + 800.0 * n * (1 + k1 * (n ** 2).sum(1, keepdims=True))
        tracks.append({"views": [int(v) for v in views], "points": pixels.tolist()})
    return {"kind": "reconstruction", "options": {"certificate": "full", **options},
            "data": {"views": [{"image_size": s} for s in (sizes or [[640, 480]] * 8)], "tracks": tracks}}


def _example(name: str, data=None, **options) -> dict:
    kind = get_kind(name)
    return solve_job({**kind.example, **({"data": data} if data else {}),
                      "options": {**kind.example.get("options", {}), "certificate": "full", **options}})


@pytest.fixture(scope="module")
def runs() -> dict:
    """The default (simple), varying and full runs, each verifying."""
    out = {model: solve_job(_scene_job({} if model == "simple" else {"camera_model": model}))
           for model in ("simple", "varying", "full")}
    for model, result in out.items():
        assert _stage(result, "bundle_adjustment")["model"] == model
        _verifies(result)
    return out


@pytest.fixture(scope="module")
def maps_uncertified() -> dict:
    """The homography example's map, then twice it with 3 px noise on its targets, L1L1 max_nodes 1."""
    data = copy.deepcopy(get_kind("homography").example["data"])
    noisy = copy.deepcopy(data["maps"][0])
    target = np.asarray(noisy["target"], dtype=float)
    noisy["target"] = (target + np.random.default_rng(0).normal(0, 3.0, target.shape)).tolist()
    data["maps"] = [data["maps"][0], noisy, copy.deepcopy(noisy)]
    result = _example("homography", data=data, norm="L1L1", max_nodes=1)
    assert [m["certified"] for m in result["maps"]] == [True, False, False]
    assert result["maps"][1]["certificate"]["root_region"] is not None
    _verifies(result)
    return result


@pytest.fixture(scope="module")
def track_uncertified() -> dict:
    result = solve_job(searched_tracks_job(norm="L1L1", max_residual=20.0, max_nodes=1))
    assert [t["status"] for t in result["tracks"]] == ["optimal", "node_limit"]
    assert len(result["tracks"][1]["certificate"]["root_region"]["functionals"]) == 1
    _verifies(result)
    return result


# --- found --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("how", ["removed", "null"])
@pytest.mark.parametrize("model", ["varying", "full"])
def test_a_done_adjustment_without_its_model_is_refused(runs, model, how):
    forged = copy.deepcopy(runs[model])
    forged["certificate"]["options"].pop("camera_model")
    rehash(forged["certificate"])
    stage = _stage(forged, "bundle_adjustment")
    assert stage["status"] == "done"
    if how == "removed":
        stage.pop("model")
    else:
        stage["model"] = None
    _refused(forged)


@pytest.mark.parametrize("model", ["full", "varying"])
def test_a_simple_adjustment_restated_as_another_model_is_refused(runs, model):
    forged = copy.deepcopy(runs["simple"])
    forged["certificate"]["options"]["camera_model"] = model
    stage = _stage(forged, "bundle_adjustment")
    assert stage["principal_point"]["estimated"] is False
    stage["model"] = model
    rehash(forged["certificate"])
    _refused(forged)


def _set(member, value):
    return lambda region: region.update({member: value})


@pytest.fixture(scope="module")
def points_uncertified() -> dict:
    """The default scene's first 40 tracks under L1L1, max_residual 20, max_nodes 1: every point
    node_limit, each with a root region."""
    result = solve_job(_scene_job({"norm": "L1L1", "max_residual": 20.0, "max_nodes": 1}, points=40))
    assert not result["points"][0]["certified"] and result["points"][0]["certificate"]["root_region"]
    _verifies(result)
    return result


@pytest.mark.parametrize("edit", [lambda region: region.update(lower=[0.0] * (len(region["functionals"]) + 1),
                                                                upper=[1.0] * (len(region["functionals"]) + 1)),
                                  lambda region: region.update(functionals="anything")],
                         ids=["box an entry longer than its functionals", "functionals a string"])
def test_an_uncertified_points_region_chart_is_read(points_uncertified, edit):
    forged = copy.deepcopy(points_uncertified)
    edit(forged["points"][0]["certificate"]["root_region"])
    _refused(forged)


def test_an_uncertified_points_other_reference_view_is_refused(points_uncertified):
    forged = copy.deepcopy(points_uncertified)
    region = forged["points"][0]["certificate"]["root_region"]
    region["reference_view"] = 1 - region["reference_view"] if region["reference_view"] in (0, 1) else 0
    assert "its chart's reference view" in _refused(forged)["detail"]


@pytest.mark.parametrize("item, edit", [
    ("map", _set("functionals", "anything")),
    ("map", _set("reference_point", 999)),
    ("map", lambda region: region.update(denominator=[0.0] * len(region["denominator"]))),
    ("map", lambda region: region.update(lower=[0.0], upper=[1.0])),
    ("track", lambda region: region.update(lower=[0.0] * 5, upper=[1.0] * 5)),
    ("track", lambda region: region.update(functionals=[[0.0] * 4])),
], ids=["map functionals a string", "map reference_point 999", "map denominator 0", "map box of 1 entry",
        "track box of 5 entries", "track functionals 0"])
def test_an_uncertified_regions_chart_is_read(maps_uncertified, track_uncertified, item, edit):
    forged = copy.deepcopy(maps_uncertified if item == "map" else track_uncertified)
    edit(forged["maps" if item == "map" else "tracks"][1]["certificate"]["root_region"])
    _refused(forged)


SHIFTS = {"(+30, -20)": (30.0, -20.0), "(-30, +20)": (-30.0, 20.0), "(-60, +45)": (-60.0, 45.0)}
# Refused while the registration's cameras were built at the image's centre (issue 35): the
# pipeline's centred adjustment lay farther from the centred model's least-squares fit than the tie
# allowed (3,323 px^2 against 2,899 at (-90, +70); an observation 5.31 px from the re-adjusted
# reconstruction's image, 3.87 allowed, at (+150, -110); 6.21 against 3.84 at (-150, +110)).
FAR_SHIFTS = {"(-90, +70)": (-90.0, 70.0), "(+150, -110)": (150.0, -110.0), "(-150, +110)": (-150.0, 110.0)}


def _centred_registration(options: dict, shift) -> dict:
    """The run as the pipeline made it before it registered at the estimated principal point: the
    registration's cameras (the certificate's) built at the image's centre, with no principal-point
    record, and its problem_sha256 of the form written then (hashed_options' third form: today's
    form states the record wherever the registration tests it) (a stored result)."""
    from geocert.pipelines.reconstruction import pipeline
    from geocert.core.certificates import problem_hash
    from geocert.verify import hashed_options
    from geocert.verify.checks import checked_options

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(pipeline, "REGISTER_AT_PRINCIPAL_POINT", False)
        result = solve_job(_scene_job(options, points=200, shift=np.tile(shift, (8, 1))))
    document = result["certificate"]
    document["problem_sha256"] = problem_hash("reconstruction", document["data"],
                                              checked_options("reconstruction", document["options"]),
                                              hashed_options.THIRD_CLAIM_OPTIONS)
    return result


@pytest.mark.parametrize("shift", list(SHIFTS) + list(FAR_SHIFTS))
@pytest.mark.parametrize("options", [{}, {"camera_model": "full"}], ids=["defaults", "full"])
def test_a_genuine_run_with_its_principal_point_off_centre_verifies(options, shift):
    """The registration tests the principal point as the adjustment does, and builds its cameras
    (the certificate's) at the one the data fix (stages.projective.principal_point): the certificate
    fits the tracks as the returned cameras do, held to the returned reconstruction re-adjusted with
    one K (its principal point free, as the certificate's was; no allowance the returned cameras do
    not need), and the certified K's principal point is the scene's (320, 240) moved by the shift,
    to 3 px."""
    shifted = {**SHIFTS, **FAR_SHIFTS}[shift]
    result = solve_job(_scene_job(options, points=200, shift=np.tile(shifted, (8, 1))))
    report = _verifies(result)
    assert _stage(result, "projective")["principal_point"]["estimated"] is True
    tie = report.scope["calibration_tie"]
    assert tie["reference"] == calibration_tie.ONE_K_REFERENCE
    assert tie["shared_cost_px2"] <= 1.01 * tie["returned_cost_px2"]
    assert tie["model_cost_px2"] <= 1.01 * tie["returned_cost_px2"]
    certified = np.array(result["summary"]["calibration"]["certified_K"])
    assert np.hypot(*(certified[:2, 2] - np.add([320.0, 240.0], shifted))) < 3.0


@pytest.mark.parametrize("shift", list(SHIFTS))
@pytest.mark.parametrize("options", [{}, {"camera_model": "full"}], ids=["defaults", "full"])
def test_a_genuine_run_registered_at_the_centre_off_centre_verifies(options, shift):
    """A run whose registration built its cameras at the image's centre (as the pipeline did
    before; the returned cameras estimate the principal point, 36, 36 and 75 px off): the
    certificate is held to the returned reconstruction re-adjusted in its cameras' model, whose
    cost beyond the returned cameras' the scope states (model_cost_px2)."""
    result = _centred_registration(options, SHIFTS[shift])
    assert "principal_point" not in _stage(result, "projective")
    report = _verifies(result)
    tie = report.scope["calibration_tie"]
    assert tie["reference"] == calibration_tie.CENTRED_REFERENCE
    assert tie["model_cost_px2"] > 1.5 * tie["returned_cost_px2"]  # off the centre: the model costs that much more
    assert tie["shared_cost_px2"] <= tie["allowed_cost_px2"]


@pytest.fixture(scope="module")
def off_centre() -> dict:
    """The defaults' run on the (+30, -20)-shifted scene, registered at the image's centre
    (verifying: above)."""
    return _centred_registration({}, SHIFTS["(+30, -20)"])


def _reposed(result: dict, K: np.ndarray) -> dict:
    """The calibration certificate's data re-posed with K, as a forger would build it: every
    registered view's camera K [R | t] and every placed point adjusted to the result's
    observations with K held (bundle model "fixed"), from the returned poses and points; the
    certificate's views and tracks kept."""
    from geocert.solvers.reconstruction import bundle

    stage = _stage(result, "autocalibration")
    cameras = {c["view"]: c for c in result["cameras"] if c.get("registered")}
    column = {v: k for k, v in enumerate(sorted(cameras))}
    R = np.array([cameras[v]["R"] for v in sorted(cameras)], dtype=float)
    t = np.array([cameras[v]["t"] for v in sorted(cameras)], dtype=float)
    placed = [p for p in result["points"] if p.get("point") is not None]
    view, track, pixels = zip(*[(column[v], j, (u, w)) for j, p in enumerate(placed) for v, u, w in p["observations"]])
    K, R, t, X, _, _ = bundle.metric(np.asarray(K, dtype=float), R, t, np.array([p["point"] for p in placed]),
                                     np.array(view), np.array(track), np.array(pixels, dtype=float), model="fixed")
    row = {p["track"]: j for j, p in enumerate(placed)}
    return {**result["calibration_certificate"]["data"],
            "cameras": [(K @ np.c_[R[column[v]], t[column[v]]]).tolist() for v in stage["certificate_views"]],
            "points": [[*X[row[track]].tolist(), 1.0] for track in stage["certificate_tracks"]]}


@pytest.mark.parametrize("focal, where", [
    (1.15, "centre"), (0.85, "centre"), (1.0, "mirrored"), (1.0, "past the returned one")],
    ids=["focal 1.15x at the centre", "focal 0.85x at the centre", "principal point mirrored about the centre",
         "principal point 3x as far past the returned one"])
def test_a_certificate_reposed_with_another_K_beside_an_off_centre_run_is_refused(off_centre, focal, where):
    """The allowance for the certificate's centred model is what that model costs, measured, not
    a wider constant: a genuine calibration certificate (its autocalibration solved and verified)
    of the off-centre run's reconstruction re-posed with another K is refused, though each costs
    less than the (-60, +45) run's genuine certificate does relative to its returned cameras (6.85
    times): the returned focal length (800) scaled by 1.15 (5.3 times the returned cameras' cost;
    817 px^2 allowed, 1204 found) or 0.85 (8.0) with the principal point at the centre (the genuine
    certificate's model, 2.33 times), or the returned focal length with the principal point
    mirrored about the centre (36 px the other side: 6.5 times) or at the centre plus 3 times its
    offset (349, 220) - (319.5, 239.5) (6.3 times), held to the returned cameras (514 px^2)."""
    from tests.verify.test_calibration_tie import carrying

    K = np.array(next(c for c in off_centre["cameras"] if c.get("registered"))["K"], dtype=float)
    centre, returned = np.array([319.5, 239.5]), K[:2, 2].copy()
    K[0, 0] *= focal
    K[1, 1] *= focal
    K[:2, 2] = {"centre": centre, "mirrored": 2 * centre - returned,
                "past the returned one": centre + 3 * (returned - centre)}[where]
    report = verify_any(carrying(off_centre, _reposed(off_centre, K)))
    assert not report.valid
    # (refused by the fit test, or by the pixel test: the mirrored principal point lies 3.86 px from
    # the centred fit's images, 3.83 allowed since the floor is of the median coordinate: review 20)
    assert any(why in report.first_failure["detail"] for why in ("reconstruction of these tracks' observations",
                                                                 "it is not these tracks' reconstruction"))


@pytest.fixture(scope="module")
def at_principal_point() -> dict:
    """The defaults' run on the (-90, +70)-shifted scene: the registration's cameras built at the
    principal point the data fix (verifying: above)."""
    return solve_job(_scene_job({}, points=200, shift=np.tile(FAR_SHIFTS["(-90, +70)"], (8, 1))))


@pytest.mark.parametrize("focal, move", [(1.15, (0.0, 0.0)), (0.85, (0.0, 0.0)), (1.0, (60.0, 0.0)),
                                         (1.0, (0.0, -60.0)), (1.0, "mirrored")],
                         ids=["focal 1.15x", "focal 0.85x", "principal point 60 px right", "principal point 60 px up",
                              "principal point mirrored about the centre"])
def test_a_certificate_reposed_with_another_K_beside_a_run_registered_at_its_principal_point_is_refused(
        at_principal_point, focal, move):
    """The one-K model's allowance (its principal point free) is what its best fit costs beyond the
    returned cameras (nothing here): a genuine certificate of the run's reconstruction re-posed with
    the returned focal length scaled, or the principal point moved 60 px or mirrored about the
    image's centre, is refused."""
    from tests.verify.test_calibration_tie import carrying

    K = np.array(next(c for c in at_principal_point["cameras"] if c.get("registered"))["K"], dtype=float)
    K[0, 0] *= focal
    K[1, 1] *= focal
    K[:2, 2] = 2 * np.array([319.5, 239.5]) - K[:2, 2] if move == "mirrored" else K[:2, 2] + move
    report = verify_any(carrying(at_principal_point, _reposed(at_principal_point, K)))
    assert not report.valid
    assert any(why in report.first_failure["detail"] for why in ("reconstruction of these tracks' observations",
                                                                 "it is not these tracks' reconstruction"))


def test_the_one_K_model_is_the_solvers_own(off_centre):
    """centred_fit with the principal point free (no centres) and the pipeline's adjustment (bundle
    model "principal": one K, its principal point free) find the same cost on the off-centre
    scene's observations, from the returned cameras; below the centred model's, at the returned
    cameras' (which estimate the principal point, one for all here)."""
    from geocert.solvers.reconstruction import bundle
    from geocert.formulations.reconstruction import centred_fit

    cameras = [c for c in off_centre["cameras"] if c.get("registered")]
    placed = [p for p in off_centre["points"] if p.get("point") is not None]
    column = {c["view"]: k for k, c in enumerate(cameras)}
    view, point, pixels = (np.array(a) for a in zip(*[(column[v], j, (u, w)) for j, p in enumerate(placed)
                                                     for v, u, w in p["observations"]]))
    X = np.array([[*p["point"], 1.0] for p in placed])
    P = np.array([c["P"] for c in cameras])
    free = float(np.sum(np.square(centred_fit.fit(P, None, X, view, point, pixels) - pixels)))
    centred = float(np.sum(np.square(centred_fit.fit(P, np.tile([319.5, 239.5], (len(cameras), 1)), X, view, point,
                                                     pixels) - pixels)))
    *_, r, _ = bundle.metric(np.array(cameras[0]["K"]), np.array([c["R"] for c in cameras]),
                             np.array([c["t"] for c in cameras]), X[:, :3], view, point, pixels.astype(float),
                             model="principal")
    assert free == pytest.approx(float(np.sum(np.square(r))), rel=1e-3)
    assert free == pytest.approx(sum(p["cost"] for p in placed), rel=1e-3)
    assert free < centred / 2


@pytest.mark.parametrize("edit", [{"chi2": 1.0}, {"inside_middle_half": False}, {"threshold": 0.0}],
                         ids=["chi2 below the threshold", "outside the middle half", "threshold 0"])
def test_a_registration_principal_point_test_that_does_not_pass_is_refused(at_principal_point, edit):
    forged = copy.deepcopy(at_principal_point)
    _stage(forged, "projective")["principal_point"].update(edit)
    assert "stages/projective/principal_point/estimated is true" in _refused(forged)["detail"]


@pytest.mark.parametrize("edit, words", [({"observations": -5}, "principal_point/observations"),
                                         ({"observations": 10 ** 9}, "a count of at most"),
                                         ({"observations": "1600"}, "principal_point/observations"),
                                         ({"chi2": True}, "principal_point/chi2"),
                                         ({"threshold": -1.0}, "principal_point/threshold")],
                         ids=["observations negative", "observations beyond tracks times views",
                              "observations a string", "chi2 a boolean", "threshold negative"])
def test_the_registration_principal_point_records_figures_are_of_their_types(at_principal_point, edit, words):
    """The record's figures are checked as the adjustment's own are (FIGURES, the counts' bound):
    the record was new, and its numbers went unread by the type checks."""
    forged = copy.deepcopy(at_principal_point)
    _stage(forged, "projective")["principal_point"].update(edit)
    assert words in _refused(forged)["detail"]


@pytest.mark.parametrize("limit, value", [("ITERATIONS", 1), ("MAX_VIEWS", 7), ("MAX_PAIRS", 100)],
                         ids=["not converged", "beyond the views bound", "beyond the pairs bound"])
def test_a_centred_fit_not_converged_or_too_large_is_not_used(off_centre, monkeypatch, limit, value):
    """The centred model's cost widens the tie only when the verifier's fit of it converged (an
    unconverged fit's cost overstates the model's) and within its cost bound: otherwise the
    certificate is held to the returned cameras, as before the fit, and the off-centre run is
    refused again (stricter, never looser)."""
    from geocert.formulations.reconstruction import centred_fit

    monkeypatch.setattr(centred_fit, limit, value)
    assert "reconstruction of these tracks' observations" in _refused(off_centre)["detail"]


def test_the_centred_model_is_the_solvers_own(off_centre):
    """centred_fit (numpy, read by the verifier) and the pipeline's adjustment (bundle model
    "simple", the principal point held at the centre) find the same cost on the off-centre scene's
    observations, from the returned cameras (which have the principal point at (349, 220))."""
    from geocert.solvers.reconstruction import bundle
    from geocert.formulations.reconstruction import centred_fit

    cameras = [c for c in off_centre["cameras"] if c.get("registered")]
    placed = [p for p in off_centre["points"] if p.get("point") is not None]
    column = {c["view"]: k for k, c in enumerate(cameras)}
    view, point, pixels = (np.array(a) for a in zip(*[(column[v], j, (u, w)) for j, p in enumerate(placed)
                                                     for v, u, w in p["observations"]]))
    X = np.array([[*p["point"], 1.0] for p in placed])
    images = centred_fit.fit(np.array([c["P"] for c in cameras]), np.tile([319.5, 239.5], (len(cameras), 1)), X,
                             view, point, pixels)
    verifier = float(np.sum(np.square(images - pixels)))
    K = np.array(cameras[0]["K"])
    K[:2, 2] = [319.5, 239.5]
    *_, r, _ = bundle.metric(K, np.array([c["R"] for c in cameras]), np.array([c["t"] for c in cameras]), X[:, :3],
                             view, point, pixels.astype(float), model="simple")
    solver = float(np.sum(np.square(r)))
    assert verifier == pytest.approx(solver, rel=1e-3)
    returned = sum(p["cost"] for p in placed)  # L2L2: each point's cost in the returned cameras
    assert verifier > 2 * returned


@pytest.mark.parametrize("member, value", [("leaves", -5), ("leaves", "many"), ("tolerance", "x")])
def test_an_uncertified_summarys_typed_members_are_read(track_uncertified, member, value):
    forged = copy.deepcopy(track_uncertified)
    forged["tracks"][1]["certificate"][member] = value
    _refused(forged)


def test_a_certified_summarys_leaves_are_read(track_uncertified):
    forged = copy.deepcopy(track_uncertified)
    forged["tracks"][0]["certificate"]["leaves"] = -5
    assert "its proof has" in _refused(forged)["detail"]


# --- genuine results that verify ------------------------------------------------------------------------

GENUINE = {
    "K known": ({"intrinsics": {"K": K800}}, {}),
    "K known, camera_model full (adjusted fixed)": ({"intrinsics": {"K": K800}, "camera_model": "full"}, {}),
    "K known, merge_components": ({"intrinsics": {"K": K800}, "merge_components": True}, {}),
    "K known, two image sizes": ({"intrinsics": {"K": K800}}, {"sizes": MIXED}),
    "two sizes, simple": ({"intrinsics": RANGES}, {"sizes": MIXED}),
    "two sizes, varying": ({"intrinsics": RANGES, "camera_model": "varying"}, {"sizes": MIXED}),
    "two sizes, full": ({"intrinsics": RANGES, "camera_model": "full"}, {"sizes": MIXED}),
    "two sizes, incremental varying": ({"intrinsics": RANGES, "camera_model": "varying",
                                        "registration": "incremental"}, {"sizes": MIXED}),
    "two sizes, per_view": ({"intrinsics": RANGES, "principal_point": "per_view"}, {"sizes": MIXED}),
    "principal_point centre": ({"principal_point": "centre"}, {}),
    "per_view": ({"principal_point": "per_view"}, {"points": 200, "shift": PER_VIEW_SHIFT}),
    "per_view incremental": ({"principal_point": "per_view", "registration": "incremental"},
                             {"points": 200, "shift": PER_VIEW_SHIFT}),
    "radial on, varying": ({"radial_distortion": "on", "registration": "incremental", "camera_model": "varying"},
                           {"points": 200, "k1": -0.15}),
    "radial auto, full": ({"radial_distortion": "auto", "registration": "incremental", "camera_model": "full"},
                          {"points": 200, "k1": -0.15}),
    "radial on, K known": ({"radial_distortion": "on", "intrinsics": {"K": K800}}, {"points": 200, "k1": -0.15}),
    "incremental full": ({"registration": "incremental", "camera_model": "full"}, {}),
    "no adjustment, varying": ({"bundle_adjustment": False, "camera_model": "varying"}, {}),
    "brief": ({"detail": "brief"}, {}),
    "uncertified points, varying": ({"norm": "L1L1", "max_residual": 20.0, "max_nodes": 1, "camera_model": "varying"},
                                    {"points": 40}),
}


@pytest.mark.parametrize("name", list(GENUINE))
def test_genuine_results_verify(name):
    options, scene = GENUINE[name]
    result = solve_job(_scene_job(options, **scene))
    if "k1" in scene and options.get("registration") == "incremental":  # the radial term is the incremental registration's
        assert result["summary"]["distortion"]["k1"] != 0.0
    _verifies(result)


@pytest.mark.parametrize("model", ["varying", "full"])
@pytest.mark.parametrize("after", [0, 40], ids=["at its first iteration", "later (here: in the depth-reversal check)"])
def test_a_cancel_in_the_adjustment_verifies(model, after):
    seen, calls = [], []

    def sink(event):
        if "bundle_adjustment" in json.dumps(event):
            seen.append(1)

    def stop():
        if seen:
            calls.append(1)
            return len(calls) > after
        return False

    result = solve_job(_scene_job({"camera_model": model}), sink=sink, should_stop=stop)
    stage = _stage(result, "bundle_adjustment")
    assert stage["status"] == "cancelled"
    if after == 0:  # stopped inside the adjustment: no model stated (how far 40 asks go depends on the run)
        assert stage.get("model") is None
    _verifies(result)


@pytest.mark.parametrize("model", ["simple", "varying", "full"])
def test_the_depth_reversal_twin_adopted_verifies(monkeypatch, model):
    from geocert.pipelines.reconstruction import pipeline
    from geocert.solvers.reconstruction import upgrade
    from geocert.formulations.reconstruction import depth_reversal
    from tests.solvers.reconstruction.test_reconstruction_long_lens import dino_like

    adjust_best = pipeline.adjust_best

    def mirrored(starts, obs, keep, threshold_px, model, should_stop=None):
        name, metric, keep, before, trials = adjust_best(starts, obs, keep, threshold_px, model, should_stop)
        twin, keep, _ = upgrade.adjust(depth_reversal.mirrored(metric, reference=0), obs.view, obs.track, obs.pixel,
                                       threshold_px, model=model)
        return name, twin, keep, before, trials

    monkeypatch.setattr(pipeline, "adjust_best", mirrored)
    scene = dino_like(3300.0, 20.0, 0.3, 0)
    result = solve_job({"kind": "reconstruction",
                        "options": {"certificate": "full", **({} if model == "simple" else {"camera_model": model})},
                        "data": {"views": [{"image_size": list(scene.image_size)}] * 6,
                                 "tracks": [{"views": [int(v) for v in views], "points": np.asarray(p).tolist()}
                                            for views, p in scene.tracks]}})
    assert result["summary"]["depth_reversal"]["adopted"] is True
    _verifies(result)


# --- refused, correctly ---------------------------------------------------------------------------------

def test_a_fixed_model_where_k_is_unknown_is_refused(runs):
    forged = copy.deepcopy(runs["simple"])
    _stage(forged, "bundle_adjustment")["model"] = "fixed"
    assert "options ask for 'simple'" in _refused(forged)["detail"]
    forged["certificate"]["options"]["intrinsics"] = {"K": _stage(forged, "bundle_adjustment")["K"]}
    rehash(forged["certificate"])
    assert "started_from" in _refused(forged)["detail"]


@pytest.mark.parametrize("model", ["varying", "full"])
def test_another_model_restated_simple_with_its_model_kept_is_refused(runs, model):
    forged = copy.deepcopy(runs[model])
    forged["certificate"]["options"].pop("camera_model")
    rehash(forged["certificate"])
    assert "options ask for 'simple'" in _refused(forged)["detail"]


@pytest.mark.parametrize("edit", [
    lambda camera: camera["K"][0].__setitem__(1, camera["K"][0][1] + 1e-3),
    lambda camera: camera["K"][1].__setitem__(1, camera["K"][1][1] * (1 + 1e-7)),
], ids=["skew 1e-3", "aspect 1e-7"])
def test_a_stated_k_edited_with_p_kept_is_refused(runs, edit):
    forged = copy.deepcopy(runs["simple"])
    edit(next(camera for camera in forged["cameras"] if camera["registered"]))
    assert "is not its P" in _refused(forged)["detail"]


def test_a_certified_cameras_focal_moved_within_1e_6_is_refused(runs):
    forged = copy.deepcopy(runs["simple"])
    camera = next(camera for camera in forged["cameras"] if camera["registered"] and camera["certified"])
    P = np.asarray(camera["P"])
    P[0] *= 1 + 5e-7
    camera["P"] = P.tolist()
    assert "not the cameras returned" in _refused(forged)["detail"]


@pytest.mark.parametrize("edit, words", [
    (lambda s: s["root_region"].update(reference_view=99), "never writes"),
    (lambda s: s.update(scope=s["scope"] + " "), "the scope its proof covers"),
    (lambda s: s["root_region"].update(lower=[True] * len(s["root_region"]["lower"])), "finite numbers"),
], ids=["reference_view on a map", "scope trailing space", "boolean lower"])
def test_edited_uncertified_map_summaries_are_refused(maps_uncertified, edit, words):
    forged = copy.deepcopy(maps_uncertified)
    edit(forged["maps"][1]["certificate"])
    assert words in _refused(forged)["detail"]


def test_an_uncertified_tracks_other_view_is_refused(track_uncertified):
    forged = copy.deepcopy(track_uncertified)
    region = forged["tracks"][1]["certificate"]["root_region"]
    region["reference_view"] = 1 - region["reference_view"]
    assert "its chart's reference view" in _refused(forged)["detail"]
