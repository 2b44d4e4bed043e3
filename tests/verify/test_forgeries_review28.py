"""Review 28 (issue 33): a hostile review of what the last stop added: the principal-point
record's test, the estimates' form marker, autocalibration intervals holding their value, the
stratified level, nodes, determinacy.proven, the intervals proven over planes
(prove_intervals_over_planes, plane_sublevel) and its work charge, and records missing members.

Found (each test marked xfail below fails on main's verifier, a false claim or a cost accepted):

- A false calibration claim through a record missing members: review 26's centred forgery (a
  reconstruction carrying a calibration certificate re-posed at the images' centre with 1.03 times
  the focal length, beside the registration's principal-point record saying ``estimated: false``)
  verifies again when the record leaves out ``K_free`` (inside_middle_half then read as written)
  or its ``chi2`` (the record then says the test did not run, beside 1,596 observations): the
  calibration tie takes the centred reading the forgery needs; a record of ``estimated: false``
  alone does too. (The same false claim was reachable through the documented limit that the chi2
  is not recomputed; closed: a record saying its test did not pass no longer gives the centred
  reading its room, test_forgeries_review26_left.test_a_not_estimated_record_below_its_threshold_
  gives_no_centred_room.)
- An autocalibration interval whose ``value`` is null (or absent) is passed over by the check that
  an interval holds its value (estimates.check_contains), and the affine stage's intervals are tied
  to nothing the stage returns (check_intrinsics ties a K stage's only): an interval moved off the
  returned plane together with its value, renamed, or the list emptied, all verify.
- The principal-point record (stages.bundle_adjustment.principal_point): with ``K_free`` deleted or
  null, ``inside_middle_half`` is read as written (a missing member switches the check off); its
  ``estimated: true`` is not tied to the cameras returned, whose principal points all lie at the
  image centre (the pipeline holds them there unless it estimated one).
- The intervals over planes: the verifier charges one unit of work for 50 camera-box bounds
  (plane_sublevel._kept), each about 70 us of CPU, where a unit elsewhere is one view or
  observation of a program built (about a microsecond): the budget's base alone (2,000,000 units)
  buys some 100 million camera-box bounds, and the boxes of a tree are bounded in one array
  (about 4 kB a camera-box at its peak).
- More returned members a result may leave out (the known gap of
  test_forgery_structure_properties.test_a_returned_record_missing_a_member_is_refused).

Tried and refused (kept below where no earlier review file covers the class): the
prove_intervals_over_planes option null, 1 or deleted with the proof kept (rehashed); the proof
moved into the affine stage's proof; the proof deleted with the result's proven_over_planes kept;
the option false with the proof deleted and the result's proven_over_planes kept; the result's
affine_increase alone edited; the proof's affine_increase lowered to 0 in both places; a stage's
level halved; the principal-point threshold deleted; inside_middle_half deleted with chi2 above
the threshold; a camera's image_size edited to switch the middle-half test off; nodes True or
3.0; a determinacy's proven null, absent or true; stats' counts edited. Accepted and read as
documented (no test): nodes not matching a tree's leaves (informational), the chi2 edited (not
recomputed; a negative one is genuine: the local fits' costs can fall either way, a fresh run's
radial chi2 was -1,243), a proven interval widened (a weaker true statement), tolerances deleted
and the document rehashed without the estimates' form (the report's scope says "the earlier
form"). The registration record's requirement waived by editing what it reads (a radial term
said kept, the radial model off, the stage cancelled): refused.
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.verify.checks import verify_any
from tests.support import stage as _stage
from tests.verify.test_forgeries import rehash, stored
from tests.verify.test_registration_record_form import centred_forgery, off_centre  # noqa: F401 (fixtures)


def _verify(document: dict):
    return verify_any(json.loads(json.dumps(document)))


def _refused(document: dict, words: str = "") -> dict:
    report = _verify(document)
    assert not report.valid, "a forged certificate was accepted"
    assert words in report.first_failure["detail"], report.first_failure
    return report.first_failure


# 1. Autocalibration intervals: their value, and the affine stage's tie to its plane

AFFINE = [("autocalibration_stratified", 0), ("autocalibration_five_views", 0)]


@pytest.mark.parametrize("name, stage", AFFINE + [("autocalibration_direct", 0)])
@pytest.mark.parametrize("how", ["null", "absent"])
def test_an_interval_with_no_value_moved_off_the_answer_is_refused(name, stage, how):
    """The first interval moved far off the stage's answer (its width kept) and its value made
    null or deleted: estimates.check_contains passes over an interval whose value is not a
    number, so "every stage's intervals hold their own value" (docs/certificate.md) holds of none."""
    result = stored(name)
    interval = result["stages"][stage]["determinacy"]["intervals"][0]
    width = interval["upper"] - interval["lower"]
    interval["lower"], interval["upper"] = interval["value"] + 100 * width, interval["value"] + 101 * width
    if how == "null":
        interval["value"] = None
    else:
        del interval["value"]
    _refused(result)


@pytest.mark.parametrize("name, stage", AFFINE)
def test_an_affine_interval_and_its_value_moved_off_the_plane_returned_is_refused(name, stage):
    """The interval and its value moved together to 0.5 .. 0.6 where the stage returns a plane
    whose first coordinate is about 0.01: the estimate says the data fix the plane away from the
    one returned. A K stage's values are the returned K's (check_intrinsics); the affine stage's
    are the returned plane's, and nothing checks them."""
    result = stored(name)
    assert abs(result["stages"][stage]["plane_at_infinity"][0]) < 0.1
    interval = result["stages"][stage]["determinacy"]["intervals"][0]
    interval.update(value=0.55, lower=0.5, upper=0.6)
    _refused(result)


