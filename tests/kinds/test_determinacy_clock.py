"""An autocalibration's determinacy analysis keeps its job's clock (issue 36): it ran after both
stages, outside any clock (0.7 s of CPU at 200 views). Now each stage's analysis stops at the
job's deadline, between two evaluations of a cost: an analysis finished by then is kept, and one
not finished (or not begun) is a document that says it was not analysed, and why. The clock here
is a counter (each reading one "second"), so that where it stops does not depend on the machine."""

from __future__ import annotations

import pytest

from geocert.kinds import autocalibration as kind_module
from geocert.kinds import get_kind
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.solvers.autocalibration import scenes, stratified
from geocert.core import determinacy

KIND = get_kind("autocalibration")


@pytest.fixture(scope="module")
def solved():
    scene = scenes.make_scene(6, 0.1, seed=21)
    parsed = KIND.parse(scene.job_data())
    options = KIND.options_type()
    problem = autocalibration_problem.prepare(parsed.cameras, parsed.points, parsed.image_size, options.intrinsics)
    return parsed, options, problem, stratified.solve(problem, options, lambda *args, **kwargs: None)


class Counter:
    """time.monotonic as a count of its readings."""

    def __init__(self):
        self.readings = 0

    def __call__(self) -> float:
        self.readings += 1
        return float(self.readings)


def item(solved, deadline):
    parsed, options, problem, result = solved
    return kind_module.stratified_item(parsed, options, problem, result, False, deadline=deadline)


def said_not_analysed(document: dict, stage: str) -> bool:
    return (document["intervals"] == [] and not document["determined"]
            and [w["code"] for w in document["warnings"]] == ["time_limit"]
            and document["warnings"][0]["detail"].startswith(f"the {stage} stage's determinacy was not analysed")
            and "time_limit_s" in document["warnings"][0]["detail"])


def test_without_a_deadline_both_stages_are_analysed(solved):
    stages = item(solved, None)["stages"]
    assert [len(stage["determinacy"]["intervals"]) for stage in stages] == [4, 5]
    assert not any(w["code"] == "time_limit" for stage in stages for w in stage["determinacy"]["warnings"])


def test_past_the_deadline_neither_stage_is_analysed_and_each_says_so(solved):
    stages = item(solved, 0.0)["stages"]  # any reading of time.monotonic is past 0
    assert [said_not_analysed(stage["determinacy"], stage["name"]) for stage in stages] == [True, True]


def test_the_clock_stops_an_analysis_under_way_keeping_the_one_finished(solved, monkeypatch):
    """The readings the affine stage's analysis takes are counted first (with no deadline to
    reach); a deadline a few readings after them lets it finish and stops the metric stage's,
    and one half-way through it stops the affine stage's too."""
    clock, ends = Counter(), []
    monkeypatch.setattr(determinacy.time, "monotonic", clock)
    monkeypatch.setattr(determinacy, "_until", _noting_ends(determinacy._until, clock, ends))
    whole = item(solved, 1e9)["stages"]
    affine_end, metric_end = ends
    assert 0 < affine_end < metric_end
    clock.readings = 0
    stopped = item(solved, float(affine_end + 3))["stages"]
    assert stopped[0]["determinacy"] == whole[0]["determinacy"] and len(whole[0]["determinacy"]["intervals"]) == 4
    assert said_not_analysed(stopped[1]["determinacy"], "metric")
    clock.readings = 0
    during = item(solved, float(affine_end // 2))["stages"]
    assert said_not_analysed(during[0]["determinacy"], "affine")
    assert said_not_analysed(during[1]["determinacy"], "metric")


def _noting_ends(until, clock, ends):
    """determinacy._until, noting the clock's readings as each analysis ends."""
    from contextlib import contextmanager

    @contextmanager
    def noted(deadline):
        with until(deadline):
            yield
        ends.append(clock.readings)

    return noted
