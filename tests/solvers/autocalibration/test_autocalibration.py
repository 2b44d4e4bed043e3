"""Stratified autocalibration's solver pieces (geocert.solvers.autocalibration): frames, the
modulus constraints, the two relaxations' under-estimation, and exact recovery without noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geocert.solvers.autocalibration import metric, scenes
from geocert.formulations.autocalibration import affine_relaxation, frames, metric_relaxation
from geocert.solvers.autocalibration import affine
from geocert.core.bnb import BnbOptions, Box
from geocert.core.conic import ConicStatus, solve_conic
from geocert.core.cones import safe_lower_bound

K0 = np.array([[1000.0, 0.0, 500.0], [0.0, 1000.0, 500.0], [0.0, 0.0, 1.0]])
RANGES = {"focal": [0.3, 5.0], "aspect": [0.9, 1.1], "skew": [-0.01, 0.01], "u": [-0.25, 0.25], "v": [-0.25, 0.25]}


def normalised_scene(views: int, noise: float, seed: int):
    scene = scenes.make_scene(views, noise, seed=seed)
    return scene, frames.normalise(scene.cameras, scene.points, np.linalg.inv(K0))


def true_plane(scene, norm) -> np.ndarray:
    plane = norm.T0.T @ scene.plane_at_infinity
    return plane[:3] / plane[3]


class TestSignedCentre:
    def test_orientation_and_null_vector(self):
        rng = np.random.default_rng(0)
        for _ in range(20):
            M, C = rng.normal(size=(3, 3)), rng.normal(size=3)
            P = M @ np.hstack([np.eye(3), -C[:, None]])
            c = frames.signed_centre(P)
            assert np.allclose(P @ c, 0, atol=1e-12)
            assert c[3] == pytest.approx(np.linalg.det(M))
            assert np.allclose(c[:3] / c[3], C)


class TestModulusConstraints:
    @pytest.mark.parametrize("seed", [0, 1, 2])
    def test_zero_at_the_true_plane_only(self, seed):
        scene, norm = normalised_scene(6, 0.0, seed)
        coef, views = frames.modulus_coefficients(norm.cameras, norm.reference)
        p = true_plane(scene, norm)
        assert len(views) == 5
        assert np.abs(frames.modulus_residuals(coef, p)).max() < 1e-9
        assert np.abs(frames.modulus_residuals(coef, p * 1.01)).max() > 1e-6


class TestChiralityBox:
    def test_the_true_plane_is_inside_the_proved_box(self):
        scene, norm = normalised_scene(8, 0.0, 3)
        coef, _ = frames.modulus_coefficients(norm.cameras, norm.reference)
        regions, excluded, reason = affine.regions_of(norm, coef)
        assert reason is None and len(regions) + len(excluded) == 2
        plane = norm.T0.T @ scene.plane_at_infinity
        inside = []
        for region in regions:
            v = np.linalg.solve(region.setup.M, plane)
            v = v[:3] / v[3]
            inside.append(bool(np.all(v >= region.lo) and np.all(v <= region.hi)))
            for side, rows in enumerate(region.basis):  # each side re-proved exactly
                rows_all = frames.chirality_rows(norm, region.delta)
                a, b = frames.frame_rows(region.G, rows_all)
                bound = frames.exact_side(a, b, side // 2, side % 2 == 1, rows)
                assert bound is not None
                assert (bound <= region.lo[side // 2]) if side % 2 == 0 else (bound >= region.hi[side // 2])
        assert any(inside)
        for item in excluded:
            assert frames.exact_gordan(frames.chirality_rows(norm, item["delta"]), item["rows"])

    def test_a_wrong_basis_proves_nothing(self):
        a = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [-1.0, -1.0, -1.0]])
        b = np.ones(4)
        assert frames.exact_side(a, b, 0, False, [0, 1, 2]) == -1.0  # row 0: v0 + 1 >= 0
        assert frames.exact_side(a, b, 0, True, [0, 1, 2]) is None  # these rows bound v0 from below only
        assert frames.exact_side(a, b, 0, True, [1, 2, 3]) == 3.0  # rows 1-3: v0 <= 1 + 1 + 1

    def test_gordan_refuses_a_feasible_set(self):
        rows = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0], [1.0, 1.0, 1.0, 1.0]])
        assert not frames.exact_gordan(rows, [0, 1, 2, 3, 4])
        rows[4] = -rows[4]
        assert frames.exact_gordan(rows, [0, 1, 2, 3, 4])


def relaxation_bound(program) -> float:
    result = solve_conic(program.q, program.A, program.b, program.cones)
    assert result.status is ConicStatus.OPTIMAL, result.raw_status
    return safe_lower_bound(program.q, program.A, program.b, program.cones, result.z, program.lower, program.upper)


class TestAffineRelaxationUnderestimates:
    @pytest.mark.parametrize("seed", [4, 5])
    def test_every_domain_point_of_a_box_costs_at_least_its_bound(self, seed):
        scene, norm = normalised_scene(6, 0.2, seed)
        coef, _ = frames.modulus_coefficients(norm.cameras, norm.reference)
        regions, _, _ = affine.regions_of(norm, coef)
        region = regions[0]
        rows = frames.chirality_rows(norm, region.delta)
        a, b = frames.frame_rows(region.G, rows)
        rng = np.random.default_rng(seed)
        checked = 0
        for _ in range(120):
            centre = rng.uniform(region.lo, region.hi)
            if not np.all(a @ centre + b >= 0):
                continue
            half = rng.uniform(0.001, 0.2) * (region.hi - region.lo)
            lo, hi = np.maximum(centre - half, region.lo), np.minimum(centre + half, region.hi)
            points = rng.uniform(lo, hi, size=(30, 3))
            points = points[np.all(points @ a.T + b >= 0, axis=1)]
            costs = [affine_relaxation.cost(region.setup, v) for v in points]
            cap = max(costs) if costs else 1.0
            program = affine_relaxation.build(region.setup, lo, hi, cap)
            if program is None or not costs:
                continue
            assert relaxation_bound(program) <= min(costs) * (1 + 1e-7) + 1e-12
            checked += 1
            if checked == 12:
                break
        assert checked == 12


class TestMetricRelaxationUnderestimates:
    def test_every_domain_point_of_a_box_costs_at_least_its_bound(self):
        scene, norm = normalised_scene(6, 0.2, 6)
        p = true_plane(scene, norm)
        setup = metric.setup_for(norm.cameras, norm.reference, p, RANGES)
        root_lo, root_hi = metric_relaxation.omega_box(RANGES)
        rng = np.random.default_rng(6)
        checked = 0
        for _ in range(200):
            K = np.array([[rng.uniform(0.5, 2), rng.uniform(-0.01, 0.01), rng.uniform(-0.25, 0.25)],
                          [0, 0, rng.uniform(-0.25, 0.25)], [0, 0, 1.0]])
            K[1, 1] = K[0, 0] * rng.uniform(0.9, 1.1)
            omega = K @ K.T
            w = np.array([omega[a, b] for a, b in metric_relaxation.ENTRIES])
            half = rng.uniform(0.001, 0.3) * (root_hi - root_lo)
            lo, hi = np.maximum(w - rng.uniform(0, 1, 5) * half, root_lo), np.minimum(w + half, root_hi)
            if not metric_relaxation.in_domain(setup, w, root_lo, root_hi):
                continue
            value = metric_relaxation.cost(setup, w)
            program = metric_relaxation.build(setup, lo, hi, value * 2 + 1e-9)
            assert program is not None
            assert relaxation_bound(program) <= value * (1 + 1e-7) + 1e-12
            checked += 1
            if checked == 15:
                break
        assert checked == 15


def lifted_point(setup, w: np.ndarray, cost: float, n: int) -> np.ndarray:
    """The relaxation's variables at a true omega: w, r, then per view lambda = 1 / q and
    nu = lambda omega, then the domain's lifted terms u^2, v^2, u v, skew^2."""
    x = np.zeros(n)
    x[:5], x[5] = w, cost * setup.unit
    omega = metric_relaxation.omega_of(w)
    for j, H in enumerate(setup.H):
        lam = 1.0 / (H[2] @ omega @ H[2])
        x[6 + 6 * j] = lam
        x[7 + 6 * j:12 + 6 * j] = lam * w
    k = metric_relaxation.intrinsics_of(w)
    u, v = w[2], w[4]
    x[-4:] = [u * u, v * v, u * v, k["skew"] ** 2]
    return x