@pytest.mark.parametrize("edit", ["renamed", "truncated", "emptied"])
def test_the_affine_intervals_name_the_planes_four_coordinates(edit):
    """The writer (autocalibration.determinacy) states plane_at_infinity[0] .. [3], in order: a
    coordinate renamed focal_x, the list cut to two, or emptied (``determined: true`` then read
    off no interval at all), all verify."""
    result = stored("autocalibration_stratified")
    determinacy = result["stages"][0]["determinacy"]
    if edit == "renamed":
        determinacy["intervals"][0]["name"] = "focal_x"
    elif edit == "truncated":
        determinacy["intervals"] = determinacy["intervals"][:2]
    else:
        determinacy["intervals"] = []
    assert determinacy["determined"] is True
    _refused(result)


def test_the_genuine_affine_intervals_are_the_planes():
    """What the tie above asks holds of the stored documents (their values are the plane's
    coordinates, to 1e-9 of each)."""
    for name, stage in AFFINE:
        record = stored(name)["stages"][stage]
        intervals = record["determinacy"]["intervals"]
        assert [i["name"] for i in intervals] == [f"plane_at_infinity[{k}]" for k in range(4)]
        for interval, coordinate in zip(intervals, record["plane_at_infinity"]):
            assert abs(interval["value"] - coordinate) <= 1e-9 * abs(coordinate)
            assert interval["lower"] <= interval["value"] <= interval["upper"]


# 2. The principal-point record of the adjustment

def _principal_point(result: dict) -> dict:
    return _stage(result, "bundle_adjustment")["principal_point"]


@pytest.mark.parametrize("how", ["deleted", "null"])
def test_inside_middle_half_flipped_with_K_free_left_out_is_refused(how):
    """Genuine: K_free's principal point (312, 234) lies inside the middle half of the 640 x 480
    images, inside_middle_half true. Flipped to false it is refused; flipped with K_free deleted
    or null, the check has nothing to read and passes (_inside_middle_half returns None). The
    pipeline writes K_free wherever it writes a chi2."""
    result = stored("reconstruction")
    record = _principal_point(result)
    assert record["inside_middle_half"] is True and record["chi2"] is not None
    if how == "deleted":
        del record["K_free"]
    else:
        record["K_free"] = None
    record["inside_middle_half"] = False
    _refused(result, "principal_point")


def test_inside_middle_half_flipped_with_K_free_kept_is_refused():
    """The same flip with K_free kept: refused (review 26's check), the control for the above."""
    result = stored("reconstruction")
    _principal_point(result)["inside_middle_half"] = False
    _refused(result, "inside_middle_half")


def test_estimated_true_beside_cameras_at_the_image_centre_is_refused():
    """``estimated: true`` with the chi2 raised above the threshold (the chi2 is not recomputed: a
    documented limit) verifies, though every camera returned has its principal point exactly at
    the image centre, where the pipeline holds it unless it estimated one (simple model). The
    cameras' P are checked: the claim "estimated" can be judged against them."""
    result = stored("reconstruction")
    stage = _stage(result, "bundle_adjustment")
    assert stage["model"] == "simple"
    for camera in result["cameras"]:
        width, height = camera["image_size"]
        assert camera["K"][0][2] == width / 2 and camera["K"][1][2] == height / 2
    _principal_point(result).update(chi2=20.0, estimated=True)
    _refused(result, "principal_point")


def test_a_camera_image_size_edited_to_switch_the_middle_half_test_off_is_refused():
    """With the registered views of two sizes, _inside_middle_half has no one size and reads the
    record as written; the sizes are the calibration certificate's, so the edit is refused."""
    result = stored("reconstruction")
    result["cameras"][0]["image_size"] = [641.0, 480.0]
    _principal_point(result)["inside_middle_half"] = False
    _refused(result)


# 2b. The registration's record left without the figures its test reads: review 26's centred
# forgery (a calibration certificate re-posed at the images' centre with 1.03 times the focal
# length, a false claim) accepted again

