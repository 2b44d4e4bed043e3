"""Many triangulation tracks at once: what ``triangulate`` returns for each, with the Python-level
work shared by every track of a group (same number of views and of branched functionals).

One track's solve is some 1,500 small Python-level calls (chart, DLT, local refinement, the
root region's 2d small SOCPs, the first relaxation) around little arithmetic. Here each stage
is done for a whole group with stacked numpy arrays:

* the charts (stacked._charts, the verifier's stacked Chart.build) and the DLT starts;
* the local refinement: a batched Levenberg-Marquardt on the L2L2 residuals;
* the root region: the 2d bounds of every track by a batched log-barrier method (each bound
  is then the safe bound of its own dual vector, cones.safe_lower_bound's, exactly as
  search.prove_root proves it: a solve that is not accurate only makes a looser bound);
* the root node's relaxation: assembled for the group (stacked.leaf_relaxations, row for row
  Relaxation.conic_data) and each solved by Clarabel as BoxProblem._bound solves it; its
  bound is the safe bound of the dual returned.

A track whose root node closes the gap ends there, as the one-node search of ``triangulate``
would; any other track (not closed at the root, a chart or start this path does not build,
a bound not proven, max_residual given, ...) is solved by ``triangulate`` itself.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import defaultdict

import numpy as np

from geocert.solvers.core.bnb import Box
from geocert.solvers.core.certificates import LeafProof, RootProof, SearchProof, encode
from geocert.solvers.core.conic import ConicStatus, ReusableConicProgram
from geocert.solvers.core.cones import ConeSpec, safe_lower_bound
from geocert.solvers.core.geometry import normalised_cameras
from geocert.solvers.fractional import stacked
from geocert.solvers.fractional.charts import Chart
from geocert.solvers.fractional.options import TriangulationOptions
from geocert.solvers.fractional.relaxation import FractionalProgram, complete_functionals, cost_unit, gamma_for
from geocert.solvers.fractional.results import SearchCertificate, TrackResult
from geocert.solvers.fractional.search import MAX_SCALE, branch_directions, depth_subspace, local_refine
from geocert.solvers.fractional.triangulation import _track_result, triangulate
from geocert.solvers.verify import self_check, self_check_enabled
from geocert.solvers.fractional.results import claim_of

D = 3
SCOPE = "every point in front of every camera"
MAX_GROUP = 256  # tracks stacked in one group's arrays


def triangulate_many(cameras: np.ndarray, tracks: list[tuple[list[int], np.ndarray]],
                     options: TriangulationOptions | None = None) -> list[TrackResult]:
    """Certified global optimum of every track: ``cameras`` (N, 3, 4) of the whole scene,
    ``tracks`` a list of ``(views, points)`` with ``views`` indices into ``cameras`` and
    ``points`` (len(views), 2). Returns one TrackResult per track, in order.

    Contract: each result is what ``triangulate(cameras[views], points, options)`` returns
    for that track in its status, certified flag and the form of its certificate (the same
    SearchCertificate; with ``options.certificate == "full"`` a proof that
    geocert.solvers.verify and the stacked verifier accept: a root proof and one leaf closed
    by a dual vector, each bound the safe bound of its own dual). What may differ: the point
    by the last bits of a converged local refinement (its cost equal to triangulate's within
    about 1e-9 relative, or lower), the lower bound and gap by a solve's accuracy (always
    proven, and within the tolerance when certified), ``nodes`` (1 where the root closed), and
    ``elapsed_s`` (the group's time shared by its tracks). Tracks the batched path does not
    close are solved by ``triangulate`` itself, so every status it can return is possible.
    With GEOCERT_SELF_VERIFY=1 every certified result is checked by the verifier, as
    ``triangulate`` checks its own.
    """
    options = options or TriangulationOptions()
    checking = self_check_enabled()
    run = dataclasses.replace(options, certificate="full") if checking else options
    cameras = normalised_cameras(cameras)
    results: list[TrackResult | None] = [None] * len(tracks)
    groups: dict[int, list[int]] = defaultdict(list)
    for i, (views, points) in enumerate(tracks):
        groups[len(views)].append(i)
    if run.max_residual is None:  # with a scope limit every track is solved alone (rare, not stacked)
        for n, members in groups.items():
            for start in range(0, len(members), MAX_GROUP):
                chunk = members[start:start + MAX_GROUP]
                started = time.perf_counter()
                solved = _solve_group(cameras, [tracks[i] for i in chunk], n, run)
                share = (time.perf_counter() - started) / len(chunk)
                for i, result in zip(chunk, solved):
                    if result is not None:
                        result.elapsed_s = share
                        results[i] = result
    for i, result in enumerate(results):
        views, points = tracks[i]
        if result is None:
            # triangulate self-checks its own results (and keeps the proof only when asked for).
            results[i] = triangulate(cameras[list(views)], points, options)
            continue
        if checking and result.certified:
            self_check("triangulation", (cameras[list(views)], np.asarray(points, dtype=float)),
                       dataclasses.asdict(run), claim_of(result, point=result.point, at_infinity=result.at_infinity))
        if options.certificate != "full" and result.certificate is not None:
            result.certificate.proof = None
    return results


def _solve_group(all_cameras: np.ndarray, tracks: list, n: int, options: TriangulationOptions) -> list:
    """Results of the tracks of one group (n views each) closed on this path; None for the rest."""
    G = len(tracks)
    out: list = [None] * G
    cams = all_cameras[np.array([list(views) for views, _ in tracks])]  # (G, n, 3, 4)
    points = np.array([np.asarray(p, dtype=float) for _, p in tracks])  # (G, n, 2)
    if n < 2 or points.shape != (G, n, 2) or not np.all(np.isfinite(points)):
        return out
    with np.errstate(all="ignore"):
        num, den, T, reference, ok = stacked._charts(cams, points)
        ok &= np.all(np.isfinite(num), axis=(1, 2, 3)) & np.all(np.isfinite(den), axis=(1, 2))
        v0, ok_start = _dlt(num)
        ok &= ok_start
        v0, ok_lm = _refine_l2l2(num, den, T[:, 3], v0, ok)
        ok &= ok_lm
    norm = options.norm
    prepared = []  # (index, chart, v0, scale, upper, gamma, B)
    for g in np.flatnonzero(ok):
        exact = np.zeros(n, dtype=bool)
        exact[reference[g]] = True
        program = FractionalProgram(num[g].copy(), den[g].copy(), exact, T[g, 3][None, :].copy(), norm)
        chart = Chart(program, T[g], int(reference[g]), False)
        start = v0[g]
        cost0 = program.cost(start)
        if not math.isfinite(cost0):
            continue
        if norm != "L2L2":
            start, cost0 = local_refine(program, start)
        if cost0 <= options.abs_gap:  # within tolerance of the trivial bound 0
            out[g] = _track_result(chart, cams[g], points[g], start, options, "optimal", 0.0, 0, None)
            continue
        factor = min(MAX_SCALE, 1.0 / math.sqrt(cost0) if norm == "L2L2" else 1.0 / cost0)
        program.rescale(factor)
        upper = program.cost(start)
        if not math.isfinite(upper):
            continue
        B = branch_directions(program, depth_subspace(program))
        prepared.append((g, chart, start, factor, upper, gamma_for(upper, norm), B))
    # Root regions, then root relaxations, by number of branched functionals.
    by_k: dict[int, list] = defaultdict(list)
    for entry in prepared:
        by_k[len(entry[6])].append(entry)
    for k, entries in by_k.items():
        roots = _root_regions(entries)
        closing = [(entry, root) for entry, root in zip(entries, roots) if root is not None]
        if closing:
            for g, result in _root_nodes(closing, cams, points, k, options):
                out[g] = result
    return out


# --- starts ---------------------------------------------------------------------------------

def _dlt(num: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chart.dlt for every track: (v, ok)."""
    G = len(num)
    rows = num.reshape(G, -1, 4)
    rows = rows / np.linalg.norm(rows, axis=2, keepdims=True)
    Y = np.linalg.svd(rows)[2][:, -1]
    ok = np.abs(Y[:, 3]) >= 1e-14 * np.linalg.norm(Y, axis=1)
    ok &= np.all(np.isfinite(Y), axis=1)
    return Y[:, :3] / np.where(ok, Y[:, 3], 1.0)[:, None], ok


def _l2l2_cost(num, den, linear, v):
    """The programs' L2L2 costs at ``v`` (inf outside the domain), and the residuals."""
    V = np.concatenate([v, np.ones((len(v), 1))], axis=1)
    g = np.einsum("gnk,gk->gn", den, V)
    r = np.einsum("gnmk,gk->gnm", num, V) / g[..., None]
    lin = np.einsum("gk,gk->g", linear, V)
    inside = np.all(g > 0, axis=1) & (lin >= -1e-12 * np.linalg.norm(linear, axis=1) * np.linalg.norm(V, axis=1))
    cost = np.where(inside, np.sum(r * r, axis=(1, 2)), np.inf)
    return np.where(np.isfinite(cost), cost, np.inf), r, g, V


def _refine_l2l2(num, den, linear, v, ok, iterations: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A batched Levenberg-Marquardt on every track's L2L2 residuals from ``v``, never moving a
    track to a worse or infeasible point; ok false where the start is not in the domain."""
    cost, r, g, V = _l2l2_cost(num, den, linear, v)
    ok = ok & np.isfinite(cost)
    lam = np.full(len(v), 1e-3)
    for _ in range(iterations):
        # J = d r / d v: (num[:, :, :, :3] - r * den[:, :, None, :3]) / g
        J = (num[..., :3] - r[..., None] * den[:, :, None, :3]) / g[..., None, None]
        J = J.reshape(len(v), -1, 3)
        JtJ = np.einsum("gra,grb->gab", J, J)
        Jtr = np.einsum("gra,gr->ga", J, r.reshape(len(v), -1))
        damped = JtJ + lam[:, None, None] * (np.eye(3) * (np.einsum("gaa->ga", JtJ)[:, None, :] + 1e-12))
        try:
            step = -np.linalg.solve(damped, Jtr[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        trial = v + step
        trial_cost, trial_r, trial_g, _ = _l2l2_cost(num, den, linear, trial)
        better = ok & np.isfinite(trial_cost) & (trial_cost < cost)
        v = np.where(better[:, None], trial, v)
        r = np.where(better[:, None, None], trial_r, r)
        g = np.where(better[:, None], trial_g, g)
        small = np.abs(cost - trial_cost) <= 1e-15 * cost
        cost = np.where(better, trial_cost, cost)
        lam = np.where(better, lam * 0.3, lam * 10.0)
        if np.all(~ok | (~better & (lam > 1e8)) | (better & small)):
            break
    return v, ok


# --- the root region ------------------------------------------------------------------------

def _root_regions(entries: list) -> list:
    """Each track's RootProof, proven as search.root_region and prove_root prove it (the same
    region, inflated by 1 + 1e-6, the same claimed box and padding), or None where not proven
    (the track is then solved alone). The 2d bounds of a track are found by the batched barrier
    method instead of 2d Clarabel solves; each is the safe bound of its own dual vector."""
    G = len(entries)
    n = len(entries[0][1].program.den)
    programs = [entry[1].program for entry in entries]
    F = np.array([complete_functionals(entry[6]) for entry in entries])  # (G, D, D)
    gamma = np.array([entry[5] for entry in entries]) * (1 + 1e-6)
    num = np.array([p.num for p in programs])
    den = np.array([p.den for p in programs])
    linear = np.array([p.linear for p in programs])  # (G, 1, 4)
    per_observation = np.concatenate([gamma[:, None, None, None] * den[:, :, None, :], num], axis=2)
    E = np.concatenate([linear, per_observation.reshape(G, 3 * n, 4)], axis=1)
    A, b = -E[..., :-1], E[..., -1]
    cones = ConeSpec(nonneg=1, soc=(3,) * n)
    Q = np.empty((G, 2 * D, D))
    Q[:, 0::2], Q[:, 1::2] = F, -F
    P = 2 * D
    x0 = np.repeat(np.array([entry[2] for entry in entries]), P, axis=0)
    with np.errstate(all="ignore"):
        x, z, solved = _barrier(Q.reshape(G * P, D), np.repeat(A, P, axis=0), np.repeat(b, P, axis=0), cones, x0)
        x, z, solved = x.reshape(G, P, D), z.reshape(G, P, -1), solved.reshape(G, P).all(axis=1)
        primal = np.einsum("gpd,gpd->gp", Q, x)
        dual = -np.einsum("gpr,gr->gp", z, b)
        values = np.minimum(primal, dual)
        lo, hi = values[:, 0::2], -values[:, 1::2]
        solved &= np.all(np.isfinite(values), axis=1) & np.all(lo <= hi, axis=1)
        pad = 0.5 * (hi - lo) + 1e-6 * (1 + np.abs(lo) + np.abs(hi))
        claim_lo, claim_hi = lo - pad, hi + pad
        transform = np.linalg.inv(F)
        proven = stacked._safe_bounds(Q, A, b, np.where(solved[:, None, None], z, 0.0), cones, claim_lo, claim_hi,
                                      transform)
        lower, upper = proven[:, 0::2], -proven[:, 1::2]
        solved &= np.all((claim_lo < lower) & (upper < claim_hi) & (lower <= upper), axis=1)
        pad = 1e-7 * (1 + np.abs(lower) + np.abs(upper))
    roots = []
    for g in range(G):
        if not solved[g]:
            roots.append(None)
            continue
        roots.append(RootProof(float(gamma[g]), F[g], claim_lo[g], claim_hi[g], lower[g] - pad[g], upper[g] + pad[g],
                               list(z[g])))
    return roots


def _barrier(q: np.ndarray, A: np.ndarray, b: np.ndarray, cones: ConeSpec, x: np.ndarray,
             t_end: float = 1e8, t_start: float = 1.0, factor: float = 30.0, final: float = 1e-6):
    """``min q'x`` subject to ``b - A x`` in ``cones`` (a nonnegative orthant and second-order
    cones) for P problems at once, ``q`` (P, n), ``A`` (P, rows, n), ``b`` (P, rows), by the
    log-barrier method from strictly feasible points ``x`` (P, n). Returns (x, z, ok): the
    last central point, its dual point ``z = -grad(barrier)(b - A x) / t`` (strictly inside the
    dual cone; its duality gap is about deg / t_end) and whether the problem's iterates stayed
    finite and strictly feasible. Nothing here needs to be exact: a bound is only ever the safe
    bound of the dual returned (cones.safe_lower_bound), which holds whatever z is."""
    P, rows, nv = A.shape
    nonneg = cones.nonneg
    runs = _runs(nonneg, cones.soc)  # (start, count, size): consecutive cones of one size
    At = A.transpose(0, 2, 1)

    def barrier(s):
        """Barrier value and strict feasibility per problem."""
        sn = s[:, :nonneg]
        feasible = np.all(sn > 0, axis=1)
        value = -np.sum(np.log(np.where(sn > 0, sn, 1.0)), axis=1)
        for start, count, size in runs:
            S = s[:, start:start + count * size].reshape(len(s), count, size)
            w = S[..., 0] ** 2 - np.sum(S[..., 1:] ** 2, axis=2)
            good = (S[..., 0] > 0) & (w > 0)
            feasible &= np.all(good, axis=1)
            value -= np.sum(np.log(np.where(good, w, 1.0)), axis=1)
        return value, feasible

    def derivatives(s, A, At):
        """grad phi (p, rows) and A' hess(phi) A (p, n, n) of the problems given: hess(phi) is
        diag(weight) plus, per cone, 4 (J S)(J S)' / w^2."""
        p = len(s)
        gphi = np.empty_like(s)
        weight = np.empty_like(s)
        sn = s[:, :nonneg]
        gphi[:, :nonneg] = -1.0 / sn
        weight[:, :nonneg] = 1.0 / (sn * sn)
        H = None
        for start, count, size in runs:
            block = slice(start, start + count * size)
            S = s[:, block].reshape(p, count, size)
            w = S[..., 0] ** 2 - np.sum(S[..., 1:] ** 2, axis=2)
            JS = S.copy()
            JS[..., 1:] *= -1.0
            gphi[:, block] = (-2.0 * JS / w[..., None]).reshape(p, -1)
            wt = np.empty_like(S)
            wt[..., 0] = -2.0 / w
            wt[..., 1:] = (2.0 / w)[..., None]
            weight[:, block] = wt.reshape(p, -1)
            u = (At[:, :, block].reshape(p, nv, count, size) * ((2.0 / w)[..., None] * JS)[:, None]).sum(axis=3)
            part = u @ u.transpose(0, 2, 1)
            H = part if H is None else H + part
        full = (At * weight[:, None, :]) @ A
        return gphi, full if H is None else H + full

    s = b - (A @ x[..., None])[..., 0]
    phi, ok = barrier(s)
    t = t_start
    while True:
        last = t >= t_end
        threshold = final if last else 1e-2  # Newton decrement^2 / 2 at which a centre is taken
        active = ok.copy()
        for _ in range(60):
            sel = np.flatnonzero(active)
            if not len(sel):
                break
            As, Ats, ss, xs = A[sel], At[sel], s[sel], x[sel]
            gphi, H = derivatives(ss, As, Ats)
            grad = t * q[sel] - (Ats @ gphi[..., None])[..., 0]
            try:
                dx = -np.linalg.solve(H, grad[..., None])[..., 0]
            except np.linalg.LinAlgError:
                return x, None, np.zeros(P, dtype=bool)
            slope = np.einsum("pn,pn->p", grad, dx)
            going = np.isfinite(slope) & (-slope > 2 * threshold)
            active[sel[~going]] = False
            if not going.any():
                break
            sel, As, ss, xs, dx, slope = sel[going], As[going], ss[going], xs[going], dx[going], slope[going]
            qs = q[sel]
            ds = -(As @ dx[..., None])[..., 0]
            f0 = t * np.einsum("pn,pn->p", qs, xs) + phi[sel]
            alpha = np.ones(len(sel))
            pending = np.ones(len(sel), dtype=bool)
            for _ in range(60):
                s_new = ss + alpha[:, None] * ds
                phi_new, feasible = barrier(s_new)
                f_new = t * np.einsum("pn,pn->p", qs, xs + alpha[:, None] * dx) + phi_new
                accept = pending & feasible & (f_new <= f0 + 0.25 * alpha * slope)
                took = sel[accept]
                x[took] = xs[accept] + alpha[accept, None] * dx[accept]
                s[took] = s_new[accept]
                phi[took] = phi_new[accept]
                pending &= ~accept
                if not pending.any():
                    break
                alpha = np.where(pending, 0.5 * alpha, alpha)
            stuck = sel[pending]
            ok[stuck] = False  # no step found: not trusted (its bound is still safe, but loose)
            active[stuck] = False
        if last:
            break
        t = min(t * factor, t_end)
    gphi, _ = derivatives(s, A, At)
    z = -gphi / t
    ok &= np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(x), axis=1)
    return x, z, ok


