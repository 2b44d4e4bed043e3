"""Certificates written by the solver and stored by a third party stay checkable: the genuine
full certificates of every certified kind in tests/data/certificates (format version 2, as the
solver wrote them before the verifier's floating-point checks were tightened, see its
make_fixtures.py) verify, each as the result that carries it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from geocert.verify.checks import verify_any, verify_document

STORED = Path(__file__).resolve().parents[1] / "data" / "certificates"
NAMES = sorted(path.stem for path in STORED.glob("*.json"))
KINDS = ("triangulation", "resection", "homography", "autocalibration", "bilinear", "reconstruction")


def stored(name: str) -> dict:
    return json.loads((STORED / f"{name}.json").read_text())


def test_every_certified_kind_is_stored():
    kinds = {stored(name)["kind"] for name in NAMES}
    methods = {stored(name)["certificate"]["options"].get("method") for name in NAMES}
    assert set(KINDS) <= kinds and {"stratified", "direct"} <= methods


def test_every_stratified_frame_is_stored():
    """A proof posed in the world as given (no world_scale: the earlier writers'), and one stating
    world_scale beside reference_scale (the current writer's): both stay readable."""
    frames = {tuple(sorted({"reference_scale", "world_scale"} & item["proof"].keys()))
              for name in NAMES if stored(name)["kind"] == "autocalibration"
              for item in stored(name)["certificate"]["items"] if isinstance(item.get("proof"), dict)
              and item["proof"].get("type", "").startswith("stratified")}
    assert {(), ("reference_scale", "world_scale")} <= frames, frames


@pytest.mark.parametrize("name", NAMES)
def test_a_stored_certificate_verifies_with_its_result(name):
    result = stored(name)
    assert result["certificate"]["version"] == 2
    report = verify_any(result)
    assert report.valid, report.first_failure
    assert report.items_checked == sum(item["certified"] for item in result["certificate"]["items"])
    assert verify_document(result["certificate"]).valid
    if "camera_certificate" in result:
        assert verify_document(result["camera_certificate"]).valid
