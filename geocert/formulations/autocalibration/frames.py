"""The frames of stratified autocalibration, in numpy only (the verifier rebuilds them).

* Image coordinates are preconditioned by ``N = K0^-1`` (K0: the middle of the intrinsics
  ranges), so that the calibration sought is near the identity (thesis 6.7 works with K = I).
* The reference camera (the lowest-indexed of the best conditioned left 3x3 blocks, reference_camera)
  is moved to ``[I | 0]`` by ``T0``;
  there the plane at infinity is ``(p, 1)`` (thesis 6.2) and view j's infinite homography is
  ``H_j = A_j - a_j p^T``, whose characteristic polynomial has coefficients affine in p (3.5, 6.2.2).
* Chirality (thesis 3.5, 6.2.3; Hartley 1998): with points and cameras sign-normalised so that
  depths are positive, the plane at infinity has the same sign on every point and, up to one
  unknown orientation ``delta``, on every signed camera centre. A quasi-affine frame ``G`` makes
  those rows have positive last coordinates; centred and scaled there, the plane at infinity is
  ``(v, 1)`` with ``v . x_k + 1 >= 0`` for every row: a polytope, boxed by six linear programs.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from geocert.core.geometry import InputError


@dataclass
class Normalised:
    """The reconstruction in the reference frame: ``cameras[i] = s_i N P_i T0`` (unit scale,
    the reference exactly [I | 0]), ``points[j] = T0^-1 X_j`` (unit norm), signs applied."""

    cameras: np.ndarray  # (m, 3, 4)
    points: np.ndarray | None  # (n, 4), sign-normalised
    reference: int
    T0: np.ndarray  # 4x4: input frame -> reference frame is X -> T0^-1 X; cameras P -> P T0
    N: np.ndarray  # 3x3 image preconditioner
    camera_signs: np.ndarray  # (m,)
    # The power of two the preconditioned reference camera N P_ref was multiplied by before T0 was
    # built from it (unit_reference_scale); None where the reference was taken at the scale given.
    reference_scale: float | None = None
    # unit_reference_scale of the preconditioned reference as given, whichever frame was built:
    # how far the reference as given lies from unit scale (earlier_frame_readable).
    reference_unit_scale: float = 1.0
    # The power of two the frame's fourth coordinate was scaled by (world_unit_scale: the cameras'
    # last columns in the reference frame times it); None where the world was taken at the scale given.
    world_scale: float | None = None
    # The other cameras' median ||a_j|| / ||A_j|| in the reference frame before world_scale: how far
    # the world as given lies from unit scale (world_scale_fits, earlier_world_readable).
    world_ratio: float = 1.0
    # The largest of those ratios (0 where there is no other camera): the farthest camera, which a
    # median over views near the reference does not see (earlier_world_readable; review 55).
    world_ratio_highest: float = 0.0


# Cameras and points are homogeneous: any scale is the same camera or point. At extreme scales the
# solve fails or overflows (the stored stratified scene, entries about 0.75: its cameras times 2^-20
# or 2^40 failed, times 2^600 overflowed to a scipy error). Each camera or point whose largest entry
# lies outside [2^SMALLEST_EXPONENT, 2^LARGEST_EXPONENT) is brought to unit size by a power of two,
# which is exact. Ordinary scales (normalised cameras near 1, pixel cameras up to about 1e8) are
# left as given: the normalised frame depends on the reference camera's scale (another, equivalent
# frame), and documents written before must be read in the frame they were written in.
SMALLEST_EXPONENT = -12
LARGEST_EXPONENT = 28


def unit_scaled(arrays: np.ndarray) -> np.ndarray:
    """Each of ``arrays`` (cameras (n, 3, 4) or points (n, 4)) whose largest entry lies outside
    [2^SMALLEST_EXPONENT, 2^LARGEST_EXPONENT) divided by the power of two that brings that entry
    into [0.5, 1)."""
    arrays = np.asarray(arrays, dtype=float)
    axes = tuple(range(1, arrays.ndim))
    _, exponent = np.frexp(np.abs(arrays).max(axis=axes))
    exponent = np.where((exponent <= SMALLEST_EXPONENT) | (exponent > LARGEST_EXPONENT), exponent, 0)
    return np.ldexp(arrays, -exponent.reshape((-1,) + (1,) * len(axes)))


def signed_centre(P: np.ndarray) -> np.ndarray:
    """The cofactor 4-vector c with P c = 0 and c[3] = det(P[:, :3]): for a real camera
    M [I | -C], c = det(M) (C, 1), so its sign carries the camera's orientation."""
    c = np.empty(4)
    for k in range(4):
        c[k] = (-1) ** (k + 1) * np.linalg.det(np.delete(P, k, axis=1))
    return c


