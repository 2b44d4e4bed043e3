"""Hostile triangulation scenes (tracks built to break a solver) and what counts as their refusal,
shared by tests/solvers/fractional/test_hostile_triangulation.py and bench/hostile_triangulation.py."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
from scipy.spatial.transform import Rotation

from geocert.core.geometry import normalised_cameras
from geocert.formulations.fractional.results import claim_of
from geocert.verify import checks as verify


def scene(seed: int, tracks: int, views: int = 12):
    rng = np.random.default_rng(seed)

    def camera():
        R = Rotation.random(random_state=rng).as_matrix()
        C = rng.normal(size=3) * rng.choice([0.1, 1, 10])
        K = np.diag([rng.uniform(100, 3000)] * 2 + [1.0])
        K[:2, 2] = rng.uniform(0, 1000, 2)
        return K @ np.hstack([R, (-R @ C)[:, None]]) * rng.choice([1, -1, 1e-6, 1e6])

    cameras = np.array([camera() for _ in range(views)])
    out = []
    for _ in range(tracks):
        k = int(rng.choice([2, 2, 3, 4, 6, 9]))
        chosen = sorted(rng.choice(views, k, replace=False).tolist())
        kind = rng.integers(0, 5)
        X = np.append(rng.normal(size=3) * rng.choice([1, 10, 1000, 1e6]), 1.0) if kind != 4 \
            else np.append(rng.normal(size=3), 0.0)
        x = np.einsum("vij,j->vi", cameras[chosen], X)
        with np.errstate(all="ignore"):
            p = x[:, :2] / x[:, 2:] + rng.normal(size=(k, 2)) * rng.choice([0.01, 1, 30])
        if kind == 3:
            p[0] += rng.normal(size=2) * 500
        out.append((chosen, np.clip(np.nan_to_num(p), -1e8, 1e8)))
    return cameras, out


def refused(cameras, views, points, result, options) -> str | None:
    claim = json.loads(json.dumps(claim_of(result, point=result.point, at_infinity=result.at_infinity)))
    try:
        verify.verify_arrays("triangulation", (normalised_cameras(cameras[views]), np.asarray(points, float)),
                             dataclasses.asdict(options), claim)
    except verify.Invalid as exc:
        return str(exc)
    return None
