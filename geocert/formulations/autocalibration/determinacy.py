"""How well a projective reconstruction fixes its metric upgrade (core/determinacy.py).

Critical motions (Sturm 1997; Kahl, Triggs and Astrom 2000) leave constant intrinsics
undetermined whatever the solver does; near-critical ones leave them undetermined at the data's
noise level. Both are judged here by how flat a cost is along the family of answers the motion
leaves open, against the noise the data carry, not by how closely the motion resembles an ideal
turntable:

- ``motion_warnings`` (the DIAC, the plane at infinity fixed): with H_j the infinite homographies
  (scaled to unit determinant: K R_j K^-1 up to noise), every DIAC omega obeys
  H_j omega H_j^T = omega, a linear map L of omega's six entries. Its least-squares misfit at the
  DIAC found estimates the noise (sigma, per entry: never below ``ROTATION_NOISE``, since
  rotations given exactly carry no estimate of their own); its singular values across the
  directions orthogonal to that DIAC say how far omega may move, 3 sigma / s_k along direction k,
  before the misfit grows by the noise. Where that moves K by more than ``RELATIVE_WIDTH`` of the
  focal length (core/determinacy.py: what ``determined`` allows), the motion does not fix K.
- ``plane_family`` (the affine stage): the modulus cost walked along its own ellipsoid's axes
  until it rises by cost_increase (3^2 times its residual variance, or the certified gap) or
  chirality ends the walk, the metric fit redone at each plane reached. Where the focal length
  moves by more than ``RELATIVE_WIDTH``, the plane at infinity is not fixed well enough to fix K.

The warning's code names the motion (what it looks like; the decision is the conditioning's):
``pure_translation`` (the views turn by under 3 degrees from the reference, median),
``orbital_motion`` (the camera centres spread over a plane, not along a line nor all round: rings,
turntables and arcs round an object), ``rotation_about_one_axis`` (the rotations' axes nearly one), ``critical_motion`` (any other
free family, e.g. half-turns about perpendicular axes).

Intervals: the affine stage's plane at infinity (input frame, unit norm) over the planes whose
modulus residuals cost at most ``cost_increase`` more; the metric stage's focal lengths, skew and
principal point (pixels) over the omega doing so for the metric cost, combined with the range
the plane's own family gives, clipped to the certified scope (the stratified method's: the
intrinsics ranges; the direct method's: what its combination of them bounds of each quantity,
direct_scope_of) and to positive focal lengths, never past the value (core.determinacy.clip).

Two warnings say where the data, not the motion, fall short (each makes the stage not
``determined``). ``at_range_edge`` where an interval is cut by the scope (its unclipped end
reaches beyond an intrinsics range's end, or its value lies on one): the scope, not the data,
bounds it, and the truth may lie beyond (a focal length beyond the default range's 5 image
sides); and (form 2) where K's aspect, focal_y / focal_x, lies on its range's end, a range
of the scope no interval's box holds (aspect_cut). A range no wider than what ``determined`` allows (the default skew's) fixes its quantity
by itself: an end beyond it is not reported, nor a value on its end where the interval spans it.
``no_redundancy`` where a cost has no residual beyond its parameters (the affine stage of four
views: three modulus constraints, three unknowns, an exact fit at one of their discrete
solutions), so that the data cannot estimate their noise and the level, 3^2 times a variance of
0 / 0, is no level at all; the metric stage, whose plane is that fit, says so too."""

from __future__ import annotations

import math

import numpy as np

from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import metric_relaxation
from geocert.core.determinacy import (ASPECT_EDGE_FORM, OWN_SCALE_FORM, RELATIVE_WIDTH, SIGMAS, certified_gap, clip,
                                      cost_increase, curvature_intervals, form, image_scale, interval, level_sigmas,
                                      not_analysed,
                                      numeric_jacobian, ranges_at, spread, sublevel_rays, tick)

# Radians: rotations given exactly (a metric reconstruction's) carry no noise estimate, and are not
# taken as known better than 0.6 degrees. Adjusted along a critical family they scatter by that
# much: the Oxford Dinosaur's bundle-adjusted axes lie within 3 degrees of one, and at 1e-3 its
# turntable, or any exact turntable perturbed by 0.5 degrees, was judged general. A caller that
# knows its rotations' standard error passes it as ``noise``.
ROTATION_NOISE = 1e-2
VIEW_JACKKNIFE_FORM = 2  # the first form whose stratified K intervals hold the views' jackknife
STILL_DEGREES = 3.0  # naming only: views turning less than this from the reference (median) translate
AXIS = 0.15  # naming only: rotations whose axes fit one axis this well (_axis_fit) share it
PATH = 0.1  # naming only: centres spread across their widest direction by less than this fraction lie on a path
ORBIT = 0.25  # naming only: centres on no path, thinner than this fraction of their second spread: an orbit
NAMES = ("focal_x", "focal_y", "skew", "principal_u", "principal_v")
CRITICAL_CODES = ("pure_translation", "orbital_motion", "rotation_about_one_axis", "critical_motion")
_ENTRIES = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def rotation_angles(H: np.ndarray) -> np.ndarray:
    """The rotation angle (degrees) of each H_j (m, 3, 3), from its eigenvalues' phases."""
    angles = []
    for Hj in H:
        det = np.linalg.det(Hj)
        values = np.linalg.eigvals(Hj / np.cbrt(det) if det != 0 else Hj)
        angles.append(float(np.degrees(np.abs(np.angle(values)).max())))
    return np.array(angles)


def _symmetric(coords: np.ndarray) -> np.ndarray:
    """The symmetric matrix of orthonormal coordinates (off-diagonal entries weighted 1/sqrt 2)."""
    S = np.zeros((3, 3))
    for c, (a, b) in zip(coords, _ENTRIES):
        S[a, b] = S[b, a] = c if a == b else c / math.sqrt(2.0)
    return S


