"""An autocalibration result's metric cameras and points compared with what its upgrade H gives
(problem.metric_cameras, metric_points), each camera and each point at its own scale: the
verifier's, numpy only.

Each recomputed entry is a sum of products of the data and H, and two machines' sums differ by
rounding relative to the magnitudes of the terms summed, not to the result, nor to any other
record. So each entry is read within ROUNDING of the terms it is computed from:

- a point p = Y[:3] / Y[3], Y = H^-1 X: within ROUNDING * (|H^-1| |X|)[:3] + |p| (|H^-1| |X|)[3],
  over |Y[3]| (the terms of Y, dehomogenised);
- a camera's t = K^-1 (P H)[:, 3] and its centre -R' t: within ROUNDING * (|t| + the terms of
  (P H)[:, 3], |P| |H[:, 3]|, over the least singular value of (P H)[:, :3], which is K R up to
  scale); its K within ROUNDING of its largest entry; its R (a rotation: scale 1) within ROUNDING.

A point far from the scene, or a camera far from the others, widens no other record's reading,
and a world of any size is read at its own (the terms shrink with it); a record whose terms
cancel (the reference camera's t, about 0) is read at its terms' size, as its rounding is."""

from __future__ import annotations

from typing import Any

import numpy as np

from geocert.core.strict import Invalid, numbers

ROUNDING = 1e-9  # relative to the terms summed: some 4.5e6 units in the last place, for any machine
CAMERA_FIELDS = ("K", "R", "t", "center")


def _array(value: Any, shape: tuple) -> np.ndarray | None:
    """``value`` as a finite float array of ``shape`` read by the verifier's strict reader (JSON
    numbers only: no strings, booleans or integers too large for a float), or None."""
    try:
        return numbers(value, "value", shape, "returned")
    except Invalid:
        return None


def cameras_close(given: Any, expected: list[dict] | None, cameras: np.ndarray, H: np.ndarray) -> bool:
    """Whether ``given`` (the result's cameras) are ``expected`` (metric_cameras of the data's
    ``cameras`` and ``H``), each camera's fields at that camera's scale."""
    if expected is None or given is None:
        return given is None and expected is None
    if not (isinstance(given, list) and len(given) == len(expected) == len(cameras)):
        return False
    for record, want, P in zip(given, expected, cameras):
        if not (isinstance(record, dict) and set(record) == set(want) == set(CAMERA_FIELDS)):
            return False
        fields = {name: _array(record[name], (3, 3) if name in ("K", "R") else (3,)) for name in CAMERA_FIELDS}
        if any(value is None for value in fields.values()):
            return False
        want = {name: np.asarray(want[name], dtype=float) for name in CAMERA_FIELDS}
        Q = P @ H
        least = np.linalg.svd(Q[:, :3], compute_uv=False)[-1]
        terms = np.linalg.norm(np.abs(P) @ np.abs(H[:, 3]))
        placed = ROUNDING * (np.linalg.norm(want["t"]) + (terms / least if least > 0 else np.inf))
        allowed = {"K": ROUNDING * np.max(np.abs(want["K"])), "R": ROUNDING, "t": placed, "center": placed}
        if not all(np.max(np.abs(fields[name] - want[name])) <= allowed[name] for name in CAMERA_FIELDS):
            return False
    return True


def points_close(given: Any, expected: list | None, points: np.ndarray | None, H: np.ndarray) -> bool:
    """Whether ``given`` (the result's points) are ``expected`` (metric_points of the data's
    ``points`` and ``H``: None for a point sent to infinity), each point at its own terms' scale."""
    if expected is None or given is None or points is None:
        return given is None and expected is None
    if not (isinstance(given, list) and len(given) == len(expected) == len(points)):
        return False
    inverse = np.linalg.inv(H)
    Y = points @ inverse.T
    terms = np.abs(points) @ np.abs(inverse).T
    for value, want, y, size in zip(given, expected, Y, terms):
        if want is None or value is None:
            if not (want is None and value is None):
                return False
            continue
        p = _array(value, (3,))
        if p is None:
            return False
        want = np.asarray(want, dtype=float)
        allowed = ROUNDING * (np.linalg.norm(size[:3]) + np.linalg.norm(want) * size[3]) / abs(y[3])
        if not np.linalg.norm(p - want) <= allowed:
            return False
    return True