def conditioning(cameras: np.ndarray) -> np.ndarray:
    """Each camera's left 3x3 block's smallest singular value over its largest."""
    s = np.linalg.svd(cameras[:, :, :3], compute_uv=False)
    return s[:, 2] / s[:, 0]


# Cameras conditioned within this fraction of the best are tied for the reference: an exact scene's
# cameras (a ring of one K) are conditioned alike to their last digits, which another machine's
# LAPACK rounds differently, so "the best conditioned" is a choice of the rounding, and on noisy
# data each camera's frame poses its own problem (the modulus constraints leave the reference's
# view out and weight the others by their frame). The reference is therefore the lowest-indexed of
# the tied cameras: a function of the data that no machine's rounding decides, except for a camera
# whose conditioning lies on the tie's edge (within REFERENCE_TIE_BAND of it), which
# reference_candidates names.
REFERENCE_TIE = 1e-9
REFERENCE_TIE_BAND = 0.5  # the edge's width, relative to REFERENCE_TIE


def _tied(ratio: np.ndarray, tie: float) -> np.ndarray:
    return np.flatnonzero(ratio >= ratio.max() * (1.0 - tie))


def reference_camera(cameras: np.ndarray) -> int:
    """The camera moved to [I | 0]: the lowest-indexed of those whose left 3x3 block is conditioned
    within REFERENCE_TIE of the best."""
    return int(_tied(conditioning(cameras), REFERENCE_TIE)[0])


def reference_candidates(cameras: np.ndarray, N: np.ndarray) -> list[int]:
    """The references normalise(cameras, ., N) may take on any machine, ascending: reference_camera's
    choice, and any lower-indexed camera on the tie's edge (one, where none is: the usual case)."""
    ratio = conditioning(np.einsum("ab,ibc->iac", N, unit_scaled(cameras)))
    wide = _tied(ratio, REFERENCE_TIE * (1.0 + REFERENCE_TIE_BAND))
    first_surely_tied = int(_tied(ratio, REFERENCE_TIE * (1.0 - REFERENCE_TIE_BAND))[0])
    return [int(i) for i in wide if i <= first_surely_tied]


# How far apart two cameras' conditioning may be and a machine's SVD still rank them either way: an
# earlier writer took the best conditioned (np.argmax), which rounding decides only among cameras
# this close (the ratios round at about 1e-15 of themselves; review 35 had an unnamed proof accepted
# in the frame of a camera 1.2e-9 below the best, which no earlier writer could have taken).
EARLIER_TIE = 1e-12


def earlier_references(cameras: np.ndarray, N: np.ndarray) -> list[int]:
    """The frames a proof naming no reference may be posed in: it was written when the reference was
    the best conditioned camera, which a machine's rounding chooses among those within EARLIER_TIE;
    best first."""
    ratio = conditioning(np.einsum("ab,ibc->iac", N, unit_scaled(cameras)))
    close = _tied(ratio, EARLIER_TIE)
    return [int(i) for i in close[np.argsort(-ratio[close], kind="stable")]]


# A projective camera is homogeneous: the reference camera times s is the same input, but T0 built
# from it is [[A^-1 / s, -A^-1 a], [0, 1]], which scales the frame's first three coordinates, and
# so the plane at infinity's p, by s. The stratified stages' branch and bound, chirality box and
# tolerances are not invariant under that: on the stored stratified scene, its reference times
# 2^28 (inside unit_scaled's range, so left as given) had a K 4,250 px off certified. The
# stratified method therefore builds T0 from the preconditioned reference divided by the power of
# two that brings its largest entry into [0.5, 1): exact, a function of the data (the verifier
# recomputes it, no document chooses it), and the same frame for the camera times any power of
# two (times any other factor, a frame at most a factor 2 away). The direct method keeps the frame
# given: its trace-one normalisation moves with the world's scale too, and its answers were
# established in that frame.
def unit_reference_scale(camera: np.ndarray) -> float:
    """The power of two that brings ``camera``'s largest entry into [0.5, 1)."""
    _, exponent = np.frexp(np.abs(camera).max())
    return float(np.ldexp(1.0, -int(exponent)))


