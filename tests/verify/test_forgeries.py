"""No forged certificate passes, whatever numbers it holds (issue 33): one class per way a third
hostile review got a false claim accepted, each reproduced on a genuine stored certificate
(tests/data/certificates) and refused. Each test fails on the verifier before the fix."""

from __future__ import annotations

import base64
import copy
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from geocert.core.certificates import data_hash, pack, problem_hash
from geocert.verify.checks import verify_any, verify_document
from tests.support import loose_gaps

STORED = Path(__file__).resolve().parents[1] / "data" / "certificates"
TINY = 5e-324  # the smallest subnormal


def stored(name: str) -> dict:
    return json.loads((STORED / f"{name}.json").read_text())


def raw_pack(z: np.ndarray) -> str:
    """A dual vector as a forger writes it (certificates.pack would write its subnormals as 0)."""
    return base64.b64encode(np.asarray(z, dtype="<f8").tobytes()).decode("ascii")


def estimates_form(document: dict) -> int:
    """The number of the estimates' form a genuine document's hash declares (core.determinacy.
    FORMS; 0: unmarked), as the verifier finds it; read before the document is changed, so that
    what a test restates is written, and hashed, in the document's own form (determinacy.reading,
    rehash's ``form``)."""
    from geocert.verify.checks import _check_hashes, checked_options

    return _check_hashes(document, checked_options(document["kind"], document["options"]))[3]


def rehash(document: dict, earlier: bool = False, marked: bool = False, form: int | None = None) -> dict:
    """The document's hashes made again, in its kind's current options form (``earlier``: its
    earliest form, as a stored document from before the hash covered more options); ``marked``:
    with the form its kind declares (Verification.hash_marks: the estimates' form), which a
    stored document's hash lacks; ``form``: with that estimates' form's mark (estimates_form; 0:
    none), for a kind declaring one."""
    from geocert.core.determinacy import FORMS
    from geocert.kinds import get_kind

    verification = get_kind(document["kind"]).verification
    forms = getattr(verification, "earlier_forms", ()) if earlier else ()
    names = forms[-1][0] if forms else getattr(verification, "claim_options", None)
    marks = getattr(verification, "hash_marks", None) if marked else None
    if form is None and not marked and not earlier:
        # a document whose data and options are as its hash says keeps its estimates' form (a
        # changed one cannot be read, and is hashed unmarked, as every stored document is)
        try:
            form = estimates_form(document)
        except Exception:  # noqa: BLE001 (the hashes no longer match: the document was changed)
            form = None
    if form is not None and getattr(verification, "hash_marks", None):
        marks = FORMS[form - 1] if form > 0 else None
    document["data_sha256"] = data_hash(document["kind"], document["data"])
    document["problem_sha256"] = problem_hash(document["kind"], document["data"], document["options"], names, marks)
    return document


def uncertify(claim: dict) -> dict:
    """``claim`` as a true claim of an item not certified: no bound stated (verify.uncertified_claim),
    its solution and cost untouched."""
    claim.update(certified=False, status="not_certified", lower_bound=None, gap=None)
    return claim


def only(document: dict, index: int) -> dict:
    """The document with every item but ``index`` uncertified (quicker; the rest untouched)."""
    for item in document["items"]:
        if item["index"] != index:
            uncertify(item)
    return document


def refused(document: dict) -> dict:
    report = verify_any(document)
    assert not report.valid, "a forged certificate was accepted"
    return report.first_failure


def refused_naming(forged: dict, check: str, *words: str) -> None:
    """The forged document, as JSON carries it, is refused by ``check`` with a detail naming each
    of ``words``."""
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid
    assert report.first_failure["check"] == check, report.first_failure
    for word in words:
        assert word in report.first_failure["detail"], report.first_failure


def _old_farkas_test(A, b, cones, z, lower, upper, transform) -> bool:
    """The Farkas test as the verifier computed it before (no normalisation, no rounding
    counted): what a forger searches with."""
    z = z.copy()
    z[cones.zero:cones.zero + cones.nonneg] = np.maximum(z[cones.zero:cones.zero + cones.nonneg], 0.0)
    a = np.asarray(A).T @ z
    if transform is not None:
        d = transform.shape[0]
        a = np.concatenate([transform.T @ a[:d], a[d:]])
    terms = np.minimum(a * lower, a * upper)
    terms[a == 0] = 0.0
    return float(b @ z) < float(terms.sum())


SEARCHED = "triangulation_l2l2"  # a stored certificate whose first track's proof is a search


@pytest.fixture(scope="module")
def forged_point():
    """A track's point moved to cost about 200 times its optimum, claimed optimal: its root
    region proven for its own cost, then one farkas leaf over the searched box (a stored
    triangulation certificate whose tracks were searched; a reconstruction's points are now
    mostly certified by their convexity, with no search to forge)."""
    from geocert.verify.fractional import TRACKS
    from geocert.formulations.fractional.relaxation import Relaxation
    from geocert.solvers.fractional.search import root_region

    document = copy.deepcopy(stored(SEARCHED)["certificate"])
    claim = document["items"][0]
    item = TRACKS.item(TRACKS.read(document["data"], 0), "L2L2")

    def cost(point):
        return float((item.raw_residuals(np.append(point, 1.0))[0] ** 2).sum())

    direction = np.array([0.6, -0.48, 0.64])
    step = 1e-3
    while cost(np.array(claim["point"]) + step * direction) < 180 * claim["cost"]:
        step *= 1.1
    bad = np.array(claim["point"]) + step * direction
    bad_cost = cost(bad)
    F = np.array(claim["proof"]["root"]["functionals"])
    k = len(claim["proof"]["search_box"][0])
    state, box, root = root_region(item.program, F[:k], math.sqrt(bad_cost))
    assert state == "ok"
    lower = bad_cost * (1 - 1e-4)
    relaxation = Relaxation(item.program, root.functionals[:k], (root.lower[k:], root.upper[k:]), root.functionals)
    data = relaxation.conic_data(box, lower)
    rows = data.cones.zero + data.cones.nonneg
    for i, j in itertools.combinations(range(rows), 2):  # what the old arithmetic accepts
        z = np.zeros(len(data.b))
        z[[i, j]] = TINY
        if _old_farkas_test(data.A, data.b, data.cones, z, data.lower, data.upper, data.transform):
            break
    else:
        pytest.fail("no subnormal Farkas vector fooled the old test")
    claim.update(point=bad.tolist(), cost=bad_cost, lower_bound=lower, gap=bad_cost - lower)
    claim["proof"] = {
        "type": "branch_and_bound", "scale": 1.0,
        "root": {"gamma": root.gamma, "functionals": root.functionals.tolist(),
                 "claim": [root.claim_lower.tolist(), root.claim_upper.tolist()],
                 "bounds": [root.lower.tolist(), root.upper.tolist()], "duals": [pack(d) for d in root.duals]},
        "tightening": [], "search_box": [box.lo.tolist(), box.hi.tolist()],
        "proofs": [{"box": [box.lo.tolist(), box.hi.tolist()], "upper_bound": lower, "kind": "farkas",
                    "z": raw_pack(z), "bound": None}],
        "leaves": [[box.lo.tolist(), box.hi.tolist(), 0]]}
    assert bad_cost > 150 * stored(SEARCHED)["certificate"]["items"][0]["cost"]
    return only(document, 0), data, z


