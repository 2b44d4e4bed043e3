"""The conic boundary: the one place that talks to the conic solver (Clarabel), and the one list
of every back-end's statuses mapped to ours (ConicStatus), so that callers read ours only.

The boundary's modules, all in geocert/core: this one (Clarabel), interior_point.py (the
structured primal-dual interior-point method, numpy, the direct autocalibration's moment programs
solved first by it) and barrier.py (the batched log-barrier method of the batched triangulation's
root regions). Each speaks its own statuses; each maps them here, through an explicit table where a
status not listed is FAILED, never OPTIMAL. tests/test_layers.py holds that no other module
imports Clarabel or names a back-end's status.

Inner-loop relaxations assemble sparse data themselves and call :func:`solve_conic`; cvxpy is
kept out of the hot path (it costs milliseconds of compilation per problem).

Conic form (Clarabel's): minimise ``q'x`` subject to ``A x + s = b``, ``s`` in the product cone.
"""

from __future__ import annotations

import enum
import functools
import itertools
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp

from geocert.core.cones import ConeSpec


class ConicStatus(enum.Enum):
    OPTIMAL = "optimal"  # a clean optimum: its bound may be trusted
    INFEASIBLE = "infeasible"  # a Farkas certificate of primal infeasibility
    UNBOUNDED = "unbounded"  # a certificate of dual infeasibility
    INACCURATE = "inaccurate"  # "almost" answers: never used to prune or certify
    FAILED = "failed"  # iteration/time limits, numerical failure


# Explicit and exhaustive: a status Clarabel adds later falls to FAILED, never to OPTIMAL.
_CLARABEL_STATUS = {
    "Solved": ConicStatus.OPTIMAL,
    "PrimalInfeasible": ConicStatus.INFEASIBLE,
    "DualInfeasible": ConicStatus.UNBOUNDED,
    "AlmostSolved": ConicStatus.INACCURATE,
    "AlmostPrimalInfeasible": ConicStatus.INACCURATE,
    "AlmostDualInfeasible": ConicStatus.INACCURATE,
    "MaxIterations": ConicStatus.FAILED,
    "MaxTime": ConicStatus.FAILED,
    "NumericalError": ConicStatus.FAILED,
    "InsufficientProgress": ConicStatus.FAILED,
    "CallbackTerminated": ConicStatus.FAILED,
    "Unsolved": ConicStatus.FAILED,
}


# The structured interior-point method's (interior_point.solve). An end other than "Solved" still
# returns the last iterate, whose dual gives a safe bound: never a clean answer.
_INTERIOR_POINT_STATUS = {
    "Solved": ConicStatus.OPTIMAL,  # residuals and gap within the tolerance, or the acceptable one
    "MaxIterations": ConicStatus.INACCURATE,
    "Stalled": ConicStatus.INACCURATE,  # no progress, or steps too short to make any
    "NumericalError": ConicStatus.INACCURATE,  # a scaling or Schur complement not factored
}

# The batched barrier's (barrier.solve_batched), one per problem. A centre reached ("Centred") is
# only ever used through the safe bound of its dual (the caller proves every bound again); a
# problem that ended otherwise is not used at all.
_BARRIER_STATUS = {
    "Centred": ConicStatus.OPTIMAL,  # every centre taken from a strictly feasible start, all finite
    "InfeasibleStart": ConicStatus.FAILED,  # the start not strictly inside the cones
    "NoStep": ConicStatus.FAILED,  # no step found along a Newton direction
    "NotFinite": ConicStatus.FAILED,  # the last point or its dual not finite
}


def map_clarabel_status(status) -> ConicStatus:
    return _CLARABEL_STATUS.get(str(status), ConicStatus.FAILED)


def map_interior_point_status(status: str) -> ConicStatus:
    return _INTERIOR_POINT_STATUS.get(status, ConicStatus.FAILED)


def map_barrier_status(status: str) -> ConicStatus:
    return _BARRIER_STATUS.get(status, ConicStatus.FAILED)


def clarabel_cones(spec: ConeSpec) -> list:
    cones = []
    if spec.zero:
        cones.append(clarabel.ZeroConeT(spec.zero))
    if spec.nonneg:
        cones.append(clarabel.NonnegativeConeT(spec.nonneg))
    cones.extend(clarabel.SecondOrderConeT(d) for d in spec.soc)
    cones.extend(clarabel.PSDTriangleConeT(n) for n in spec.psd)
    return cones