# A stratified proof written before proofs stated reference_scale is posed in the reference as
# given, whose scale the writer did not choose: the failure the unit reference frame mends can be
# certified in it. Written that way (the reference as given) on the stored stratified scene, its
# reference times 2^k (the preconditioned reference's largest entry in [2^(k-10), 2^(k-9))): K
# within 4e-4 px of the truth up to k = 18 (the optimum lies 1.4e-4 px from it), then 0.03 px off
# (k = 19), 0.34 px (k = 20), and 4,250 px off certified and verified (k = 28); scaled down,
# nothing moved (to unit_scaled's floor, below which the camera is unit-scaled anyway). Such a
# proof is read in its given frame only where that frame is well scaled, the preconditioned
# reference's largest entry below 2^EARLIER_FRAME_EXPONENT (twice k = 17's, a factor 4 short of
# the first K moved), and refused otherwise (proofs.check_earlier_frame). The stored
# certificates' references lie in [2^-10, 2^-9) and [1, 2).
EARLIER_FRAME_EXPONENT = 8


def earlier_frame_readable(norm: Normalised) -> bool:
    """Whether an earlier writer's proof (no reference_scale: the reference as given) may be read
    in this problem's frame as given: its preconditioned reference's largest entry below
    2^EARLIER_FRAME_EXPONENT (reference_unit_scale at least 2^-EARLIER_FRAME_EXPONENT)."""
    return norm.reference_unit_scale >= 2.0 ** -EARLIER_FRAME_EXPONENT


# The unit reference frame fixes the reference camera's scale, not the world's: with the reference
# at [I | 0], the gauge left is X -> diag(1, 1, 1, 1/lambda) X, which keeps the reference and
# multiplies every other camera's last column a_j by lambda (and the plane at infinity's p by
# 1/lambda). A writer chooses lambda freely (the reference's centre at the origin and the fourth
# coordinate times k), and the stages' box, tolerances and each camera's Frobenius normalisation
# (which shrinks A_j as a_j grows) are not invariant under it: on the stored stratified scene,
# k = 2^28 had a K 397 px off certified and verified. The stratified method therefore scales the
# fourth coordinate by the power of two that brings the other cameras' median ||a_j|| / ||A_j||
# (their distance from the reference, in its frame) into [2^(WORLD_EXPONENT - 1), 2^WORLD_EXPONENT):
# a function of the data, stated in proofs as world_scale and recomputed by the verifier. The
# octave is the geometric middle of the ratios over which the stored scene, solved in its world as
# given, kept K within 3e-4 px (1.1e-6 to 301, EARLIER_WORLD_LOWEST below); nearer 1 the search
# slowed (review 33's tied scene's affine stage: 1,141 nodes at [2^-6, 2^-5), its node limit at
# [2^-4, 2^-3) and [0.5, 1); a 12-view ring: 17 s at [0.5, 1), 9 s at [2^-5, 2^-4)). Norms and a
# median of products round differently on another machine, so a stated scale is taken where it
# brings the data's ratio into the octave within WORLD_SCALE_TOLERANCE (world_scale_fits): one
# power of two, or its neighbour where the ratio lies on the octave's edge.
WORLD_EXPONENT = -5
WORLD_SCALE_TOLERANCE = 1e-9


def world_ratio(cameras: np.ndarray, reference: int) -> float:
    """The median over the cameras other than ``reference`` of ||a_j|| / ||A_j|| (cameras in the
    reference's frame, [A_j | a_j]); 1 where there is no other camera or the median is not a
    positive finite number (every centre the reference's: no scale to fix)."""
    others = np.delete(cameras, reference, axis=0)
    if not len(others):
        return 1.0
    ratio = float(np.median(np.linalg.norm(others[:, :, 3], axis=1) / np.linalg.norm(others[:, :, :3], axis=(1, 2))))
    return ratio if np.isfinite(ratio) and ratio > 0.0 else 1.0


