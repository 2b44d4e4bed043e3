"""Levenberg-Marquardt for bundle adjustment with the Schur complement (Triggs et al. 2000,
"Bundle adjustment: a modern synthesis", section 6.1): the points' blocks are eliminated one
by one, leaving a dense system in the camera parameters only (12 per view: a few hundred
unknowns for the Dinosaur's 36 views), so a step costs a few array operations over the
observations. scipy.optimize.least_squares with ``jac_sparsity`` solves the same problem, but
its LSMR inner solver meets the projective gauge's rank deficiency with hundreds of inner
iterations (10 minutes for the Dinosaur on this machine, against seconds here).

The problem: observation m depends on one camera's parameters ``A[view[m]]`` (c each), the
parameters every view shares ``S`` (s) and one point's ``B[track[m]]`` (d); ``residual(A_m,
S, B_m)`` is vectorised over observations and returns (M, 2). Jacobians are central
differences, vectorised the same way (one perturbed copy per parameter coordinate).

When to stop is ``StopRule``'s, Ceres Solver's three tests (Solver::Options function_tolerance,
gradient_tolerance, parameter_tolerance) with Ceres's defaults; the iteration cap comes on top."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StopRule:
    """When ``solve`` ends before its iteration cap, Ceres Solver's way (Solver::Options; the
    defaults are Ceres's):

    - ``function_tolerance``: a step taken lowered the cost by at most this fraction of the cost
      before it (Ceres: |cost change| / cost <= function_tolerance);
    - ``gradient_tolerance``: the largest entry of the (robustly weighted) gradient J^T r is at
      most this, checked before each step (Ceres: max_norm(gradient) <= gradient_tolerance);
    - ``parameter_tolerance``: a step's length is at most (|x| + parameter_tolerance) *
      parameter_tolerance, x every camera, shared and point parameter (Ceres's definition); the
      step is taken when it lowers the cost, then the solve ends.

    0 turns a test off. Near the minimum, Levenberg-Marquardt's steps shrink geometrically, so the
    cost still to be gained is of the order of the last step's gain: with ``function_tolerance``
    1e-6 and M residuals of about sigma pixels each, about 1e-6 M sigma^2, against the cost's own
    chi-square spread of sqrt(2 M) sigma^2 (M = 10^4: 0.01 against 141)."""

    function_tolerance: float = 1e-6
    gradient_tolerance: float = 1e-10
    parameter_tolerance: float = 1e-8


# Ceres Solver's defaults: what ``solve`` uses unless told otherwise.
CERES = StopRule()


def _central_columns(evaluate, values: np.ndarray, step: float) -> np.ndarray:
    """d evaluate / d values by central differences, one coordinate at a time: ``values`` is
    (M, k) (a row per observation) or (k,) (shared), ``evaluate`` maps it to (M, 2); (M, 2, k)."""
    columns = []
    for k in range(values.shape[-1]):
        h = step * np.maximum(1.0, np.abs(values[..., k]))
        plus, minus = values.copy(), values.copy()
        plus[..., k] += h
        minus[..., k] -= h
        columns.append((evaluate(plus) - evaluate(minus)) / (2 * np.reshape(h, (-1, 1))))
    return np.stack(columns, axis=-1) if columns else np.zeros(evaluate(values).shape + (0,))


def _jacobians(residual, A, S, B, view, track, step=1e-6):
    Am, Bm = _rows(A, view), _rows(B, track)
    ja = _central_columns(lambda a: residual(a, S, Bm), Am, step)
    js = _central_columns(lambda shared: residual(Am, shared, Bm), S, step)
    jb = _central_columns(lambda b: residual(Am, S, b), Bm, step)
    return ja, js, jb


def _rows(values: np.ndarray, index: np.ndarray) -> np.ndarray:
    """values[index] for an integer index along the first axis: np.take's copy of the same rows,
    several times faster than numpy's fancy indexing on the stacks here (a (p, 3, 3) stack
    gathered to 9,000 observations: 0.03 against 0.14 ms)."""
    return np.take(values, index, axis=0)


def _sum_by(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Rows of ``values`` (M, ...) summed by ``index`` (M,) into n rows: np.add.at's sum, by one
    bincount (several times faster than ufunc.at on the observations)."""
    return _SumBy(index, n)(values)


