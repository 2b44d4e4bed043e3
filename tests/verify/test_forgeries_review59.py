"""Review 59: a hostile review of the certificates for issue 33, where review 58 left off: its
three fixes and their neighbours (the photos reconstruction's images record, a map estimate's
value floor across units, the comparisons of verify.estimates and verify.fractional at NaN, inf,
subnormals and -0.0).

Tried (each forgery built from a genuine document, its hashes made again where the data moved,
verify_any run):

- The photos example (examples/reconstruction-photos.json, a full certificate): 68 forgeries of
  its images record, the matches stage restated alike unless said: the stage's status failed,
  cancelled, skipped, not_run, time_limit (tracks_kept 0) or "Done"; counts true, 1268.0, -0.0,
  6.0, 15.0 (the record only); candidate_pairs 16, 10^6, 10^30; features_per_image zeros,
  negative, floats, true, 1e308, 10^30, 5 each, the first 0, one short; a pair's views equal, out
  of range, negative, false/true, floats, three; its matches, inliers or guided true, float, 0,
  2,000, above each other, 10^30; a member added or views deleted; pairs emptied, null, all 15,
  reversed, one beyond the candidates; counts null or deleted, 10^6 dropped as short; stopped
  beside done; time_s negative, NaN, inf. 33 verified before this review, 4 after (below).
- Map estimates in other units (within COORDINATE_LIMIT, the map not certified and its figures
  its writer's, every interval collapsed to a thousandth of its width): the stored 3-D
  homography's second map with source and targets scaled apart both ways (7 scalings), moved 1e8
  off the origin (3); review 58's resection scaled apart both ways and moved off the origin (7).
- The comparisons alone: estimates._close (2,304 calls: stated and recomputed NaN, +-inf,
  +-5e-324, -0.0, 1e308, the largest float, 10**400, 2**1024, true, "1", null, against widths and
  slacks NaN, +-inf, negative, subnormal), _check_offset (13,824), fractional._agrees (256).

Found (a test below for each, which failed while the class stood):

1. A homography's centroid image was held to MAP_VALUE_ROUNDING of the largest coordinate of
   source or target: a 3-D homography's source in a fine unit (x1e8, within COORDINATE_LIMIT) and
   its targets in a coarse one (x1e-8) gave the centroid image, in the target's units, a floor
   of 4.9e-7, wider than its intervals (1.3e-10): every interval collapsed to a thousandth of
   its width verified. Fixed: a homography's floor reads the target alone (as review 58 did a
   resection's the source).
2. The photos' images record (examples/reconstruction-photos.json, a full certificate; each edit
   made to the matches stage alike): review 58's ties were skipped where a count was null or
   deleted (tracks_kept null beside 10^9 tracks built), tracks_built had no bound (10^6 dropped as
   short, built restated to match, beside 2,639 inliers; every pair deleted beside 1,270 tracks),
   and "stopped" was any text beside matching done. Fixed: where matching ran (done, time_limit,
   failed) each count is stated, the tracks built are at most the verified pairs' inliers, and
   stopped is stated only of a clock.
3. A verified pair's figures against its writer's (features.match_pair): matches 2,000 beside
   the first image's 1,027 features, a pair of an image with 0 features, inliers above matches
   with no guided count, a guided count above the inliers (or 10^19), all verified. Fixed: each
   figure at most the first image's features; inliers above matches only as the guided count.
4. The images record was tied to the matches stage by ==: 1268.0, -0.0 or a pair's views [0.0,
   1.0] equal to the stage's ints (typed there only); the float views stopped the check with a
   TypeError. Fixed: the two records are the same JSON; a pair states its views and figures only
   (a member "extra" verified).
5. estimates._close read a stated int beyond float range (10**400) with math.isfinite, which
   raised OverflowError: a stop, not a refusal (not reached from a document, whose reader refuses
   such a number first). Fixed: a stated number is is_number's.
6. A map estimate's ends kept JACOBIAN_ROUNDING (eps / 1e-6) of the width per unit of the data's
   offset ratio (largest coordinate over spread): a resection's source moved 1e8 off the origin
   with a spread of 1.8e-3 (review 58's camera, its world x1e-3, every coordinate within
   COORDINATE_LIMIT: ratio 5.4e10) gave its ends a slack of 12 widths, and every centre interval
   (1e-4 to 6e-4 wide) collapsed to a thousandth of its width verified, beside determined true.
   The writer read the width from a central difference of residuals in the world's coordinates,
   rounded at eps of 1e8 (8e-6 of their spread): 0.4 of the width from the same data's at the
   origin. A 3-D homography's source moved alike (the stored one's x1e-3, 1e8 off the origin)
   verified collapsed too (its writer was normalised already; the slack was the verifier's). Fixed:
   a resection's estimate is read in normalised coordinates as a homography's (fractional.
   normalisation, shared: the residuals and the centre's offset from the source centroid in that
   frame), its widths within 1e-4 of the origin's 1e8 off, and the width slack is MAP_WIDTH_SLACK
   and the cost spread alone. Documents of the writers before whose estimate was read in the
   world's coordinates are refused from an offset ratio of about 5e6 (docs/certificate.md).

Held: the matches stage's status edits (refused by check_statuses beside points, or by the tracks
kept), views out of range or equal, candidate_pairs beyond the pairs of views, negative or float
counts in the stage; every homography and resection in other units but those above; every
comparison at NaN, inf, subnormals and -0.0 (matched only a finite number within its slack).
Left as read (the record cannot tell): a pair's inliers or matches 0 (the matching's min_inliers
is not stated in the document to hold them to), every pair of views claimed verified with made-up
figures, the pairs' order.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.formulations.fractional.fixed_order import mul
from geocert.verify.checks import verify_any
from geocert.core.determinacy import reading
from tests.verify.test_forgeries import estimates_form, STORED, refused_naming, rehash, stored, uncertify
from tests.verify.test_forgeries_review58 import resections, restated_map  # noqa: F401  (resections: the fixture)

pytestmark = pytest.mark.filterwarnings("ignore")


def _valid(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


def _rescaled(result: dict, index: int, world: float, pixels: float) -> dict:
    """The result with map ``index``'s data restated in other units (its source points times
    ``world``, its targets times ``pixels``), the matrix restated to match, not certified, with the
    cost, residuals and estimate its writers state for those data (review 58's _rescaled, for a
    map of any dimensions): a genuine document (every coordinate within COORDINATE_LIMIT)."""
    from geocert.core.geometry import COORDINATE_LIMIT
    from geocert.formulations.fractional import determinacy as estimate
    from geocert.formulations.fractional.items import MapItem
    from geocert.verify.fractional import _stated_figure

    form = estimates_form(result["certificate"])  # the document's own, in which it is restated
    result = copy.deepcopy(result)
    norm = result["certificate"]["options"]["norm"]
    data = result["certificate"]["data"]["maps"][index]
    source, target = np.array(data["source"]) * world, np.array(data["target"]) * pixels
    assert np.abs(source).max() <= COORDINATE_LIMIT and np.abs(target).max() <= COORDINATE_LIMIT
    data.update(source=source.tolist(), target=target.tolist())
    claim = result["certificate"]["items"][index]
    scaled = np.diag([pixels] * target.shape[1] + [1.0])
    M = scaled @ np.array(claim["matrix"]) @ np.diag([1 / world] * source.shape[1] + [1.0])
    uncertify(claim)
    claim.pop("proof")
    claim["matrix"] = M.tolist()
    item = MapItem((source, target), norm, chart=False)
    claim["cost"], _ = _stated_figure(item, M, norm)
    entry = result["maps"][index]
    entry.update({name: claim[name] for name in ("matrix", "cost", "lower_bound", "gap", "status", "certified")})
    entry["residuals"] = item.exact_residuals(M).tolist()
    entry.pop("certificate")
    with reading(form):
        entry["determinacy"] = json.loads(json.dumps(estimate.map_(source, target, M, claim["cost"], None)))
    certified = len(result["maps"]) - 1
    result["stats"].update(certified=certified, statuses={"optimal": certified, "not_certified": 1})
    rehash(result["certificate"], form=form)
    return result


def _collapsed(result: dict, index: int) -> dict:
    """Every interval of the map collapsed to a thousandth of its width, and ``determined``
    restated as the collapsed intervals give it (a genuine map's may be false: its intervals
    beyond their tolerance), so that only the intervals' check can refuse it."""
    from geocert.core.determinacy import fixes

    forged = copy.deepcopy(result)
    determinacy = forged["maps"][index]["determinacy"]
    for found in determinacy["intervals"]:
        width = found["upper"] - found["lower"]
        found["lower"], found["upper"] = found["value"] - width / 1000, found["value"] + width / 1000
    determinacy["determined"] = all(fixes(i) for i in determinacy["intervals"]) and not determinacy["warnings"]
    return forged


