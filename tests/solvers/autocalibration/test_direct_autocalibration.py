"""Direct autocalibration (thesis chapter 7, geocert.formulations.autocalibration.direct*): the moment
machinery against brute-force expansion, the safe bound's soundness for any dual vector, exact
recovery, the certified optimum against many-start local minimisation, and the verifier refusing
tampered certificates."""

from __future__ import annotations

import copy
from types import SimpleNamespace

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import direct_solve, scenes
from geocert.formulations.autocalibration import direct
from geocert.core import interior_point
from geocert.formulations.autocalibration import direct_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.core.certificates import pack, unpack
from geocert.core.cones import smat
from geocert.verify.checks import verify_any

UNIT = {"aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "principal_point": [[-0.1, 0.1], [-0.1, 0.1]]}


def table71(seed: int, noise: float, varying: bool = False):
    scene, Ks = scenes.table71_scene(seed, noise, varying)
    intrinsics = {**UNIT, "focal": [0.05, 1.0] if varying else [0.5, 2.0]}
    return scene, Ks, {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()}, intrinsics


def random_feasible(rng: np.random.Generator) -> np.ndarray:
    """A random PSD rank-3 Q of trace 1."""
    B = rng.normal(size=(4, 3))
    Q = B @ B.T
    return Q / np.trace(Q)


def setup_of(scene, intrinsics, chirality="none"):
    problem = autocalibration_problem.prepare(scene.cameras, scene.points, None, intrinsics, unit_reference=False)
    return direct.setup_for(problem, chirality)


# --- the moment machinery ---------------------------------------------------------------------

class TestMoments:
    def test_every_block_is_its_polynomial_matrix_at_a_point(self):
        rng = np.random.default_rng(0)
        scene, _, _, intrinsics = table71(1, 0.0)
        setup = setup_of(scene, intrinsics, "centers")
        orientation = setup.orientations[0]
        program = direct_relaxation.build(setup.cameras, orientation.pairs, 2)
        for _ in range(5):
            Q = random_feasible(rng)
            x = direct_relaxation.x_of(Q)
            y = program.moments.vector(x)
            s = program.b - program.A @ y[1:]
            # objective: the moments give (7.12) at Q
            assert program.constant + program.q @ y[1:] == pytest.approx(direct_relaxation.cost(setup.cameras, Q),
                                                                         rel=1e-9, abs=1e-12)
            # det Q (zero rows), the 3x3 minors and the chirality pairs (nonnegative rows), brute force
            assert s[0] == pytest.approx(np.linalg.det(Q), abs=1e-12)
            minors3 = [np.linalg.det(Q[np.ix_(k, k)]) for k in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3])]
            assert np.allclose(s[1:5], minors3, atol=1e-12)
            pairs = np.einsum("kab,ab->k", orientation.pairs, direct.adjugate(Q))
            assert np.allclose(s[5:5 + len(pairs)], pairs, atol=1e-12)
            # the PSD blocks: Q's localizer, the 2x2 minors' localizers, the moment matrix
            start = program.cones.zero + program.cones.nonneg
            v1 = program.moments.vector(x)[:1 + direct_relaxation.N]  # monomials of degree <= 1
            v2 = program.moments.vector(x)[:len(direct_relaxation.monomials(2))]
            expected = [np.kron(Q, np.outer(v1, v1))]
            expected += [np.linalg.det(Q[np.ix_(k, k)]) * np.outer(v1, v1)
                         for k in ([0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3])]
            expected.append(np.outer(v2, v2))
            for n, M in zip(program.cones.psd, expected):
                rows = n * (n + 1) // 2
                assert np.allclose(smat(s[start:start + rows], n), M, atol=1e-12)
                start += rows
            assert np.allclose(direct_relaxation.moment_matrix(program, y[1:]), np.outer(v2, v2))

    def test_monomials_are_graded_and_indexed(self):
        moments = direct_relaxation.Moments(2)
        assert len(moments.exps) == 715 and moments.exps[0].sum() == 0
        assert np.array_equal(moments.index(moments.exps), np.arange(715))
        with pytest.raises(ValueError):
            moments.index(np.array([[5] + [0] * (direct_relaxation.N - 1)]))

    def test_the_frame_does_not_depend_on_lapacks_eigenvector_signs(self, monkeypatch):
        """A recorded dual vector is for one program: a verifier whose eigh signs its eigenvectors
        otherwise must rebuild the same frame, hence the same program."""
        scene, _, _, intrinsics = table71(4, 0.2)
        cameras = autocalibration_problem.prepare(scene.cameras, scene.points, None, intrinsics).norm.cameras
        T = direct_relaxation.conditioning_frame(cameras)
        rng, eigh = np.random.default_rng(6), np.linalg.eigh

        def flipped(M):
            values, V = eigh(M)
            return values, V * rng.choice([-1.0, 1.0], size=V.shape[1])

        monkeypatch.setattr(direct_relaxation.np.linalg, "eigh", flipped)
        for _ in range(10):
            assert np.array_equal(direct_relaxation.conditioning_frame(cameras), T)


