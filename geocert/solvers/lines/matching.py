"""Matching segments when only segments are given (no appearance: geometry alone).

Left-right (one stereo frame): a left segment's endpoints give two epipolar lines in the right
image; a right segment matches when the stretch of it between those epipolar lines overlaps it
(the overlap ratio, in [0, 1], at least ``min_overlap``), its orientation is within
``max_stereo_angle_deg`` of the left segment's, and the point it gives the left segment's midpoint
is in front of both cameras. Segments nearly along the epipolar lines (within
``min_epipolar_angle_deg``) are not matched: the stereo pair cannot place them. The cost
(1 - overlap + angle / max angle) is minimised over one-to-one assignments (Hungarian method,
scipy's linear_sum_assignment), and a match is dropped when another candidate of either segment
costs within ``ambiguity_margin`` of it (nearby parallel segments at other depths, which geometry
alone cannot tell apart).

Frame to frame (left images): a nearest-neighbour tracker on the segments' geometry: a segment of
frame b is a candidate for one of frame a when their orientations differ by at most
``max_track_angle_deg`` and its midpoint lies within ``max_track_px`` of frame a's segment's line
and of its midpoint (``2 max_track_px``); the cost (normalised distance and angle) is minimised
over one-to-one assignments. A line seen in the four views is a left-a segment tracked to a left-b
segment, both with a stereo match, whose right segments are tracked to each other too.

Matching compares every pair of segments (cubic in the assignment): with ``should_stop`` it asks
the clock between blocks of rows of the costs and before each assignment, and raises
``MatchingStopped`` when told to stop, so that a pair keeps its time limit whatever its segments.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import linear_sum_assignment

from geocert.core.declared_options import DeclaredRanges, option
from geocert.solvers.lines.geometry import Rig, cross, skew

_BIG = 1e6
_BLOCK = 1 << 18  # pairs of segments costed at a time between clock checks (a few MB of arrays)


class MatchingStopped(Exception):
    """``should_stop`` said to stop before the matching was done."""


def _check(should_stop: Callable[[], bool] | None) -> None:
    if should_stop is not None and should_stop():
        raise MatchingStopped


@dataclass
class MatchingOptions:
    min_overlap: float = option(0.5, ge=0, le=1)
    max_stereo_angle_deg: float = option(20.0, gt=0, le=90)
    min_epipolar_angle_deg: float = option(5.0, ge=0, lt=90)
    max_track_px: float = option(60.0, gt=0, le=10_000)
    max_track_angle_deg: float = option(10.0, gt=0, le=90)
    # track again with the first estimate's rotation, and estimate again
    guided: bool = option(True, description="track again with the first estimate's rotation and estimate again "
                                            "(segments only)")
    # > 0: a stereo match is dropped when a rival's cost is within this of its own
    ambiguity_margin: float = option(0.0, ge=0, le=10, description=(
        "drop a stereo match whose rival costs within this of it (0: off)"))

    OPTION_RANGES = DeclaredRanges()


def fundamental(rig: Rig) -> np.ndarray:
    """F with x_right^T F x_left = 0."""
    return np.linalg.inv(rig.K_right).T @ skew(rig.t) @ rig.R @ np.linalg.inv(rig.K_left)


def _homogeneous(points: np.ndarray) -> np.ndarray:
    return np.concatenate([points, np.ones(points.shape[:-1] + (1,))], axis=-1)


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, M) angles (degrees, 0..90) between the orientations of segments a (N, 4) and b (M, 4)."""
    da = a[:, 2:] - a[:, :2]
    db = b[:, 2:] - b[:, :2]
    da = da / np.linalg.norm(da, axis=1, keepdims=True)
    db = db / np.linalg.norm(db, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.abs(da @ db.T), 0.0, 1.0)))


