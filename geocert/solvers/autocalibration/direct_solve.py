"""Direct autocalibration solved (thesis chapter 7): the moment relaxation of each orientation as
one SDP, first by interior_point (a structured interior-point method, numpy: 1.2 to 2 processor
seconds a solve on Table 7.1's scenes) and, when its solve is not clean, by Clarabel
(assembled directly, sparse: no cvxpy); its safe bound, the quadric from the first-order moments,
rounded to the feasible set and polished locally, the rank test, and where the relaxation is not
tight, a split of the program (MAX_SPLITS).

Why interior_point first: besides its speed (its docstring), Clarabel's clean ("Solved") answers with
the static regularisation below stopped measurably short of the relaxation's value. On seed 1006
(varying focal) Clarabel's bound was 2.270649e-4 with the moment matrix's second eigenvalue 1.9e-5
of the first, so reported not certified (gap 1.2e-4 relative, at all three attempts) as "order 2
not quite tight"; interior_point's is 2.2709252e-4 against the best quadric's 2.2709250e-4, ratio
3.4e-8: the relaxation is tight there, the gap was the solver's.

The rest of this docstring is the Clarabel path, as measured before interior_point. Where a solve's
time goes (order 2, Table 7.1's 12 views, profiled): assembling the program takes 0.02 s and Clarabel's setup 0.1 s; the rest is 12 to 22 interior-point iterations,
each dominated by the factorisation of the KKT system, in which the moment matrix's cone is a dense
1540-row block and the other cones (Q's 40 x 40 localizer, six 10 x 10 ones) fill in around it:
per iteration about the time of a dense Cholesky factorisation of order 2250 (0.44 s with numpy on
this machine's one core, against 0.27 to 0.5 s measured per iteration when idle). The supernodal
"faer" factorisation is about ten times faster than the default QDLDL on it (4.0 s against 44.5 s,
one solve); a second thread did not help on the shared machine. Clarabel's iterative refinement
(up to 10 steps per KKT solve by default) took a quarter of each iteration: one step is used
(REFINEMENT_STEPS). Measured without gain (seeds 1000 and 1006): equilibration off,
chordal decomposition off, presolve off (setup 0.2 s either way), a step fraction of 0.995;
tolerance 1e-7 saves one iteration but leaves the bound 1.3e-4 below the optimum (seed 1000), too
far for the 1e-4 certification; Q's localizer replaced by Q >= 0 and its diagonal's localizers
(0.24 s an iteration against 0.42) took 17 to 60 iterations and stalled "AlmostSolved" on 3 of 5
scenes. Dropping the six 2 x 2 minors'
localizers saves a third of each iteration but leaves the relaxation far from tight (gap 26%,
moment rank 46 on seed 1000): they stay.

Attempts (ATTEMPTS, in order, each Clarabel with more static regularisation than its default,
1e-6: the default stalls at iteration 11 on these programs): tolerance 1e-8 first, which with the
centred program (direct_relaxation's docstring) places the bound within about 1e-5 of the
optimum relative, then 1e-9, then 1e-8 with regularisation 1e-7. The next attempt runs when a solve
is not clean ("AlmostSolved" or worse), or when it is clean with a rank-one moment matrix but its
gap misses the tolerance (the solver's accuracy, not the relaxation, is then at fault). Only
"Solved" certifies (conic.py's status map); the bound is safe either way. Measured on Table 7.1's
scenes (centred program): most end at the first attempt (13 to 17 iterations, 5 to 7 processor
seconds under load); seed 1004 stalled "AlmostSolved" at both tolerances with regularisation 1e-6
(16 and 17 s) and ended "Solved" with 1e-7 (5 s); seed 1006 (varying focal) is rank one with the
second eigenvalue 1.9e-5 of the first and a gap of 1.1e-4 to 1.5e-4 relative at all three
attempts: the order-2 relaxation is not quite tight there, and it is reported not certified.
Regularisation 1e-7 first was no faster on four other scenes (13 to 17 iterations either way).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from geocert.formulations.autocalibration import direct
from geocert.core import interior_point
from geocert.formulations.autocalibration import direct_relaxation
from geocert.core.certificates import pack
from geocert.formulations.autocalibration.proofs import sublevel_level
from geocert.core.conic import ConicStatus, SolveSettings, solve_once


@dataclass
class DirectStage:
    status: str
    certified: bool
    Q: np.ndarray | None  # program frame, trace 1
    cost: float
    lower_bound: float
    order: int
    rank: int | None = None
    eigenvalue_ratio: float | None = None
    conic_status: list = field(default_factory=list)
    proof: dict | None = None
    reason: str | None = None
    elapsed_s: float = 0.0


class Stopped(Exception):
    """Raised by a solve's ``check`` to end the search: ``status`` "cancelled" or "time_limit"."""

    def __init__(self, status: str, reason: str):
        super().__init__(reason)
        self.status, self.reason = status, reason