class TestSubnormalFarkasVectors:
    """Class 1: a branch-and-bound tree replaced by one farkas leaf whose z is zero but for
    entries of about 5e-324: b'z rounds below 0 while every product in A'z and in the box charge
    underflows, so the infeasibility test passed. Now a dual vector with a subnormal entry is
    refused, a Farkas vector is scaled to entries near 1 before the test, and both sides count
    their rounding."""

    def test_a_point_costing_200_times_its_optimum_is_refused(self, forged_point):
        document, _, _ = forged_point
        assert refused(document)["check"] in ("format", "leaf_bounds")

    def test_the_farkas_test_itself_is_not_fooled(self, forged_point):
        from geocert.core.cones import proves_infeasible

        _, data, z = forged_point
        assert not proves_infeasible(data.A, data.b, data.cones, z, data.lower, data.upper, data.transform)
        # Entries just above the subnormal range: the test scales z to entries near 1 first.
        assert not proves_infeasible(data.A, data.b, data.cones, z / TINY * 2.0 ** -1022, data.lower, data.upper,
                                     data.transform)

    def test_a_dual_vector_with_a_subnormal_entry_is_refused_by_its_reader(self):
        from geocert.core.strict import Invalid, dual_vector

        with pytest.raises(Invalid, match="subnormal"):
            dual_vector(raw_pack(np.array([1.0, TINY, 0.0])), 3)
        assert dual_vector(pack(np.array([1.0, TINY, -0.0])), 3).tolist() == [1.0, 0.0, 0.0]

    def test_a_safe_bound_from_underflowing_products_is_no_bound(self):
        """min 0 x over {x in [2, 3]: 0.4 x >= 0.6} is 0; z = 5e-324 on the row made the old
        bound -b'z = 5e-324 (0.6 z rounds up to one subnormal, 0.4 z down to 0)."""
        from geocert.core.cones import ConeSpec, proves_infeasible, safe_lower_bound

        A, b, cones = np.array([[-0.4]]), np.array([-0.6]), ConeSpec(nonneg=1)
        lower, upper = np.array([2.0]), np.array([3.0])
        assert safe_lower_bound(np.zeros(1), A, b, cones, np.array([TINY]), lower, upper) <= 0.0
        assert not proves_infeasible(A, b, cones, np.array([TINY]), lower, upper)


@pytest.fixture(scope="module")
def forged_metric():
    from geocert.formulations.autocalibration import metric_relaxation
    from geocert.formulations.autocalibration import problem as autocalibration_problem
    from geocert.verify.autocalibration import read_data

    document = copy.deepcopy(stored("autocalibration_five_views")["certificate"])
    claim = document["items"][1]
    cameras, points, size = read_data(document["data"])
    problem = autocalibration_problem.prepare(cameras, points, size, dict(document["options"].get("intrinsics") or {}))
    plane = autocalibration_problem.plane_from_input(problem, np.array(claim["plane_at_infinity"]))
    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, plane, problem.unit_ranges)
    K = np.array(claim["K"])
    factor = 1.0
    # below the 1.0 "proven"
    while metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, K)) < 40 * claim["cost"]:
        factor *= 1.01
        K = np.array(claim["K"])
        K[0, 0] *= factor
        K[1, 1] *= factor
    cost = metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, K))
    lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
    assert metric_relaxation.in_domain(setup, autocalibration_problem.w_of_K(problem, K), lo, hi)
    setup.unit = TINY
    lower = cost * (1 - 1e-4)
    program = metric_relaxation.build(setup, lo, hi, lower)
    A = program.A.toarray() if hasattr(program.A, "toarray") else np.asarray(program.A)
    row = next(i for i in range(program.cones.zero) if program.b[i] >= 0.5 and np.abs(A[i]).max() < 0.5)
    z = np.zeros(len(program.b))
    z[row] = -TINY
    claim.update(K=K.tolist(), cost=cost, lower_bound=lower, gap=cost - lower)
    claim["proof"] = {"type": "stratified_metric", "unit": TINY, "tightening": [],
                      "search_box": [lo.tolist(), hi.tolist()],
                      "proofs": [{"box": [lo.tolist(), hi.tolist()], "upper_bound": lower, "kind": "dual",
                                  "z": raw_pack(z), "bound": 1.0}],
                      "leaves": [[lo.tolist(), hi.tolist(), 0]]}
    return document, program, z


class TestStratifiedUnit:
    """Class 2: the stratified stages' ``unit`` (the programs' objective is unit times the cost)
    was only checked to be positive: with unit 5e-324, a dual entry of -5e-324 on an equality row
    whose coefficients are all below 1/2 gave a program bound of one subnormal, 1.0 once divided
    by the unit, over the whole omega box (here a K costing 40 times the optimum, which costs
    0.02: a scene with such a row, tests/data/certificates' autocalibration_five_views). Now a unit must put the claimed cost within
    proofs.UNIT_RANGE, and the bound counts its rounding (one subnormal, at least)."""

    def test_a_calibration_costing_40_times_the_optimum_is_refused(self, forged_metric):
        document, _, _ = forged_metric
        assert document["items"][1]["lower_bound"] < 1.0  # what the old arithmetic "proved"
        assert refused(document)["check"] in ("program", "format", "lower_bound")

    def test_its_program_bound_is_no_bound(self, forged_metric):
        from geocert.core.cones import safe_lower_bound

        _, program, z = forged_metric
        assert safe_lower_bound(program.q, program.A, program.b, program.cones, z, program.lower,
                                program.upper) <= 0.0

    @pytest.mark.parametrize("unit", [TINY, 1e-300, 0.0, -1.0, 1e300])
    def test_a_unit_that_puts_the_cost_far_from_1_is_refused(self, unit):
        result = stored("autocalibration_five_views")
        result["certificate"]["items"][1]["proof"]["unit"] = unit
        assert refused(result)["check"] in ("program", "format")
        result = stored("autocalibration_five_views")
        for region in result["certificate"]["items"][0]["proof"]["regions"]:
            region["unit"] = unit
        assert refused(result)["check"] in ("program", "format")


def _resolved_cameras(result: dict, document: dict) -> None:
    """What a forger does with a camera certificate: every searched camera called certified,
    with the lower bound its claim states, and the summary's counts to match."""
    searched = [camera for camera in result["cameras"] if camera.get("searched")]
    for camera, claim in zip(searched, document["items"]):
        camera.update(certified=True, status="optimal", lower_bound=claim["lower_bound"],
                      gap=camera["cost"] - claim["lower_bound"], optimal_cost=claim["cost"], bound_reason=None)
    result["camera_certificate"] = document
    count = sum(camera["certified"] for camera in result["cameras"])
    result["summary"].update(cameras_certified=count, cameras_certified_fraction=count / len(searched))
    for stage in result["stages"]:
        if stage["name"] == "cameras":
            stage["certified"] = count


class TestEmbeddedCertificatesTied:
    """Class 3: a reconstruction's camera certificate was only checked to be valid and built from
    the returned points: one solved under L1L1 inside an L2L2 result made every camera
    "certified optimal" with a lower bound above its own cost (gap -8 to -11). Now it must be a
    resection certificate with the result's norm, max_residual, abs_gap and camera_rel_gap, and
    a certified camera's lower bound at most its cost."""

    @staticmethod
    def camera_certificate(result: dict, **options) -> dict:
        from geocert.jobs.runner import solve_job

        maps = result["camera_certificate"]["data"]["maps"]
        own = result["camera_certificate"]["options"]
        job_options = {"norm": own["norm"], "rel_gap": own["rel_gap"], "abs_gap": own["abs_gap"],
                       "max_residual": own["max_residual"], "certificate": "full", **options}
        return solve_job({"kind": "resection", "data": {"maps": maps}, "options": job_options})["certificate"]

    def test_a_camera_certificate_under_another_norm_is_refused(self):
        result = stored("reconstruction")
        other = self.camera_certificate(result, norm="L1L1")
        assert verify_document(other).valid
        _resolved_cameras(result, other)
        assert any(c["lower_bound"] is not None and c["lower_bound"] > c["cost"] for c in result["cameras"])
        assert refused(result)["check"] == "returned"

    @pytest.mark.parametrize("options", [{"rel_gap": 0.4}, {"abs_gap": 1e-5}, {"max_residual": 50.0}])
    def test_a_camera_certificate_with_other_options_is_refused(self, options):
        result = stored("reconstruction")
        other = self.camera_certificate(result, **options)
        assert verify_document(other).valid
        _resolved_cameras(result, other)
        assert refused(result)["check"] == "returned"

    def test_a_certificate_of_another_kind_is_refused(self):
        result = stored("reconstruction")
        result["camera_certificate"] = stored("triangulation_l2l2")["certificate"]
        assert refused(result)["check"] == "returned"

    def test_a_certified_camera_bound_above_its_cost_is_refused(self):
        result = stored("reconstruction")
        camera = next(c for c in result["cameras"] if c["certified"])
        camera.update(lower_bound=camera["cost"] * 1.5, gap=-0.5 * camera["cost"])
        assert refused(result)["check"] == "returned"


