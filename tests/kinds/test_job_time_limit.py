"""A many-item job's time limit in all (options.job_time_limit_s): its items share one clock, so a
large triangulation (tracks solved 500 at a time, each batch's searches one after another) ends at
it with the tracks it finished, the rest reading time_limit, not started, never certified. Before,
a batch had no shared clock: 500 tracks each ran their own time_limit_s (about 4 hours a task)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.core.geometry import InputError
from geocert.solvers.fractional.many_tracks import triangulate_many
from geocert.formulations.fractional.options import TriangulationOptions
from tests.support import reconstruction_data, service_job

NOT_STARTED = "not started"


def searched_job(tracks: int, **options) -> dict:
    """Tracks each solved by a search of its own (a scope limit, max_residual, sends every track
    of a batch to the search alone: milliseconds each, one after another)."""
    return service_job(np.random.default_rng(7), tracks, views=4, max_residual=50.0, detail="brief", **options)


def test_a_large_triangulation_ends_at_its_job_time_limit_keeping_what_it_finished():
    job = searched_job(3000, job_time_limit_s=0.5)
    tracks = solve_job(job)["tracks"]
    assert len(tracks) == 3000
    finished = [track for track in tracks if NOT_STARTED not in (track["reason"] or "")]
    not_started = [track for track in tracks if NOT_STARTED in (track["reason"] or "")]
    assert finished and not_started  # the clock ended it part way (3000 searches take far longer)
    assert tracks[:len(finished)] == finished  # in order: what was solved first is kept
    assert all(track["status"] != "cancelled" for track in tracks)
    assert any(track["certified"] and track["point"] is not None for track in finished)
    for track in not_started:
        assert track["status"] == "time_limit" and not track["certified"]
        assert track["point"] is None and track["cost"] is None and track["lower_bound"] is None
        assert "job_time_limit_s" in track["reason"]
    for track in finished:  # a search stopped by the clock says so; nothing uncertified claims it
        assert track["certified"] == (track["status"] == "optimal")


def test_a_batch_given_a_past_deadline_starts_no_search():
    job = searched_job(20)
    cameras = np.asarray(job["data"]["cameras"], dtype=float)
    tracks = [(track["views"], np.asarray(track["points"], dtype=float)) for track in job["data"]["tracks"]]
    results = triangulate_many(cameras, tracks, TriangulationOptions(max_residual=50.0),
                               deadline=time.monotonic() - 1, not_started="not started: past it")
    assert [result.status for result in results] == ["time_limit"] * 20
    assert not any(result.certified for result in results)
    assert all(result.point is None and result.reason == "not started: past it" for result in results)


@pytest.mark.parametrize("value", [0, -1, 1e6, float("nan")])
def test_a_job_time_limit_out_of_range_is_refused_naming_it(value):
    with pytest.raises(InputError) as refused:
        solve_job({**searched_job(2), "options": {"job_time_limit_s": value}})
    assert refused.value.field == "options/job_time_limit_s"


def registration_past_its_limits() -> dict:
    """A reconstruction of 40 views whose limits add up to 0.07 s in all, less than its
    registration's initial pair search takes on any machine (200 essential matrices)."""
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=40, points=3000, seed=3, noise_px=0.3)
    return {"kind": "reconstruction",
            "options": {"time_limit_s": 0.001, "autocalibration_time_limit_s": 0.01, "structure_time_limit_s": 0.05},
            "data": {"views": [{"image_size": list(scene.image_size)}] * 40,
                     "tracks": [{"views": [int(v) for v in views], "points": [[float(u), float(w)] for u, w in pixels]}
                                for views, pixels in scene.tracks]}}