# --- the safe bound -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def noisy():
    scene, Ks, data, intrinsics = table71(2, 0.2)
    setup = setup_of(scene, intrinsics, "none")
    options = SimpleNamespace(relaxation_order=2, metric_rel_gap=1e-4, abs_gap=1e-12)
    return setup, direct_solve.solve_direct(setup, options, True)


class TestSafeBound:
    def test_any_dual_vector_bounds_every_feasible_quadric(self):
        """The safe bound holds for any z, not only the solver's: random duals, random Q."""
        rng = np.random.default_rng(1)
        scene, _, _, intrinsics = table71(3, 0.2)
        setup = setup_of(scene, intrinsics, "centers")
        program = direct_relaxation.build(setup.cameras, setup.orientations[0].pairs, 2)
        feasible = [Q for Q in (random_feasible(rng) for _ in range(400))
                    if direct.chirality_holds(setup.orientations[0], Q)]
        lowest = min(direct_relaxation.cost(setup.cameras, Q) for Q in feasible)
        for _ in range(30):
            z = rng.normal(size=len(program.b)) * rng.choice([1e-3, 1.0, 10.0])
            bound, _ = direct_relaxation.safe_bound(program, z)
            assert bound <= lowest

    def test_the_solvers_dual_and_its_perturbations_bound_random_feasible_quadrics(self, noisy):
        setup, stage = noisy
        rng = np.random.default_rng(2)
        program = direct_relaxation.build(setup.cameras, None, 2, (), setup.focal)
        z = unpack(stage.proof["programs"][0]["z"])
        feasible = [Q for Q in (random_feasible(rng) for _ in range(2000)) if direct.within_focal(setup, Q)]
        assert len(feasible) >= 20
        costs = [direct_relaxation.cost(setup.cameras, Q) for Q in feasible]
        costs.append(direct_relaxation.cost(setup.cameras, stage.Q))
        for scale in (0.0, 1e-6, 1e-3):
            bound, _ = direct_relaxation.safe_bound(program, z + scale * rng.normal(size=z.shape))
            assert bound <= min(costs)

    def test_certified_and_rank_one(self, noisy):
        setup, stage = noisy
        assert stage.certified and stage.conic_status == ["ipm Solved"]
        assert stage.rank == 1 and stage.eigenvalue_ratio < 1e-4
        assert stage.lower_bound <= stage.cost <= stage.lower_bound + 1e-4 * stage.cost

    def test_never_above_many_start_local_minimisation(self, noisy):
        setup, stage = noisy
        rng = np.random.default_rng(3)
        polished = [direct_solve.polish(setup.cameras, random_feasible(rng)) for _ in range(40)]
        kept = [Q for Q in polished if direct.within_focal(setup, Q)]  # the program's feasible set
        assert len(kept) >= 10
        local = min(direct_relaxation.cost(setup.cameras, Q) for Q in kept)
        assert stage.cost <= local * (1 + 1e-9)
        assert stage.lower_bound <= local



