"""Synthetic stereo line scenes with known motion: the tests', the benchmark's and the kind's
example. A rig like the thesis's (7.4 cm baseline, wide field of view), lines in front of it, and
their segments in the four views of each frame pair (pixels, optional noise on the endpoints)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import Rig, rodrigues

WIDTH, HEIGHT = 640, 480


def thesis_rig(baseline: float = 0.074, focal: float = 320.0) -> Rig:
    """Horizontal baseline, identical cameras, 90 degrees horizontal field of view."""
    K = np.array([[focal, 0, WIDTH / 2], [0, focal, HEIGHT / 2], [0, 0, 1.0]])
    return Rig(K, K.copy(), np.eye(3), np.array([-baseline, 0.0, 0.0]))


def random_lines(rng, count: int, depth=(2.0, 6.0), spread: float = 1.5, length=(0.5, 1.5)) -> np.ndarray:
    """(count, 2, 3) 3D segments (endpoints) in front of the origin."""
    centres = np.column_stack([rng.uniform(-spread, spread, count), rng.uniform(-spread, spread, count) * 0.75,
                               rng.uniform(*depth, count)])
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    half = rng.uniform(*length, count)[:, None] / 2
    return np.stack([centres - half * directions, centres + half * directions], axis=1)


def random_motion(rng, degrees: float = 3.0, metres: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    axis = rng.normal(size=3)
    R = rodrigues(np.radians(degrees) * axis / np.linalg.norm(axis))
    direction = rng.normal(size=3)
    return R, metres * direction / np.linalg.norm(direction)


def project(rig: Rig, X: np.ndarray, R: np.ndarray | None = None, t: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Segments (N, 4) in the left and right images of the 3D segments X (N, 2, 3), after the
    motion (R, t) when given (X_b = R X + t)."""
    if R is not None:
        X = X @ R.T + t
    out = []
    for P in rig.cameras():
        x = np.concatenate([X, np.ones(X.shape[:2] + (1,))], axis=2) @ P.T
        x = x[..., :2] / x[..., 2:]
        out.append(x.reshape(-1, 4))
    return out[0], out[1]


@dataclass
class PairScene:
    rig: Rig
    R: np.ndarray
    t: np.ndarray
    lines3d: np.ndarray  # (N, 2, 3) in frame a
    segments: np.ndarray  # (N, 4, 4): left a, right a, left b, right b (pixels)
    outliers: np.ndarray  # (N,) bool: lines whose frame-b views belong to another line


def pair_scene(rng, count: int, noise_px: float = 0.0, outlier_fraction: float = 0.0, degrees: float = 3.0,
               metres: float = 0.1, rig: Rig | None = None) -> PairScene:
    """Lines matched across a frame pair; an outlier's frame-b views are another 3D line's."""
    rig = rig or thesis_rig()
    R, t = random_motion(rng, degrees, metres)
    X = random_lines(rng, count)
    la, ra = project(rig, X)
    lb, rb = project(rig, X, R, t)
    outliers = np.zeros(count, dtype=bool)
    bad = int(round(outlier_fraction * count))
    if bad:
        outliers[rng.choice(count, bad, replace=False)] = True
        other = random_lines(rng, bad)
        lb[outliers], rb[outliers] = project(rig, other, R, t)
    segments = np.stack([la, ra, lb, rb], axis=1)
    if noise_px:
        segments = segments + rng.normal(scale=noise_px, size=segments.shape)
    return PairScene(rig, R, t, X, segments, outliers)


def sequence(rng, frames: int, count: int, noise_px: float = 0.0, degrees: float = 2.0, metres: float = 0.05,
             rig: Rig | None = None) -> tuple[Rig, list[tuple[np.ndarray, np.ndarray]], list[dict]]:
    """A static scene seen by a moving rig: the poses (X_k = R_k X_0 + t_k) and the segments per
    frame ({"left", "right"}: (N, 4) each, the same line order in every frame, lines behind the
    cameras dropped from no frame: the scene is kept in front)."""
    rig = rig or thesis_rig()
    X = random_lines(rng, count, depth=(3.0, 8.0))
    poses = [(np.eye(3), np.zeros(3))]
    for _ in range(frames - 1):
        R, t = random_motion(rng, degrees, metres)
        R0, t0 = poses[-1]
        poses.append((R @ R0, R @ t0 + t))
    out = []
    for R, t in poses:
        left, right = project(rig, X, R, t)
        if noise_px:
            left = left + rng.normal(scale=noise_px, size=left.shape)
            right = right + rng.normal(scale=noise_px, size=right.shape)
        out.append({"left": left, "right": right})
    return rig, poses, out