@dataclass
class ConicResult:
    status: ConicStatus
    x: np.ndarray | None
    z: np.ndarray | None  # dual vector, for certificates
    primal_objective: float
    dual_objective: float
    raw_status: str

    @property
    def lower_bound(self) -> float:
        # Both objectives bound the optimum within the solver's tolerance; the smaller is the safer.
        return min(self.primal_objective, self.dual_objective)

    @property
    def dual_usable(self) -> bool:
        """A clean optimum's dual, or an almost-solved one's (Clarabel's "AlmostSolved"): for a
        caller whose bound is safe whatever multipliers it is given, as good as any."""
        return self.status is ConicStatus.OPTIMAL or self.raw_status == "AlmostSolved"


def _settings(tolerance: float, lean: bool = False) -> clarabel.DefaultSettings:
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = 100
    settings.tol_gap_abs = tolerance
    settings.tol_gap_rel = tolerance
    settings.tol_feas = tolerance
    if lean:
        settings.equilibrate_enable = False
        settings.iterative_refinement_enable = False
    return settings


# Solves aim at 1e-9. On nearly exact relaxations (tiny boxes) Clarabel can stall with a
# duality gap near 3e-8 and answer AlmostSolved; such a solve is repeated once at 1e-7, and only
# a clean "Solved" there is trusted. Both are far below the gaps searches stop at (1e-4 and up
# on costs scaled to about 1), and the lower bound taken is the smaller objective anyway.
_RETRY_TOLERANCE = 1e-7
_SETTINGS = _settings(1e-9)
_RETRY_SETTINGS = _settings(_RETRY_TOLERANCE)

# Small programs (a track's relaxations and root region, a small map's) are built well scaled:
# charts normalise the frame and costs are scaled so that the incumbent costs 1. For them
# Clarabel's equilibration and iterative refinement cost about 30% of the solve time (151 against
# 107 us a solve, side by side) and change nothing measurable: on 586 Dinosaur relaxations and
# root-region programs, the same statuses (all Solved), 1.8 fewer iterations on average, and
# objectives within 8e-10 of the full settings'. The
# termination test (and so the meaning of "Solved") is the same. A lean solve that does not end
# cleanly is repeated with the full settings before anything else is concluded.
_LEAN_SETTINGS = _settings(1e-9, lean=True)
_LEAN_ROWS = 400


@functools.lru_cache(maxsize=8)
def _lean_settings(tolerance: float) -> clarabel.DefaultSettings:
    return _LEAN_SETTINGS if tolerance == 1e-9 else _settings(tolerance, lean=True)


@functools.lru_cache(maxsize=8)
def _full_settings(tolerance: float) -> clarabel.DefaultSettings:
    return _SETTINGS if tolerance == 1e-9 else _settings(tolerance)


@functools.lru_cache(maxsize=64)
def _zero_quadratic(n: int) -> sp.csc_matrix:
    return sp.csc_matrix((n, n))


def dense_to_csc(A: np.ndarray) -> sp.csc_matrix:
    """CSC from a small dense array, built from its triple (a third faster than scipy's path)."""
    mask_t = (A != 0).T
    indptr = np.zeros(A.shape[1] + 1, dtype=np.int32)
    np.cumsum(mask_t.sum(axis=1), out=indptr[1:])
    return sp.csc_matrix((A.T[mask_t], np.nonzero(mask_t)[1].astype(np.int32), indptr), shape=A.shape)


def _new_solver(q: np.ndarray, A: sp.csc_matrix, b: np.ndarray, cones: ConeSpec, settings):
    return clarabel.DefaultSolver(_zero_quadratic(q.shape[0]), q, A, b, clarabel_cones(cones), settings)


def solve_conic(q: np.ndarray, A: np.ndarray | sp.csc_matrix, b: np.ndarray, cones: ConeSpec) -> ConicResult:
    """Solve a linear-objective conic program; never raises on solver trouble, reports it instead."""
    if isinstance(A, np.ndarray):
        A = dense_to_csc(A)
    try:
        lean = A.shape[0] <= _LEAN_ROWS
        solver = _new_solver(q, A, b, cones, _LEAN_SETTINGS if lean else _SETTINGS)
        return _retried(_result(solver.solve()), q, A, b, cones, lean)
    except BaseException as exc:  # Clarabel raises on malformed data (panic) as a Python exception
        if isinstance(exc, (KeyboardInterrupt, SystemExit)):
            raise
        return ConicResult(ConicStatus.FAILED, None, None, np.nan, np.nan, f"exception: {exc}")


@dataclass(frozen=True)
class SolveSettings:
    """The settings of a one-off solve whose program needs other than the boundary's (a field left
    None keeps Clarabel's default): the direct method's large moment programs (regularisation,
    refinement, one thread) and multiplier searches that only need some dual, checked elsewhere."""

    gap: float | None = None  # absolute and relative duality gap
    feasibility: float | None = None
    max_iter: int | None = None
    regularisation: float | None = None  # the static regularisation constant
    refinement_steps: int | None = None
    threads: int | None = None
    faer: bool = False  # the faer factorisation, when the build has it