# --- candidates from a relaxation that is not rank one --------------------------------------------

class TestExtraction:
    @pytest.mark.parametrize("count", [2, 3])
    def test_a_mixtures_points_are_recovered(self, count):
        """The moments of a mixture of ``count`` points (random feasible quadrics, random weights):
        extraction at that rank returns exactly those points (any order). Fails when a
        multiplication matrix reads x_k's neighbour's rows (the mutation checked)."""
        rng = np.random.default_rng(7 + count)
        scene, _, _, intrinsics = table71(3, 0.2)
        program = direct_relaxation.build(setup_of(scene, intrinsics, "none").cameras, None, 2)
        points = [direct_relaxation.x_of(random_feasible(rng)) for _ in range(count)]
        weights = rng.random(count) + 0.2
        weights /= weights.sum()
        y = sum(w * program.moments.vector(x) for w, x in zip(weights, points))[1:]
        found = direct_solve.extract(program, y, count)
        assert len(found) == count
        for x in points:
            assert min(np.abs(f - x).max() for f in found) < 1e-8

    def test_a_loose_relaxation_still_returns_a_quadric_keeping_chirality(self, monkeypatch):
        """Table 7.1's seed 1008, varying focal, chirality "points", without the focal rows (with
        them the scene certifies: the next test): not certified, no bound stated, and the quadric
        returned keeps every point in front of every camera with the focal lengths within 5%.
        Which way it gets there rests on the conic solver's path: on one machine the order-2
        relaxation is rank 3 (not tight), its first moments round and polish to quadrics putting
        cameras behind the scene, and one of the points extracted from its moment matrix polishes
        to one that keeps every point in front (without the extraction, EXTRACTED_RANKS = 1, no
        quadric is returned: the mutation checked there); on an AMD EPYC the relaxation comes out
        rank one (eigenvalue ratio 3.5e-6) and its gap, 1.4e-4, misses the tolerance. So the
        rank is not asserted, the outcome is."""
        monkeypatch.setattr(direct, "focal_rows", lambda cameras, ranges: None)
        scene, Ks = scenes.table71_scene(1008, 0.2, True)
        data = {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()}
        intrinsics = {**UNIT, "focal": [0.05, 1.0]}
        result = solve_job(job(data, intrinsics, chirality="points", varying_focal=True))
        stage = result["stages"][0]
        assert stage["status"] == "not_certified" and stage["certificate"]["moment_rank"] >= 1
        assert stage["lower_bound"] is None and stage["gap"] is None  # not certified: no bound stated
        points = np.array(result["points"])
        for camera in result["cameras"]:
            assert np.all((points - np.array(camera["center"])) @ np.array(camera["R"])[2] > 0)
        focal = [K[0][0] for K in result["Ks"]]
        truth = [K[0, 0] for K in Ks]
        assert np.allclose(focal, truth, rtol=0.05)


# --- end to end ---------------------------------------------------------------------------------

def test_the_focal_rows_make_seed_1008_certify(monkeypatch):
    """The same scene with the focal rows (direct.focal_rows): the nearly degenerate quadric that
    kept the lower half's relaxation at 3.27e-4 (eigenvalues 4.6e-6 to 0.999) breaks them, and the
    unsplit order-2 relaxation is rank one and tight at the best quadric (4.6433e-4, gap 1.7e-10,
    measured). Mutation: without the rows (focal_rows -> None) it is not certified.
    The path there is the rounding's: with one OpenBLAS thread the unsplit program ends rank 3
    (bound 2.8e-4), its split's lower half (3.6e-4) splits again, and one of those halves ends
    "Stalled" at 1.4e-3, above the best quadric: its safe bound alone excludes it
    (direct_solve._solve_order's settled; tests/solvers/autocalibration/test_direct_split.py), so
    the splitting certifies at its upper half (rank one) whichever way that half's solve ends. It
    solves with the Schur complement assembled through the svec operator ("kron"; the two assemblies
    agree to 1e-12: tests/core/test_interior_point.py), as it did when measured."""
    scene, Ks = scenes.table71_scene(1008, 0.2, True)
    data = {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()}
    monkeypatch.setattr(interior_point, "ASSEMBLY", "kron")
    result = solve_job(job(data, {**UNIT, "focal": [0.05, 1.0]}, chirality="points", varying_focal=True))
    stage = result["stages"][0]
    assert stage["certified"], stage["reason"]
    assert stage["cost"] == pytest.approx(4.6433e-4, rel=1e-4)
    focal, truth = [K[0][0] for K in result["Ks"]], [K[0, 0] for K in Ks]
    assert np.allclose(focal, truth, rtol=0.05)
    points = np.array(result["points"])
    for camera in result["cameras"]:
        assert np.all((points - np.array(camera["center"])) @ np.array(camera["R"])[2] > 0)