def _with_registration_record(forged: dict, genuine: dict, drop: tuple = (), **edits) -> dict:
    forged = copy.deepcopy(forged)
    record = copy.deepcopy(_stage(genuine, "projective")["principal_point"])
    record.update(edits)
    for name in drop:
        del record[name]
    _stage(forged, "projective")["principal_point"] = record
    return forged


LEFT_OUT = {
    "K_free deleted": (("K_free",), {"inside_middle_half": False}),
    "K_free null": ((), {"inside_middle_half": False, "K_free": None}),
    "chi2 deleted": (("chi2",), {}),
    "chi2 null": ((), {"chi2": None}),
    "only estimated": (("observations", "K_free", "chi2", "threshold", "inside_middle_half"), {}),
}


@pytest.mark.parametrize("case", list(LEFT_OUT))
def test_the_centred_forgery_beside_a_record_missing_its_figures_is_refused(off_centre, centred_forgery,  # noqa: F811
                                                                            case):
    """The genuine record (1,596 observations, chi2 3,183 against 13.8, K_free's principal point
    inside the middle half, estimated) is refused with ``estimated: false`` (review 26), and so is
    inside_middle_half flipped. Leave out K_free (the middle-half test is then read as written)
    or the chi2 (the record then says the test did not run, though 1,596 observations are far
    more than MIN_TEST_OBSERVATIONS): estimated false is consistent, the calibration tie takes the
    centred reading, and the false certificate verifies."""
    drop, edits = LEFT_OUT[case]
    genuine = _stage(off_centre, "projective")["principal_point"]
    assert genuine["estimated"] is True and genuine["chi2"] > genuine["threshold"]
    _refused(_with_registration_record(centred_forgery, off_centre, drop, estimated=False, **edits))


def test_the_centred_forgery_beside_the_whole_record_flipped_is_refused(off_centre, centred_forgery):  # noqa: F811
    """The control: every figure kept, estimated and inside_middle_half flipped: refused."""
    _refused(_with_registration_record(centred_forgery, off_centre, (), estimated=False, inside_middle_half=False),
             "inside_middle_half")


@pytest.mark.parametrize("waiver", ["radial term said kept", "radial model off", "cancelled"])
def test_the_records_requirement_cannot_be_waived_by_editing_what_it_reads(centred_forgery, waiver):  # noqa: F811
    """The centred forgery (its registration record deleted) with an edit to what decides that
    the record must be stated (a radial term kept, the radial model off, the stage cancelled):
    refused, by that requirement or by the edited member's own check."""
    forged = copy.deepcopy(centred_forgery)
    projective = _stage(forged, "projective")
    assert "principal_point" not in projective
    if waiver == "radial term said kept":
        projective["radial_distortion"].update(estimated=True, k1=-0.087, chi2=50.0)
    elif waiver == "radial model off":
        projective["radial_distortion"]["model"] = "off"
    else:
        projective["cancelled"] = True
    _refused(forged)


# 3. The intervals proven over planes (prove_intervals_over_planes)

@pytest.fixture(scope="module")
def over_planes() -> dict:
    from tests.solvers.autocalibration.test_autocalibration_over_planes import solved

    return copy.deepcopy(solved(prove_intervals_over_planes=True))


def _sublevel(document: dict) -> dict:
    return document["certificate"]["items"][1]["proof"]["plane_sublevel"]


@pytest.mark.slow
def test_the_plane_searches_pay_a_unit_for_each_camera_box_bound(over_planes, monkeypatch):
    """The genuine document (8 views) replayed: every box of a plane_sublevel tree is bounded
    against every camera (plane_sublevel.excluded: arrays of boxes x cameras), and the verifier
    charges len(boxes) * cameras // 50 + 1 units for them. A unit of work is one view or
    observation of a program built (docs/certificate.md); a camera-box bound (interval arithmetic
    in mean-value form over 8 variables) costs more than one, measured 65 to 78 us of CPU against
    the chart reference's 1.2 us a unit. Counted, not timed: the units charged cover the
    camera-box bounds made."""
    from geocert.formulations.autocalibration import plane_sublevel

    counted = {"bounds": 0, "units": 0}
    excluded, charge = plane_sublevel.excluded, plane_sublevel.charge

    def counting_excluded(context, region, lo, hi):
        counted["bounds"] += len(lo) * max(len(context.problem.norm.cameras), 1)
        return excluded(context, region, lo, hi)

    def counting_charge(units, what):
        if "plane_sublevel" in what:
            counted["units"] += units
        return charge(units, what)

    monkeypatch.setattr(plane_sublevel, "excluded", counting_excluded)
    monkeypatch.setattr(plane_sublevel, "charge", counting_charge)
    assert _verify(over_planes).valid
    assert counted["bounds"] > 10_000
    assert counted["bounds"] <= counted["units"], counted


