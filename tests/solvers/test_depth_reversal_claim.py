"""The verifier's reading of the depth-reversal check's record (reconstruction.depth_reversal_claim):
its thresholds are the pipeline's, and a record is refused unless it is its verdict's."""

from __future__ import annotations

import pytest

from geocert.pipelines.reconstruction import ambiguity
from geocert.solvers.core.strict import Invalid
from geocert.solvers.reconstruction import depth_reversal_claim as claim


def test_the_thresholds_are_the_pipelines():
    assert (claim.MIRROR_CHI2, claim.MIRROR_MARGIN) == (ambiguity.MIRROR_CHI2, ambiguity.MIRROR_MARGIN)


def _figures(cost=100.0, twin=400.0, variance=1.0, **more):
    statistic = (twin - cost) / variance
    ambiguous = not (statistic > claim.MIRROR_CHI2 and twin > 1.1 * cost)
    return {"checked": True, "cost_px2": cost, "mirror_cost_px2": twin, "noise_variance_px2": variance,
            "statistic": statistic, "cost_ratio": twin / cost, "threshold": claim.MIRROR_CHI2,
            "margin": claim.MIRROR_MARGIN, "ambiguous": ambiguous, "adopted": False,
            "mirror_rotation_deg": {"0": 0.0, "1": 30.0}, **more}


CAMERAS = [{"view": 0, "registered": True, "mirror_rotation_deg": 0.0},
           {"view": 1, "registered": True, "mirror_rotation_deg": 30.0}]


def test_a_verdict_its_figures_give_is_read():
    claim.check({"depth_reversal": _figures(), "poses_determined": True}, CAMERAS, [])
    claim.check({"depth_reversal": _figures(twin=100.5), "poses_determined": False}, CAMERAS, [])


@pytest.mark.parametrize("summary", [
    {"depth_reversal": _figures(), "poses_determined": False},  # the verdict not the figures'
    {"depth_reversal": _figures(ambiguous=True), "poses_determined": False},
    {"depth_reversal": {**_figures(), "statistic": 0.0}, "poses_determined": True},
    {"depth_reversal": {"checked": False, "reason": "fewer than 2 views registered"}, "poses_determined": None},
    {"depth_reversal": {"checked": False, "reason": "stopped before the twin's adjustment ended"},
     "poses_determined": None},
    {"depth_reversal": None, "poses_determined": True},
], ids=["verdict", "ambiguous_word", "statistic", "not_checked_with_2_views", "not_checked_no_stop", "no_record"])
def test_a_record_not_its_verdicts_is_refused(summary):
    cameras = [dict(c, mirror_rotation_deg=None) for c in CAMERAS] if summary["poses_determined"] is None else CAMERAS
    with pytest.raises(Invalid):
        claim.check(summary, cameras, [])


@pytest.mark.parametrize("value", ["none", -1.0, 181.0, 5.0])
def test_a_cameras_mirror_rotation_is_the_figures(value):
    cameras = [CAMERAS[0], dict(CAMERAS[1], mirror_rotation_deg=value)]
    with pytest.raises(Invalid):
        claim.check({"depth_reversal": _figures(), "poses_determined": True}, cameras, [])
