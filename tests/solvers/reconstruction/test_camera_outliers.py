"""A camera whose certificate fails only on a few gross outlier observations is certified on
the rest (camera_claim.outliers: missed by more than 8 noise scales, at most 5% of its points),
and says how many it set aside; the verifier recomputes the rule from the returned camera and
refuses any other count."""

from __future__ import annotations

import copy

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from geocert.formulations.fractional.options import MapOptions
from geocert.solvers.reconstruction import structure
from geocert.formulations.reconstruction import camera_claim
from geocert.verify.reconstruction import camera_maps
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import refused, stored
from tests.support import loose_gaps


def _scene_with_outliers(seed: int = 0, points: int = 600, outliers: int = 12):
    """A camera K [R | t] (its pose refitted on the inliers, K fixed: what a robust adjustment
    returns), its points and pixels with 0.5 px noise, and ``outliers`` of them in one corner moved 12 px alike (2% of them)."""
    rng = np.random.default_rng(seed)
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    X = rng.uniform([-1, -1, 4], [1, 1, 6], size=(points, 3))
    R0, t0 = Rotation.from_rotvec([0.05, -0.1, 0.02]).as_matrix(), np.array([0.1, -0.2, 0.3])
    proj = (X @ R0.T + t0) @ K.T
    x = proj[:, :2] / proj[:, 2:] + rng.normal(0, 0.5, size=(points, 2))
    bad = np.argsort(X[:, 0] + X[:, 1])[-outliers:]  # one corner's, moved alike (a repeated texture mismatched):
    x[bad] += [12.0, 0.0]  # a free 3x4 camera leans toward them, a pose cannot
    bad = np.sort(bad)
    inliers = np.setdiff1d(np.arange(points), bad)

    def residual(p):
        R = Rotation.from_rotvec(p[:3]).as_matrix() @ R0
        pr = (X[inliers] @ R.T + t0 + p[3:]) @ K.T
        return (pr[:, :2] / pr[:, 2:] - x[inliers]).ravel()

    p = least_squares(residual, np.zeros(6), method="lm").x
    R = Rotation.from_rotvec(p[:3]).as_matrix() @ R0
    return K @ np.column_stack([R, t0 + p[3:]]), X, x, bad


def test_the_rule_sets_aside_only_the_gross_outliers():
    P, X, x, bad = _scene_with_outliers()
    beyond = camera_claim.outliers(X, x, P)
    assert beyond is not None and set(np.flatnonzero(beyond)) == set(bad)
    source, target = X.tolist(), x.tolist()
    kept = camera_claim.kept(source, target, P, len(bad))
    assert kept is not None and len(kept[0]) == len(X) - len(bad)
    assert camera_claim.kept(source, target, P, 0) == (source, target)
    assert camera_claim.kept(source, target, P, len(bad) + 1) is None  # another count is refused
    clean = np.delete(x, bad, axis=0)
    assert camera_claim.outliers(np.delete(X, bad, axis=0), clean, P) is None  # Gaussian noise: none aside


def test_a_camera_with_outlier_observations_is_certified_on_the_rest():
    P, X, x, bad = _scene_with_outliers()
    options = MapOptions(norm="L2L2", rel_gap=1e-2)
    # On every observation a free 3x4 camera leans toward the outliers: no bound could certify it
    Xh = np.hstack([X, np.ones((len(X), 1))])
    cost = float((((Xh @ P.T)[:, :2] / (Xh @ P.T)[:, 2:] - x) ** 2).sum())
    free = structure.free_camera_cost(P, X, x, "L2L2")
    tolerance = camera_claim.tolerance(len(X), camera_claim.POSE_DOF, "L2L2", options.rel_gap)
    assert not camera_claim.within(cost, free, tolerance, options.abs_gap)
    bound = structure._bound_camera(0, P, X, x, options, False, dof=camera_claim.POSE_DOF)
    assert bound.certified and bound.set_aside == len(bad) and bound.points == len(X) - len(bad)
    assert bound.lower_bound <= bound.cost <= (1 + bound.tolerance) * bound.lower_bound


def _with_statement(result: dict) -> dict:
    said = camera_claim.statement(result["norm"], result["camera_certificate"]["options"]["rel_gap"], set_aside=True)
    result["summary"]["camera_claim"] = said
    next(s for s in result["stages"] if s["name"] == "cameras")["claim"] = said
    return result


def test_a_genuine_result_stating_nothing_set_aside_verifies():
    result = stored("reconstruction")
    for camera in result["cameras"]:
        if camera.get("registered") and camera.get("status") != "not_run":
            camera["set_aside"] = 0
    assert verify_any(_with_statement(result)).valid


def test_observations_set_aside_beyond_the_rule_are_refused():
    """A forger drops the three observations a certified camera fits worst, re-solves its
    resection on the rest (a valid resection certificate), and states set_aside 3: the rule
    recomputed from the returned camera sets none aside on these data, so it is refused."""
    from geocert.jobs.runner import solve_job

    result = stored("reconstruction")
    registered = [c for c in result["cameras"] if c.get("registered")]
    searched = [c for c in result["cameras"] if c.get("searched")]
    camera = next(c for c in searched if c["certified"])
    maps = camera_maps(result["points"], searched)
    entry = maps[searched.index(camera)]
    X, x, P = np.array(entry["source"]), np.array(entry["target"]), np.array(camera["P"])
    pr = np.hstack([X, np.ones((len(X), 1))]) @ P.T
    worst = set(np.argsort(np.linalg.norm(x - pr[:, :2] / pr[:, 2:], axis=1))[-3:].tolist())
    entry["source"] = [s for k, s in enumerate(entry["source"]) if k not in worst]
    entry["target"] = [t for k, t in enumerate(entry["target"]) if k not in worst]
    own = result["camera_certificate"]["options"]
    with loose_gaps():
        document = solve_job({"kind": "resection", "data": {"maps": maps},
                              "options": {"norm": own["norm"], "rel_gap": own["rel_gap"], "abs_gap": own["abs_gap"],
                                          "max_residual": own["max_residual"], "certificate": "full"}})["certificate"]
    result["camera_certificate"] = document
    claim = document["items"][searched.index(camera)]
    X, x = np.array(entry["source"]), np.array(entry["target"])
    pr = np.hstack([X, np.ones((len(X), 1))]) @ P.T
    cost = float(((x - pr[:, :2] / pr[:, 2:]) ** 2).sum())
    for c in registered:
        c.setdefault("set_aside", 0)
    camera.update(set_aside=3, points=len(X), cost=cost, lower_bound=claim["lower_bound"],
                  gap=cost - claim["lower_bound"], optimal_cost=claim["cost"],
                  tolerance=camera_claim.tolerance(len(X), camera["degrees_of_freedom"], result["norm"],
                                                   own["rel_gap"]))
    forged = _with_statement(result)
    unstated = copy.deepcopy(forged)
    failure = refused(forged)
    assert failure["check"] == "returned" and "set_aside 3" in str(failure), failure
    unstated["cameras"][unstated["cameras"].index(camera)]["set_aside"] = 0  # the same maps, nothing set aside
    assert refused(unstated)["check"] == "returned"  # its map then is not the returned points