# (tolerance, Clarabel's static regularisation; None: interior_point, the structured interior-point method)
ATTEMPTS = ((1e-9, None), (1e-8, 1e-6), (1e-9, 1e-6), (1e-8, 1e-7))
IPM_MAX_ITER = 50
# Iterative refinement steps per KKT solve (Clarabel's default: up to 10, to 1e-13 relative).
# Each step is a product with the KKT matrix, whose moment-matrix block is dense (1540 x 1540),
# and a solve with its factor: measured (seed 1000, fixed focal, 14 iterations either
# way, loaded machine, two runs each), 0.45-0.47 s of processor time per iteration with the
# default, 0.33-0.38 s with one step, 0.30-0.34 s with none; one step leaves the safe bound within
# 1e-10 relative of the default's, none moved it 5e-6 and doubled the iterations on seed 1006.
REFINEMENT_STEPS = 1


def _settings(tolerance: float, regularisation: float = 1e-6) -> SolveSettings:
    return SolveSettings(gap=tolerance, feasibility=tolerance, max_iter=60, regularisation=regularisation,
                         refinement_steps=REFINEMENT_STEPS, threads=1, faer=True)


def solve_program(program: direct_relaxation.Program, enough=None, attempts=None,
                  check=None) -> tuple[ConicStatus, np.ndarray | None, np.ndarray | None, str]:
    """(status, y, z, raw status) of the first clean solve among ATTEMPTS that ``enough(y, z)``
    accepts (default: any clean solve), else the clean one with the highest safe bound, else the
    last with a dual (still a safe bound); never raises on solver trouble. ``check()`` is called
    before each attempt and each interior-point iteration: it may raise Stopped."""
    answer = (ConicStatus.FAILED, None, None, "not solved")
    for tolerance, regularisation in ATTEMPTS if attempts is None else attempts:
        if check is not None:
            check()
        if regularisation is None:
            retry = _solve_ipm(program, tolerance, check)
        else:
            retry = _solve_once(program, tolerance, regularisation)
        clean = answer[0] is ConicStatus.OPTIMAL
        if retry[0] is ConicStatus.OPTIMAL:
            # of two clean solves the one with the higher safe bound (a later attempt is not
            # necessarily the more accurate: Clarabel's regularised solves stop further from the
            # optimum than interior_point's)
            if (not clean or direct_relaxation.safe_bound(program, retry[2])[0]
                    > direct_relaxation.safe_bound(program, answer[2])[0]):
                answer = retry
        elif (not clean and retry[2] is not None) or answer[2] is None:
            answer = retry
        if answer[0] is ConicStatus.OPTIMAL and (enough is None or enough(answer[1], answer[2])):
            break
    return answer


def _solve_ipm(program: direct_relaxation.Program, tolerance: float, check=None):
    """interior_point's solve as (status, y, z, raw status): OPTIMAL only when its residuals and gap
    met the tolerance (core.conic's map of its statuses)."""
    result = interior_point.solve(program.q, program.A, program.b, program.cones.zero, program.cones.nonneg,
                                  program.cones.psd, tolerance=tolerance, max_iter=IPM_MAX_ITER, check=check)
    raw = f"ipm {result.raw_status}"
    if result.status is ConicStatus.FAILED or result.y is None or result.z is None:
        return ConicStatus.FAILED, None, None, raw
    return result.status, result.y, result.z, raw


def _solve_once(program: direct_relaxation.Program, tolerance: float, regularisation: float):
    result = solve_once(program.q, program.A, program.b, program.cones, _settings(tolerance, regularisation))
    if result.x is None or not (np.all(np.isfinite(result.x)) and np.all(np.isfinite(result.z))):
        return ConicStatus.FAILED, None, None, result.raw_status
    return result.status, result.x, result.z, result.raw_status


def rank_test(program: direct_relaxation.Program, y: np.ndarray) -> tuple[int, float, np.ndarray]:
    """(numerical rank, second / first eigenvalue, eigenvalues) of the moment matrix."""
    values = np.linalg.eigvalsh(direct_relaxation.moment_matrix(program, y))[::-1]
    rank = int(np.sum(values > direct.RANK_TOLERANCE * values[0]))
    return rank, float(values[1] / values[0]), values


