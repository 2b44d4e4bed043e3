"""Issue 35 (honesty): under "auto", registered views spread too far for the stratified frame
(frames.world_frame_bounded false) send the upgrade to the direct method without trying the
stratified one; when the direct method then finds the upgrade, the result says the stratified
method was not run and why (Metric.stratified_not_run, the autocalibration stage's reason)."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.solvers.reconstruction import upgrade
from tests.verify.test_forgeries_review55 import _norm, _with_near_views


@pytest.mark.slow  # the direct method on twelve views: some 15 to 50 s
def test_auto_says_the_stratified_method_was_not_run_on_views_spread_beyond_its_frame():
    # review 55's data: six views 2^-36 from the reference outvote the median, leaving the
    # scene's cameras some 3e6 away in the stratified frame (beyond 2^8)
    data, _ = _with_near_views(-36.0, 6)
    norm = _norm(data)
    assert not frames.world_frame_bounded(norm) and norm.world_scale * norm.world_ratio_highest > 2.0 ** 8
    P, X = np.asarray(data["cameras"], dtype=float), np.asarray(data["points"], dtype=float)[:4]
    metric = upgrade.autocalibrate(list(P), X, tuple(data["image_size"]), {},
                                   autocalibration_problem.AutocalibrationOptions(time_limit_s=60), 200, "auto")
    assert metric.K is not None and [stage["name"] for stage in metric.stages] == ["direct"]
    said = metric.stratified_not_run
    assert said is not None and "stratified method was not run" in said, said
    assert "spread too far" in said and "world_frame_bounded" in said and "direct" in said, said


def test_the_direct_method_asked_for_says_nothing_of_the_stratified_one(monkeypatch):
    """Method "direct" never runs the stratified method: not running it is what was asked."""
    monkeypatch.setattr(upgrade, "_direct", lambda problem, P, X, options: (np.eye(4), np.eye(3), [
        {"name": "direct", "status": "optimal", "certified": True, "reason": None}]))
    data, _ = _with_near_views(-36.0, 6)
    P, X = np.asarray(data["cameras"], dtype=float), np.asarray(data["points"], dtype=float)
    for method, said in (("direct", False), ("auto", True)):
        metric = upgrade.autocalibrate(list(P), X, tuple(data["image_size"]), {},
                                       autocalibration_problem.AutocalibrationOptions(), 200, method)
        assert (metric.stratified_not_run is not None) is said, (method, metric.stratified_not_run)