def in_cones(program, x: np.ndarray, tol: float = 1e-9) -> bool:
    s = program.b - program.A @ x
    c = program.cones
    scale = tol * (1 + np.abs(program.A) @ np.abs(x) + np.abs(program.b))
    if np.any(np.abs(s[:c.zero]) > scale[:c.zero]):
        return False
    start = c.zero
    if np.any(s[start:start + c.nonneg] < -scale[start:start + c.nonneg]):
        return False
    start += c.nonneg
    for size in c.soc:
        block = s[start:start + size]
        if block[0] < np.linalg.norm(block[1:]) - scale[start:start + size].max():
            return False
        start += size
    for size in c.psd:
        from geocert.core.cones import smat
        rows = size * (size + 1) // 2
        if np.linalg.eigvalsh(smat(s[start:start + rows], size))[0] < -scale[start:start + rows].max():
            return False
        start += rows
    return bool(np.all(x >= program.lower - 1e-12 * np.abs(x)) and np.all(x <= program.upper + 1e-12 * np.abs(x)))


class TestMetricDomainRows:
    """The intrinsics ranges inside the metric relaxation (metric_relaxation.domain_rows): every
    calibration within the ranges, the extreme ones above all (skew, aspect and focal at their
    limits, where a noisy optimum sits), is a feasible point of the relaxation of any box around
    it, with its true lifted terms."""

    @pytest.mark.parametrize("seed", [0, 1, 2])
    def test_calibrations_on_the_ranges_edges_are_feasible(self, seed):
        scene, norm = normalised_scene(6, 0.2, seed)
        setup = metric.setup_for(norm.cameras, norm.reference, true_plane(scene, norm), RANGES)
        root_lo, root_hi = metric_relaxation.omega_box(RANGES)
        rng = np.random.default_rng(seed)
        checked = bounded = 0
        for _ in range(100):
            pick = lambda name: RANGES[name][rng.integers(2)] if rng.random() < 0.6 else rng.uniform(*RANGES[name])  # noqa: E731
            f, aspect, skew, u, v = (pick(name) for name in ("focal", "aspect", "skew", "u", "v"))
            K = np.array([[f, skew, u], [0.0, f * aspect, v], [0.0, 0.0, 1.0]])
            omega = K @ K.T
            w = np.array([omega[a, b] for a, b in metric_relaxation.ENTRIES])
            if not metric_relaxation.in_domain(setup, w, root_lo, root_hi):
                continue
            half = rng.uniform(1e-4, 0.3) * (root_hi - root_lo)
            lo = np.maximum(w - rng.uniform(0, 1, 5) * half, root_lo)
            hi = np.minimum(w + rng.uniform(0, 1, 5) * half, root_hi)
            value = metric_relaxation.cost(setup, w)
            setup.unit = 1.0 / value  # as the search sets it: the incumbent's cost is about 1
            program = metric_relaxation.build(setup, lo, hi, value * 2 + 1e-9)
            assert program is not None
            assert in_cones(program, lifted_point(setup, w, value, len(program.q))), (f, aspect, skew, u, v)
            checked += 1
            result = solve_conic(program.q, program.A, program.b, program.cones)
            if result.status is ConicStatus.OPTIMAL:
                bound = safe_lower_bound(program.q, program.A, program.b, program.cones, result.z, program.lower,
                                         program.upper) / setup.unit
                assert bound <= value * (1 + 1e-7) + 1e-12
                bounded += 1
        assert checked >= 40 and bounded >= 30

    def test_they_close_a_gap_the_ranges_edge_left_open(self):
        """10 views, 1% noise: the optimum's skew sits on its limit. Without the rows the search
        ran 4611 nodes in 60 s to a 3e-4 gap; with them it certifies 1e-4."""
        scene, norm = normalised_scene(10, 1.0, 0)
        stage = affine.solve_affine(norm, BnbOptions(rel_gap=1e-5, time_limit_s=60), False)
        setup = metric.setup_for(norm.cameras, norm.reference, stage.plane[:3], RANGES)
        lo, hi = metric_relaxation.omega_box(RANGES)
        result = metric.solve_metric(setup, lo, hi, BnbOptions(rel_gap=1e-4, max_nodes=400), False)
        assert result.certified
        k = metric_relaxation.intrinsics_of(result.w)
        assert min(abs(k["skew"] - RANGES["skew"][0]), abs(k["skew"] - RANGES["skew"][1])) < 1e-9


