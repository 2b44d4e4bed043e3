"""Review 24 (issue 33): a hostile review of the direct method's proven focal interval, the
calibration tie's other tracks, the returned_K_not_certified warning and the centred calibration
certificate on an off-centre scene.

Found (verified on main, each test below failing there):

- The tie's other tracks allowed the certificate's cameras twice the returned cameras' cost
  (calibration_tie._other_tracks). Genuine certificates measure within 0.12 standard deviations
  of the returned cameras' cost (times the model's ratio, 1 for every run of today's pipeline):
  the (+30, -20) scene of 200 tracks with 40 (20) held 0.00, centred 0.00, (-60, +45) 0.00, the
  Oxford Model House with 60 of its tracks held 0.12, the Oxford Dinosaur's every 10th track (66
  held) 0.01 (calibration_tie.OTHER_TRACKS_MEASURED). On the 40-track (+30, -20) run a certificate
  of the 6 (12, 20) tracks nearest the scene's middle, its cameras re-posed at 1.02 to 1.08 times
  the focal length and fitted to every placed track with K held, was tied (1.08 times: 445 px^2 on
  the other tracks against 471 allowed, the returned cameras 229), and the whole document verified
  with a certified K 8% long. The allowance is now the shared observations' (_fit): the noise's 3
  standard deviations and a quarter of what the model's ratio adds (246 px^2 there): 1.04 times
  and beyond are refused, 1.02 (236 px^2, within the noise) still ties.
- The returned_K_not_certified warning was only asked to be there: its words were the document's.
  On the stored reconstruction (the returned K 0.05% and 0.7 px from the certified one) it verified
  saying "focal +0.00%, principal point 0.0 px", saying the returned K is the certified one, or
  given twice. It now states summary/calibration/difference's figures as the pipeline writes them,
  once, and only when the returned K is not the certified one.

Stated, not tightened: a calibration certificate built at the image's centre beside an off-centre
run is allowed a quarter of the centred model's misfit (review 22), room a forger can use: re-posed
at 0.96 to 1.05 times the returned focal length at (+30, -20) (36 px off) and 1.00 to 1.15 at
(-60, +45) (75 px off) it is tied, where the genuine centred certificates certify 1.002 and 1.07
times. The statement promised "a reconstruction that close, fitting about as well", not a focal
length; tightening would refuse the stored genuine 75 px certificate (it uses 0.73 of the room),
so the tolerance is now stated in the report's statement and docs/certificate.md. Seen beside it
(on main too, not changed here): a run registered at the centre (the pipeline before issue 35)
with 40 or 20 of 200 tracks held at (-60, +45) is refused by the shared observations' fit (377.5
px^2 against 366 allowed).

Tried and not passing (guards below where cheap):

- The direct proven interval (Table 7.1's seed 5, both ends proven): each end's dual scaled by
  1e-300, 1e-200, 0, -1, 1e200; each c set to 0, -0, 5e-324, 1e-308, -1, +-1e300; cost_increase 0,
  -0, 2^-128 (the genuine dual then proves nothing: refused), 1e-300 and 5e-324 (out of range); an
  end dropped (the scope's end then, wider than the interval stated: refused); the interval
  flipped or narrowed (refused); the stage's cost, lower_bound or gap removed, null, a string, a
  boolean, 0, -1, 1e300 (each refused: the stage states its claim's); determinacy saying proven
  without its intervals or with them but proven false (refused). Widening the stated interval
  (to [0, 1e308] or a negative lower end) verifies: a weaker true statement, as documented. Every
  dual is read by direct_relaxation.safe_bound in the programs rebuilt from this certificate's own
  data, so a dual from another problem proves only what it proves here.
"""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored
from tests.verify.test_direct_autocalibration_proven import result as direct_result  # noqa: F401  (a fixture)
from tests.verify.test_forgeries_review18 import SHIFTS, _scene_job


