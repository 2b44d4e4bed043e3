"""The conic-solver boundary: status map, and solvers reused across programs (solvers.conic)."""

import numpy as np
import pytest

from geocert.core import conic
from geocert.core.cones import ConeSpec
from geocert.core.conic import ConicStatus, ReusableConicProgram, map_clarabel_status, solve_conic

BALL = ConeSpec(nonneg=1, soc=(4,))


def ball(centre, radius: float, cap: float = 100.0):
    """{x : ||x - centre|| <= radius, sum(x) <= cap} as (A, b): one nonnegative row, one SOC."""
    A = np.vstack([np.ones((1, 3)), np.zeros((1, 3)), -np.eye(3)])
    b = np.concatenate([[cap, radius], -np.asarray(centre, dtype=float)])
    return A, b


def minimum(q, centre, radius):
    """min q.x over the ball (the cap inactive): q.centre - radius |q|."""
    return float(q @ centre - radius * np.linalg.norm(q))


class TestStatusMap:
    def test_only_solved_is_optimal(self):
        assert map_clarabel_status("Solved") is ConicStatus.OPTIMAL
        for almost in ("AlmostSolved", "AlmostPrimalInfeasible", "AlmostDualInfeasible"):
            assert map_clarabel_status(almost) is ConicStatus.INACCURATE

    def test_an_unknown_status_is_a_failure(self):
        assert map_clarabel_status("SomethingNew") is ConicStatus.FAILED


class TestReusableConicProgram:
    def setup_method(self):
        conic._POOL.entries.clear()

    def test_solves_agree_with_closed_form(self):
        rng = np.random.default_rng(7)
        program = ReusableConicProgram()
        for _ in range(5):
            q, centre, radius = rng.normal(size=3), rng.normal(size=3), rng.uniform(0.5, 2)
            result = program.solve(q, *ball(centre, radius), BALL)
            assert result.status is ConicStatus.OPTIMAL
            assert result.primal_objective == pytest.approx(minimum(q, centre, radius), abs=1e-7)

    def test_a_pooled_solver_gives_what_a_new_one_gives(self):
        rng = np.random.default_rng(8)
        first, second = ReusableConicProgram(), ReusableConicProgram()
        q1, q2 = rng.normal(size=3), rng.normal(size=3)
        first.solve(q1, *ball([1.0, 2.0, 3.0], 1.0), BALL)
        assert len(conic._POOL.entries) == 1
        pooled = second.solve(q2, *ball([-1.0, 0.5, 2.0], 0.7), BALL)  # same pattern: the pooled solver
        assert len(conic._POOL.entries) == 1
        fresh = solve_conic(q2, *ball([-1.0, 0.5, 2.0], 0.7), BALL)
        assert pooled.primal_objective == fresh.primal_objective
        assert np.array_equal(pooled.x, fresh.x) and np.array_equal(pooled.z, fresh.z)

    def test_re_solving_reloads_data_another_program_replaced(self):
        """A root region re-solves its feasible set in many directions; if another program used
        the pooled solver in between, its own data must come back first."""
        rng = np.random.default_rng(9)
        mine, other = ReusableConicProgram(), ReusableConicProgram()
        centre, radius = np.array([1.0, 2.0, 3.0]), 1.0
        mine.solve(rng.normal(size=3), *ball(centre, radius), BALL)
        other.solve(rng.normal(size=3), *ball([10.0, -4.0, 0.0], 3.0), BALL)  # same solver, other data
        q = rng.normal(size=3)
        again = mine.solve_objective(q)
        assert again.status is ConicStatus.OPTIMAL
        assert again.primal_objective == pytest.approx(minimum(q, centre, radius), abs=1e-7)

    def test_a_different_pattern_gets_its_own_solver(self):
        program = ReusableConicProgram()
        A, b = ball([0.0, 0.0, 0.0], 1.0)
        program.solve(np.ones(3), A, b, BALL)
        A_sparser = A.copy()
        A_sparser[0, 2] = 0.0  # the cap on x0 + x1 only: another nonzero pattern
        result = program.solve(np.array([0.0, 0.0, 1.0]), A_sparser, b, BALL)
        assert result.primal_objective == pytest.approx(-1.0, abs=1e-7)
        assert len(conic._POOL.entries) == 2

    def test_pool_stays_bounded(self):
        for n in range(conic._POOL.size + 10):
            cap = np.zeros((n + 1, 3))  # programs of different shapes
            cap[:, 0] = 1.0
            A, b = ball([0.0, 0.0, 0.0], 1.0)
            A = np.vstack([cap, A[1:]])
            b = np.concatenate([np.full(len(cap), 100.0 + n), b[1:]])
            ReusableConicProgram().solve(np.ones(3), A, b, ConeSpec(nonneg=len(cap), soc=(4,)))
        assert len(conic._POOL.entries) == conic._POOL.size

    def test_a_refused_update_never_gives_a_wrong_answer(self):
        """Clarabel may refuse to load new data into a built solver: the program that wanted it
        gets a new solver, and a program whose data the refused solver held does not trust it."""

        class Refusing:  # takes new objectives, and new data only halfway (b, not A)
            def __init__(self, solver):
                self.solver = solver

            def update(self, q=None, b=None, A=None):
                self.solver.update(q=q) if b is None else self.solver.update(q=q, b=b)
                if A is not None:
                    raise RuntimeError("update refused")

            def solve(self):
                return self.solver.solve()

        rng = np.random.default_rng(10)
        mine, other = ReusableConicProgram(), ReusableConicProgram()
        centre, radius = np.array([1.0, 2.0, 3.0]), 1.0
        mine.solve(rng.normal(size=3), *ball(centre, radius), BALL)
        (entry,) = conic._POOL.entries.values()
        entry.solver = Refusing(entry.solver)
        q_other = rng.normal(size=3)
        theirs = other.solve(q_other, *ball([10.0, -4.0, 0.0], 3.0), BALL)
        assert theirs.primal_objective == pytest.approx(minimum(q_other, np.array([10.0, -4.0, 0.0]), 3.0), abs=1e-7)
        q = rng.normal(size=3)
        again = mine.solve_objective(q)
        assert again.status is ConicStatus.FAILED or again.primal_objective == pytest.approx(
            minimum(q, centre, radius), abs=1e-7)


