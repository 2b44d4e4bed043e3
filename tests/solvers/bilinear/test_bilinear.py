"""Bilinear fitting (thesis chapter 8): the envelopes and the lifted relaxation under-estimate,
exact recovery, certified costs against alternating least squares and SCIP, bad input named,
full certificates verified and tampered ones refused."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from testing.bilinear import scene
from geocert.jobs.runner import parse_job, solve_job
from geocert.formulations.bilinear import problem
from geocert.formulations.bilinear.options import BilinearOptions
from geocert.formulations.bilinear.relaxation import Relaxation, mccormick_rows
from geocert.solvers.bilinear.search import Model, fit_frame
from geocert.core.conic import ConicStatus, solve_conic
from geocert.core.geometry import InputError
from geocert.verify.checks import verify_any


def envelope_violation(rows, m: float, a: float) -> float:
    """How far the point (m, a, m a) is outside the rows c_a a + c_m m + c_g g <= rhs (<= 0: inside)."""
    c_a, c_m, c_g, rhs = rows
    return float(np.max(c_a * a + c_m * m + c_g * (m * a) - rhs))


interval = st.tuples(st.floats(-50, 50), st.floats(1e-3, 50)).map(lambda p: (p[0], p[0] + p[1]))


@settings(max_examples=200, deadline=None)
@given(box=interval, alpha=interval, s=st.floats(0, 1), w=st.floats(0, 1))
def test_mccormick_envelopes_hold_on_their_rectangle(box, alpha, s, w):
    (l, u), (L, U) = box, alpha
    m, a = l + s * (u - l), L + w * (U - L)
    rows = mccormick_rows(np.array(l), np.array(u), L, U)
    scale = 1 + abs(l * L) + abs(u * U) + abs(l * U) + abs(u * L)
    assert envelope_violation(rows, m, a) <= 1e-12 * scale
    for corner_m, corner_a in ((l, L), (l, U), (u, L), (u, U)):  # exact at the corners: tight
        c_a, c_m, c_g, rhs = rows
        assert np.min(np.abs(c_a * corner_a + c_m * corner_m + c_g * corner_m * corner_a - rhs)) <= 1e-12 * scale


def test_the_envelope_check_can_fail():
    """The property above is not vacuous: an envelope with one coefficient wrong (u for l in the
    first under-estimator, a plausible slip) cuts off points of the rectangle, and the check says so."""
    rng = np.random.default_rng(0)
    caught = 0
    for _ in range(200):
        l, u = sorted(rng.uniform(-5, 5, 2))
        L, U = sorted(rng.uniform(-5, 5, 2))
        c_a, c_m, c_g, rhs = mccormick_rows(np.array(l), np.array(u), L, U)
        c_a = c_a.copy()
        c_a[0] = u  # mutated: should be l
        m, a = rng.uniform(l, u), rng.uniform(L, U)
        caught += envelope_violation((c_a, c_m, c_g, rhs), m, a) > 1e-9
    assert caught > 20


def lifted_point(relaxation: Relaxation, model: Model, M, alpha, t) -> np.ndarray:
    """A true point (camera, coefficients) as a point of the relaxation's variables."""
    K = relaxation.K
    x = np.zeros(relaxation.nvar)
    x[relaxation.ig:relaxation.ig + 6 * K] = np.outer(M.ravel(), alpha).ravel()
    x[relaxation.ia:relaxation.ia + K] = alpha
    x[relaxation.im:relaxation.im + 6] = M.ravel()
    x[relaxation.it:relaxation.it + 2] = t
    r = model.u - (model.shape(alpha) @ M.T + t)
    if relaxation.norm == "L1L1":
        x[relaxation.ie:] = np.abs(r).ravel()
    else:
        x[relaxation.ie] = np.linalg.norm(r)
    return x


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), norm=st.sampled_from(["L1L1", "L2L2"]),
       coefficients=st.sampled_from(["convex", "affine"]))
