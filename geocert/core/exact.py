"""Residuals and costs computed exactly from the floats' values and rounded once: the same floats
on every machine, whatever its BLAS kernels or SIMD width.

A residual is target minus the image of a point under a matrix, (M X)[:-1] / (M X)[-1]. Far from
the origin it is a difference of numbers many orders larger than itself, which each machine's
dot products round differently: a cost stated from one machine's floats may lie anywhere in a
window as wide as that rounding (proof.residual_uncertainty), and a window that wide let a forged
certificate understate a far resection's cost fourfold (review 37). Computed exactly, the cost is
one number: the writer states it and the verifier holds it to its rounding alone.

Python's integers carry the arithmetic: every float is an integer times a power of 2, so the
image's coordinates are ratios of integers and ``int / int`` rounds the residual correctly.
About 10 microseconds an observation: the callers take this path where the floats' rounding
matters to the cost (``needs_exact``), not for every track of a reconstruction."""

from __future__ import annotations

import math

import numpy as np

from geocert.core.geometry import cost_rounding, norm_terms

# Float evaluation serves where its cost is this share of OBJECTIVE_TOLERANCE (relative) from
# the exact one at worst; elsewhere the cost is computed exactly. A writer's float cost and a
# verifier's then differ by at most half the tolerance. A hundredth sent 4,340 of the Oxford
# Dinosaur's 4,983 tracks (projective cameras: terms far larger than their residuals) down the
# exact path, 0.22 s of CPU against 0.06 s for the whole solve at a quarter (240 tracks).
FLOAT_SHARE = 0.25


def scaled(values: list[float]) -> tuple[list[int], int]:
    """Integers n_i and one exponent e with values[i] = n_i * 2**e exactly."""
    ratios = [float(v).as_integer_ratio() for v in values]
    shift = max(d.bit_length() - 1 for _, d in ratios)
    return [n << (shift - (d.bit_length() - 1)) for n, d in ratios], -shift


def _residuals_of(rows: list[list[int]], point: list[int], target: list[float]) -> list[float]:
    """target - image of one point (its integers) under one matrix (its rows' integers; the two
    scales cancel in the ratio), each coordinate rounded once; inf where the depth is 0."""
    image = [sum(m * v for m, v in zip(row, point)) for row in rows]
    depth = image[-1]
    if depth == 0:
        return [math.inf] * len(target)
    out = []
    for k, t in enumerate(target):
        tn, td = float(t).as_integer_ratio()
        numerator, denominator = tn * depth - td * image[k], td * depth
        try:
            out.append(numerator / denominator)
        except OverflowError:  # beyond the largest float
            out.append(math.inf if (numerator > 0) == (denominator > 0) else -math.inf)
    return out


