"""A lower bound on an L2L2 resection's global optimum with no search (a "sublevel_bound" proof):
numpy only, the solver states it and the verifier recomputes it.

With cost increase 0, the enclosure (1) and rounds (2) of fractional.resection_sublevel prove
that every camera of the scope (every 3x4 camera putting every point at positive depth) costing
at most U (the returned camera P0's cost c from above) lies in the ball |phi| <= r (whitened
coordinates on the slice through P0's reference depth). The global optimum costs at most c, so it
is one of them, and it suffices to bound the cost below over that ball:

    cost(phi) = sum_j |n_j + C_j phi|^2 / w_j(phi)^2,   w_j(phi) = w_j + g_j . phi   (both exact),

and 1 / w^2 is convex in w > 0, so above its tangent at p_j (the computed w_j):
1 / w_j(phi)^2 >= F_j(phi) = v_j - sigma_j g_j . phi, sigma_j = 2 / p_j^3, v_j ~ 1 / p_j^2 less
the errors of p_j, g_j and sigma_j over the ball (so F_j holds for the exact w_j(phi)). F_j >= 0
on the ball (checked), so each term is at least |n_j + C_j phi|^2 F_j(phi), a quadratic times a
linear function whose cubic part is at least -sigma_j |g_j| r |C_j phi|^2: the cost is at least

    q0 + 2 rho' phi + phi' K phi,   q0 = sum v_j |n_j|^2,   rho = sum v_j C_j' n_j - sigma_j |n_j|^2 g_j / 2,
    K = sum (v_j - sigma_j |g_j| r) C_j' C_j - sigma_j (C_j' n_j g_j' + g_j n_j' C_j),

the cost's own expansion at P0 but for the depths' curvature, which is dropped (so rho is about
half the cost's gradient, about 0 at a local optimum, and q0 about c). Radially, with the
data-derived n_j, C_j's errors as in resection_sublevel (|a + b|^2 >= (1 - eta) |a|^2 -
(1 / eta - 1) |b|^2, weighted by F_j's upper bound), it is at least a0 - 2 a1 |phi| + a2 |phi|^2
(a0 rounded down, a1 up, a2 down and positive: kappa <= lambda_min(K) proven by Cholesky), whose
minimum over |phi| <= r is at least a0 - min(a1^2 / a2, 2 a1 r). Every camera of the scope
costing at most U costs at least that, every other more than U >= c: it bounds the optimum
(rounded down, less UNDERFLOW). No convexity of the cost is needed. The ball's radius enters only
through the cubic term and the depths' spread (r |g_j| / w_j, about 1e-3): the bound is within
about |rho|^2 / kappa of c.

The proof states the reference point, the radius (1) passes at and the rounds (2): the verifier
recomputes the enclosure at that radius, the rounds and the bound from the data and the claim's
camera alone, in a pass over the points per round (as a proven interval's check).
"""

from __future__ import annotations

import math

import numpy as np

from geocert.core import summary_notes
from geocert.core.strict import Invalid, number, record
from geocert.formulations.fractional.convexity import SMALLEST, UNDERFLOW
from geocert.formulations.fractional.fixed_order import gram, norm, weighted
from geocert.formulations.fractional.resection_sublevel import (ETA, MAX_ROUNDS, ROUNDS_STOP, U, Scene, encloses,
                                                            least_eigenvalue_below, reference_point, shrink,
                                                            smallest_radius)

TYPE = summary_notes.SUBLEVEL_BOUND  # the proof type, named once where its note is written


def tangent_terms(scene: Scene, r: float) -> tuple[float, float, float] | None:
    """(a0, a1, a2): every camera of the scope within |phi| <= r costs at least
    a0 - 2 a1 |phi| + a2 |phi|^2 (a0 rounded down, a1 up, a2 down); None where F_j >= 0, kappa or
    a2 > 0 is not proven."""
    k = scene.k
    with np.errstate(all="ignore"):
        p = scene.w
        inv2 = 1 / (p * p)
        sigma = 2 / (p * p * p)  # the tangent's slope (an exact number: its error is counted in v)
        sig_up = sigma * (1 + 8 * U)
        g, n, C = scene.g, scene.n, scene.C
        g_len = np.sqrt((g * g).sum(axis=1)) * (1 + 8 * U)
        # 1 / w^2 >= 1 / p^2 - (2 / p^3)(w_exact - p + g_exact . phi): w's and g's errors, and
        # sigma's against 2 / p^3, taken off v over the ball
        v = (inv2 * (1 - 4 * U) - sig_up * (scene.w_err + r * (scene.g_err + 4 * U * g_len)) * (1 + 8 * U)) * (1 - 4 * U)
        spread = sig_up * g_len * r * (1 + 8 * U)  # |sigma_j g_j . phi| over the ball, from above
        u = (v - spread) * (1 - 4 * U)  # F_j's least over the ball, and the weight of |C_j phi|^2
        F_up = (v + spread) * (1 + 4 * U)
        usable = bool(np.all(p >= SMALLEST) and np.all(u > 0) and np.all(np.isfinite(F_up)) and np.all(np.isfinite(sigma)))
        if not usable:
            return None
        # elementwise, in a fixed order (fixed_order): one bound on every machine, whatever its BLAS kernel
        Cn = (C * n[:, :, None]).sum(axis=1)  # C_j' n_j
        cross = ((Cn[:, :, None] * g[:, None, :]) * sigma[:, None, None]).sum(axis=0)  # sum sigma_j C_j' n_j g_j'
        K = gram(C, u) - (cross + cross.T)
        nn = (n * n).sum(axis=1)
        rho = weighted(C, n, v) - 0.5 * ((g * nn[:, None]) * sigma[:, None]).sum(axis=0)
        q0 = float((v * nn).sum())
        C_F = np.sqrt((C * C).sum(axis=(1, 2)))
        n_len = np.sqrt(nn)
        K_allowance = 4 * (k + 16) * U * float((u * C_F * C_F).sum() + 2 * (sigma * C_F * n_len * g_len).sum())
        rho_up = (norm(rho) * (1 + 8 * U)
                  + 2 * (k + 16) * U * float((v * C_F * n_len).sum() + (sigma * nn * g_len).sum())) * (1 + 4 * U)
        q0_lo = q0 * (1 - (k + 16) * U)
        kappa = least_eigenvalue_below(K, K_allowance)
        if kappa is None:
            return None
        errors_n = 2 / ETA * float((F_up * scene.eps_n ** 2).sum()) * (1 + 8 * U)
        errors_C = 2 / ETA * float((F_up * scene.err_C ** 2).sum()) * (1 + 8 * U)
        a2 = ((1 - ETA) * kappa - errors_C) * (1 - 8 * U)
        a1 = (1 - ETA) * rho_up * (1 + 4 * U)
        a0 = ((1 - ETA) * q0_lo - errors_n) * (1 - 8 * U) if (1 - ETA) * q0_lo > errors_n \
            else ((1 - ETA) * q0_lo - errors_n) * (1 + 8 * U)
    if not (a2 > 0 and math.isfinite(a0) and math.isfinite(a1) and math.isfinite(a2)):
        return None
    return a0, a1, a2