# 1. A homography's centroid image is held to the rounding of the target's units, not the source's

@pytest.mark.parametrize("world,pixels", [(1e8, 1e-8)])
def test_a_homography_restated_narrower_with_its_source_in_a_finer_unit_is_refused(world, pixels):
    """The centroid image's value and ends were allowed MAP_VALUE_ROUNDING of the data's largest
    coordinate, source or target: the stored 3-D homography's second map with its source in a
    finer unit (2.8e8) and its targets in a coarser one (2.5e-8, the intervals 1.3e-10 wide) gave
    the centroid image, in the target's units, a floor of 4.9e-7; every interval collapsed to a
    thousandth of its width verified, beside determined true."""
    genuine = _rescaled(stored("homography3_l2l1"), 1, world, pixels)
    assert _valid(genuine)
    refused_naming(_collapsed(genuine, 1), "returned", "maps/1/determinacy/intervals/0/")


# 2-4. The photos reconstruction's images record (tests first on the record alone, quick, then on a
#      solved document, slow)

def _record() -> tuple[dict, dict, dict]:
    """A result, images record and matches stage as kinds.reconstruction writes them (counts of
    the photos example's form)."""
    images = {"images": 3, "features_per_image": [100, 90, 80], "candidate_pairs": 3, "pairs_chosen_by": "exhaustive",
              "verified_pairs": [{"views": [0, 1], "matches": 60, "inliers": 50},
                                 {"views": [1, 2], "matches": 40, "inliers": 30, "guided": 45}],
              "tracks_built": 52, "dropped_inconsistent": 1, "dropped_short": 1, "tracks_kept": 50}
    images["verified_pairs"][1]["inliers"] = 45  # the guided matches replaced the pair's (more inliers)
    matches = {"name": "matches", "status": "done", **copy.deepcopy(images)}
    return {"summary": {"tracks": 50, "views": 3}}, images, matches