@pytest.fixture(scope="module")
def subset() -> dict:
    """The (+30, -20) off-centre run with a calibration certificate of 40 of its 200 tracks (the
    registration at the estimated principal point)."""
    return solve_job(_scene_job({"autocalibration_points": 40}, points=200,
                                shift=np.tile(SHIFTS["(+30, -20)"], (8, 1))))


def test_the_genuine_other_tracks_cost_what_the_returned_cameras_do(subset):
    """The genuine certificate's cameras fit the other 160 tracks' 1,280 observations within a
    standard deviation of the returned cameras' cost (measured: 176.11 against 176.11)."""
    report = verify_any(json.loads(json.dumps(subset)))
    assert report.valid, report.first_failure
    tie = report.scope["calibration_tie"]
    sd = tie["other_returned_cost_px2"] * np.sqrt(2.0 / (2 * tie["other_observations"]))
    assert abs(tie["other_cost_px2"] - tie["other_returned_cost_px2"]) <= sd


def _middle_reposed(result: dict, count: int, scale: float) -> tuple[dict, dict]:
    """(the result naming the ``count`` tracks nearest the scene's middle as the certificate's, the
    certificate's data): its cameras K [R | t], K the returned one with its focal length times
    ``scale`` (the returned principal point, square pixels, no skew), adjusted (bundle model
    "fixed") to every placed track's observations, as a forger fits them; its points the held
    tracks'."""
    from geocert.solvers.reconstruction import bundle
    from tests.support import stage

    cameras = {c["view"]: c for c in result["cameras"] if c.get("registered")}
    views = sorted(cameras)
    column = {v: k for k, v in enumerate(views)}
    placed = [p for p in result["points"] if p.get("point") is not None]
    X = np.array([p["point"] for p in placed])
    held = sorted(placed[j]["track"] for j in np.argsort(np.linalg.norm(X - np.median(X, axis=0), axis=1))[:count])
    view, track, pixels = zip(*[(column[v], j, (u, w)) for j, p in enumerate(placed) for v, u, w in p["observations"]])
    K = np.array(cameras[views[0]]["K"], dtype=float)
    K[0, 0] *= scale
    K[1, 1], K[0, 1] = K[0, 0], 0.0
    K, R, t, Y, _, _ = bundle.metric(K, np.array([cameras[v]["R"] for v in views], dtype=float),
                                     np.array([cameras[v]["t"] for v in views], dtype=float), X, np.array(view),
                                     np.array(track), np.array(pixels, dtype=float), model="fixed")
    row = {p["track"]: j for j, p in enumerate(placed)}
    data = {**result["calibration_certificate"]["data"],
            "cameras": [(K @ np.c_[R[column[v]], t[column[v]]]).tolist() for v in views],
            "points": [[*Y[row[track]].tolist(), 1.0] for track in held]}
    forged = copy.deepcopy(result)
    record = stage(forged, "autocalibration")
    record.update(certificate_views=views, certificate_tracks=held)
    if "points_used" in record:  # the record restated as the forger's certificate has it
        record["points_used"] = len(held)
    return forged, data


@pytest.mark.parametrize("count", [6, 20])
def test_middle_tracks_reposed_at_1_08_are_refused_by_the_other_tracks(subset, count):
    """Found: the certificate of the ``count`` tracks nearest the middle, re-posed at 1.08 times
    the focal length and fitted to every track (its autocalibration solved and verified, the
    returned_K_not_certified warning restated), verified within twice the returned cameras' cost
    on the other tracks."""
    from tests.verify.test_calibration_tie import carrying

    result, data = _middle_reposed(subset, count, 1.08)
    forged = carrying(result, data)  # (its returned_K_not_certified warning restated with the new difference)
    returned = float(next(c for c in subset["cameras"] if c.get("registered"))["K"][0][0])
    assert abs(forged["summary"]["calibration"]["certified_K"][0][0] / returned - 1.08) < 0.01
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid
    assert "holds no point for" in report.first_failure["detail"], report.first_failure


