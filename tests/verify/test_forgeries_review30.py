"""Review 30 (issue 33): a hostile review of what the last stop added: the calibration tie's centred
room decided by the verifier's own re-adjustment (calibration_tie._centred_reference, centred_fit),
the principal-point records' figures named unchecked in the report's scope, the reconstruction
stage records' completeness (checks.COMPLETE), plane_sublevel's chirality rows charged by rows x
boxes, the direct method's per-view proven focal intervals, and the bilinear verification on
core/csc.py's numpy CSC.

Found (each test marked xfail below fails on main's verifier, a false claim accepted):

1. A principal-point record's other figures, read as checked: the report's scope names the
   records' observations and chi2 as the pipeline's, unchecked, and says "their shape and
   agreement with themselves are checked". K_free is not tied to anything either (the room no
   longer follows from it): the stored run's adjustment record with K_free's focal length 5,000 px
   (the cameras' 797), skew 3 and principal point (1000, 1000), outside a 640 x 480 image,
   verifies; so do a chi2 of -1 (a chi-square is never negative) and a K_free whose focal length
   is the subnormal 5e-324 (the calibration-matrix test takes it as positive). What it buys: the
   off-centre run (principal point near (349, 220) px in 640 x 480 images) with the images' size
   restated 460 px wide in the hashed input labels and the cameras (rehashed), the adjustment's
   K_free moved inside that middle half (so its "estimated: true" stands, though the returned
   cameras' principal point lies outside it), the registration's record "held at the centre":
   the verifier's own free fit lies outside the middle half, grants the centred room, and a
   calibration certificate built at the restated centre with 1.03 times the focal length (823.6
   px against 799.6; 3,711 px^2 on the shared observations, 3,846 allowed) verifies. With the
   adjustment's K_free left the free fit's it is refused. Cause: the shape
   check (reconstruction_members._check_record_shape) types K_free and the chi2 but holds neither
   to what it is, and the scope's sentence names only two of the figures. Fix: name every figure
   the verifier does not replay (K_free, chi2, observations, inside_middle_half as read off
   K_free) in principal_point_records, and refuse what no fit can write (a negative chi2, a
   focal length below a normal float or outside the kind's focal range); where the adjustment
   says estimated, judge the middle half from the returned cameras' principal point (the K each
   P fixes), not from K_free.
2. Completeness is presence, not content: review 29's fix (check_complete over COMPLETE) asks that
   each member of a stage record be present, "null where it has nothing to state", and types few.
   A done stage's member set to null or emptied verifies: the autocalibration stage's
   motion_warnings emptied (its critical_motion still "critical_motion": the warning's text
   gone), its reason null; the adjustment's principal-point record null (and with it the
   report's "unchecked" sentence about it: the record's figures vanish from the scope); the
   adjustment's starts emptied and rms_px_after null; the registration's focal_rounds and
   rms_reprojection_px null. On a run of today's form (input labels and records stated, the scene
   at the images' centre) the adjustment's record nulled, its starts emptied and rms_px_after
   null verify too, where the registration's record nulled is refused. Cause: COMPLETE lists names, and null is taken wherever a member is,
   not only where its writer writes null. Fix: type each member as its writer writes it on the
   stage's path (lists stay lists; the warnings tied to critical_motion; a record where the
   options ask for the test is a record, not null).
3. The verifier's own re-adjustment is not charged (cost): centred_fit.fit_with_intrinsics, run
   by the calibration tie once or twice (CENTRED_HELD: the free fit, then the centred one) under
   the document's work budget, charges nothing for its up to SOLVES (45) solves, each summing a
   block for every pair of observations of a point (up to MAX_PAIRS, 100,000) and a dense system
   of 6 * views + 3 unknowns (views up to MAX_VIEWS, 100). Measured on a synthetic scene of 100
   views, 1,000 points seen 10 times (10,000 observations, 100,000 pairs), one fit run inside a
   budget of 10 units: 3.3 to 3.7 s of CPU at 0.5 px noise (converged), 12.0 to 12.8 s at 50 px
   (declined after its solves), two runs each, load average 7.4 to 8.4 on 2 cores; none of it
   drawn from the budget, and the tie may run two fits. Fix: charge the pairs and observations
   each solve sums (strict.charge) before it, so a document pays for its fits by its size.
4. The adjustment stage's K, which docs/certificate.md calls "certified, not informational: the
   returned cameras' K when they share one", is only typed (reconstruction_stages._figure: a
   calibration matrix with positive focal lengths): the stored run (six cameras sharing one K,
   summary.calibration model shared) with the stage's K at ten times the focal length (7,970 px),
   its principal point at u = -321 (outside the image), or a skew of 1.5 verifies. Cause: no
   check reads the stage's K beside the cameras' (the autocalibration stage's is tied to the
   calibration certificate; the adjustment's to nothing). Fix: where the registered cameras share
   one K (the K each P fixes: intrinsics_of), require the stage's K to be it (calibration_claim
   .same), else null or what the model leaves shared.
5. An item's informational words, untyped: a reconstruction camera's ``reason`` 1 verifies, where
   docs/certificate.md says every item's reason is "null or of its type" (a string). Fix: type it
   with the cameras' other members (verify.notes).
6. The per-view principal points' record says each view's estimated principal point lies in the
   middle half of its image (inside_middle_half), and the verifier reads it as written
   (reconstruction_members._check_principal_points_per_view): review 16's per-view run (each
   view's principal point within 15 px of the centre of 640 px images) with its images restated
   1,260 px wide (the cameras' image_size and the hashed input labels, rehashed; the calibration
   certificate solved again at that size) verifies, three views' principal points (u 310.6 to
   313.8) left of the middle half [315, 945], the record still saying inside, estimated (the
   shared record's K_free, u 322, inside, agrees). Fix: judge it as _inside_middle_half does the
   shared record's, from each returned camera's principal point (intrinsics_of(P)) and its view's
   image size.

Tried and refused (plain tests below): the autocalibration stage's critical_motion set to null
beside the summary's (motion_claim judges it again); the restated image size beside the
adjustment's genuine K_free (class 1's control); the bilinear certificates' duals made subnormal,
scaled by 1e-300 or 1e300, an entry 1e308 or the smallest normal, nudged one ulp, zeros made -0.0:
the numpy CSC path's verdict is scipy's on each (80 random perturbations tried, none differing);
their data's coordinates made -0.0, subnormal or 1e300, the basis scaled by 1e-300 (rehashed):
refused alike on both paths; the CSC product itself against scipy's on entries holding inf, NaN,
subnormals and -0.0, to the bit (NaN where scipy's is NaN).

Read and judged sound (no test): direct_sublevel.check_views (each view's ends from its own forms
over every view's program, BMAX_i = |p_i2|^2, the scope's range per view from the per-view focal
rows, the cost_increase floor shared with the one-focal check; a program of the stored 12-view
document, 2,841 rows charged, builds and bounds in about 19 ms, its dual vector alone some 3,700
size units); plane_sublevel's chirality blocks (CHIRALITY_PAIRS pairs at a time, rows / (65,536 /
boxes) steps, charged ceil(boxes x rows / 64) units); the CSC's explicit zeros (counted by nnz as
scipy's, read False by != 0); a member name repeated (strict.load_document refuses it).
Accepted and read as documented (no test): the stage figures docs/certificate.md calls
informational (RMS values, thresholds, linear_K, focal_rounds, rotation_noise_rad) edited; an
autocalibration stage's certificate summary or determinacy null (the brief detail, not hashed).
"""

