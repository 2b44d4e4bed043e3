"""Review 25 (issue 33): a hostile review of the verification adapter as an abstract base class
(verify/verification.py: hook() reading Verification's defaults) and of review 24's tightened
reconstruction checks (the calibration tie's other tracks, the returned_K_not_certified warning's
figures).

Found (verified on main, the tests below failing there):

- The returned_K_not_certified warning's figures are checked only beside summary/calibration
  (_check_moved_warning). A result without summary/calibration is read as one from before it was
  stated (_check_unstated_calibration), which asked for the warning but read none of its words:
  the stored reconstruction with summary/calibration removed (autocalibration_certified and
  _determined set false) verified with its warning saying "focal +0.00%, principal point 0.0 px",
  "+25.00%, 300.0 px", "the returned K is the certified one", or given twice. It is now read
  there as beside summary/calibration, its figures those of a registered camera's K against the
  stage's certified one (the genuine words without summary/calibration still verify:
  review 3's TestOldResultAllowances).
- Beside summary/calibration, the warning had only to hold its figures: saying anything else
  beside them verified ("...; the returned K is nonetheless the certified one", other figures
  appended or inserted, the figures in a sentence saying the K is the certified one). Its words
  are now one of the pipeline's forms, written by one function both read
  (calibration_claim.moved_warning).
- The same for the other calibration warnings the verifier asks for: critical_motion and
  certified_K_of_calibrated_cameras verified saying "none: the tracks determine K and every number
  here is certified". Their words (and certified_K_on_range_edge's) are now the pipeline's, from
  calibration_claim (critical_warning, CALIBRATED_CAMERAS_WARNING, edge_warning).
- Not a forgery: hook() evaluated Verification's default before the adapter's member, so a member
  declared without a default (domain) raised for every adapter; it now reads the default only
  when the adapter has none.

Tried and not passing (guards below):

- The hooks, hook by hook: for every listed adapter (triangulation, resection, homography,
  autocalibration, bilinear, stereo_lines, reconstruction) every hook the verifier reads was
  compared between the commit before the base class and main: each adapter's own members are
  unchanged, and every hook it lacks reads None (or ()) where getattr's default was None (or ());
  rel_gap_of, uncertified_statuses and forget keep their fallbacks. 3,485 edited documents (every
  member of the result, certificate, options, first and last item, proof, summary, stats, first
  item of each list and the embedded certificates, deleted or renamed, with and without new
  hashes) gave the same verdict and first failing check on both commits.
- The calibration tie's other tracks ((+30, -20) scene, 200 tracks, 40 and 20 held): the 6, 12
  and 20 tracks nearest the middle re-posed at 0.95, 0.96, 0.97, 1.03, 1.035, 1.04 and 1.05 times
  the focal length and fitted to every track, the autocalibration solved on them and the warning
  restated: each refused by the other tracks.
- summary/calibration/difference edited together with the warning's figures, or the returned and
  certified K swapped: refused (the difference is recomputed from the two K; the returned K is
  the cameras', the certified one the certificate's).
"""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest

from geocert.verify.adapters import VERIFIED_KINDS
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash, stored
from tests.verify.test_forgeries_review24 import _middle_reposed, subset  # noqa: F401  (a fixture)


def _warning(result: dict) -> dict:
    return next(w for w in result["summary"]["warnings"] if w["code"] == "returned_K_not_certified")


def _figures(result: dict, said: str) -> None:
    warning = _warning(result)
    warning["detail"] = re.sub(r"focal [^,]*, principal point [0-9.]+ px", said, warning["detail"])


UNSTATED_EDITS = {
    "zero figures": lambda r: _figures(r, "focal +0.00%, principal point 0.0 px"),
    "large figures": lambda r: _figures(r, "focal +25.00%, principal point 300.0 px"),
    "says the same K": lambda r: _warning(r).update(detail="the returned K is the certified one"),
    "twice": lambda r: r["summary"]["warnings"].append(dict(_warning(r))),
}


@pytest.mark.parametrize("edit", list(UNSTATED_EDITS))
def test_the_returned_K_warning_without_summary_calibration_is_refused(edit):
    """Found: summary/calibration removed (the summary's autocalibration_certified and _determined
    false, as a result from before it was stated), the warning's words edited: verified on main."""
    result = stored("reconstruction")
    del result["summary"]["calibration"]
    result["summary"].update(autocalibration_certified=False, autocalibration_determined=False)
    UNSTATED_EDITS[edit](result)
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid
    assert "returned_K_not_certified" in report.first_failure["detail"], report.first_failure


WORDS_EDITS = {
    "other figures appended": lambda d: d + " (in all: focal +30.00%, principal point 250.0 px)",
    "a denial appended": lambda d: d + "; the returned K is nonetheless the certified one",
    "the figures in another sentence": lambda d: "the returned K is the certified one; focal +0.05%, principal point 0.7 px",
    "other figures beside them": lambda d: d.replace("0.7 px)", "0.7 px, then focal -12.00%, principal point 90.0 px)"),
}


@pytest.mark.parametrize("edit", list(WORDS_EDITS))
def test_the_returned_K_warning_says_nothing_beside_its_figures(edit):
    """Found: the stored reconstruction's warning holding its figures (focal +0.05%, principal
    point 0.7 px) and saying something else beside them: verified on main (review 24 asked only
    that the figures be in its words)."""
    result = stored("reconstruction")
    warning = _warning(result)
    warning["detail"] = WORDS_EDITS[edit](warning["detail"])
    assert "focal +0.05%, principal point 0.7 px" in warning["detail"]
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid
    assert "returned_K_not_certified" in report.first_failure["detail"], report.first_failure


