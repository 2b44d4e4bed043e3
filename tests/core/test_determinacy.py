"""Determinacy (issue 19): intervals from the local curvature and the degeneracies recognised.
Scenes built to be degenerate are flagged and get wide intervals; well-posed ones are not flagged,
their intervals hold the truth and shrink with more data."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import scipy.stats

from testing.determinacy import cameras_looking_at_origin, project
from geocert.jobs.runner import solve_job
from geocert.solvers import datasets
from geocert.solvers.autocalibration import scenes
from geocert.core.determinacy import STUDENT_FORM, curvature_intervals, level_sigmas, reading
from geocert.formulations.fractional import determinacy as fractional

from tests.support import random_cameras, shared_data


def codes(document: dict) -> list[str]:
    return [w["code"] for w in document["warnings"]]


def interval(document: dict, name: str) -> dict:
    return next(i for i in document["intervals"] if i["name"] == name)


def width(document: dict, name: str) -> float:
    found = interval(document, name)
    return np.inf if found["lower"] is None else found["upper"] - found["lower"]


class TestCurvatureIntervals:
    def test_a_linear_fit_gets_its_standard_errors(self):
        rng = np.random.default_rng(0)
        A = rng.normal(size=(40, 3))
        x = np.linalg.lstsq(A, A @ [1.0, 2.0, 3.0] + rng.normal(scale=0.1, size=40), rcond=None)[0]
        r = A @ x - (A @ [1.0, 2.0, 3.0] + rng.normal(scale=0.1, size=40))
        out = curvature_intervals(A, r, {"x0": (x[0], np.array([1.0, 0, 0]))}, sigmas=1.0)
        # one standard error's coverage (68.3%) from 37 degrees of freedom: the Student quantile
        expected = scipy.stats.t.ppf(0.5 + math.erf(1.0 / math.sqrt(2.0)) / 2, 37) \
            * np.sqrt((r @ r) / 37 * np.linalg.inv(A.T @ A)[0, 0])
        found = out.intervals[0]
        assert found["upper"] - x[0] == pytest.approx(expected, rel=1e-9)
        with reading(STUDENT_FORM - 1):  # the earlier forms: the standard errors themselves
            earlier = curvature_intervals(A, r, {"x0": (x[0], np.array([1.0, 0, 0]))}, sigmas=1.0).intervals[0]
        assert earlier["upper"] - x[0] == pytest.approx(np.sqrt((r @ r) / 37 * np.linalg.inv(A.T @ A)[0, 0]), rel=1e-9)

    @pytest.mark.parametrize("dof", [1, 2, 3, 5, 11, 40, 1000, 100000])
    def test_the_level_is_the_student_quantile_of_the_degrees_of_freedom(self, dof):
        """core.determinacy.level_sigmas (pure Python, the verifier computes it too) against
        scipy's Student quantile at 3 standard errors' two-sided coverage."""
        expected = scipy.stats.t.ppf(0.5 + math.erf(3.0 / math.sqrt(2.0)) / 2, dof)
        assert level_sigmas(dof) == pytest.approx(expected, rel=1e-9)
        with reading(STUDENT_FORM - 1):
            assert level_sigmas(dof) == 3.0

    def test_a_direction_the_data_do_not_fix_is_unbounded(self):
        A = np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])  # only x0 + x1 is seen
        out = curvature_intervals(A, np.array([0.1, -0.1, 0.05]), {
            "x0": (0.0, np.array([1.0, 0.0])), "sum": (0.0, np.array([1.0, 1.0]))})
        assert interval(out.document(), "x0")["lower"] is None
        assert interval(out.document(), "sum")["lower"] is not None

    def test_never_narrower_than_the_certified_gap_allows(self):
        A = np.eye(2)
        out = curvature_intervals(A, np.zeros(2), {"x0": (0.0, np.array([1.0, 0.0]))}, gap=0.25)
        assert interval(out.document(), "x0")["upper"] == pytest.approx(0.5)


class TestTriangulation:
    def track(self, centres, noise, seed):
        cameras = cameras_looking_at_origin(centres)
        X = np.array([0.3, -0.2, 0.1])
        points = project(cameras, X) + np.random.default_rng(seed).normal(scale=noise, size=(len(centres), 2))
        result = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": [
            {"views": list(range(len(centres))), "points": points.tolist()}]}, "options": {}})
        return X, result["tracks"][0]["determinacy"]

    def test_wide_baseline_intervals_hold_the_truth_and_shrink_with_views(self):
        inside, widths = 0, {}
        for views in (3, 12):
            angles = np.linspace(0, np.pi / 2, views)
            centres = 10 * np.c_[np.sin(angles), np.zeros(views), np.cos(angles)]
            for seed in range(10):
                X, document = self.track(centres, 1.0, seed)
                assert codes(document) == [] and document["determined"]
                inside += all(interval(document, k)["lower"] <= X[i] <= interval(document, k)["upper"]
                              for i, k in enumerate("xyz"))
                widths.setdefault(views, []).append(width(document, "depth_view0"))
        assert inside >= 17  # of 20: 3 standard errors each
        assert np.median(widths[12]) < 0.7 * np.median(widths[3])

    def test_near_zero_parallax_is_flagged_and_wide(self):
        narrow = np.array([[0.0, 0, 10], [0.05, 0, 10], [0.1, 0, 10]])
        wide = np.array([[0.0, 0, 10], [7.0, 0, 7], [10.0, 0, 0]])
        _, flat = self.track(narrow, 1.0, 0)
        _, good = self.track(wide, 1.0, 0)
        assert "near_zero_parallax" in codes(flat) and not flat["determined"]
        assert width(flat, "depth_view0") > 50 * width(good, "depth_view0")


class TestMaps:
    def resection(self, points3, noise=0.5, seed=0):
        centre = np.array([0.0, 0.0, -10.0])
        camera = cameras_looking_at_origin(centre[None, :])
        image = np.array([project(camera, X)[0] for X in points3])
        image += np.random.default_rng(seed).normal(scale=noise, size=image.shape)
        result = solve_job({"kind": "resection", "data": {"maps": [
            {"source": points3.tolist(), "target": image.tolist()}]}, "options": {}})
        return centre, result["maps"][0]["determinacy"]

    def test_a_well_posed_resection_holds_its_centre(self):
        points3 = np.random.default_rng(1).uniform(-2, 2, size=(20, 3))
        centre, document = self.resection(points3)
        assert codes(document) == []
        for k, name in enumerate(("centre_x", "centre_y", "centre_z")):
            assert interval(document, name)["lower"] <= centre[k] <= interval(document, name)["upper"]

    @staticmethod
    def house_resections(points: int, seed: int = 1007) -> tuple[list[dict], list[np.ndarray]]:
        """The Oxford Model House's ten cameras, each resected from ``points`` points in the
        house's box at 0.1 px (40 maps, one job): each map's determinacy and true centre."""
        views = datasets.load_vgg_cameras(shared_data("oxford_house"), "house", (768, 576))
        cameras, centres, (lo, hi) = views.cameras, views.centres, views.box
        rng = np.random.default_rng(seed)
        maps, truths = [], []
        for _ in range(40):
            view = rng.integers(len(cameras))
            points3 = rng.uniform(lo, hi, size=(points, 3))
            image = np.array([project(cameras[view][None], X)[0] for X in points3])
            maps.append({"source": points3.tolist(),
                         "target": (image + rng.normal(scale=0.1, size=image.shape)).tolist()})
            truths.append(centres[view])
        result = solve_job({"kind": "resection", "data": {"maps": maps}, "options": {}})
        return [item["determinacy"] for item in result["maps"]], truths

    def test_six_point_resections_on_real_cameras_are_not_determined(self):
        """A 6-point projective camera leaves one degree of freedom for the noise, whose estimate
        from it is below a tenth of the truth one time in four. At 3 standard errors whatever the
        degrees of freedom (the estimates' forms 0 and 1) 8 of 39 `determined` centres missed the
        truth here (issue 37, F3); at the Student quantile of one (235.8) the few still judged
        narrow are so because their noise estimate is near 0 (5 of 37 missed, over seven draws of
        40), so today's form warns few_degrees_of_freedom and determines none."""
        documents, _ = self.house_resections(6)
        assert all(d["redundancy"] == 1 and "few_degrees_of_freedom" in codes(d) for d in documents)
        assert not any(d["determined"] for d in documents)

    @pytest.mark.parametrize("points", [7, 12])
    def test_few_point_resections_on_real_cameras_hold_their_centres(self, points):
        """From 7 points (three degrees of freedom) and 12 (thirteen), at the Student level, a
        `determined` centre holds the truth but for about one in a hundred, and most centres are
        still determined (the correction does not merely mark everything undetermined)."""
        documents, truths = self.house_resections(points)
        determined = missed = 0
        for document, centre in zip(documents, truths):
            if document["determined"]:
                determined += 1
                missed += not all(interval(document, name)["lower"] <= centre[k] <= interval(document, name)["upper"]
                                  for k, name in enumerate(("centre_x", "centre_y", "centre_z")))
        assert determined >= 30
        assert missed <= 1, (missed, determined)

    def test_coplanar_points_are_flagged(self):
        points3 = np.random.default_rng(1).uniform(-2, 2, size=(20, 3))
        points3[:, 2] = 0.3 * points3[:, 0] + np.random.default_rng(2).normal(scale=0.005, size=20)  # nearly a plane
        _, document = self.resection(points3)
        assert "near_coplanar_points" in codes(document) and not document["determined"]

    def test_collinear_points_are_flagged_for_a_homography(self):
        rng = np.random.default_rng(2)
        t = rng.uniform(0, 100, size=10)
        source = np.c_[t, 2 * t + rng.normal(scale=0.01, size=10)]
        H = np.array([[1.1, 0.1, 5], [0.05, 0.9, -3], [1e-4, 2e-4, 1]])
        image = np.c_[source, np.ones(10)] @ H.T
        target = image[:, :2] / image[:, 2:]
        result = solve_job({"kind": "homography", "data": {"maps": [
            {"source": source.tolist(), "target": target.tolist()}]}, "options": {}})
        assert "near_collinear_points" in codes(result["maps"][0]["determinacy"])

    def test_a_spread_homography_is_not_flagged(self):
        rng = np.random.default_rng(3)
        source = rng.uniform(0, 100, size=(12, 2))
        image = np.c_[source, np.ones(12)] @ np.array([[1.1, 0.1, 5], [0.05, 0.9, -3], [1e-4, 2e-4, 1]]).T
        target = image[:, :2] / image[:, 2:] + rng.normal(scale=0.5, size=(12, 2))
        document = fractional.map_(source, target, None, None, None)
        assert document is None  # no map, nothing to say
        result = solve_job({"kind": "homography", "data": {"maps": [
            {"source": source.tolist(), "target": target.tolist()}]}, "options": {}})
        assert result["maps"][0]["determinacy"]["determined"]


class TestAutocalibration:
    TRUTH = {"focal_x": 1000.0, "focal_y": 1000.0, "skew": 0.0, "principal_u": 500.0, "principal_v": 500.0}

    @staticmethod
    @functools.lru_cache(maxsize=None)
    def _solved(motion):
        scene = scenes.make_scene(12, 0.1, seed=1, motion=motion)
        return solve_job({"kind": "autocalibration", "data": scene.job_data(), "options": {"time_limit_s": 5}})

    def stages(self, motion):
        return self._solved(motion)["stages"]

    def test_cameras_all_round_are_not_flagged_and_hold_the_truth(self):
        for stage in self.stages("sphere"):
            assert stage["determinacy"]["determined"], stage["determinacy"]
        metric = self.stages("sphere")[1]["determinacy"]
        for name, value in self.TRUTH.items():
            assert interval(metric, name)["lower"] <= value <= interval(metric, name)["upper"]

    def test_the_principal_point_and_skew_are_held_to_the_images_scale(self):
        """Issue 37 F4: their tolerance is a tenth of half the image's larger side (here 1000 x
        1000: 50 px), not a tenth of the focal length (100 px here; 331 px on the dino, wider than
        its principal point's whole range); the focal lengths keep a tenth of their own."""
        metric = self.stages("sphere")[1]["determinacy"]
        assert list(scenes.make_scene(12, 0.1, seed=1, motion="sphere").job_data()["image_size"]) == [1000, 1000]
        for name in ("skew", "principal_u", "principal_v"):
            assert interval(metric, name)["tolerance"] == pytest.approx(50.0, rel=1e-12)
        for name in ("focal_x", "focal_y"):
            found = interval(metric, name)
            assert found["tolerance"] == pytest.approx(0.1 * found["value"], rel=1e-12)

    def test_the_images_scale_without_an_image_size_is_the_principal_point_ranges(self):
        from geocert.core.determinacy import image_scale
        from geocert.formulations.autocalibration.problem import default_ranges

        dino = default_ranges((720, 576))["principal_point"]
        assert image_scale((720, 576), dino) == image_scale(None, dino) == 360.0  # a tolerance of 36 px
        assert image_scale(None, [[100.0, 140.0], [0.0, 60.0]]) == 60.0
        assert image_scale(None, [[1.0, 1.0], [2.0, 2.0]]) is None

    def test_a_turntable_is_flagged_and_its_focal_length_is_wide(self):
        ring = self.stages("ring")[1]["determinacy"]
        sphere = self.stages("sphere")[1]["determinacy"]
        assert "orbital_motion" in codes(ring) and not ring["determined"]
        assert width(ring, "focal_x") > 20 * width(sphere, "focal_x")

    @pytest.mark.parametrize("noise", [0.1, 1.0])
    def test_the_motion_is_read_off_the_infinite_homographies(self, noise):
        from geocert.formulations.autocalibration import determinacy, problem
        from geocert.formulations.autocalibration import metric_relaxation

        found = {}
        for motion in ("ring", "sphere", "translation"):
            for seed in range(4):
                scene = scenes.make_scene((10, 20)[seed % 2], noise, seed=900 + seed, motion=motion)
                prepared = problem.prepare(scene.cameras, scene.points, (1000, 1000), {})
                p = problem.plane_from_input(prepared, scene.plane_at_infinity)
                H = metric_relaxation.homographies(prepared.norm.cameras, prepared.norm.reference, p)
                found.setdefault(motion, []).append([w["code"] for w in determinacy.motion_warnings(H, scene.centres)])
        assert found["ring"] == [["orbital_motion"]] * 4
        assert found["sphere"] == [[]] * 4
        assert found["translation"] == [["pure_translation"]] * 4

    def test_a_translating_camera_is_flagged(self):
        for stage in self.stages("translation"):
            assert "pure_translation" in codes(stage["determinacy"])


class TestStereoLines:
    """A frame pair's motion: intervals from the refinement's curvature, the lines eliminated."""

    @staticmethod
    def pair(rng, noise, lines3d=None):
        from geocert.solvers.lines import scenes as line_scenes

        scene = line_scenes.pair_scene(rng, 40, noise_px=noise, degrees=3.0, metres=0.1)
        if lines3d is not None:
            la, ra = line_scenes.project(scene.rig, lines3d)
            lb, rb = line_scenes.project(scene.rig, lines3d, scene.R, scene.t)
            scene.segments = np.stack([la, ra, lb, rb], axis=1) + rng.normal(scale=noise, size=(len(lines3d), 4, 4))
        rig = scene.rig
        job = {"kind": "stereo_lines", "options": {"solver": "incremental", "sample_size": 3},
               "data": {"rig": {"K_left": rig.K_left.tolist(), "K_right": rig.K_right.tolist(), "R": rig.R.tolist(),
                                "t": rig.t.tolist()}, "matches": [scene.segments.tolist()]}}
        return scene, solve_job(job)["pairs"][0]

    def test_intervals_hold_the_true_motion(self):
        rng = np.random.default_rng(4)
        inside = 0
        for _ in range(8):
            scene, pair = self.pair(rng, 0.5)
            document = pair["determinacy"]
            # Bounded; not `determined`: 40 lines at 0.5 px do not fix a 10 cm step to 10% of itself
            # (test_stereo_translation.py holds the pairs that claim it to it).
            assert all(i["lower"] is not None for i in document["intervals"]), document
            angle = np.degrees(np.arccos((np.trace(scene.R) - 1) / 2))
            truths = {"rotation_angle_deg": angle, "t_x": scene.t[0], "t_y": scene.t[1], "t_z": scene.t[2]}
            inside += sum(interval(document, k)["lower"] <= v <= interval(document, k)["upper"]
                          for k, v in truths.items())
        # 31 of 32 measured (28 with the refinement's lines in Euclidean coordinates, which stopped
        # further short of the optimum): the refined estimate is not quite the unweighted optimum
        # the curvature is taken at (Huber weights, 8 iterations at most)
        assert inside >= 29

    def test_parallel_lines_are_flagged(self):
        rng = np.random.default_rng(5)
        centres = np.c_[rng.uniform(-1.5, 1.5, 40), rng.uniform(-1, 1, 40), rng.uniform(2, 6, 40)]
        direction = np.array([0.0, 1.0, 0.05]) / np.linalg.norm([0.0, 1.0, 0.05])
        lines3d = np.stack([centres - 0.5 * direction, centres + 0.5 * direction], axis=1)
        _, pair = self.pair(rng, 0.5, lines3d)
        if pair["status"] == "estimate":  # or the pair fails, saying why: either way not passed off as fixed
            assert "near_parallel_lines" in codes(pair["determinacy"])
        else:
            assert pair["determinacy"] is None and pair["reason"]


class TestBilinear:
    """A frame's coefficients: intervals hold the truth on well-posed frames; a nearly dependent
    basis is flagged and its coefficients left unbounded or wide."""

    @staticmethod
    def solve(basis, points):
        job = {"kind": "bilinear", "data": {"basis": basis.tolist(), "frames": [{"points": points.tolist()}]},
               "options": {"norm": "L2L2"}}
        return solve_job(job)["frames"][0]

    def test_intervals_hold_the_true_coefficients(self):
        from testing.bilinear import scene

        inside = total = 0
        for seed in range(6):
            basis, points, _, alpha, _ = scene(3, 20, 0.005, 40 + seed)
            document = self.solve(basis, points)["determinacy"]
            assert document["determined"], document
            for k, value in enumerate(alpha):
                found = interval(document, f"coefficient[{k}]")
                inside += found["lower"] <= value <= found["upper"]
                total += 1
        assert inside >= 0.9 * total

    def test_a_nearly_dependent_basis_is_flagged(self):
        from testing.bilinear import scene

        basis, points, *_ = scene(3, 20, 0.005, 50)
        basis[2] = basis[0] + 1e-4 * np.random.default_rng(1).normal(size=basis[0].shape)
        item = self.solve(basis, points)
        document = item["determinacy"]
        assert "near_dependent_basis" in codes(document) and not document["determined"]


class TestTracksMany:
    """fractional.determinacy.tracks_many: for every track the document ``track`` gives."""

    @staticmethod
    def same(a, b) -> bool:
        if isinstance(a, dict):
            return isinstance(b, dict) and a.keys() == b.keys() and all(TestTracksMany.same(a[k], b[k]) for k in a)
        if isinstance(a, list):
            return isinstance(b, list) and len(a) == len(b) and all(TestTracksMany.same(x, y) for x, y in zip(a, b))
        if isinstance(a, float) and isinstance(b, float):
            return abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1e-300)
        return a == b

    def scene(self):
        from geocert.formulations.fractional.results import TrackResult

        rng = np.random.default_rng(7)
        centres = np.array([[0.0, 0, 10], [0.05, 0, 10], [7.0, 0, 7], [10.0, 0, 0], [0.1, 0, 10]])
        cameras = cameras_looking_at_origin(centres)
        affine = cameras[0].copy()
        affine[2] = [0.0, 0.0, 0.0, 1.0]  # a camera whose centre is at infinity
        cameras = np.concatenate([cameras, affine[None]])
        X = np.array([0.3, -0.2, 0.1])
        tracks, results = [], []
        for views in ([0, 1], [0, 1, 4], [0, 2, 3], [2, 3], [5, 2, 3], [0, 1, 2, 3, 4], [1, 2]):
            points = project(cameras[views], X) + rng.normal(size=(len(views), 2))
            tracks.append((views, points))
            point = (X + rng.normal(size=3) * 0.01).tolist()
            # One gap wider than the curvature's delta (track 3's), which then sets the widths.
            lower = -100.0 if views == [2, 3] else 1.999
            results.append(TrackResult("optimal", True, cost=2.0, lower_bound=lower, point=point))
        tracks += [([0, 2], tracks[0][1]), ([0, 3], tracks[0][1]), ([2, 3], tracks[3][1])]
        results += [TrackResult("time_limit", False),  # no point
                    TrackResult("optimal", True, cost=1.0, lower_bound=1.0, point=[0.0, 0.0, 1.0, 0.0],
                                at_infinity=True),
                    TrackResult("optimal", True, cost=1.0, lower_bound=0.5, point=centres[2].tolist())]  # at a centre
        # Rays from a centre at infinity are not compared: one ray left (no warning), or two
        # nearly parallel ones (a warning); and rays meeting on one line (J'J singular along it).
        for views, point in (([5, 2], X), ([5, 0, 1], X), ([0, 3], np.array([5.0, 0.0, 5.0]))):
            tracks.append((views, project(cameras[views], point) + rng.normal(size=(len(views), 2))))
            results.append(TrackResult("optimal", True, cost=2.0, lower_bound=1.999, point=point.tolist()))
        return cameras, tracks, results

    def test_the_same_documents_as_track_by_track(self):
        from geocert.core.determinacy import safely

        cameras, tracks, results = self.scene()
        many = fractional.tracks_many(cameras, tracks, results)
        by_length: dict[int, list] = {}  # the job's squared residuals, pooled as tracks_many pools them
        for (v, p), r in zip(tracks, results):
            if r.point is not None and not r.at_infinity:
                with np.errstate(all="ignore"):
                    by_length.setdefault(len(v), []).append(float(((project(cameras[v], np.array(r.point)) - p) ** 2).sum()))
        pooled = fractional.pooled_increase({n: np.array(c) for n, c in by_length.items()})
        assert fractional.pooled_for(cameras, tracks, results) == pytest.approx(pooled, rel=1e-12)
        alone = [safely(fractional.track, cameras[v], p, r.point, r.at_infinity, r.cost, r.lower_bound, None, pooled)
                 for (v, p), r in zip(tracks, results)]
        assert all(self.same(a, b) for a, b in zip(alone, many)), [i for i, (a, b) in enumerate(zip(alone, many))
                                                                    if not self.same(a, b)]
        # The scene holds what it is meant to: warnings, a missing depth, unbounded intervals, none.
        assert many[7] is None and codes(many[8]) == ["at_infinity"]
        assert "near_zero_parallax" in codes(many[0]) and codes(many[2]) == []
        assert [i["name"] for i in many[4]["intervals"]] == ["x", "y", "z"]  # view 0's centre at infinity
        # at a centre, read at the pooled level: its own level is not finite, so not analysed (review 62)
        assert codes(many[9]) == ["not_analysed"] and many[9]["intervals"] == []
        assert codes(many[10]) == [] and "near_zero_parallax" in codes(many[11])
        assert "near_zero_parallax" in codes(many[12]) and interval(many[12], "x")["lower"] is None