from __future__ import annotations

import base64
import copy
import json
import re

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.support import stage as _stage
from tests.verify.test_forgeries import raw_pack, stored
from tests.verify.test_forgeries_review16 import per_view  # noqa: F401 (a fixture)
from tests.verify.test_registration_record_form import off_centre  # noqa: F401 (a fixture)


def _verify(document: dict):
    return verify_any(json.loads(json.dumps(document)))


def _refused(document: dict, words: str = "") -> dict:
    report = _verify(document)
    assert not report.valid, "a forged certificate was accepted"
    assert words in report.first_failure["detail"], report.first_failure
    return report.first_failure


# 1. A principal-point record's figures the scope does not name

def _adjustment_record(result: dict) -> dict:
    return _stage(result, "bundle_adjustment")["principal_point"]


def test_the_genuine_record_and_the_scopes_sentence():
    """What the forgeries below start from: the genuine run's record (the test ran on 96
    observations, K_free near the returned K, inside the middle half) verifies, its scope naming
    observations and chi2 as the pipeline's."""
    result = stored("reconstruction")
    record = _adjustment_record(result)
    assert record["chi2"] > 0 and record["inside_middle_half"] is True
    assert abs(record["K_free"][0][0] - 797) < 10
    report = _verify(result)
    assert report.valid, report.first_failure
    said = report.scope["principal_point_records"]
    assert said.startswith("unchecked:") and "observations, chi2" in said