def _coords(S: np.ndarray) -> np.ndarray:
    return np.array([S[a, b] if a == b else math.sqrt(2.0) * S[a, b] for a, b in _ENTRIES])


def invariance_operator(H: np.ndarray) -> np.ndarray:
    """L (6m x 6): the coordinates of H_j S H_j^T - S for every view, as a linear map of S's
    (H_j scaled to unit determinant)."""
    basis = [_symmetric(e) for e in np.eye(6)]
    blocks = []
    for Hj in H:
        det = np.linalg.det(Hj)
        if not det != 0 or not np.isfinite(det):
            continue
        Hn = Hj / np.cbrt(det)
        blocks.append(np.array([_coords(Hn @ E @ Hn.T - E) for E in basis]).T)
    return np.vstack(blocks) if blocks else np.zeros((0, 6))


def intrinsics(omega: np.ndarray) -> np.ndarray:
    """(fx, fy, skew, u, v) of the K with K K^T ~ omega (omega33 scaled to 1), NaN unless omega
    is positive definite."""
    omega = np.asarray(omega, dtype=float)
    if not (np.all(np.isfinite(omega)) and omega[2, 2] > 0):
        return np.full(5, np.nan)
    J = np.eye(3)[::-1]
    try:
        L = np.linalg.cholesky(J @ (omega / omega[2, 2]) @ J)
    except np.linalg.LinAlgError:
        return np.full(5, np.nan)
    K = J @ L @ J
    K = K * np.sign(np.diag(K))[None, :]
    K = K / K[2, 2]
    return np.array([K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]])


def change(reference: np.ndarray, other: np.ndarray) -> float:
    """How far other intrinsics are from reference ones, as ``determined`` measures it: the
    focal lengths relative to themselves, the skew and principal point relative to the focal
    length (inf when either is not a calibration)."""
    if not (np.all(np.isfinite(reference)) and np.all(np.isfinite(other))):
        return math.inf
    f = 0.5 * (abs(reference[0]) + abs(reference[1]))
    return float(max(abs(other[0] / reference[0] - 1), abs(other[1] / reference[1] - 1),
                     *(abs(other[k] - reference[k]) / f for k in (2, 3, 4))))


def _best_calibration(L: np.ndarray) -> np.ndarray | None:
    """The DIAC (coordinates) L fits best, as a calibration: on a critical motion the best fit
    alone may be any member of the family, a calibration or not. Candidates: the plane of L's two
    best fitting directions, and the identity (a camera whose image coordinates are its rays);
    among the positive definite ones fitting within the noise of the best fit, the one farthest
    from singular, else the best fitting."""
    _, singular, vt = np.linalg.svd(L, full_matrices=False)
    noise = singular[-1] / math.sqrt(max(len(L) - 5, 1))
    allowed = singular[-1] ** 2 + (SIGMAS * noise) ** 2
    candidates = [math.cos(a) * vt[-1] + math.sin(a) * vt[-2] for a in np.linspace(0.0, math.pi, 181)[:-1]]
    candidates.append(_coords(np.eye(3)) / math.sqrt(3.0))
    fitting, best, best_misfit = [], None, math.inf
    for candidate in candidates:
        candidate = candidate if np.trace(_symmetric(candidate)) >= 0 else -candidate
        smallest = float(np.linalg.eigvalsh(_symmetric(candidate))[0])
        if not smallest > 0:
            continue
        misfit = float(np.linalg.norm(L @ candidate))
        if misfit ** 2 <= allowed:
            fitting.append((smallest, candidate))
        if misfit < best_misfit:
            best, best_misfit = candidate, misfit
    return max(fitting, key=lambda pair: pair[0])[1] if fitting else best


def diac_family(H: np.ndarray, omega: np.ndarray | None = None, noise: float | None = None,
                threshold: float = RELATIVE_WIDTH) -> dict | None:
    """The directions along which the DIAC is free at the noise level (module docstring): their
    count (those moving K by more than ``threshold``), the largest move of K within 3 standard
    errors along any direction, sigma and the singular values. None when no DIAC positive definite
    fits (nothing to measure around)."""
    L = invariance_operator(H)
    if len(L) < 6:
        return None
    if omega is None:
        best = _best_calibration(L)
        if best is None:
            return None
    else:
        best = _coords(np.asarray(omega, dtype=float))
    best = best / np.linalg.norm(best)
    if np.trace(_symmetric(best)) < 0:
        best = -best
    here = intrinsics(_symmetric(best))
    if not np.all(np.isfinite(here)):
        return None
    redundancy = max(len(L) - 5, 1)
    misfit = float(np.linalg.norm(L @ best))
    sigma = float(noise) if noise is not None else max(misfit / math.sqrt(redundancy), ROTATION_NOISE)
    basis = np.linalg.svd(best[None, :])[2][1:].T  # (6, 5): omega's directions that are not its scale
    _, singular, vt = np.linalg.svd(L @ basis, full_matrices=False)
    moves = []
    for s, v in zip(singular, vt):
        step = SIGMAS * sigma / s if s > 0 else math.inf
        if not math.isfinite(step):
            moves.append(math.inf)
            continue
        moves.append(max(change(here, intrinsics(_symmetric(best + sign * step * (basis @ v)))) for sign in (1, -1)))
    moves = np.array(moves)
    return {"free": int(np.sum(moves > threshold)), "largest_move": float(moves.max()), "sigma": sigma,
            "singular": singular, "moves": moves}


