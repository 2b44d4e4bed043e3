"""A job's options are parsed without walking their dataclass's fields again: what a class
declares (defaults, types, ranges) is read once a class, not on every job's parse, and the
refusals are worded as before."""

from __future__ import annotations

import dataclasses

import pytest

from geocert.core.geometry import InputError
from geocert.kinds import get_kind
from geocert.kinds.base import options_from


def test_a_parse_walks_no_fields_once_the_class_was_read(monkeypatch):
    options_type = get_kind("triangulation").options_type
    given = {"norm": "L2L2", "rel_gap": 1e-3, "max_nodes": 100, "job_time_limit_s": 60}
    options_from(options_type, given)  # the class read
    walked = []
    real = dataclasses.fields
    monkeypatch.setattr(dataclasses, "fields", lambda cls: walked.append(cls) or real(cls))
    options = options_from(options_type, given)
    assert walked == []
    assert (options.norm, options.rel_gap, options.max_nodes, options.job_time_limit_s) == ("L2L2", 1e-3, 100, 60)


@pytest.mark.parametrize("given, where, words", [
    ({"nope": 1}, "options/nope", "unknown option (known: "),
    ({"max_nodes": 1.5}, "options/max_nodes", "must be an integer"),
    ({"norm": 3}, "options/norm", "must be a string"),
    ({"max_residual": None, "rel_gap": "x"}, "options/rel_gap", "must be a number"),
    ({"max_nodes": 0}, "options/max_nodes", "must be a finite number"),
])
def test_the_refusals_name_the_option(given, where, words):
    options_type = get_kind("triangulation").options_type
    for _ in range(2):  # the class read, then from what was kept
        with pytest.raises(InputError) as refused:
            options_from(options_type, given)
        assert refused.value.field == where and words in str(refused.value)