RECORD_EDITS = {
    "K_free far from every camera": dict(K_free=[[5000.0, 3.0, 1000.0], [0.0, 7000.0, 1000.0], [0.0, 0.0, 1.0]],
                                         inside_middle_half=False),
    "chi2 negative": dict(chi2=-1.0),
    "K_free's focal length subnormal": dict(K_free=[[5e-324, 0.0, 311.9], [0.0, 5e-324, 234.1], [0.0, 0.0, 1.0]]),
}


@pytest.mark.parametrize("edit", list(RECORD_EDITS))
def test_a_record_figure_edited_is_refused_or_named_unchecked(edit):
    """Accepted only with the scope's sentence naming the figure edited among the pipeline's,
    unchecked (K_free), or refused where no fit writes it (a negative chi2, a subnormal focal)."""
    result = stored("reconstruction")
    _adjustment_record(result).update(copy.deepcopy(RECORD_EDITS[edit]))
    report = _verify(result)
    if report.valid:
        said = report.scope.get("principal_point_records", "")
        assert edit.startswith("K_free far") and "K_free" in said.split(":", 1)[1].split("which")[0], said


# What an unchecked K_free buys: the adjustment's record says its free fit lies inside the middle
# half of the images (so "estimated: true" stands beside the returned cameras' principal point,
# (349, 220) px), and the images' size, a hashed datum a forger rehashes, is restated 460 px wide, so
# the verifier's own free fit (u 349, past 3/4 of 460) lies outside the middle half and grants the
# centred room. A calibration certificate built at the restated centre (229.5, 239.5) with 1.03 times
# the focal length (823.6 px against the returned 799.6) then verifies: measured, 3,711 px^2 on the
# shared observations, 3,846 allowed (the centred model's 3,586 plus its share of the misfit).

FAKE_SIZE = (460.0, 480.0)


def _carrying(result: dict, data: dict) -> dict:
    """tests.verify.test_calibration_tie.carrying, with the stage's ranges the certificate's (its
    data's image size is not the result's)."""
    from geocert.jobs.runner import solve_job
    from geocert.formulations.reconstruction import calibration_claim
    from tests.verify.test_calibration_tie import registered_at

    options = dict(result["calibration_certificate"]["options"])
    other = solve_job({"kind": "autocalibration", "data": data, "options": options})
    assert all(stage["certified"] for stage in other["stages"]) and verify_any(other).valid
    forged = registered_at(result, data)
    forged["calibration_certificate"] = other["certificate"]
    stage = _stage(forged, "autocalibration")
    stage.update(K=other["K"], intrinsics=other["intrinsics"])
    for given, claim in zip(stage["stages"], other["certificate"]["items"]):
        given.update({name: claim[name] for name in ("cost", "lower_bound", "gap", "status", "certified")})
    summary = forged["summary"]["calibration"]
    summary["certified_K"] = other["K"]
    summary["difference"] = difference = calibration_claim.difference(np.asarray(summary["K"]), np.asarray(other["K"]))
    for warning in forged["summary"]["warnings"]:
        if warning["code"] == "returned_K_not_certified":
            warning["detail"] = re.sub(r"focal [^,]*, principal point [0-9.]+ px",
                                       f"focal {difference['focal_percent']:+.2f}%, principal point "
                                       f"{difference['principal_point_px']:.1f} px", warning["detail"])
    return forged