def _check(result: dict, images: dict, matches: dict) -> None:
    from geocert.verify.reconstruction_members import _check_image_counts

    _check_image_counts(result, images, matches)


def test_the_records_form_verifies():
    _check(*_record())
    result, images, matches = _record()
    matches["status"] = "time_limit"
    _check(result, {**images, "stopped": "x"}, {**matches, "stopped": "x"})


def _edited(edit) -> tuple[dict, dict, dict]:
    result, images, matches = _record()
    edit(images)
    edit(matches)
    return result, images, matches


RECORD = {
    "tracks_kept null beside 10^9 built": lambda r: r.update(tracks_kept=None, tracks_built=10 ** 9),
    "tracks_kept deleted": lambda r: r.pop("tracks_kept"),
    "verified_pairs null": lambda r: r.update(verified_pairs=None),
    "10^6 dropped as short": lambda r: r.update(dropped_short=10 ** 6, tracks_built=10 ** 6 + 51),
    "every pair deleted": lambda r: r.update(verified_pairs=[]),
    "stopped beside done": lambda r: r.update(stopped="features read of 3 of 3 images"),
    "matches above the features": lambda r: r["verified_pairs"][0].update(matches=101),
    "a pair of an image of 0 features": lambda r: r.update(features_per_image=[0, 90, 80]),
    "inliers above matches unguided": lambda r: r["verified_pairs"][0].update(inliers=61),
    "guided above the inliers": lambda r: r["verified_pairs"][1].update(guided=46),
    "guided 10^19": lambda r: r["verified_pairs"][1].update(guided=10 ** 19),
    "a pair's member no writer states": lambda r: r["verified_pairs"][0].update(extra=1),
}


@pytest.mark.parametrize("name", sorted(RECORD))
def test_an_images_record_contradicting_its_writer_is_refused(name):
    """Each accepted before (review 58's ties skipped a null count, and read no bound among a
    pair's figures or between the pairs and the tracks)."""
    from geocert.core.strict import Invalid

    with pytest.raises(Invalid, match="images/"):
        _check(*_edited(RECORD[name]))