def polish(cameras: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Local minimisation of f over Q = B B' / trace (B 4x3) from a rank-3 PSD start."""
    from scipy.optimize import least_squares

    values, V = np.linalg.eigh(Q)
    B0 = V[:, 1:] * np.sqrt(np.maximum(values[1:], 1e-12))

    def residuals(b):
        B = b.reshape(4, 3)
        S = B @ B.T
        S = S / np.trace(S)
        w = np.einsum("iab,bc,idc->iad", cameras, S, cameras)
        return np.concatenate([w[:, 0, 0] - w[:, 1, 1], w[:, 0, 1], w[:, 0, 2], w[:, 1, 2]])

    result = least_squares(residuals, B0.ravel(), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    B = result.x.reshape(4, 3)
    S = B @ B.T
    return direct.rank_three_projection(S)


# A polish held to the focal rows keeps each this far inside its row (trace-1 units), well within
# direct.PSD_TOLERANCE of the domain check, so the returned Q (rounded to JSON) meets them there too.
FOCAL_MARGIN = 1e-10


def polish_within(cameras: np.ndarray, Q: np.ndarray, focal: np.ndarray) -> np.ndarray | None:
    """The polish with the focal rows (direct.focal_rows) as constraints: f over Q = B B' / trace
    subject to tr(S_k Q) >= FOCAL_MARGIN (SLSQP; 12 unknowns). Used when the free polish slides
    past a range's end, where the optimum of a relaxation that is not tight rounds to a Q just
    outside a row (Table 7.1's seed 1072, varying focal: a view whose focal length, 0.053, is near
    the range's 0.05). None when SLSQP ends without meeting every row."""
    from scipy.optimize import minimize

    values, V = np.linalg.eigh(Q)
    B0 = V[:, 1:] * np.sqrt(np.maximum(values[1:], 1e-12))

    def normalised(b):
        B = b.reshape(4, 3)
        S = B @ B.T
        return S / np.trace(S)

    def cost(b):
        S = normalised(b)
        w = np.einsum("iab,bc,idc->iad", cameras, S, cameras)
        return float(np.sum(np.concatenate([w[:, 0, 0] - w[:, 1, 1], w[:, 0, 1], w[:, 0, 2], w[:, 1, 2]]) ** 2))

    def rows(b):
        return np.einsum("kab,ab->k", focal, normalised(b)) - FOCAL_MARGIN

    found = minimize(cost, B0.ravel(), method="SLSQP", constraints=[{"type": "ineq", "fun": rows}],
                     options={"maxiter": 500, "ftol": 1e-16})
    S = direct.rank_three_projection(normalised(found.x))
    return S if np.all(np.einsum("kab,ab->k", focal, S / np.trace(S)) >= 0) else None


def extract(program: direct_relaxation.Program, y: np.ndarray, rank: int) -> list[np.ndarray]:
    """The ``rank`` points x whose moments the moment matrix M_d(y) would be a mixture of, if it
    were (Henrion and Lasserre's extraction, 2005): M = V V' with V's columns the top eigenvectors
    scaled by their roots; V in column echelon form on ``rank`` independent rows among the
    monomials of degree <= 1 (pivoted QR); the multiplication matrix of each variable x_k maps
    those rows' monomials to x_k times them (degree <= 2, in M's basis); a random combination's
    Schur vectors diagonalise them all at once, and x_k at point j is q_j' N_k q_j. Exact for a flat
    M of that rank; otherwise the points are only starts for the polish (every candidate is
    checked for feasibility and costed before use: nothing here touches the bound)."""
    import scipy.linalg as sl

    M = direct_relaxation.moment_matrix(program, y)
    values, vectors = np.linalg.eigh(M)
    values, vectors = values[::-1][:rank], vectors[:, ::-1][:, :rank]
    V = vectors * np.sqrt(np.maximum(values, 0.0))
    basis = direct_relaxation.monomials(program.moments.order)
    low = np.flatnonzero(basis.sum(axis=1) <= 1)
    _, _, pivots = sl.qr(V[low].T, pivoting=True)
    rows = low[pivots[:rank]]
    try:
        W = V @ np.linalg.inv(V[rows])
    except np.linalg.LinAlgError:
        return []
    position = {tuple(e): i for i, e in enumerate(basis)}
    N = []
    for k in range(direct_relaxation.N):
        shift = np.zeros(direct_relaxation.N, dtype=np.int64)
        shift[k] = 1
        N.append(W[[position[tuple(basis[r] + shift)] for r in rows]])
    weights = np.random.default_rng(0).random(direct_relaxation.N)
    _, Z = sl.schur(sum(w * Nk for w, Nk in zip(weights / weights.sum(), N)))
    points = np.array([[Z[:, j] @ Nk @ Z[:, j] for Nk in N] for j in range(rank)])
    return [x for x in points if np.all(np.isfinite(x))]


EXTRACTED_RANKS = 4  # mixtures of 2 .. this many points are tried when the moment matrix is not rank one


def allowed(setup: direct.DirectSetup, orientation: direct.Orientation, Q: np.ndarray) -> bool:
    """Chirality and the focal rows (the polish is unconstrained: it can slide towards f -> 0). The
    rows within direct.PSD_TOLERANCE of Q's trace, as the domain check (direct.in_domain) and the
    verifier hold them: a relaxation whose optimum has a focal length at a range's end rounds to a
    Q on that row, by round-off on either side of it (Table 7.1's seed 1072, varying focal). And
    rank 3 beyond round-off: a polish can slide to a rank-1 Q (eigenvalues 1, 0, 0, 0 to 1e-17,
    seed 1008 without the focal rows, on some BLAS kernels), which no metric upgrade comes from
    and on which chirality's products hold trivially."""
    values = np.linalg.eigvalsh(Q)
    if not values[1] > direct.PSD_TOLERANCE * np.abs(values).max():
        return False
    return direct.chirality_holds(orientation, Q) and direct.within_focal(setup, Q / np.trace(Q),
                                                                          direct.PSD_TOLERANCE)


def candidates(setup: direct.DirectSetup, y: np.ndarray, orientation: direct.Orientation,
               program: direct_relaxation.Program | None = None, rank: int = 1) -> list[np.ndarray]:
    """Feasible quadrics from a relaxation's moments: the first moments rounded, and rounded then
    polished (each kept only when chirality and the focal rows hold); when the moment matrix's rank is
    above one (and ``program`` is given), also the points extracted for mixtures of 2 to
    EXTRACTED_RANKS points, each rounded and polished the same way. A relaxation that is not tight
    can put its first moments (the mixture's mean) where every rounding breaks chirality (Table
    7.1's seed 1008, varying focal: the mean's polish puts cameras behind the scene) while one of
    the extracted points leads to a quadric that keeps it."""
    starts = [y[:direct_relaxation.N]]
    if program is not None and rank > 1:
        for r in range(2, EXTRACTED_RANKS + 1):
            starts += extract(program, y, r)
    out, seen = [], []
    for x in starts:
        rounded = direct.rank_three_projection(direct_relaxation.q_of(x))
        if any(np.linalg.norm(rounded - other) <= 1e-6 for other in seen):
            continue  # the same start again (extracted mixtures repeat their points): its polish is known
        seen.append(rounded)
        if allowed(setup, orientation, rounded):
            out.append(rounded)
        polished = polish(setup.cameras, rounded)
        if allowed(setup, orientation, polished):
            out.append(polished)
        elif setup.focal is not None and direct.chirality_holds(orientation, polished):
            held = polish_within(setup.cameras, rounded, setup.focal)
            if held is not None and allowed(setup, orientation, held):
                out.append(held)
    return out


def solve_direct(setup: direct.DirectSetup, options, record: bool, check=None) -> DirectStage:
    """``check()``, called between programs and between interior-point iterations, may raise
    Stopped: the stage then ends with that status, keeping the best quadric found and, once every
    orientation's program is solved, their bound."""
    start = time.perf_counter()
    if not setup.orientations:
        return DirectStage("failed", False, None, math.inf, -math.inf, options.relaxation_order,
                           reason=("no plane at infinity is consistent with chirality (both orientations excluded); the "
                                   "cameras' signs may not be oriented: orient the reconstruction with its points "
                                   "first (POST /v1/orient, docs/kinds.md, \"Camera signs\")"),
                           elapsed_s=time.perf_counter() - start)
    stage = _solve_order(setup, options, options.relaxation_order, record, check)
    stage.elapsed_s = time.perf_counter() - start
    return stage


@dataclass
class Leaf:
    """One program of the split: an orientation's relaxation restricted by cuts."""
    orientation: direct.Orientation
    cuts: tuple
    program: direct_relaxation.Program
    status: ConicStatus
    y: np.ndarray
    z: np.ndarray
    raw: str
    bound: float
    rank: tuple


# Splits of the lowest-bound program when the gap misses the tolerance (each solves two programs).
# Order 2 is not tight on some of Table 7.1's scenes (varying focal, seeds 1008, 1010 and 1012 of
# the first 13: the moment matrix a mixture of two points, the relaxation 3e-5 to 13% below the
# best quadric, which 300-start local searches confirm). Cutting between the two points the
# moment matrix mixes (x_k <= c and x_k >= c, each with its localizing matrix) made the half
# holding the optimum rank one and tight on seeds 1010 and 1012 (gaps 6e-8 and 3e-8 relative).
# Seed 1008 (varying focal) is not certified either way, for a reason splitting does not reach
# (measured): without chirality the global minimum of (7.12) (3.23e-4) puts cameras behind
# the scene (df 1.87), and the half holding it stalls at 3.13e-4; with chirality the best quadric
# (4.64e-4, rank one in its half) is separated from a lower half whose relaxation stays at 3.27e-4
# through three splits on entries 7, 8, 8 (rank one, ratio 3.5e-6), because its minimiser is a nearly
# degenerate quadric (eigenvalues 4.6e-6, 1.7e-4, 1.1e-3, 0.999 at trace 1) at which the chirality
# products R_k' adj(Q) R_l are at most 2.3e-8 in size (some negative at the first moments' quadric, while
# the moments satisfy them): the order-2 relaxation barely sees them there.
MAX_SPLITS = direct.MAX_CUTS  # the verifier refuses deeper paths


def _solve_leaf(setup, options, order, orientation, cuts, check=None) -> Leaf | None:
    program = direct_relaxation.build(setup.cameras, orientation.pairs, order, cuts, setup.focal)

    def enough(y, z):
        """A rank-one solve whose gap misses the tolerance is worth a more accurate attempt (the
        unsplit programs only: a half's own rounding may leave the half)."""
        if cuts or rank_test(program, y)[0] != 1:
            return True
        found = [direct_relaxation.cost(setup.cameras, Q) for Q in candidates(setup, y, orientation)]
        if not found:
            return True
        best = min(found)
        return (best - direct_relaxation.safe_bound(program, z)[0]
                <= max(options.abs_gap, options.metric_rel_gap * abs(best)))

    # a half is solved by interior_point only: where it stalled (seeds 1008, 1012 and 1042, varying focal),
    # Clarabel's attempts took 6 to 20 s each and ended "AlmostSolved" too (the result is then not certified)
    status, y, z, raw = solve_program(program, enough, ATTEMPTS[:1] if cuts else ATTEMPTS, check)
    if z is None:
        return Leaf(orientation, cuts, program, status, y, z, raw, -math.inf, (0, math.nan, None))
    return Leaf(orientation, cuts, program, status, y, z, raw, direct_relaxation.safe_bound(program, z)[0],
                rank_test(program, y))


def split_of(leaf: Leaf) -> tuple[int, float] | None:
    """(k, c) to cut a program at: between the two points its moment matrix mixes (the entry
    where they differ most, halfway), or, without two such points, at the mean of the entry of
    largest variance."""
    if leaf.rank[0] >= 2:
        points = extract(leaf.program, leaf.y, 2)
        if len(points) == 2:
            k = int(np.argmax(np.abs(points[0] - points[1])))
            if abs(points[0][k] - points[1][k]) > 1e-6:
                return k, float((points[0][k] + points[1][k]) / 2)
    M = direct_relaxation.moment_matrix(leaf.program, leaf.y)
    mean = M[0, 1:1 + direct_relaxation.N]
    variance = np.diag(M)[1:1 + direct_relaxation.N] - mean ** 2
    k = int(np.argmax(variance))
    if not variance[k] > 1e-12:
        return None
    return k, float(mean[k])


def _solve_order(setup: direct.DirectSetup, options, order: int, record: bool, check=None) -> DirectStage:
    best, best_cost = None, math.inf
    statuses, leaves = [], []
    stopped: Stopped | None = None

    def consider(leaf):
        nonlocal best, best_cost
        statuses.append(leaf.raw)
        for Q in candidates(setup, leaf.y, leaf.orientation, leaf.program, leaf.rank[0]):
            c = direct_relaxation.cost(setup.cameras, Q)
            if c < best_cost:
                best, best_cost = Q, c

    try:
        for orientation in setup.orientations:
            leaf = _solve_leaf(setup, options, order, orientation, (), check)
            if leaf.z is None:
                return DirectStage("failed", False, None, math.inf, -math.inf, order,
                                   conic_status=statuses + [leaf.raw], reason=f"the conic solver failed ({leaf.raw})")
            leaves.append(leaf)
            consider(leaf)
    except Stopped as stop:  # not every orientation bounded: no bound, the best quadric so far
        return DirectStage(stop.status, False, best, best_cost, -math.inf, order, conic_status=statuses,
                           reason=stop.reason)

    def settled(leaf):
        """A leaf whose solve was clean, or whose safe bound (safe from any dual vector: the
        verifier recomputes it) lies above the best quadric's cost: that program holds no quadric
        as good, whatever its solve's status. Seed 1008 (varying focal, the focal rows): the
        lower half's halves bound 5.9e-3 (clean) and 1.4e-3 against the best quadric's 4.64e-4,
        the latter's solve "Stalled" or "Solved" by the BLAS's rounding (one OpenBLAS thread or
        two): the splitting, tight at its other half (rank one), certified on one only."""
        return leaf.status is ConicStatus.OPTIMAL or leaf.bound > best_cost

    def standing(leaves):
        return all(settled(leaf) for leaf in leaves), min(leaf.bound for leaf in leaves)

    kept = list(leaves)
    for _ in range(MAX_SPLITS):
        lowest = min(leaves, key=lambda leaf: leaf.bound)
        tight = best is not None and best_cost - lowest.bound <= max(options.abs_gap, options.metric_rel_gap * abs(best_cost))
        exact = best is not None and best_cost - lowest.bound <= options.abs_gap
        if best is None or (tight and (lowest.rank[0] == 1 or exact)) or any(
                leaf.status is not ConicStatus.OPTIMAL for leaf in leaves):
            # (a gap within the tolerance with a moment matrix of rank above one is split too, for the rank,
            # unless the gap is within abs_gap: a noise-free scene, cost ~0 and the bound 0, whose halves'
            # solves stalled (the user's scene without noise: 30 s more, nothing to gain); a half whose solve
            # was not clean stops the splitting: split again, such halves stalled again, 24 s)
            break
        cut = split_of(lowest)
        if cut is None:
            break
        try:
            halves = [_solve_leaf(setup, options, order, lowest.orientation, lowest.cuts + ((cut[0], cut[1], sign),),
                                  check) for sign in (1, -1)]
        except Stopped as stop:  # the splitting so far stands (its leaves cover every orientation)
            stopped = stop
            break
        if any(half.z is None for half in halves):
            statuses += [half.raw for half in halves]
            break
        leaves = [leaf for leaf in leaves if leaf is not lowest] + halves
        for half in halves:
            consider(half)
        if standing(leaves) > standing(kept):
            kept = list(leaves)
    # every splitting's smallest bound is a bound; the proof is the splitting with the best (clean
    # first): a half whose solve stalled can charge its dual residual far below its parent's bound
    # (seed 1008, varying focal: 7.5e-1 relative below the best quadric against 1.3e-1 unsplit)
    leaves = kept
    lowest = min(leaves, key=lambda leaf: leaf.bound)
    bound = lowest.bound
    clean = all(settled(leaf) for leaf in leaves)
    rank, ratio = lowest.rank[0], lowest.rank[1]  # of the program the bound is from
    programs = [{"delta": leaf.orientation.delta, "z": pack(leaf.z), "bound": leaf.bound,
                 **({"cuts": [[int(k), float(c), int(sign)] for k, c, sign in leaf.cuts]} if leaf.cuts else {})}
                for leaf in leaves]
    proof = {"type": "direct_moment", "order": order, "programs": programs, "excluded": setup.excluded,
             "moment_rank": rank, "eigenvalue_ratio": ratio} if record else None
    if best is None:
        return DirectStage("not_certified" if stopped is None else stopped.status, False, None, math.inf, bound, order,
                           rank, ratio, statuses, None, "no feasible quadric rounded from the relaxation satisfies "
                           "chirality and the focal ranges" + ("" if stopped is None else f" ({stopped.reason})"))
    tolerance = max(options.abs_gap, options.metric_rel_gap * abs(best_cost))
    certified = clean and best_cost - bound <= tolerance
    reason = None
    split = f" split into {len(leaves)} programs" if len(leaves) > len(setup.orientations) else ""
    if not clean:
        reason = f"the conic solve was not clean ({', '.join(statuses)}): its bound is reported, not certified"
    elif not certified and rank == 1:
        # the moment matrix's rank says the relaxation is tight; what failed is the gap's tolerance
        reason = (f"the gap {best_cost - bound:.3g} misses the tolerance {tolerance:.3g} (max of abs_gap and "
                  f"metric_rel_gap times the cost) though the moment matrix is rank one at order {order}{split} "
                  f"(eigenvalue ratio {ratio:.3g}): the conic solve's accuracy, not the relaxation, limits the "
                  "bound; the bound and the rounded solution are returned")
    elif not certified:
        reason = (f"the relaxation is not tight at order {order}{split}: moment matrix rank {rank}, gap "
                  f"{best_cost - bound:.3g} against the tolerance {tolerance:.3g}; the bound and the rounded "
                  "solution are returned")
    status = "optimal" if certified else "not_certified"
    if stopped is not None and not certified:
        status, reason = stopped.status, f"{stopped.reason}; {reason}" if reason else stopped.reason
    return DirectStage(status, certified, best, best_cost, bound, order, rank, ratio, statuses, proof, reason)


# --- the proven interval of the focal length (direct_sublevel) ---------------------------------

DINKELBACH_STEPS = 6  # c <- r at the relaxation's minimiser, until it moves less than DINKELBACH_TOLERANCE
DINKELBACH_TOLERANCE = 1e-6
CLARABEL_STEPS = 1  # Dinkelbach's steps by Clarabel where the interior point's solves were not clean
# Clarabel at tolerance 1e-6 (the safe bound does not need an accurate dual, only one whose charges are
# small; measured on seed 3's lower end at c = 0.94: "Solved" in 8.4 s, safe bound 0.143, the same as at 1e-7
# in 10.1 s, where interior_point stalled with a safe bound of -0.070)
CLARABEL_ATTEMPT = ((1e-6, 1e-6),)
INTERVAL_PAD = 1e-9  # the interval stated, this much (relative) wider than the one its duals prove here


def prove_focal(setup: direct.DirectSetup, Q: np.ndarray, cost: float, increase: float, check=None) -> dict | None:
    """The direct proof's ``sublevel`` (direct_sublevel): for each end and each orientation of the
    setup, c by Dinkelbach's iteration from the returned Q's r (each step one solve of the interval
    program at c, c then r at its first moments), then solves at that c moved outward by 1e-6,
    1e-4 and 1e-2 relative; of every solve's dual whose safe bound is above 0, the one proving the
    tightest end (direct_sublevel.end) is kept. An end no dual proves is null: the scope's own
    (measured: the lower end's programs stall the interior point on some scenes, where Clarabel took
    23 s a solve, "AlmostSolved"). None when neither end is proven, or ``check()`` raises Stopped."""
    if not (math.isfinite(cost) and math.isfinite(increase) and increase >= 0 and cost >= 0):
        return None
    level = sublevel_level(cost, increase)
    sides = _prove_ends(setup, Q, level, check, None)
    if sides["lower"] is None and sides["upper"] is None:
        return None
    sublevel = {"cost_increase": float(increase), **sides, "interval": [0.0, 0.0]}
    lo, hi = _proven_here(setup, sublevel, level)
    sublevel["interval"] = [lo * (1 - INTERVAL_PAD), hi * (1 + INTERVAL_PAD)]
    return sublevel


def prove_focal_lengths(setup: direct.DirectSetup, Q: np.ndarray, cost: float, increase: float,
                        check=None) -> dict | None:
    """The varying-focal direct proof's ``sublevel`` (direct_sublevel.check_views): each view's
    ends as prove_focal's, with that view's forms over the same programs; a view neither of whose
    ends is proven states the scope's range. None when no end of any view is proven, or ``check()``
    raises Stopped."""
    from geocert.formulations.autocalibration import direct_sublevel

    if not (math.isfinite(cost) and math.isfinite(increase) and increase >= 0 and cost >= 0):
        return None
    level = sublevel_level(cost, increase)
    f0, scope = float(setup.problem.K0[0, 0]), direct_sublevel.scope_range(setup.problem.unit_ranges)
    views = []
    for view in range(len(setup.cameras)):
        sides = _prove_ends(setup, Q, level, check, view)
        lo, hi = direct_sublevel.pixels(f0, *_ends_here(setup, sides, level, view), scope)
        views.append({**sides, "interval": [lo * (1 - INTERVAL_PAD), hi * (1 + INTERVAL_PAD)]})
    if all(v["lower"] is None and v["upper"] is None for v in views):
        return None
    return {"cost_increase": float(increase), "views": views}


def _prove_ends(setup: direct.DirectSetup, Q: np.ndarray, level: float, check, view: int | None,
                ratio=None) -> dict:
    """{"lower": entries or None, "upper": ...}: prove_focal's search, of the views' mean r (view
    None) or of view ``view``'s, or of ``ratio`` (a direct_intrinsics.Ratio) when given."""
    from geocert.formulations.autocalibration import direct_intrinsics, direct_sublevel

    if ratio is None:
        def value(Q):
            return direct_sublevel.ratio(setup.cameras, Q, view)

        def build(pairs, c, sign):
            return direct_sublevel.side_program(setup.cameras, pairs, setup.focal, c, sign, level, view)

        def proves(c, sign, safe):
            return direct_sublevel.end(setup.cameras, c, sign, safe, view)
    else:
        def value(Q):
            return ratio.at(Q)

        def build(pairs, c, sign):
            return direct_intrinsics.side_program(setup.cameras, pairs, setup.focal, ratio, c, sign, level)

        proves = ratio.end

    start = value(Q / np.trace(Q))
    sides = {}
    for side, sign in (("lower", 1.0), ("upper", -1.0)):
        entries = []
        for orientation in setup.orientations:
            best, best_end = None, None

            clean = True

            def solved(c, attempts=ATTEMPTS[:1]):
                nonlocal best, best_end, clean
                program = build(orientation.pairs, c, sign)
                status, y, z, raw = solve_program(program, None, attempts, check)
                clean = clean and status is ConicStatus.OPTIMAL
                if z is not None:
                    safe, _ = direct_relaxation.safe_bound(program, z, -math.inf)
                    proven = proves(c, sign, safe)
                    if proven is not None and (best_end is None or sign * (proven - best_end) > 0):
                        best, best_end = {"delta": orientation.delta, "c": float(c), "z": pack(z)}, proven
                return y

            def dinkelbach(steps, attempts, c):
                for _ in range(steps):
                    y = solved(c, attempts)
                    if y is None:
                        break
                    moved = value(direct_relaxation.q_of(y[:direct_relaxation.N]))
                    if not math.isfinite(moved):
                        break
                    # never past the returned Q's own r: it is in the set
                    moved = min(moved, start) if sign > 0 else max(moved, start)
                    done = abs(moved - c) <= DINKELBACH_TOLERANCE * abs(c)
                    c = moved
                    if done:
                        break
                for slack in (1e-6, 1e-4, 1e-2):
                    trial = c - sign * slack * abs(c)
                    if best_end is not None and sign * (best_end - trial) >= 0:
                        break  # a dual at c proves about c: not beyond what is proven (measured: Clarabel's
                        # certifications redone where the interior point had proven as much, 45 s for nothing)
                    solved(trial, attempts)
                    if best_end is not None and sign * (best_end - trial) >= 0:
                        break  # nothing further out can prove a tighter end

            dinkelbach(DINKELBACH_STEPS, ATTEMPTS[:1], start)
            if not clean:
                # the interior point stalled (the lower end's programs, on some scenes): Clarabel, slower and clean;
                # stopped by the job's clock, what is proven so far stands. (Measured, Table 7.1's varying seed 7,
                # 8 views: from the c the interior point's iterates reached, or Clarabel only where they proved
                # nothing, the lower ends of 3 views came out 3 to 7 times as wide, for 0.55x and 0.4x the CPU.)
                try:
                    dinkelbach(CLARABEL_STEPS, CLARABEL_ATTEMPT, start)
                except Stopped:
                    pass
            if best is None:
                entries = None  # this end is the scope's
                break
            entries.append(best)
        sides[side] = entries
    return sides


def _proven_here(setup, sublevel: dict, level: float) -> tuple[float, float]:
    """The interval the entries prove, as the verifier computes it (direct_sublevel.check)."""
    from geocert.formulations.autocalibration import direct_sublevel

    return direct_sublevel.pixels(float(setup.problem.K0[0, 0]), *_ends_here(setup, sublevel, level, None),
                                  direct_sublevel.scope_range(setup.problem.unit_ranges))


def _ends_here(setup, sides: dict, level: float, view: int | None) -> tuple[float, float]:
    """r's (lower, upper) ends the entries prove (view ``view``'s, or the mean's), as the verifier
    computes them (direct_sublevel._ends); an end with no entries is infinite."""
    from geocert.formulations.autocalibration import direct_sublevel
    from geocert.core.certificates import unpack

    ends = {"lower": -math.inf, "upper": math.inf}
    for side, sign in (("lower", 1.0), ("upper", -1.0)):
        if sides[side] is None:
            continue
        found = []
        for entry, orientation in zip(sides[side], setup.orientations):
            program = direct_sublevel.side_program(setup.cameras, orientation.pairs, setup.focal, entry["c"], sign,
                                                   level, view)
            safe, _ = direct_relaxation.safe_bound(program, unpack(entry["z"]), -math.inf)
            found.append(direct_sublevel.end(setup.cameras, entry["c"], sign, safe, view))
        ends[side] = min(found) if sign > 0 else max(found)
    return ends["lower"], ends["upper"]


def prove_intrinsics(setup: direct.DirectSetup, Q: np.ndarray, cost: float, increase: float, check=None) -> dict:
    """The direct proof's sublevel["intrinsics"] (direct_intrinsics): each ratio's ends by
    prove_focal's search, and the intervals they prove as the verifier reads them, padded outward
    by INTERVAL_PAD (of the value and f0). A ratio whose search ``check()`` stops, and every one
    after it, is left unproven (null ends): what was proven stands."""
    from geocert.formulations.autocalibration import direct_intrinsics

    level = sublevel_level(cost, increase)
    forms = direct_intrinsics.ratios(setup.cameras)
    out, stopped = {}, False
    for name in direct_intrinsics.RATIOS:
        sides = {"lower": None, "upper": None}
        if not stopped:
            try:
                sides = _prove_ends(setup, Q, level, check, None, forms[name])
            except Stopped:
                stopped = True
        out[name] = sides
    f0 = float(setup.problem.K0[0, 0])
    # as the verifier reads them (direct_intrinsics.check)
    proven = direct_intrinsics.proven_ends(setup, out, "intrinsics", setup.orientations, level)

    def pad(x, sign, scale):
        return None if x is None else x + sign * INTERVAL_PAD * (abs(x) + scale)

    out["intervals"] = [[pad(proven[n][0], -1.0, 1.0 if n == "aspect" else f0),
                         pad(proven[n][1], 1.0, 1.0 if n == "aspect" else f0)] for n in direct_intrinsics.NAMES]
    return out
