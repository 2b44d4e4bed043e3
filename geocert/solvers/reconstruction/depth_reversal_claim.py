"""The depth-reversal check's record, as the verifier reads it (numpy only).

The check (pipelines/reconstruction/ambiguity.py) compares the returned rig with its adjusted
depth-reversed twin; the verifier cannot run that adjustment, so the verdict's figures are taken
as stated, but they must be the verdict's: ``summary.poses_determined`` is null exactly when the
check did not run, and then only for a reason the result shows (fewer than 2 views registered, a
stop, the adjustment switched off); when it ran, the statistic, the cost ratio and the three
outcomes (rejected, adopted, ambiguous) are recomputed from the stated costs and noise at the
pipeline's thresholds, and each registered camera's ``mirror_rotation_deg`` is the figures' for
its view. What stays unchecked is stated in docs/certificate.md: the costs themselves and the
twin's rotations, which need the twin."""

from __future__ import annotations

import math
from typing import Any

from geocert.solvers.core.geometry import is_number
from geocert.solvers.core.strict import Invalid

# The pipeline's (ambiguity.MIRROR_CHI2, MIRROR_MARGIN; tests/solvers/test_depth_reversal_claim.py
# checks they agree).
MIRROR_CHI2 = 10.8
MIRROR_MARGIN = 0.10
ROUNDING = 1e-9
NOT_CHECKED = {"fewer than 2 views registered": "registered",
               "stopped before the twin's adjustment ended": "stopped",
               "options.bundle_adjustment is false: the twin could only be compared adjusted": "not_adjusted"}


def _close(value: Any, expected: float) -> bool:
    return is_number(value) and abs(value - expected) <= ROUNDING * max(abs(expected), 1e-300)


def check(summary: dict, cameras: list[dict], stages: list) -> None:
    """Refuse a depth-reversal record that is not its verdict's (module docstring)."""
    figures, poses = summary.get("depth_reversal"), summary.get("poses_determined")
    registered = [c for c in cameras if c.get("registered") is True]
    if figures is None:  # a result from before the check: nothing stated of it
        if poses is not None or any(c.get("mirror_rotation_deg") is not None for c in registered):
            raise Invalid("returned", "summary/poses_determined or a camera's mirror_rotation_deg is stated without "
                                      "summary/depth_reversal")
        return
    if not isinstance(figures, dict) or figures.get("checked") not in (True, False):
        raise Invalid("returned", "summary/depth_reversal must be an object saying whether the check ran (checked)")
    if figures["checked"] is False:
        why = NOT_CHECKED.get(figures.get("reason"))
        shown = {"registered": len(registered) < 2,
                 "stopped": any(isinstance(s, dict) and s.get("status") in ("cancelled", "time_limit") for s in stages),
                 "not_adjusted": any(isinstance(s, dict) and s.get("name") == "bundle_adjustment"
                                     and s.get("status") == "skipped" for s in stages)}.get(why, False)
        if not shown or poses is not None or any(c.get("mirror_rotation_deg") is not None for c in registered):
            raise Invalid("returned", f"summary/depth_reversal says the check did not run ({figures.get('reason')!r:.80}), "
                                      "which the result does not show, or poses_determined or a camera's "
                                      "mirror_rotation_deg is stated beside it")
        return
    names = ("cost_px2", "mirror_cost_px2", "noise_variance_px2", "statistic")
    if not all(is_number(figures.get(n)) for n in names) or not (figures["cost_px2"] > 0
                                                                   and figures["noise_variance_px2"] > 0):
        raise Invalid("returned", f"summary/depth_reversal must state {', '.join(names)} as numbers, the costs and "
                                  "noise positive")
    cost, twin, variance = figures["cost_px2"], figures["mirror_cost_px2"], figures["noise_variance_px2"]
    statistic = (twin - cost) / variance
    rejected = statistic > MIRROR_CHI2 and twin > (1 + MIRROR_MARGIN) * cost
    adopted = -statistic > MIRROR_CHI2 and cost > (1 + MIRROR_MARGIN) * twin
    ambiguous = not (rejected or adopted)
    if not (_close(figures["statistic"], statistic) and _close(figures.get("cost_ratio"), twin / cost)
            and figures.get("threshold") == MIRROR_CHI2 and figures.get("margin") == MIRROR_MARGIN
            and figures.get("ambiguous") is ambiguous and figures.get("adopted") is adopted
            and poses is (not ambiguous)):
        raise Invalid("returned", "summary/depth_reversal's verdict (ambiguous, adopted, poses_determined) or its "
                                  "statistic and cost ratio are not what its costs and noise give at the check's "
                                  f"thresholds ({MIRROR_CHI2:g} variances, {100 * MIRROR_MARGIN:g}%)")
    angles = figures.get("mirror_rotation_deg")
    if not isinstance(angles, dict) or not all(is_number(a) and 0 <= a <= 180 for a in angles.values()):
        raise Invalid("returned", "summary/depth_reversal/mirror_rotation_deg must map views to angles in [0, 180]")
    for camera in registered:
        stated, expected = camera.get("mirror_rotation_deg"), angles.get(str(camera.get("view")))
        if not (stated == expected or (stated is not None and expected is not None and _close(stated, expected))):
            raise Invalid("returned", f"cameras/{camera.get('view')}/mirror_rotation_deg {stated!r:.40} is not "
                                      f"summary/depth_reversal's for its view ({expected!r})")
    if not math.isfinite(statistic):
        raise Invalid("returned", "summary/depth_reversal's statistic is not finite")