class TestNoiseFreeRecovery:
    @pytest.mark.parametrize("views", [10, 20])
    def test_exact_plane_and_calibration_certified(self, views):
        scene, norm = normalised_scene(views, 0.0, 7)
        options = BnbOptions(rel_gap=1e-5, abs_gap=1e-12, max_nodes=200, time_limit_s=30)
        stage = affine.solve_affine(norm, options, record=False)
        assert stage.certified and stage.status == "optimal"
        p = true_plane(scene, norm)
        assert np.linalg.norm(stage.plane[:3] - p) <= 1e-7 * np.linalg.norm(p)
        setup = metric.setup_for(norm.cameras, norm.reference, stage.plane[:3], RANGES)
        lo, hi = metric_relaxation.omega_box(RANGES)
        result = metric.solve_metric(setup, lo, hi, BnbOptions(rel_gap=1e-4, abs_gap=1e-12, max_nodes=200), False)
        assert result.certified
        assert np.allclose(result.w, [1, 0, 0, 1, 0], atol=1e-7)  # K = K0 exactly: omega = I after preconditioning
        assert np.linalg.eigvalsh(metric_relaxation.omega_of(result.w))[0] >= 0
        baseline, psd = metric.linear_baseline(setup)
        assert psd and np.allclose(baseline, [1, 0, 0, 1, 0], atol=1e-7)