def _axis_fit(H: np.ndarray) -> float:
    """How nearly the rotations share one axis (0: exactly): the stacked H_j / det^(1/3) - I's
    smallest singular value over the next (for the warning's detail only)."""
    stacked = [Hj / np.cbrt(np.linalg.det(Hj)) - np.eye(3) for Hj in H if np.linalg.det(Hj) != 0]
    if not stacked:
        return math.nan
    s = np.linalg.svd(np.vstack(stacked), compute_uv=False)
    return float(s[2] / max(float(s[1]), 1e-300))


def motion_name(H: np.ndarray, centres: np.ndarray | None) -> tuple[str, str]:
    """(code, what the motion looks like): named by its geometry alone (the rotation angles are
    K's conjugates', read off H's eigenvalues), whatever the noise made of the decision."""
    angles = rotation_angles(H)
    looks = f"the views rotate by {np.median(angles):.3g} degrees from the reference (median; {angles.max():.3g} at most)"
    fit = _axis_fit(H)
    if math.isfinite(fit):
        looks += f", their axes fit one axis to {fit:.2g}"
    if np.median(angles) < STILL_DEGREES:
        return "pure_translation", looks
    if centres is not None and len(centres) >= 4 and np.all(np.isfinite(centres)):
        widths = spread(centres)
        orbit = widths[1] >= PATH and widths[2] < ORBIT * widths[1]
        looks += (f", the camera centres' spreads are {widths[1]:.2g} and {widths[2]:.2g} of their widest "
                  f"({'a path' if widths[1] < PATH else 'a ring or an arc' if orbit else 'all round'})")
        if orbit:
            return "orbital_motion", looks
    return ("rotation_about_one_axis" if fit < AXIS else "critical_motion"), looks


def rotation_plane_family(rotations: np.ndarray, reference: np.ndarray, centres: np.ndarray,
                          noise: float | None = None) -> dict | None:
    """``plane_family`` for a metric reconstruction: rotations R_j R_0^T relative to the
    reference view (rotation ``reference``, R_0), the centres (m + 1 rows, the reference's
    first). In the reference camera's frame the cameras are [H_j | -H_j c_j] and the plane at
    infinity is p = 0; the modulus cost is walked from there to the noise level (each camera's
    left 3x3 entries known to ``noise``, default ``ROTATION_NOISE``: the residuals' standard
    errors are that times their gradients in those entries), chirality keeping every centre on
    one side, and the DIAC refitted (linearly) on each plane reached. Returns the largest move of
    K from the identity and how many walks ended beyond any calibration; None when the data are
    not a metric reconstruction of at least 3 views."""
    R = np.asarray(rotations, dtype=float)
    C = np.asarray(centres, dtype=float)
    if len(R) < 2 or len(C) != len(R) + 1 or not np.all(np.isfinite(C)):
        return None
    sigma = ROTATION_NOISE if noise is None else float(noise)
    c = (np.asarray(reference, dtype=float) @ (C[1:] - C[0]).T).T  # the centres in the reference's frame
    size = max(float(np.abs(c).max()), 1e-300)
    c = c / size  # the translations' scale is arbitrary: unit size keeps p of order one
    cameras = np.concatenate([np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1)[None],
                              np.concatenate([R, -np.einsum("jab,jb->ja", R, c)[:, :, None]], axis=2)])
    coef, _ = frames.modulus_coefficients(cameras, 0)

    def residuals(q):
        return frames.modulus_residuals(coef, q)

    zero = np.zeros(3)
    J = numeric_jacobian(residuals, zero)
    per_view = np.array([np.linalg.norm(numeric_jacobian(lambda a, j=j: _view_residual(coef, cameras, j, a),
                                                         cameras[j + 1, :, :3].ravel())) for j in range(len(R))])
    delta = SIGMAS ** 2 * float(np.mean((sigma * per_view) ** 2)) * len(R) / max(len(R) - 3, 1)
    rows = np.concatenate([c, np.ones((len(c), 1))], axis=1)

    def allowed(q):
        return bool(np.all(rows @ np.append(q, 1.0) > 0))

    points = sublevel_rays(lambda q: float(residuals(q) @ residuals(q)), zero, J.T @ J,
                           float(residuals(zero) @ residuals(zero)) + delta, [], allowed=allowed)
    here = intrinsics(np.eye(3))
    moves = []
    for q in points:
        if q is None:
            moves.append(math.inf)
            continue
        H = R - np.einsum("ja,b->jab", -np.einsum("jab,jb->ja", R, c), q)
        L = invariance_operator(H)
        best = _best_calibration(L) if len(L) >= 6 else None
        moves.append(math.inf if best is None else change(here, intrinsics(_symmetric(best))))
    return {"largest_move": max(moves), "cost_increase": delta, "sigma": sigma}


def _view_residual(coef, cameras, j, entries):
    """View j's modulus residual at p = 0 as a function of its left 3x3 block's entries."""
    A = entries.reshape(3, 3)
    tr = np.trace(A)
    minors = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0] + A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]
              + A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
    return np.array([np.cbrt(np.linalg.det(A)) * tr - minors])


def _moved(move: float) -> str:
    """How far a critical family moves K, in words (a relative move of the focal length)."""
    return "to no calibration at all" if not math.isfinite(move) else f"by {100 * move:.3g}% of the focal length"


