"""Issue 35 (honesty): a reconstruction with autocalibration "auto" whose registered views spread
too far for the stratified frame returns the direct method's upgrade; its autocalibration stage
says the stratified method was not run and why (the page shows that reason beside the metric
upgrade), and the document still verifies.

The kind's example registers views well spread; the spread check is made to say "too far"
(upgrade.frames, for the upgrade alone) so that the rest of the run, and the verifier, are
genuine. tests/solvers/reconstruction/test_upgrade_over_spread.py holds views truly beyond 2^8."""

from __future__ import annotations

import copy
import json
from types import SimpleNamespace

import pytest

from geocert.formulations.autocalibration import frames
from geocert.solvers.reconstruction import upgrade

pytestmark = [pytest.mark.filterwarnings("ignore"), pytest.mark.slow]  # a full solve: some 20 s


def _spread_too_far(monkeypatch) -> None:
    monkeypatch.setattr(upgrade, "frames", SimpleNamespace(world_frame_bounded=lambda norm: False,
                                                           EARLIER_WORLD_HIGHEST=frames.EARLIER_WORLD_HIGHEST))


@pytest.fixture(scope="module")
def over_spread():
    from geocert.jobs.runner import solve_job
    from geocert.kinds.reconstruction import KIND

    body = copy.deepcopy(KIND.example)
    body["options"].update(autocalibration="auto", certificate="full")
    with pytest.MonkeyPatch.context() as patched:
        _spread_too_far(patched)
        return solve_job(body)


def _stage(result: dict) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == "autocalibration")


def test_the_autocalibration_stage_says_the_stratified_method_was_not_run_and_why(over_spread):
    stage = _stage(over_spread)
    assert stage["method"] == "auto" and [s["name"] for s in stage["stages"]] == ["direct"], stage
    assert stage["K"] is not None and stage["status"] == "done"
    reason = stage["reason"] or ""
    assert "stratified method was not run" in reason and "spread too far" in reason, reason
    # the full certificate's note follows it, not in its place
    assert "carries only the stratified method's certificate" in reason, reason


def test_the_document_saying_so_verifies_with_geocert_verify(over_spread, tmp_path, capsys):
    from geocert.app.cli import main

    path = tmp_path / "over_spread.json"
    path.write_text(json.dumps(over_spread))
    code = main(["verify", str(path)])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["valid"], report.get("first_failure")
