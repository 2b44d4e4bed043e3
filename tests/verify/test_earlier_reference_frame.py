"""A stratified proof written before proofs stated ``reference_scale`` is posed in the reference
camera as given. That frame moves with the camera's scale, which is no part of the input, and
the failure the unit reference frame mends could be certified in it: the stored stratified
scene's reference times 2^28, solved by that earlier writer, certified K = [[5000, 10, 250],
[0, 5250, 750]] (a corner of the intrinsics ranges; the truth is f = 1000, (500, 500)), and the
verifier, reading proofs without a scale in their given frame, accepted it.

Such a proof is now read in its given frame only where that frame is well scaled (the
preconditioned reference camera's largest entry below 2^frames.EARLIER_FRAME_EXPONENT), and
refused naming proof/reference_scale otherwise; the stored certificates of that writer lie
well inside and still verify (test_stored_certificates).

earlier/autocalibration_stratified_reference_times_2p28.json is that earlier writer's result,
stored as written: the stored stratified certificate's data with camera 5 (its reference) times
2^28, solved with the certificate's own options by the code before the unit reference frame
(tests/formulations/autocalibration/test_reference_scale.py poses the same data)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.verify.autocalibration import read_data
from geocert.verify.checks import verify_any

STORED = Path(__file__).resolve().parents[1] / "data" / "certificates"
TRUTH = np.array([[1000.0, 0.0, 500.0], [0.0, 1000.0, 500.0], [0.0, 0.0, 1.0]])  # examples/generate.py's scene
EARLIER_WRITTEN = ("autocalibration_stratified", "autocalibration_five_views", "reconstruction",
                   "reconstruction_labelled")  # stored stratified proofs stating no reference_scale


def _read(name: str) -> dict:
    return json.loads((STORED / f"{name}.json").read_text())


def _stratified_certificate(result: dict) -> dict:
    return result["certificate"] if result["kind"] == "autocalibration" else result["calibration_certificate"]


def _given_frame(certificate: dict):
    cameras, points, image_size = read_data(certificate["data"])
    intrinsics = dict(certificate["options"].get("intrinsics") or {})
    return autocalibration_problem.prepare(cameras, points, image_size, intrinsics,
                                           certificate["items"][0]["proof"].get("reference"), unit_reference=False)


def test_the_earlier_writers_certificate_in_a_badly_scaled_frame_is_refused():
    result = _read("earlier/autocalibration_stratified_reference_times_2p28")
    items = result["certificate"]["items"]
    # as written: both stages certified, no scale stated, and the K certified is no answer
    assert all(item["certified"] for item in items)
    assert not any("reference_scale" in item["proof"] for item in items)
    assert np.abs(np.asarray(result["K"]) - TRUTH).max() > 1000.0
    report = verify_any(result)
    assert not report.valid
    assert report.first_failure["check"] == "scope"
    assert report.first_failure["detail"].startswith("proof/reference_scale is not stated")
    assert not frames.earlier_frame_readable(_given_frame(result["certificate"]).norm)


@pytest.mark.parametrize("name", EARLIER_WRITTEN)
def test_the_stored_earlier_certificates_lie_in_the_range_read_as_given(name):
    """The stated range holds every stored certificate of that writer, with room: a factor 2^7 or
    more below its bound (each also verifies: test_stored_certificates)."""
    certificate = _stratified_certificate(_read(name))
    assert not any("reference_scale" in item.get("proof", {}) for item in certificate["items"])
    problem = _given_frame(certificate)
    assert frames.earlier_frame_readable(problem.norm)
    assert problem.norm.reference_unit_scale >= 2.0 ** (7 - frames.EARLIER_FRAME_EXPONENT)


def _earlier_writer(monkeypatch, factor: float) -> dict:
    """The stored scene with its reference camera times ``factor``, solved as the earlier writer
    did: the stratified stages in the reference as given, their proofs stating no scale."""
    prepare = autocalibration_problem.prepare

    def as_given(*args, **kwargs):
        if len(args) < 6:  # the frame not chosen by the caller: the reference as given
            kwargs.setdefault("unit_reference", False)
        return prepare(*args, **kwargs)

    certificate = _read("autocalibration_stratified")["certificate"]
    data = copy.deepcopy(certificate["data"])
    cameras = np.asarray(data["cameras"], dtype=float)
    cameras[5] *= factor  # its reference (frames.reference_camera)
    data["cameras"] = cameras.tolist()
    with monkeypatch.context() as patched:
        patched.setattr(autocalibration_problem, "prepare", as_given)
        patched.delenv("GEOCERT_SELF_VERIFY", raising=False)  # that writer's self-check was that verifier's
        return solve_job({"kind": "autocalibration", "data": data, "options": certificate["options"]})


def test_an_earlier_writers_proof_in_a_well_scaled_frame_still_verifies(monkeypatch):
    """Just inside the range (the reference's largest entry in [2^7, 2^8)): read as given."""
    result = _earlier_writer(monkeypatch, 2.0 ** 17)
    assert _given_frame(result["certificate"]).norm.reference == 5
    assert not any("reference_scale" in item["proof"] for item in result["certificate"]["items"])
    assert np.abs(np.asarray(result["K"]) - TRUTH).max() < 0.01
    assert verify_any(result).valid


def test_an_earlier_writers_proof_just_beyond_the_range_is_refused(monkeypatch):
    """The same writer one power of two further (its K still good: the range leaves a margin):
    refused whatever its K, the frame is not one read as given; solved now, it verifies."""
    result = _earlier_writer(monkeypatch, 2.0 ** 18)
    report = verify_any(result)
    assert not report.valid and report.first_failure["detail"].startswith("proof/reference_scale is not stated")
    current = solve_job({"kind": "autocalibration", "data": result["certificate"]["data"],
                         "options": result["certificate"]["options"]})
    assert all("reference_scale" in item["proof"] for item in current["certificate"]["items"])
    assert np.abs(np.asarray(current["K"]) - TRUTH).max() < 0.01
    assert verify_any(current).valid