def motion_warnings(H: np.ndarray, centres: np.ndarray | None, noise: float | None = None,
                    omega: np.ndarray | None = None, reference: np.ndarray | None = None,
                    plane_noise: float | None = None, threshold: float = RELATIVE_WIDTH) -> list[dict]:
    """The critical motion, if any, of views whose infinite homographies are H (m, 3, 3; for a
    metric reconstruction, the rotations relative to one view) and whose centres are ``centres``
    (m or m + 1 rows, or None). ``noise``: the standard error of the H's entries (radians for
    rotations), when the caller knows it; ``omega``: the DIAC in H's frame to measure around
    (default: the one the H fit best); ``reference``: for a metric reconstruction, the reference
    view's rotation R_0 (H = R_j R_0^T), with the centres of every view, the reference's first:
    then the plane at infinity's own family is judged too (``rotation_plane_family``), as the
    autocalibration kind's affine stage judges it, with the rotations known to ``plane_noise``
    (default ``noise``: a caller whose rotations were adjusted may hold the DIAC's judgement to
    ROTATION_NOISE, the drift along a critical family, and the plane's to the residuals' own
    noise). ``threshold``: the move of K that is too far (``RELATIVE_WIDTH``; the verifier asks
    just either side of it, to demand only a judgement no rounding can turn). Returns [] or one
    warning {code, detail}."""
    H = np.asarray(H, dtype=float)
    if len(H) < 2:
        return []
    family = diac_family(H, omega, noise, threshold)
    if reference is not None and centres is not None and (family is None or family["free"] == 0):
        planes = rotation_plane_family(H, reference, centres, noise if plane_noise is None else plane_noise)
        if planes is not None and planes["largest_move"] > threshold:
            code, looks = motion_name(H, centres)
            moved = _moved(planes["largest_move"])
            return [{"code": code,
                     "detail": f"the modulus cost rises by no more than the noise ({SIGMAS:g} standard errors, each "
                               f"camera known to {planes['sigma']:.2g}) along a family of planes at infinity that "
                               f"moves K {moved} (more than {100 * RELATIVE_WIDTH:g}%); {looks}: a near-critical "
                               "motion for constant intrinsics (the plane at infinity is not fixed)"}]
    if family is None or family["free"] == 0:
        return []
    # Every direction free although the views turn by more than the noise: the H do not fit one
    # K at all (a wrong plane at infinity, varying intrinsics), which is not a motion's doing.
    still = bool(np.median(np.radians(rotation_angles(H))) < SIGMAS * family["sigma"])
    if family["free"] >= 5 and not still:
        return []
    code, looks = motion_name(H, centres)
    moved = _moved(family["largest_move"])
    return [{"code": code,
             "detail": f"the DIAC is free along {family['free']} of its 5 directions at the data's noise level "
                       f"(sigma {family['sigma']:.2g}): {SIGMAS:g} standard errors along them move K {moved} "
                       f"(more than {100 * RELATIVE_WIDTH:g}%); {looks}: a critical motion for constant intrinsics"}]


def judged_motion(problem, p: np.ndarray, K_pixels: np.ndarray | None, centres: np.ndarray | None) -> list[dict]:
    """The DIAC family's critical-motion warning at the plane p and the returned K's DIAC (None:
    the DIAC the infinite homographies fit best), alone: cheap, and judged again by the verifier
    from the returned plane and K whatever the stage's analysis came to."""
    from geocert.formulations.autocalibration.problem import w_of_K

    H = metric_relaxation.homographies(problem.norm.cameras, problem.norm.reference, p)
    omega = None if K_pixels is None else metric_relaxation.omega_of(w_of_K(problem, np.asarray(K_pixels, float)))
    return motion_warnings(H, centres, omega=omega)


def with_motion(document: dict | None, judged: list[dict] | None, what: str) -> dict | None:
    """A stage's determinacy that its clock stopped (core.determinacy.not_analysed) or that failed
    (None: the data defeated its linear algebra) still states the critical motion ``judged``
    (judged_motion), after its ``time_limit`` or ``not_analysed`` warning: a stage stopped or
    failed is no place to hide one (review 43). An analysis that ran states its own."""
    if not judged:
        return document
    if document is None:
        document = not_analysed(what, "the data defeated its linear algebra", "not_analysed")
    elif document.get("intervals") != [] or len(document.get("warnings") or []) != 1:
        return document
    return {**document, "warnings": [*document["warnings"], *judged]}


def _merge(warnings: list[dict], more: list[dict]) -> list[dict]:
    """One warning per code, the details of a repeated code joined."""
    out = [dict(w) for w in warnings]
    for w in more:
        same = next((o for o in out if o["code"] == w["code"]), None)
        if same is None:
            out.append(dict(w))
        else:
            same["detail"] += "; and " + w["detail"]
    return out


def refit(problem, p: np.ndarray, w: np.ndarray) -> np.ndarray | None:
    """The metric cost's local minimum over omega for the plane (p, 1), started at w (the
    intrinsics ranges not imposed: the interval is clipped to them afterwards)."""
    from scipy.optimize import least_squares

    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    try:
        fit = least_squares(lambda x: metric_relaxation.residuals(setup, x), w, method="lm", xtol=1e-12, ftol=1e-12)
    except (ValueError, np.linalg.LinAlgError):
        return None
    return fit.x if np.all(np.isfinite(fit.x)) else None


def _K_of_w(problem, w: np.ndarray | None) -> np.ndarray:
    """(fx, fy, skew, u, v) in pixels for preconditioned omega entries w (NaN when not a K)."""
    if w is None:
        return np.full(5, np.nan)
    k = intrinsics(metric_relaxation.omega_of(w))
    if not np.all(np.isfinite(k)):
        return k
    K = problem.K0 @ np.array([[k[0], k[2], k[3]], [0.0, k[1], k[4]], [0.0, 0.0, 1.0]])
    return np.array([K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]])