def test_the_lifted_relaxation_under_estimates(seed, norm, coefficients):
    """A true point in a random box is feasible for the box's relaxation (within its variables'
    bounds, for the cap of its own cost), at its own cost; so the relaxation's safe bound, from a
    solved dual, is never above it."""
    rng = np.random.default_rng(seed)
    K, N = int(rng.integers(1, 5)), int(rng.integers(6, 12))
    basis, points, *_ = scene(K, N, 0.01, seed % 1000)
    frame = problem.normalise(basis, points)
    model = Model(frame, norm, coefficients, 3.0)
    relaxation = Relaxation(frame.X, frame.u, norm, coefficients, 3.0)
    lo = rng.uniform(-2, 1, 6)
    hi = lo + rng.uniform(1e-3, 2, 6)
    M = (lo + rng.uniform(0, 1, 6) * (hi - lo)).reshape(2, 3)
    v = rng.dirichlet(np.ones(K)) if coefficients == "convex" else rng.uniform(-3, 3, K)
    alpha = problem.project_coefficients(v, coefficients, 3.0)
    t = model.best_t(M, alpha) + rng.normal(size=2) * 0.1
    cost = model.cost(M, alpha, t)
    data = relaxation.conic_data(lo, hi, cost * (1 + 1e-12) + 1e-12)
    assert data is not None
    x = lifted_point(relaxation, model, M, alpha, t)
    tol = 1e-9 * (1 + np.abs(x).max())
    assert np.all(x >= data.lower - tol) and np.all(x <= data.upper + tol)
    slack = data.b - data.A @ x
    zero, nonneg = data.cones.zero, data.cones.nonneg
    assert np.all(np.abs(slack[:zero]) <= tol)
    assert np.all(slack[zero:zero + nonneg] >= -tol)
    if norm == "L2L2":
        cone = slack[zero + nonneg:]
        assert cone[0] >= np.linalg.norm(cone[1:]) - tol
        assert x[relaxation.ie] ** 2 == pytest.approx(cost, rel=1e-9, abs=1e-12)
    else:
        assert data.q @ x == pytest.approx(cost, rel=1e-9, abs=1e-12)
    res = solve_conic(data.q, data.A, data.b, data.cones)
    if res.status is ConicStatus.OPTIMAL:
        assert relaxation.bound(data, res.z) <= cost * (1 + 1e-7) + 1e-9


@pytest.mark.parametrize("norm", ["L1L1", "L2L2"])
def test_exact_recovery_without_noise(norm):
    basis, points, camera, alpha, _ = scene(4, 20, 0.0, 3)
    fit = fit_frame(basis, points, BilinearOptions(norm=norm))
    assert fit.certified and fit.status == "optimal"
    assert np.allclose(fit.coefficients, alpha, atol=1e-6)
    assert np.allclose(fit.camera, camera, atol=1e-5 * np.abs(camera).max())
    assert fit.cost <= 1e-6


@pytest.mark.parametrize("norm", ["L1L1", "L2L2"])
def test_certified_cost_is_never_above_alternating_least_squares(norm):
    """ALS from many starts (inside the camera box the certificate covers) never beats the
    certified lower bound, so the certified cost is within the gap of the best of them."""
    for seed in range(3):
        basis, points, *_ = scene(4, 15, 0.01, 10 + seed)
        fit = fit_frame(basis, points, BilinearOptions(norm=norm))
        assert fit.certified, fit.reason
        frame = problem.normalise(basis, points)
        model = Model(frame, norm, "convex", 10.0)
        lo = np.array(fit.camera_box[0]) / frame.camera_scale
        hi = np.array(fit.camera_box[1]) / frame.camera_scale
        rng = np.random.default_rng(seed)
        best = math.inf
        for _ in range(12):
            start = rng.dirichlet(np.ones(4))
            M, t = model.camera_step(start, lo, hi)
            M, a, t, value = model.als(M, start, t, 40, lo, hi)
            raw = problem.cost(problem.residuals(basis, points, problem.to_raw(frame, M, t), a), norm)
            assert raw >= fit.lower_bound * (1 - 1e-9)
            best = min(best, raw)
        assert fit.cost <= best + fit.tolerance


@pytest.mark.parametrize("norm", ["L1L1", "L2L2"])
def test_scip_optimum_lies_within_our_bounds(norm):
    """SCIP (spatial branch and bound, relative gap 1e-7) on the same problem over the same camera
    box: every point it finds costs at least our lower bound, and when it closes its gap its
    optimum lies in [lower_bound, cost]. (SCIP closes the L1 instance in seconds; on L2 it stops at
    its time limit with the optimum found, our cost to 1e-8, and its gap open.)"""
    pytest.importorskip("pyscipopt")
    from testing.bilinear import scip_bilinear

    basis, points, *_ = scene(3, 8, 0.005, 100)
    fit = fit_frame(basis, points, BilinearOptions(norm=norm, rel_gap=1e-4))
    assert fit.certified, fit.reason
    cost, dual, done = scip_bilinear(basis, points, norm, fit.camera_box[1][0], time_limit=30, gap=1e-7)
    assert cost >= fit.lower_bound * (1 - 1e-7)
    if done:
        assert fit.lower_bound * (1 - 1e-7) <= cost <= fit.cost * (1 + 1e-7)
        assert dual <= fit.cost * (1 + 1e-7)