CALIBRATION_WARNINGS = [("reconstruction", "critical_motion"), ("reconstruction_labelled", "critical_motion"),
                        ("reconstruction_labelled", "certified_K_of_calibrated_cameras")]


@pytest.mark.parametrize("name, code", CALIBRATION_WARNINGS)
def test_the_other_calibration_warnings_say_what_the_pipeline_says(name, code):
    """Found: the stored reconstructions' critical_motion and certified_K_of_calibrated_cameras
    warnings saying the opposite of what they warn of: verified on main (the verifier asked only
    that they be there)."""
    result = stored(name)
    warning = next(w for w in result["summary"]["warnings"] if w["code"] == code)
    warning["detail"] = "none: the tracks determine K and every number here is certified"
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid
    assert code in report.first_failure["detail"], report.first_failure


def test_every_form_of_the_returned_K_warning_is_the_pipelines():
    """The forms the verifier accepts are the pipeline's, written through the same function, for
    each of the three which-K cases and both causes."""
    from geocert.formulations.reconstruction import calibration_claim

    moved = {"focal_percent": 0.054, "principal_point_px": 0.707}
    forms = {calibration_claim.moved_warning(adjusted, which, moved)
             for adjusted in (True, False) for which in ("shared", "varying", "per_view")}
    assert len(forms) == 6 and all("(focal +0.05%, principal point 0.7 px)" in form for form in forms)


# --- tried, not passing: guards (each passing on main too) ----------------------------------------

def test_the_difference_edited_with_the_warning_is_refused():
    """summary/calibration/difference and the warning's figures edited together to say the
    returned K is the certified one: the difference is recomputed from the two K."""
    result = stored("reconstruction")
    result["summary"]["calibration"]["difference"].update(focal_percent=0.0, principal_point_px=0.0)
    _figures(result, "focal +0.00%, principal point 0.0 px")
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid and "difference" in report.first_failure["detail"], report.first_failure


def test_the_returned_and_certified_K_swapped_are_refused():
    """summary/calibration's K and certified_K swapped (the warning's figures restated for the
    swap): the returned K is the cameras', the certified one the calibration certificate's."""
    from geocert.formulations.reconstruction import calibration_claim

    result = stored("reconstruction")
    claim = result["summary"]["calibration"]
    claim["K"], claim["certified_K"] = claim["certified_K"], claim["K"]
    claim["difference"] = d = calibration_claim.difference(np.asarray(claim["K"]), np.asarray(claim["certified_K"]))
    _figures(result, f"focal {d['focal_percent']:+.2f}%, principal point {d['principal_point_px']:.1f} px")
    report = verify_any(json.loads(json.dumps(result)))
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure


@pytest.mark.parametrize("scale", [0.97, 1.03])
def test_middle_tracks_reposed_at_3_percent_are_refused_by_the_other_tracks(subset, scale):  # noqa: F811
    """The 20 tracks nearest the middle of the (+30, -20) run (40 of 200 held), re-posed at 0.97
    or 1.03 times the focal length and fitted to every track, the autocalibration solved on them,
    the warning restated: refused by the other tracks."""
    from tests.verify.test_calibration_tie import carrying

    result, data = _middle_reposed(subset, 20, scale)
    forged = carrying(result, data)
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid
    assert "holds no point for" in report.first_failure["detail"], report.first_failure


STORED_BY_KIND = {"triangulation": "triangulation_l2l2", "resection": "resection_l2l2",
                  "homography": "homography2_l2l2", "autocalibration stratified": "autocalibration_stratified",
                  "autocalibration direct": "autocalibration_direct_points", "bilinear": "bilinear_l2l2",
                  "reconstruction": "reconstruction"}


@pytest.mark.parametrize("kind", list(STORED_BY_KIND))
def test_any_stated_member_of_a_certified_item_deleted_is_refused(kind):
    """Each kind's stored certificate, any member of its first item that states something (not
    null) deleted, the hashes made again: refused, whatever default a hook the kind leaves out
    reads (the same verdicts on the commit before the base class)."""
    base = stored(STORED_BY_KIND[kind])
    for name, value in base["certificate"]["items"][0].items():
        if value is None:
            continue
        forged = copy.deepcopy(base)
        del forged["certificate"]["items"][0][name]
        rehash(forged["certificate"])
        assert not verify_any(json.loads(json.dumps(forged))).valid, name


def test_a_stereo_lines_certificate_is_refused_whatever_it_holds():
    """stereo_lines certifies nothing: its adapter (NoCertificates, now a Verification with every
    default) still refuses any document naming it, from a triangulation certificate relabelled."""
    document = copy.deepcopy(stored("triangulation_l2l2")["certificate"])
    document["kind"] = "stereo_lines"
    document["data"] = {"pairs": document["data"].pop("tracks")}
    for item in document["items"]:  # the members a stereo_lines claim would have (its solution R, t)
        item["R"], item["t"] = item.pop("point"), item.pop("at_infinity")
    rehash(document)
    report = verify_any(document)
    assert not report.valid and "never certified" in report.first_failure["detail"], report.first_failure
    assert VERIFIED_KINDS["stereo_lines"].certifies is False


def test_hook_reads_a_member_declared_without_a_default():
    """hook() evaluated Verification's default before looking at the adapter: a member declared
    with no default (domain) raised AttributeError for every adapter, which defines it (fails on
    main; no check reads domain through hook() yet)."""
    from geocert.verify.verification import hook

    for kind in VERIFIED_KINDS.values():
        assert hook(kind.verification, "domain") == kind.verification.domain, kind.name

