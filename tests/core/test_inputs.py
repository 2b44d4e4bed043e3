"""Bad input names the field and the reason; the solve reports what only it can discover."""

import numpy as np
import pytest

from geocert.core.geometry import InputError
from geocert.jobs.runner import parse_job, solve_job

from tests.support import random_cameras


def job(**changes):
    rng = np.random.default_rng(0)
    cameras = random_cameras(rng, 3).tolist()
    body = {"kind": "triangulation",
            "data": {"cameras": cameras, "tracks": [{"views": [0, 1], "points": [[300.0, 200.0], [310.0, 205.0]]}]},
            "options": {"norm": "L2L2"}}
    for path, value in changes.items():
        target = body
        keys = path.split("__")
        for key in keys[:-1]:
            target = target[int(key)] if key.isdigit() else target[key]
        last = keys[-1]
        target[int(last) if last.isdigit() else last] = value
    return body


class TestParse:
    @pytest.mark.parametrize("changes, field", [
        ({"kind": "nope"}, "kind"),
        ({"data__tracks__0__views": [0]}, "data/tracks/0/views"),
        ({"data__tracks__0__points": [[1.0, 2.0]]}, "data/tracks/0"),
        ({"data__tracks__0__views": [0, 7]}, "data/tracks/0/views/1"),
        ({"data__tracks__0__views": [1, 1]}, "data/tracks/0/views"),
        ({"data__tracks__0__points": [[float("nan"), 1.0], [1.0, 2.0]]}, "data/tracks/0/points/0/0"),
        ({"data__cameras__1": [[1, 0, 0, 0], [2, 0, 0, 0], [0, 0, 1, 0]]}, "data/cameras/1"),
        ({"data__cameras__2": [[1, 0, 0, 0], [0, 1, 0, 0]]}, "data/cameras"),
        ({"data__tracks": []}, "data/tracks"),
        ({"options": {"norm": "L3"}}, "options/norm"),
        ({"options": {"rel_gap": -1}}, "options/rel_gap"),
        ({"options": {"rel_gap": "small"}}, "options/rel_gap"),
        ({"options": {"max_nodes": 1.5}}, "options/max_nodes"),
        ({"options": {"colour": "red"}}, "options/colour"),
        ({"options": {"max_residual": 0}}, "options/max_residual"),
    ])
    def test_error_names_the_field(self, changes, field):
        with pytest.raises(InputError) as error:
            parse_job(job(**changes))
        assert error.value.field == field
        assert error.value.reason


class TestSolveTimeStatuses:
    def test_no_point_in_front_of_every_camera_is_infeasible(self):
        # In front of these three means z > 0, x > 0 and x + z < 0 at once: no such point.
        cameras = [
            [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]],
            [[0, 0, 1, 0], [0, 1, 0, 0], [1, 0, 0, 0]],
            [[0, 1, 0, 0], [1, 0, 0, 1], [-1, 0, -1, 0]],
        ]
        body = {"kind": "triangulation", "data": {"cameras": cameras, "tracks": [
            {"views": [0, 1, 2], "points": [[0.1, 0.2], [0.3, 0.1], [0.2, -0.4]]}]}}
        track = solve_job(body)["tracks"][0]
        # A solver failing to find a point is no proof that none exists: not "infeasible".
        assert track["status"] == "not_certified" and not track["certified"]
        assert "no point in front of every camera was found" in track["reason"]
        assert track["point"] is None

    def test_rays_from_one_centre_are_degenerate_not_wrong(self):
        # Two views from the same centre whose rays disagree: every depth along them fits as
        # badly, so the region within the residual bound is unbounded. Say so in the reason (the
        # status is not_certified: "degenerate" would be a claim the verifier cannot check).
        K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
        c, s = np.cos(0.2), np.sin(0.2)
        R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        cameras = [np.hstack([K, np.zeros((3, 1))]).tolist(), (K @ np.hstack([R, np.zeros((3, 1))])).tolist()]
        body = {"kind": "triangulation", "data": {"cameras": cameras, "tracks": [
            {"views": [0, 1], "points": [[330.0, 250.0], [300.0, 240.0]]}]}}
        track = solve_job(body)["tracks"][0]
        assert track["status"] == "not_certified" and not track["certified"]
        assert "parallel" in track["reason"]
        assert track["lower_bound"] is None

    def test_one_camera_twice_with_one_observation_costs_zero(self):
        P = np.array([[800.0, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]])
        body = {"kind": "triangulation", "data": {"cameras": [P.tolist(), P.tolist()], "tracks": [
            {"views": [0, 1], "points": [[330.0, 250.0], [330.0, 250.0]]}]}}
        track = solve_job(body)["tracks"][0]
        assert track["certified"] and track["cost"] == pytest.approx(0.0, abs=1e-9)


