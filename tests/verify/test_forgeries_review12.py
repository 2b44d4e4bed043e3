"""A twelfth hostile review of the verifier (issue 33): a reconstruction camera's verdict hidden
behind a status that claims less. Each test starts from the stored genuine reconstruction (two
of its six cameras judged and not certified: a free 3x4 camera beats each by more than its
allowance, so no bound can certify it), edits the cameras and their stage consistently with one
another, and asserts the verifier refuses it; each forgery verified before its fix.

- A judged camera called never started (``time_limit`` or ``cancelled``), its point count left
  out: unstarted cameras were ordered by their stated counts, so a missing count sorted last.
  They are now ordered by the counts recomputed from the returned points.
- A judged camera called not judged (``not_run``): it left the doubtful rule's count, so the
  result could drop its ``reconstruction_doubtful`` warning. A camera is not judged only when the
  cameras stage never ran: then none is, and the stage did not end "done".

Found and left (the review's other classes, for a later stop): stage statuses not tied to what
each stage produced, nested stage members (``same_rig_as``, ``radial_tested``, ``per_view``,
``started_from``) untyped, and a job's stop read from its own stats alone."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from geocert.verify.checks import verify_any

STORED = Path(__file__).parent.parent / "data" / "certificates"
UNCERTIFIABLE = (1, 2)  # judged, not certified, not searched: "no bound can certify it"


@pytest.fixture(scope="module")
def genuine() -> dict:
    document = json.loads((STORED / "reconstruction.json").read_text())
    assert verify_any(document).valid
    assert [document["cameras"][v]["status"] for v in UNCERTIFIABLE] == ["not_certified"] * 2
    return document


def _stage(document: dict, name: str) -> dict:
    return next(stage for stage in document["stages"] if stage["name"] == name)


def _unfigured(camera: dict, status: str) -> None:
    camera.update(status=status, cost=None, points=None, degrees_of_freedom=None, tolerance=None,
                  bound_reason=None)


@pytest.mark.parametrize("stop", ["time_limit", "cancelled"])
def test_a_judged_camera_called_never_started_is_refused(genuine, stop):
    forged = copy.deepcopy(genuine)
    for view in UNCERTIFIABLE:
        _unfigured(forged["cameras"][view], stop)
    _stage(forged, "cameras").update(status=stop, cameras_not_started=len(UNCERTIFIABLE))
    if stop == "cancelled":
        forged["stats"]["statuses"] = {"cancelled": 1}
    report = verify_any(forged)
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure


def test_a_count_of_cameras_not_started_other_than_those_called_so_is_refused(genuine):
    forged = copy.deepcopy(genuine)
    for view in UNCERTIFIABLE:
        _unfigured(forged["cameras"][view], "time_limit")
        forged["cameras"][view]["points"] = 16
    _stage(forged, "cameras").update(status="time_limit", cameras_not_started=1)
    report = verify_any(forged)
    assert not report.valid and "not started" in report.first_failure["detail"], report.first_failure


def test_a_judged_camera_called_not_judged_is_refused(genuine):
    forged = copy.deepcopy(genuine)
    for view in UNCERTIFIABLE:
        camera = forged["cameras"][view]
        _unfigured(camera, "not_run")
        camera.update(certified=False, searched=False, lower_bound=None, gap=None, optimal_cost=None,
                      set_aside=None, points=0)
    report = verify_any(forged)
    assert not report.valid and "not judged" in report.first_failure["detail"], report.first_failure