class TestReconstructionFieldsTied:
    """Class 4: only each camera's P was compared with the certificate: K, R, t or the centre
    changed after the fact, an unregistered camera claiming certified, a summary edited to all
    cameras certified at a better RMS all verified. Now K, R, t and the centre must be what P
    gives, an unregistered camera claims nothing, and the summary's counts and RMS are
    recomputed from the items."""

    @pytest.mark.parametrize("field, change", [("K", lambda K: [[K[0][0] * 1.2, 0.0, K[0][2]], K[1], K[2]]),
                                               ("R", lambda R: [R[1], R[0], [-x for x in R[2]]]),
                                               ("t", lambda t: [t[0] + 1.0, t[1], t[2]]),
                                               ("center", lambda c: [c[0], c[1], c[2] - 3.0])])
    def test_a_camera_field_not_from_its_P_is_refused(self, field, change):
        result = stored("reconstruction")
        camera = result["cameras"][0]
        camera[field] = change(camera[field])
        assert refused(result)["check"] == "returned"

    def test_an_extra_unregistered_camera_claiming_certified_is_refused(self):
        result = stored("reconstruction")
        result["cameras"].append({**{k: None for k in result["cameras"][0]}, "view": len(result["cameras"]),
                                  "name": "extra", "registered": False, "certified": True, "status": "optimal",
                                  "searched": False, "points": 0})
        result["summary"].update(views=len(result["cameras"]))
        assert refused(result)["check"] == "returned"

    @pytest.mark.parametrize("changes", [{"cameras_certified": 6, "cameras_certified_fraction": 1.0},
                                         {"rms_reprojection_px": 0.01}, {"points_certified": 99},
                                         {"views_registered": 7}, {"observations": 1}])
    def test_an_edited_summary_is_refused(self, changes):
        result = stored("reconstruction")
        result["summary"].update(changes)
        assert refused(result)["check"] == "returned"

    def test_observations_not_the_certified_track_are_refused(self):
        result = stored("reconstruction")
        result["points"][0]["observations"][0][1] += 5.0
        assert refused(result)["check"] == "returned"


class TestBilinearScopeStated:
    """Class 5: a bilinear frame's summary root_region (its scope: the camera box its proof
    covers) could be widened to +-1e6, or dropped for an unbounded scope, and still verify; the
    report's scope named no box. Now the summary must be the proof's box, and the report states
    each frame's box (scope.camera_boxes)."""

    @pytest.mark.parametrize("change", ["widened", "unbounded", "dropped"])
    def test_a_summary_scope_not_the_proofs_is_refused(self, change):
        result = stored("bilinear_l1l1")
        region = result["frames"][0]["certificate"]["root_region"]
        if change == "widened":
            region["camera_lower"] = [[-1e6] * 3] * 2
            region["camera_upper"] = [[1e6] * 3] * 2
        elif change == "unbounded":
            region["camera_lower"] = region["camera_upper"] = None
        else:
            result["frames"][0]["certificate"]["root_region"] = None
        assert refused(result)["check"] == "returned"

    def test_the_report_states_each_frames_box(self):
        result = stored("bilinear_l1l1")
        report = verify_any(result)
        assert report.valid
        boxes = {entry["item"]: entry for entry in report.scope["camera_boxes"]}
        for claim in result["certificate"]["items"]:
            lo, hi = claim["proof"]["camera_box"]
            assert boxes[claim["index"]]["camera_lower"] == [lo[:3], lo[3:]]
            assert boxes[claim["index"]]["camera_upper"] == [hi[:3], hi[3:]]


class TestDeterminacyWithinScope:
    """Class 6: a metric stage's intervals reached outside its scope's ranges (here a skew of
    [-35, 55] px beside a scope of [-10, 10], as stored). Each must lie within its range (the
    stratified scope: K within the intrinsics ranges, so f_x, f_x times the aspect, the skew and
    the principal point within theirs). Fixed by the determinacy work of issue 37 (its clip); this
    test stands for issue 33's class on the stored certificate."""

    def test_the_metric_stages_intervals_lie_within_the_intrinsics_ranges(self):
        from geocert.formulations.autocalibration import determinacy
        from geocert.formulations.autocalibration import problem as autocalibration_problem
        from geocert.verify.autocalibration import read_data

        result = stored("autocalibration_five_views")
        stage = result["stages"][1]
        skew = next(i for i in stage["determinacy"]["intervals"] if i["name"] == "skew")
        assert skew["lower"] < -10 and skew["upper"] > 10  # as stored: beyond the scope
        cameras, points, size = read_data(result["certificate"]["data"])
        problem = autocalibration_problem.prepare(cameras, points, size, {})
        p = autocalibration_problem.plane_from_input(problem, np.array(stage["plane_at_infinity"]))
        document = determinacy.metric_stage(problem, p, np.array(stage["K"]), stage["cost"], stage["lower_bound"], None)
        r = problem.ranges
        (u_lo, u_hi), (v_lo, v_hi) = r["principal_point"]
        scope = {"focal_x": tuple(r["focal"]), "focal_y": (r["focal"][0] * r["aspect"][0], r["focal"][1] * r["aspect"][1]),
                 "skew": tuple(r["skew"]), "principal_u": (u_lo, u_hi), "principal_v": (v_lo, v_hi)}
        for interval in document["intervals"]:
            low, high = scope[interval["name"]]
            for end in (interval["lower"], interval["upper"]):
                assert end is None or low <= end <= high, (interval, (low, high))


class TestVerifierCost:
    """Class 7: the direct method's verifier built one polynomial row per (point, centre) pair
    before any size check (10,060 points: 36 s and 1.7 GB). Now every size is checked against its
    limit before anything is built (direct.MAX_CHIRALITY_PAIRS, the dual vector's length, the
    autocalibration and bilinear data limits), and a verification pays for the programs it builds
    from a budget in proportion to the document's size (strict.charge)."""

    @staticmethod
    def many_points(count: int) -> dict:
        """The direct certificate with ``count`` copies of its points put first (the same
        geometry: its exclusion's rows, shifted, still exclude the same orientation)."""
        document = stored("autocalibration_direct_points")["certificate"]
        points = document["data"]["points"]
        document["data"]["points"] = [points[i % len(points)] for i in range(count)] + points
        for excluded in document["items"][0]["proof"]["excluded"]:
            excluded["rows"] = [row + count for row in excluded["rows"]]
        return rehash(document)

    def test_ten_thousand_points_are_refused_before_any_program_is_built(self, monkeypatch):
        from geocert.formulations.autocalibration import direct_relaxation

        built = []
        original = direct_relaxation.build
        monkeypatch.setattr(direct_relaxation, "build", lambda cameras, pairs, *a, **k: built.append(
            0 if pairs is None else len(pairs)) or original(cameras, pairs, *a, **k))
        document = self.many_points(10_060)
        failure = refused(document)
        assert failure["check"] in ("options", "data", "format")
        assert not [count for count in built if count > 1000], built

    def test_a_short_dual_vector_is_refused_before_its_program_is_built(self, monkeypatch):
        from geocert.formulations.autocalibration import direct_relaxation

        built = []
        original = direct_relaxation.build
        monkeypatch.setattr(direct_relaxation, "build", lambda cameras, pairs, *a, **k: built.append(
            0 if pairs is None else len(pairs)) or original(cameras, pairs, *a, **k))
        document = self.many_points(1_500)  # within the pair limit
        for program in document["items"][0]["proof"]["programs"]:
            program["z"] = pack(np.ones(10))
        assert refused(document)["check"] == "leaf_bounds"
        assert not [count for count in built if count > 1000], built

    def test_every_program_is_paid_for_before_it_is_built(self, monkeypatch):
        """With no budget beyond the document's bare size, a genuine certificate of each kind is
        refused for its work, never after building a program it could not pay for."""
        from geocert.core import strict

        monkeypatch.setattr(strict, "WORK_PER_UNIT", 0)
        monkeypatch.setattr(strict, "WORK_BASE", 10)
        import geocert.verify.checks as verify

        monkeypatch.setattr(verify, "WORK_PER_UNIT", 0)
        monkeypatch.setattr(verify, "WORK_BASE", 10)
        for name in ("resection_caps", "bilinear_l1l1", "autocalibration_stratified", "autocalibration_direct"):
            report = verify_any(stored(name))
            assert not report.valid and "more work than its size pays for" in report.first_failure["detail"], name

    def test_a_basis_beyond_the_limits_is_refused(self):
        from geocert.formulations.bilinear import problem as bilinear_problem
        from geocert.core.geometry import InputError

        with pytest.raises(InputError, match="limit"):
            bilinear_problem.read_basis([[[0.0, 0.0, float(i)]] * 2 for i in range(bilinear_problem.MAX_SHAPES + 1)])


