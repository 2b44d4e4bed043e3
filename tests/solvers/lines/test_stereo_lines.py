"""Stereo line motion (thesis chapter 9): the four solvers on synthetic rigs with known motion,
RANSAC with outliers, matching from segments, the kind's input checks. No timed assertions
(speed: bench/stereo_lines.py)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import parse_job, solve_job
from geocert.kinds.stereo_lines import KIND
from geocert.core.geometry import InputError
from geocert.solvers.lines import align, incremental, linear, polynomial, scenes
from geocert.solvers.lines import refine as refinement
from geocert.solvers.lines.geometry import line_set, log_rotation, rodrigues, rotation_error_deg
from geocert.solvers.lines import matching
from geocert.solvers.lines.matching import MatchingOptions, four_view_matches
from geocert.solvers.lines.pipeline import StereoLinesOptions, estimate_motion, estimate_pair
from geocert.solvers.lines.results import Degenerate

SOLVERS = {"polynomial": (polynomial.solve, 2), "linear": (linear.solve, 3), "incremental": (incremental.solve, 2),
           "align": (align.solve, 2)}


def best(candidates, R):
    return min(candidates, key=lambda m: rotation_error_deg(m.R, R))


class TestExactWithoutNoise:
    @pytest.mark.parametrize("name", SOLVERS)
    @pytest.mark.parametrize("seed", range(8))
    def test_minimal_case_recovers_the_motion(self, name, seed):
        solve, minimum = SOLVERS[name]
        scene = scenes.pair_scene(np.random.default_rng(seed), minimum, degrees=3.0, metres=0.1)
        motion = best(solve(line_set(scene.rig, scene.segments)), scene.R)
        assert rotation_error_deg(motion.R, scene.R) < 1e-6
        assert np.linalg.norm(motion.t - scene.t) < 1e-7
        assert np.allclose(motion.R.T @ motion.R, np.eye(3), atol=1e-12) and np.linalg.det(motion.R) > 0

    @pytest.mark.parametrize("name", SOLVERS)
    def test_many_lines_and_a_larger_motion(self, name):
        solve, _ = SOLVERS[name]
        scene = scenes.pair_scene(np.random.default_rng(100), 20, degrees=10.0, metres=0.3)
        motion = best(solve(line_set(scene.rig, scene.segments)), scene.R)
        assert rotation_error_deg(motion.R, scene.R) < 1e-6
        assert np.linalg.norm(motion.t - scene.t) < 1e-7

    def test_the_incremental_solvers_single_step_is_the_thesiss_first_order_answer(self):
        scene = scenes.pair_scene(np.random.default_rng(5), 10, degrees=2.0)
        once = incremental.solve(line_set(scene.rig, scene.segments), incremental.IncrementalOptions(iterations=1))[0]
        error = rotation_error_deg(once.R, scene.R)
        assert 1e-6 < error < 0.2  # first order in the rotation: close, not exact; iterating makes it exact


class TestDegree11:
    @pytest.mark.parametrize("seed", range(6))
    def test_the_true_rotation_is_among_the_real_roots(self, seed):
        scene = scenes.pair_scene(np.random.default_rng(seed), 2, degrees=5.0)
        Q, _, _ = polynomial.quadratics(line_set(scene.rig, scene.segments))
        p, _ = polynomial.degree_11(Q / np.abs(Q).max())
        assert len(p) == 12 and p[0] != 0  # degree 11
        w = log_rotation(scene.R)
        angle = np.linalg.norm(w)
        c = np.tan(angle / 2) * w / angle  # the Cayley vector of the true rotation
        roots = polynomial.real_roots(p, 1e-4)
        assert np.min(np.abs(roots - c[2])) < 1e-7
        assert np.allclose(polynomial.cayley(c), scene.R, atol=1e-12)


class TestDegenerate:
    def test_parallel_lines_are_refused(self):
        rng = np.random.default_rng(3)
        X = scenes.random_lines(rng, 6)
        direction = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
        centres = X.mean(axis=1)
        X = np.stack([centres - 0.5 * direction, centres + 0.5 * direction], axis=1)
        rig = scenes.thesis_rig()
        R, t = scenes.random_motion(rng)
        segments = np.stack([*scenes.project(rig, X), *scenes.project(rig, X, R, t)], axis=1)
        lines = line_set(rig, segments)
        with pytest.raises(Degenerate, match="parallel"):
            align.solve(lines.subset([0, 1]))
        estimate = estimate_motion(lines, StereoLinesOptions(solver="polynomial", sample_size=2))
        assert estimate.status == "failed" and "parallel" in estimate.reason

    def test_lines_through_the_baseline_are_flagged_and_never_sampled(self):
        rng = np.random.default_rng(4)
        rig = scenes.thesis_rig()  # baseline along x: lines along x lie in epipolar planes
        X = scenes.random_lines(rng, 8)
        centres = X.mean(axis=1)
        X = np.stack([centres - [0.5, 0, 0], centres + [0.5, 0, 0]], axis=1)
        R, t = scenes.random_motion(rng, degrees=1.0)
        segments = np.stack([*scenes.project(rig, X), *scenes.project(rig, X, R, t)], axis=1)
        segments[:, :, 1] += 0.5  # not exactly horizontal in the image (as noise would leave them)
        segments[:, :, 3] -= 0.5
        estimate = estimate_motion(line_set(rig, segments), StereoLinesOptions())
        assert estimate.status == "failed" and "epipolar plane" in estimate.reason
        assert sorted(estimate.degenerate) == list(range(8))

    def test_too_few_lines_is_a_failed_pair_saying_why(self):
        scene = scenes.pair_scene(np.random.default_rng(5), 2)
        estimate = estimate_motion(line_set(scene.rig, scene.segments), StereoLinesOptions(solver="linear",
                                                                                             sample_size=3))
        assert estimate.status == "failed" and "2 lines" in estimate.reason


class TestRansac:
    @pytest.mark.parametrize("name", SOLVERS)
    def test_outlier_lines_are_found_and_the_motion_recovered(self, name):
        scene = scenes.pair_scene(np.random.default_rng(11), 60, noise_px=0.0, outlier_fraction=0.3)
        lines = line_set(scene.rig, scene.segments)
        estimate = estimate_motion(lines, StereoLinesOptions(solver=name, sample_size=SOLVERS[name][1]))
        assert estimate.status == "estimate"
        assert rotation_error_deg(estimate.R, scene.R) < 1e-5 and np.linalg.norm(estimate.t - scene.t) < 1e-5
        inliers = set(estimate.inliers)
        assert not inliers & set(np.flatnonzero(scene.outliers))
        usable = set(np.flatnonzero(~scene.outliers)) - set(estimate.degenerate)
        assert inliers == usable

    @pytest.mark.parametrize("name,rotation_deg,translation_m", [
        ("incremental", 1.5, 0.15), ("polynomial", 1.5, 0.15)])
    def test_accuracy_under_noise_and_outliers(self, name, rotation_deg, translation_m):
        errors = []
        for seed in range(5):
            scene = scenes.pair_scene(np.random.default_rng(20 + seed), 100, noise_px=0.5, outlier_fraction=0.3)
            estimate = estimate_motion(line_set(scene.rig, scene.segments),
                                       StereoLinesOptions(solver=name, sample_size=3))
            assert estimate.status == "estimate"
            errors.append((rotation_error_deg(estimate.R, scene.R), np.linalg.norm(estimate.t - scene.t)))
            assert len(set(estimate.inliers) & set(np.flatnonzero(scene.outliers))) <= 3  # outlier lines kept
        rotation, translation = np.median(errors, axis=0)
        assert rotation < rotation_deg and translation < translation_m

    def test_refinement_keeps_the_motion_and_its_inliers(self):
        scene = scenes.pair_scene(np.random.default_rng(30), 60, noise_px=0.3, outlier_fraction=0.2)
        lines = line_set(scene.rig, scene.segments)
        plain = estimate_motion(lines, StereoLinesOptions(refine=False))
        refined = estimate_motion(lines, StereoLinesOptions(refine=True))
        assert refined.refined and not plain.refined
        assert rotation_error_deg(refined.R, scene.R) < 2.0
        assert len(refined.inliers) >= 0.8 * len(plain.inliers)

    def test_the_refinements_jacobian_is_the_residuals_derivative(self):
        """The exact Jacobian (motion: a rotation vector on the left, then t; each line: its two
        points moved across the line in the first image and in their inverse depths) against
        central differences of the residuals, away from the optimum (a wrong Jacobian would still
        converge, slower or elsewhere)."""
        scene = scenes.pair_scene(np.random.default_rng(31), 20, noise_px=0.5)
        lines = line_set(scene.rig, scene.segments)
        R, t = rodrigues(np.array([0.01, -0.02, 0.015])) @ scene.R, scene.t + 0.01
        problem = refinement._Problem(lines)
        P, Q = refinement._start(lines, R, t)
        lateral = refinement._lateral(P, Q)
        r, Jm, Jl = problem.jacobian(R, t, P, Q, lateral)
        np.testing.assert_allclose(r, problem.residuals(R.copy(), t.copy(), P.copy(), Q.copy()), atol=1e-12)
        h = 1e-6

        def moved(k, sign):
            step = np.zeros(10)
            step[k] = sign * h
            P1, Q1 = P.copy(), Q.copy()
            P1[:, :3] += step[6] * lateral
            P1[:, 3] += step[7]
            Q1[:, :3] += step[8] * lateral
            Q1[:, 3] += step[9]
            return problem.residuals(rodrigues(step[:3]) @ R, t + step[3:6], P1, Q1)

        numeric = np.stack([(moved(k, 1) - moved(k, -1)) / (2 * h) for k in range(10)], axis=2)
        exact = np.concatenate([Jm, Jl], axis=2)
        for columns in (slice(0, 3), slice(3, 6), slice(6, 10)):
            scale = np.abs(numeric[:, :, columns]).max()
            np.testing.assert_allclose(exact[:, :, columns], numeric[:, :, columns], atol=1e-6 * scale)

    def test_the_refinement_reaches_the_motion_on_a_sequence(self):
        """bench/stereo_lines.py's section 4 sequence end to end (100 lines a frame, 0.5 px, 1
        degree and 3 cm a frame): the refined motions' 90th percentiles of error are within 0.2
        degrees and 2 cm (0.135 and 1.35 measured; with the lines' points moved in Euclidean
        coordinates, 12 iterations, 0.275 and 2.46: some pairs stopped short of the optimum or in a
        worse one)."""
        rig, poses, frames = scenes.sequence(np.random.default_rng(5), 41, 100, noise_px=0.5, degrees=1.0,
                                             metres=0.03)
        rotation, translation = [], []
        for k in range(40):
            estimate, _, _ = estimate_pair(rig, frames[k], frames[k + 1], None, StereoLinesOptions())
            assert estimate.status == "estimate", estimate.reason
            R = poses[k + 1][0] @ poses[k][0].T
            rotation.append(rotation_error_deg(estimate.R, R))
            translation.append(np.linalg.norm(estimate.t - (poses[k + 1][1] - R @ poses[k][1])))
        assert np.percentile(rotation, 90) <= 0.2, np.percentile(rotation, 90)
        assert np.percentile(translation, 90) <= 0.02, np.percentile(translation, 90)

    def test_the_refinements_lines_start_in_front_of_the_rig(self):
        """Points the algebraic triangulation puts behind the cameras or far off start at the
        scene's depth on their ray (from there a point would pass through infinity, where its
        projected line turns over), and their image in the first view is kept."""
        P = np.array([[0.5, 0.2, 4.0], [1.0, -2.0, -8.0], [0.1, 0.1, 500.0], [0.3, 0.0, 0.01]])
        X = refinement._inverse_depth(P, depth=4.0)
        np.testing.assert_allclose(X[:, :3], P / P[:, 2:3])
        np.testing.assert_allclose(X[:, 3], [0.25, 0.25, 0.25, 0.25])


class TestMatching:
    def test_segments_are_matched_left_right_and_tracked(self):
        rig, poses, frames = scenes.sequence(np.random.default_rng(8), 2, 40, degrees=1.0, metres=0.03)
        quads = four_view_matches(rig, frames[0], frames[1], MatchingOptions())
        correct = np.all(quads == quads[:, :1], axis=1)  # the sequence keeps one line order
        assert len(quads) >= 20 and correct.mean() >= 0.9

    def test_matching_asks_the_clock_and_stops_before_its_assignments(self, monkeypatch):
        """Matching compares every pair of segments and solves four assignments before RANSAC
        first asked should_stop (2000 segments an image with a 2 s limit ran 35 s): now it asks
        between blocks of its costs and before each assignment. Told to stop at once, no
        assignment is solved and the pair fails saying so."""
        rig, _, frames = scenes.sequence(np.random.default_rng(8), 2, 40, degrees=1.0, metres=0.03)
        assignments, asked = [], []
        solve = matching._assign
        monkeypatch.setattr(matching, "_assign", lambda cost: assignments.append(cost.shape) or solve(cost))
        estimate, quads, _ = estimate_pair(rig, frames[0], frames[1], None, StereoLinesOptions(),
                                           lambda: asked.append(True) or True)
        assert asked and assignments == [] and quads is None
        assert estimate.status == "failed" and "stopped while matching segments" in estimate.reason

    def test_a_stop_during_the_guided_matching_keeps_the_first_estimate(self, monkeypatch):
        """Told to stop once the segments are tracked again with the first estimate's rotation,
        the pair stops there (no assignment of the second matching is solved) and keeps that
        estimate: the best so far."""
        from geocert.solvers.lines import pipeline

        rig, poses, frames = scenes.sequence(np.random.default_rng(9), 2, 60, degrees=1.0, metres=0.03)
        guided, assignments = [], []
        match, solve = pipeline.four_view_matches, matching._assign

        def matched(*args, **kwargs):
            guided.append(args[4] is not None)  # rotation given: the guided matching
            return match(*args, **kwargs)

        monkeypatch.setattr(pipeline, "four_view_matches", matched)
        monkeypatch.setattr(matching, "_assign", lambda cost: assignments.append(guided[-1]) or solve(cost))
        estimate, quads, _ = estimate_pair(rig, frames[0], frames[1], None, StereoLinesOptions(),
                                           lambda: bool(guided and guided[-1]))
        assert guided == [False, True] and True not in assignments
        assert estimate.status == "estimate" and quads is not None and len(quads)
        assert rotation_error_deg(estimate.R, poses[1][0]) < 0.5

    def test_a_sequence_from_segments_gives_its_trajectory(self):
        rig, poses, frames = scenes.sequence(np.random.default_rng(9), 4, 60, degrees=1.0, metres=0.03)
        job = {"kind": "stereo_lines", "options": {"solver": "polynomial", "sample_size": 2},
               "data": {"rig": {"K_left": rig.K_left.tolist(), "K_right": rig.K_right.tolist(), "R": rig.R.tolist(),
                                "t": rig.t.tolist()},
                        "frames": [{"left": f["left"].tolist(), "right": f["right"].tolist()} for f in frames]}}
        result = solve_job(job)
        KIND.result_model.model_validate(result)
        assert [pair["status"] for pair in result["pairs"]] == ["estimate"] * 3
        assert all(pair["matches"] and pair["certified"] is False for pair in result["pairs"])
        for pose, (R, t) in zip(result["trajectory"], poses):
            assert rotation_error_deg(np.array(pose["R"]), R) < 1e-5
            assert np.linalg.norm(np.array(pose["t"]) - t) < 1e-5


def example() -> dict:
    return copy.deepcopy(KIND.example)


class TestBadInput:
    @pytest.mark.parametrize("mutate,field", [
        (lambda j: j["data"]["rig"].__setitem__("R", [[1, 0, 0], [0, 1, 0], [0, 0, -1]]), "data/rig/R"),
        (lambda j: j["data"]["rig"].__setitem__("R", [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]), "data/rig/R"),
        (lambda j: j["data"]["rig"].__setitem__("t", [0, 0, 0]), "data/rig/t"),
        (lambda j: j["data"]["rig"].__setitem__("K_left", [[0, 0, 0], [0, 1, 0], [0, 0, 1]]), "data/rig/K_left"),
        (lambda j: j["data"]["matches"][0][3].__setitem__(2, [5.0, 5.0, 5.0, 5.0]), "data/matches/0/3/2"),
        (lambda j: j["data"]["matches"].__setitem__(0, j["data"]["matches"][0][:1]), "data/matches/0"),
        (lambda j: j["options"].__setitem__("sample_size", 1), "options/sample_size"),
        (lambda j: j["options"].update(solver="linear", sample_size=2), "options/sample_size"),
        (lambda j: j["options"].__setitem__("ransac", {"threshold": 1}), "options/ransac/threshold"),
        (lambda j: j["options"].__setitem__("ransac", {"confidence": 1.5}), "options/ransac/confidence"),
        (lambda j: j["options"].__setitem__("refine", 1), "options/refine"),
        (lambda j: j["options"].__setitem__("matching", {"guided": "yes"}), "options/matching/guided"),
        (lambda j: j["options"].__setitem__("ransac", {"max_iterations": 2.5}), "options/ransac/max_iterations"),
        (lambda j: j["options"].__setitem__("solver", "magic"), "options/solver"),
        (lambda j: j["data"].__setitem__("frames", [{"left": [], "right": []}] * 2), "data/frames"),
    ])
    def test_named(self, mutate, field):
        job = example()
        mutate(job)
        with pytest.raises(InputError) as error:
            parse_job(job)
        assert error.value.field == field

    def test_zero_length_segments_in_frames_and_too_few_segments(self):
        job = example()
        segments = job["data"].pop("matches")[0]
        frame = {"left": [quad[0] for quad in segments], "right": [quad[1] for quad in segments]}
        job["data"]["frames"] = [copy.deepcopy(frame), copy.deepcopy(frame)]
        job["data"]["frames"][1]["left"][4] = [1.0, 2.0, 1.0, 2.0]
        with pytest.raises(InputError) as error:
            parse_job(job)
        assert error.value.field == "data/frames/1/left/4"
        job["data"]["frames"][1]["left"] = job["data"]["frames"][1]["left"][:1]
        with pytest.raises(InputError) as error:
            parse_job(job)
        assert error.value.field == "data/frames/1/left"

    def test_a_null_seed_is_fresh_randomness(self):
        job = example()
        job["options"]["ransac"] = {"seed": None}
        assert parse_job(job)[2].ransac.seed is None

    def test_a_null_sample_size_is_the_solvers_minimum(self):
        job = example()
        job["options"] = {"solver": "linear", "sample_size": None}
        _, _, options = parse_job(job)
        assert options.samples == 3


class TestGuidedMatching:
    def test_tracking_with_the_rotation_corrects_mistracked_parallel_edges(self):
        rig, poses, frames, _ = scenes.room_loop(np.random.default_rng(6), frames=180, noise_px=0.5, boxes=30,
                                                 take=30)
        wrong = {False: [], True: []}
        for k in range(len(frames) - 1):
            a, b = frames[k], frames[k + 1]
            for guided in (False, True):
                rotation = poses[k + 1][0] @ poses[k][0].T if guided else None
                quads = four_view_matches(rig, a, b, MatchingOptions(), rotation)
                ids = np.stack([a["ids"][quads[:, 0]], a["ids"][quads[:, 1]], b["ids"][quads[:, 2]],
                                b["ids"][quads[:, 3]]], axis=1)
                wrong[guided].append(1 - np.all(ids == ids[:, :1], axis=1).mean())
        assert np.mean(wrong[True]) < 0.03 < np.mean(wrong[False])


class TestIndoorSequence:
    def test_a_walk_in_a_room_of_boxes_from_segments(self):
        """The thesis's setting (7.4 cm baseline, 90 degrees of field of view), segments only,
        detected in no particular order: every pair estimated, nearly all exactly without noise
        (the appearance-free matcher can pair nearby parallel edges wrongly: those few pairs are
        off by a fraction of a degree), and the trajectory stays on the walk."""
        rig, poses, frames, _ = scenes.room_loop(np.random.default_rng(6), frames=180, boxes=30, take=16)
        options = StereoLinesOptions()
        R, t = np.eye(3), np.zeros(3)
        errors = []
        from geocert.solvers.lines.pipeline import estimate_pair

        for k in range(len(frames) - 1):
            estimate, quads, _ = estimate_pair(rig, frames[k], frames[k + 1], None, options)
            assert estimate.status == "estimate" and len(quads) >= 15
            errors.append(rotation_error_deg(estimate.R, poses[k + 1][0] @ poses[k][0].T))
            R, t = estimate.R @ R, estimate.R @ t + estimate.t
        assert np.median(errors) < 1e-6 and max(errors) < 1.0
        assert rotation_error_deg(R, poses[-1][0]) < 1.0
        assert np.linalg.norm(-R.T @ t + poses[-1][0].T @ poses[-1][1]) < 0.05