def room_of_boxes(rng, boxes: int = 12, size=(8.0, 2.6, 8.0)) -> np.ndarray:
    """(N, 2, 3) the edges of an indoor scene (world coordinates, y down as in the cameras): the
    room's 12 edges, a door frame and a window on the walls, and ``boxes`` boxes on the floor
    (12 edges each) kept away from the room's centre, where the rig moves."""
    w, h, d = size
    edges = []

    def box(lo, hi):
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        for i in range(8):
            for j in range(i + 1, 8):
                if np.sum(corners[i] != corners[j]) == 1:
                    edges.append((corners[i], corners[j]))

    box(np.array([-w / 2, -h / 2, -d / 2]), np.array([w / 2, h / 2, d / 2]))  # the room (floor at y = h/2)
    for x0 in (-1.2, 0.4):  # a door frame and a window on the far wall, shelves on the side walls
        edges += [(np.array([x0, h / 2, d / 2]), np.array([x0, -0.6, d / 2])),
                  (np.array([x0 + 0.9, h / 2, d / 2]), np.array([x0 + 0.9, -0.6, d / 2])),
                  (np.array([x0, -0.6, d / 2]), np.array([x0 + 0.9, -0.6, d / 2]))]
    for z0 in (-2.0, 0.5, 2.5):
        for side in (-1, 1):
            edges.append((np.array([side * w / 2, z0 / 4, z0 - 1.0]), np.array([side * w / 2, z0 / 4, z0 + 0.8])))
    placed = 0
    while placed < boxes:
        centre = rng.uniform([-w / 2 + 0.6, -d / 2 + 0.6], [w / 2 - 0.6, d / 2 - 0.6])
        if np.hypot(*centre) < 2.6:
            continue
        half = rng.uniform(0.2, 0.5, size=3)
        top = h / 2 - 2 * half[1]
        box(np.array([centre[0] - half[0], top, centre[1] - half[2]]),
            np.array([centre[0] + half[0], h / 2, centre[1] + half[2]]))
        placed += 1
    return np.array(edges, dtype=float)


def visible_segments(rig: Rig, X: np.ndarray, R: np.ndarray, t: np.ndarray, near: float = 0.2,
                     min_length_px: float = 15.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parts of the 3D segments X (N, 2, 3; world) in front of both cameras of the rig at pose
    (R, t) (X_cam = R X + t) and inside both images: (left, right, index) with index the 3D segment
    each image segment comes from (the same for left and right: a segment is kept when visible in
    both, clipped in 3D to the part both cameras see)."""
    P_left, P_right = rig.cameras()
    cam = X @ R.T + t  # (N, 2, 3) left camera frame
    keep_left, keep_right, index = [], [], []
    for i, (a, b) in enumerate(cam):
        lo, hi = 0.0, 1.0
        for P in (P_left, P_right):  # clip the parameter range to each camera's near plane and image
            pa, pb = P[:, :3] @ a + P[:, 3], P[:, :3] @ b + P[:, 3]
            # constraints linear in s after multiplying by depth: depth(s) > near, 0 < u < W, 0 < v < H
            for ca, cb in ((pa[2] - near, pb[2] - near), (pa[0], pb[0]), (WIDTH * pa[2] - pa[0], WIDTH * pb[2] - pb[0]),
                           (pa[1], pb[1]), (HEIGHT * pa[2] - pa[1], HEIGHT * pb[2] - pb[1])):
                if ca < 0 and cb < 0:
                    lo, hi = 1.0, 0.0
                elif ca < 0:
                    lo = max(lo, ca / (ca - cb))
                elif cb < 0:
                    hi = min(hi, ca / (ca - cb))
        if hi - lo < 1e-6:
            continue
        p, q = a + lo * (b - a), a + hi * (b - a)
        segments = []
        for P in (P_left, P_right):
            x = np.array([P[:, :3] @ p + P[:, 3], P[:, :3] @ q + P[:, 3]])
            segments.append((x[:, :2] / x[:, 2:]).ravel())
        if min(np.hypot(s[2] - s[0], s[3] - s[1]) for s in segments) < min_length_px:
            continue
        keep_left.append(segments[0])
        keep_right.append(segments[1])
        index.append(i)
    return np.array(keep_left).reshape(-1, 4), np.array(keep_right).reshape(-1, 4), np.array(index, dtype=int)


def room_loop(rng, frames: int = 120, radius: float = 1.2, noise_px: float = 0.0, rig: Rig | None = None,
              boxes: int = 12, take: int | None = None) -> tuple[Rig, list[tuple[np.ndarray, np.ndarray]], list[dict], float]:
    """A rig walking once round a circle in a room of boxes, looking along its path (slightly
    outwards), back to where it started: poses X_k = R_k X_0 + t_k (frame 0's left camera as the
    origin), segments per frame (left, right; visible parts only, with noise on the endpoints),
    and the loop's length. ``take``: only the first so many frames (the tests' short walk)."""
    rig = rig or thesis_rig()
    world = room_of_boxes(rng, boxes)
    world_poses = []
    for k in range(frames + 1 if take is None else min(take, frames + 1)):  # the last frame is the first again
        angle = 2 * np.pi * k / frames
        centre = np.array([radius * np.cos(angle), 0.1 * np.sin(2 * angle), radius * np.sin(angle)])
        heading = angle + np.pi / 2 - 0.3  # tangent, turned slightly outwards
        forward = np.array([np.cos(heading), 0.0, np.sin(heading)])
        down = np.array([0.0, 1.0, 0.0])
        right = np.cross(down, forward)
        R = np.stack([right, down, forward])  # rows: camera axes in the world
        world_poses.append((R, -R @ centre))
    R0, t0 = world_poses[0]
    poses, out = [], []
    for R, t in world_poses:
        poses.append((R @ R0.T, t - R @ R0.T @ t0))  # relative to frame 0
        left, right, ids = visible_segments(rig, world, R, t)
        if noise_px:
            left = left + rng.normal(scale=noise_px, size=left.shape)
            right = right + rng.normal(scale=noise_px, size=right.shape)
        order = rng.permutation(len(left))  # detections come in no particular order
        out.append({"left": left[order], "right": right[order], "ids": ids[order]})  # ids: the room's edge seen
    return rig, poses, out, 2 * np.pi * radius