class TestNumberArray:
    """The strict reader checks rows of floats in bulk and any other row entry by entry; either
    way the first offending entry is named."""

    @pytest.mark.parametrize("value, field", [
        ([[1.0, 2.0], [3.0, float("nan")]], "x/1/1"),
        ([[1.0, 2.0], [3.0, float("inf")]], "x/1/1"),
        ([[1.0, 2.0], [3.0, True]], "x/1/1"),
        ([[1.0, 2.0], [3, "4"]], "x/1/1"),
        ([[1.0, 2.0], [3, 2**1100]], "x/1/1"),
        ([[1.0, 2.0], [5e9, 1.0]], "x/1/0"),
    ])
    def test_the_first_bad_entry_is_named(self, value, field):
        from geocert.core.geometry import number_array

        with pytest.raises(InputError) as raised:
            number_array(value, "x", "pairs", 2, limit=1e9)
        assert raised.value.field == field

    def test_good_rows_of_floats_and_ints_are_read(self):
        from geocert.core.geometry import number_array

        array = number_array([[1.0, 2], [3, 4.5]], "x", "pairs", 2, limit=1e9)
        assert array.tolist() == [[1.0, 2.0], [3.0, 4.5]]
        with pytest.raises(InputError, match="rows of one length"):
            number_array([[1.0, 2.0], [3.0]], "x", "pairs", 2)


class TestCameraChecks:
    """check_cameras checks every camera at once: the camera named is the first that fails any
    check, with the first check it fails (non-finite entries before everything else), and the
    cameras it returns are those of normalised_cameras."""

    def cameras(self):
        return np.random.default_rng(3).normal(size=(5, 3, 4))

    @pytest.mark.parametrize("spoil, named", [
        ({1: "depth", 2: "zero", 3: "nan"}, ("cameras/3", "non-finite")),  # finiteness first, over all
        ({1: "depth", 2: "zero"}, ("cameras/1", "rank-deficient")),  # a zero row: rank 2 at most
        ({2: "zero", 3: "rank"}, ("cameras/2", "camera matrix is zero")),
        ({0: "rank", 4: "zero"}, ("cameras/0", "rank-deficient")),
        ({4: "depth"}, ("cameras/4", "rank-deficient")),
    ])
    def test_the_first_failing_camera_and_check_are_named(self, spoil, named):
        from geocert.core.geometry import check_cameras

        cams = self.cameras()
        for index, how in spoil.items():
            if how == "zero":
                cams[index] = 0
            elif how == "depth":
                cams[index, 2] = 0
            elif how == "rank":
                cams[index, 2] = 2 * cams[index, 0] - cams[index, 1]
            else:
                cams[index, 1, 2] = np.nan
        with pytest.raises(InputError) as error:
            check_cameras(cams)
        assert error.value.field == named[0] and named[1] in str(error.value)

    def test_rank_deficiency_quotes_that_cameras_singular_values(self):
        from geocert.core.geometry import check_cameras

        cams = self.cameras()
        cams[3, 2] = cams[3, 0]
        with pytest.raises(InputError) as error:
            check_cameras(cams)
        assert str(np.linalg.svd(cams[3], compute_uv=False).tolist()) in str(error.value)

    def test_cameras_far_from_one_are_scaled_by_powers_of_two_alone(self):
        from geocert.core.geometry import check_cameras, normalised_cameras

        cams = self.cameras()
        cams[1] *= 2.0 ** 200
        cams[3] *= 2.0 ** -200
        cams[4] *= 2.0 ** 60  # near enough to 1: kept as it is
        checked = check_cameras(cams)
        assert np.array_equal(checked, normalised_cameras(cams))
        assert np.array_equal(checked[[0, 2, 4]], cams[[0, 2, 4]])
        for index in (1, 3):
            ratio = checked[index] / cams[index]
            assert np.all(ratio == ratio.flat[0]) and np.frexp(ratio.flat[0])[0] == 0.5  # one power of two
            assert 0.5 <= np.abs(checked[index]).max() < 1