def _resized_centred_forgery(off_centre: dict, K_free_inside: bool) -> dict:  # noqa: F811
    from tests.verify.test_forgeries import rehash
    from tests.verify.test_forgeries_review18 import _reposed

    width, height = FAKE_SIZE
    K = np.array(next(c for c in off_centre["cameras"] if c.get("registered"))["K"], dtype=float)
    K[0, 0] *= 1.03
    K[1, 1], K[0, 1], K[:2, 2] = K[0, 0], 0.0, [(width - 1) / 2, (height - 1) / 2]
    data = _reposed(off_centre, K)
    data["image_size"] = [width, height]
    forged = _carrying(off_centre, data)
    genuine = _stage(off_centre, "projective")["principal_point"]
    _stage(forged, "projective")["principal_point"].update(
        estimated=False, inside_middle_half=False, K_free=copy.deepcopy(genuine["K_free"]))
    adjusted = _stage(forged, "bundle_adjustment")["principal_point"]
    if K_free_inside:
        adjusted["K_free"][0][2], adjusted["K_free"][1][2] = (width - 1) / 2 + 10.0, (height - 1) / 2
    else:
        adjusted["inside_middle_half"] = False  # what its K_free says of the restated images
    for camera in forged["cameras"]:
        camera["image_size"] = [width, height]
    labels = forged["certificate"]["data"]["input_labels"]
    labels["image_sizes"] = [[width, height] for _ in labels["image_sizes"]]
    rehash(forged["certificate"])
    return forged


def test_the_off_centre_runs_principal_point_lies_past_the_restated_middle_half(off_centre):  # noqa: F811
    """The premise: the returned cameras and both records put u near 349 px, inside the middle half
    of the 640 px images and outside that of 460 px ones (|u - 230| > 115)."""
    width = FAKE_SIZE[0]
    for name in ("projective", "bundle_adjustment"):
        u = _stage(off_centre, name)["principal_point"]["K_free"][0][2]
        assert abs(u - 320) <= 160 and abs(u - width / 2) > width / 4
    assert _verify(off_centre).valid


def test_the_restated_size_beside_the_genuine_adjustment_record_is_refused(off_centre):  # noqa: F811
    """The control: the size restated, the adjustment's K_free left the free fit's (outside the
    middle half, as its record then says): it says estimated, and its test cannot have passed."""
    _refused(_resized_centred_forgery(off_centre, K_free_inside=False), "estimated is true")


def test_the_restated_size_beside_k_free_moved_inside_is_refused(off_centre):  # noqa: F811
    _refused(_resized_centred_forgery(off_centre, K_free_inside=True))


# 2. Stage members present but null or emptied

NULLED = [("autocalibration", "motion_warnings", []), ("autocalibration", "reason", None),
          ("bundle_adjustment", "principal_point", None), ("bundle_adjustment", "starts", []),
          ("bundle_adjustment", "rms_px_after", None), ("projective", "focal_rounds", None),
          ("projective", "rms_reprojection_px", None)]


def test_the_genuine_stages_state_what_is_nulled_below():
    """Each member nulled below holds something in the genuine done stage (the autocalibration
    stage's one warning is the critical motion the summary states)."""
    result = stored("reconstruction")
    for name, member, _ in NULLED:
        record = _stage(result, name)
        assert record["status"] == "done" and record[member] not in (None, [], {}), (name, member)
    assert [w["code"] for w in _stage(result, "autocalibration")["motion_warnings"]] == ["critical_motion"]
    assert result["summary"]["critical_motion"] == "critical_motion"