def world_ratio_highest(cameras: np.ndarray, reference: int) -> float:
    """The largest over the cameras other than ``reference`` of ||a_j|| / ||A_j|| (cameras in the
    reference's frame); 0 where there is no other camera, inf where one is not finite."""
    others = np.delete(cameras, reference, axis=0)
    if not len(others):
        return 0.0
    with np.errstate(all="ignore"):
        ratios = np.linalg.norm(others[:, :, 3], axis=1) / np.linalg.norm(others[:, :, :3], axis=(1, 2))
    return float(np.max(np.where(np.isnan(ratios), np.inf, ratios)))


def world_unit_scale(ratio: float) -> float:
    """The power of two that brings ``ratio`` into [2^(WORLD_EXPONENT - 1), 2^WORLD_EXPONENT)."""
    _, exponent = np.frexp(ratio)
    return float(np.ldexp(1.0, WORLD_EXPONENT - int(exponent)))


def world_scale_fits(scale: float, ratio: float) -> bool:
    """Whether ``scale`` (a stated world_scale) is a power of two that brings the data's ``ratio``
    into [2^(WORLD_EXPONENT - 1), 2^WORLD_EXPONENT) within WORLD_SCALE_TOLERANCE (another machine's
    rounding of the ratio)."""
    mantissa, _ = np.frexp(scale)
    top = 2.0 ** WORLD_EXPONENT
    return bool(scale > 0.0 and np.isfinite(scale) and mantissa == 0.5
                and 0.5 * top * (1.0 - WORLD_SCALE_TOLERANCE) <= scale * ratio < top * (1.0 + WORLD_SCALE_TOLERANCE))


# A proof written before proofs stated world_scale (the world as given) is read only where the world
# as given is near enough unit scale, the data's world_ratio in [2^EARLIER_WORLD_LOWEST,
# 2^EARLIER_WORLD_HIGHEST) (proofs.check_earlier_frame). Written that way on the stored stratified
# scene with its fourth coordinate times 2^k (its ratio 2^-9.8 at k = 0): K within 3e-4 px of the
# truth from ratio 1.1e-6 to 301, 0.89 px off at 1.2e3, 293 px at 1.9e4 (the metric stage at its
# clock), and 397 px off certified and verified at 3.1e5 (review 54); below 1e-9 nothing was
# certified. The upper limit is a factor 4 short of the first K moved; the stored certificates lie
# at 2^-10. The median alone is a vote a forger wins by adding views: review 55 put that scene's
# cameras at 2^18 with six views of the same K translated 2^6 from the reference (the median 34,
# inside the limit), and an earlier writer's proofs certified a K 399 px off that verified. Every
# other camera, the farthest too (world_ratio_highest), must therefore lie below the upper limit.
EARLIER_WORLD_LOWEST = -20
EARLIER_WORLD_HIGHEST = 8


def earlier_world_readable(norm: Normalised) -> bool:
    """Whether a proof stating no world_scale may be read in this problem's world as given: the
    median ratio in [2^EARLIER_WORLD_LOWEST, 2^EARLIER_WORLD_HIGHEST) and the largest below the top."""
    return (2.0 ** EARLIER_WORLD_LOWEST <= norm.world_ratio < 2.0 ** EARLIER_WORLD_HIGHEST
            and norm.world_ratio_highest < 2.0 ** EARLIER_WORLD_HIGHEST)


# The frame's world_scale brings the median into the octave, and the median is a vote: views added
# near the reference decide it and leave the scene's other cameras far (review 55: six views of the
# same K translated 2^-36 from the reference put the stored scene's cameras at ratio 2^18.7 in the
# frame, and a K 399 px off was certified and verified; at 2^10.2 K was exact, at 2^13.2 and 2^15.2
# the metric stage reached its clock 0.13 and 61 px off). The far cameras behave as the uniform
# scene's did in the world as given, so the frame is used only where every other camera lies
# below 2^EARLIER_WORLD_HIGHEST in it: the stratified method refuses other data (the kind's
# check_options, a 422 naming data/cameras) and the verifier proofs posed in such a frame.
def world_frame_bounded(norm: Normalised) -> bool:
    """Whether every other camera lies below 2^EARLIER_WORLD_HIGHEST from the reference in the
    world-scaled frame (true where the world was taken as given: earlier_world_readable's)."""
    return norm.world_scale is None or norm.world_scale * norm.world_ratio_highest < 2.0 ** EARLIER_WORLD_HIGHEST