class TestUnreadFields:
    """Class 8: fields no check reads (a leaf's own bound beside the recomputed one, sign on a proof
    that is not a cut, the moment matrix's rank) took NaN, strings, booleans. Now every number in a
    document must be finite, a proof record has its fields and no other, and each field no check
    reads is null or of its type (docs/certificate.md lists them as informational)."""

    @staticmethod
    def cut_proof(result: dict) -> dict:
        return next(p for region in result["certificate"]["items"][0]["proof"]["regions"] for p in region["proofs"]
                    if p["kind"] == "cut")

    @pytest.mark.parametrize("value", [float("nan"), "0.5", True, float("inf")])
    def test_an_affine_proofs_bound(self, value):
        result = stored("autocalibration_five_views")
        self.cut_proof(result)["bound"] = value
        assert refused(result)["check"] == "format"

    @pytest.mark.parametrize("value", [float("nan"), "x", True])
    def test_sign_on_a_proof_that_is_not_a_cut(self, value):
        result = stored("autocalibration_stratified")
        result["certificate"]["items"][1]["proof"]["proofs"][0]["sign"] = value
        assert refused(result)["check"] == "format"

    @pytest.mark.parametrize("value", [float("nan"), "1", True, 1.5])
    def test_the_moment_rank(self, value):
        result = stored("autocalibration_direct")
        result["certificate"]["items"][0]["proof"]["moment_rank"] = value
        assert refused(result)["check"] == "format"
        result = stored("autocalibration_direct")
        result["stages"][0]["certificate"]["moment_rank"] = value
        assert refused(result)["check"] in ("format", "returned")

    @pytest.mark.parametrize("name", ["bound", "z"])
    def test_a_fractional_proofs_unread_fields(self, name):
        result = stored("resection_node_tightening")
        proof = next(p for p in result["certificate"]["items"][0]["proof"]["proofs"] if p["kind"] == "tightened")
        proof[name] = True
        assert refused(result)["check"] == "format"


def exact_homography_minimum(source: np.ndarray, target: np.ndarray, matrix: np.ndarray, offset: np.ndarray) -> float:
    """The L2L2 minimum of a homography whose source lies near ``offset``, computed on the source
    moved to the origin (exact: the coordinates are within a factor 2 of the offset) from the
    matrix given, polished by Levenberg-Marquardt: an independent judge of a claimed bound."""
    import scipy.optimize

    shifted = source - offset
    move = np.eye(3)
    move[:2, 2] = offset

    def residuals(h):
        p = np.c_[shifted, np.ones(len(shifted))] @ h.reshape(3, 3).T
        return (target - p[:, :2] / p[:, 2:]).ravel()

    start = matrix @ move
    fit = scipy.optimize.least_squares(residuals, (start / np.linalg.norm(start)).ravel(), method="lm", xtol=1e-15,
                                       ftol=1e-15, gtol=1e-15)
    return float((fit.fun ** 2).sum())


class TestFarFromTheOrigin:
    """Class 9: a verified homography claim 1.1e-8 (relative) above the exact minimum, its source
    1e6 from the origin: a proof bounds the program the verifier builds, which is the data's
    problem only up to rounding. Now the bound is lowered by the program's distance from the data
    at the solution (proof.program_discount), in the verifier and the solvers alike."""

    OFFSET = np.array([1e6, 1.3e6])

    def test_the_stored_over_claim_is_read_as_what_is_proven(self):
        # as the solver wrote it before: its float cost 1.6e-8 (relative) off the matrix's exact
        # cost, which the verifier now holds a far claim to (review 37 class 1), so it is refused
        result = json.loads((STORED / "earlier" / "homography_far_from_origin.json").read_text())
        claim = result["certificate"]["items"][0]
        data = result["certificate"]["data"]["maps"][0]
        exact = exact_homography_minimum(np.array(data["source"]), np.array(data["target"]),
                                         np.array(claim["matrix"]), self.OFFSET)
        assert claim["lower_bound"] > exact * (1 + 1e-9)  # the over-claim
        report = verify_any(result)
        standing = {entry["item"]: entry["proven"] for entry in (report.scope or {}).get("discounted", [])}
        assert not report.valid or standing.get(0, claim["lower_bound"]) <= exact
        assert report.first_failure["check"] == "objective"

    def test_a_new_claim_is_below_the_exact_minimum_and_verifies(self):
        from geocert.jobs.runner import solve_job

        data = stored("homography_far_from_origin")["certificate"]["data"]
        result = solve_job({"kind": "homography", "data": data, "options": {"norm": "L2L2", "certificate": "full"}})
        claim = result["certificate"]["items"][0]
        assert claim["certified"]
        exact = exact_homography_minimum(np.array(data["maps"][0]["source"]), np.array(data["maps"][0]["target"]),
                                         np.array(claim["matrix"]), self.OFFSET)
        assert claim["lower_bound"] <= exact
        report = verify_any(result)
        assert report.valid and not report.scope.get("discounted"), report.first_failure


@pytest.fixture(scope="module")
def thin_cut_metric():
    """The stratified metric stage "proved" by one leaf closed by a cut whose dual vector is 0,
    over the omega box of intrinsics whose principal point is pinned to +-1e-6 px (the middle of
    its default range, so the affine stage's genuine proof stands): a K of focal 600 px claimed
    optimal where the scene's own (focal 1000 px, in the same box) costs almost nothing."""
    from geocert.formulations.autocalibration import metric_relaxation
    from geocert.formulations.autocalibration import problem as autocalibration_problem
    from geocert.verify.autocalibration import read_data

    result = stored("autocalibration_stratified")
    document = result["certificate"]
    cameras, points, image_size = read_data(document["data"])
    (ul, uu), (vl, vu) = autocalibration_problem.resolve_ranges({}, image_size)["principal_point"]
    u0, v0 = (ul + uu) / 2, (vl + vu) / 2
    document["options"]["intrinsics"] = {"principal_point": [[u0 - 1e-6, u0 + 1e-6], [v0 - 1e-6, v0 + 1e-6]]}
    problem = autocalibration_problem.prepare(cameras, points, image_size, document["options"]["intrinsics"])
    claim = document["items"][1]
    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference,
                                        autocalibration_problem.plane_from_input(problem,
                                                                                 np.array(claim["plane_at_infinity"])),
                                        problem.unit_ranges)
    lo, hi = metric_relaxation.omega_box(problem.unit_ranges)

    def w(focal):
        return autocalibration_problem.w_of_K(problem, np.array([[focal, 0.0, u0], [0.0, focal, v0], [0.0, 0.0, 1.0]]))

    cost = metric_relaxation.cost(setup, w(600.0))
    setup.unit = 1.0 / cost
    rows = len(metric_relaxation.build(setup, lo, hi, cost, cap_row=True).b)
    claim.update(K=[[600.0, 0.0, u0], [0.0, 600.0, v0], [0.0, 0.0, 1.0]], cost=cost, lower_bound=cost * (1 - 1e-5),
                 gap=cost * 1e-5)
    claim["proof"] = {"type": "stratified_metric", "unit": 1.0 / cost, "tightening": [],
                      "search_box": [lo.tolist(), hi.tolist()],
                      "proofs": [{"box": [lo.tolist(), hi.tolist()], "upper_bound": cost, "kind": "cut",
                                  "z": pack(np.zeros(rows)), "bound": None, "axis": 2, "sign": 1.0}],
                      "leaves": [[lo.tolist(), hi.tolist(), 0]]}
    rehash(document)
    truth = w(1000.0)
    assert metric_relaxation.in_domain(setup, truth, lo, hi)
    assert metric_relaxation.cost(setup, truth) < 1e-6 * claim["lower_bound"]
    return only(document, 1)


