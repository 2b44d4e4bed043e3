"""Progress's item counts: ``items_done`` and ``items_total``, and their deprecated old names
``tracks_done`` and ``tracks_total`` carrying the same values (quick tier: no server; a finished job's progress through a server: test_service)."""

from __future__ import annotations

import numpy as np

from geocert.app.cli import openapi_document
from geocert.app.schemas import JobProgress
from geocert.jobs.runner import solve_job
from tests.support import triangulation_job


def test_every_progress_event_has_both_names_with_the_same_values():
    events = []
    solve_job(triangulation_job(np.random.default_rng(3), tracks=3, views=4, norm="L2L2"), sink=events.append)
    assert events
    for event in events:
        assert (event["tracks_done"], event["tracks_total"]) == (event["items_done"], event["items_total"])
    assert (events[-1]["items_done"], events[-1]["items_total"]) == (3, 3)


def test_progress_stored_under_either_pair_of_names_shows_both():
    old = JobProgress.model_validate({"tracks_done": 4, "tracks_total": 9}).model_dump()
    new = JobProgress.model_validate({"items_done": 4, "items_total": 9}).model_dump()
    assert old == new
    assert (new["items_done"], new["items_total"], new["tracks_done"], new["tracks_total"]) == (4, 9, 4, 9)


def test_the_old_names_are_deprecated_in_the_schema():
    fields = openapi_document()["components"]["schemas"]["JobProgress"]["properties"]
    assert fields["tracks_done"].get("deprecated") and fields["tracks_total"].get("deprecated")
    assert not fields["items_done"].get("deprecated") and not fields["items_total"].get("deprecated")