class TestLeanSettings:
    def test_a_lean_solve_that_fails_is_solved_again_with_the_full_settings(self, monkeypatch):
        """Small programs are first solved without equilibration and iterative refinement; one
        that does not end cleanly must not be reported as a failure (or trusted) as it stands."""
        conic._POOL.entries.clear()  # no solver built with the usual lean settings to reuse
        starved = conic._settings(1e-9, lean=True)
        starved.max_iter = 1  # the lean attempt cannot finish
        monkeypatch.setattr(conic, "_LEAN_SETTINGS", starved)
        q, centre, radius = np.array([1.0, -2.0, 0.5]), np.array([1.0, 2.0, 3.0]), 1.5
        for result in (solve_conic(q, *ball(centre, radius), BALL),
                       ReusableConicProgram().solve(q, *ball(centre, radius), BALL)):
            assert result.status is ConicStatus.OPTIMAL
            assert result.primal_objective == pytest.approx(minimum(q, centre, radius), abs=1e-7)


class TestPSDCones:
    """Positive semidefinite cones at the conic boundary, with safe bounds from their duals: what
    the SDP relaxations of autocalibration will stand on."""

    def smallest_eigenvalue_program(self, C: np.ndarray):
        """min trace(C X) s.t. trace(X) = 1, X PSD: its value is C's smallest eigenvalue."""
        from geocert.core.cones import ConeSpec, svec
        n = len(C)
        size = n * (n + 1) // 2
        q = svec(C)
        trace = svec(np.eye(n))
        A = np.vstack([trace[None, :], -np.eye(size)])  # trace(X) = 1; svec(X) in the PSD cone
        b = np.concatenate([[1.0], np.zeros(size)])
        return q, A, b, ConeSpec(zero=1, psd=(n,))

    def test_svec_is_an_isometry(self):
        from geocert.core.cones import smat, svec
        rng = np.random.default_rng(4)
        for n in (1, 2, 4):
            A, B = rng.normal(size=(2, n, n))
            A, B = A + A.T, B + B.T
            assert svec(A) @ svec(B) == pytest.approx(np.trace(A @ B))
            assert np.allclose(smat(svec(A), n), A)

    def test_the_solver_and_the_safe_bound_agree_with_the_eigenvalue(self):
        from geocert.core.cones import safe_lower_bound
        rng = np.random.default_rng(5)
        for n in (2, 3, 5):
            C = rng.normal(size=(n, n))
            C = C + C.T
            q, A, b, cones = self.smallest_eigenvalue_program(C)
            result = conic.solve_conic(q, A, b, cones)
            assert result.status is conic.ConicStatus.OPTIMAL
            smallest = np.linalg.eigvalsh(C)[0]
            assert result.primal_objective == pytest.approx(smallest, abs=1e-6)
            # Every feasible X has |svec entries| <= 1 (trace 1, PSD): the box the residual is
            # charged to. The safe bound is below the optimum, and close to it.
            box = np.ones(len(q))
            bound = safe_lower_bound(q, A, b, cones, result.z, -box, box)
            assert bound <= smallest + 1e-12 and bound >= smallest - 1e-6
            # Any dual vector gives a valid bound once projected, however wrong it is.
            noisy = result.z + rng.normal(size=len(result.z)) * 0.1
            assert safe_lower_bound(q, A, b, cones, noisy, -box, box) <= smallest + 1e-12

    def test_the_projection_lands_in_the_cone(self):
        from geocert.core.cones import ConeSpec, project_dual, smat
        rng = np.random.default_rng(6)
        z = rng.normal(size=1 + 2 + 3 + 6)
        projected = project_dual(z, ConeSpec(nonneg=1, soc=(2,), psd=(2, 3)))[3:]
        assert np.linalg.eigvalsh(smat(projected[:3], 2))[0] >= -1e-12
        assert np.linalg.eigvalsh(smat(projected[3:], 3))[0] >= -1e-12