class TestRangePruning:
    """metric_relaxation.may_meet_ranges prunes boxes of omega with no K in the ranges: it must
    never prune a box holding an in-range K (property), and it must prune most boxes far from one."""

    def test_never_prunes_a_box_around_an_in_range_calibration(self):
        rng = np.random.default_rng(8)
        root_lo, root_hi = metric_relaxation.omega_box(RANGES)
        for _ in range(3000):
            point = {name: rng.uniform(*RANGES[name]) for name in ("focal", "aspect", "skew", "u", "v")}
            w = metric_relaxation.w_of_intrinsics(point)
            k = metric_relaxation.intrinsics_of(w)
            assert metric_relaxation.in_ranges(RANGES, k)
            half = rng.uniform(0, 0.1) * (root_hi - root_lo)
            lo, hi = w - rng.uniform(0, 1, 5) * half, w + rng.uniform(0, 1, 5) * half
            assert metric_relaxation.may_meet_ranges(RANGES, lo, hi)
            assert metric_relaxation.may_meet_ranges(RANGES, w, w)  # a box of one point

    def test_prunes_boxes_far_from_every_calibration(self):
        rng = np.random.default_rng(9)
        root_lo, root_hi = metric_relaxation.omega_box(RANGES)
        pruned = 0
        for _ in range(500):
            centre = rng.uniform(root_lo, root_hi)
            half = 0.01 * (root_hi - root_lo)
            pruned += not metric_relaxation.may_meet_ranges(RANGES, centre - half, centre + half)
        assert pruned > 300


@pytest.fixture(scope="module")
def node_tightened():
    scene, norm = normalised_scene(10, 0.5, 1)
    ranges = {"focal": [0.3, 5.0], "aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "u": [-0.25, 0.25],
              "v": [-0.25, 0.25]}
    stage = affine.solve_affine(norm, BnbOptions(rel_gap=1e-5, abs_gap=1e-12), record=False)
    setup = metric.setup_for(norm.cameras, norm.reference, stage.plane[:3], ranges)
    lo, hi = metric_relaxation.omega_box(ranges)
    result = metric.solve_metric(setup, lo, hi, BnbOptions(rel_gap=1e-4, abs_gap=1e-12, max_nodes=3000), True)
    return setup, result