@pytest.mark.parametrize("name, member, value", NULLED, ids=[f"{n}/{m}={v!r}" for n, m, v in NULLED])
def test_a_done_stages_member_nulled_or_emptied_is_refused(name, member, value):
    result = stored("reconstruction")
    _stage(result, name)[member] = value
    _refused(result)


@pytest.fixture(scope="module")
def centred_today() -> dict:
    """A run of today's form (it states its input labels and records), the synthetic scene at the
    images' centre: both principal-point tests ran (estimated false)."""
    from geocert.jobs.runner import solve_job
    from tests.verify.test_forgeries_review18 import _scene_job

    result = solve_job(_scene_job({}, points=200))
    for name in ("projective", "bundle_adjustment"):
        assert _stage(result, name)["principal_point"]["estimated"] is False
    assert _verify(result).valid
    return result


TODAYS_NULLED = [("bundle_adjustment", "principal_point", None), ("bundle_adjustment", "starts", []),
                 ("bundle_adjustment", "rms_px_after", None)]


@pytest.mark.parametrize("name, member, value", TODAYS_NULLED, ids=[f"{n}/{m}={v!r}" for n, m, v in TODAYS_NULLED])
def test_todays_form_with_a_done_stages_member_nulled_is_refused(centred_today, name, member, value):
    result = copy.deepcopy(centred_today)
    assert _stage(result, name)[member] not in (None, [])
    _stage(result, name)[member] = value
    _refused(result)


def test_todays_form_with_the_registrations_record_nulled_is_refused(centred_today):
    """The control: the registration's record nulled is refused (calibration_tie: the run's
    registration tests the principal point, so it states its record)."""
    result = copy.deepcopy(centred_today)
    _stage(result, "projective")["principal_point"] = None
    _refused(result, "principal_point")


def test_the_stages_critical_motion_nulled_is_refused():
    """The control: the autocalibration stage's critical_motion nulled, with its warnings and
    reason, is judged again (motion_claim) and refused."""
    result = stored("reconstruction")
    _stage(result, "autocalibration").update(motion_warnings=[], critical_motion=None, reason=None)
    _refused(result, "critical_motion")


# 3. The centred re-adjustment, uncharged

def _ring_scene(views: int, points: int, seen: int, noise: float, seed: int = 0):
    """``views`` cameras (f 800 px, principal point (320, 240)) on a ring looking at ``points``
    points near the origin, each seen by ``seen`` of them, ``noise`` px of Gaussian noise."""
    rng = np.random.default_rng(seed)
    X = np.c_[rng.normal(size=(points, 3)), np.ones(points)]
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    P = []
    for k in range(views):
        a = 2 * np.pi * k / views
        C = np.array([6 * np.cos(a), 6 * np.sin(a), 0.5 * np.sin(3 * a)])
        z = -C / np.linalg.norm(C)
        x = np.cross([0.0, 0.0, 1.0], z)
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(z, x), z])
        P.append(K @ np.c_[R, -R @ C])
    P = np.array(P)
    view, point, uv = [], [], []
    for p in range(points):
        for v in rng.choice(views, seen, replace=False):
            q = P[v] @ X[p]
            view.append(v), point.append(p), uv.append(q[:2] / q[2] + rng.normal(scale=noise, size=2))
    return P, X, np.array(view), np.array(point), np.array(uv)


def test_the_centred_fit_is_charged_for_the_pairs_it_sums():
    """Within a verification's budget, the fit pays at least a unit for each pair of observations
    of a point its solves sum (each solve sums all of them), before summing them."""
    from geocert.core import strict
    from geocert.formulations.reconstruction import centred_fit

    P, X, view, point, uv = _ring_scene(views=20, points=300, seen=6, noise=0.5)
    pairs = int(np.sum(np.bincount(point) ** 2))
    assert pairs <= centred_fit.MAX_PAIRS and len(P) <= centred_fit.MAX_VIEWS
    budget = 10 ** 9
    with strict.work_budget(budget):
        fitted = centred_fit.fit_with_intrinsics(P, None, X, view, point, uv)
        spent = budget - strict._WORK.get()[0]
    assert fitted is not None  # the fit ran (converged): what it summed was paid for
    assert spent >= pairs, f"{spent} units charged for solves summing {pairs} pairs each"


