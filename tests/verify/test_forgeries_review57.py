"""Review 57: DOCSTRING PENDING"""

from __future__ import annotations

import copy

import pytest

from tests.verify.test_forgeries import refused_naming, stored
from tests.verify.test_forgeries_review56 import _valid

pytestmark = pytest.mark.filterwarnings("ignore")


# 1. A reconstruction summary's counts are the items' numbers themselves

@pytest.mark.parametrize("name", ["views_registered", "points", "observations", "points_certified",
                                  "cameras_certified"])
@pytest.mark.parametrize("step", [1e-10, 2.0 ** -40])
def test_a_summary_count_that_is_not_the_items_number_is_refused(name, step):
    result = stored("reconstruction")
    count = result["summary"][name]
    assert type(count) is int and count > 0
    result["summary"][name] = count * (1 + step)  # inside the 1e-9 a recomputed sum may round by
    refused_naming(result, "returned", f"summary/{name}")


def test_a_count_written_as_its_float_and_a_fraction_within_rounding_verify():
    result = stored("reconstruction")
    summary = result["summary"]
    summary["cameras_certified"] = float(summary["cameras_certified"])  # 4.0 is 4, as JavaScript writes it
    summary["cameras_certified_fraction"] = summary["cameras_certified_fraction"] * (1 + 2.0 ** -52)
    assert _valid(result)


# 2. The depth-reversal record: a figure recomputed from extreme stated ones (overflowing to inf)
#    is compared with nothing, and whether the check ran is a boolean

def test_a_depth_reversal_statistic_beside_a_subnormal_noise_is_refused():
    """The twin costs 15% more, a statistic of 3 noise variances (below the 10.8 that tells the
    twin apart: ambiguous, poses not determined); the noise restated 5e-324 makes the recomputed
    statistic 15 / 5e-324 = inf, and |3 - inf| <= 1e-9 * inf held: the record stated a statistic
    below its threshold beside the verdict "rejected" and poses_determined true."""
    from geocert.core.strict import Invalid
    from geocert.formulations.reconstruction import depth_reversal_claim as claim
    from tests.verify.test_depth_reversal_claim import CAMERAS, _figures

    genuine = _figures(cost=100.0, twin=115.0, variance=5.0)
    assert genuine["ambiguous"] is True  # 3 variances: ambiguous, as the pipeline judges it
    claim.check({"depth_reversal": genuine, "poses_determined": False}, CAMERAS, [])
    forged = dict(genuine, noise_variance_px2=5e-324, ambiguous=False)
    with pytest.raises(Invalid, match="statistic"):
        claim.check({"depth_reversal": forged, "poses_determined": True}, CAMERAS, [])


def test_a_cost_ratio_beside_a_subnormal_cost_is_refused():
    from geocert.core.strict import Invalid
    from geocert.formulations.reconstruction import depth_reversal_claim as claim
    from tests.verify.test_depth_reversal_claim import CAMERAS, _figures

    forged = dict(_figures(cost=5e-324, twin=400.0), cost_ratio=2.0)  # 400 / 5e-324 overflows
    with pytest.raises(Invalid, match="cost ratio"):
        claim.check({"depth_reversal": forged, "poses_determined": True}, CAMERAS, [])


@pytest.mark.parametrize("checked", [1, 1.0, 0, 0.0])
def test_whether_the_depth_reversal_check_ran_stated_as_a_number_is_refused(checked):
    from geocert.core.strict import Invalid
    from geocert.formulations.reconstruction import depth_reversal_claim as claim
    from tests.verify.test_depth_reversal_claim import CAMERAS, _figures

    with pytest.raises(Invalid, match="checked"):
        claim.check({"depth_reversal": _figures(checked=checked), "poses_determined": True}, CAMERAS, [])


@pytest.fixture(scope="module")
def example_reconstruction() -> dict:
    """The kind's example (examples/reconstruction-tracks.json: 8 views, 60 tracks) solved with a
    full certificate: its result states the depth-reversal record (the check ran, the twin
    rejected: poses determined)."""
    import json
    from pathlib import Path

    from geocert.jobs.runner import solve_job

    job = json.loads((Path(__file__).resolve().parents[2] / "examples" / "reconstruction-tracks.json").read_text())
    job["options"]["certificate"] = "full"
    result = solve_job(job)
    assert result["summary"]["depth_reversal"]["checked"] is True and result["summary"]["poses_determined"] is True
    assert _valid(result)
    return result


@pytest.mark.slow  # the example's solve: about 9 s
@pytest.mark.parametrize("member,value", [("noise_variance_px2", 5e-324), ("checked", 1)])
def test_a_genuine_reconstructions_depth_reversal_record_so_edited_is_refused(example_reconstruction, member, value):
    forged = copy.deepcopy(example_reconstruction)
    forged["summary"]["depth_reversal"][member] = value
    refused_naming(forged, "returned", "depth_reversal")


# 3. A reconstruction summary's critical motion is a motion's name or null

@pytest.mark.slow  # the example's solve: about 9 s
@pytest.mark.parametrize("value", [False, 0, 0.0, [], ""])
def test_a_summary_critical_motion_not_a_name_is_refused(example_reconstruction, value):
    """Where the returned cameras' motion is judged not critical (the example: null), a summary
    stating false, 0 or [] was read as none by its truthiness and verified: a type no writer gives,
    which a reader takes for "judged not critical"."""
    assert example_reconstruction["summary"]["critical_motion"] is None
    forged = copy.deepcopy(example_reconstruction)
    forged["summary"]["critical_motion"] = value
    refused_naming(forged, "returned", "summary/critical_motion")