def modulus_walk(problem, p: np.ndarray, gap: float | None, extra: list | None = None) -> dict:
    """The modulus cost's residuals at the plane p, their Jacobian, its level (``cost_increase``
    over its own residuals' variance, or the certified ``gap``) and the planes its walk reaches
    (``sublevel_rays`` along the ellipsoid's axes and the ``extra`` gradients' extreme directions,
    chirality ending a walk): numpy only, so that the verifier walks again what the writer walked."""
    coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
    rows = [frames.chirality_rows(problem.norm, delta) for delta in (1.0, -1.0)]

    def allowed(q):  # problem.allowed_by_chirality, its rows made once
        values = [r @ np.append(q, 1.0) for r in rows]
        return any(bool(np.all(v > 0) or np.all(v < 0)) for v in values)

    def residuals(q):
        return frames.modulus_residuals(coef, q)

    J = numeric_jacobian(residuals, p)
    r = residuals(p)
    cost = float(r @ r)
    delta = cost_increase(cost, len(r) - 3, gap)
    points = sublevel_rays(lambda q: float(residuals(q) @ residuals(q)), p, J.T @ J, cost + delta, extra or [],
                           allowed=allowed)
    return {"J": J, "residuals": r, "cost_increase": delta, "points": points}


def plane_family(problem, p: np.ndarray, w: np.ndarray | None, gap: float | None, extra: list | None = None,
                 walk: dict | None = None) -> dict:
    """The planes the modulus cost cannot tell from p at its noise level (module docstring),
    walked along its ellipsoid's axes and the directions extreme for ``extra`` gradients
    (``walk``: that walk made already); with the metric fit redone at each (w: the fit at p; None:
    the linear method's, refined)."""
    walk = walk or modulus_walk(problem, p, gap, extra)
    points = walk["points"]
    if w is None:
        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
        w = refit(problem, p, metric_relaxation.linear_baseline(setup)[0])
    here = _K_of_w(problem, w)
    Ks = []
    for q in points:
        tick()  # each refit is a least-squares fit of its own
        Ks.append(None if q is None else _K_of_w(problem, refit(problem, q, w)) if w is not None else np.full(5, np.nan))
    moves = [math.inf if k is None else change(here, k) for k in Ks]
    return {**walk, "K": here, "Ks": Ks, "w": w, "largest_move": max(moves) if moves else 0.0}


def _plane_warning(family: dict, H: np.ndarray, centres: np.ndarray | None, named: list[dict]) -> list[dict]:
    """The warning when the plane's family moves K by more than ``determined`` allows; its code
    the motion warnings' (``named``) when they name the motion, else by the centres' shape."""
    move = family["largest_move"]
    if not move > RELATIVE_WIDTH or not np.all(np.isfinite(family["K"])):
        return []
    focal = [k[0] for k in family["Ks"] if k is not None and np.isfinite(k[0])]
    reach = ("to planes with no calibration at all" if not math.isfinite(move) or len(focal) < len(family["Ks"])
             else f"over planes whose constant-K fit has a focal length from {min(focal):.4g} to {max(focal):.4g} px")
    code, looks = motion_name(H, centres)
    if named:
        code = named[0]["code"]
    return [{"code": code,
             "detail": f"the modulus cost rises by at most {family['cost_increase']:.3g} (the noise level: "
                       f"{SIGMAS:g} standard errors of its own residuals) {reach}, against "
                       f"{family['K'][0]:.4g} px at the plane found (more than {100 * RELATIVE_WIDTH:g}% apart): the "
                       f"motion does not fix the plane at infinity; {looks}: a critical or near-critical motion for "
                       "constant intrinsics"}]


def affine_walk(problem, p: np.ndarray, gap: float | None) -> dict:
    """The affine stage's intervals (the plane at infinity as the result states it, over the planes
    the modulus walk reaches) and that walk (``modulus_walk``, its extra directions the stated
    plane's coordinates' gradients): numpy only, the verifier's too."""
    from geocert.formulations.autocalibration.problem import plane_in_input

    plane = plane_in_input(problem, p)  # as the result states it

    def plane_of(q):  # nearby planes with the returned plane's sign
        out = plane_in_input(problem, q)
        return out if out @ plane >= 0 else -out

    gradient = numeric_jacobian(plane_of, p)
    walk = modulus_walk(problem, p, gap, list(gradient))
    value = plane_of(p)
    lo, hi = ranges_at(value, [None if q is None else plane_of(q) for q in walk["points"]])
    return {**walk, "value": value, "gradient": gradient,
            "intervals": [interval(f"plane_at_infinity[{k}]", value[k], lo[k], hi[k]) for k in range(4)]}


def affine_stage(problem, p: np.ndarray, cost: float | None, lower: float | None, centres: np.ndarray | None,
                 K_pixels: np.ndarray | None = None) -> dict:
    from geocert.formulations.autocalibration.problem import w_of_K

    walk = affine_walk(problem, p, certified_gap(cost, lower))
    w = None if K_pixels is None else w_of_K(problem, np.asarray(K_pixels, dtype=float))
    family = plane_family(problem, p, w, certified_gap(cost, lower), walk=walk)
    quantities = {f"plane_at_infinity[{k}]": (float(walk["value"][k]), walk["gradient"][k]) for k in range(4)}
    out = curvature_intervals(family["J"], family["residuals"], quantities, certified_gap(cost, lower))
    out.intervals = walk["intervals"]
    H = metric_relaxation.homographies(problem.norm.cameras, problem.norm.reference, p)
    omega = (None if family["w"] is None or not np.all(np.isfinite(family["K"]))
             else metric_relaxation.omega_of(family["w"]))
    named = motion_warnings(H, centres, omega=omega)
    out.warnings = _merge(_merge(out.warnings, named), _plane_warning(family, H, centres, named))
    out.warnings += no_redundancy("the affine stage's modulus constraints", len(family["residuals"]), 3)
    return out.document()


def no_redundancy(what: str, residuals: int, parameters: int) -> list[dict]:
    """The warning of a cost with no residual beyond its parameters (module docstring): none
    where it has some."""
    if residuals > parameters:
        return []
    return [{"code": "no_redundancy",
             "detail": f"{what}: {residuals} residuals for {parameters} parameters, no redundancy: the fit is exact "
                       "whatever the noise, so the data cannot estimate their noise and the intervals' level "
                       f"({SIGMAS:g}^2 times the residual variance) is not estimated, and the fit may be a wrong "
                       "one of the constraints' exact solutions. More views fix it"}]