def test_a_centred_fit_its_budget_cannot_pay_declines():
    """A budget too small for one solve: the fit declines (None: the tie then holds the certificate
    to the returned cameras, stricter) and charges nothing it did not run, refusing nothing."""
    from geocert.core import strict
    from geocert.formulations.reconstruction import centred_fit

    P, X, view, point, uv = _ring_scene(views=20, points=300, seen=6, noise=0.5)
    assert centred_fit.fit_with_intrinsics(P, None, X, view, point, uv) is not None  # unbudgeted, it converges
    budget = int(np.sum(np.bincount(point) ** 2))  # less than a solve's pairs and observations
    with strict.work_budget(budget):
        assert centred_fit.fit_with_intrinsics(P, None, X, view, point, uv) is None
        assert 0 <= strict._WORK.get()[0] <= budget


# 4. The adjustment stage's K, said certified, tied to nothing

ADJUSTMENT_K_EDITS = {
    "focal length times 10": lambda K: K[0].__setitem__(0, 10 * K[0][0]) or K[1].__setitem__(1, 10 * K[1][1]),
    "principal point outside the image": lambda K: K[0].__setitem__(2, -321.0),
    "skew": lambda K: K[0].__setitem__(1, 1.5),
}


def test_the_genuine_adjustment_k_is_the_cameras_shared_one():
    """What docs/certificate.md says of the adjustment stage's K ("certified, not informational:
    the returned cameras' K when they share one") holds of the genuine run: its cameras share one
    K (summary.calibration's, model shared) and the stage states it."""
    result = stored("reconstruction")
    Ks = [c["K"] for c in result["cameras"] if c.get("registered")]
    assert all(K == Ks[0] for K in Ks) and result["summary"]["calibration"]["model"] == "shared"
    assert _stage(result, "bundle_adjustment")["K"] == Ks[0] == result["summary"]["calibration"]["K"]


@pytest.mark.parametrize("edit", list(ADJUSTMENT_K_EDITS))
def test_the_adjustment_stages_k_edited_is_refused(edit):
    result = stored("reconstruction")
    ADJUSTMENT_K_EDITS[edit](_stage(result, "bundle_adjustment")["K"])
    _refused(result)


# 5. An item's informational words, untyped

def test_a_cameras_reason_a_number_is_refused():
    """docs/certificate.md: every item's ``reason`` is informational, "each must be null or of its
    type" (a string); a camera's reason 1 verifies."""
    result = stored("reconstruction")
    assert result["cameras"][0]["reason"] is None
    result["cameras"][0]["reason"] = 1
    _refused(result)


# 6. The per-view principal points' record: inside_middle_half read as written

RESTATED_WIDTH = 1260.0  # middle half [315, 945]: the shared K_free's u (322) inside, three views' (310.6 to 313.8) not


def _restated_wide(result: dict) -> dict:
    """The per-view run with its images restated RESTATED_WIDTH wide (the cameras' image_size, the
    hashed input labels, rehashed; the calibration certificate solved again on its data at that
    size, as the tie asks its size be the views')."""
    from tests.verify.test_forgeries import rehash

    size = [RESTATED_WIDTH, 480.0]
    data = copy.deepcopy(result["calibration_certificate"]["data"])
    data["image_size"] = size
    forged = _carrying(result, data)
    for camera in forged["cameras"]:
        camera["image_size"] = list(size)
    labels = forged["certificate"]["data"]["input_labels"]
    labels["image_sizes"] = [list(size) for _ in labels["image_sizes"]]
    rehash(forged["certificate"])
    return forged