class TestSafeBoundOfAnyIterate:
    """The last iterate of a failed solve can hold huge or non-finite entries: it gives no bound
    (-inf) and proves nothing, silently, never NaN or an overflowed +inf."""

    @pytest.mark.parametrize("spoil", [np.inf, np.nan, 1e300])
    def test_a_spoiled_dual_bounds_nothing(self, spoil):
        import warnings

        from geocert.core.cones import proves_infeasible, safe_lower_bound

        centre = np.array([0.5, -0.2, 0.1])
        A, b = ball(centre, 1.0)
        q = np.array([1.0, 2.0, -1.0])
        lower, upper = np.full(3, -10.0), np.full(3, 10.0)
        result = solve_conic(q, A, b, BALL)
        assert result.status is ConicStatus.OPTIMAL
        z = np.full_like(result.z, spoil)
        z[0] = -spoil if np.isfinite(spoil) else spoil
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no overflow or invalid-value warning escapes
            assert safe_lower_bound(q, A, b, BALL, z, lower, upper) == -np.inf
            assert not proves_infeasible(A, b, BALL, z, lower, upper)
        assert safe_lower_bound(q, A, b, BALL, result.z, lower, upper) <= minimum(q, centre, 1.0) + 1e-7


class TestSafeLowerBoundsOfRows:
    """cones.safe_lower_bounds (many dual vectors over one feasible set, as the root region
    uses) gives each row safe_lower_bound's bound, for every cone kind, and nothing for a row that
    is not finite."""

    def test_each_row_is_the_single_bound(self):
        from geocert.core.cones import safe_lower_bound, safe_lower_bounds

        rng = np.random.default_rng(4)
        cones = ConeSpec(zero=2, nonneg=3, soc=(3, 4, 3), psd=(3,))
        rows, n = cones.rows, 5
        A, b = rng.normal(size=(rows, n)), rng.normal(size=rows)
        Q, Z = rng.normal(size=(6, n)), rng.normal(size=(6, rows))
        lower, upper = -rng.uniform(1, 2, n), rng.uniform(1, 2, n)
        transform = rng.normal(size=(2, 2))
        Z[4, 3] = np.inf
        together = safe_lower_bounds(Q, A, b, cones, Z, lower, upper, transform)
        alone = [safe_lower_bound(q, A, b, cones, z, lower, upper, transform) for q, z in zip(Q, Z)]
        assert together[4] == -np.inf and alone[4] == -np.inf
        assert np.allclose(np.delete(together, 4), np.delete(alone, 4), rtol=1e-12, atol=1e-12)
        assert np.isfinite(np.delete(together, 4)).all()


class TestSolveOnce:
    """A one-off solve with its own settings: they reach the solver, and trouble is reported."""

    def test_solves_agree_with_closed_form(self):
        q, centre = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.4])
        result = conic.solve_once(q, *ball(centre, 1.5), BALL, conic.SolveSettings(gap=1e-10, feasibility=1e-10))
        assert result.status is ConicStatus.OPTIMAL
        assert result.primal_objective == pytest.approx(minimum(q, centre, 1.5), abs=1e-8)

    def test_its_iteration_cap_is_the_one_given(self):
        q, centre = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.4])
        result = conic.solve_once(q, *ball(centre, 1.5), BALL, conic.SolveSettings(max_iter=1))
        assert result.raw_status == "MaxIterations" and result.status is ConicStatus.FAILED

    def test_malformed_data_is_a_failure_not_an_exception(self):
        A, b = ball([0.0, 0.0, 0.0], 1.0)
        result = conic.solve_once(np.ones(3), A, b[:-1], BALL, conic.SolveSettings())
        assert result.status is ConicStatus.FAILED and result.x is None
