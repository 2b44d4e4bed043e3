"""The depth-reversed twin of a metric reconstruction (numpy only).

Under a narrow field of view the cameras are nearly affine, and an affine camera cannot tell a
scene from its mirror image in depth (the Necker reversal; Hartley and Zisserman, "Multiple View
Geometry", 2nd ed., section 14.3, the bas-relief ambiguity beside it): reflect every point in a
plane facing the reference camera, conjugate each relative rotation by that reflection (its angle
is kept, its axis mirrored in the reference camera's frame), and every point keeps its image in
every view up to the perspective that is left. The twin built here is that reflection about the
points' centroid along the reference view's optical axis, each camera's view of the centroid held;
an adjustment from it (the pipeline's) then says whether the observations tell the two apart."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

MIRROR = np.diag([1.0, 1.0, -1.0])


def mirrored(metric, reference: int):
    """The depth-reversed twin of ``metric`` (an upgrade.Metric: rotations, translations, points)
    in view ``reference``'s frame: with W = R_ref^T diag(1, 1, -1) R_ref (the reflection along the
    reference camera's optical axis, in world coordinates) and c the points' centroid, each point X
    goes to c + W (X - c) and each camera R to diag(1, 1, -1) R W (again a rotation), its
    translation keeping the centroid where that camera saw it. Every camera then sees every point
    at the same x and y in its own frame, its depth about the centroid's reversed: the images
    agree exactly for affine cameras, nearly for long lenses. The reference camera is unchanged."""
    finite = np.isfinite(metric.points[:, 0])
    centroid = metric.points[finite].mean(axis=0) if finite.any() else np.zeros(3)
    R_ref = metric.rotations[reference]
    W = R_ref.T @ MIRROR @ R_ref
    rotations, translations = [], []
    for R, t in zip(metric.rotations, metric.translations):
        if R is None:
            rotations.append(None)
            translations.append(None)
            continue
        seen = R @ centroid + t  # the centroid in this camera's frame, kept
        twin = MIRROR @ R @ W
        rotations.append(twin)
        translations.append(seen - twin @ centroid)
    points = metric.points.copy()
    points[finite] = centroid + (metric.points[finite] - centroid) @ W.T
    return replace(metric, rotations=rotations, translations=translations, points=points)


def mirror_angles_deg(rotations: dict[int, np.ndarray], reference: int) -> dict[int, float]:
    """How far each camera of the twin ``mirrored`` builds in view ``reference``'s frame points
    from the camera given, degrees, keyed as ``rotations`` (view: R): the twin's rotation relative
    to the reference, diag(1, 1, -1) Q diag(1, 1, -1), against the given one, Q = R R_ref'. It reads
    the rotations only, so anyone holding the returned cameras recomputes it (the adjustment from
    the twin then moves its cameras a few degrees: 1 to 5 on the long-lens turntables measured)."""
    R_ref = np.asarray(rotations[reference], dtype=float)
    out = {}
    for view, R in rotations.items():
        Q = np.asarray(R, dtype=float) @ R_ref.T
        out[view] = rotation_between_deg(Q, MIRROR @ Q @ MIRROR)
    return out


def rotation_between_deg(A: np.ndarray, B: np.ndarray) -> float:
    """The angle of the rotation taking A to B, degrees."""
    R = A.T @ B
    sine = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.degrees(np.arctan2(sine, 0.5 * (np.trace(R) - 1.0))))