def test_l1_resists_outliers():
    """Thesis 8.5.1 (figure 8.2): with 20% gross outliers the L1 fit recovers the shape far better
    than L2 and the linear baseline."""
    shape_errors = {"L1L1": [], "L2L2": [], "linear": []}
    for seed in range(3):
        basis, points, camera, alpha, clean = scene(3, 30, 0.002, 50 + seed, outliers=0.2)
        truth = problem.shape_of(basis, alpha)
        for norm in ("L1L1", "L2L2"):
            fit = fit_frame(basis, points, BilinearOptions(norm=norm))
            shape_errors[norm].append(np.sqrt(np.mean(np.sum((np.array(fit.shape) - truth) ** 2, axis=1))))
        b = np.array(fit.baseline["coefficients"])
        shape_errors["linear"].append(np.sqrt(np.mean(np.sum((problem.shape_of(basis, b) - truth) ** 2, axis=1))))
    l1 = np.median(shape_errors["L1L1"])
    assert l1 < 0.5 * np.median(shape_errors["L2L2"]) and l1 < 0.5 * np.median(shape_errors["linear"])


def job(basis, frames, **options) -> dict:
    return {"kind": "bilinear", "data": {"basis": basis, "frames": frames}, "options": options}


class TestBadInput:
    def setup_method(self):
        basis, points, *_ = scene(3, 10, 0.01, 1)
        self.basis, self.points = basis.tolist(), points.tolist()

    def field(self, data_job) -> str:
        with pytest.raises(InputError) as error:
            parse_job(data_job)
        return error.value.field

    def test_shapes_of_different_sizes(self):
        basis = copy.deepcopy(self.basis)
        basis[1] = basis[1][:-1]
        assert self.field(job(basis, [{"points": self.points}])) == "data/basis/1"

    def test_fewer_points_than_unknowns(self):
        points = [p if j < 4 else None for j, p in enumerate(self.points)]  # 8 equations, 10 unknowns
        assert self.field(job(self.basis, [{"points": points}])) == "data/frames/0/points"

    def test_frame_of_another_size(self):
        assert self.field(job(self.basis, [{"points": self.points[:-1]}])) == "data/frames/0/points"

    def test_equal_shapes(self):
        basis = copy.deepcopy(self.basis)
        basis[2] = basis[0]
        assert self.field(job(basis, [{"points": self.points}])) == "data/basis/2"

    def test_rank_deficient_basis(self):
        b = np.array(self.basis)
        basis = [b[0].tolist(), b[1].tolist(), (0.25 * b[0] + 0.75 * b[1]).tolist()]
        assert self.field(job(basis, [{"points": self.points}])) == "data/basis/2"

    def test_nan(self):
        basis = copy.deepcopy(self.basis)
        basis[0][2][1] = float("nan")
        assert self.field(job(basis, [{"points": self.points}])) == "data/basis/0/2/1"
        points = copy.deepcopy(self.points)
        points[4][0] = float("nan")
        assert self.field(job(self.basis, [{"points": points}])) == "data/frames/0/points/4/0"

    def test_bad_options(self):
        for options, name in (({"norm": "L2L1"}, "options/norm"), ({"coefficients": "free"}, "options/coefficients"),
                              ({"camera": "projective"}, "options/camera"), ({"camera_bound": -1.0}, "options/camera_bound")):
            assert self.field(job(self.basis, [{"points": self.points}], **options)) == name


@pytest.fixture(scope="module")
def certified_result():
    basis, points, *_ = scene(3, 12, 0.01, 4)
    frames = [{"points": points.tolist()}, {"points": [None if j == 2 else p for j, p in enumerate(points.tolist())]}]
    return solve_job(job(basis.tolist(), frames, norm="L1L1", certificate="full"))


def test_full_certificate_verifies(certified_result):
    result = certified_result
    assert all(frame["certified"] for frame in result["frames"])
    report = verify_any(result)
    assert report.valid, report.first_failure
    names = [check["name"] for check in report.checks]
    for name in ("objective", "scope", "tightening", "coverage", "leaf_bounds", "lower_bound", "returned"):
        assert name in names


