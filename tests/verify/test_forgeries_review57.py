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
