"""An eleventh hostile review of the verifier (issue 33): numbers a document states beside its
proofs, which earlier reviews left as the document's word. Each class starts from a genuine
document (a stored certificate, tests/data/certificates, or a result the solver returns here),
asserts it verifies, edits one field (or a few, kept consistent with one another) and asserts
the verifier refuses it. Each test failed before its fix (the forgery verified).

The classes: a reconstruction's stage figures (linear_K, K_free, RMS values, times, counts)
accepted any number; a direct autocalibration's relaxation figures (order, moment_rank,
eigenvalue_ratio) any integer; a branch-and-bound root's bounds and claimed box any box enclosing
what is recomputed; the run-control options (max_nodes, time_limit_s, ...) of reconstruction,
bilinear and autocalibration documents any number; the bundle_adjustment stage's K, which the
depth-reversal record's focal length is read against, any K; and the depth-reversal record's
observations any count at least those fitting (on the K-known path, where no stage counts them).

Found and left (informational, documented): a determinacy estimate's intervals (value, lower,
upper, tolerance) and its redundancy, an item's elapsed_s and the stats' times take any finite
number of their type (a curvature estimate is not certified; the times are not bounded above);
the depth-reversal record's mirror_focal_px, where the twin is not adopted, any positive number
(it needs the twin's adjustment); a root's claimed box edited (widened, or narrowed while it still encloses
the proven range) is accepted: sound (the proven range is recomputed over it), and the solver's
own box is half the range's width beyond it on each side on every stored root (0.5000 to
0.5001), but a batched solve's inexact barrier makes it differ in genuine documents."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries_review7 import ambiguous_rig  # noqa: F401 (a fixture: the nearly affine turntable)

STORED = Path(__file__).parent.parent / "data" / "certificates"


def _stored(name: str) -> dict:
    return json.loads((STORED / f"{name}.json").read_text())


def _refused(document: dict) -> str:
    report = verify_any(document)
    assert not report.valid
    return report.first_failure["detail"]


def _stage(result: dict, name: str) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == name)


# --- a reconstruction's stage figures ------------------------------------------------------------

def _set(path: str, value):
    def edit(result: dict) -> None:
        stage, *rest = path.split("/")
        target = _stage(result, stage)
        for key in rest[:-1]:
            target = target[int(key)] if isinstance(target, list) else target[key]
        last = rest[-1]
        if isinstance(target, list):
            target[int(last)] = value
        else:
            target[last] = value
    return edit


def _set_entry(path: str, row: int, column: int, value):
    def edit(result: dict) -> None:
        stage, *rest = path.split("/")
        target = _stage(result, stage)
        for key in rest:
            target = target[key]
        target[row][column] = value
    return edit


STAGE_FORGERIES = {
    "linear_K negative focal": _set_entry("autocalibration/linear_K", 0, 0, -803.0),
    "linear_K boolean": _set_entry("autocalibration/linear_K", 1, 1, True),
    "linear_K huge": _set_entry("autocalibration/linear_K", 0, 2, 1e300),
    "linear_K not upper triangular": _set_entry("autocalibration/linear_K", 2, 0, 5.0),
    "linear_K a string": _set("autocalibration/linear_K", "803"),
    "K_free negative focal": _set_entry("bundle_adjustment/principal_point/K_free", 1, 1, -790.0),
    "rms negative": _set("bundle_adjustment/rms_px_after", -0.54),
    "rms boolean": _set("projective/rms_reprojection_px", True),
    "rms huge": _set("bundle_adjustment/rms_px_before", 1e300),
    "focal round negative": _set("projective/focal_rounds/0/focal_px", -768.0),
    "a count fractional": _set("projective/initial_pair_search/thresholds/relaxations", 2.5),
    "a nested stage's nodes negative": _set("autocalibration/stages/0/nodes", -2),
    "a noise negative": _set("autocalibration/rotation_noise_rad/estimated", -0.0025),
    "a threshold boolean": _set("bundle_adjustment/principal_point/threshold", True),
    "a time negative": _set("structure/elapsed_s", -0.05),
    "a cpu time huge": _set("cameras/cpu_s", 1e300),
}


class TestStageFigures:
    """A reconstruction's stage figures the verifier reads nowhere else are informational, but
    of their types (stage_checks.FIGURES): a negative focal length, a boolean, 1e300, a fraction
    for a count were each accepted; and the summary's times are each stage's."""

    def test_the_genuine_document_verifies(self):
        assert verify_any(_stored("reconstruction")).valid

    @pytest.mark.parametrize("name", list(STAGE_FORGERIES))
    def test_a_figure_of_no_run_is_refused(self, name):
        forged = _stored("reconstruction")
        STAGE_FORGERIES[name](forged)
        assert "stages/" in _refused(forged)

    def test_a_summary_time_not_its_stage_is_refused(self):
        forged = _stored("reconstruction")
        forged["summary"]["time_s"]["structure"] = 0.5
        assert "summary/time_s/structure" in _refused(forged)



# --- a direct autocalibration's relaxation figures ----------------------------------------------

def _summary(result: dict) -> dict:
    return result["stages"][0]["certificate"]


def _proof(result: dict) -> dict:
    return result["certificate"]["items"][0]["proof"]


class TestDirectRelaxationFigures:
    """The summary's order is the options' relaxation_order (the programs the verifier builds),
    its moment_rank and eigenvalue_ratio the proof's; the proof's are a rank and ratio an
    order-2 moment matrix (55 x 55) has, agreeing with each other. Negative, zero, too large
    and boolean values were each accepted (typed as integers only)."""

    def test_the_genuine_document_verifies(self):
        document = _stored("autocalibration_direct")
        assert verify_any(document).valid
        assert _summary(document)["order"] == 2 and _proof(document)["moment_rank"] == 1

    @pytest.mark.parametrize("value", [-1, 0, 1, 3, 1000])
    def test_another_order_is_refused(self, value):
        forged = _stored("autocalibration_direct")
        _summary(forged)["order"] = value
        assert "order" in _refused(forged)

    @pytest.mark.parametrize("value", [-1, 0, 2, 56])
    def test_a_summary_rank_not_the_proofs_is_refused(self, value):
        forged = _stored("autocalibration_direct")
        _summary(forged)["moment_rank"] = value
        assert "moment_rank" in _refused(forged)

    @pytest.mark.parametrize("value", [-1, 0, 56, 10**9])
    def test_a_rank_no_moment_matrix_has_is_refused(self, value):
        """The proof's and the summary's restated together (so they agree)."""
        forged = _stored("autocalibration_direct")
        _summary(forged)["moment_rank"] = _proof(forged)["moment_rank"] = value
        assert "moment_rank" in _refused(forged)

    @pytest.mark.parametrize("rank, ratio", [(2, None), (1, 0.5), (1, 2.0), (1, 1e300)])
    def test_a_rank_and_ratio_that_disagree_are_refused(self, rank, ratio):
        forged = _stored("autocalibration_direct")
        ratio = _proof(forged)["eigenvalue_ratio"] if ratio is None else ratio
        for record in (_summary(forged), _proof(forged)):
            record.update(moment_rank=rank, eigenvalue_ratio=ratio)
        assert "moment_rank" in _refused(forged) or "eigenvalue_ratio" in _refused(forged)

    def test_a_summary_ratio_not_the_proofs_is_refused(self):
        forged = _stored("autocalibration_direct")
        _summary(forged)["eigenvalue_ratio"] = -_summary(forged)["eigenvalue_ratio"]
        assert "eigenvalue_ratio" in _refused(forged)


# --- a branch-and-bound root's stated bounds and claim -------------------------------------------

def _root(document: dict) -> dict:
    return document["certificate"]["items"][0]["proof"]["root"]


# The last functional (never branched on: the first k are, and a branched one's loosened bound
# already failed the search's coverage) is edited.
ROOT_EDITS = {
    "an upper bound loosened": lambda root: root["bounds"][1].__setitem__(-1, root["bounds"][1][-1] + 1.0),
    "a lower bound loosened": lambda root: root["bounds"][0].__setitem__(-1, root["bounds"][0][-1] - 1.0),
}


class TestRootInternals:
    """A root's bounds looser than the proven ones were accepted (the search must cover what is
    stated, so sound, but not the proof the solver wrote: a document edited there states
    internals no solver run produced). Now the bounds are the proven ones, within 1e-6 of their
    size (the solver pads by 1e-7). Resection (proof.py) and triangulation (the stacked path,
    stacked._root_holds, and the per-item path behind it)."""

    @pytest.mark.parametrize("name", ["resection_l2l2", "resection_l1l1", "triangulation_l2l2", "homography2_l2l2"])
    def test_the_genuine_documents_verify(self, name):
        assert verify_any(_stored(name)).valid

    @pytest.mark.parametrize("name", ["resection_l2l2", "triangulation_l2l2", "homography2_l2l2"])
    @pytest.mark.parametrize("edit", list(ROOT_EDITS))
    def test_edited_internals_are_refused(self, name, edit):
        forged = _stored(name)
        ROOT_EDITS[edit](_root(forged))
        assert not verify_any(forged).valid

    @pytest.mark.parametrize("name", ["resection_l2l2", "triangulation_l2l2"])
    def test_a_sign_flipped_bound_is_refused(self, name):
        """Each side of the bounds flipped in sign (one at a time), wherever that loosens them (a
        tightening one fails the enclosure, as before)."""
        document = _stored(name)
        root = _root(document)
        for side in (0, 1):
            for j, value in enumerate(root["bounds"][side]):
                if not (-value < value if side == 0 else -value > value):
                    continue
                forged = copy.deepcopy(document)
                _root(forged)["bounds"][side][j] = -value
                assert not verify_any(forged).valid, (side, j)


# --- run-control options ----------------------------------------------------------------------

RUN_CONTROL = [
    ("reconstruction", "max_nodes", 0), ("reconstruction", "max_nodes", 2.5), ("reconstruction", "time_limit_s", -60),
    ("reconstruction", "time_limit_s", 1e300), ("reconstruction", "autocalibration_max_nodes", 0),
    ("reconstruction", "autocalibration_time_limit_s", True), ("reconstruction", "structure_time_limit_s", 0),
    ("reconstruction", "autocalibration_points", 5), ("reconstruction", "threshold_px", -2.0),
    ("reconstruction", "min_inliers", 12.5), ("reconstruction", "focal_prior_rounds", 0),
    ("reconstruction", "focal_prior_factor", 1e300), ("reconstruction", "seed", -1),
    ("reconstruction", "focal_prior_px", -800.0), ("reconstruction", "bundle_adjustment", 1),
    ("reconstruction", "camera_model", "affine"), ("reconstruction", "registration", 3),
    ("bilinear_l2l2", "max_nodes", 0), ("bilinear_l2l2", "max_nodes", 1.5), ("bilinear_l2l2", "time_limit_s", -60),
    ("bilinear_l2l2", "time_limit_s", True), ("bilinear_l2l2", "job_time_limit_s", 1e300),
    ("autocalibration_stratified", "max_nodes", 0), ("autocalibration_stratified", "max_nodes", -20000),
    ("autocalibration_stratified", "time_limit_s", 1e300), ("autocalibration_stratified", "time_limit_s", 0),
    ("autocalibration_direct", "max_nodes", 2.5), ("autocalibration_direct", "max_nodes", 10**7),
    ("autocalibration_direct", "time_limit_s", True), ("autocalibration_direct", "time_limit_s", -1.0),
]


class TestRunControlOptions:
    """Options that control a run are not hashed; a document stating one the solver refuses (its
    kind's OPTION_RANGES, as triangulation, resection and homography already did) states a run
    that never was: each was accepted, and is refused under "options"."""

    @pytest.mark.parametrize("name", ["reconstruction", "bilinear_l2l2", "autocalibration_stratified",
                                      "autocalibration_direct"])
    def test_the_genuine_documents_verify(self, name):
        assert verify_any(_stored(name)).valid

    @pytest.mark.parametrize("name, option, value", RUN_CONTROL)
    def test_an_option_the_solver_refuses_is_refused(self, name, option, value):
        forged = _stored(name)
        forged["certificate"]["options"][option] = value
        report = verify_any(forged)
        assert not report.valid and report.first_failure["check"] == "options"
        assert option in report.first_failure["detail"]

    @pytest.mark.parametrize("name, option, value", [("reconstruction", "max_nodes", 1_000_000),
                                                     ("reconstruction", "time_limit_s", 3600),
                                                     ("reconstruction", "seed", 7),
                                                     ("bilinear_l2l2", "max_nodes", 1),
                                                     ("autocalibration_direct", "time_limit_s", 0.5)])
    def test_an_option_the_solver_takes_verifies(self, name, option, value):
        forged = _stored(name)
        forged["certificate"]["options"][option] = value
        assert verify_any(forged).valid


# --- the depth-reversal record's K and observations ----------------------------------------------

class TestDepthReversalK:
    """The record's focal length is read against the bundle_adjustment stage's K; that K stated
    beside the record (both edited to another focal length, the cameras' K kept) was accepted.
    Now the stage's K is the returned cameras' K wherever they share one."""

    def test_the_genuine_result_verifies(self, ambiguous_rig):
        _, result = ambiguous_rig
        assert verify_any(result).valid and result["summary"]["depth_reversal"]["checked"] is True

    @pytest.mark.parametrize("focal", [20_000.0, 35_402.9, 1e12])
    def test_a_stage_K_not_the_cameras_is_refused(self, ambiguous_rig, focal):
        forged = copy.deepcopy(ambiguous_rig[1])
        K = _stage(forged, "bundle_adjustment")["K"]
        K[0][0] = K[1][1] = focal
        forged["summary"]["depth_reversal"]["focal_px"] = focal
        assert "cameras returned" in _refused(forged)


@pytest.fixture(scope="module")
def known_K() -> dict:
    """A K-known reconstruction (a 6-view turntable, 30 tracks, 0.5 px of noise, one observation
    40 px off): the depth-reversal check runs, and no stage counts the observations it was sent
    (180, every observation of every track)."""
    from geocert.jobs.runner import solve_job
    from geocert.solvers.reconstruction import synthetic
    from tests.support import reconstruction_data

    scene = synthetic.turntable(views=6, points=30, focal=800.0, step_degrees=20, noise_px=0.5, seed=1)
    tracks = list(scene.tracks)
    views, pixels = tracks[0]
    pixels = pixels.copy()
    pixels[0] += 40.0
    tracks[0] = (views, pixels)
    data = reconstruction_data(tracks, scene.image_size, 6)
    return solve_job({"kind": "reconstruction", "data": data,
                      "options": {"certificate": "full", "intrinsics": {"K": scene.K.tolist()},
                                  "resect_cameras": False}})


class TestKnownKObservations:
    """On the K-known path the record's observations were only typed (a count at least those
    fitting): any count from 174 to 2^40 verified. Now it lies between the returned points'
    observations plus 2 for each track not returned, and one a view for each track."""

    def test_the_genuine_result_verifies(self, known_K):
        assert verify_any(known_K).valid
        assert known_K["summary"]["depth_reversal"]["observations"] == 180

    @pytest.mark.parametrize("count", [175, 181, 1000, 2**40])
    def test_a_count_the_data_cannot_hold_is_refused(self, known_K, count):
        forged = copy.deepcopy(known_K)
        forged["summary"]["depth_reversal"]["observations"] = count
        assert "observations" in _refused(forged)