def _clarabel_settings(chosen: SolveSettings) -> clarabel.DefaultSettings:
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    if chosen.gap is not None:
        settings.tol_gap_abs = settings.tol_gap_rel = chosen.gap
    if chosen.feasibility is not None:
        settings.tol_feas = chosen.feasibility
    if chosen.max_iter is not None:
        settings.max_iter = chosen.max_iter
    if chosen.regularisation is not None:
        settings.static_regularization_constant = chosen.regularisation
    if chosen.refinement_steps is not None:
        settings.iterative_refinement_max_iter = chosen.refinement_steps
    if chosen.threads is not None:
        settings.max_threads = chosen.threads
    if chosen.faer:
        try:
            settings.direct_solve_method = "faer"
        except Exception:  # a build without it: the default factorisation
            pass
    return settings


def solve_once(q: np.ndarray, A: np.ndarray | sp.csc_matrix, b: np.ndarray, cones: ConeSpec,
               settings: SolveSettings) -> ConicResult:
    """One solve with the given settings and no retry: the caller decides what an inaccurate
    answer is worth. Never raises on solver trouble, reports it instead."""
    if isinstance(A, np.ndarray):
        A = dense_to_csc(A)
    try:
        return _result(_new_solver(q, A, b, cones, _clarabel_settings(settings)).solve())
    except BaseException as exc:  # Clarabel raises on malformed data (panic) as a Python exception
        if isinstance(exc, (KeyboardInterrupt, SystemExit)):
            raise
        return ConicResult(ConicStatus.FAILED, None, None, np.nan, np.nan, f"exception: {exc}")


def _retried(result: ConicResult, q, A: sp.csc_matrix, b, cones: ConeSpec, lean: bool,
             tolerance: float = 1e-9) -> ConicResult:
    """A lean solve that did not end cleanly solved again with the full settings; an inaccurate
    answer solved again at the retry tolerance (see _RETRY_SETTINGS), unless it was solved at
    that tolerance or looser already (the same solve again would end the same way)."""
    if lean and result.status in (ConicStatus.INACCURATE, ConicStatus.FAILED):
        result = _result(_new_solver(q, A, b, cones, _SETTINGS).solve())
    elif result.status is ConicStatus.INACCURATE and tolerance >= _RETRY_TOLERANCE:
        return result
    if result.status is not ConicStatus.INACCURATE:
        return result
    return _result(_new_solver(q, A, b, cones, _RETRY_SETTINGS).solve())


def _result(solution) -> ConicResult:
    raw_status = str(solution.status)
    status = map_clarabel_status(raw_status)
    x = np.array(solution.x, dtype=float)
    z = np.array(solution.z, dtype=float)
    primal, dual = float(solution.obj_val), float(solution.obj_val_dual)
    # A sum is finite only if every term is (an overflowing sum of finite terms is refused too,
    # which is as it should be); cheaper than np.isfinite on the small vectors of the hot path.
    if status is ConicStatus.OPTIMAL and not math.isfinite(float(x.sum()) + primal):
        status = ConicStatus.FAILED
    return ConicResult(status=status, x=x, z=z, primal_objective=primal, dual_objective=dual,
                       raw_status=raw_status)


@dataclass
class _Loaded:
    """A Clarabel solver, the CSC matrix it was built on (its data updated in place), and a
    token of the program whose data it holds."""

    csc: sp.csc_matrix
    solver: Any
    lean: bool
    holder: int = 0


def _updated(entry: _Loaded, q: np.ndarray, data: np.ndarray, b: np.ndarray) -> _Loaded | None:
    """The entry loaded with new data, or None when Clarabel refuses the update (then a new
    solver is built: a refused update must not fail the solve)."""
    try:
        entry.csc.data[:] = data
        entry.solver.update(q=q, b=b, A=entry.csc)
        return entry
    except Exception:
        entry.holder = 0  # its data are now nobody's: whoever uses it next must load all of theirs
        return None


class _Pool(threading.local):
    """Per thread, the solvers of small dense programs by (shape, cones, nonzero pattern), kept
    from one program to the next: a track's root region and first relaxation have the patterns
    of the previous track with as many views, and a built solver skips Clarabel's setup (28 of
    78 us for a track's root-region program, 60 of about 300 us for its relaxation, measured
    with the full settings). Only lean solvers are kept: with no equilibration, a solver loaded with
    new data solves exactly the problem a new one would, though not always to the same last bits:
    a bound can differ by about 1e-11 relative with what the process solved before (each is the
    safe bound of its own dual; emptying the pool at the start of a job did not remove it)."""

    size = 64

    def __init__(self) -> None:
        self.entries: OrderedDict = OrderedDict()

    def get(self, key) -> _Loaded | None:
        entry = self.entries.get(key)
        if entry is not None:
            self.entries.move_to_end(key)
        return entry

    def put(self, key, entry: _Loaded) -> None:
        self.entries[key] = entry
        if len(self.entries) > self.size:
            self.entries.popitem(last=False)

    def drop(self, key) -> None:
        self.entries.pop(key, None)