def forged(result, change) -> dict:
    document = copy.deepcopy(result["certificate"])
    change(document["items"][0])
    return document


@pytest.mark.parametrize("change, check", [
    # the lower bound raised to the cost (gap 0), above what the proof's leaves prove
    (lambda item: item.__setitem__("lower_bound", item["cost"]) or item.__setitem__("gap", 0.0), "lower_bound"),
    (lambda item: item["coefficients"].__setitem__(0, item["coefficients"][0] + 1e-3), "objective"),
    (lambda item: item["proof"]["leaves"].pop(), "coverage"),
    # a wider camera box stated: the root's rounds no longer start from it (a narrower one is
    # refused before, at scope: it no longer holds the returned camera's default box)
    (lambda item: item["proof"]["camera_box"][0].__setitem__(0, item["proof"]["camera_box"][0][0] * 2),
     "tightening"),
    (lambda item: item["proof"]["camera_box"][0].__setitem__(0, item["proof"]["camera_box"][0][0] / 2), "scope"),
    (lambda item: item["proof"]["tightening"][0]["box_out"][0].__setitem__(
        0, item["proof"]["tightening"][0]["box_out"][0][0] + 1e-3), "tightening"),
])
def test_tampered_certificate_is_refused(certified_result, change, check):
    document = forged(certified_result, change)
    report = verify_any(document)
    assert not report.valid
    assert report.first_failure["check"] == check, report.first_failure


def test_a_node_tightening_side_moved_is_refused(certified_result):
    """A coefficient's side moved beyond what its dual vector proves, in a node tightening record."""
    records = [item["proof"]["node_tightening"] for item in certified_result["certificate"]["items"]]
    assert any(records), "the fixture's search tightened no node: nothing to tamper with"

    def change(item):
        record = item["proof"]["node_tightening"][0]
        lo_out, hi_out = record["box_out"]
        lo_out[6] = min(hi_out[6], lo_out[6] + 0.5 * (hi_out[6] - lo_out[6]) + 1e-6)
    index = next(i for i, r in enumerate(records) if r)
    document = copy.deepcopy(certified_result["certificate"])
    change(document["items"][index])
    report = verify_any(document)
    assert not report.valid and report.first_failure["check"] == "tightening", report.first_failure
    assert "beyond the proven" in report.first_failure["detail"], report.first_failure


def test_a_dual_vector_changed_is_refused(certified_result):
    from geocert.core.certificates import pack, unpack

    def change(item):
        for record in item["proof"]["proofs"]:
            if record["kind"] == "dual":
                z = unpack(record["z"])
                record["z"] = pack(z * 0.5)
    report = verify_any(forged(certified_result, change))
    assert not report.valid and report.first_failure["check"] in ("leaf_bounds", "lower_bound")