def residuals(matrices: np.ndarray, points: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """target - (M X)[:-1] / (M X)[-1] for each observation, exactly and rounded once.

    ``matrices`` (m + 1, d + 1) for one map, or (n, m + 1, d + 1) one per observation;
    ``points`` (d + 1,) homogeneous for one point, or (n, d + 1); ``targets`` (n, m)."""
    targets = np.asarray(targets, dtype=float)
    n, m = targets.shape
    matrices = np.asarray(matrices, dtype=float)
    points = np.asarray(points, dtype=float)
    shared_matrix = matrices.ndim == 2
    shared_point = points.ndim == 1
    if shared_matrix:
        entries, _ = scaled(matrices.ravel().tolist())
        width = matrices.shape[1]
        rows_shared = [entries[i * width:(i + 1) * width] for i in range(matrices.shape[0])]
    if shared_point:
        point_shared, _ = scaled(points.tolist())
    out = np.empty((n, m))
    for i, target in enumerate(targets.tolist()):
        if shared_matrix:
            rows = rows_shared
        else:
            entries, _ = scaled(matrices[i].ravel().tolist())
            width = matrices.shape[2]
            rows = [entries[j * width:(j + 1) * width] for j in range(matrices.shape[1])]
        point = point_shared if shared_point else scaled(points[i].tolist())[0]
        out[i] = _residuals_of(rows, point, target)
    return out


def cost(residuals: np.ndarray, norm: str) -> float:
    """The norm's cost of ``residuals`` (n, m) as every machine computes it: each observation's
    term by IEEE operations on its own coordinates, the terms summed correctly rounded (fsum)."""
    return math.fsum(norm_terms(np.asarray(residuals, dtype=float), norm).tolist())


def slack(residuals: np.ndarray, norm: str) -> float:
    """What a cost stated from these exact residuals is held to besides the relative tolerance:
    4 ulps of each residual (the writer computes the same floats; nothing a document chooses)."""
    with np.errstate(all="ignore"):
        return cost_rounding(residuals, 4.0 * np.spacing(np.abs(residuals)), norm)


def needs_exact(residuals: np.ndarray, uncertainty: np.ndarray, cost_value: float, norm: str,
                tolerance: float) -> bool:
    """Whether a float evaluation of these residuals (each within ``uncertainty`` of the exact
    one) may move the cost by more than FLOAT_SHARE of ``tolerance`` (relative) of itself."""
    with np.errstate(all="ignore"):
        spread = cost_rounding(residuals, uncertainty, norm)
    return not spread <= FLOAT_SHARE * tolerance * abs(cost_value)


def exact_squared_residuals(source: np.ndarray, target: np.ndarray, matrix: np.ndarray) -> float:
    """The squared residuals' sum of ``matrix`` on the data, the same float on every machine: each
    residual computed exactly (integer arithmetic on the floats' exact values) and rounded once
    (Python's int division is correctly rounded), their squares summed exactly and rounded once.
    On a near-exact fit the float sum is each machine's rounding noise, multiples of itself apart
    between BLAS kernels (review 35), and a level read from a stated cost instead let a forger
    choose it (review 36); about 10 ms for 1000 points."""
    M = np.asarray(matrix, dtype=float)
    entries, _ = scaled(M.ravel().tolist())
    rows = [entries[i * M.shape[1]:(i + 1) * M.shape[1]] for i in range(M.shape[0])]
    total, exponent = 0, 0
    for X, x in zip(np.asarray(source, dtype=float).tolist(), np.asarray(target, dtype=float).tolist()):
        point, _ = scaled(X + [1.0])  # one scale for the point's entries: it cancels in the ratio
        image = [sum(m * v for m, v in zip(row, point)) for row in rows]
        if image[-1] == 0:
            return math.inf
        for k, t in enumerate(x):
            tn, td = float(t).as_integer_ratio()
            a, b = ((tn * image[-1] - td * image[k]) / (td * image[-1])).as_integer_ratio()
            square_exponent = 2 * (b.bit_length() - 1)  # b is a power of 2
            if square_exponent > exponent:
                total <<= square_exponent - exponent
                exponent = square_exponent
            total += (a * a) << (exponent - square_exponent)
    try:
        return total / (1 << exponent)
    except OverflowError:  # a sum beyond the largest float
        return math.inf


def exact_centroid_image(source: np.ndarray, matrix: np.ndarray) -> list[float]:
    """The source points' centroid mapped by ``matrix``, the same floats on every machine: the
    centroid and its image computed exactly (integer arithmetic on the floats' exact values) and
    each coordinate rounded once; inf where the centroid maps to infinity or beyond the largest
    float. A homography estimate's value: computed through the normalisers, as the estimate's
    gradient is, it differed between BLAS kernels by 310 ulps 1e6 off the origin (review 37
    class 3)."""
    M = np.asarray(matrix, dtype=float)
    entries, _ = scaled(M.ravel().tolist())
    rows = [entries[i * M.shape[1]:(i + 1) * M.shape[1]] for i in range(M.shape[0])]
    points = np.asarray(source, dtype=float)
    coordinates, exponent = scaled(points.ravel().tolist())  # source = coordinates * 2**exponent
    dims = points.shape[1]
    # the centroid (sum / k, 1) scaled by k * 2**-exponent: (sum of the integers, k * 2**-exponent)
    centroid = [sum(coordinates[j::dims]) for j in range(dims)] + [len(points) << -exponent]
    image = [sum(m * v for m, v in zip(row, centroid)) for row in rows]
    if image[-1] == 0:
        return [math.inf] * (len(image) - 1)
    out = []
    for value in image[:-1]:
        try:
            out.append(value / image[-1])  # Python's int division: correctly rounded
        except OverflowError:
            out.append(math.inf)
    return out
