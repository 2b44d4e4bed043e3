"""Checks of map correspondences that the parser makes before any solve (numpy only)."""

from __future__ import annotations

import math

import numpy as np

from geocert.core.geometry import InputError


def minimum_points(n: int, m: int) -> int:
    """Fewest correspondences that determine the (m+1)(n+1) - 1 degrees of freedom."""
    return math.ceil(((m + 1) * (n + 1) - 1) / m)


def check_correspondences(source: np.ndarray, target: np.ndarray, field_name: str) -> None:
    """Raise InputError for data that cannot determine a general map (and say why)."""
    n, m = source.shape[1], target.shape[1]
    if len(source) != len(target):
        raise InputError(field_name, f"has {len(source)} source points but {len(target)} target points")
    needed = minimum_points(n, m)
    if len(source) < needed:
        raise InputError(f"{field_name}/source", f"a P^{n} -> P^{m} map needs at least {needed} points, got {len(source)}")
    for name, array in (("source", source), ("target", target)):
        bad = np.argwhere(~np.isfinite(array))
        if len(bad):
            raise InputError(f"{field_name}/{name}/{bad[0][0]}", "contains a non-finite number")
    _, first = np.unique(source, axis=0, return_index=True)
    if len(first) < len(source):
        duplicate = sorted(set(range(len(source))) - set(first.tolist()))[0]
        raise InputError(f"{field_name}/source/{duplicate}", "duplicates an earlier source point")
    centred = source - source.mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    if singular[-1] <= 1e-9 * max(singular[0], 1e-300):
        shape = {2: "on one line", 3: "on one plane"}.get(n, "in one hyperplane")
        what = "a general projective camera" if (n, m) == (3, 2) else f"a general P^{n} -> P^{m} map"
        raise InputError(f"{field_name}/source", f"all source points lie {shape}: a degenerate configuration for {what}")