def test_a_focal_length_at_a_ranges_end_still_gives_a_quadric():
    """Table 7.1's seed 1072, varying focal: one view's focal length is 0.053 against the range's
    0.05, the order-2 relaxation is not tight (moment rank 2), and its first moments round to a
    quadric 1.8e-4 outside that view's focal row (trace-1 units); the free polish slides further out
    (1.1e-3). The polish held to the rows (direct_solve.polish_within) gives a quadric within them,
    and the scene certifies rank one. Mutation: without polish_within, no quadric at all ("no
    feasible quadric rounded from the relaxation satisfies chirality and the focal ranges")."""
    scene, Ks = scenes.table71_scene(1072, 0.2, True)
    data = {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()}
    result = solve_job(job(data, {**UNIT, "focal": [0.05, 1.0]}, chirality="none", varying_focal=True))
    stage = result["stages"][0]
    assert result["Ks"] is not None and stage["certified"], stage["reason"]
    focal, truth = [K[0][0] for K in result["Ks"]], [K[0, 0] for K in Ks]
    assert np.allclose(focal, truth, rtol=0.1)
    assert min(focal) >= 0.05 * (1 - 1e-6)


def job(data, intrinsics, **options):
    return {"kind": "autocalibration", "data": copy.deepcopy(data),  # the direct method keeps time_limit_s (60 s by default): outcomes must not depend on the machine's speed
            "options": {"method": "direct", "intrinsics": intrinsics, "time_limit_s": 3600, **options}}


class TestExactRecovery:
    def test_noiseless_scene(self):
        scene, Ks, data, intrinsics = table71(4, 0.0)
        result = solve_job(job(data, intrinsics, chirality="centers", abs_gap=1e-8))
        stage = result["stages"][0]
        assert stage["name"] == "direct" and stage["certified"], stage["reason"]
        assert stage["certificate"]["moment_rank"] == 1
        assert np.abs(np.array(result["K"]) - Ks[0]).max() < 1e-6
        plane = np.array(result["plane_at_infinity"])
        assert min(np.linalg.norm(plane - scene.plane_at_infinity), np.linalg.norm(plane + scene.plane_at_infinity)) < 1e-6
        for camera in result["cameras"]:
            assert np.linalg.det(np.array(camera["R"])) == pytest.approx(1.0)
            assert np.abs(np.array(camera["K"]) - Ks[0]).max() < 1e-6


@pytest.fixture(scope="module")
def certified_points():
    scene, Ks, data, intrinsics = table71(5, 0.2)
    document = job(data, intrinsics, chirality="points", certificate="full")
    return scene, document, solve_job(document)


