"""The batched triangulation path (many_tracks.triangulate_many) calls its callback as it goes, and
a stop it asks for takes effect there: the per-track work of a batch (two local refinements, the
root region's conic solves, the root node's) was done for every track of a group of 500 before
the callback was first called, so a cancel of an L1L1 job waited for a whole batch (about a
second of CPU a batch here, several under load) and its progress stood still meanwhile."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.jobs.runner import parse_job, solve_items
from geocert.solvers.fractional import many_tracks
from geocert.solvers.fractional.triangulation import TriangulationOptions

from tests.support import random_cameras, service_job


def scene(tracks: int = 120, seed: int = 3):
    """Tracks of 2 and 3 views out of 3 cameras: under L1L1 most close on the batched path."""
    body = service_job(np.random.default_rng(seed), tracks=tracks, views=3)
    cameras = np.array(body["data"]["cameras"], dtype=float)
    return cameras, [(track["views"], np.array(track["points"], dtype=float)) for track in body["data"]["tracks"]]


class Counted:
    """Counts the calls of one of many_tracks' per-track steps (its own name: not triangulate's)."""

    def __init__(self, monkeypatch, name: str):
        self.calls = 0
        original = getattr(many_tracks, name)

        def counted(*args, **kwargs):
            self.calls += 1
            return original(*args, **kwargs)

        monkeypatch.setattr(many_tracks, name, counted)


@pytest.mark.parametrize("norm", ["L1L1", "L2L1"])
def test_the_callback_is_called_every_few_tracks_of_the_batched_work(norm, monkeypatch):
    cameras, tracks = scene()
    refinements, regions = Counted(monkeypatch, "local_refine"), Counted(monkeypatch, "root_region")
    between = []  # (refinements, root regions) of the batched path since the call before

    def callback(progress):
        between.append((refinements.calls, regions.calls))
        refinements.calls = regions.calls = 0
        return False

    results = many_tracks.triangulate_many(cameras, tracks, TriangulationOptions(norm=norm), callback,
                                           stop_ends_batch=True)
    between.append((refinements.calls, regions.calls))
    assert all(result.certified for result in results)
    # every track went through the batched refinements and root regions (none is trivial here)
    assert sum(r for r, _ in between) >= 2 * len(tracks) and sum(g for _, g in between) >= 0.9 * len(tracks)
    # each track's batched step ticks once: at most CHECK_EVERY tracks between two calls (a root
    # node's refinement of its relaxation's point is a third refinement of a track)
    assert max(g for _, g in between) <= many_tracks.CHECK_EVERY, between
    assert max(r for r, _ in between) <= 3 * many_tracks.CHECK_EVERY, between  # was every track's, 240


def test_a_stop_during_the_batched_work_ends_the_batch_there(monkeypatch):
    cameras, tracks = scene()
    regions = Counted(monkeypatch, "root_region")
    alone = Counted(monkeypatch, "triangulate")
    calls = []

    def callback(progress):
        calls.append(progress)
        return len(calls) >= 3  # a cancel seen at the third call

    results = many_tracks.triangulate_many(cameras, tracks, TriangulationOptions(norm="L1L1"), callback,
                                           stop_ends_batch=True)
    assert len(calls) == 3  # nothing asked again once stopped
    assert alone.calls == 0 and regions.calls <= many_tracks.CHECK_EVERY  # no further work was started
    stopped = [result for result in results if result.status == "cancelled"]
    assert len(stopped) == len(tracks)  # none had ended: each reads cancelled, not started, no point
    assert all(not r.certified and r.point is None and r.reason == many_tracks.STOPPED_BEFORE for r in stopped)


def test_without_stop_ends_batch_a_stop_keeps_each_tracks_best_point(monkeypatch):
    """A reconstruction's structure stage (its time limit) keeps a stopped track's best point: the
    batched work is not interrupted, and each track left is prepared, its search stopped."""
    cameras, tracks = scene(40)
    calls = []

    def callback(progress):
        calls.append(progress)
        return True

    results = many_tracks.triangulate_many(cameras, tracks, TriangulationOptions(norm="L1L1", rel_gap=1e-9), callback)
    assert all(result.point is not None for result in results)
    assert {result.status for result in results} <= {"optimal", "cancelled"}


def test_a_cancel_during_a_batch_of_the_job_runner_is_seen_within_a_few_tracks():
    """The job runner's stop check (a cancel read from Redis) reaches the batched work through the
    engine callback: once it says stop, the batch ends, its items and the next groups' read
    cancelled, and the check is not asked again for every remaining track."""
    body = service_job(np.random.default_rng(5), tracks=600, views=3, norm="L1L1")
    kind, parsed, options = parse_job(body)
    asked = []

    def should_stop():
        asked.append(1)
        return len(asked) >= 4  # the group's first check, then three from inside the batch

    progress = []
    items = solve_items(kind, parsed, options, range(600), sink=progress.append, should_stop=should_stop)
    assert len(items) == 600 and all(item["status"] == "cancelled" for item in items)
    assert len(asked) <= 6
    during = progress[:-1]  # the last: the batch's items, ended (cancelled)
    assert len(during) >= 2  # the batch told its progress while it ran (with no bounds yet); was none
    assert all(p["items_done"] == 0 and p["lower_bound"] is None for p in during)
