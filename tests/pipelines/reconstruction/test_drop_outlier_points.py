"""The safety net after the certified triangulation (pipeline._drop_outlier_points), every point's
observations at once: the same verdicts as one point at a time, on points in front, behind, far
off, at infinity and unsolved."""

from types import SimpleNamespace

import numpy as np

from geocert.pipelines.reconstruction.pipeline import Point, _drop_outlier_points


def _one_at_a_time(points, P, threshold_px):
    kept = []
    for point in points:
        r = point.result
        if r.point is None:
            kept.append(point)
            continue
        X = np.array(r.point if r.at_infinity else [*r.point, 1.0])
        image = np.array([P[int(v)] for v, _, _ in point.observations]) @ X
        with np.errstate(divide="ignore", invalid="ignore"):
            error = np.linalg.norm(image[:, :2] / image[:, 2:3] - np.array(point.observations)[:, 1:], axis=1)
        if (not r.at_infinity and np.any(image[:, 2] <= 0)) or not np.all(
                np.nan_to_num(error, nan=np.inf) <= threshold_px * np.sqrt(len(point.observations))):
            continue
        kept.append(point)
    return kept


def _scene(seed=0, n_points=300):
    rng = np.random.default_rng(seed)
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    P = {}
    for v in range(6):
        angle = 0.15 * v
        R = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
        P[v] = K @ np.c_[R, [0.3 * v, 0.0, 5.0]]
    points = []
    for k in range(n_points):
        kind = k % 6
        views = sorted(rng.choice(6, size=int(rng.integers(2, 6)), replace=False).tolist())
        if kind == 5:
            X = np.r_[rng.normal(size=3), 0.0]  # at infinity
        else:
            X = np.r_[rng.normal(size=3), 1.0]
        if kind == 3:
            X[2] = -20.0  # behind every camera
        observations = []
        for v in views:
            x = P[v] @ X
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = x[:2] / x[2] + rng.normal(scale=0.5, size=2)
            if kind == 2 and v == views[-1]:
                uv = uv + 40.0  # one observation far off
            observations.append([v, *np.nan_to_num(uv, nan=1e9, posinf=1e9, neginf=-1e9)])
        if kind == 4 and k % 12 == 4:
            result = SimpleNamespace(point=None, at_infinity=False)  # not solved: kept as it is
        else:
            result = SimpleNamespace(point=(X if kind == 5 else X[:3]).tolist(), at_infinity=kind == 5)
        points.append(Point(track=k, result=result, observations=observations))
    return points, P


def test_the_same_verdicts_as_one_point_at_a_time():
    for seed in range(5):
        points, P = _scene(seed)
        for threshold in (0.5, 1.0, 4.0):
            kept, dropped = _drop_outlier_points(points, P, threshold)
            expected = _one_at_a_time(points, P, threshold)
            assert [p.track for p in kept] == [p.track for p in expected]
            assert dropped == len(points) - len(expected)
            assert 0 < dropped < len(points)


def test_no_solved_point():
    points = [Point(track=0, result=SimpleNamespace(point=None, at_infinity=False), observations=[[0, 1.0, 2.0]])]
    assert _drop_outlier_points(points, {}, 1.0) == (points, 0)