class TestCutMovedOverTheBox:
    """A cut leaf beyond its cut by at most coverage.SIDE_TOLERANCE of the root box's size was
    moved back to the cut's proven value, the boxes on its inner face extended over the sliver,
    and the coverage check read the leaves as claimed. Where a coordinate's range is narrower than
    that tolerance, a cut proving nothing (z = 0: the box's own side) moved the only leaf off the
    whole box, which still read as covered, and closed it at the cap the forger chose. Now the
    leaves must cover the box as the checks read them (moved and extended)."""

    def test_one_cut_leaf_over_a_thin_box_is_refused(self, thin_cut_metric):
        assert refused(thin_cut_metric)["check"] in ("coverage", "leaf_bounds")

    def test_the_thin_box_is_thinner_than_the_tolerance(self, thin_cut_metric):
        from geocert.core.coverage import SIDE_TOLERANCE

        lo, hi = (np.array(side) for side in thin_cut_metric["items"][1]["proof"]["search_box"])
        assert (hi - lo).min() < SIDE_TOLERANCE * np.abs(np.r_[lo, hi]).max()

    def test_the_leaves_on_moved_faces_are_paid_for(self, thin_cut_metric):
        """Each moved leaf was tested against every leaf (O(moves x leaves), unpaid: 8,000 moved
        leaves and 8,000 leaves on their face took 16 s and verified). Now the leaves on a moved
        face are found by sorting, and each test of one against its moved leaf is paid for."""
        document = copy.deepcopy(thin_cut_metric)
        proof = document["items"][1]["proof"]
        leaf = proof["leaves"][0]
        flat = [list(leaf[0]), list(leaf[1]), 0]
        flat[0][2] = flat[1][2]  # a leaf of no width on the moved leaves' face
        proof["leaves"] = [leaf] * 3000 + [flat] * 3000
        assert "more work than its size pays for" in refused(document)["detail"]


@pytest.fixture(scope="module")
def calibrated_reconstruction():
    """A reconstruction result as the solver writes it today (its summary states the calibration:
    the stored one predates it): make_fixtures' scene, its autocalibration certified, the cameras
    returned using the K the bundle adjustment moved from the certified one."""
    import sys

    sys.path.insert(0, str(STORED))
    from make_fixtures import reconstruction

    result = reconstruction()
    calibration = result["summary"]["calibration"]
    assert calibration["certified"] and not calibration["returned_is_certified"]
    return result


class TestCalibrationTied:
    """The summary's calibration (the K the returned cameras use, the certified K, whether they
    are the same, how far apart) was read by no check: a K of focal 5,000 px called the returned
    cameras' and the certified one, their cameras using 797 px, verified. Now it is recomputed
    from the cameras returned, and tied to the autocalibration stage, the summary's flags and its
    warnings (the metric upgrade's own certification stays the pipeline's statement, as the scope
    says)."""

    @staticmethod
    def forged(result: dict, **changes) -> dict:
        result = copy.deepcopy(result)
        result["summary"]["calibration"].update(changes)
        return result

    def test_a_calibration_the_cameras_do_not_use_is_refused(self, calibrated_reconstruction):
        K = [[5000.0, 0.0, 10.0], [0.0, 5000.0, 10.0], [0.0, 0.0, 1.0]]
        forged = self.forged(calibrated_reconstruction, K=K, certified_K=K, returned_is_certified=True,
                             source="autocalibration",
                             difference={"focal_percent": 0.0, "principal_point_px": 0.0, "aspect": 0.0, "skew_px": 0.0})
        assert refused(forged)["check"] == "returned"

    @pytest.mark.parametrize("changes", [{"returned_is_certified": True, "source": "autocalibration"},
                                         {"certified": False}, {"determined": True},
                                         {"difference": {"focal_percent": 0.0, "principal_point_px": 0.0,
                                                         "aspect": 0.0, "skew_px": 0.0}},
                                         {"certified_K": [[700.0, 0.0, 320.0], [0.0, 700.0, 240.0], [0, 0, 1.0]]}])
    def test_an_edited_calibration_is_refused(self, calibrated_reconstruction, changes):
        assert refused(self.forged(calibrated_reconstruction, **changes))["check"] == "returned"

    def test_a_warning_about_the_calibration_removed_is_refused(self, calibrated_reconstruction):
        forged = copy.deepcopy(calibrated_reconstruction)
        warnings = forged["summary"]["warnings"]
        assert any(w["code"] == "returned_K_not_certified" for w in warnings)
        forged["summary"]["warnings"] = [w for w in warnings if w["code"] != "returned_K_not_certified"]
        assert refused(forged)["check"] == "returned"

    def test_the_genuine_result_verifies(self, calibrated_reconstruction):
        assert verify_any(calibrated_reconstruction).valid


class TestIntegerEntriesReadInBulk:
    """Rows holding an integer were read entry by entry (6 microseconds each): a metric proof of
    200,000 leaves with integer corners (8.4 MB) took 25 s before its coverage was refused, 9 s
    read in bulk. Integers are now read in bulk as floats are; an entry that is not a finite JSON
    number is still named."""

    def test_integer_rows_are_not_checked_entry_by_entry(self, monkeypatch):
        from geocert.core import geometry

        def entry_by_entry(*args, **kwargs):
            raise AssertionError("read entry by entry")

        monkeypatch.setattr(geometry, "_check_entries", entry_by_entry)
        array = geometry.number_array([[0, 1, 2.5]] * 1000, "x", "rows", 2)
        assert array.shape == (1000, 3) and array.dtype == float

    @pytest.mark.parametrize("bad", [True, "1", 2 ** 1023, 10 ** 400, float("nan")])
    def test_a_bad_entry_is_named(self, bad):
        from geocert.core.geometry import InputError, number_array

        with pytest.raises(InputError) as caught:
            number_array([[0, 1, 2]] * 3 + [[0, bad, 2]], "x", "rows", 2)
        assert caught.value.field == "x/3/1"


class TestMetricRoundsBounded:
    """A metric proof's tightening rounds were unbounded, and each builds its program whatever its
    duals: 1,000 rounds proving nothing (every dual null, 560 KB) added 6 s and verified, some 6
    minutes within the 32 MB body limit. Now at most proofs.MAX_ROUNDS (the solver makes 12)."""

    def test_rounds_beyond_the_limit_are_refused_before_any_is_built(self, monkeypatch):
        from geocert.formulations.autocalibration import metric_relaxation
        from geocert.formulations.autocalibration.proofs import MAX_ROUNDS

        result = stored("autocalibration_five_views")
        proof = result["certificate"]["items"][1]["proof"]
        box = proof["search_box"]
        cap = proof["tightening"][-1]["cap"] if proof["tightening"] else result["certificate"]["items"][1]["cost"]
        proof["tightening"] += [{"cap": cap, "box_in": box, "box_out": box, "duals": [None] * 10}] * (MAX_ROUNDS + 1)
        built = []
        original = metric_relaxation.build
        monkeypatch.setattr(metric_relaxation, "build", lambda *a, **k: built.append(1) or original(*a, **k))
        assert refused(only(result["certificate"], 1))["check"] == "format"
        assert not built


