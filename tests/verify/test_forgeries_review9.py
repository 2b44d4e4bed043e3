"""A ninth hostile review of the verifier (issue 33), aimed at what the eighth review's round
added: the resection's proven centre intervals (fractional.resection_sublevel), the triangulation's
intervals raised to the pooled level, the depth-reversal record, camera_misfit's bound_reason, the
maps' time_limit statuses, and floating-point hygiene wherever a document-chosen number scales a
bound. Each class is built from genuine solver output (geocert.jobs.runner.solve_job) or a genuine
stored certificate (tests/data/certificates); each test of the sound outcome xfails (strict) while
the verifier accepts the forgery, and beside it the genuine document it starts from verifies. Each
class's docstring says what is accepted, how false it is (measured), and a suggested fix."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from tests.verify.test_forgeries_review5 import XFAIL, _valid
from tests.verify.test_forgeries_review7 import ambiguous_rig  # noqa: F401 (a fixture: the nearly affine turntable)

# --- a resection's proven interval at a level the document chooses ------------------------------

# The forged levels (squared pixels): 0 (the cameras costing no more than the returned one) and
# a thousandth of a squared pixel, each about 10^4 times or more below the camera's own level.
FORGED_LEVELS = (0.0, 1e-3)


@pytest.fixture(scope="module")
def proven_resection() -> tuple[np.ndarray, dict]:
    """(the true camera centre, the genuine full result of one 25-point L2L2 resection with 1 px
    of noise, certified with a proven interval of its centre)."""
    from geocert.jobs.runner import solve_job
    from tests.formulations.fractional.test_resection_proven import resection_job
    from tests.support import seed

    rng = np.random.default_rng(seed("resection proven", "forged"))
    job, (truth,) = resection_job(rng, 25, 1.0)
    result = solve_job(job)
    item = result["maps"][0]
    assert item["certified"] and item["determinacy"]["proven"] is True
    return truth, result


def _map_proven_at(result: dict, level: float) -> dict:
    """``result`` with its map's proven interval proven again, genuinely (resection_sublevel: the
    enclosure test and the rounds pass), at cost increase ``level``: the proof's sublevel, the
    determinacy's proven_intervals and the determinacy's own cost_increase all restated."""
    from geocert.formulations.fractional.determinacy import proven_map
    from geocert.formulations.fractional.resection_sublevel import resection_sublevel

    forged = copy.deepcopy(result)
    data = forged["certificate"]["data"]["maps"][0]
    claim = forged["certificate"]["items"][0]
    sublevel = resection_sublevel(np.asarray(data["source"], dtype=float), np.asarray(data["target"], dtype=float),
                                  np.asarray(claim["matrix"], dtype=float), level)
    assert sublevel is not None
    claim["proof"]["sublevel"] = sublevel
    determinacy = forged["maps"][0]["determinacy"]
    determinacy["cost_increase"] = level
    determinacy["proven_intervals"] = proven_map(sublevel)
    return forged


def _own_level(result: dict) -> float:
    """The level the map's interval is documented at (docs/certificate.md: 3^2 times its cost
    over 2k - 11, at least its gap), from its claim."""
    from geocert.core.determinacy import cost_increase

    claim = result["certificate"]["items"][0]
    points = len(result["certificate"]["data"]["maps"][0]["source"])
    return cost_increase(claim["cost"], 2 * points - 11, claim["gap"])


def _holds(document: dict, truth: np.ndarray) -> np.ndarray:
    found = document["proven_intervals"]["intervals"]
    return np.array([i["lower"] <= x <= i["upper"] for i, x in zip(found, truth)])


class TestResectionProvenAtAChosenLevel:
    """A resection's proven interval is refused below its determinacy's cost_increase
    (fractional._check_proven), but that cost_increase is the document's own number: nothing ties it
    to the map's claim, as review 8 tied a track's (TrackItems.check_returned: at least the
    track's own level, 3^2 times its cost over 2n - 3, from its claim, under every norm). A
    25-point camera with 1 px of noise: its genuine interval, at its own level 12.17 px^2 (3^2 x
    52.7 / 39), holds the true centre; proven again genuinely at cost increase 0 (or 1e-3), the
    determinacy's cost_increase restated to match, it verifies "proven": true, each interval
    about 1/17 of the genuine width (x [-0.679, -0.665] against [-0.785, -0.559]), and the true
    centre (-0.634, -0.886, -7.399) lies outside all three (x by 0.031, y by 0.022, z by 0.12,
    1.8 to 2.3 times the forged intervals' widths beyond them). Suggested fix: as for a track, a
    map's proven interval's level is at least its own, recomputed from its claim's cost and gap
    and its number of points (determinacy.prove_map's cost_increase), whatever the
    determinacy's cost_increase says (and that cost_increase is then checked against it too)."""

    def test_the_genuine_interval_holds_the_truth(self, proven_resection):
        truth, result = proven_resection
        assert _valid(result)
        determinacy = result["maps"][0]["determinacy"]
        assert _holds(determinacy, truth).all()
        assert determinacy["proven_intervals"]["cost_increase"] == pytest.approx(_own_level(result), rel=1e-12)

    @pytest.mark.parametrize("level", FORGED_LEVELS)
    def test_the_forgery_is_false(self, proven_resection, level):
        truth, result = proven_resection
        forged = _map_proven_at(result, level)
        assert level < 1e-3 * _own_level(result)  # the documented level: 12.17
        assert not _holds(forged["maps"][0]["determinacy"], truth).any()  # the true centre outside all three

    @pytest.mark.parametrize("level", FORGED_LEVELS)
    def test_a_map_proven_below_its_own_level_is_refused(self, proven_resection, level):
        assert not _valid(_map_proven_at(proven_resection[1], level))

    @pytest.mark.parametrize("level", [0.0, True, 1e300])
    def test_a_determinacy_read_at_another_level_is_refused(self, proven_resection, level):
        forged = copy.deepcopy(proven_resection[1])
        forged["maps"][0]["determinacy"]["cost_increase"] = level  # the genuine interval kept
        assert not _valid(forged)


# --- options the solver refuses, in a certificate ------------------------------------------------

# Run-control options a stored resection certificate states (max_nodes 5000, time_limit_s 60),
# changed to values the solver refuses on input (geocert.jobs.runner.solve_job: InputError).
REFUSED_OPTIONS = [("max_nodes", -5000), ("max_nodes", 0), ("max_nodes", True), ("time_limit_s", -60.0),
                   ("time_limit_s", True), ("time_limit_s", 1e300), ("job_time_limit_s", -600.0),
                   ("max_nodes", 2.5), ("max_nodes", None), ("time_limit_s", "60"), ("job_time_limit_s", 1e6)]


def _with_option(document: dict, name: str, value) -> dict:
    forged = copy.deepcopy(document)
    forged["certificate"]["options"][name] = value
    return forged


class TestOptionsTheSolverRefuses:
    """docs/certificate.md: "options the solver would refuse ... are invalid (check options)", and
    "every number in a document must be a JSON number: ... not a boolean". The verifier reads only
    the options a claim depends on (verify.checked_options: norm, gaps, max_residual) and hashes
    only those (claim_options), so the run-control options are neither checked nor hashed: the
    stored L2L2 resection verifies, unchanged but for its certificate's options, with max_nodes
    -5000, 0 or true, time_limit_s -60, true or 1e300, or job_time_limit_s -600, each of which
    geocert.jobs.runner.solve_job refuses on input ("options/max_nodes: must be a finite number >= 1
    and <= 1e+06", "must be a number", ...). The document then states options no solve ran under
    (a certified item of 4 leaves beside a node limit of 0, a limit of -60 s), and no re-hash is
    needed to do it. Suggested fix: validate every option with the kind's own options class, as
    the solver does (checked_options reading the whole options object), and refuse a boolean
    wherever a number stands; or, if run-control options are to stay informational, list them
    as such in docs/certificate.md and check their types."""

    def test_the_genuine_document_verifies(self):
        from tests.verify.test_forgeries import stored

        assert _valid(stored("resection_l2l2"))

    @pytest.mark.parametrize("name,value", REFUSED_OPTIONS)
    def test_the_forgery_is_false(self, name, value):
        from geocert.jobs.runner import solve_job
        from geocert.core.geometry import InputError
        from tests.verify.test_forgeries import stored

        certificate = stored("resection_l2l2")["certificate"]
        with pytest.raises(InputError, match=f"options/{name}"):
            solve_job({"kind": "resection", "data": certificate["data"],
                       "options": {"certificate": "full", name: value}})

    @pytest.mark.parametrize("name,value", REFUSED_OPTIONS)
    def test_options_the_solver_refuses_are_refused(self, name, value):
        from tests.verify.test_forgeries import stored

        assert not _valid(_with_option(stored("resection_l2l2"), name, value))

    def test_the_solvers_own_edges_verify(self):
        """The verifier reads the ranges the solver and the API state (OPTION_RANGES,
        JOB_LIMIT_RANGE), so each range's own inclusive edge verifies."""
        from geocert.formulations.fractional.options import MapOptions
        from tests.verify.test_forgeries import stored

        edges = [("max_nodes", MapOptions.OPTION_RANGES["max_nodes"]["ge"]),
                 ("max_nodes", MapOptions.OPTION_RANGES["max_nodes"]["le"]),
                 ("time_limit_s", MapOptions.OPTION_RANGES["time_limit_s"]["le"]),
                 ("job_time_limit_s", MapOptions.JOB_LIMIT_RANGE["le"])]
        for name, value in edges:
            assert _valid(_with_option(stored("resection_l2l2"), name, value)), (name, value)


# --- a map's summary root_region, not the proof's -------------------------------------------------


def _root_ratios(item: dict) -> np.ndarray:
    """What the summary's root_region says of the map returned: (F l) / (d . l), l its last row."""
    region = item["certificate"]["root_region"]
    last = np.asarray(item["matrix"], dtype=float)[-1]
    return np.asarray(region["functionals"]) @ last / (np.asarray(region["denominator"]) @ last)


def _root_region_moved(document: dict) -> dict:
    """``document`` with its first map's summary root_region moved by its own width, each range
    [lower, upper] to [upper, 2 upper - lower]: its words ("lower <= (F l) / (d . l) <= upper for
    the last row l of every map in the scope") kept."""
    forged = copy.deepcopy(document)
    region = forged["maps"][0]["certificate"]["root_region"]
    lower, upper = np.asarray(region["lower"]), np.asarray(region["upper"])
    region["lower"], region["upper"] = upper.tolist(), (2 * upper - lower).tolist()
    return forged


class TestMapRootRegionNotTheProofs:
    """Issue 33's fix of its class 5 made a bilinear frame's summary root_region the proof's (the scope); a map's
    (resection, homography) is still read as informational (docs/certificate.md), yet it states a
    fact in words: "lower <= (F l) / (d . l) <= upper for the last row l of every map in the
    scope". Moved by its own width (each range [lower, upper] to [upper, 2 upper - lower]) on the
    stored L2L2 resection and homography, it verifies, and the map returned, which is in the scope,
    breaks it (resection: ratios 0.1451, 0.2459, 0.1255 against forged lower ends 0.1485, 0.2599,
    0.1341). Any numbers verify (1e300, true, a sign flipped). Suggested fix: as for a bilinear
    frame, the summary's root_region is the proof's root box in the caller's terms (recomputed
    from proof.root and the chart), or it carries no statement the verifier does not check."""

    @pytest.mark.parametrize("name", ["resection_l2l2", "homography2_l2l2"])
    def test_the_genuine_region_holds_the_returned_map(self, name):
        from tests.verify.test_forgeries import stored

        document = stored(name)
        assert _valid(document)
        region, ratios = document["maps"][0]["certificate"]["root_region"], _root_ratios(document["maps"][0])
        assert np.all(np.asarray(region["lower"]) <= ratios) and np.all(ratios <= np.asarray(region["upper"]))

    @pytest.mark.parametrize("name", ["resection_l2l2", "homography2_l2l2"])
    def test_the_forgery_is_false(self, name):
        from tests.verify.test_forgeries import stored

        forged = _root_region_moved(stored(name))
        region = forged["maps"][0]["certificate"]["root_region"]
        assert np.all(_root_ratios(forged["maps"][0]) < np.asarray(region["lower"]))  # the returned map outside

    @pytest.mark.parametrize("name", ["resection_l2l2", "homography2_l2l2"])
    def test_a_root_region_not_the_proofs_is_refused(self, name):
        from tests.verify.test_forgeries import stored

        assert not _valid(_root_region_moved(stored(name)))


# --- the depth-reversal record's figures beside the verdict ---------------------------------------

# Each forged figure of summary.depth_reversal (the nearly affine turntable's record), against what
# the result shows: the returned rig fits 46 observations (summary.observations, the points'
# observations), its shared focal length is 15071.13 px (every camera's K), the projective stage
# read 240 observations. The first three say the returned rig fits everything at the twin's focal
# length; the rest are numbers no pipeline writes (a negative count, a boolean, a subnormal focal).
RECORD_FORGERIES = [{"observations_fitting": 240, "mirror_observations_fitting": 46, "focal_px": 45697.98646526578},
                    {"observations": -1}, {"observations_fitting": True}, {"focal_px": 5e-324},
                    {"mirror_focal_px": -1.0}, {"model": 7}, {"returned_refitted": 0.5}]


def _record_restated(result: dict, changes: dict) -> dict:
    forged = copy.deepcopy(result)
    forged["summary"]["depth_reversal"].update(changes)
    return forged


class TestDepthReversalFiguresUnread:
    """depth_reversal_claim.check recomputes the record's verdict from its two costs and noise and
    its angles from the returned rotations, and docs/certificate.md lists what stays taken as
    stated: "the two costs and the noise". The record's other figures are read by no check:
    observations, observations_fitting, mirror_observations_fitting, focal_px, mirror_focal_px,
    model, returned_refitted. On the nearly affine turntable (review 7's fixture: poses not
    determined, the returned rig fitting 46 of the 240 observations and its twin 147, focal
    lengths 15071 px against 45698 px) the record verifies restated to say the returned rig fits
    all 240 observations at the twin's focal length and the twin only 46, and equally with a count
    of -1 or true, a focal length of 5e-324 or -1, a model 7 or returned_refitted 0.5, none of
    which the pipeline writes (ambiguity.check). What is false is measured from the result itself:
    the returned rig's observations (summary.observations) are 46, its focal length (each camera's
    K) 15071.13 px. Suggested fix: check each figure the result shows (observations_fitting and
    focal_px against the returned rig's, or the twin's where adopted; observations against the
    projective stage's count) and the types and ranges of the rest (counts non-negative integers,
    focal lengths positive, model one of bundle.MODELS, returned_refitted a boolean), or
    list them in docs/certificate.md as taken as stated."""

    def test_the_genuine_record_is_the_results(self, ambiguous_rig):  # noqa: F811
        result = ambiguous_rig[1]
        assert _valid(result)
        record = result["summary"]["depth_reversal"]
        assert record["observations_fitting"] == result["summary"]["observations"] > 0
        assert all(c["K"][0][0] == record["focal_px"] for c in result["cameras"] if c["registered"])

    @pytest.mark.parametrize("changes", RECORD_FORGERIES)
    def test_the_forgery_is_false(self, ambiguous_rig, changes):  # noqa: F811
        from geocert.solvers.reconstruction.bundle import MODELS

        result = ambiguous_rig[1]
        record = _record_restated(result, changes)["summary"]["depth_reversal"]
        shown = (record["observations_fitting"] == result["summary"]["observations"]
                 and record["focal_px"] == result["cameras"][2]["K"][0][0]
                 and type(record["observations"]) is int and record["observations"] >= 0
                 and type(record["observations_fitting"]) is int
                 and record["mirror_focal_px"] > 0 and record["model"] in MODELS
                 and type(record["returned_refitted"]) is bool)
        assert not shown

    @pytest.mark.parametrize("changes", RECORD_FORGERIES)
    def test_a_record_not_the_results_is_refused(self, ambiguous_rig, changes):  # noqa: F811
        assert not _valid(_record_restated(ambiguous_rig[1], changes))

    def test_the_verifiers_models_are_the_bundles(self):
        from geocert.solvers.reconstruction import bundle
        from geocert.formulations.reconstruction import depth_reversal_claim

        assert depth_reversal_claim.MODELS == bundle.MODELS


# --- informational fields not of their type -------------------------------------------------------


def _set(document: dict, path: tuple, value) -> dict:
    forged = copy.deepcopy(document)
    target = forged
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return forged


# Fields of the stored L2L2 resection's result that no check reads, each given a value not of its
# type: a boolean where a number stands (docs/certificate.md: "not a boolean"), a number where a
# list stands (the result model, kinds.resection_homography.MapsResult, refuses these two).
MISTYPED = [(("maps", 0, "determinacy", "redundancy"), True), (("maps", 0, "determinacy", "cost_increase"), True),
            (("maps", 0, "determinacy", "intervals", 0, "lower"), True),
            (("maps", 0, "certificate", "root_region", "lower", 0), True),
            (("maps", 0, "certificate", "root_region", "reference_point"), -1.5), (("stats", "solve_s"), True),
            (("maps", 0, "determinacy", "intervals"), True), (("maps", 0, "determinacy", "warnings"), 1e300)]


class TestInformationalFieldsNotOfTheirType:
    """docs/certificate.md (issue 33's class 8): fields no check reads are informational, "and each
    must be null or of its type (a finite number, an integer, a string)"; "every number in a
    document must be a JSON number: ... not a boolean". Only an item's nodes, elapsed_s and reason
    and a summary's scope, note, order, moment_rank and eigenvalue_ratio are typed
    (verify._check_item_notes, SUMMARY_NOTES): the stored L2L2 resection verifies with its
    determinacy's redundancy, cost_increase or an interval's lower end true, a summary
    root_region's bound true or its reference_point -1.5 (a point index), stats.solve_s true, its
    determinacy's intervals true or its warnings 1e300 (no list: the service's own result model
    refuses these two). JSON readers read true as 1 in arithmetic (Python, JavaScript): the
    redundancy 3 (2 x 7 - 11) reads as 1. The same holds of a track's determinacy (each member but
    proven and proven_intervals takes any value), and of a reconstruction camera's bound_reason
    (camera_misfit's diagnosis, in words: the stored reconstruction's view 1 verifies with it true
    or 5.0, where an item's reason must be a string). Suggested fix: read each informational field
    with its type, as _check_item_notes does (the determinacy by the kind's result model, strictly:
    no boolean for a number), or say in docs/certificate.md which fields are not typed."""

    def test_the_genuine_fields_are_of_their_type(self):
        from tests.verify.test_forgeries import stored

        document = stored("resection_l2l2")
        assert _valid(document)
        for path, _ in MISTYPED:
            value = document
            for key in path:
                value = value[key]
            assert not isinstance(value, bool) and isinstance(value, (int, float, list))
        assert document["maps"][0]["determinacy"]["redundancy"] == 3

    def test_the_result_model_refuses_two(self):
        from pydantic import ValidationError

        from geocert.kinds import get_kind
        from tests.verify.test_forgeries import stored

        model = get_kind("resection").result_model
        for path, value in MISTYPED[-2:]:
            with pytest.raises(ValidationError):
                model.model_validate(_set(stored("resection_l2l2"), path, value))

    @pytest.mark.parametrize("path,value", MISTYPED)
    def test_a_field_not_of_its_type_is_refused(self, path, value):
        from tests.verify.test_forgeries import stored

        assert not _valid(_set(stored("resection_l2l2"), path, value))

    @pytest.mark.parametrize("path,value", [(("tracks", 0, "determinacy", "redundancy"), True),
                                            (("tracks", 0, "determinacy", "method"), 1.0),
                                            (("tracks", 0, "determinacy", "warnings"), [1.0])])
    def test_a_tracks_determinacy_not_of_its_type_is_refused(self, path, value):
        from tests.verify.test_forgeries import stored

        document = stored("triangulation_l2l2")
        assert _valid(document)
        assert not _valid(_set(document, path, value))

    @pytest.mark.parametrize("value", [True, 5.0])
    def test_a_bound_reason_not_words_is_refused(self, value):
        from tests.verify.test_forgeries import stored

        document = stored("reconstruction")
        assert isinstance(document["cameras"][1]["bound_reason"], str) and _valid(document)
        assert not _valid(_set(document, ("cameras", 1, "bound_reason"), value))