class TestNodeTightening:
    """Before a box is split it is tightened; the slabs cut off are leaves closed by their cut.
    No point of a slab (off its inner face) may cost at most the cut's cap, and the verifier must
    refuse a leaf moved past its cut."""

    def test_cut_slabs_hold_no_point_costing_at_most_their_cap(self, node_tightened):
        setup, result = node_tightened
        assert result.certified
        cuts = [(box, proof) for box, proof in result.leaves if isinstance(proof, metric.CutProof)]
        assert len(cuts) > 10
        rng = np.random.default_rng(3)
        checked = 0
        for box, proof in cuts[:40]:
            for w in rng.uniform(box.lo, box.hi, size=(20, 5)):
                if metric_relaxation.in_domain(setup, w, result.lo, result.hi):
                    assert metric_relaxation.cost(setup, w) > proof.upper_bound
                    checked += 1
        assert checked > 0

    def test_the_lower_bound_is_below_every_sampled_cost(self, node_tightened):
        setup, result = node_tightened
        rng = np.random.default_rng(4)
        for box, _ in result.leaves[:200]:
            for w in rng.uniform(box.lo, box.hi, size=(5, 5)):
                if metric_relaxation.in_domain(setup, w, result.lo, result.hi):
                    assert metric_relaxation.cost(setup, w) >= result.lower_bound * (1 - 1e-9)

    def test_a_certificate_with_cuts_verifies_and_a_leaf_past_its_cut_is_refused(self):
        import copy

        from geocert.jobs.runner import solve_job
        from geocert.verify.checks import verify_any

        scene = scenes.make_scene(10, 0.5, seed=1)
        result = solve_job({"kind": "autocalibration", "data": scene.job_data(), "options": {"certificate": "full"}})
        proof = result["certificate"]["items"][1]["proof"]
        cut_leaves = [leaf for leaf in proof["leaves"] if leaf[2] is not None and proof["proofs"][leaf[2]]["kind"] == "cut"]
        assert result["stages"][1]["certified"] and cut_leaves
        report = verify_any(result)
        assert report.valid, report.first_failure
        forged = copy.deepcopy(result)
        proof = forged["certificate"]["items"][1]["proof"]
        leaf = next(leaf for leaf in proof["leaves"] if leaf[2] is not None and proof["proofs"][leaf[2]]["kind"] == "cut")
        cut = proof["proofs"][leaf[2]]
        if cut["sign"] > 0:
            leaf[1][cut["axis"]] += 1e-3
        else:
            leaf[0][cut["axis"]] -= 1e-3
        assert verify_any(forged).first_failure["check"] == "leaf_bounds"


    def test_the_affine_stage_cuts_too_and_its_cuts_are_checked(self):
        import copy

        from geocert.jobs.runner import solve_job
        from geocert.verify.checks import verify_any

        scene = scenes.make_scene(20, 0.1, seed=20000)
        result = solve_job({"kind": "autocalibration", "data": scene.job_data(), "options": {"certificate": "full"}})
        assert verify_any(result).valid
        forged = copy.deepcopy(result)
        region = forged["certificate"]["items"][0]["proof"]["regions"][0]
        leaf = next(leaf for leaf in region["leaves"]
                    if leaf[2] is not None and region["proofs"][leaf[2]]["kind"] == "cut")
        cut = region["proofs"][leaf[2]]
        if cut["sign"] > 0:
            leaf[1][cut["axis"]] += 1e-3
        else:
            leaf[0][cut["axis"]] -= 1e-3
        assert verify_any(forged).first_failure["check"] == "leaf_bounds"