def _runs(start: int, soc: tuple[int, ...]) -> list[tuple[int, int, int]]:
    """The second-order cones as runs (start row, count, size) of consecutive cones of one size."""
    runs: list[list[int]] = []
    for size in soc:
        if runs and runs[-1][2] == size:
            runs[-1][1] += 1
        else:
            runs.append([start, 1, size])
        start += size
    return [tuple(run) for run in runs]


# --- the root node --------------------------------------------------------------------------

def _root_nodes(closing: list, cams, points, k: int, options: TriangulationOptions) -> list:
    """The one-node search of ``triangulate`` (bnb.branch_and_bound's root node, bounded as
    BoxProblem._bound bounds it) for tracks with a proven root region: (index, TrackResult) of
    those whose root closes the gap. The relaxations are assembled for all of them at once
    (stacked.leaf_relaxations: Relaxation.conic_data row for row) and each solved by Clarabel
    with BoxProblem's settings; each bound is the safe bound of its own dual vector."""
    norm = options.norm
    entries = [entry for entry, _ in closing]
    proofs = [root for _, root in closing]
    G = len(entries)
    num = np.array([entry[1].program.num for entry in entries])
    den = np.array([entry[1].program.den for entry in entries])
    linear = np.array([entry[1].program.linear for entry in entries])
    F = np.array([proof.functionals for proof in proofs])
    bounds = np.array([[proof.lower, proof.upper] for proof in proofs])  # (G, 2, D)
    box = bounds[:, :, :k].copy()
    ub = np.array([entry[4] for entry in entries])
    reference = np.array([entry[1].reference for entry in entries])
    with np.errstate(all="ignore"):
        E, cones, q, lower, upper, transform, built = stacked.leaf_relaxations(
            num, den, linear, F, k, bounds, box, ub, norm, reference)
    cols = E.shape[2] - 1
    A, b = -E[..., :cols], E[..., cols]
    solver = ReusableConicProgram(lean=True)  # BoxProblem's
    Z = np.zeros((G, 1, E.shape[1]))
    X = np.zeros((G, cols))
    solved = built.copy()
    for g in np.flatnonzero(built):
        result = solver.solve(q, A[g], b[g], cones)
        if result.status is not ConicStatus.OPTIMAL:
            solved[g] = False  # infeasible, or not clean: the track is solved alone
            continue
        Z[g, 0], X[g] = result.z, result.x
    with np.errstate(all="ignore"):
        safe = stacked._safe_bounds(np.broadcast_to(q, (G, 1, cols)), A, b, Z, cones, lower, upper, transform)[:, 0]
    done = []
    for g in np.flatnonzero(solved & np.isfinite(safe) & (safe >= 0)):
        index, chart, v0, factor, upper_bound, gamma, B = entries[g]
        program = chart.program
        unit = cost_unit(factor, norm)
        abs_gap = options.abs_gap * unit

        def tolerance(value: float) -> float:
            return max(abs_gap, options.rel_gap * abs(value))

        root = Box(box[g, 0].copy(), box[g, 1].copy())
        incumbent = v0
        candidate = _candidate(program, X[g, :D], v0)
        if candidate is not None:  # bnb's use of the relaxation's point
            value = program.cost(candidate)
            if value < upper_bound - tolerance(upper_bound):
                candidate, value = local_refine(program, candidate)
            if value < upper_bound:
                incumbent, upper_bound = candidate, value
        bound = float(safe[g])
        if not bound >= upper_bound - tolerance(upper_bound):
            continue  # not closed at the root: the track is solved alone
        leaf = LeafProof(root, float(ub[g]), "dual", Z[g, 0].copy(), bound)
        to_chart = np.linalg.inv(chart.T)
        certificate = SearchCertificate(SCOPE, chart.reference, (B @ to_chart[:3]).tolist(), to_chart[3].tolist(),
                                        root.lo.tolist(), root.hi.tolist(), tolerance(upper_bound) / unit, True, 1)
        if options.certificate == "full":
            certificate.proof = encode(SearchProof(factor, proofs[g], [], root, [(root, leaf)]))
        lower_bound = min(bound, upper_bound) / unit
        done.append((index, _track_result(chart, cams[index], points[index], incumbent, options, "optimal",
                                          lower_bound, 1, certificate)))
    return done


def _candidate(program: FractionalProgram, v: np.ndarray, interior: np.ndarray) -> np.ndarray | None:
    """BoxProblem._candidate: the relaxation's point, or one slightly towards the interior."""
    if math.isfinite(program.cost(v)):
        return v
    for step in (1e-9, 1e-6, 1e-3):
        w = v + step * (interior - v)
        if math.isfinite(program.cost(w)):
            return w
    return None
