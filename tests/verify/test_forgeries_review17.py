"""A seventeenth hostile review of the verifier (issue 33), aimed at what landed since review 16: a
reconstruction's problem_sha256 covering camera_model and principal_point (the second form's scope
stating them), a root region's ``meaning`` limited to the solver's words (today's, or the earlier
ones with the report's scope naming the items), and, beside them, a job cancelled before it
started, the metric stage's proven intervals and the direct method's programs. Forgeries start
from genuine solves (the kinds' examples; synthetic reconstruction scenes) and are edited as a
forger would, rehashed where an edit touches what the hashes cover.

Found (each verified, stating something false; fixed after the review, each test failing on the code
before):

- An uncertified item's summary is read for its tolerance_met only
  (test_an_uncertified_items_root_region_and_scope_are_read): a triangulation track restated
  uncertified (its claim too, the job's stats to match) keeps a summary whose root_region says
  "for every point X of space", with lower 5 above upper -5 (an empty box: no point of the scope
  could cost less than the cap) and reference_view 99 of a 2-view track, beside scope "every point
  of space": it verifies. The solver writes such a summary for a search that met its tolerance and
  did not certify (documents.certificate_summary), in TRACK_REGION_MEANING's words; review 16's fix
  reads the words of certified items only (fractional._check_root_region returns when the claim is not
  certified, checks._check_summaries reads only tolerance_met there). The box itself cannot be
  checked without its proof, but the words, the reference view and lower <= upper can, and the
  scope words as for a certified item's.
- options.camera_model is tied to nothing it chooses
  (test_a_camera_model_restated_beside_a_simple_adjustment_is_refused): the per-view run (camera
  model "simple", principal_point per_view) with options.camera_model "varying" or "full",
  rehashed in the current form, verifies, its adjustment stage still saying model "simple" and its
  per-view record "estimated" (which the pipeline runs only in the simple model). The hash now
  covers the option, so a user hashing a request for camera_model "varying" finds a match with a
  document whose adjustment ran another model. The adjustment's model is the option's (or "fixed"
  with K given: reconstruction_members' comment) and could be checked so.
- The models other than "simple" are tied to no camera
  (test_a_simple_per_view_run_restated_as_another_model_is_refused): the same run with
  options.camera_model and the adjustment's model both "varying" (one focal length per view, the
  principal point at the image centre: pipeline.py) or "full" (one K, all five entries free), its
  two principal point records dropped, rehashed: verifies, while every returned P shares one focal
  length and has a principal point of its own up to 15 px off the centre. The cameras' tolerances
  are read off P (review 16), so each certified camera's claim holds; what is false is the model
  the stage says it adjusted, and the request the hash matches. _check_principal_points_per_view
  returns for any model but "simple"; "varying" could require P's principal points at the image
  centre, "full" (and "simple") one K.

Fixed after the review: an uncertified item's root region states the solver's words, a box with
lower <= upper and its chart's reference view, and its scope the search's words
(fractional._uncertified_region, _check_scope_words); the adjustment's model is the one the options ask
for, and the cameras returned have its calibration (reconstruction_members._check_adjustment_model:
one K for "fixed" and "full"; square pixels, no skew and one principal point for "varying"; one
focal length too for "simple", a principal point per view only as its test says).

Tried and refused (or accepted with the claim still true):

- Hash forms (the per-view run: 200 points, 8 views, each view's principal point shifted up to
  15 px): rehashed into the second form as it is, it verifies, the scope stating "camera_model
  'simple'; principal_point 'per_view' (not its default)"; there with principal_point removed
  (read as "auto") or "centre": refused (the per-view record needs per_view); camera_model
  "varying" or "full" with the adjustment's model the same and the per-view record dropped: refused
  in either form (the shared principal point record says estimated, in the simple model only).
  Rehashed into the earliest form it verifies, the scope stating both options.
- Root region words (an L1L1 reconstruction, max_residual 20, 30 points each searched; the
  triangulation and homography examples, L1L1): the map's earlier or current words on a track, a
  track's earlier words on a map, the earlier words with a trailing space or a no-break space,
  the meaning removed or null: refused. The earlier words on every point (30) or every other one
  (15) verify, the scope naming the first five and "and 25 more" (its length bounded); on both
  triangulation tracks and on the homography's map: verify, the scope naming them. The region's
  key removed or the summary null: verifies, stating nothing. A region stated where the proof
  searched nothing was refused in review 16 and still is: the earlier words on the convexity-
  certified track of the L2L2 example are refused. A brief result (no summaries) given a summary
  in the earlier words verifies, the scope naming the track; with its box's upper doubled, refused.
- A job cancelled before it started (cancelled_item): with method "direct" it states one "direct"
  stage, with "stratified" the two; each is refused ("no certified item to check"), as nothing is
  certified.
- The metric stage's proven intervals (the autocalibration example): focal_x widened to
  [500, 2000], [-1e6, 2000] or [-1e300, 1e300] in both the proof's sublevel and the result's
  proven_intervals verifies (a weaker true statement: every K costing that little has a focal
  length in it); widened in only one of them: refused ("not its proof's sublevel"); bounds
  swapped: refused (narrower than proven); NaN or Infinity: refused (format).
- The direct method's programs (the example, method direct: one program, chirality "centers"):
  the program stated twice, or a second one with z all 0 (refused: one program or a split's
  leaves), its delta true (refused: no orientation), order 3 (refused), moment_rank 1 with
  eigenvalue_ratio 0 (refused: not the stage's). A program's ``bound`` set to 1e300 verifies: it is
  informational, the bound being recomputed from z (direct.check_proof), as the summaries' notes are.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.core.certificates import problem_hash
from geocert.verify import fractional as items
from geocert.solvers.reconstruction import synthetic
from geocert.verify import hashed_options
from geocert.verify.checks import verify_any
from tests.support import refused as _refused, searched_tracks_job, stage as _stage, verified as _verifies
from tests.verify.test_forgeries import rehash, uncertify

VIEWS = 8


def _example(name: str, **options) -> dict:
    kind = get_kind(name)
    return solve_job({**kind.example, "options": {**kind.example.get("options", {}), "certificate": "full", **options}})


@pytest.fixture(scope="module")
def triangulation_l1() -> dict:
    """SEARCHED_TRACKS under L1L1 with max_residual 20: both tracks searched."""
    result = solve_job(searched_tracks_job(norm="L1L1", max_residual=20.0))
    assert all(track["certified"] and track["certificate"]["root_region"] for track in result["tracks"])
    _verifies(result)
    return result


@pytest.fixture(scope="module")
def per_view() -> dict:
    """Review 16's per-view scene: each view's principal point moved by up to 15 px."""
    scene = synthetic.scene(views=VIEWS, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
    shift = np.random.default_rng(1).uniform(-15, 15, (VIEWS, 2))
    result = solve_job({"kind": "reconstruction", "options": {"certificate": "full", "principal_point": "per_view"},
                        "data": {"views": [{"image_size": list(scene.image_size)}] * VIEWS,
                                 "tracks": [{"views": [int(v) for v in views],
                                             "points": (pixels + shift[np.asarray(views)]).tolist()}
                                            for views, pixels in scene.tracks]}})
    adjustment = _stage(result, "bundle_adjustment")
    assert adjustment["model"] == "simple" and adjustment["principal_point_per_view"]["estimated"] is True
    assert result["certificate"]["options"]["camera_model"] == "simple"
    _verifies(result)
    return result


# --- found --------------------------------------------------------------------------------------------

def test_an_uncertified_items_root_region_and_scope_are_read(triangulation_l1):
    forged = copy.deepcopy(triangulation_l1)
    track, claim = forged["tracks"][1], forged["certificate"]["items"][1]
    uncertify(claim)
    claim.pop("proof", None)
    track.update(certified=False, status="not_certified", lower_bound=None, gap=None)
    summary = track["certificate"]
    summary["tolerance_met"] = False
    size = len(summary["root_region"]["lower"])
    summary["root_region"].update(meaning="lower <= (F X) / (d . X) <= upper for every point X of space",
                                  lower=[5.0] * size, upper=[-5.0] * size, reference_view=99)
    summary["scope"] = "every point of space"
    forged["stats"].update(certified=1, statuses={"optimal": 1, "not_certified": 1})
    assert "tracks/1/certificate" in _refused(forged)["detail"]


@pytest.mark.parametrize("model", ["varying", "full"])
def test_a_camera_model_restated_beside_a_simple_adjustment_is_refused(per_view, model):
    forged = copy.deepcopy(per_view)
    forged["certificate"]["options"]["camera_model"] = model
    assert "problem_sha256" in _refused(copy.deepcopy(forged))["detail"]  # the hash covers it
    rehash(forged["certificate"])
    assert "camera_model" in _refused(forged)["detail"]



@pytest.mark.parametrize("model", ["varying", "full"])
def test_a_simple_per_view_run_restated_as_another_model_is_refused(per_view, model):
    forged = copy.deepcopy(per_view)
    forged["certificate"]["options"]["camera_model"] = model
    adjustment = _stage(forged, "bundle_adjustment")
    adjustment["model"] = model
    adjustment.pop("principal_point_per_view")
    adjustment.pop("principal_point")
    rehash(forged["certificate"])
    assert "bundle_adjustment" in _refused(forged)["detail"]


# --- refused, or accepted with the claim true -----------------------------------------------------------

def _second_form(result: dict) -> dict:
    certificate = result["certificate"]
    certificate["problem_sha256"] = problem_hash("reconstruction", certificate["data"], certificate["options"],
                                                 hashed_options.SECOND_CLAIM_OPTIONS)
    return result


class TestHashForms:
    def test_the_second_form_states_the_camera_model_and_principal_point(self, per_view):
        scope = _verifies(_second_form(copy.deepcopy(per_view))).scope["problem_sha256"]
        assert scope.startswith("the second form")
        assert "camera_model 'simple'; principal_point 'per_view' (not its default)" in scope

    @pytest.mark.parametrize("value", [None, "centre"], ids=["removed", "centre"])
    def test_another_principal_point_in_the_second_form_is_refused(self, per_view, value):
        forged = copy.deepcopy(per_view)
        if value is None:
            forged["certificate"]["options"].pop("principal_point")
        else:
            forged["certificate"]["options"]["principal_point"] = value
        assert "principal_point_per_view" in _refused(_second_form(forged))["detail"]

    @pytest.mark.parametrize("second", [False, True], ids=["current form", "second form"])
    @pytest.mark.parametrize("model", ["varying", "full"])
    def test_the_camera_model_restated_with_the_adjustment_is_refused(self, per_view, model, second):
        forged = copy.deepcopy(per_view)
        forged["certificate"]["options"]["camera_model"] = model
        adjustment = _stage(forged, "bundle_adjustment")
        adjustment["model"] = model
        adjustment.pop("principal_point_per_view")
        _second_form(forged) if second else rehash(forged["certificate"])
        assert "principal_point" in _refused(forged)["detail"]


class TestRootRegionWords:
    @pytest.mark.parametrize("meaning", [
        items.MAP_REGION_MEANING_EARLIER, items.MAP_REGION_MEANING, items.TRACK_REGION_MEANING_EARLIER + " ",
        items.TRACK_REGION_MEANING_EARLIER.replace(" ", "\u00a0", 1), None, "missing",
    ], ids=["map earlier", "map current", "trailing space", "no-break space", "null", "missing"])
    def test_other_words_on_a_track_are_refused(self, triangulation_l1, meaning):
        forged = copy.deepcopy(triangulation_l1)
        region = forged["tracks"][0]["certificate"]["root_region"]
        if meaning == "missing":
            region.pop("meaning")
        else:
            region["meaning"] = meaning
        assert "tracks/0/certificate/root_region/meaning" in _refused(forged)["detail"]

    def test_a_tracks_words_on_a_map_are_refused(self):
        forged = _example("homography", norm="L1L1", max_residual=20.0)
        forged["maps"][0]["certificate"]["root_region"]["meaning"] = items.TRACK_REGION_MEANING_EARLIER
        assert "maps/0/certificate/root_region/meaning" in _refused(forged)["detail"]

    def test_earlier_words_on_a_map_are_said(self):
        result = _example("homography", norm="L1L1", max_residual=20.0)
        result["maps"][0]["certificate"]["root_region"]["meaning"] = items.MAP_REGION_MEANING_EARLIER
        said = _verifies(result).scope["root_region"]
        assert said.startswith("the root_region of maps/0 states the earlier words")

    def test_earlier_words_on_every_track_are_said(self, triangulation_l1):
        result = copy.deepcopy(triangulation_l1)
        for track in result["tracks"]:
            track["certificate"]["root_region"]["meaning"] = items.TRACK_REGION_MEANING_EARLIER
        said = _verifies(result).scope["root_region"]
        assert said.startswith("the root_region of tracks/0, tracks/1 states the earlier words")
        assert "not every one of the scope" in said

    def test_many_earlier_words_keep_the_scope_short(self):
        from geocert.verify.fractional import earlier_words_scope

        said = earlier_words_scope([f"points/{i}" for i in range(10_000)])["root_region"]
        assert "points/0, points/1, points/2, points/3, points/4 and 9995 more" in said and len(said) < 400


class TestCancelledBeforeStart:
    @pytest.mark.parametrize("method, stages", [("direct", ["direct"]), ("stratified", ["affine", "metric"])])
    def test_a_job_cancelled_before_it_started_states_its_methods_stages_and_certifies_nothing(self, method, stages):
        kind = get_kind("autocalibration")
        result = solve_job({**kind.example, "options": {**kind.example.get("options", {}), "certificate": "full",
                                                        "method": method}}, should_stop=lambda: True)
        assert [(s["name"], s["status"]) for s in result["stages"]] == [(name, "cancelled") for name in stages]
        assert _refused(result)["detail"] == "no certified item to check"


@pytest.fixture(scope="module")
def autocalibration() -> dict:
    result = _example("autocalibration")
    assert _stage(result, "metric")["determinacy"]["proven_intervals"] is not None
    _verifies(result)
    return result


def _widen(result: dict, bounds, proof: bool = True, returned: bool = True) -> dict:
    forged = copy.deepcopy(result)
    if proof:
        forged["certificate"]["items"][1]["proof"]["sublevel"]["intervals"][0] = list(bounds)
    if returned:
        interval = _stage(forged, "metric")["determinacy"]["proven_intervals"]["intervals"][0]
        assert interval["name"] == "focal_x"
        interval.update(lower=bounds[0], upper=bounds[1])
    return forged


class TestProvenIntervals:
    @pytest.mark.parametrize("bounds", [(500.0, 2000.0), (-1e6, 2000.0), (-1e300, 1e300)])
    def test_widened_in_both_verifies(self, autocalibration, bounds):
        _verifies(_widen(autocalibration, bounds))

    @pytest.mark.parametrize("where", ["proof", "returned"])
    def test_widened_in_one_is_refused(self, autocalibration, where):
        forged = _widen(autocalibration, (500.0, 2000.0), proof=where == "proof", returned=where == "returned")
        assert "not its proof's sublevel" in _refused(forged)["detail"]

    def test_swapped_bounds_are_refused(self, autocalibration):
        lower, upper = autocalibration["certificate"]["items"][1]["proof"]["sublevel"]["intervals"][0]
        assert "narrower than what its leaves prove" in _refused(_widen(autocalibration, (upper, lower)))["detail"]

    @pytest.mark.parametrize("bound", [float("nan"), float("inf")])
    def test_non_finite_bounds_are_refused(self, autocalibration, bound):
        report = verify_any(json.loads(json.dumps(_widen(autocalibration, (999.0, bound)))))
        assert not report.valid and "finite" in report.first_failure["detail"]


class TestRootRegionWhereStated:
    def test_a_brief_result_given_a_summary_in_the_earlier_words_is_said(self, triangulation_l1):
        brief = solve_job(searched_tracks_job(norm="L1L1", max_residual=20.0, detail="brief"))
        assert brief["tracks"][0]["certificate"] is None
        summary = copy.deepcopy(triangulation_l1["tracks"][0]["certificate"])
        summary.pop("proof", None)
        summary["root_region"]["meaning"] = items.TRACK_REGION_MEANING_EARLIER
        brief["tracks"][0]["certificate"] = summary
        assert _verifies(brief).scope["root_region"].startswith("the root_region of tracks/0 states the earlier")
        summary["root_region"]["upper"] = [2 * value for value in summary["root_region"]["upper"]]
        assert "not its proof's root box" in _refused(brief)["detail"]

    def test_earlier_words_where_no_search_ran_are_refused(self):
        result = solve_job(searched_tracks_job())  # L2L2: track 0 certified by convexity, track 1 searched
        assert result["certificate"]["items"][0]["proof"]["type"] == "convexity"
        region = copy.deepcopy(result["tracks"][1]["certificate"]["root_region"])
        region["meaning"] = items.TRACK_REGION_MEANING_EARLIER
        result["tracks"][0]["certificate"]["root_region"] = region
        assert "its proof searched no box" in _refused(result)["detail"]


def test_the_earliest_form_states_the_camera_options(per_view):
    forged = rehash(copy.deepcopy(per_view)["certificate"], earlier=True)
    result = {**copy.deepcopy(per_view), "certificate": forged}
    scope = _verifies(result).scope["problem_sha256"]
    assert scope.startswith("the earlier form") and "principal_point 'per_view' (not its default)" in scope


@pytest.fixture(scope="module")
def direct() -> dict:
    result = _example("autocalibration", method="direct")
    assert [program.get("delta") for program in result["certificate"]["items"][0]["proof"]["programs"]] == [None]
    _verifies(result)
    return result


class TestDirectPrograms:
    @pytest.mark.parametrize("edit, words", [
        (lambda proof: proof["programs"].append(copy.deepcopy(proof["programs"][0])), "needs one program"),
        (lambda proof: proof["programs"].append({**proof["programs"][0], "z": [0.0] * len(proof["programs"][0]["z"])}),
         "needs one program"),
        (lambda proof: proof["programs"][0].update(delta=True), "not an orientation left to bound"),
        (lambda proof: proof.update(order=3), "relaxation order 3"),
        (lambda proof: proof.update(moment_rank=1, eigenvalue_ratio=0.0), "eigenvalue_ratio"),
    ], ids=["program twice", "a second program of z 0", "delta true", "order 3", "ratio 0"])
    def test_edited_programs_are_refused(self, direct, edit, words):
        forged = copy.deepcopy(direct)
        edit(forged["certificate"]["items"][0]["proof"])
        assert words in _refused(forged)["detail"]

    def test_a_programs_stated_bound_above_its_proven_one_is_refused(self, direct):
        """Informational once (its value unread); since review 41 a recorded bound is at most the
        one its vector proves (proofs.check_recorded_bound): a record of 1e300 is refused."""
        forged = copy.deepcopy(direct)
        forged["certificate"]["items"][0]["proof"]["programs"][0]["bound"] = 1e300
        report = verify_any(json.loads(json.dumps(forged)))
        assert not report.valid and report.first_failure["check"] == "leaf_bounds", report.first_failure
