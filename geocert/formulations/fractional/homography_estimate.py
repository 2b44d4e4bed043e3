"""A homography's determinacy estimate (fractional.determinacy.map_) in a fixed order of operations:
the same floats on every machine.

The estimate's intervals are sqrt(delta g' (J'J)^+ g) about the centroid's image (core.determinacy).
Computed through BLAS and LAPACK (a central-difference Jacobian of residuals evaluated by matmul,
J'J, eigh) the ends of a homography 1e7 from the origin with 1 px of noise lay 7e-3 to 1.6e-2 of
the interval's width apart between OpenBLAS's Haswell and Prescott kernels (review 38 class 4),
and a verifier holding them to that much could not tell an interval collapsed onto its value
(review 37 class 3). Here every step is an IEEE operation in an order of its own: the normalisers
from correctly rounded sums (math.fsum), the normalised map computed exactly and rounded once, the
parameters' basis a Householder reflection (fractional.normalisation, shared with a resection's
estimate), the Jacobian analytic (elementwise numpy and fixed_order.mul), J'J by fixed_order.mul
and its eigendecomposition by fixed_order.symmetric_eigen; so the writer and the verifier, which
recomputes the estimate by this function, read one width.
"""

from __future__ import annotations

import math

import numpy as np

from geocert.core.determinacy import SINGULAR, Determinacy, certified_gap, cost_increase, few_degrees, interval, spread
from geocert.core.exact import exact_centroid_image, exact_squared_residuals
from geocert.formulations.fractional.fixed_order import mul, symmetric_eigen
from geocert.formulations.fractional.normalisation import complement, normalised_map

FLAT = 1e-2  # fractional.determinacy.FLAT: points whose centred spread along a direction is below this


def information(source: np.ndarray, target: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """J'J of the pixel residuals in the normalised map's parameters (the directions orthogonal to
    it, so the scale is no parameter), the centroid image's gradient in them (one row a target
    coordinate), and the residuals' number; analytic, in a fixed order."""
    m, n1 = M.shape
    dt = m - 1
    (cs, ss), (ct, st), N = normalised_map(source, target, M)
    basis = complement(N.ravel())
    xs = np.hstack([ss * (source - cs), np.ones((len(source), 1))])  # the normalised source points
    y = mul(xs, N.T)
    u = y[:, :dt] / y[:, dt:]
    denominator = st * y[:, dt:]  # the pixel residual is y_12 / (st y_3) + ct - target
    columns, gradient = [], []
    # the source centroid normalises to the origin: its image moves with the last column of N
    yc = N[:, -1]
    uc = yc[:dt] / yc[dt]
    for k in range(basis.shape[1]):
        B = basis[:, k].reshape(m, n1)
        z = mul(xs, B.T)
        columns.append(((z[:, :dt] - u * z[:, dt:]) / denominator).ravel())
        gradient.append((B[:dt, -1] - uc * B[dt, -1]) / (st * yc[dt]))
    J = np.array(columns).T
    return mul(J.T, J), np.array(gradient).T, J.shape[0]


def intervals(information_: np.ndarray, squared: float, redundancy: int, quantities: dict[str, tuple],
              gap: float | None) -> Determinacy:
    """core.determinacy.information_intervals in a fixed order (fixed_order.symmetric_eigen, the
    projections summed in order, the half-width's terms by math.fsum)."""
    delta = cost_increase(squared, redundancy, gap)
    out = Determinacy(cost_increase=delta, redundancy=redundancy, warnings=few_degrees(redundancy))
    if not (np.all(np.isfinite(information_)) and math.isfinite(delta)):
        for name, (value, _, scale) in quantities.items():
            out.intervals.append(interval(name, value, None, None, scale))
        return out
    values, vectors = symmetric_eigen(information_)
    largest = max(float(values[-1]), 1e-300)
    fixed = values > SINGULAR * largest
    for name, (value, gradient, scale) in quantities.items():
        g = mul(vectors.T, np.asarray(gradient, dtype=float))
        free = float(np.abs(g[~fixed]).max(initial=0.0))
        if free > 1e-6 * max(float(np.abs(g).max()), 1e-300) or not math.isfinite(value):
            out.intervals.append(interval(name, value, None, None, scale))
            continue
        half = math.sqrt(delta * math.fsum((g[fixed] * g[fixed] / values[fixed]).tolist()))
        out.intervals.append(interval(name, value, value - half, value + half, scale))
    return out


def homography(source: np.ndarray, target: np.ndarray, M: np.ndarray, cost: float | None,
               lower: float | None) -> dict:
    """The estimate of a homography (M (d+1) x (d+1)): where the source points' centroid goes, its
    value the exact image (exact_centroid_image), its level from the exact squared residuals."""
    with np.errstate(all="ignore"):  # a point mapped to infinity: its residuals' column is not finite
        J_J, gradient, residuals = information(source, target, M)
    value = exact_centroid_image(source, M)  # the same floats on every machine
    names = ("centroid_image_x", "centroid_image_y", "centroid_image_z")
    centred = target - np.array([math.fsum(target[:, j].tolist()) / len(target) for j in range(target.shape[1])])
    extent = math.sqrt(math.fsum((centred * centred).ravel().tolist()) / len(target))  # the targets' spread
    quantities = {names[k]: (float(value[k]), gradient[k], extent) for k in range(len(value))}
    out = intervals(J_J, exact_squared_residuals(source, target, M), residuals - J_J.shape[0], quantities,
                    certified_gap(cost, lower))
    dims = source.shape[1]
    for name, pts in (("source", source), ("target", target)):
        flat = spread(pts)
        if flat[dims - 1] < FLAT:
            shape = "collinear" if dims == 2 else "coplanar"
            out.warnings.append({"code": f"near_{shape}_points",
                                 "detail": f"the {name} points are nearly {shape} (spread {flat[dims - 1]:.2g} of "
                                           "their extent): the map is poorly fixed off that line or plane"})
    return out.document()