# --- Hostile review of the reconstruction kind's camera and calibration claims (issues 33, 35). ---
# Each class below is a false claim `verify_any` accepted on a genuine result (make_fixtures'
# reconstruction, through the calibrated_reconstruction fixture); each test failed until the
# verifier refused it. Each class's docstring says what was accepted.


def _cameras_stage(result: dict) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == "cameras")


def _autocalibration_stage(result: dict) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == "autocalibration")


def _uncertify_camera(result: dict, view: int) -> dict:
    """Camera ``view`` (certified in the genuine result) called uncertified, with the summary's and
    the cameras stage's counts to match: a true, weaker claim, which verifies."""
    result = copy.deepcopy(result)
    result["cameras"][view].update(certified=False, status="not_certified")
    count = sum(camera["certified"] is True for camera in result["cameras"])
    result["summary"].update(cameras_certified=count, cameras_certified_fraction=count / len(result["cameras"]))
    _cameras_stage(result)["certified"] = count
    return result


class TestUncertifiedCameraClaims:
    """A searched camera the result calls uncertified still states a lower_bound, gap,
    optimal_cost, tolerance and degrees_of_freedom. Its lower_bound is compared with the proven one
    only when its resection claim is certified, and with its cost, its optimal_cost, tolerance and
    degrees of freedom only when the camera is certified (_check_camera_certificate,
    _camera_tolerance): a lower bound of 1e9 on a camera costing 4.3 verifies."""

    def test_the_weaker_claim_verifies(self, calibrated_reconstruction):
        view = next(c["view"] for c in calibrated_reconstruction["cameras"] if c["certified"])
        assert verify_any(_uncertify_camera(calibrated_reconstruction, view)).valid

    def test_a_lower_bound_with_no_proof_behind_it_is_refused(self, calibrated_reconstruction):
        result = calibrated_reconstruction
        view = next(c["view"] for c in result["cameras"] if c["certified"])
        position = [c["view"] for c in result["cameras"] if c.get("searched")].index(view)
        forged = _uncertify_camera(result, view)
        forged["camera_certificate"]["items"][position]["certified"] = False
        camera = forged["cameras"][view]
        camera.update(lower_bound=1e9, gap=camera["cost"] - 1e9)
        assert refused(forged)["check"] == "returned"

    @pytest.mark.parametrize("changes", [{"optimal_cost": 0.001}, {"tolerance": 50.0}, {"degrees_of_freedom": 3}])
    def test_an_uncertified_searched_camera_states_only_true_figures(self, calibrated_reconstruction, changes):
        view = next(c["view"] for c in calibrated_reconstruction["cameras"] if c["certified"])
        forged = _uncertify_camera(calibrated_reconstruction, view)
        forged["cameras"][view].update(changes)
        assert refused(forged)["check"] == "returned"

    @pytest.mark.parametrize("changes", [{"status": "optimal"}, {"tolerance": 5.0}, {"degrees_of_freedom": 1}])
    def test_an_unsearched_camera_states_only_true_figures(self, calibrated_reconstruction, changes):
        forged = copy.deepcopy(calibrated_reconstruction)
        camera = next(c for c in forged["cameras"] if c["registered"] and not c["searched"])
        camera.update(changes)
        assert refused(forged)["check"] == "returned"


class TestCamerasCertifiedFraction:
    """summary.cameras_certified_fraction divides by the cameras whose status is not "not_run" or
    "cancelled", and a registered camera's status is its own statement: the two registered cameras
    no bound certifies relabelled "not_run" make the summary say every camera is certified (4/4 =
    1.0, with 6 registered), and it verifies."""

    def test_uncertified_cameras_relabelled_not_run_are_refused(self, calibrated_reconstruction):
        forged = copy.deepcopy(calibrated_reconstruction)
        uncertified = [c for c in forged["cameras"] if c["registered"] and not c["certified"]]
        assert uncertified
        for camera in uncertified:
            camera["status"] = "not_run"
        forged["summary"]["cameras_certified_fraction"] = 1.0
        assert refused(forged)["check"] == "returned"


class TestSummaryFieldsUntied:
    """Summary fields no check reads: the tracks count, the counts of what the pipeline dropped or
    removed, and the camera claim's text (it states camera_rel_gap in words). A summary saying 1,000
    tracks (16 returned, none dropped), or "every camera is exactly right", verifies; a camera claim
    naming camera_rel_gap 0.25 verifies beside options of 0.999."""

    @pytest.mark.parametrize("changes", [{"tracks": 1000}, {"points_dropped": 7}, {"cameras_dropped": 5},
                                         {"observations_removed": 77},
                                         {"camera_claim": "every camera returned is exactly right"}])
    def test_an_untied_summary_field_edited_is_refused(self, calibrated_reconstruction, changes):
        forged = copy.deepcopy(calibrated_reconstruction)
        forged["summary"].update(changes)
        assert refused(forged)["check"] == "returned"


class TestCalibrationClaimsBehindNoProof:
    """What the summary says of the calibration beyond the K returned rests on fields nothing
    proves: without summary.calibration (read as a result from before it was stated) the summary's
    autocalibration_determined, critical_motion and warnings are unchecked; with it, the critical
    motion is read from the document's own summary and stage, and certified_K from the stage's K.
    So a result whose tracks do not determine K (a critical motion, said so by the genuine result)
    verifies as "determined" with no warning, and a K the bundle adjustment moved verifies as the
    certified one. (The scope says the upgrade's certification is the pipeline's statement; these
    flags are what a user reads first.)"""

    def test_determined_claimed_with_the_calibration_removed_is_refused(self, calibrated_reconstruction):
        forged = copy.deepcopy(calibrated_reconstruction)
        assert forged["summary"]["critical_motion"]
        del forged["summary"]["calibration"]
        forged["summary"].update(autocalibration_determined=True, critical_motion=None, warnings=[])
        _autocalibration_stage(forged).update(determined=True, critical_motion=None)
        assert refused(forged)["check"] == "returned"

    def test_determined_claimed_after_the_critical_motion_is_erased_is_refused(self, calibrated_reconstruction):
        forged = copy.deepcopy(calibrated_reconstruction)
        forged["summary"]["calibration"]["determined"] = True
        forged["summary"].update(autocalibration_determined=True, critical_motion=None,
                                 warnings=[w for w in forged["summary"]["warnings"] if w["code"] != "critical_motion"])
        _autocalibration_stage(forged).update(determined=True, critical_motion=None)
        assert refused(forged)["check"] == "returned"

    def test_the_returned_K_called_certified_through_the_stage_is_refused(self, calibrated_reconstruction):
        forged = copy.deepcopy(calibrated_reconstruction)
        calibration = forged["summary"]["calibration"]
        calibration.update(certified_K=calibration["K"], returned_is_certified=True, source="autocalibration",
                           difference={"focal_percent": 0.0, "principal_point_px": 0.0, "aspect": 0.0, "skew_px": 0.0})
        _autocalibration_stage(forged)["K"] = calibration["K"]
        forged["summary"]["warnings"] = [w for w in forged["summary"]["warnings"]
                                         if w["code"] != "returned_K_not_certified"]
        assert refused(forged)["check"] == "returned"