def test_some_views_principal_points_lie_past_the_restated_middle_half(per_view):  # noqa: F811
    """The premise: the record says each view's principal point was estimated inside the middle
    half; the returned cameras' (the K each P fixes) lie within 15 px of the 640 px images' centre,
    three of them left of 315 (outside the middle half of 1,260 px images); the shared record's
    K_free (u 322) stays inside it, as its inside_middle_half says."""
    from geocert.verify.reconstruction_members import intrinsics_of

    record = _stage(per_view, "bundle_adjustment")["principal_point_per_view"]
    assert record["estimated"] is True and record["inside_middle_half"] is True
    us = [intrinsics_of(c["P"])[0, 2] for c in per_view["cameras"] if c.get("registered")]
    assert sum(abs(u - RESTATED_WIDTH / 2) > RESTATED_WIDTH / 4 for u in us) >= 3
    assert all(abs(u - 320) <= 80 for u in us)
    u_free = _stage(per_view, "bundle_adjustment")["principal_point"]["K_free"][0][2]
    assert abs(u_free - RESTATED_WIDTH / 2) <= RESTATED_WIDTH / 4


def test_per_view_principal_points_outside_the_stated_middle_half_are_refused(per_view):  # noqa: F811
    """Refused by the shared record's check (class 1): it says estimated, and the returned cameras'
    principal points (here each view's own) are judged against the restated middle half."""
    _refused(_restated_wide(per_view), "principal_point/estimated is true")


def test_per_view_principal_points_outside_the_middle_half_beside_a_shared_record_not_estimated(per_view):  # noqa: F811
    """The same forgery with the shared record's chi2 (the pipeline's, unchecked) edited below its
    threshold and estimated false: only the per-view record then says estimated, and its
    inside_middle_half is judged from each returned camera's principal point and its image."""
    forged = _restated_wide(per_view)
    _stage(forged, "bundle_adjustment")["principal_point"].update(chi2=5.0, estimated=False)
    _refused(forged, "principal_point_per_view/estimated is true")


# 7. The bilinear verification on the numpy CSC: scipy's verdicts, hostile duals

def _decoded(text: str) -> np.ndarray:
    return np.frombuffer(base64.b64decode(text), dtype="<f8").copy()


def _hostile(z: np.ndarray, how: str, j: int) -> np.ndarray:
    z = z.copy()
    if how == "one subnormal":
        z[j] = 5e-324
    elif how == "scaled 1e-300":
        z = z * 1e-300
    elif how == "zeros negative":
        z[j] = 0.0
        z[z == 0] = -0.0
    elif how == "scaled 1e300":
        z = z * 1e300
    elif how == "one 1e308":
        z[j] = 1e308
    elif how == "smallest normals":
        z[[j, (j + 7) % len(z)]] = 2.2250738585072014e-308
    else:  # one ulp up
        z = np.nextafter(z, np.inf)
    return z


HOSTILE = ["one subnormal", "scaled 1e-300", "zeros negative", "scaled 1e300", "one 1e308", "smallest normals",
           "one ulp up"]