def ball_minimum(scene: Scene, r: float) -> float:
    """A lower bound (rounded down) of the cost of every camera of the scope within |phi| <= r:
    tangent_terms' radial quadratic at its least over [0, r]; -inf where it is not proven."""
    terms = tangent_terms(scene, r)
    if terms is None:
        return -math.inf
    a0, a1, a2 = terms
    with np.errstate(all="ignore"):
        drop = min(a1 * a1 / a2, 2 * a1 * r) * (1 + 8 * U)
        value = a0 - drop
        bound = (value * (1 - 8 * U) if value > 0 else value * (1 + 8 * U)) - UNDERFLOW
    return bound if math.isfinite(bound) else -math.inf


def proven_bound(scene: Scene, radius: float, rounds: int, strictness: float = 1.0) -> tuple[float, float]:
    """(the bound, the final radius) the enclosure at ``radius`` and ``rounds`` rounds prove;
    -inf where the enclosure fails."""
    if not encloses(scene, 0.0, radius, strictness=strictness):
        return -math.inf, radius
    r = radius
    for _ in range(rounds):
        r = shrink(scene, 0.0, r)
    return ball_minimum(scene, r), r


def resection_bound(source, target, matrix) -> tuple[float, dict] | None:
    """(the bound, the proof) a solver states for camera ``matrix`` (None where none is proven):
    the smallest radius the enclosure passes with twice its allowances, the rounds until they
    shrink r by less than 1%."""
    reference = reference_point(source)
    scene = Scene(source, target, matrix, reference)
    if not scene.usable:
        return None
    radius = smallest_radius(scene, 0.0)
    if radius is None:
        return None
    r, rounds = radius, 0
    while rounds < MAX_ROUNDS:
        smaller = shrink(scene, 0.0, r)
        rounds += 1
        if not smaller < ROUNDS_STOP * r:
            r = smaller
            break
        r = smaller
    bound = ball_minimum(scene, r)
    if not math.isfinite(bound):
        return None
    return bound, {"type": TYPE, "reference": reference, "radius": float(radius), "rounds": rounds}


def verify_resection_bound(source: np.ndarray, target: np.ndarray, proof: dict, matrix: np.ndarray,
                           options: dict) -> float:
    """The lower bound a "sublevel_bound" proof establishes for the camera ``matrix`` (an L2L2
    resection, any max_residual: the bound is over the whole scope, which holds the narrower
    one); refused unless the enclosure passes at the stated radius."""
    record(proof, "proof", ("type", "reference", "radius", "rounds"), ("sublevel",))
    radius = number(proof.get("radius"), "proof/radius")
    reference, rounds = proof.get("reference"), proof.get("rounds")
    if options["norm"] != "L2L2":
        raise Invalid(TYPE, "a sublevel_bound proof is for L2L2 (its cost the sum of squares)")
    if (source.shape[1], target.shape[1]) != (3, 2):
        raise Invalid(TYPE, "a sublevel_bound proof is for a resection (3D -> 2D)")
    if type(reference) is not int or not 0 <= reference < len(source):
        raise Invalid(TYPE, "proof/reference must index a point of the map")
    if type(rounds) is not int or not 0 <= rounds <= MAX_ROUNDS:
        raise Invalid(TYPE, f"proof/rounds must be an integer from 0 to {MAX_ROUNDS}")
    scene = Scene(source, target, matrix, reference)
    if not scene.usable:
        raise Invalid(TYPE, "the map's numbers are outside the range a sublevel_bound is checked for (6 points at "
                            "least, every number 0 or of magnitude within [2^-128, 2^128], every depth positive)")
    bound, _ = proven_bound(scene, radius, rounds)
    if not math.isfinite(bound):
        raise Invalid(TYPE, f"nothing proven at radius {radius!r}: the cameras costing as little as the one returned "
                            "are not shown to lie within it, or the cost's quadratic bound is not proven on it")
    return bound