def normalise(cameras: np.ndarray, points: np.ndarray | None, N: np.ndarray, reference: int | None = None,
              unit_reference: bool = False, world: bool | float | None = None) -> Normalised:
    """The reconstruction in the frame of camera ``reference`` (default reference_camera); with
    ``unit_reference``, that camera brought to unit scale first (unit_reference_scale). ``world``:
    True, the fourth coordinate scaled by world_unit_scale of the data's world_ratio; a number, by
    that stated power of two where it fits the data (world_scale_fits; otherwise by the data's, and
    proofs.check_reference refuses the stated one); False, the world as
    given; None (default), True with ``unit_reference`` and False without."""
    cams = np.einsum("ab,ibc->iac", N, unit_scaled(cameras))
    points = None if points is None else unit_scaled(points)
    r = reference_camera(cams) if reference is None else reference
    unit = unit_reference_scale(cams[r])
    scale = unit if unit_reference else None
    A, a = (cams[r, :, :3], cams[r, :, 3]) if scale is None else (cams[r, :, :3] * scale, cams[r, :, 3] * scale)
    Ainv = np.linalg.inv(A)
    T0 = np.eye(4)
    T0[:3, :3] = Ainv
    T0[:3, 3] = -Ainv @ a
    out = cams @ T0
    ratio, highest = world_ratio(out, r), world_ratio_highest(out, r)
    world = unit_reference if world is None else world
    world_scale = (None if world is False else float(world) if world is not True and world_scale_fits(float(world), ratio)
                   else world_unit_scale(ratio))  # a stated scale that does not fit: the data's (refused by its check)
    if world_scale is not None:  # X -> diag(1, 1, 1, 1 / world_scale) X: exact, a power of two
        T0[:, 3] *= world_scale
        out[:, :, 3] *= world_scale
    out /= np.linalg.norm(out, axis=(1, 2))[:, None, None] / np.sqrt(3.0)
    out[r] = np.hstack([np.eye(3), np.zeros((3, 1))])
    pts = None
    if points is not None:
        inv = np.eye(4)
        inv[:3, :3] = A
        inv[:3, 3] = a
        pts = points @ inv.T
        if world_scale is not None:
            pts[:, 3] /= world_scale
        pts /= np.linalg.norm(pts, axis=1)[:, None]
    signs = np.ones(len(out))
    if pts is not None:
        depth_signs = np.sign(np.einsum("ik,jk->ij", out[:, 2, :], pts))
        tau = np.where(depth_signs[r] >= 0, 1.0, -1.0)  # the reference's view of each point
        for _ in range(4):  # majority vote, alternately cameras and points (deterministic)
            signs = np.where((depth_signs * tau[None, :]).sum(axis=1) >= 0, 1.0, -1.0)
            signs[r] = 1.0
            tau = np.where((depth_signs * signs[:, None]).sum(axis=0) >= 0, 1.0, -1.0)
        pts = pts * tau[:, None]
        out = out * signs[:, None, None]
    return Normalised(out, pts, r, T0, N, signs, scale, unit, world_scale, ratio, highest)


def modulus_coefficients(cameras: np.ndarray, reference: int) -> tuple[np.ndarray, np.ndarray]:
    """For every view but the reference: ``(coef, views)``, coef (m', 3, 4) such that
    (alpha, beta, gamma) of ``H = A - a p^T`` equal ``coef[:, :, :3] @ p + coef[:, :, 3]``
    (trace, sum of principal 2x2 minors, determinant: each affine in p, a rank-one update)."""
    views = np.array([i for i in range(len(cameras)) if i != reference])

    def char(H):  # (k, 3, 3) -> (k, 3): alpha, beta, gamma
        tr = np.trace(H, axis1=1, axis2=2)
        minors = (H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] * H[:, 1, 0] + H[:, 0, 0] * H[:, 2, 2]
                  - H[:, 0, 2] * H[:, 2, 0] + H[:, 1, 1] * H[:, 2, 2] - H[:, 1, 2] * H[:, 2, 1])
        return np.stack([tr, minors, np.linalg.det(H)], axis=1)

    A, a = cameras[views, :, :3], cameras[views, :, 3]
    base = char(A)
    coef = np.empty((len(views), 3, 4))
    coef[:, :, 3] = base
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        coef[:, :, k] = char(A - a[:, :, None] * e[None, None, :]) - base
    return coef, views