@pytest.mark.parametrize("name", ["bilinear_l2l2", "bilinear_l1l1"])
@pytest.mark.parametrize("how", HOSTILE)
def test_the_numpy_csc_verdict_is_scipys_on_hostile_duals(monkeypatch, name, how):
    """A round's first dual vector edited as ``how`` says: the verifier on core.csc's matrix and
    on scipy.sparse's (the solver's, as before the numpy path) reach the same verdict."""
    import scipy.sparse as sp

    import geocert.verify.bilinear as verify_bilinear

    document = stored(name)
    rounds = document["certificate"]["items"][0]["proof"]["tightening"]
    edited = 0
    for r in rounds:
        at = next((k for k, z in enumerate(r["duals"]) if isinstance(z, str)), None)
        if at is not None:
            z = _decoded(r["duals"][at])
            r["duals"][at] = raw_pack(_hostile(z, how, len(z) // 3))
            edited += 1
    assert edited
    numpy_report = _verify(document)
    monkeypatch.setattr(verify_bilinear, "CscMatrix", sp.csc_matrix)
    scipy_report = _verify(document)
    assert numpy_report.valid == scipy_report.valid, (numpy_report.first_failure, scipy_report.first_failure)
    if how in ("one subnormal", "scaled 1e-300"):
        assert not numpy_report.valid  # a subnormal entry proves nothing (strict.dual_vector)


DATA_EDITS = ["a coordinate -0.0", "a coordinate subnormal", "a coordinate 1e300", "a basis entry subnormal",
              "basis entries -0.0", "the basis scaled by 1e-300"]


@pytest.mark.parametrize("name", ["bilinear_l2l2", "bilinear_l1l1"])
@pytest.mark.parametrize("how", DATA_EDITS)
def test_the_numpy_csc_verdict_is_scipys_on_hostile_data(monkeypatch, name, how):
    """The data edited (and rehashed, as a forger would): each is refused, on core.csc's matrix
    as on scipy's (the relaxations are built from the data: a product of a subnormal or -0.0
    coordinate, or a basis scaled to nothing, reads alike in both)."""
    import scipy.sparse as sp

    import geocert.verify.bilinear as verify_bilinear
    from tests.verify.test_forgeries import rehash

    document = stored(name)
    data = document["certificate"]["data"]
    if how == "a coordinate -0.0":
        data["frames"][0]["points"][0][0] = -0.0
    elif how == "a coordinate subnormal":
        data["frames"][0]["points"][0][0] = 5e-324
    elif how == "a coordinate 1e300":
        data["frames"][0]["points"][0][0] = 1e300
    elif how == "a basis entry subnormal":
        data["basis"][0][0][0] = 5e-324
    elif how == "basis entries -0.0":
        data["basis"][0][0][0] = data["basis"][1][1][1] = -0.0
    else:
        data["basis"] = (np.asarray(data["basis"]) * 1e-300).tolist()
    rehash(document["certificate"])
    numpy_report = _verify(document)
    monkeypatch.setattr(verify_bilinear, "CscMatrix", sp.csc_matrix)
    scipy_report = _verify(document)
    assert not numpy_report.valid and not scipy_report.valid
    assert numpy_report.first_failure["check"] == scipy_report.first_failure["check"]


def test_the_csc_product_is_scipys_on_nonfinite_and_subnormal_entries():
    """dense @ CscMatrix against dense @ scipy's csc_matrix of the same entries (inf, NaN,
    subnormals, -0.0, an explicit zero), to the bit (NaN where scipy's is NaN)."""
    import scipy.sparse as sp

    from geocert.core.csc import CscMatrix

    rng = np.random.default_rng(30)
    rows, cols = 7, 9
    mask = rng.random((rows, cols)) < 0.5
    r, c = np.nonzero(mask)
    values = rng.normal(size=len(r))
    values[:6] = [np.inf, -np.inf, 5e-324, -0.0, 0.0, 1e308]
    pattern, order = CscMatrix.from_triplets(r, c, (rows, cols))
    ours = CscMatrix((values[order], pattern.indices, pattern.indptr), (rows, cols))
    theirs = sp.csc_matrix((values[order], pattern.indices.copy(), pattern.indptr.copy()), shape=(rows, cols))
    for x in (rng.normal(size=(3, rows)), np.array([[np.nan, 1.0, 0.0, -0.0, 5e-324, 1e308, -1e308]]),
              np.array([[0.0] * rows]), np.array([[np.inf] + [1.0] * (rows - 1)])):
        with np.errstate(all="ignore"):
            mine, scipys = x @ ours, np.asarray(x @ theirs)
        assert np.array_equal(np.isnan(mine), np.isnan(scipys))
        keep = ~np.isnan(scipys)
        assert np.array_equal(mine[keep].view(np.int64), scipys[keep].view(np.int64))