def _restate_mirror_angles(result: dict) -> None:
    """Each registered camera's mirror_rotation_deg, and the depth-reversal record's, restated from
    the cameras' rotations as the pipeline states them (depth_reversal.mirror_angles_deg)."""
    from geocert.formulations.reconstruction.depth_reversal import mirror_angles_deg

    figures = result["summary"].get("depth_reversal") or {}
    if not figures.get("checked"):
        return
    posed = {c["view"]: np.asarray(c["R"], dtype=float) for c in result["cameras"] if c["registered"]}
    angles = mirror_angles_deg(posed, figures["reference_view"])
    figures["mirror_rotation_deg"] = {str(view): angle for view, angle in angles.items()}
    for camera in result["cameras"]:
        if camera["registered"]:
            camera["mirror_rotation_deg"] = angles[camera["view"]]


def _moved_camera_result(result: dict, view: int, degrees: float, camera_rel_gap: float,
                         on_rays: bool = False, abs_gap: float | None = None) -> dict:
    """``result`` made again, every certificate genuine, around camera ``view`` rotated by
    ``degrees`` about its centre (K kept): the points triangulated anew in the moved cameras, the
    camera certificate solved with ``camera_rel_gap`` on them, each searched camera called
    certified exactly when its claim holds (camera_claim), and the counts to match. The summary's
    camera_claim text is left as it was. ``abs_gap``: the result solved with it instead.
    ``on_rays``: track 0 loses its observation in ``view`` (it stays certified), and every other
    point is returned uncertified, placed on the moved camera's ray through its observation
    there."""
    from geocert.jobs.runner import solve_job
    from geocert.core.geometry import norm_cost
    from geocert.formulations.reconstruction import camera_claim
    from geocert.verify.reconstruction import camera_maps

    result = copy.deepcopy(result)
    certificate, options = result["certificate"], result["certificate"]["options"]
    options["camera_rel_gap"] = camera_rel_gap
    if abs_gap is not None:
        options["abs_gap"] = abs_gap
    angle = math.radians(degrees)
    turn = np.array([[math.cos(angle), 0, math.sin(angle)], [0, 1, 0], [-math.sin(angle), 0, math.cos(angle)]])
    camera = result["cameras"][view]
    K, R, t = (np.array(camera[name], dtype=float) for name in ("K", "R", "t"))
    R, t = turn @ R, turn @ t
    camera.update(R=R.tolist(), t=t.tolist(), P=(K @ np.column_stack([R, t])).tolist(), center=(-R.T @ t).tolist())
    _restate_mirror_angles(result)
    if on_rays:
        track = certificate["data"]["tracks"][0]
        where = track["views"].index(view)
        del track["views"][where], track["points"][where], result["points"][0]["observations"][where]
    registered = [c for c in result["cameras"] if c["registered"]]
    certificate["data"]["cameras"] = [c["P"] for c in registered]
    own = {name: options[name] for name in ("norm", "rel_gap", "abs_gap", "max_residual")}
    with loose_gaps():
        points = solve_job({"kind": "triangulation", "options": {**own, "certificate": "full"},
                            "data": {"cameras": certificate["data"]["cameras"], "tracks": certificate["data"]["tracks"]}})
    certificate["items"] = points["certificate"]["items"]
    for point, solved in zip(result["points"], points["tracks"]):
        point.update({name: solved[name] for name in ("point", "at_infinity", "cost", "lower_bound", "gap", "status",
                                                      "certified", "certificate")})
    if on_rays:
        P, centre = np.array(camera["P"]), np.array(camera["center"])
        for point, claim in zip(result["points"][1:], certificate["items"][1:]):
            _, u, v = next(o for o in point["observations"] if o[0] == view)
            ray = np.linalg.solve(P[:, :3], [u, v, 1.0])  # in front of the camera: positive depth
            X = centre + np.linalg.norm(np.array(point["point"]) - centre) * ray / np.linalg.norm(ray)
            for record_ in (point, claim):
                record_.pop("proof", None)
                record_.update(point=X.tolist(), certified=False, status="not_certified", cost=None,
                               lower_bound=None, gap=None)
            point["certificate"] = None
    rehash(certificate)
    if on_rays:  # every placed point, certified or not, as the forger's maps (the verifier's hold certified ones)
        maps = [{"source": [p["point"] for p in result["points"] if p["point"] is not None
                            and any(o[0] == c["view"] for o in p["observations"])],
                 "target": [o[1:] for p in result["points"] if p["point"] is not None
                            for o in p["observations"] if o[0] == c["view"]]} for c in registered]
    else:
        maps = camera_maps(result["points"], registered)
    with loose_gaps():
        cameras = solve_job({"kind": "resection", "data": {"maps": maps},
                             "options": {**own, "rel_gap": camera_rel_gap, "certificate": "full"}})["certificate"]
    result["camera_certificate"] = cameras
    dof = camera_claim.degrees_of_freedom([c["K"] for c in registered])
    for c, entry, claim in zip(registered, maps, cameras["items"]):
        source, target = np.array(entry["source"]), np.array(entry["target"])
        projected = np.hstack([source, np.ones((len(source), 1))]) @ np.array(c["P"]).T
        cost = norm_cost(target - projected[:, :2] / projected[:, 2:3], options["norm"])
        # the tolerance's formula, as the forger applies it (camera_claim.tolerance refuses a gap beyond its cap)
        tolerance = (1 + camera_claim.allowance(len(source), dof, options["norm"])) / (1 - camera_rel_gap) - 1
        certified = camera_claim.within(cost, claim["lower_bound"], tolerance, options["abs_gap"])
        c.update(cost=cost, searched=True, free_camera=None, points=len(source), degrees_of_freedom=dof,
                 tolerance=tolerance,
                 certified=certified, status="optimal" if certified else "not_certified",
                 lower_bound=claim["lower_bound"], gap=cost - claim["lower_bound"], optimal_cost=claim["cost"])
    squared = []
    for point in result["points"]:
        X = np.array([*point["point"], 1.0])
        for w, u, v in point["observations"]:
            image = np.array(result["cameras"][w]["P"]) @ X
            squared.append(float(np.sum((image[:2] / image[2] - [u, v]) ** 2)))
    count = sum(c["certified"] for c in result["cameras"])
    points_certified = sum(p["certified"] for p in result["points"])
    result["summary"].update(rms_reprojection_px=math.sqrt(sum(squared) / len(squared)), cameras_certified=count,
                             cameras_certified_fraction=count / len(result["cameras"]), observations=len(squared),
                             points_certified=points_certified,
                             points_certified_fraction=points_certified / len(result["points"]))
    _cameras_stage(result).update(certified=count, searched=len(registered))
    next(stage for stage in result["stages"] if stage["name"] == "structure")["certified"] = points_certified
    every = points_certified == len(result["points"])
    result["stats"].update(certified=int(every), statuses={"optimal": 1} if every else {})
    bounded = [c for c in result["cameras"] if c["registered"] and c["status"] not in ("not_run", "cancelled")]
    doubtful = len(bounded) >= 2 and sum(not c["certified"] for c in bounded) > 0.5 * len(bounded)
    warnings = [w for w in result["summary"]["warnings"] if w["code"] != "reconstruction_doubtful"]
    result["summary"].update(doubtful=doubtful, warnings=[{"code": "reconstruction_doubtful", "detail": "most"}]
                             * doubtful + warnings)
    return result