EDGE = 1e-9  # relative: a value this close to an intrinsics range's end lies on it


def clipped_to_scope(found: dict, lowest: float | None, highest: float | None) -> tuple[dict, str | None]:
    """An interval clipped to its scope (core.determinacy.clip) and, where the scope cuts it, what
    the clip hid: its value on (or beyond) a range's end (the optimum pinned there: the data pull
    beyond it), or its end beyond a range's end. A range no wider than the interval's tolerance
    allows (2 tolerances: the default skew's, 2% of the image side against a tenth of half the
    image's larger side, core.determinacy.image_scale) fixes its quantity by itself, the user's
    statement of it rather than a search range:
    an end beyond it is not reported, nor a value on its end where the interval spans it all (the
    data then do not prefer one value in it to another; the default skew pinned at its end over a
    general motion)."""
    value, tolerance, cut = found["value"], found.get("tolerance"), []
    narrow = (lowest is not None and highest is not None and tolerance is not None
              and highest - lowest <= 2.0 * tolerance)
    clipped = clip(dict(found), lowest, highest)
    spans = narrow and clipped["lower"] == lowest and clipped["upper"] == highest
    for end, edge, sign in (("lower", lowest, -1.0), ("upper", highest, 1.0)):
        if edge is None or not math.isfinite(edge):
            continue
        reach = found[end]
        if value is not None and sign * (value - edge) >= -EDGE * max(abs(edge), 1.0) and not spans:
            cut.append(f"its value {value:.6g} lies on the range's {end} end {edge:.6g}")
        elif not narrow and reach is not None and sign * (reach - edge) > 0:
            cut.append(f"its {end} end {reach:.6g} lies beyond the range's {edge:.6g}")
    return clip(found, lowest, highest), (f"{found['name']} ({' and '.join(cut)})" if cut else None)


def aspect_cut(value, lowest: float, highest: float) -> str | None:
    """Where K's aspect (focal_y / focal_x, ``value`` K's five NAMES) lies on (or beyond) an end of
    the aspect range, a range of the stratified scope that no interval's box holds (scope_of clips
    focal_y to [focal's low * aspect's low, focal's high * aspect's high], which a K pinned on the
    aspect's end lies well inside): what it says (None: not cut). The aspect's scale is its value,
    as a focal length's (core.determinacy.tolerance): a range no wider than two tolerances fixes
    it by itself (the default, 0.95 to 1.05), the user's statement of it, and is not reported
    (clipped_to_scope's narrow range, whose spanning the aspect, stating no interval, cannot ask).
    Form ASPECT_EDGE_FORM on."""
    fx, fy = float(value[0]), float(value[1])
    if form() < ASPECT_EDGE_FORM or not (fx > 0 and math.isfinite(fx) and math.isfinite(fy)):
        return None
    aspect = fy / fx
    if highest - lowest <= 2.0 * RELATIVE_WIDTH * abs(aspect):
        return None
    for end, edge, sign in (("lower", lowest, -1.0), ("upper", highest, 1.0)):
        if sign * (aspect - edge) >= -EDGE * max(abs(edge), 1.0):
            return (f"the aspect focal_y / focal_x (its value {aspect:.6g} lies on the aspect range's {end} end "
                    f"{edge:.6g})")
    return None


def range_edge(cut: list[str | None]) -> list[dict]:
    """The ``at_range_edge`` warning naming the quantities whose intervals the scope cut (none: no
    warning)."""
    named = [c for c in cut if c]
    if not named:
        return []
    return [{"code": "at_range_edge",
             "detail": f"the intrinsics ranges (the certified scope) cut the interval of {'; '.join(named)}: there "
                       "the scope, not the data, bounds the quantity, and answers as good lie beyond it; widen "
                       "the range (options.intrinsics) to learn whether the data fix it"}]


def scope_of(problem) -> list[tuple[float | None, float | None]]:
    """Each of NAMES' clip: the intrinsics ranges (the stratified metric stage's certified scope;
    the direct method's is not these: direct_scope_of)."""
    r = problem.ranges
    (fl, fu), (al, au), (sl, su) = r["focal"], r["aspect"], r["skew"]
    (ul, uu), (vl, vu) = r["principal_point"]
    return [(max(fl, 0.0), fu), (max(fl * al, 0.0), fu * au), (sl, su), (ul, uu), (vl, vu)]


def direct_scope_of(problem) -> list[tuple[float | None, float | None]]:
    """Each of NAMES' clip for the direct method: its scope holds each view's combination
    (w11 + w22) / w33 = fx^2 + fy^2 + skew^2 + (u - u0)^2 + (v - v0)^2 (preconditioned) within
    [low, high] (direct.focal_rows), not each intrinsic within its own range, so its certified K
    may lie beyond one range (review 62: f = 1000 with the focal range [300, 990]). What that
    scope bounds of each quantity alone: |each| <= f0 sqrt(high) about K0's (the others 0), the
    focal lengths positive; no lower end of its own beyond that (the others can make up low)."""
    from geocert.formulations.autocalibration.direct_sublevel import scope_range

    high = 2.0 * scope_range(problem.unit_ranges)[1]
    f0, u0, v0 = float(problem.K0[0, 0]), float(problem.K0[0, 2]), float(problem.K0[1, 2])
    reach = f0 * math.sqrt(high)
    return [(0.0, reach), (0.0, reach), (-reach, reach), (u0 - reach, u0 + reach), (v0 - reach, v0 + reach)]