@pytest.fixture(scope="module")
def photographed() -> dict:
    """The kind's example from photos (6 images) solved with a full certificate, as review 58's."""
    from pathlib import Path

    from geocert.jobs.runner import solve_job

    job = json.loads((Path(__file__).resolve().parents[2] / "examples" / "reconstruction-photos.json").read_text())
    job["options"]["certificate"] = "full"
    result = json.loads(json.dumps(solve_job(job)))
    assert _valid(result)
    return result


def _restated(result: dict, edit, images_only: bool = False) -> dict:
    forged = copy.deepcopy(result)
    edit(forged["images"])
    if not images_only:
        edit(next(stage for stage in forged["stages"] if stage["name"] == "matches"))
    return forged


def _pair(**figures):
    return lambda r: r["verified_pairs"][0].update(figures)


@pytest.mark.slow  # the example's solve and each verification: about 20 s in all
@pytest.mark.parametrize("edit,images_only,field", [
    (lambda r: r.update(tracks_kept=None, tracks_built=10 ** 9), False, "images/tracks_kept"),
    (lambda r: r.update(dropped_short=10 ** 6, tracks_built=r["tracks_built"] + 10 ** 6), False, "images/tracks_built"),
    (lambda r: r.update(verified_pairs=[]), False, "images/tracks_built"),
    (lambda r: r.update(stopped="x"), False, "images/stopped"),
    (_pair(matches=2000), False, "images/verified_pairs/0"),
    (lambda r: r["features_per_image"].__setitem__(0, 0), False, "images/verified_pairs/0"),
    (lambda r: r["verified_pairs"][0].update(inliers=r["verified_pairs"][0]["matches"] + 100), False,
     "images/verified_pairs/0"),
    (lambda r: r["verified_pairs"][0].update(guided=r["verified_pairs"][0]["inliers"] + 50), False,
     "images/verified_pairs/0"),
    (lambda r: r.update(tracks_kept=float(r["tracks_kept"])), True, "images/tracks_kept"),
    (lambda r: r.update(dropped_short=-0.0), True, "images/dropped_short"),
    (lambda r: r["verified_pairs"][0].update(views=[0.0, 1.0]), True, "images/verified_pairs"),
])
def test_a_photos_images_record_contradicting_its_writer_is_refused(photographed, edit, images_only, field):
    refused_naming(_restated(photographed, edit, images_only), "returned", field)


# 5. and review 58's comparisons at the ends of the float range (stated or recomputed NaN, inf,
#    subnormals, -0.0, ints beyond float range): none matches what it is not

SPECIAL = [float("nan"), float("inf"), -float("inf"), 5e-324, -5e-324, -0.0, 0.0, 1.0, 1e308, -1e308,
           1.7976931348623157e308, 10 ** 400, 2 ** 1024, True, "1", None]


def _matches(given, expected, width, absolute) -> bool:
    import math

    if given is None or expected is None:
        return given is None and expected is None
    numbers = [given, expected, width, absolute]
    if any(type(x) not in (int, float) or type(x) is int and abs(x) >= 2 ** 1023 for x in numbers) or not all(
            math.isfinite(x) for x in numbers):
        return False
    return abs(given - expected) <= 1e-6 * abs(width) + absolute + 1e-9 * abs(expected)


def test_close_matches_only_a_finite_number_within_its_slack():
    import itertools

    from geocert.verify.estimates import _close

    recomputed = [x for x in SPECIAL if type(x) is float or x is None]
    slacks = [(0.0, 0.0), (1.0, 0.0), (float("inf"), 0.0), (float("nan"), 0.0), (0.0, float("inf")),
              (0.0, float("nan")), (-float("inf"), 0.0), (0.0, -1.0), (5e-324, 5e-324)]
    for given, expected, (width, absolute) in itertools.product(SPECIAL, recomputed, slacks):
        assert _close(given, expected, width, absolute) == _matches(given, expected, width, absolute), \
            (given, expected, width, absolute)


def test_an_end_offset_matches_only_finite_numbers():
    import itertools
    import math

    from geocert.core.strict import Invalid
    from geocert.verify.estimates import _check_offset

    for given, value, own_value, own_end, width in itertools.product(
            SPECIAL, [0.0, -0.0, 1.0, 5e-324, 1e308], [0.0, 1.0, float("nan"), float("inf"), -0.0, 5e-324],
            [1.0, float("nan"), float("inf"), -float("inf"), 5e-324, None], [1.0, float("nan"), float("inf"), 0.0]):
        try:
            _check_offset("at", "lower", {"value": value, "lower": given}, {"value": own_value, "lower": own_end},
                          width, 0.0)
        except Invalid:
            continue
        in_range = type(given) in (int, float) and (type(given) is float or abs(given) < 2 ** 1023)
        assert (given is None and own_end is None) or (in_range and all(
            math.isfinite(x) for x in (given, value, own_value, own_end, width))), (given, value, own_value, own_end)