class TestPooledNoise:
    """A track's intervals use the residual variance of the job's tracks together (the image noise is
    the detector's, shared by every track): a track of 2 views estimates it from one degree of
    freedom, and 3 standard errors of that estimate covered the truth about 85% of the time on the
    Dinosaur's cameras, not 99.7% (bench.determinacy --triangulation-only)."""

    @staticmethod
    def scene(rng, views: int, count: int) -> tuple[np.ndarray, np.ndarray, list]:
        """(cameras, true points, tracks): ``count`` points about the origin, each seen by 2 or 3
        of ``views`` random cameras with 0.5 px of noise."""
        cameras = random_cameras(rng, views)
        truth, tracks = rng.normal(size=(count, 3)), []
        for X in truth:
            seen = sorted(rng.choice(views, size=int(rng.integers(2, 4)), replace=False).tolist())
            tracks.append({"views": seen, "points": (project(cameras[seen], X)
                                                     + rng.normal(scale=0.5, size=(len(seen), 2))).tolist()})
        return cameras, truth, tracks

    @staticmethod
    def costs(rng, sigma: float, views: int, count: int) -> np.ndarray:
        return sigma ** 2 * rng.chisquare(2 * views - 3, size=count)

    def test_the_pooled_variance_is_the_noise(self):
        rng = np.random.default_rng(3)
        increase, dof = fractional.pooled_increase({2: self.costs(rng, 0.5, 2, 800), 4: self.costs(rng, 0.5, 4, 200)})
        assert dof > 1500
        assert increase == pytest.approx(9 * 0.25, rel=0.1)  # 3 standard errors: many degrees of freedom

    def test_gross_outliers_are_not_pooled(self):
        rng = np.random.default_rng(4)
        costs = self.costs(rng, 0.5, 3, 500)
        costs[:5] = 1e6  # five tracks a thousand pixels off
        increase, dof = fractional.pooled_increase({3: costs})
        assert increase == pytest.approx(9 * 0.25, rel=0.15) and dof <= 3 * 495

    def test_few_degrees_of_freedom_widen_the_interval(self):
        """One 2-view track: its variance is known from one degree of freedom, so the quantile is
        Student's (about 236 for 3 standard errors' coverage), not 3."""
        increase, dof = fractional.pooled_increase({2: np.array([0.25])})
        assert dof == 1 and increase / 0.25 > 200 ** 2

    def test_nothing_to_pool(self):
        assert fractional.pooled_increase({}) is None
        assert fractional.pooled_increase({1: np.array([0.0])}) is None

    def test_the_intervals_cover_the_truth_as_often_as_they_say(self):
        """1,500 tracks of 2 and 3 views, 0.5 px noise: each coordinate's interval (3 standard
        errors, 99.73% nominal) holds the true point at least 99% of the time; each track's own
        variance alone gave about 88% to 95% on such scenes."""
        cameras, truth, tracks = self.scene(np.random.default_rng(11), 8, 1500)
        items = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": tracks},
                           "options": {}})["tracks"]
        inside = np.array([[interval(item["determinacy"], q)["lower"] is not None
                            and interval(item["determinacy"], q)["lower"] <= x[k] <= interval(item["determinacy"], q)["upper"]
                            for k, q in enumerate("xyz")] for item, x in zip(items, truth)])
        assert inside.mean(axis=0).min() >= 0.99, inside.mean(axis=0)

    @pytest.mark.parametrize("options", [{}, {"max_residual": 5.0}], ids=["convexity", "search"])
    def test_proven_intervals_are_proven_at_the_pooled_level(self, options):
        """Each certified track's proven interval is proven at its determinacy's cost_increase
        (the pooled noise's, for most tracks above their own), whether the convexity bound or a
        search certified it; the result verifies, and each of the 60 proven boxes holds the true
        point (measured: all 60 under either path)."""
        from geocert.verify.checks import verify_any

        cameras, truth, tracks = self.scene(np.random.default_rng(12), 6, 60)
        result = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": tracks},
                            "options": {**options, "certificate": "full"}})
        proven = [(item["determinacy"], x) for item, x in zip(result["tracks"], truth)
                  if item["determinacy"]["proven_intervals"] is not None]
        assert len(proven) >= 50
        raised = 0
        for determinacy, x in proven:
            level = determinacy["proven_intervals"]["cost_increase"]
            assert level >= determinacy["cost_increase"] * (1 - 1e-9)
            raised += determinacy["redundancy"] == 1 and level > 0  # a 2-view track, at the pooled level
            box = {i["name"]: (i["lower"], i["upper"]) for i in determinacy["proven_intervals"]["intervals"]}
            assert all(box[q][0] <= x[k] <= box[q][1] for k, q in enumerate("xyz"))
        assert raised >= 10
        assert verify_any(result).valid


