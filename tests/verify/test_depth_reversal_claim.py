"""The verifier's reading of the depth-reversal check's record (reconstruction.depth_reversal_claim):
its thresholds are the pipeline's, and a record is refused unless it is its verdict's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.core.strict import Invalid
from geocert.formulations.reconstruction import depth_reversal_claim as claim


def _figures(cost=100.0, twin=400.0, variance=1.0, **more):
    statistic = (twin - cost) / variance
    ambiguous = not (statistic > claim.MIRROR_CHI2 and twin > (1 + claim.MIRROR_MARGIN) * cost)
    return {"checked": True, "cost_px2": cost, "mirror_cost_px2": twin, "noise_variance_px2": variance,
            "statistic": statistic, "cost_ratio": twin / cost if cost else None, "threshold": claim.MIRROR_CHI2,
            "margin": claim.MIRROR_MARGIN, "ambiguous": ambiguous, "adopted": False,
            "reference_view": 0, "mirror_rotation_deg": {"0": 0.0, "1": TURNED}, "model": "simple",
            "returned_refitted": True, "observations": 100, "observations_fitting": 90,
            "mirror_observations_fitting": 80, "focal_px": 1000.0, "mirror_focal_px": 1100.0, **more}


# View 1 turned 15 degrees about the vertical from view 0: its twin in view 0's frame, turned the
# other way, points 30 degrees from it (the mirror reverses the turn's axis' depth component).
ROTATIONS = [np.eye(3), Rotation.from_euler("y", 15.0, degrees=True).as_matrix()]
TURNED = 30.0
CAMERAS = [{"view": v, "registered": True, "R": R.tolist(), "mirror_rotation_deg": a}
           for v, (R, a) in enumerate(zip(ROTATIONS, (0.0, TURNED)))]


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
    with pytest.raises(Invalid, match="depth_reversal"):
        claim.check(summary, cameras, [])


@pytest.mark.parametrize("capped", [True, False, None])
def test_whether_the_twins_adjustment_reached_its_cap_is_a_boolean_where_stated(capped):
    # mirror_capped: the twin's stated cost is an upper bound (its adjustment at its iteration
    # cap); taken as stated like the costs, absent from results written before it
    more = {} if capped is None else {"mirror_capped": capped}
    claim.check({"depth_reversal": _figures(**more), "poses_determined": True}, CAMERAS, [])


@pytest.mark.parametrize("capped", [0.5, 1, "yes", None])
def test_a_mirror_capped_not_a_boolean_is_refused(capped):
    with pytest.raises(Invalid, match="mirror_capped"):
        claim.check({"depth_reversal": _figures(mirror_capped=capped), "poses_determined": True}, CAMERAS, [])


def test_the_angle_is_the_constructed_twins():
    assert claim.depth_reversal.mirror_angles_deg(dict(enumerate(ROTATIONS)), 0) == pytest.approx({0: 0.0, 1: TURNED})
    # a turn about the reference's optical axis is its own mirror image
    about_the_axis = Rotation.from_euler("z", 40.0, degrees=True).as_matrix()
    assert claim.depth_reversal.mirror_angles_deg({0: np.eye(3), 1: about_the_axis}, 0)[1] == pytest.approx(0.0,
                                                                                                            abs=1e-9)


@pytest.mark.parametrize("value", ["none", -1.0, 181.0, 5.0, 0.0, None])
def test_a_cameras_mirror_rotation_is_the_twins(value):
    cameras = [CAMERAS[0], dict(CAMERAS[1], mirror_rotation_deg=value)]
    with pytest.raises(Invalid, match=r"cameras/1/mirror_rotation_deg"):
        claim.check({"depth_reversal": _figures(), "poses_determined": True}, cameras, [])


@pytest.mark.parametrize("angles", [{"0": 0.0, "1": 0.0}, {"0": 0.0}, {"0": 0.0, "1": TURNED, "2": 0.0}],
                         ids=["zero", "missing", "extra"])
def test_the_figures_mirror_rotations_are_the_twins(angles):
    """The same false angles stated in the figures and by every camera are refused too."""
    cameras = [dict(c, mirror_rotation_deg=angles.get(str(c["view"]))) for c in CAMERAS]
    with pytest.raises(Invalid, match="mirror_rotation_deg"):
        claim.check({"depth_reversal": _figures(mirror_rotation_deg=angles), "poses_determined": True}, cameras, [])


def test_another_reference_view_is_read_about_it():
    """Stated about view 1, the angles are view 0's twin's about view 1 (the same 30 degrees)."""
    claim.check({"depth_reversal": _figures(reference_view=1, mirror_rotation_deg={"0": TURNED, "1": 0.0}),
                 "poses_determined": True}, [dict(CAMERAS[0], mirror_rotation_deg=TURNED),
                                             dict(CAMERAS[1], mirror_rotation_deg=0.0)], [])


def test_a_zero_cost_states_no_ratio():
    """An exact fit (cost 0) has no cost ratio: None is read, a number refused."""
    figures = _figures(cost=0.0, twin=400.0)
    claim.check({"depth_reversal": figures, "poses_determined": True}, CAMERAS, [])
    with pytest.raises(Invalid, match="depth_reversal"):
        claim.check({"depth_reversal": {**figures, "cost_ratio": 1.0}, "poses_determined": True}, CAMERAS, [])