def stereo_matches(rig: Rig, left: np.ndarray, right: np.ndarray, options: MatchingOptions,
                   should_stop: Callable[[], bool] | None = None) -> np.ndarray:
    """(K, 2) index pairs (left, right) of matched segments."""
    if len(left) == 0 or len(right) == 0:
        return np.zeros((0, 2), int)
    F = fundamental(rig)
    rows = max(1, _BLOCK // len(right))
    blocks = []
    for begin in range(0, len(left), rows):
        _check(should_stop)
        blocks.append(_stereo_costs(rig, F, left[begin:begin + rows], right, options))
    cost = np.concatenate(blocks)
    _check(should_stop)
    pairs = _assign(cost)
    if options.ambiguity_margin > 0 and len(pairs):
        # Ambiguous: another candidate nearly as good for either segment (nearby parallel segments
        # at other depths): a wrong match there is a wrong 3D line that small motions cannot expose.
        chosen = cost[pairs[:, 0], pairs[:, 1]]
        rival = cost.copy()
        rival[pairs[:, 0], pairs[:, 1]] = _BIG
        second = np.minimum(rival[pairs[:, 0]].min(axis=1), rival[:, pairs[:, 1]].min(axis=0))
        pairs = pairs[second > chosen + options.ambiguity_margin]
    return pairs


def _stereo_costs(rig: Rig, F: np.ndarray, left: np.ndarray, right: np.ndarray, options: MatchingOptions) -> np.ndarray:
    """(N, M) costs of matching left segments to right ones (_BIG where not allowed)."""
    a0, a1 = _homogeneous(left[:, :2]), _homogeneous(left[:, 2:])
    e0, e1 = a0 @ F.T, a1 @ F.T  # (N, 3) epipolar lines in the right image
    c0, c1 = right[:, :2], right[:, 2:]
    m = cross(_homogeneous(c0), _homogeneous(c1))  # (M, 3) right segments' lines
    # Where each epipolar line meets each right segment's line, as a parameter along the segment.
    span = c1 - c0
    length2 = (span * span).sum(axis=1)

    def parameter(e: np.ndarray) -> np.ndarray:
        p = cross(m[None, :, :], e[:, None, :])  # (N, M, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = p[..., 0] / p[..., 2], p[..., 1] / p[..., 2]
            return ((x - c0[:, 0]) * span[:, 0] + (y - c0[:, 1]) * span[:, 1]) / length2

    s0, s1 = parameter(e0), parameter(e1)
    lo, hi = np.minimum(s0, s1), np.maximum(s0, s1)
    overlap = (np.minimum(hi, 1.0) - np.maximum(lo, 0.0)) / (np.maximum(hi, 1.0) - np.minimum(lo, 0.0))
    # The right segment's angle to the epipolar lines of the left segment.
    epi_dir_right = np.stack([e0[:, 1], -e0[:, 0]], axis=1)
    epi_dir_right /= np.linalg.norm(epi_dir_right, axis=1, keepdims=True)
    span_unit = span / np.sqrt(length2)[:, None]
    epipolar_angle = np.degrees(np.arcsin(np.clip(np.abs(
        span_unit[None, :, 0] * epi_dir_right[:, None, 1] - span_unit[None, :, 1] * epi_dir_right[:, None, 0]),
        0.0, 1.0)))
    angle = _angles(left, right)
    # The left midpoint's partner on the right segment's line, triangulated: depth > 0 in both views.
    midpoint = (a0 + a1) / 2
    e_mid = midpoint @ F.T
    q = cross(m[None, :, :], e_mid[:, None, :])  # (N, M, 3) homogeneous right points
    depth_ok = _positive_depths(rig, midpoint, q)
    cost = 1.0 - overlap + angle / options.max_stereo_angle_deg
    allowed = (np.nan_to_num(overlap, nan=-1.0) >= options.min_overlap) & (angle <= options.max_stereo_angle_deg) \
        & (epipolar_angle >= options.min_epipolar_angle_deg) & depth_ok
    return np.where(allowed, cost, _BIG)


def _positive_depths(rig: Rig, x_left: np.ndarray, x_right: np.ndarray) -> np.ndarray:
    """(N, M) whether the left points (N, 3) and right points (N, M, 3) triangulate in front of
    both cameras (midpoint method on the normalised rays)."""
    ray_l = x_left @ np.linalg.inv(rig.K_left).T  # (N, 3), left frame
    with np.errstate(divide="ignore", invalid="ignore"):
        ray_r = x_right @ (np.linalg.inv(rig.K_right).T @ rig.R)  # right rays in the left frame (R^T r)
        ray_r = ray_r * np.sign(x_right[..., 2:])  # homogeneous sign: a ray, not its opposite
    centre_r = -rig.R.T @ rig.t
    # Solve a ray_l - b ray_r = centre_r in least squares for every pair (the (N, M) products as
    # matrix products: numpy's sums over a last axis of 3 are slow).
    uu = (ray_l * ray_l).sum(axis=1)[:, None]
    uc = (ray_l @ centre_r)[:, None]
    vv = (ray_r[..., None, :] @ ray_r[..., :, None])[..., 0, 0]
    uv = (ray_r @ ray_l[:, :, None])[..., 0]
    vc = ray_r @ centre_r
    det = uu * vv - uv * uv
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (vv * uc - uv * vc) / det
        b = (uv * uc - uu * vc) / det
    return (np.nan_to_num(a, nan=-1.0) > 0) & (np.nan_to_num(b, nan=-1.0) > 0)


def track(a: np.ndarray, b: np.ndarray, options: MatchingOptions,
          should_stop: Callable[[], bool] | None = None) -> np.ndarray:
    """(K, 2) index pairs (segment of frame a, segment of frame b) in one image."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros((0, 2), int)
    _check(should_stop)
    line_a = cross(_homogeneous(a[:, :2]), _homogeneous(a[:, 2:]))
    line_a /= np.linalg.norm(line_a[:, :2], axis=1, keepdims=True)
    mid_a = (a[:, :2] + a[:, 2:]) / 2
    mid_b = (b[:, :2] + b[:, 2:]) / 2
    perpendicular = np.abs(line_a[:, :2] @ mid_b.T + line_a[:, 2:3])  # (N, M)
    travel = np.hypot(mid_a[:, None, 0] - mid_b[None, :, 0], mid_a[:, None, 1] - mid_b[None, :, 1])
    angle = _angles(a, b)
    cost = perpendicular / options.max_track_px + travel / (4 * options.max_track_px) \
        + angle / options.max_track_angle_deg
    allowed = (perpendicular <= options.max_track_px) & (travel <= 2 * options.max_track_px) \
        & (angle <= options.max_track_angle_deg)
    _check(should_stop)
    return _assign(np.where(allowed, cost, _BIG))


def _assign(cost: np.ndarray) -> np.ndarray:
    rows, cols = linear_sum_assignment(cost)
    keep = cost[rows, cols] < _BIG
    return np.column_stack([rows[keep], cols[keep]]).astype(int)


def rotated(segments: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Segments (N, 4) moved by the homography H (3x3)."""
    ends = _homogeneous(segments.reshape(-1, 2)) @ H.T
    return (ends[:, :2] / ends[:, 2:]).reshape(-1, 4)


STEREO_CACHE = "stereo_matches"  # the frame's member keeping its left-right matches


def frame_stereo_matches(rig: Rig, frame: dict, options: MatchingOptions,
                         should_stop: Callable[[], bool] | None = None) -> np.ndarray:
    """stereo_matches of a frame ({"left", "right"}), made once and kept in the frame (under
    ``STEREO_CACHE``, with what they depend on): every frame of a sequence is matched left to right
    in two frame pairs, each twice when guided, and that matching is half the cost of a pair."""
    made_of = (rig, frame["left"], frame["right"])  # the very objects (compared by identity)
    settings = (options.min_overlap, options.max_stereo_angle_deg, options.min_epipolar_angle_deg,
                options.ambiguity_margin)
    kept = frame.get(STEREO_CACHE)
    if kept is not None and all(a is b for a, b in zip(kept[0], made_of)) and kept[1] == settings:
        return kept[2]
    pairs = stereo_matches(rig, frame["left"], frame["right"], options, should_stop)
    frame[STEREO_CACHE] = (made_of, settings, pairs)
    return pairs


def four_view_matches(rig: Rig, frame_a: dict, frame_b: dict, options: MatchingOptions,
                      rotation: np.ndarray | None = None,
                      should_stop: Callable[[], bool] | None = None) -> np.ndarray:
    """(K, 4) indices [left a, right a, left b, right b] of the lines seen in the four views.

    With ``rotation`` (the frame pair's R, e.g. a first estimate's), frame a's segments are first
    moved by the rotation's homographies (K R K^-1 in the left image, K_r R0 R R0^T K_r^-1 in the
    right): the tracker then only bridges the translation's parallax, and its preference for
    small image motion no longer pulls the matches, and the motion, towards a smaller rotation."""
    left_a, right_a = frame_a["left"], frame_a["right"]
    if rotation is not None:
        left_a = rotated(left_a, rig.K_left @ rotation @ np.linalg.inv(rig.K_left))
        right_a = rotated(right_a, rig.K_right @ rig.R @ rotation @ rig.R.T @ np.linalg.inv(rig.K_right))
    stereo_a = dict(map(tuple, frame_stereo_matches(rig, frame_a, options, should_stop)))
    stereo_b = dict(map(tuple, frame_stereo_matches(rig, frame_b, options, should_stop)))
    right_track = dict(map(tuple, track(right_a, frame_b["right"], options, should_stop)))
    # A line is kept when the right images' tracker agrees with the left's (the loop left a ->
    # left b -> right b closes through right a): one check that removes most of the
    # appearance-free matcher's confusions between nearby parallel segments.
    quads = [(i, stereo_a[i], j, stereo_b[j]) for i, j in track(left_a, frame_b["left"], options, should_stop)
             if i in stereo_a and j in stereo_b and right_track.get(stereo_a[i]) == stereo_b[j]]
    return np.array(quads, dtype=int).reshape(-1, 4)