def modulus_residuals(coef: np.ndarray, p: np.ndarray) -> np.ndarray:
    """cbrt(gamma) alpha - beta per view (thesis 6.21)."""
    abg = coef[:, :, :3] @ p + coef[:, :, 3]
    return np.cbrt(abg[:, 2]) * abg[:, 0] - abg[:, 1]


def chirality_rows(norm: Normalised, delta: float) -> np.ndarray:
    """Rows w (4-vectors) with pi . w > 0 for the plane at infinity pi in the reference frame:
    the signed points, then delta times the signed camera centres."""
    centres = np.array([delta * signed_centre(P) for P in norm.cameras])
    centres /= np.linalg.norm(centres, axis=1)[:, None]
    return centres if norm.points is None else np.vstack([norm.points, centres])


def interior_plane(rows: np.ndarray) -> np.ndarray | None:
    """A plane pi with pi . w > 0 for every row, as deep inside as a linear program finds, or None."""
    from scipy.optimize import linprog

    k = len(rows)
    # maximise t subject to rows @ pi >= t, -1 <= pi <= 1
    c = np.zeros(5)
    c[4] = -1.0
    A_ub = np.hstack([-rows, np.ones((k, 1))])
    res = linprog(c, A_ub=A_ub, b_ub=np.zeros(k), bounds=[(-1, 1)] * 4 + [(None, 1)], method="highs")
    if res.status != 0 or -res.fun <= 1e-9:
        return None
    return res.x[:4]