def test_a_reconstruction_stops_at_its_time_limit_in_all_keeping_the_views_registered():
    """A reconstruction's limits add up to its time limit in all (time_bound_s: here 0.07 s);
    its registration and adjustments had none of their own (they asked only for a cancel): 40
    views ran their whole registration, the initial pair's 200 candidate essential matrices
    first, about 10 s. Now they stop at that clock: the item reads time_limit, not cancelled,
    every stage it stopped says time_limit (the views registered by then kept, when any were)."""
    result = solve_job(registration_past_its_limits())
    assert result["stats"]["statuses"] == {"time_limit": 1}
    stages = {stage["name"]: stage for stage in result["stages"]}
    assert stages["projective"]["status"] == "time_limit"
    assert all(stage["status"] in ("time_limit", "skipped") for stage in stages.values())
    assert all("time limit in all" in stage["reason"] for stage in stages.values() if stage["status"] == "time_limit")
    assert sum(camera["registered"] for camera in result["cameras"]) < 40  # stopped in the registration
    assert not any(point["certified"] and point["status"] != "optimal" for point in result["points"])
    # where a user looks first, the result says it did not finish, and no warning says that
    # nothing could be found when nothing was sought
    warnings = result["summary"]["warnings"]
    assert warnings[0]["code"] == "time_limit" and "projective" in warnings[0]["detail"]
    assert not any("was found" in warning["detail"] for warning in warnings)


def test_a_reconstruction_stopped_by_its_clock_after_certified_points_verifies(monkeypatch):
    """Its clock in all passing in the cameras stage (a fake clock jumps ahead as the first camera
    is bounded, standing in for a slow machine), its points certified before: the item and the
    job's statistics read time_limit, and the full certificate verifies. The verifier read a
    stopped run's item as "cancelled" or by its points only, so it refused this genuine result
    ("stats/statuses is {'time_limit': 1}, the items give {'optimal': 1}")."""
    from types import SimpleNamespace

    from geocert.kinds import reconstruction as kind
    from geocert.solvers.reconstruction import structure, synthetic
    from geocert.verify.checks import verify_any

    scene = synthetic.scene(views=6, points=40, seed=3, noise_px=0.5)
    data = reconstruction_data(scene.tracks, scene.image_size, 6)
    options = {"certificate": "full", "intrinsics": {"K": [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]}}
    late = {"s": 0.0}
    monkeypatch.setattr(kind, "time", SimpleNamespace(perf_counter=lambda: time.perf_counter() + late["s"],
                                                      process_time=time.process_time))
    bound_camera = structure._bound_camera

    def past_the_clock(*args, **kwargs):
        late["s"] = 1e6
        return bound_camera(*args, **kwargs)

    monkeypatch.setattr(structure, "_bound_camera", past_the_clock)
    result = solve_job({"kind": "reconstruction", "data": data, "options": options})
    assert result["stats"]["statuses"] == {"time_limit": 1}
    assert result["points"] and all(point["certified"] for point in result["points"])
    report = verify_any(result)
    assert report.valid, report.first_failure


def test_a_large_maps_tightening_stops_at_its_time_limit():
    """A resection of 2,000 points tightens its root box (up to 4 rounds of 22 programs) before
    its search: the item's clock covers that too, so with a time limit already past when it
    starts no tightening program is solved, the search stops at its root, whose untightened bound
    does not close (0.1% to 1.6% on such maps, against rel_gap 1e-3), and the map reads
    time_limit, not certified; the document claims nothing, which the verifier says. Before, the
    tightening ran whatever the limit and closed the L2L2 root: optimal (measured, 2.1 s)."""
    from geocert.verify.checks import verify_any
    from tests.support import map_job

    job = map_job(np.random.default_rng(3), "resection", 2000, "L2L2", maps=1)
    # start + 1e-300 rounds to start: the deadline has passed whatever the machine's speed
    job["options"].update(time_limit_s=1e-300)
    result = solve_job(job)
    item = result["maps"][0]
    assert item["status"] == "time_limit" and not item["certified"]
    assert verify_any(result).first_failure["detail"] == "no certified item to check"