def test_agrees_matches_only_a_finite_number_within_its_rounding():
    import itertools
    import math

    from geocert.verify import fractional

    for given, expected in itertools.product(SPECIAL, [float("nan"), float("inf"), -float("inf"), 5e-324, -0.0,
                                                       0.0, 1.0, 1e308]):
        for shaped in (lambda x: x, lambda x: [x, 1.0]):
            with np.errstate(all="ignore"):
                agreed = fractional._agrees(shaped(given), shaped(expected))
            in_range = type(given) in (int, float) and (type(given) is float or abs(given) < 2 ** 1023)
            assert not agreed or (in_range and math.isfinite(given) and math.isfinite(expected)
                                  and abs(given - expected) <= 1e-9 * max(1.0, abs(expected))), (given, expected)


# Held: attacks already refused, kept as guards: homographies restated in other units (source and
# targets scaled apart both ways), every interval collapsed onto its value

@pytest.mark.parametrize("world,pixels", [(1e6, 1e-6), (1e-6, 1e6), (1e-8, 1e6), (1.0, 1e-9), (1e6, 1.0)])
def test_a_homography_in_other_units_collapsed_is_refused(world, pixels):
    genuine = _rescaled(stored("homography3_l2l1"), 1, world, pixels)
    assert _valid(genuine)
    refused_naming(_collapsed(genuine, 1), "returned", "maps/1/determinacy/intervals/0/")


# 6. A map estimate's ends, for data so far off the origin that the width's slack exceeds the width

def _moved(result: dict, world: float, shift: float) -> dict:
    """The second map's source scaled by ``world`` and moved by ``shift`` (along (1, -1/2, 1/3)),
    the camera restated to match (review 58's ``restated_map``)."""
    data = result["certificate"]["data"]["maps"][1]
    offset = shift * np.array([1.0, -0.5, 1 / 3])
    undo = np.eye(4)
    undo[:3, :3] /= world
    undo[:3, 3] = -offset / world
    M = mul(np.array(result["certificate"]["items"][1]["matrix"]), undo)  # the same floats under every kernel
    return restated_map(result, np.array(data["source"]) * world + offset, np.array(data["target"]), M)


@pytest.mark.parametrize("world,shift", [(1e-3, 1e8), (1.0, 1e8), (1.0, 1e6), (1e-6, 1e3)])
def test_a_resection_far_off_the_origin_collapsed_is_refused(resections, world, shift):
    genuine = _moved(resections, world, shift)
    assert _valid(genuine)
    refused_naming(_collapsed(genuine, 1), "returned", "maps/1/determinacy/intervals/0/")


def _homography_moved(world: float, shift: float) -> dict:
    """The stored 3-D homography's second map, its source scaled by ``world`` (_rescaled) and moved
    by ``shift`` (along (1, -1/2, 1/3)), the matrix, cost, residuals and estimate restated."""
    from geocert.formulations.fractional import determinacy as estimate
    from geocert.formulations.fractional.items import MapItem
    from geocert.verify.fractional import _stated_figure

    result = _rescaled(stored("homography3_l2l1"), 1, world, 1.0)
    form = estimates_form(result["certificate"])  # the stored document's, in which it is restated
    data = result["certificate"]["data"]["maps"][1]
    offset = shift * np.array([1.0, -0.5, 1 / 3])
    source, target = np.array(data["source"]) + offset, np.array(data["target"])
    data["source"] = source.tolist()
    claim = result["certificate"]["items"][1]
    undo = np.eye(4)
    undo[:3, 3] = -offset
    M = mul(np.array(claim["matrix"]), undo)  # the same floats under every kernel
    item = MapItem((source, target), "L2L1", chart=False)
    claim["matrix"], (claim["cost"], _) = M.tolist(), _stated_figure(item, M, "L2L1")
    entry = result["maps"][1]
    entry.update(matrix=claim["matrix"], cost=claim["cost"], residuals=item.exact_residuals(M).tolist())
    with reading(form):
        entry["determinacy"] = json.loads(json.dumps(estimate.map_(source, target, M, claim["cost"], None)))
    rehash(result["certificate"], form=form)
    return result