def quasi_affine_frame(rows: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """G (4x4) with last row ``plane`` (so every row's last coordinate is positive), then
    centred on the rows' mean and scaled to unit RMS radius: rows in that frame are ``G @ w``."""
    _, _, vt = np.linalg.svd(plane[None, :])
    G = np.vstack([vt[1:], plane / np.linalg.norm(plane)])
    y = rows @ G.T
    x = y[:, :3] / y[:, 3:4]
    mean = x.mean(axis=0)
    # Whitened (not just scaled): a flat cloud of rows makes a long polytope of planes.
    values, vectors = np.linalg.eigh(np.cov((x - mean).T) + 1e-300 * np.eye(3))
    W = (vectors / np.sqrt(np.maximum(values, 1e-300 * values.max()))) @ vectors.T
    Ha = np.eye(4)
    Ha[:3, :3] = W
    Ha[:3, 3] = -W @ mean
    return Ha @ G


def centred_frame(rows: np.ndarray, plane: np.ndarray, rounds: int = 4) -> np.ndarray:
    """A quasi-affine frame whose plane at infinity sits at the Chebyshev centre of the polytope
    of planes (recomputed a few times): an arbitrary interior plane can leave the polytope
    hundreds of units long, and branch and bound pays for every unit.

    The rows' coordinates are first scaled by powers of two (exact, and 1 for rows of order 1):
    in a world of size 1e-9 against a last coordinate 1, the centre's plane mixes the two scales
    and its frame loses the cloud's spread to cancellation, a few rounds later to 1e134-sized rows
    no linear program reads, on some machines' kernels and not others. The frame of the original
    rows is the scaled rows' frame times the same scaling."""
    scale = np.exp2(-np.round(np.log2(np.maximum(np.abs(rows).max(axis=0), np.finfo(float).tiny))))
    return _centred_frame(rows * scale, plane / scale, rounds) * scale


def _centred_frame(rows: np.ndarray, plane: np.ndarray, rounds: int) -> np.ndarray:
    from scipy.optimize import linprog

    G = quasi_affine_frame(rows, plane)
    for _ in range(rounds):
        a, b = frame_rows(G, rows)
        norms = np.linalg.norm(a, axis=1)
        # maximise r subject to a_k . v + b_k >= r |a_k|
        res = linprog([0, 0, 0, -1], A_ub=np.hstack([-a, norms[:, None]]), b_ub=b,
                      bounds=[(None, None)] * 3 + [(0, None)], method="highs")
        if res.status != 0:
            break
        centre = G.T @ np.append(res.x[:3], 1.0)
        G = quasi_affine_frame(rows, centre / np.linalg.norm(centre))
    return G


def frame_rows(G: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The polytope of v in the frame: ``a_k . v + b_k >= 0`` with (a_k, b_k) = G @ w_k."""
    y = rows @ G.T
    return y[:, :3], y[:, 3]


def plane_map(G: np.ndarray, sign: float) -> np.ndarray:
    """M (4x4) with (num_1, num_2, num_3, d) = M @ (v, 1) the reference-frame plane at infinity
    G^T (v, 1), signed so that d > 0 on the chirality polytope; p = num / d."""
    M = sign * G.T
    return M / M[3, 3]  # d = 1 at the frame's centre (v = 0): the relaxation's numbers near 1


# --- the root box, proved by exact arithmetic ------------------------------------------------

def box_side(a: np.ndarray, b: np.ndarray, axis: int, upper: bool) -> tuple[float, list[int]] | None:
    """A bound on v[axis] over {v : a v + b >= 0} and the three rows that prove it (or None)."""
    from scipy.optimize import linprog

    c = np.zeros(3)
    c[axis] = -1.0 if upper else 1.0
    res = linprog(c, A_ub=-a, b_ub=b, bounds=[(None, None)] * 3, method="highs")
    if res.status != 0:
        return None
    y = -np.asarray(res.ineqlin.marginals)
    basis = [int(i) for i in np.argsort(-y)[:3]]
    bound = exact_side(a, b, axis, upper, basis)
    return None if bound is None else (bound, basis)


def exact_side(a: np.ndarray, b: np.ndarray, axis: int, upper: bool, basis: list[int]) -> float | None:
    """The bound three rows prove, computed exactly (rationals from the floats) and rounded
    outward: y >= 0 with sum_k y_k a_k = +-e_axis gives +-v[axis] = sum y_k a_k . v >= -sum y_k b_k.
    None when the rows do not prove a bound (singular, or a negative multiplier)."""
    if len(basis) != 3 or len(set(basis)) != 3 or not all(0 <= k < len(a) for k in basis):
        return None
    M = [[Fraction(float(a[k][i])) for k in basis] for i in range(3)]  # columns are the rows a_k
    rhs = [Fraction(0)] * 3
    rhs[axis] = Fraction(-1 if upper else 1)
    y = _solve3(M, rhs)
    if y is None or any(value < 0 for value in y):
        return None
    total = -sum(value * Fraction(float(b[k])) for value, k in zip(y, basis))
    bound = -total if upper else total
    result = float(bound)
    # float() rounds to nearest: step outward so that the float still bounds the exact value.
    if upper and Fraction(result) < bound:
        result = float(np.nextafter(result, np.inf))
    if not upper and Fraction(result) > bound:
        result = float(np.nextafter(result, -np.inf))
    return result


# The chirality rows in a region's frame are floats computed from the data (a normalisation through
# LAPACK, a product with the frame through BLAS): another machine's kernels give rows a few ulps of
# their magnitudes away, and the exact bound three of them prove moves with them. ROWS_ROUNDING
# (64 ulps) bounds that move relative to the magnitudes; side_slack turns it into a distance on
# the side.
ROWS_ROUNDING = 64 * 2.0 ** -52


def side_slack(a: np.ndarray, magnitudes: np.ndarray, basis: list[int], axis: int, reaches: np.ndarray) -> float:
    """How far the bound three rows prove may move when each row moves by ROWS_ROUNDING of its
    magnitudes, over a box whose points are at most ``reaches[j]`` from the frame's origin along
    axis j: with y the multipliers (sum y_k a_k = +-e_axis), sum_k y_k (sum_j m_kj reaches_j + m_k3)
    ROWS_ROUNDING, doubled for the two machines' rows (0 when the rows are singular in floats).
    ``magnitudes`` (m) are |rows| @ |G|^T, the sizes each entry of (a, b) = rows @ G^T is rounded
    from, column by column: a frame stretching one axis pays for that axis' long reach with its
    small entries, and lends no slack to the others (one reach for every axis did)."""
    M = np.array([a[k] for k in basis], dtype=float).T
    rhs = np.zeros(3)
    rhs[axis] = 1.0
    try:
        y = np.abs(np.linalg.solve(M, rhs))
    except np.linalg.LinAlgError:
        return 0.0
    with np.errstate(all="ignore"):
        sizes = np.array([float(magnitudes[k, :3] @ reaches) + float(magnitudes[k, 3]) for k in basis])
        slack = 2.0 * ROWS_ROUNDING * float(y @ sizes)
    return slack if np.isfinite(slack) else 0.0


def _solve3(M: list[list[Fraction]], rhs: list[Fraction]) -> list[Fraction] | None:
    """Gaussian elimination in rationals (3x3)."""
    rows = [M[i][:] + [rhs[i]] for i in range(3)]
    for col in range(3):
        pivot = next((r for r in range(col, 3) if rows[r][col] != 0), None)
        if pivot is None:
            return None
        rows[col], rows[pivot] = rows[pivot], rows[col]
        for r in range(3):
            if r != col and rows[r][col] != 0:
                factor = rows[r][col] / rows[col][col]
                rows[r] = [x - factor * y for x, y in zip(rows[r], rows[col])]
    return [rows[i][3] / rows[i][i] for i in range(3)]


def exact_gordan(rows: np.ndarray, chosen: list[int]) -> bool:
    """Whether the chosen rows have, in exact arithmetic, a nonzero nonnegative combination
    equal to 0 (then pi . w > 0 on all of them is impossible, by Gordan's alternative)."""
    from fractions import Fraction

    if not 1 <= len(chosen) <= 5 or len(set(chosen)) != len(chosen) or not all(0 <= i < len(rows) for i in chosen):
        return False
    W = [[Fraction(float(rows[i][c])) for i in chosen] for c in range(4)]  # 4 x k
    null = _null_vector(W, len(chosen))
    if null is None:
        return False
    if all(x <= 0 for x in null):
        null = [-x for x in null]
    return all(x >= 0 for x in null) and any(x > 0 for x in null)


def _null_vector(W, k):
    """A nonzero rational vector y with W y = 0, when the null space is one-dimensional."""
    from fractions import Fraction

    rows = [r[:] for r in W]
    pivots = []
    r = 0
    for c in range(k):
        p = next((i for i in range(r, len(rows)) if rows[i][c] != 0), None)
        if p is None:
            continue
        rows[r], rows[p] = rows[p], rows[r]
        for i in range(len(rows)):
            if i != r and rows[i][c] != 0:
                f = rows[i][c] / rows[r][c]
                rows[i] = [x - f * y for x, y in zip(rows[i], rows[r])]
        pivots.append(c)
        r += 1
    free = [c for c in range(k) if c not in pivots]
    if len(free) != 1:
        return None
    y = [Fraction(0)] * k
    y[free[0]] = Fraction(1)
    for i, c in enumerate(pivots):
        y[c] = -rows[i][free[0]] / rows[i][c]
    return y


def check_reconstruction(cameras: np.ndarray, field: str = "data/cameras") -> None:
    if cameras.ndim != 3 or cameras.shape[1:] != (3, 4):
        raise InputError(field, "must be a list of 3x4 matrices")
    if len(cameras) < 3:
        raise InputError(field, f"autocalibration needs at least 3 cameras, got {len(cameras)}")
    cameras = unit_scaled(cameras)
    s = np.linalg.svd(cameras, compute_uv=False)
    for i, values in enumerate(s):
        if not values[2] > 1e-9 * values[0]:
            raise InputError(f"{field}/{i}", "is rank-deficient (a camera has rank 3)")
    left = np.linalg.svd(cameras[:, :, :3], compute_uv=False)
    if not np.any(left[:, 2] > 1e-9 * left[:, 0]):
        raise InputError(field, "no camera has an invertible left 3x3 block (every centre at infinity)")


def gordan_rows(rows: np.ndarray) -> list[int] | None:
    """Rows (at most 5) with a nonnegative combination exactly 0: no plane is positive on all."""
    from scipy.optimize import linprog

    k = len(rows)
    res = linprog(np.zeros(k), A_eq=np.vstack([rows.T, np.ones((1, k))]), b_eq=np.append(np.zeros(4), 1.0),
                  bounds=[(0, None)] * k, method="highs")
    if res.status != 0:
        return None
    chosen = [int(i) for i in np.argsort(-res.x)[:5] if res.x[i] > 0]
    return chosen if exact_gordan(rows, chosen) else None