class TestCertificate:
    def test_certified_verifies_and_points_are_in_front(self, certified_points):
        scene, _, result = certified_points
        stage = result["stages"][0]
        assert stage["certified"], stage["reason"]
        report = verify_any(result)
        assert report.valid, report.first_failure
        K = np.array(result["K"])
        assert abs(K[0, 0] - 1) < 0.05 and abs(K[1, 1] - 1) < 0.05
        points = np.array(result["points"])
        for camera in result["cameras"]:
            depth = (points - np.array(camera["center"])) @ np.array(camera["R"])[2]
            assert np.all(depth > 0)

    @pytest.mark.parametrize("tamper", ["dual", "lower_bound", "data", "quadric", "order", "exclusion"])
    def test_tampering_is_refused(self, certified_points, tamper):
        _, _, result = certified_points
        document = copy.deepcopy(result["certificate"])
        claim = document["items"][0]
        if tamper == "dual":
            z = unpack(claim["proof"]["programs"][0]["z"])
            claim["proof"]["programs"][0]["z"] = pack(z * 1.5)
        elif tamper == "lower_bound":  # a bound raised above what the dual proves
            claim["lower_bound"], claim["gap"] = claim["cost"], 0.0
        elif tamper == "data":
            document["data"]["cameras"][0][0][0] *= 1.001
        elif tamper == "quadric":
            Q = np.array(claim["dual_absolute_quadric"])
            claim["dual_absolute_quadric"] = (Q + 1e-4 * np.eye(4)).tolist()
        elif tamper == "order":
            claim["proof"]["order"] = 3
        elif tamper == "exclusion":
            claim["proof"]["excluded"] = []
        report = verify_any(document)
        assert not report.valid

    def test_a_weakened_relaxation_is_caught(self, certified_points, monkeypatch):
        """The mutation check: a safe bound that forgets the dual's negative eigenvalue is too high
        for some dual vector. A dual whose moment block is pushed down at M_d's (0, 0) entry (the
        constant 1, no moment to correct there) raises -b'z by as much as it lowers lambda_min:
        the sound bound stays below every feasible cost, the weakened one rises above it."""
        rng = np.random.default_rng(5)
        scene, _, _, intrinsics = table71(3, 0.2)
        setup = setup_of(scene, intrinsics, "none")
        program = direct_relaxation.build(setup.cameras, None, 2)
        lowest = min(direct_relaxation.cost(setup.cameras, random_feasible(rng)) for _ in range(200))
        corner = len(program.b) - program.cones.psd[-1] * (program.cones.psd[-1] + 1) // 2  # M_d's (0, 0) in svec
        duals = []
        for _ in range(10):
            z = rng.normal(size=len(program.b))
            z[corner] -= 10.0
            duals.append(z)
            assert direct_relaxation.safe_bound(program, z)[0] <= lowest
        original = np.linalg.eigvalsh
        # the charge dropped
        monkeypatch.setattr(direct_relaxation.np.linalg, "eigvalsh", lambda M: np.abs(original(M)))
        assert any(direct_relaxation.safe_bound(program, z)[0] > lowest for z in duals)


class TestBadInput:
    @pytest.mark.parametrize("options,field", [
        ({"chirality": "sideways"}, "options/chirality"),
        ({"relaxation_order": 3}, "options/relaxation_order"),
        ({"relaxation_order": 1}, "options/relaxation_order"),
        ({"varying_focal": "yes"}, "options/varying_focal"),
    ])
    def test_named(self, options, field):
        from geocert.jobs.runner import parse_job
        from geocert.core.geometry import InputError

        scene, _, data, intrinsics = table71(1, 0.0)
        with pytest.raises(InputError) as error:
            parse_job(job(data, intrinsics, **options))
        assert error.value.field == field

    def test_points_chirality_needs_points(self):
        from geocert.core.geometry import InputError

        scene, _, data, intrinsics = table71(1, 0.0)
        del data["points"]
        with pytest.raises(InputError) as error:
            solve_job(job(data, intrinsics, chirality="points"))
        assert error.value.field == "options/chirality"


@pytest.mark.parametrize("chirality, remedy", [("points", '"centers" or give fewer points'),
                                               ("centers", '"none" or fewer cameras')])
def test_a_program_too_large_names_a_remedy_that_shrinks_it(chirality, remedy):
    from geocert.core.geometry import InputError

    views = 2000 if chirality == "centers" else 300  # centres alone: views (views - 1) / 2 pairs
    with pytest.raises(InputError, match=remedy):
        direct.check_size(views, 1000, chirality)
