"""A map in normalised coordinates, the same floats on every machine: the frame a map's
determinacy estimate (fractional.determinacy.map_ for a resection, fractional.homography_estimate
for a homography) reads its curvature in, whose writer and verifier both call these.

Each side's points are centred on their centroid and scaled to a mean distance of sqrt 2 from it,
the centroid and the scale from correctly rounded sums (math.fsum), and the map taken into that
frame exactly (integer arithmetic on the floats' exact values) and rounded once. The estimate's
width then reads numbers of the size of the data's spread wherever the data sit: computed in the
data's own coordinates, a map 1e8 off the origin over a spread of 1e-3 took its Jacobian from
residuals rounded at 5e10 times eps of that spread, and its width moved by multiples of itself
(review 59 class 6).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from geocert.core.geometry import SQUARES_SAFE, square_safe_shift
from geocert.formulations.fractional.fixed_order import mul, norm


def normaliser(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The centroid and the scale putting the points' mean distance from it at sqrt 2, each from
    correctly rounded sums (the same floats whatever the machine's reductions); ArithmeticError
    where the scale is 0 or not finite (the normaliser would be singular)."""
    centre = np.array([math.fsum(points[:, j].tolist()) / len(points) for j in range(points.shape[1])])
    offsets = points - centre
    # Squares of offsets below 1e-150 underflow: there the offsets are read at a power of two
    # bringing the largest near 1, exactly, and the mean scaled back; a spread of 1e-180 read as 0
    # gave the scale of 1e-300 and a centre at the centroid (review 61). (Above 1e150 the squares
    # overflow, the scale is 0 and no estimate is made, as the data's exact cost overflows too.)
    largest = float(np.max(np.abs(offsets))) if offsets.size else 0.0
    shift = square_safe_shift(largest) if largest < SQUARES_SAFE[0] else 0
    offsets = np.ldexp(offsets, shift)
    squares = offsets[:, 0] * offsets[:, 0]
    for j in range(1, points.shape[1]):
        squares = squares + offsets[:, j] * offsets[:, j]
    mean = math.ldexp(math.fsum(np.sqrt(squares).tolist()) / len(points), -shift)
    scale = math.sqrt(2.0) / max(mean, 1e-300)
    if not (scale > 0 and math.isfinite(scale)):  # a spread beyond the largest float: no estimate (safely)
        raise ArithmeticError("the points' spread is not a finite positive number")
    return centre, scale


def _similarity(centre: np.ndarray, scale: float, inverse: bool) -> list[list[Fraction]]:
    """The normaliser x -> scale (x - centre) (or its inverse) as an exact homogeneous matrix."""
    d = len(centre)
    s, c = Fraction(scale), [Fraction(float(x)) for x in centre]
    rows = [[Fraction(0)] * (d + 1) for _ in range(d + 1)]
    for j in range(d):
        rows[j][j] = 1 / s if inverse else s
        rows[j][d] = c[j] if inverse else -s * c[j]
    rows[d][d] = Fraction(1)
    return rows


def _product(a: list[list[Fraction]], b: list[list[Fraction]]) -> list[list[Fraction]]:
    return [[sum((a[i][p] * b[p][j] for p in range(len(b))), Fraction(0)) for j in range(len(b[0]))]
            for i in range(len(a))]


def normalised_map(source: np.ndarray, target: np.ndarray, M: np.ndarray
                   ) -> tuple[tuple[np.ndarray, float], tuple[np.ndarray, float], np.ndarray]:
    """The source's and the target's normalisers (centre, scale) and the map between the normalised
    points, Tt M Ts^-1 computed exactly and rounded once, scaled to unit Frobenius norm."""
    (cs, ss), (ct, st) = normaliser(source), normaliser(target)
    exact = _product(_product(_similarity(ct, st, False), [[Fraction(float(x)) for x in row] for row in M]),
                     _similarity(cs, ss, True))
    N = np.array([[float(x) for x in row] for row in exact])
    return (cs, ss), (ct, st), N / norm(N.ravel())


def complement(v: np.ndarray) -> np.ndarray:
    """An orthonormal basis (columns) of the directions orthogonal to the unit vector v: the
    columns of the Householder reflection taking v to a coordinate axis, but that axis's (the
    normalised map's parameters: its scale is none)."""
    k = int(np.argmax(np.abs(v)))
    w = v.copy()
    w[k] = v[k] + math.copysign(1.0, v[k])
    H = np.eye(len(v)) - (2.0 / float(mul(w, w))) * (w[:, None] * w[None, :])
    return np.delete(H, k, axis=1)
