"""Review 59: a hostile review of the certificates for issue 33, where review 58 left off: its
three fixes and their neighbours (the photos reconstruction's images record, a map estimate's
value floor across units, the comparisons of verify.estimates and verify.fractional at NaN, inf,
subnormals and -0.0).

Found (a test below for each, which failed while the class stood):

1. A homography's centroid image was held to MAP_VALUE_ROUNDING of the largest coordinate of
   source or target: a 3-D homography's source in a fine unit (x1e8, within COORDINATE_LIMIT) and
   its targets in a coarse one (x1e-8) gave the centroid image, in the target's units, a floor
   of 4.9e-7, wider than its intervals (1.3e-10): every interval collapsed to a thousandth of
   its width verified.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import refused_naming, rehash, stored, uncertify

pytestmark = pytest.mark.filterwarnings("ignore")


def _valid(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


def _rescaled(result: dict, index: int, world: float, pixels: float) -> dict:
    """The result with map ``index``'s data restated in other units (its source points times
    ``world``, its targets times ``pixels``), the matrix restated to match, not certified, with the
    cost, residuals and estimate its writers state for those data (review 58's _rescaled, for a
    map of any dimensions): a genuine document (every coordinate within COORDINATE_LIMIT)."""
    from geocert.core.geometry import COORDINATE_LIMIT
    from geocert.formulations.fractional import determinacy as estimate
    from geocert.formulations.fractional.items import MapItem
    from geocert.verify.fractional import _stated_figure

    result = copy.deepcopy(result)
    norm = result["certificate"]["options"]["norm"]
    data = result["certificate"]["data"]["maps"][index]
    source, target = np.array(data["source"]) * world, np.array(data["target"]) * pixels
    assert np.abs(source).max() <= COORDINATE_LIMIT and np.abs(target).max() <= COORDINATE_LIMIT
    data.update(source=source.tolist(), target=target.tolist())
    claim = result["certificate"]["items"][index]
    scaled = np.diag([pixels] * target.shape[1] + [1.0])
    M = scaled @ np.array(claim["matrix"]) @ np.diag([1 / world] * source.shape[1] + [1.0])
    uncertify(claim)
    claim.pop("proof")
    claim["matrix"] = M.tolist()
    item = MapItem((source, target), norm, chart=False)
    claim["cost"], _ = _stated_figure(item, M, norm)
    entry = result["maps"][index]
    entry.update({name: claim[name] for name in ("matrix", "cost", "lower_bound", "gap", "status", "certified")})
    entry["residuals"] = item.exact_residuals(M).tolist()
    entry.pop("certificate")
    entry["determinacy"] = json.loads(json.dumps(estimate.map_(source, target, M, claim["cost"], None)))
    certified = len(result["maps"]) - 1
    result["stats"].update(certified=certified, statuses={"optimal": certified, "not_certified": 1})
    rehash(result["certificate"])
    return result


def _collapsed(result: dict, index: int) -> dict:
    forged = copy.deepcopy(result)
    for found in forged["maps"][index]["determinacy"]["intervals"]:
        width = found["upper"] - found["lower"]
        found["lower"], found["upper"] = found["value"] - width / 1000, found["value"] + width / 1000
    return forged


# 1. A homography's centroid image is held to the rounding of the target's units, not the source's

@pytest.mark.parametrize("world,pixels", [(1e8, 1e-8)])
def test_a_homography_restated_narrower_with_its_source_in_a_finer_unit_is_refused(world, pixels):
    """The centroid image's value and ends were allowed MAP_VALUE_ROUNDING of the data's largest
    coordinate, source or target: the stored 3-D homography's second map with its source in a
    finer unit (2.8e8) and its targets in a coarser one (2.5e-8, the intervals 1.3e-10 wide) gave
    the centroid image, in the target's units, a floor of 4.9e-7; every interval collapsed to a
    thousandth of its width verified, beside determined true."""
    genuine = _rescaled(stored("homography3_l2l1"), 1, world, pixels)
    assert _valid(genuine)
    refused_naming(_collapsed(genuine, 1), "returned", "maps/1/determinacy/intervals/0/")