class TestCameraToleranceFromOptions:
    """A camera moved after the fact is refused as certified at the genuine camera_rel_gap (0.25):
    rotated by 1 degree about its centre, its points triangulated anew in the moved cameras and
    its resection solved on them, it costs 1,190 against a proven bound of 3.1. But camera_rel_gap
    is accepted up to 1 and enters every camera's tolerance as 1 / (1 - camera_rel_gap): at 0.999
    the tolerance is 999, and the same result verifies with all six cameras "certified", the moved
    one included, beside a summary whose camera_claim still says camera_rel_gap 0.25. Likewise
    abs_gap, unbounded: solved with abs_gap 1e6, the camera rotated 20 degrees and every point
    verify as certified beside an RMS of 86 px (true as the scope states it; said nowhere a user
    looks first)."""

    def test_a_moved_camera_called_certified_is_refused(self, calibrated_reconstruction):
        forged = _moved_camera_result(calibrated_reconstruction, 4, 1.0, 0.25)
        camera = forged["cameras"][4]
        assert not camera["certified"] and camera["cost"] > 100 * camera["lower_bound"]
        assert verify_any(forged).valid  # the moved camera, honestly uncertified
        camera.update(certified=True, status="optimal", bound_reason=None)  # (its words cleared: review 60)
        count = sum(c["certified"] for c in forged["cameras"])
        forged["summary"].update(cameras_certified=count, cameras_certified_fraction=count / len(forged["cameras"]))
        _cameras_stage(forged)["certified"] = count
        assert refused(forged)["check"] == "returned"

    def test_a_moved_camera_certified_by_a_camera_rel_gap_near_1_is_refused(self, calibrated_reconstruction):
        forged = _moved_camera_result(calibrated_reconstruction, 4, 1.0, 0.999)
        assert forged["cameras"][4]["certified"] and forged["cameras"][4]["tolerance"] > 900
        assert "camera_rel_gap 0.25" in forged["summary"]["camera_claim"]
        assert refused(forged)["check"] == "options"  # the gaps are capped (camera_claim.MAX_REL_GAP, MAX_ABS_GAP)

    def test_a_moved_camera_certified_by_a_huge_abs_gap_is_refused(self, calibrated_reconstruction):
        forged = _moved_camera_result(calibrated_reconstruction, 4, 20.0, 0.25, abs_gap=1e6)
        assert all(c["certified"] for c in forged["cameras"]) and forged["summary"]["points_certified"] == 16
        assert forged["summary"]["rms_reprojection_px"] > 50
        assert refused(forged)["check"] == "options"  # the gaps are capped (camera_claim.MAX_REL_GAP, MAX_ABS_GAP)


class TestCameraCertifiedOnUncertifiedPoints:
    """A camera's certificate is built on every returned point, certified or not, and an
    uncertified point's position is backed by no proof: camera 4 rotated 20 degrees about its
    centre, its tracks' points returned uncertified on its own rays (one track, not seen by it,
    certified, so the certificate has a claim), costs 0 on them and verifies as "certified"
    beside an RMS of 150 px."""

    def test_a_camera_certified_on_points_placed_on_its_own_rays_is_refused(self, calibrated_reconstruction):
        forged = _moved_camera_result(calibrated_reconstruction, 4, 20.0, 0.25, on_rays=True)
        camera = forged["cameras"][4]
        assert camera["certified"] and camera["cost"] < 1e-12 and forged["summary"]["rms_reprojection_px"] > 50
        assert forged["summary"]["points_certified"] == 1
        assert refused(forged)["check"] == "returned"


class TestUnitOnExactData:
    """A genuine stratified certificate of exact data: the solver's unit is 1 over its first
    incumbent's cost (about 1), and the cost claimed at the rounded solution a rounding error
    (1e-31). checked_unit refused it (the claimed cost was not within UNIT_RANGE in the programs'
    units), so a reconstruction's calibration certificate on exact tracks failed its verifier. A
    unit of order 1 enlarges no bound; the subnormal and far units stay refused."""

    def test_a_unit_near_1_is_accepted_whatever_the_cost(self):
        from geocert.formulations.autocalibration.proofs import checked_unit

        assert checked_unit(1.526, "regions/0/unit", 1.3e-31) == 1.526

    @pytest.mark.parametrize("unit", [TINY, 1e-300, 1e-5, 1e5, 1e300])
    def test_a_unit_far_from_1_and_from_the_cost_is_refused(self, unit):
        from geocert.formulations.autocalibration.proofs import checked_unit
        from geocert.core.strict import Invalid

        with pytest.raises(Invalid):
            checked_unit(unit, "regions/0/unit", 1.3e-31)


class TestDoubtfulTied:
    """summary.doubtful and its warning (claims._doubts: most bounded cameras uncertified, many
    observations rejected, many cameras dropped) were read by no check: the warning a user reads
    first could be removed. Now recomputed from the cameras and the summary's counts."""

    @staticmethod
    def doubtful(result: dict) -> dict:
        """The genuine result with its certified cameras called uncertified (a weaker claim, each
        count to match): then most bounded cameras are not certified, which is doubtful."""
        result = copy.deepcopy(result)
        for camera in result["cameras"]:  # still bounded by their certified resections
            if camera["certified"]:
                camera.update(certified=False, status="not_certified")
        result["summary"].update(cameras_certified=0, cameras_certified_fraction=0.0)
        _cameras_stage(result)["certified"] = 0
        return result

    def test_the_genuine_result_says_whether_it_is_doubtful(self, calibrated_reconstruction):
        assert calibrated_reconstruction["summary"]["doubtful"] is False
        assert verify_any(calibrated_reconstruction).valid

    def test_a_doubtful_result_unsaid_is_refused(self, calibrated_reconstruction):
        forged = self.doubtful(calibrated_reconstruction)
        assert "doubtful" in refused(forged)["detail"]
        forged["summary"]["doubtful"] = True
        forged["summary"]["warnings"].insert(0, {"code": "reconstruction_doubtful", "detail": "most cameras"})
        report = verify_any(forged)
        assert report.valid, report.first_failure


class TestCalibrationCertificateOfCalibratedCameras:
    """The incremental registration builds its projective cameras as K [R | t] with one K, so the
    calibration certificate proves that K upgrades cameras which already assume it, not that the
    tracks fix K (metric cost about 1e-28). The result must say so: the autocalibration stage's
    ``cameras_built_with_one_K``, recomputed from the certificate's cameras, and the
    ``certified_K_of_calibrated_cameras`` warning beside it."""

    def test_cameras_built_with_one_K_are_recognised_and_projective_ones_are_not(self):
        from scipy.spatial.transform import Rotation

        from geocert.formulations.reconstruction.calibration_claim import built_with_one_K

        K = np.array([[800.0, 0.5, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])
        rng = np.random.default_rng(4)
        cameras = [K @ np.c_[Rotation.random(random_state=i).as_matrix(), rng.normal(size=3)] for i in range(5)]
        assert built_with_one_K(cameras) and built_with_one_K([-2.0 * P for P in cameras])
        H = rng.normal(size=(4, 4))
        assert not built_with_one_K([P @ H for P in cameras])
        other = np.diag([1.01, 1.0, 1.0]) @ K
        assert not built_with_one_K(cameras[:4] + [other @ np.linalg.solve(K, cameras[4])])

    def test_the_genuine_result_says_so(self, calibrated_reconstruction):
        stage = next(s for s in calibrated_reconstruction["stages"] if s["name"] == "autocalibration")
        assert stage["cameras_built_with_one_K"] is True
        assert "certified_K_of_calibrated_cameras" in [w["code"] for w in calibrated_reconstruction["summary"]["warnings"]]
        assert verify_any(copy.deepcopy(calibrated_reconstruction)).valid

    def test_the_warning_left_out_is_refused(self, calibrated_reconstruction):
        forged = copy.deepcopy(calibrated_reconstruction)
        forged["summary"]["warnings"] = [w for w in forged["summary"]["warnings"]
                                         if w["code"] != "certified_K_of_calibrated_cameras"]
        assert refused(forged)["check"] == "returned"

    def test_the_stage_denying_it_is_refused(self, calibrated_reconstruction):
        forged = copy.deepcopy(calibrated_reconstruction)
        stage = next(s for s in forged["stages"] if s["name"] == "autocalibration")
        stage["cameras_built_with_one_K"] = False
        forged["summary"]["warnings"] = [w for w in forged["summary"]["warnings"]
                                         if w["code"] != "certified_K_of_calibrated_cameras"]
        assert refused(forged)["check"] == "returned"