def metric_walk(problem, p: np.ndarray, w: np.ndarray, gap: float | None) -> dict:
    """The metric stage's estimate at the plane p and omega entries w before the plane's own
    family is added: the metric residuals, their Jacobian, K's entries and their gradients, the
    curvature estimate (its level), and the intrinsics over the omega the metric cost's walk
    reaches, clipped as the stage clips (``intervals``; the stage's own are these widened by the
    plane's family, so they hold these). Numpy only: the verifier walks it again."""
    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    informative = np.concatenate([np.arange(5) + 6 * j for j in range(len(setup.H))])  # the 33 entry is 0

    def residuals(x, q=p):
        here = setup if q is p else metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, q,
                                                                problem.unit_ranges)
        return metric_relaxation.residuals(here, x)[informative]

    J = numeric_jacobian(residuals, w)
    value = _K_of_w(problem, w)
    gradient = numeric_jacobian(lambda x: _K_of_w(problem, x), w)
    f = 0.5 * (abs(value[0]) + abs(value[1]))
    # skew and principal point: the image's scale in today's form (core.determinacy.image_scale),
    # the focal length's before
    own = image_scale(problem.image_size, problem.ranges["principal_point"]) if form() >= OWN_SCALE_FORM else None
    side = f if own is None else own
    scales = (value[0], value[1], side, side, side)
    quantities = {name: (float(value[k]), gradient[k], scales[k]) for k, name in enumerate(NAMES)}
    out = curvature_intervals(J, residuals(w), quantities, gap)
    # omega's own uncertainty: the metric cost walked to cost + delta along its ellipsoid.
    r = residuals(w)
    points = sublevel_rays(lambda x: float(residuals(x) @ residuals(x)), w, J.T @ J,
                           float(r @ r) + float(out.cost_increase or 0.0), list(gradient))
    lo, hi = ranges_at(value, [None if x is None else _K_of_w(problem, x) for x in points])
    bounds = scope_of(problem)
    return {"setup": setup, "residuals": residuals, "J": J, "value": value, "gradient": gradient, "scales": scales,
            "estimate": out, "lower": lo, "upper": hi,
            "intervals": [clip(interval(name, value[k], lo[k], hi[k], scales[k]), *bounds[k])
                          for k, name in enumerate(NAMES)]}


def _without_view(problem, p: np.ndarray, view: int) -> tuple[np.ndarray, int, np.ndarray] | None:
    """The normalised cameras without ``view``, their reference and the plane (p, 1) in their frame:
    the same frame unless ``view`` is the reference, else that of the remaining cameras' reference
    (frames.reference_camera), the plane carried along (pi -> T^T pi)."""
    cameras, reference = problem.norm.cameras, problem.norm.reference
    kept = np.delete(cameras, view, axis=0)
    if view != reference:
        return kept, reference - (view < reference), p
    r = frames.reference_camera(kept)
    A, a = kept[r, :, :3], kept[r, :, 3]
    try:
        Ainv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return None
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Ainv, -Ainv @ a
    moved = kept @ T
    moved /= np.linalg.norm(moved, axis=(1, 2))[:, None, None] / np.sqrt(3.0)
    moved[r] = np.hstack([np.eye(3), np.zeros((3, 1))])
    plane = T.T @ np.append(p, 1.0)
    if not abs(plane[3]) > 1e-300:
        return None
    return moved, r, plane[:3] / plane[3]


def view_jackknife(problem, p: np.ndarray, w: np.ndarray) -> np.ndarray | None:
    """The delete-one-view jackknife's standard deviation of K's five NAMES (pixels): each view left
    out in turn, the modulus fit and the metric fit redone from (p, w). The views, not the
    residuals, are the independent units: every modulus and DIAC residual is written in the
    reference view's frame, so that view's noise is common to them all and moves the estimate
    without raising the cost, which a level from the residuals' own variance cannot see (on the
    dino's hemisphere the estimate's spread over noise draws was twice the curvature's; docs/
    kinds.md). None where a fit fails or fewer than five views remain."""
    from scipy.optimize import least_squares

    m = len(problem.norm.cameras)
    if m - 1 < 5:
        return None
    samples = []
    for view in range(m):
        tick()
        moved = _without_view(problem, p, view)
        if moved is None:
            return None
        cameras, reference, q = moved
        coef, _ = frames.modulus_coefficients(cameras, reference)
        try:
            q = least_squares(lambda x: frames.modulus_residuals(coef, x), q, method="lm", xtol=1e-12,
                              ftol=1e-12).x
            setup = metric_relaxation.setup_for(cameras, reference, q, problem.unit_ranges)
            x = least_squares(lambda x: metric_relaxation.residuals(setup, x), w, method="lm", xtol=1e-12,
                              ftol=1e-12).x
        except (ValueError, np.linalg.LinAlgError):
            return None
        k = _K_of_w(problem, x)
        if not np.all(np.isfinite(k)):
            return None
        samples.append(k)
    samples = np.array(samples)
    return np.sqrt((m - 1) / m * ((samples - samples.mean(axis=0)) ** 2).sum(axis=0))