class _SumBy:
    """``_sum_by`` over one index, its bincount positions made once per row width: ``solve`` sums
    by the tracks three times an iteration, and building the positions cost as much as the sum."""

    def __init__(self, index: np.ndarray, n: int):
        self.index, self.n, self.at = index, n, {}

    def __call__(self, values: np.ndarray) -> np.ndarray:
        flat = values.reshape(len(self.index), -1)
        k = flat.shape[1]
        at = self.at.get(k)
        if at is None:
            at = self.at[k] = (self.index[:, None] * k + np.arange(k)[None, :]).ravel()
        return np.bincount(at, weights=flat.ravel(), minlength=self.n * k).reshape((self.n,) + values.shape[1:])


def _inverse(V: np.ndarray) -> np.ndarray:
    """Inverses of a stack of square matrices (k, d, d); for d = 3 by cofactors (the adjugate over
    the determinant, written out entry by entry), several times faster than np.linalg.inv on small
    blocks. A singular block gives non-finite entries (the step is then refused and the damping
    raised)."""
    if V.shape[-1] != 3:
        return np.linalg.inv(V)
    a, b, c = V[:, 0, 0], V[:, 0, 1], V[:, 0, 2]
    d, e, f = V[:, 1, 0], V[:, 1, 1], V[:, 1, 2]
    g, h, i = V[:, 2, 0], V[:, 2, 1], V[:, 2, 2]
    adjugate = np.empty_like(V)
    adjugate[:, 0, 0], adjugate[:, 0, 1], adjugate[:, 0, 2] = e * i - f * h, c * h - b * i, b * f - c * e
    adjugate[:, 1, 0], adjugate[:, 1, 1], adjugate[:, 1, 2] = f * g - d * i, a * i - c * g, c * d - a * f
    adjugate[:, 2, 0], adjugate[:, 2, 1], adjugate[:, 2, 2] = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * adjugate[:, 0, 0] + b * adjugate[:, 1, 0] + c * adjugate[:, 2, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        return adjugate / det[:, None, None]


def _damped(V: np.ndarray, lam: float, finite: bool) -> np.ndarray:
    """V + lam (diag(V) I + 1e-12 I) for a stack V (p, d, d), the points' damped blocks. Off the
    diagonal that adds lam (0 + 0) = 0, which leaves an entry as it is unless it is -0.0 (V's
    entries are bincount's sums, which never are) or its block's diagonal is not finite (inf 0 =
    nan): when ``finite`` (every entry of V finite) only the diagonal is computed, the same
    floats as the whole expression's, in a copy of V."""
    if not finite:
        d = V.shape[-1]
        return V + lam * (np.einsum("pii->pi", V)[:, :, None] * np.eye(d) + 1e-12 * np.eye(d))
    p, d = V.shape[0], V.shape[-1]
    damped = V.copy()
    damped.reshape(p, d * d)[:, ::d + 1] += lam * (V.reshape(p, d * d)[:, ::d + 1] + 1e-12)
    return damped


def _robust_weights(r: np.ndarray, f_scale: float | None) -> np.ndarray:
    """Per observation, the iteratively reweighted least squares weight of a Huber loss on the
    residual's length (None: plain least squares)."""
    if f_scale is None:
        return np.ones(len(r))
    length = np.linalg.norm(r, axis=1)
    return np.where(length <= f_scale, 1.0, f_scale / np.maximum(length, 1e-300))


def _cost(r, f_scale):
    if f_scale is None:
        return float(np.sum(r * r))
    length = np.linalg.norm(r, axis=1)
    return float(np.sum(np.where(length <= f_scale, length ** 2, 2 * f_scale * length - f_scale ** 2)))


class _Blocks:
    """The reduced system's sums over observations, block by block: observation m's parameters
    are its view's c and the s shared ones (schur.solve's cam_cols), so a product X_m^T Y_m of two
    per-observation blocks (r x (c + s)) lands in the block of its view with itself, and a product
    between two observations of one point in the block of their two views. Each block's terms
    are summed by one matrix product over the observations (or pairs) sorted by block, then the
    few blocks placed in the nc x nc matrix: rather than a product per observation and pair and a
    scatter of each (the observations outnumber the blocks a thousandfold)."""

    def __init__(self, view: np.ndarray, track: np.ndarray, n: int, c: int, s: int, p: int):
        self.k = c + s
        nc = n * c + s
        # Pairs of different observations of the same point, each pair once (first before second
        # in the point's observations): their blocks, summed, give C and C^T (V^-1 is symmetric).
        order = np.argsort(track, kind="stable")
        counts = np.bincount(track, minlength=p)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        first, second = [], []
        top = counts.max() + 1 if len(counts) else 1
        for k in range(1, top):
            for l in range(k + 1, top):
                pts = np.flatnonzero(counts >= l)
                first.append(order[starts[pts] + k - 1])
                second.append(order[starts[pts] + l - 1])
        first = np.concatenate(first) if first else np.zeros(0, dtype=int)
        second = np.concatenate(second) if second else np.zeros(0, dtype=int)

        def columns(v):  # the reduced system's columns of view v's block: its c, then the s shared
            return np.concatenate([c * v + np.arange(c), n * c + np.arange(s)])

        def grouped(key, rows_of, cols_of):
            """Sorted by key, each run of one key's [start, end) and its block's flat indices."""
            order = np.argsort(key, kind="stable")
            keys, begin = np.unique(key[order], return_index=True)
            end = np.append(begin[1:], len(order))
            at = np.array([(columns(rows_of(q))[:, None] * nc + columns(cols_of(q))[None, :]).ravel()
                           for q in keys], dtype=int).reshape(len(keys), (c + s) ** 2)
            return order, list(zip(begin.tolist(), end.tolist())), at

        self.own_order, self.own_runs, self.own_at = grouped(view, lambda q: q, lambda q: q)
        key = view[first] * n + view[second]
        order, self.pair_runs, self.pair_at = grouped(key, lambda q: q // n, lambda q: q % n)
        self.first, self.second = first[order], second[order]
        self.size = nc

    def _summed(self, X, Y, runs, at) -> np.ndarray:
        # Each run's product is X[a:b].reshape(-1, k).T @ Y[a:b].reshape(-1, k) (the same operands'
        # memory, so the same BLAS call and sums), from views made once and written into its block:
        # the loop runs for every view and view pair at every damping tried.
        k = self.k
        r = X.shape[1]
        rows_x, rows_y = X.reshape(-1, k), Y.reshape(-1, k)
        columns_x = rows_x.T
        out = np.empty((len(runs), k, k))
        for i, (a, b) in enumerate(runs):
            np.matmul(columns_x[:, a * r:b * r], rows_y[a * r:b * r], out=out[i])
        return np.bincount(at.ravel(), weights=out.ravel(), minlength=self.size ** 2).reshape(self.size, self.size)

    def own(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """sum_m X_m^T Y_m (X, Y: (M, r, c + s)) in the reduced system's nc x nc matrix."""
        Xs = _rows(X, self.own_order)
        return self._summed(Xs, Xs if Y is X else _rows(Y, self.own_order), self.own_runs, self.own_at)

    def gathered(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Y (M, r, c + s) in the order ``reduction`` reads it (once per Jacobian, not per damping)."""
        return _rows(Y, self.own_order), _rows(Y, self.second)

    def reduction(self, X: np.ndarray, Y: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """sum over the observations m, m' of each point of X_m^T Y_m' in the nc x nc matrix, for
        X_m = V_j^-1 W_m^T and Y_m = W_m^T (``gathered``): W V^-1 W^T, what eliminating the points
        takes off U."""
        own = self._summed(_rows(X, self.own_order), Y[0], self.own_runs, self.own_at)
        if len(self.first) == 0:
            return own
        cross = self._summed(_rows(X, self.first), Y[1], self.pair_runs, self.pair_at)
        return own + cross + cross.T


def solve(residual, A, S, B, view, track, f_scale: float | None = None, max_iterations: int = 50,
          stop: StopRule = CERES, jacobian=None, should_stop=None):
    """Minimise sum_m rho(|residual_m|^2) over A (n, c), S (s,), B (p, d); returns A, S, B,
    the residuals (M, 2) and the number of iterations (steps computed, each taken or not, at
    most ``max_iterations``; ``stop`` ends it sooner). Every point must be observed.
    ``jacobian(A_m, S, B_m)``, when given, returns the analytic (ja, js, jb) instead of central
    differences. ``should_stop()``, asked before each iteration, ends the solve where it is
    (a cancel, a time limit)."""
    n, c = A.shape
    s = len(S)
    p, d = B.shape
    nc = n * c + s
    M = len(view)
    cam_cols = np.concatenate([c * view[:, None] + np.arange(c)[None, :],
                               np.broadcast_to(n * c + np.arange(s), (M, s))], axis=1)  # (M, c + s)
    blocks = _Blocks(view, track, n, c, s, p)
    by_track = _SumBy(track, p)
    r = residual(_rows(A, view), S, _rows(B, track))
    cost = _cost(r, f_scale)
    lam = 1e-3
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        if should_stop is not None and should_stop():
            break
        ja, js, jb = (_jacobians(residual, A, S, B, view, track) if jacobian is None
                      else jacobian(_rows(A, view), S, _rows(B, track)))
        je = np.concatenate([ja, js], axis=2)  # (M, 2, c + s)
        rw = r
        if f_scale is not None:  # Huber's weights (plain least squares: all 1)
            root = np.sqrt(_robust_weights(r, f_scale))
            je, jb, rw = je * root[:, None, None], jb * root[:, None, None], r * root[:, None]
        # Normal equations' blocks: U summed by view (blocks.own), W and the gradients per observation.
        U = blocks.own(je, je)
        diag_u = np.diag(U).copy()
        # jb^T copied contiguous first: numpy's stacked product then takes its fast path (the same
        # sums, about a third less CPU than from the transposed view). V's and W^T's terms in one
        # product, jb^T [jb, je]: each entry is the same sum as from the two products apart.
        both = np.ascontiguousarray(jb.transpose(0, 2, 1)) @ np.concatenate([jb, je], axis=2)
        V = by_track(both[:, :, :d])
        finite_v = bool(np.isfinite(V).all())
        WmT = np.ascontiguousarray(both[:, :, d:])  # (M, d, c+s): each observation's W^T
        WmT_gathered = blocks.gathered(WmT)
        ga = np.einsum("mki,mk->mi", je, rw)  # (M, c+s); einsum: faster than matmul on stacks of vectors
        gb = by_track(np.einsum("mki,mk->mi", jb, rw))
        if stop.gradient_tolerance > 0:
            gradient = max(np.abs(np.bincount(cam_cols.ravel(), weights=ga.ravel(), minlength=nc)).max(initial=0.0),
                           np.abs(gb).max(initial=0.0))
            if gradient <= stop.gradient_tolerance:
                iterations -= 1  # no step computed
                break
        while True:
            Vinv = _inverse(_damped(V, lam, finite_v))
            # Reduced system: (U - W V^-1 W^T) da = -(ga - W V^-1 gb).
            VWT = _rows(Vinv, track) @ WmT  # (M, d, c+s): (W V^-1)^T, V^-1 being symmetric
            Ured = U - blocks.reduction(VWT, WmT_gathered)
            Ured[np.diag_indices(nc)] += lam * diag_u + 1e-12
            rhs = np.bincount(cam_cols.ravel(), weights=(ga - np.einsum("mj,mjk->mk", _rows(gb, track), VWT)).ravel(),
                              minlength=nc)
            try:
                da = -np.linalg.solve(Ured, rhs)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            if not np.all(np.isfinite(da)):
                lam *= 10
                if lam > 1e12:
                    return A, S, B, r, iterations
                continue
            # Back substitution: db_j = -V_j^-1 (gb_j + sum_m W_m^T da_m).
            wda = by_track(np.einsum("mij,mj->mi", WmT, np.take(da, cam_cols)))
            db = -(Vinv @ (gb + wda)[:, :, None])[:, :, 0]
            A_new = A + da[:n * c].reshape(n, c)
            S_new = S + da[n * c:]
            B_new = B + db
            small = stop.parameter_tolerance > 0 and (
                np.sqrt(np.sum(da * da) + np.sum(db * db))
                <= (np.sqrt(np.sum(A * A) + np.sum(S * S) + np.sum(B * B)) + stop.parameter_tolerance)
                * stop.parameter_tolerance)
            r_new = residual(_rows(A_new, view), S_new, _rows(B_new, track))
            cost_new = _cost(r_new, f_scale) if np.all(np.isfinite(r_new)) else np.inf
            if cost_new < cost:
                # A step within the parameter tolerance ends the solve, taken: near an exact fit it
                # is small against the parameters but not against what is left of the error.
                converged = small or cost - cost_new <= stop.function_tolerance * cost
                A, S, B, r, cost = A_new, S_new, B_new, r_new, cost_new
                lam = max(lam / 3, 1e-12)
                break
            if small:
                return A, S, B, r, iterations
            lam *= 4
            if lam > 1e12:
                return A, S, B, r, iterations
        if converged:
            break
    return A, S, B, r, iterations