_POOL = _Pool()


_TOKENS = itertools.count(1)


class ReusableConicProgram:
    """A conic program re-solved with new numbers but the same shape, as in branch and bound.

    Keeps the CSC structure and the Clarabel solver (its symbolic factorisation) while the
    sparsity pattern and cones stay the same, and updates the data in place; any change of
    pattern rebuilds both (or takes a pooled solver of that exact pattern, see _Pool), so reuse
    can never alter the problem solved.
    """

    def __init__(self, lean: bool | None = None, tolerance: float = 1e-9) -> None:
        """``lean``: the lean settings (no equilibration) for small programs (None: by size);
        False for programs not built well scaled, where a lean solve fails and is repeated.
        ``tolerance``: the solves' (lean or full; a lean solve that fails is repeated with the full
        settings at 1e-9), e.g. looser for bound tightening, whose sides are safe bounds of
        whatever dual the solve returns."""
        self._lean = lean
        self._tolerance = tolerance
        self._token = next(_TOKENS)
        self._key = None
        self._mask: np.ndarray | None = None
        self._entry: _Loaded | None = None
        self._data = self._b = self._cones = None

    def solve(self, q: np.ndarray, A: np.ndarray | sp.csc_matrix, b: np.ndarray, cones: ConeSpec) -> ConicResult:
        """``A`` dense (small problems: its nonzero pattern is compared) or CSC (large ones: its
        index arrays are compared); either way the solver is only updated when they match."""
        key = (A.shape, cones.zero, cones.nonneg, cones.soc, cones.psd)
        lean = A.shape[0] <= _LEAN_ROWS if self._lean is None else self._lean
        pool_key = None
        try:
            if sp.issparse(A):
                mask, data = None, A.data
                same = (key == self._key and self._mask is None and np.array_equal(A.indptr, self._entry.csc.indptr)
                        and np.array_equal(A.indices, self._entry.csc.indices))
                entry = self._entry if same else None
            else:
                mask = A != 0
                data = A.T[mask.T]
                same = key == self._key and self._mask is not None and np.array_equal(mask, self._mask)
                entry = self._entry if same else None
                if entry is None and lean:
                    pool_key = (key, mask.tobytes(), self._tolerance)
                    entry = _POOL.get(pool_key)
            if entry is not None:
                entry = _updated(entry, q, data, b)
            if entry is None:
                csc = A.copy() if mask is None else dense_to_csc(A)
                solver = _new_solver(q, csc, b, cones, _lean_settings(self._tolerance) if lean
                                     else _full_settings(self._tolerance))
                entry = _Loaded(csc, solver, lean)
                if pool_key is not None:
                    _POOL.put(pool_key, entry)
            entry.holder = self._token
            self._key, self._mask, self._entry = key, mask, entry
            self._data, self._b, self._cones = data, b, cones
            return _retried(_result(entry.solver.solve()), q, entry.csc, b, cones, entry.lean, self._tolerance)
        except BaseException as exc:
            if isinstance(exc, (KeyboardInterrupt, SystemExit)):
                raise
            self._key = None
            if pool_key is not None:
                _POOL.drop(pool_key)  # never hand a solver in an unknown state to another program
            return ConicResult(ConicStatus.FAILED, None, None, np.nan, np.nan, f"exception: {exc}")

    def solve_objective(self, q: np.ndarray) -> ConicResult:
        """The last program solved again with objective ``q`` (a feasible set optimised in many
        directions, as for root regions and bound tightening): no data compared, and none copied
        unless another program has used the pooled solver since."""
        if self._key is None:
            return ConicResult(ConicStatus.FAILED, None, None, np.nan, np.nan, "no program to re-solve")
        entry = self._entry
        try:
            if entry.holder != self._token:
                entry.csc.data[:] = self._data
                entry.solver.update(q=q, b=self._b, A=entry.csc)
                entry.holder = self._token
            else:
                entry.solver.update(q=q)
            return _retried(_result(entry.solver.solve()), q, entry.csc, self._b, self._cones, entry.lean,
                            self._tolerance)
        except BaseException as exc:
            if isinstance(exc, (KeyboardInterrupt, SystemExit)):
                raise
            self._key = None
            return ConicResult(ConicStatus.FAILED, None, None, np.nan, np.nan, f"exception: {exc}")