class TestOneTrackJobs:
    """A triangulation job of one 2-view track, as a user sends a single point: its pool is the
    track itself, one degree of freedom, so its level is a noise estimate from one residual, the
    6-point resection's case (issue 37, F3), which the documented rule says determines nothing. On
    main such tracks on the Oxford Dinosaur's 36 projective cameras were `determined` with no
    warning: 0.5 px of noise, eight draws of 800 such jobs, 1,698 determined, 20 of them missing
    the truth (1.2%: 15 of 869 in one set of four draws, 5 of 829 in bench.determinacy
    --lone-tracks's); the same tracks pooled in one job missed 20 of 4,000 (0.5%). Today's form
    warns `few_degrees_of_freedom` and determines none."""

    @staticmethod
    def jobs(count: int, seed: int = 11) -> tuple[list[dict], np.ndarray]:
        cameras, tracks = datasets.load_dinosaur(shared_data("oxford_dinosaur"))
        rng = np.random.default_rng(seed)
        chosen = rng.choice(len(tracks), count, replace=False)
        first = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": [
            {"views": tracks[i].views, "points": tracks[i].points.tolist()} for i in chosen]},
            "options": {"detail": "brief"}})["tracks"]
        truths = np.array([t["point"] for t in first])
        jobs = []
        for i, X in zip(chosen, truths):
            views = tracks[i].views[:2]
            points = project(cameras[views], X) + rng.normal(scale=0.5, size=(2, 2))
            jobs.append({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": [
                {"views": list(map(int, views)), "points": points.tolist()}]}, "options": {}})
        return jobs, truths

    def test_a_lone_two_view_track_warns_and_is_not_determined(self):
        from geocert.verify.checks import verify_any

        jobs, _ = self.jobs(40)
        for job in jobs:
            result = solve_job(job)
            document = result["tracks"][0]["determinacy"]
            assert "few_degrees_of_freedom" in codes(document) and not document["determined"], document
        assert verify_any(solve_job({**job, "options": {"certificate": "full"}})).valid

    def test_the_verifier_requires_the_warning(self):
        """A document of today's form with the warning dropped and `determined` restated is refused
        (the verifier recomputes the track's estimate at the pooled level it states)."""
        from geocert.verify.checks import verify_any

        jobs, _ = self.jobs(1)
        result = solve_job({**jobs[0], "options": {"certificate": "full"}})
        document = result["tracks"][0]["determinacy"]
        document["warnings"] = [w for w in document["warnings"] if w["code"] != "few_degrees_of_freedom"]
        document["determined"] = all(fractional_fixes(i) for i in document["intervals"]) and not document["warnings"]
        assert not verify_any(result).valid

    def test_two_tracks_pool_two_degrees_and_are_judged(self):
        """Two 2-view tracks pool two degrees of freedom: no warning for that, intervals judged."""
        jobs, _ = self.jobs(2)
        job = {**jobs[0], "data": {**jobs[0]["data"], "tracks": jobs[0]["data"]["tracks"] + jobs[1]["data"]["tracks"]}}
        for item in solve_job(job)["tracks"]:
            assert "few_degrees_of_freedom" not in codes(item["determinacy"])


def fractional_fixes(found: dict) -> bool:
    from geocert.core.determinacy import fixes

    return fixes(found)