def _moved_warning(result: dict) -> dict:
    return next(w for w in result["summary"]["warnings"] if w["code"] == "returned_K_not_certified")


@pytest.mark.parametrize("edit", ["zero figures", "says the same K", "twice"])
def test_the_returned_K_warning_states_the_difference(edit):
    """Found: the stored reconstruction's warning (focal +0.05%, principal point 0.7 px) edited to
    say nothing moved, or given twice, verified."""
    result = stored("reconstruction")
    assert verify_any(copy.deepcopy(result)).valid
    warning = _moved_warning(result)
    assert "focal +0.05%, principal point 0.7 px" in warning["detail"]
    if edit == "zero figures":
        warning["detail"] = re.sub(r"focal [^,]*, principal point [0-9.]+ px", "focal +0.00%, principal point 0.0 px",
                                   warning["detail"])
    elif edit == "says the same K":
        warning["detail"] = "the returned K is the certified one"
    else:
        result["summary"]["warnings"].append(dict(warning))
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid
    assert "returned_K_not_certified" in report.first_failure["detail"], report.first_failure


def test_the_returned_K_warning_is_still_required():
    """Guard (refused on main too): the warning deleted."""
    result = stored("reconstruction")
    result["summary"]["warnings"] = [w for w in result["summary"]["warnings"]
                                     if w["code"] != "returned_K_not_certified"]
    report = verify_any(result)
    assert not report.valid and "returned_K_not_certified" in report.first_failure["detail"]


# --- tried, not passing: guards ------------------------------------------------------------------

EDITS = {  # each a sublevel edit: (side, field, value) or (None, name, value)
    "lower z * 1e-300": ("lower", "z", 1e-300), "upper z * 1e-200": ("upper", "z", 1e-200),
    "lower z * 0": ("lower", "z", 0.0), "upper z * -1": ("upper", "z", -1.0), "lower z * 1e200": ("lower", "z", 1e200),
    "lower c 0": ("lower", "c", 0.0), "lower c -0": ("lower", "c", -0.0), "upper c 5e-324": ("upper", "c", 5e-324),
    "upper c 1e-308": ("upper", "c", 1e-308), "lower c 1e300": ("lower", "c", 1e300),
    "upper c -1e300": ("upper", "c", -1e300), "cost_increase 0": (None, "cost_increase", 0.0),
    "cost_increase 2^-128": (None, "cost_increase", 2.0 ** -128), "cost_increase 5e-324": (None, "cost_increase", 5e-324),
    "lower end dropped": (None, "lower", None), "upper end dropped": (None, "upper", None),
}


@pytest.mark.parametrize("edit", list(EDITS))
def test_the_direct_proven_intervals_numbers_edited_are_refused(direct_result, edit):  # noqa: F811
    """The direct method's proven focal interval (Table 7.1's seed 5), one number of its proof
    replaced by a subnormal, 0, -0, a huge or tiny normal number, or its sign flipped, the result's
    determinacy restated from it: refused, every dual read by safe_bound in the programs rebuilt
    from the certificate's data (passing on main as here)."""
    from geocert.formulations.autocalibration import direct_sublevel
    from geocert.core.certificates import pack, unpack
    from tests.verify.test_forgeries import rehash

    forged = copy.deepcopy(direct_result)
    sublevel = forged["certificate"]["items"][0]["proof"]["sublevel"]
    side, name, value = EDITS[edit]
    if side is None:
        sublevel[name] = value
    elif name == "z":
        sublevel[side][0]["z"] = pack(unpack(sublevel[side][0]["z"]) * value)
    else:
        sublevel[side][0]["c"] = value
    forged["stages"][0]["determinacy"]["proven_intervals"] = direct_sublevel.proven_document(sublevel)
    rehash(forged["certificate"])
    first = verify_any(json.loads(json.dumps(forged))).first_failure
    assert first is not None and first["check"] == "proven_interval", first