@pytest.mark.slow
class TestOverPlanesRefused:
    """Refused today: the option and its proof out of step, or moved (no earlier review file)."""

    def test_the_option_null_or_a_number_is_refused(self, over_planes):
        for value in (None, 1):
            document = copy.deepcopy(over_planes)
            document["certificate"]["options"]["prove_intervals_over_planes"] = value
            rehash(document["certificate"], marked=True)
            assert _refused(document)["check"] == "options"

    def test_the_option_deleted_with_the_proof_kept_is_refused(self, over_planes):
        document = copy.deepcopy(over_planes)
        del document["certificate"]["options"]["prove_intervals_over_planes"]
        rehash(document["certificate"], marked=True)
        _refused(document, "prove_intervals_over_planes")

    def test_the_proof_moved_into_the_affine_proof_is_refused(self, over_planes):
        document = copy.deepcopy(over_planes)
        items = document["certificate"]["items"]
        items[0]["proof"]["plane_sublevel"] = items[1]["proof"].pop("plane_sublevel")
        _refused(document, "plane_sublevel")

    @pytest.mark.parametrize("option", [True, False])
    def test_proven_over_planes_without_the_proof_is_refused(self, over_planes, option):
        document = copy.deepcopy(over_planes)
        del document["certificate"]["items"][1]["proof"]["plane_sublevel"]
        document["certificate"]["options"]["prove_intervals_over_planes"] = option
        rehash(document["certificate"], marked=True)
        _refused(document, "proven_over_planes")

    def test_the_results_affine_increase_alone_raised_is_refused(self, over_planes):
        document = copy.deepcopy(over_planes)
        document["stages"][1]["determinacy"]["proven_over_planes"]["affine_increase"] *= 2
        _refused(document, "proven_over_planes")

    def test_the_affine_increase_lowered_in_proof_and_result_is_refused(self, over_planes):
        from geocert.formulations.autocalibration import plane_sublevel

        document = copy.deepcopy(over_planes)
        _sublevel(document)["affine_increase"] = 0.0
        document["stages"][1]["determinacy"]["proven_over_planes"] = plane_sublevel.proven_document(
            _sublevel(document))
        _refused(document, "affine_increase")


# 4. More members a returned record may leave out (the known gap, beyond its 7 cases)

MISSING_MEMBERS = [
    ("autocalibration_stratified", ("stages", 0, "certificate")),
    ("autocalibration_stratified", ("stages", 0, "determinacy")),
    ("autocalibration_stratified", ("stages", 1, "determinacy")),
    ("autocalibration_stratified", ("baseline",)),
    ("triangulation_l2l2", ("stats", "statuses")),
    ("triangulation_l2l2", ("stats", "items")),
    ("triangulation_l2l2", ("stats", "nodes")),
]
_STILL_OPEN = pytest.mark.xfail(strict=True, reason="review 28: a returned record may leave out members its writer "
                                                    "writes")
MISSING_MEMBER_CASES = [pytest.param(name, path, id="/".join(map(str, path)),
                                     marks=[_STILL_OPEN] if name == "reconstruction" else [])
                        for name, path in MISSING_MEMBERS]


@pytest.mark.parametrize("name, path", MISSING_MEMBER_CASES)
def test_a_returned_record_missing_a_member_is_refused(name, path):
    """Each deletion leaves no false number behind, but the record is not its writer's (a chi2
    deleted says "the test did not run" beside the free fit the test made, K_free); see
    test_inside_middle_half_flipped_with_K_free_left_out_is_refused for one that does."""
    result = stored(name)
    assert _verify(result).valid
    parent = result
    for key in path[:-1]:
        parent = parent[key]
    del parent[path[-1]]
    assert not _verify(result).valid


# The reconstruction's case, fixed: a principal-point record is one of its writer's two shapes
# (reconstruction_members._check_record_shape)
RECONSTRUCTION_MISSING = [("stages", 2, "principal_point", member)
                          for member in ("chi2", "K_free", "threshold", "inside_middle_half", "observations")]


@pytest.mark.parametrize("path", RECONSTRUCTION_MISSING, ids=["/".join(map(str, p)) for p in RECONSTRUCTION_MISSING])
def test_a_reconstructions_principal_point_record_missing_a_member_is_refused(path):
    result = stored("reconstruction")
    assert _verify(result).valid
    del result["stages"][2]["principal_point"][path[-1]]
    _refused(result, "principal_point")


def test_the_reconstructions_adjustment_stage_is_the_third():
    """The paths above name the adjustment's stage by its place."""
    assert stored("reconstruction")["stages"][2]["name"] == "bundle_adjustment"
    assert [s["name"] for s in stored("autocalibration_stratified")["stages"]] == ["affine", "metric"]
