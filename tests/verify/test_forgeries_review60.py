"""Review 60: a hostile review of the reconstruction kind's certificate (photos to cameras and
points, with the ``images`` record of their matching), where review 59 left off: the record
against the points, the views' types, the words and summaries beside certified claims, the
warnings, and the counts' types.

Tried (each forgery built from a genuine document: the stored reconstruction_labelled and the
photos example solved with a full certificate, examples/reconstruction-photos.json; verify_any
run): the images record (restated in the matches stage alike) with an image's features, or the
inliers of its pairs, below what the points observe in it, and with its pairs split into two
groups of images (the pairs kept given inliers enough for every view) beside tracks joining both;
a camera's view, an observation's view and the data's views stated as true or 1.0; a certified
camera's reason and bound_reason and a certified point's reason stated ("not proven"); each
warning stated twice; a certified point's certificate summary null; and every integer the result
states (its items, stages, summary, images record and stats; the certificates beside it are
verified by their own kinds) stated as its float.

Found (a test below for each, which failed while the class stood):

1. The images record was not read against the points: an image of 10 features, or whose verified
   pairs hold 5 inliers each, observed 443 times by the points, and pairs splitting the six
   photos into {0, 1, 2} and {3, 4, 5} beside tracks joining the two, verified. Fixed
   (reconstruction_members._check_image_points): in each view the points observe at most its
   image's features and at most the inliers of its verified pairs, and each point's views lie in
   one connected component of the verified pairs. Without the record (tracks sent) nothing is read.
2. Views compared with ==: a camera's view true or 1.0, an observation's view true or 1.0 and the
   data's views [0, true, ...] (rehashed) verified. Fixed: the view lists and the observations are
   compared as JSON (the record's way since review 59).
3. A certified camera's reason or bound_reason, and a certified point's reason, were any words
   ("not proven" verified). Fixed: null beside a certified camera or point, as their writers
   state them. The earlier forgeries that call an uncertified camera certified now clear its
   bound_reason, as a writer certifying it would, so that the check each was written for is the
   one refusing it: test_forgeries.py (_resolved_cameras, and the moved camera called certified),
   test_forgeries_review.py (a result with its certificate's members) and
   tests/kinds/test_reconstruction_kind.py (a camera not searched claimed certified).
4. Each warning could be stated twice (the critical_motion warning twice verified: the checks
   ask whether a warning of a code is there). Fixed, checked last: each warning once, and no code
   twice but camera_dropped (once a camera dropped).
5. A certified point's certificate summary null verified (a reconstruction takes no
   options.detail; its writer states a summary for every certified point). Fixed: refused.
6. Counts as floats: 12.0 was accepted where a count was compared with == (the summary's views
   registered, points, observations, certified points and cameras, cameras_dropped; a camera's
   points and degrees of freedom; the structure and cameras stages' counts; the job's stats) and
   refused where a count was typed. Fixed (strict.same_counts): a count is an integer everywhere.
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.core.strict import Invalid
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import refused_naming, rehash, stored
from tests.verify.test_forgeries_review59 import photographed  # noqa: F401  (the fixture)

pytestmark = pytest.mark.filterwarnings("ignore")


def _valid(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


@pytest.fixture(scope="module")
def labelled() -> dict:
    """The stored reconstruction of the current form (its labels stated)."""
    document = stored("reconstruction_labelled")
    assert _valid(document)
    return document


def _forged(document: dict, edit) -> dict:
    forged = copy.deepcopy(document)
    edit(forged)
    return forged


# 1. The images record against the points (tests on the record alone first, quick, then on the
#    photos example, slow)

def _points(*views_each: list) -> dict:
    """A result whose points observe ``views_each`` (one list of views a point)."""
    return {"points": [{"observations": [[view, 1.0, 2.0] for view in views]} for views in views_each]}


def _images(features: list, pairs: list) -> dict:
    return {"features_per_image": features,
            "verified_pairs": [{"views": list(views), "matches": inliers, "inliers": inliers}
                               for views, inliers in pairs]}


def _check(result: dict, images: dict) -> None:
    from geocert.verify.reconstruction_members import _check_image_points

    _check_image_points(result, images)


def test_points_within_the_records_figures_verify():
    _check(_points([0, 1], [0, 1, 2], [1, 2]), _images([2, 3, 2], [((0, 1), 2), ((1, 2), 2)]))
    _check(_points([0, 1]), {"features_per_image": None, "verified_pairs": None})  # a record stating neither


@pytest.mark.parametrize("images,points", [
    (_images([1, 5, 5], [((0, 1), 5), ((1, 2), 5)]), _points([0, 1], [0, 1, 2])),  # view 0: 2 > 1 feature
    (_images([5, 5, 5], [((0, 1), 1), ((1, 2), 5)]), _points([0, 1], [0, 1, 2])),  # view 0: 2 > 1 inlier
    (_images([5, 5, 5, 5], [((0, 1), 5), ((2, 3), 5)]), _points([0, 1], [1, 2])),  # views 1, 2 in no chain
])
def test_points_beyond_the_records_figures_are_refused(images, points):
    with pytest.raises(Invalid, match="images/"):
        _check(points, images)


def _restated(edit):
    """``edit`` made to the images record and to the matches stage alike (review 59 ties them)."""
    def both(forged: dict) -> None:
        edit(forged["images"])
        edit(next(stage for stage in forged["stages"] if stage["name"] == "matches"))
    return both


def _observed(result: dict, view: int) -> int:
    return sum(1 for point in result["points"] for observation in point["observations"] if observation[0] == view)


def _split(record: dict) -> None:
    """The verified pairs within {0, 1, 2} and within {3, 4, 5} only, the pairs (1, 2) and (3, 4)
    given 520 inliers (of their 1,019 and 914 features), so that every view's pairs hold at least
    the observations the points make of it: only the tracks joining the halves contradict them."""
    record["verified_pairs"] = [pair for pair in record["verified_pairs"]
                                if set(pair["views"]) <= {0, 1, 2} or set(pair["views"]) <= {3, 4, 5}]
    for pair in record["verified_pairs"]:
        if pair["views"] in ([1, 2], [3, 4]):
            pair.update(matches=520, inliers=520)


@pytest.mark.slow  # the example's solve and each verification: about 10 s in all
def test_a_photos_record_contradicting_its_points_is_refused(photographed):
    last = len(photographed["images"]["features_per_image"]) - 1
    assert _observed(photographed, last) > 10
    refused_naming(_forged(photographed, _restated(lambda r: r["features_per_image"].__setitem__(last, 10))),
                   "returned", f"images/features_per_image/{last}")

    def few_inliers(record: dict) -> None:
        for pair in record["verified_pairs"]:
            if last in pair["views"]:
                pair.update(matches=5, inliers=5)

    refused_naming(_forged(photographed, _restated(few_inliers)), "returned", "images/verified_pairs", "inliers")
    split = _forged(photographed, _restated(_split))
    assert any({0, 1, 2} & {o[0] for o in p["observations"]} and {3, 4, 5} & {o[0] for o in p["observations"]}
               for p in split["points"])
    refused_naming(split, "returned", "images/verified_pairs", "no chain of verified pairs")


# 2. Views compared as JSON (true and 1.0 are not view 1)

@pytest.mark.parametrize("value", [True, 1.0])
def test_a_view_stated_as_another_type_is_refused(labelled, value):
    refused_naming(_forged(labelled, lambda r: r["cameras"][1].update(view=value)), "returned", "one per view")

    def observation(forged: dict) -> None:
        point = next(p for p in forged["points"] if any(o[0] == 1 for o in p["observations"]))
        next(o for o in point["observations"] if o[0] == 1)[0] = value

    refused_naming(_forged(labelled, observation), "returned", "observations are not the track")

    def data(forged: dict) -> None:
        forged["certificate"]["data"]["views"][1] = value
        rehash(forged["certificate"])

    refused_naming(_forged(labelled, data), "returned", "not the cameras returned")


# 3. No reason words beside a certified camera or point

@pytest.mark.parametrize("member", ["reason", "bound_reason"])
def test_words_beside_a_certified_camera_are_refused(labelled, member):
    view = next(c["view"] for c in labelled["cameras"] if c["certified"] is True)
    refused_naming(_forged(labelled, lambda r: r["cameras"][view].update({member: "not proven"})), "returned",
                   f"cameras/{view}/{member}")


def test_words_beside_a_certified_point_are_refused(labelled):
    index = next(k for k, p in enumerate(labelled["points"]) if p["certified"] is True)
    refused_naming(_forged(labelled, lambda r: r["points"][index].update(reason="not proven")), "returned",
                   f"points/{index}/reason")


# 4. Each warning stated once

def test_a_warning_stated_twice_is_refused(labelled):
    assert any(w["code"] == "critical_motion" for w in labelled["summary"]["warnings"])

    def twice(forged: dict) -> None:
        warnings = forged["summary"]["warnings"]
        warnings.append(copy.deepcopy(next(w for w in warnings if w["code"] == "critical_motion")))

    refused_naming(_forged(labelled, twice), "returned", "summary/warnings", "critical_motion")


# 5. A certified point states its proof's summary

def test_a_certified_point_without_its_summary_is_refused(labelled):
    index = next(k for k, p in enumerate(labelled["points"]) if p["certified"] is True)
    refused_naming(_forged(labelled, lambda r: r["points"][index].update(certificate=None)), "returned",
                   f"points/{index}/certificate")


# 6. A count is an integer everywhere in the document

def _stage(name: str):
    return lambda r: next(stage for stage in r["stages"] if stage["name"] == name)


COUNTS = {
    "summary/views_registered": lambda r: r["summary"],
    "summary/points": lambda r: r["summary"],
    "summary/observations": lambda r: r["summary"],
    "summary/points_certified": lambda r: r["summary"],
    "summary/cameras_certified": lambda r: r["summary"],
    "summary/cameras_dropped": lambda r: r["summary"],
    "cameras/0/points": lambda r: r["cameras"][0],
    "cameras/0/degrees_of_freedom": lambda r: r["cameras"][0],
    "stages/structure/points": _stage("structure"),
    "stages/structure/certified": _stage("structure"),
    "stages/cameras/cameras": _stage("cameras"),
    "stages/cameras/degrees_of_freedom": _stage("cameras"),
    "stats/items": lambda r: r["stats"],
    "stats/certified": lambda r: r["stats"],
}


@pytest.mark.parametrize("where", sorted(COUNTS))
def test_a_count_stated_as_a_float_is_refused(labelled, where):
    name = where.rsplit("/", 1)[1]

    def as_float(forged: dict) -> None:
        record = COUNTS[where](forged)
        assert type(record[name]) is int
        record[name] = float(record[name])

    refused_naming(_forged(labelled, as_float), "returned", name)


def test_a_status_count_stated_as_a_float_is_refused(labelled):
    def as_float(forged: dict) -> None:
        statuses = forged["stats"]["statuses"]
        status = next(iter(statuses))
        statuses[status] = float(statuses[status])

    refused_naming(_forged(labelled, as_float), "returned", "stats/statuses")


def test_the_stored_reconstructions_still_verify(labelled):
    assert _valid(labelled)
    assert _valid(stored("reconstruction"))