def metric_intervals(problem, p: np.ndarray, w: np.ndarray, gap: float | None, direct: bool = False) -> dict:
    """The metric stage's intervals at the plane p and omega entries w: the metric walk's and the
    plane family's (the modulus cost's, to its own noise level, the metric fit redone on each plane
    it reaches) added in quadrature, clipped to the certified scope (the intrinsics ranges;
    ``direct``: the direct method's, direct_scope_of); with the walk and the family (the verifier
    makes them again: the family's refits with the writer's scipy, as the rest of an
    autocalibration's check)."""
    walk = metric_walk(problem, p, w, gap)
    residuals, J, value, scales = (walk[k] for k in ("residuals", "J", "value", "scales"))
    # The plane is an estimate too: its family moves the optimum, in the directions extreme for K.
    Jp = numeric_jacobian(lambda q: residuals(w, q), p)
    try:
        D = -np.linalg.lstsq(J, Jp, rcond=None)[0]  # dw*/dp, 5 x 3: the directions extreme for K
        extra = list(walk["gradient"] @ D)
    except np.linalg.LinAlgError:
        extra = []
    family = plane_family(problem, p, w, None, extra)
    lo_p, hi_p = ranges_at(value, family["Ks"])
    lower_end = value - np.hypot(value - walk["lower"], value - lo_p)
    upper_end = value + np.hypot(walk["upper"] - value, hi_p - value)
    # Form VIEW_JACKKNIFE_FORM on (the stratified method's): never narrower than the views'
    # jackknife at the level's quantile of its m - 1 degrees of freedom (view_jackknife: the
    # reference view's noise, which the walks cannot see)
    jackknife = None if direct or form() < VIEW_JACKKNIFE_FORM else view_jackknife(problem, p, w)
    if jackknife is not None:
        reach = level_sigmas(len(problem.norm.cameras) - 1) * jackknife
        lower_end, upper_end = np.minimum(lower_end, value - reach), np.maximum(upper_end, value + reach)
    unclipped = [interval(name, value[k], lower_end[k], upper_end[k], scales[k]) for k, name in enumerate(NAMES)]
    scope = (direct_scope_of if direct else scope_of)(problem)
    clipped = [clipped_to_scope(dict(found), *bounds) for found, bounds in zip(unclipped, scope)]
    # the stratified scope's aspect range, which none of the boxes holds (aspect_cut); the direct
    # method's scope is its combination, no aspect range of its own
    aspect = None if direct else tuple(float(e) for e in problem.ranges["aspect"])
    cut = [cut for _, cut in clipped] + ([] if aspect is None else [aspect_cut(value, *aspect)])
    return {"walk": walk, "family": family, "jackknife": jackknife, "intervals": [found for found, _ in clipped],
            "cut": cut, "unclipped": unclipped, "scope": scope, "aspect": aspect}


def metric_stage(problem, p: np.ndarray, K_pixels: np.ndarray, cost: float | None, lower: float | None,
                 centres: np.ndarray | None, direct: bool = False) -> dict:
    """K's intervals (metric_intervals; ``direct``: the direct method's, clipped to its scope) and
    the motion's warnings: the DIAC family's and the plane family's."""
    from geocert.formulations.autocalibration.problem import w_of_K

    w = w_of_K(problem, K_pixels)
    found = metric_intervals(problem, p, w, certified_gap(cost, lower), direct)
    out = found["walk"]["estimate"]
    out.intervals = found["intervals"]
    H = found["walk"]["setup"].H
    named = motion_warnings(H, centres, omega=metric_relaxation.omega_of(w))
    out.warnings = _merge(_merge(out.warnings, named), _plane_warning(found["family"], H, centres, named))
    # the plane is an estimate too (its family widens K's intervals): its modulus constraints'
    # redundancy as well as the DIAC entries'
    out.warnings += no_redundancy("the modulus constraints that give the plane at infinity's share of these "
                                  "intervals", len(found["family"]["residuals"]), 3)
    out.warnings += no_redundancy("the DIAC entries", *found["walk"]["J"].shape)
    out.warnings += range_edge(found["cut"])
    return out.document()


def varying_focal_residuals(problem, theta: np.ndarray) -> np.ndarray:
    """varying_focal_stage's residuals at theta = (a_0 .. a_m-1, the plane's 3 coordinates): each
    other view's DIAC diag(a_i^2, a_i^2, 1) less the reference view's carried by H_i, weighted as
    the metric stage's five entries (the verifier reads the stage's level from them)."""
    reference, m = problem.norm.reference, len(problem.norm.cameras)
    focal, q = theta[:m], theta[m:]
    H = metric_relaxation.homographies(problem.norm.cameras, reference, q)
    omega_ref = np.diag([focal[reference] ** 2, focal[reference] ** 2, 1.0])
    out = []
    for j, i in enumerate(i for i in range(m) if i != reference):
        image = H[j] @ omega_ref @ H[j].T
        diff = np.diag([focal[i] ** 2, focal[i] ** 2, 1.0]) - image / image[2, 2]
        out.append(metric_relaxation.WEIGHTS[:5] * np.array([diff[x, y] for x, y in metric_relaxation.ENTRIES]))
    return np.concatenate(out)


def varying_focal_stage(problem, p: np.ndarray, Ks: list, centres: np.ndarray | None) -> dict | None:
    """One focal length per view (zero skew, unit aspect, the principal point at the
    preconditioner's): each view's DIAC diag(a_i^2, a_i^2, 1) (preconditioned, a_i = f_i / f0)
    against the reference view's carried by H_i, with the plane p free too."""
    if any(K is None for K in Ks):
        return None
    f0 = float(problem.K0[0, 0])
    a = np.array([float(np.asarray(K)[0, 0]) / f0 for K in Ks])
    m = len(Ks)

    def residuals(theta):
        return varying_focal_residuals(problem, theta)

    theta = np.concatenate([a, p])
    J = numeric_jacobian(residuals, theta)
    quantities = {f"focal[{i}]": (f0 * a[i], f0 * np.eye(len(theta))[i], f0 * a[i]) for i in range(m)}
    out = curvature_intervals(J, residuals(theta), quantities)
    for found in out.intervals:
        clip(found, 0.0, None)
    norm = problem.norm
    out.warnings += motion_warnings(metric_relaxation.homographies(norm.cameras, norm.reference, p), centres)
    out.warnings += no_redundancy("the per-view focal lengths' DIAC entries", len(J), len(theta))
    return out.document()