class TestUncleanSolvesStillBound:
    """A solve that stops with NumericalError or AlmostSolved still returns a dual iterate, and the
    safe bound holds for any dual vector: the box is bounded by it instead of keeping its parent's
    bound. At 10 views and 0.1% noise (seed 10016) Clarabel stops that way on boxes whose optimum
    is about 7e4 times the incumbent's cost; with only clean solves used, the affine bound stayed 0
    over 5,400 nodes."""

    def test_the_scene_that_stalled_certifies_and_verifies(self):
        from geocert.jobs.runner import solve_job
        from geocert.verify.checks import verify_any

        scene = scenes.make_scene(10, 0.1, seed=10016)
        result = solve_job({"kind": "autocalibration", "data": scene.job_data(),
                            "options": {"certificate": "full", "max_nodes": 3000}})
        affine_stage, metric_stage = result["stages"]
        assert affine_stage["certified"] and affine_stage["status"] == "optimal"
        assert affine_stage["lower_bound"] > 0.99 * affine_stage["cost"] > 0
        assert metric_stage["certified"]
        report = verify_any(result)
        assert report.valid, report.first_failure

    def test_an_unclean_solves_dual_bounds_every_sampled_point(self):
        from geocert.core import conic

        scene, norm = normalised_scene(10, 0.1, 10016)
        coef, _ = frames.modulus_coefficients(norm.cameras, norm.reference)
        regions, _, _ = affine.regions_of(norm, coef)
        region = regions[0]
        region.setup.unit = 1.0 / 1.6e-5  # as the search scales it (the incumbent's cost about 1)
        rows_a, rows_b = frames.frame_rows(region.G, frames.chirality_rows(norm, region.delta))
        rng = np.random.default_rng(0)
        unclean = 0
        for _ in range(40):
            centre = rng.uniform(region.lo, region.hi)
            half = rng.uniform(0.02, 0.3) * (region.hi - region.lo)
            lo, hi = np.maximum(centre - half, region.lo), np.minimum(centre + half, region.hi)
            program = affine_relaxation.build(region.setup, lo, hi, 1e300)
            if program is None:
                continue
            result = conic.solve_conic(program.q, program.A, program.b, program.cones)
            if result.status is ConicStatus.OPTIMAL or result.z is None:
                continue
            unclean += 1
            # The iterate as returned, and the same spoiled further (what "any dual vector" claims).
            spoiled = result.z * rng.uniform(0.5, 1.5, size=result.z.shape)
            bounds = [safe_lower_bound(program.q, program.A, program.b, program.cones, z,
                                       program.lower, program.upper) / region.setup.unit for z in (result.z, spoiled)]
            for v in rng.uniform(lo, hi, size=(200, 3)):
                value = affine_relaxation.cost(region.setup, v)
                if math.isfinite(value) and np.all(rows_a @ v + rows_b >= 0):  # a plane of the domain
                    assert value >= max(bounds) * (1 - 1e-9)
        assert unclean > 0  # the case this class is about occurred


def test_the_metric_stage_tightening_stops_at_a_cancel_or_its_time_limit():
    """With many views one tightening round is ten conic programs of seconds each, and the rounds
    ran before the search looked at the clock (a 60-view metric stage took 12 s with a limit of 2
    s): a cancel seen at the stage's first check now stops it before any program."""
    from geocert.formulations.autocalibration import problem as autocalibration_problem
    from geocert.solvers.autocalibration import stratified
    from geocert.verify.autocalibration import read_data

    cameras, points, image_size = read_data(scenes.make_scene(6, 0.1, seed=5).job_data())
    options = autocalibration_problem.AutocalibrationOptions(time_limit_s=60)
    metric_calls = []

    def cancel_in_the_metric_stage(progress):
        if getattr(progress, "stage", None) == "metric":
            metric_calls.append(progress)
            return len(metric_calls) > 1  # the stage's announcement passes; its first check cancels
        return False

    result = stratified.solve(autocalibration_problem.prepare(cameras, points, image_size, options.intrinsics), options,
                              cancel_in_the_metric_stage)
    assert result.metric.status == "cancelled" and result.metric.rounds == []


class TestSplitClock:
    """A box's tightening before its split is ten programs (each entry of omega minimised and
    maximised); with many views each takes a tenth of a second or more, and the engine reads its
    clock only between boxes. Past the stage's deadline a split halves the box untightened."""

    def _problem(self):
        scene, norm = normalised_scene(6, 0.5, 1)
        setup = metric.setup_for(norm.cameras, norm.reference, true_plane(scene, norm), RANGES)
        lo, hi = metric_relaxation.omega_box(RANGES)
        problem = metric.MetricProblem(setup, lo, hi, record=False)
        w, value = problem.improve(0.5 * (lo + hi))
        setup.unit = 1.0 / value
        problem.upper = value
        return problem, Box(lo.copy(), hi.copy())

    def test_a_split_before_its_deadline_tightens(self):
        problem, box = self._problem()
        children = problem.split(box, None)
        assert len(children) > 2 or not np.allclose(
            np.min([c.lo for c in children], axis=0), box.lo) or not np.allclose(
            np.max([c.hi for c in children], axis=0), box.hi)

    def test_a_split_past_its_deadline_only_halves(self):
        problem, box = self._problem()
        problem.deadline = 0.0
        children = problem.split(box, None)
        assert len(children) == 2
        assert np.allclose(np.min([c.lo for c in children], axis=0), box.lo)
        assert np.allclose(np.max([c.hi for c in children], axis=0), box.hi)