@pytest.mark.parametrize("world,shift", [(1e-3, 1e8), (1.0, 1e8)])
def test_a_homography_far_off_the_origin_collapsed_is_refused(world, shift):
    genuine = _homography_moved(world, shift)
    assert _valid(genuine)
    refused_naming(_collapsed(genuine, 1), "returned", "maps/1/determinacy/intervals/0/")


def _widths(result: dict) -> np.ndarray:
    return np.array([found["upper"] - found["lower"] for found in result["maps"][1]["determinacy"]["intervals"]])


def _narrowed(result: dict, share: float) -> dict:
    """The document with each interval narrowed by ``share`` of its width about its own value."""
    forged = copy.deepcopy(result)
    for found in forged["maps"][1]["determinacy"]["intervals"]:
        half = (1 - share) * (found["upper"] - found["lower"]) / 2
        found["lower"], found["upper"] = found["value"] - half, found["value"] + half
    return forged


def _recomputed_widths(result: dict) -> np.ndarray:
    """The widths the verifier recomputes from the document (estimates._check_maps: the estimate
    at the returned matrix, from the certificate's data as it reads them)."""
    from geocert.core.determinacy import safely
    from geocert.formulations.fractional import determinacy as estimate
    from geocert.verify.adapters import VERIFIED_KINDS

    document = json.loads(json.dumps(result))
    source, target = VERIFIED_KINDS[document["kind"]].verification.read(document["certificate"]["data"], 1)
    item = document["maps"][1]
    with reading(estimates_form(document["certificate"])):  # as the verifier reads the document
        own = safely(estimate.map_, source, target, item["matrix"], item["cost"], item.get("lower_bound"))
    return np.array([found["upper"] - found["lower"] for found in own["intervals"]])


@pytest.mark.parametrize("map_kind", ["resection", "homography"])
def test_a_map_estimates_widths_do_not_move_with_the_data_far_off_the_origin(resections, map_kind):
    """The writer reads the estimate in normalised coordinates: the same data (the world x1e-3)
    moved 1e8 off the origin give widths within 1e-3 of those at the origin (measured 7.6e-5 for
    the resection and 6.8e-5 to 2.3e-4 for the homography, as the moved data round: 8e-6 of their
    spread; the writer before read them 0.4 and 0.8 of the width apart), and so does the verifier's
    recomputation; it reads the writer's widths as its own, and refuses them 4e-3 narrower (each end
    2e-3 of the width in, beyond estimates.MAP_WIDTH_SLACK; the slack of before, 12 widths here,
    took any)."""
    moved = (lambda shift: _moved(resections, 1e-3, shift)) if map_kind == "resection" else (
        lambda shift: _homography_moved(1e-3, shift))
    at_origin, far = moved(0.0), moved(1e8)
    assert np.max(np.abs(_widths(far) / _widths(at_origin) - 1)) < 1e-3
    assert np.max(np.abs(_recomputed_widths(far) / _widths(at_origin) - 1)) < 1e-3
    assert _valid(far)
    refused_naming(_narrowed(far, 4e-3), "returned", "maps/1/determinacy/intervals/")


def test_a_resection_of_the_writer_before_far_off_the_origin_still_verifies():
    """A third party's stored resection from the writer that read the estimate in the world's
    coordinates (tests/data/certificates/earlier/resection_far_world_frame_estimate.json: review 58's
    cameras, the second map moved 3e7 off the origin, an offset ratio of 1.6e7, written by that
    writer): its widths lie within estimates.MAP_WIDTH_SLACK of today's recomputation, so it
    verifies; its intervals 4e-3 narrower are refused."""
    earlier = json.loads((STORED / "earlier" / "resection_far_world_frame_estimate.json").read_text())
    source = np.array(earlier["certificate"]["data"]["maps"][1]["source"])
    assert np.abs(source).max() / np.sqrt(((source - source.mean(0)) ** 2).sum(1).mean()) > 1e7
    assert _valid(earlier)
    refused_naming(_narrowed(earlier, 4e-3), "returned", "maps/1/determinacy/intervals/")