def test_geocert_verify_checks_it_without_a_conic_solver(certified_result, tmp_path):
    """`geocert verify` accepts the result (exit 0) and refuses a forged one (exit 1); the check
    imports no conic solver."""
    import json
    import subprocess
    import sys

    good = tmp_path / "result.json"
    good.write_text(json.dumps(certified_result))
    run = subprocess.run([sys.executable, "-m", "geocert.app.cli", "verify", str(good)], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    bad = copy.deepcopy(certified_result["certificate"])
    bad["items"][1]["proof"]["leaves"].pop(0)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(bad))
    assert subprocess.run([sys.executable, "-m", "geocert.app.cli", "verify", str(path)],
                          capture_output=True, text=True).returncode == 1
    code = ("import json, sys; from geocert.verify.checks import verify_any; "
            f"valid = verify_any(json.load(open({str(good)!r}))).valid; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('clarabel', 'cvxpy', 'pyscipopt')]; "
            "print(json.dumps([valid, bad]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [True, []]


def test_affine_coefficients_and_a_given_camera_box_verify():
    """Affine coefficients (sum 1, |alpha_i| <= coefficient_bound) and a scope box given by
    camera_bound: certified, the box as asked, verified; a claim that the box was smaller than
    camera_bound's is refused."""
    basis, points, *_ = scene(3, 12, 0.01, 6)
    result = solve_job(job(basis.tolist(), [{"points": points.tolist()}], coefficients="affine",
                           coefficient_bound=5.0, camera_bound=400.0, certificate="full"))
    frame = result["frames"][0]
    assert frame["certified"] and sum(frame["coefficients"]) == pytest.approx(1.0, abs=1e-12)
    assert frame["certificate"]["root_region"]["camera_upper"] == [[400.0] * 3] * 2
    assert verify_any(result).valid
    document = copy.deepcopy(result["certificate"])
    document["items"][0]["proof"]["camera_box"][1][0] = 200.0
    report = verify_any(document)
    assert not report.valid and report.first_failure["check"] == "scope"


def test_root_rounds_alternate_camera_and_coefficients(certified_result):
    """The root's tightening rounds are half rounds: the camera's entries, then the coefficients',
    alternately, each record with null duals for the half it leaves alone (and that half's sides
    unmoved)."""
    K = 3
    for item in certified_result["certificate"]["items"]:
        rounds = item["proof"]["tightening"]
        assert len(rounds) >= 2
        for number, record in enumerate(rounds):
            duals = record["duals"]
            camera, coefficients = duals[:12], duals[12:]
            idle = coefficients if number % 2 == 0 else camera
            assert all(z is None for z in idle), f"round {number} solved for both halves"
            assert any(z is not None for z in (camera if number % 2 == 0 else coefficients))
            (lo_in, hi_in), (lo_out, hi_out) = record["box_in"], record["box_out"]
            half = slice(6, 6 + K) if number % 2 == 0 else slice(0, 6)
            assert lo_out[half] == lo_in[half] and hi_out[half] == hi_in[half]


def test_a_side_moved_without_its_dual_is_refused(certified_result):
    """A half round's record leaves the other half's duals null: a side of that half moved anyway
    (with nothing proving it) is refused."""
    document = copy.deepcopy(certified_result["certificate"])
    record = document["items"][0]["proof"]["tightening"][0]  # the camera's half: coefficients' duals null
    lo_out, hi_out = record["box_out"]
    lo_out[6] = 0.5 * (lo_out[6] + hi_out[6])
    report = verify_any(document)
    assert not report.valid and report.first_failure["check"] == "tightening", report.first_failure
    assert "beyond the proven" in report.first_failure["detail"], report.first_failure


def test_root_incumbent_past_its_deadline_takes_one_step(monkeypatch):
    """Past its deadline the incumbent's search makes the one camera step an incumbent needs and
    nothing more (no further start, no alternating step, no L1 polish); before it, many."""
    from geocert.solvers.bilinear import search

    basis, points, *_ = scene(10, 30, 0.005, 0)
    frame = problem.normalise(basis, points)
    for norm in ("L2L2", "L1L1"):
        model = Model(frame, norm, "convex", 10.0)
        calls = {"camera": 0, "alpha": 0}
        camera_step, alpha_step = Model.camera_step, Model.alpha_step

        def counted_camera(self, *args):
            calls["camera"] += 1
            return camera_step(self, *args)

        def counted_alpha(self, *args):
            calls["alpha"] += 1
            return alpha_step(self, *args)
        monkeypatch.setattr(Model, "camera_step", counted_camera)
        monkeypatch.setattr(Model, "alpha_step", counted_alpha)
        M, alpha, t, value = search.root_incumbent(model, deadline=-math.inf)
        assert calls == {"camera": 1, "alpha": 0}
        assert value == pytest.approx(model.cost(M, alpha, t), rel=1e-12)  # the cost in the model's own norm
        search.root_incumbent(model)
        assert calls["camera"] > 6 and calls["alpha"] > 6
        monkeypatch.undo()


def test_a_frame_past_its_time_limit_stops_every_step():
    """With a time limit already spent, no tightening solve starts (the root's first half round
    records null duals only) and the search stops at its root: time_limit, not certified."""
    basis, points, *_ = scene(20, 50, 0.005, 0)
    fit = fit_frame(basis, points, BilinearOptions(norm="L2L2", time_limit_s=1e-6, certificate="full"))
    assert fit.status == "time_limit" and not fit.certified and fit.nodes <= 1
    import geocert.solvers.bilinear.search as search
    relaxation = Relaxation(*(lambda f: (f.X, f.u))(problem.normalise(basis, points)), "L2L2", "convex", 10.0)
    lo, hi, _, _, rounds = search.tighten(relaxation, np.full(6, -8.0), np.full(6, 8.0), 1.0, deadline=-math.inf)
    assert len(rounds) == 1 and all(z is None for z in rounds[0]["duals"])
    assert np.array_equal(lo, np.full(6, -8.0)) and np.array_equal(hi, np.full(6, 8.0))


def test_the_cost_cap_row_is_inserted_where_stacking_puts_it():
    """relaxation.insert_row (the cost cap's row, built without vstack) gives exactly the matrix
    of stacking the rows above, the new row and the rows below, on random sparse matrices and on
    both norms' relaxations (the verifier rebuilds the same program through it)."""
    import scipy.sparse as sp

    from geocert.formulations.bilinear.relaxation import insert_row, with_cost_cap

    def stacked(A, at, columns):
        row = np.zeros(A.shape[1])
        row[columns] = 1.0
        return sp.vstack([A[:at], sp.csr_matrix(row), A[at:]]).tocsc()
    rng = np.random.default_rng(0)
    for trial in range(200):
        n, m = rng.integers(1, 12, 2)
        A = sp.random(n, m, density=rng.uniform(0, 1), random_state=trial, format="csc")
        at = int(rng.integers(0, n + 1))
        columns = np.flatnonzero(rng.uniform(size=m) < 0.5)
        got = insert_row(A, at, columns)
        got.check_format()
        for c in range(m):  # rows sorted within each column, as a solver reading raw CSC expects
            assert np.all(np.diff(got.indices[got.indptr[c]:got.indptr[c + 1]]) > 0), trial
        assert np.array_equal(got.toarray(), stacked(A, at, columns).toarray()), trial
    basis, points, *_ = scene(4, 15, 0.01, 1)
    frame = problem.normalise(basis, points)
    for norm in ("L1L1", "L2L2"):
        relaxation = Relaxation(frame.X, frame.u, norm, "convex", 10.0)
        data = relaxation.conic_data(np.full(6, -4.0), np.full(6, 4.0), 10.0)
        capped = with_cost_cap(relaxation, data, 10.0)
        at = data.cones.zero + data.cones.nonneg
        expected = stacked(data.A, at, np.arange(relaxation.ie, relaxation.nvar))
        assert np.array_equal(capped.A.toarray(), expected.toarray())


def test_the_basis_rank_check_is_one_decomposition_and_a_bisection(monkeypatch):
    """One singular value decomposition per shape cost K^3 N (100 s of the API's time for 300
    shapes of 400 points): a good basis takes one, a degenerate one a bisection, which still
    names the first shape that depends on those before it."""
    from geocert.formulations.bilinear import problem

    calls = []
    svd = np.linalg.svd
    monkeypatch.setattr(problem.np.linalg, "svd", lambda *a, **k: calls.append(1) or svd(*a, **k))
    basis = np.random.default_rng(0).normal(size=(64, 30, 3))
    problem.read_basis(basis.tolist())
    assert len(calls) == 1
    basis[41] = 0.25 * basis[3] + 0.75 * basis[17]
    calls.clear()
    with pytest.raises(InputError) as caught:
        problem.read_basis(basis.tolist())
    assert caught.value.field == "data/basis/41" and len(calls) <= 8


def test_a_camera_beyond_its_incumbents_box_is_searched_again(monkeypatch):
    """With camera_bound null the proof's box must hold the default box of the camera returned
    (problem.default_half_width, which the verifier asks for). An incumbent an eighth of the
    optimum's size gives a box the optimum lies outside: the search's camera then asks a wider
    box, the solver searches that one, and the frame is certified over a box the verifier
    accepts."""
    from geocert.solvers.bilinear import search

    basis, points, *_ = scene(3, 12, 0.01, 4)
    found = search.root_incumbent

    def small(model, *args, **kwargs):
        M, alpha, t, _ = found(model, *args, **kwargs)
        M = M / 8
        t = model.best_t(M, alpha)
        return M, alpha, t, model.cost(M, alpha, t)
    monkeypatch.setattr(search, "root_incumbent", small)
    searched = []
    original = search._search

    def counted(model, relaxation, frame, options, incumbent, half, *rest):
        searched.append(half)
        return original(model, relaxation, frame, options, incumbent, half, *rest)
    monkeypatch.setattr(search, "_search", counted)
    result = solve_job(job(basis.tolist(), [{"points": points.tolist()}], certificate="full"))
    frame = problem.normalise(basis, points)
    M = np.asarray(result["frames"][0]["camera"])[:, :3] / frame.camera_scale
    assert len(searched) >= 2 and searched[-1] >= problem.default_half_width(M) > searched[0]
    assert result["frames"][0]["certified"]
    report = verify_any(result)
    assert report.valid, report.first_failure
