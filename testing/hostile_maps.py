"""Hostile resection and homography problems and what counts as their refusal, shared by
tests/solvers/fractional/test_hostile_maps.py and bench/hostile_maps.py."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
from scipy.spatial.transform import Rotation

from geocert.solvers.fractional.inputs import minimum_points
from geocert.formulations.fractional.options import MapOptions
from geocert.formulations.fractional.results import claim_of
from geocert.verify import checks as verify


KINDS = ("resection", "homography")


INGREDIENTS = ("flat", "principal", "behind", "outliers", "duplicate", "centroid")


def options_for(norm: str) -> MapOptions:
    return MapOptions(norm=norm, certificate="full", time_limit_s=2.0, max_nodes=300)


def problem(seed: int, index: int) -> dict:
    """Problem ``index`` of ``seed``: kind, ingredients, source (k, n), target (k, 2)."""
    rng = np.random.default_rng([seed, index])
    kind = KINDS[index % 2]
    n = 3 if kind == "resection" else 2
    minimal = minimum_points(n, 2)
    count = minimal + 1 if rng.random() < 0.35 else int(rng.integers(minimal + 2, 25))
    chosen = [name for name in INGREDIENTS if rng.random() < 0.3]
    P = random_camera(rng)
    M = P if n == 3 else P[:, [0, 1, 3]]  # homography: the plane z = 0 seen by the camera
    X = rng.normal(size=(count, n))
    if "flat" in chosen:  # nearly coplanar (resection) or collinear (homography)
        X[:, -1] = rng.normal(size=count) * rng.choice([1e-3, 1e-6])
        if n == 3:  # in a tilted plane, not the one of a coordinate axis
            X = X @ Rotation.random(random_state=rng).as_matrix().T
    if "centroid" in chosen:
        X = np.vstack([X, X.mean(axis=0)])
    if "duplicate" in chosen:
        j = int(rng.integers(len(X)))
        X = np.vstack([X, X[j] + rng.normal(size=n) * rng.choice([1e-12, 1e-8])])
    Xh = np.hstack([X, np.ones((len(X), 1))])
    depth_row = M[2]
    if "principal" in chosen or "behind" in chosen:  # moved along the depth gradient
        j = int(rng.integers(len(X)))
        g = depth_row[:n]
        typical = float(np.median(np.abs(Xh @ depth_row)))
        wanted = typical * (rng.choice([1e-3, 1e-6, 1e-9]) if "principal" in chosen else -rng.uniform(0.1, 1))
        X[j] += (wanted - Xh[j] @ depth_row) * g / (g @ g)
        Xh = np.hstack([X, np.ones((len(X), 1))])
    proj = Xh @ M.T
    with np.errstate(all="ignore"):
        x = proj[:, :2] / proj[:, 2:] + rng.normal(size=(len(X), 2)) * rng.choice([0.01, 1, 30])
    if "outliers" in chosen:
        bad = rng.choice(len(X), size=min(len(X), int(rng.integers(1, 4))), replace=False)
        x[bad] += rng.normal(size=(len(bad), 2)) * 500
    # The same problem in hostile coordinates: similarities of source and target.
    s, a = rng.choice([1e-6, 1e-3, 1, 1e3, 1e6]), rng.choice([1e-6, 1, 1e6])
    source = X * s + rng.normal(size=n) * s * rng.choice([0, 1, 1e3, 1e6])
    target = x * a + rng.normal(size=2) * a * rng.choice([0, 1e3, 1e6])
    target = np.clip(np.nan_to_num(target, posinf=1e8, neginf=-1e8), -1e8, 1e8)
    order = rng.permutation(len(source))
    return {"kind": kind, "ingredients": chosen, "scales": (float(s), float(a)),
            "source": source[order], "target": target[order]}


def refused(kind: str, source, target, result, options: MapOptions) -> str | None:
    """The verifier's reason for refusing this certified result, as the service's document holds it."""
    claim = json.loads(json.dumps(claim_of(result, matrix=result.matrix)))
    try:
        verify.verify_arrays(kind, (np.asarray(source, float), np.asarray(target, float)),
                             dataclasses.asdict(options), claim)
    except verify.Invalid as exc:
        return f"{exc.check}: {exc.detail}"
    return None



def random_camera(rng) -> np.ndarray:
    """A random pinhole camera K [R | -R C] about 8 units from the origin, looking at it."""
    C = rng.normal(size=3) * 2 + np.array([0.0, 0.0, -8.0])
    forward = -C / np.linalg.norm(C)
    right = np.cross(rng.normal(size=3), forward)
    right /= np.linalg.norm(right)
    R = np.vstack([right, np.cross(forward, right), forward])
    R = Rotation.from_rotvec(rng.normal(size=3) * 0.1).as_matrix() @ R
    K = np.diag([rng.uniform(100, 3000)] * 2 + [1.0])
    K[:2, 2] = rng.uniform(0, 1000, 2)
    return K @ np.hstack([R, (-R @ C)[:, None]])
