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
               metres: float = 0.1, rig: Rig | None = None, depth: tuple[float, float] = (2.0, 6.0)) -> PairScene:
    """Lines matched across a frame pair; an outlier's frame-b views are another 3D line's."""
    rig = rig or thesis_rig()
    R, t = random_motion(rng, degrees, metres)
    X = random_lines(rng, count, depth=depth)
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


def _where_positive(lo: float, hi: float, ca: float, cb: float) -> tuple[float, float]:
    """[lo, hi] narrowed to where ca + s (cb - ca) >= 0 (s in [0, 1]; empty: lo > hi)."""
    if ca < 0 and cb < 0:
        return 1.0, 0.0
    if ca < 0:
        return max(lo, ca / (ca - cb)), hi
    if cb < 0:
        return lo, min(hi, ca / (ca - cb))
    return lo, hi


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
                lo, hi = _where_positive(lo, hi, ca, cb)
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


def corridor_edges(rng, length: float = 40.0, width: float = 2.0, height: float = 2.6, eye: float = 1.3
                   ) -> np.ndarray:
    """(N, 2, 3) the edges of a corridor (camera axes: x right, y down, z along the corridor;
    the rig at the origin, ``eye`` above the floor): its four long edges, door frames on both walls
    (two uprights and a lintel each) and ceiling lights (rectangles) every 1.5 to 3.5 m, and floor
    tiles' joints across the floor every 0.6 m. Most of what a
    corridor shows runs along the walk, parallel to the translation."""
    floor, ceiling, x = eye, eye - height, width / 2
    edges = [((-x, floor, 0.0), (-x, floor, length)), ((x, floor, 0.0), (x, floor, length)),
             ((-x, ceiling, 0.0), (-x, ceiling, length)), ((x, ceiling, 0.0), (x, ceiling, length))]
    z = rng.uniform(0.5, 1.5)
    while z < length - 1:
        side = rng.choice([-x, x])
        top = floor - 2.0
        edges += [((side, floor, z), (side, top, z)), ((side, floor, z + 0.9), (side, top, z + 0.9)),
                  ((side, top, z), (side, top, z + 0.9))]
        z += rng.uniform(1.5, 3.0)
    z = rng.uniform(0.5, 2.0)
    while z < length - 1:  # a ceiling light: 0.6 x 1.2 m
        lo, hi = (-0.3, z), (0.3, z + 1.2)
        edges += [((lo[0], ceiling, lo[1]), (hi[0], ceiling, lo[1])), ((lo[0], ceiling, hi[1]), (hi[0], ceiling, hi[1])),
                  ((lo[0], ceiling, lo[1]), (lo[0], ceiling, hi[1])), ((hi[0], ceiling, lo[1]), (hi[0], ceiling, hi[1]))]
        z += rng.uniform(2.0, 3.5)
    z = 0.6
    while z < length:  # joints across the floor
        edges.append(((-x, floor, z), (x, floor, z)))
        z += 0.6
    return np.array(edges, dtype=float)


def corridor_walk(rng, frames: int = 6, step: float = 0.08, noise_px: float = 0.5, clutter: float = 0.3,
                  near: float = 2.0, far: float = 8.0, jitter_deg: float = 0.2, rig: Rig | None = None
                  ) -> tuple[Rig, list[tuple[np.ndarray, np.ndarray]], list[np.ndarray]]:
    """A rig walking ``step`` a frame down ``corridor_edges`` (turning by ``jitter_deg`` at random
    a frame), and per frame pair the lines matched across its four views: the parts of the
    corridor's edges ``near`` to ``far`` ahead of frame k's rig (the segments 2 to 8 m away),
    ``noise_px`` on the endpoints, and ``clutter`` (a fraction of the lines) matched wrongly (their
    frame k+1 views another line's). Returns the rig, the poses (X_k = R_k X_0 + t_k) and the
    (N, 4, 4) matches of each pair."""
    rig = rig or thesis_rig()
    world = corridor_edges(rng)
    poses = [(np.eye(3), np.zeros(3))]
    for _ in range(frames - 1):
        R = rodrigues(np.radians(jitter_deg) * rng.normal(size=3) / np.sqrt(3))
        t = -R @ np.array([0.0, 0.0, step])  # the world moves back as the rig walks forward
        R0, t0 = poses[-1]
        poses.append((R @ R0, R @ t0 + t))
    pairs = []
    for k in range(frames - 1):
        (Ra, ta), (Rb, tb) = poses[k], poses[k + 1]
        R, t = Rb @ Ra.T, tb - Rb @ Ra.T @ ta  # frame k to frame k+1
        X = world @ Ra.T + ta  # frame k's coordinates
        X = _clip_depth(X, near, far)
        la, ra = project(rig, X)
        lb, rb = project(rig, X, R, t)
        count = len(X)
        bad = rng.choice(count, int(round(clutter * count)), replace=False)
        if len(bad) > 1:  # each wrong match takes the next wrong one's frame k+1 views
            lb[bad], rb[bad] = lb[np.roll(bad, 1)], rb[np.roll(bad, 1)]
        segments = np.stack([la, ra, lb, rb], axis=1) + rng.normal(scale=noise_px, size=(count, 4, 4))
        pairs.append(segments)
    return rig, poses, pairs


def _clip_depth(X: np.ndarray, near: float, far: float) -> np.ndarray:
    """The parts of segments X (N, 2, 3) with depth z within [near, far] (segments outside dropped)."""
    out = []
    for a, b in X:
        lo, hi = 0.0, 1.0
        lo, hi = _where_positive(lo, hi, a[2] - near, b[2] - near)
        lo, hi = _where_positive(lo, hi, far - a[2], far - b[2])
        if hi - lo > 1e-6:
            out.append((a + lo * (b - a), a + hi * (b - a)))
    return np.array(out, dtype=float).reshape(-1, 2, 3)
