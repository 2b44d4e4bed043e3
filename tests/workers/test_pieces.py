"""A task's independent pieces spread over solver processes (workers.pieces), in a real Redis: a
helper (here a thread running ``help_with``, as the ``solve_pieces`` task does) takes its share,
the results come back in order and equal to the in-process ones, a helper's error fails the task
with that error, a cancel stops every piece, a time stop keeps a prefix, a lost piece is computed
again, and what a helper reads from Redis is data and a registered function, never code."""

from __future__ import annotations

import pickle
import threading
import time

import numpy as np
import pytest

from geocert.jobs.store import JobStore
from geocert.core import pieces
from geocert.workers import pieces as workers_pieces
from tests.support import embedded_redis_client


@pytest.fixture(scope="module")
def jobs(tmp_path_factory):
    for client in embedded_redis_client(tmp_path_factory, decode_responses=True):
        yield JobStore(client)


@pieces.piece
def slow_square(shared: dict, item: np.ndarray) -> np.ndarray:
    time.sleep(shared["sleep_s"])
    return item * item + shared["offset"]


def in_process(one, items, stop):
    return [one(item) for item in items]


class Helper:
    """A helper solver: takes pieces of any set of the job as they appear, until stopped."""

    def __init__(self, jobs: JobStore, job_id: str):
        self.jobs, self.job_id, self.solved, self.running = jobs, job_id, 0, True
        self.thread = threading.Thread(target=self._run, name="helper", daemon=True)
        self.sets: list[str] = []

    def _run(self):
        while self.running:
            for key in self.jobs.binary.scan_iter(match=f"geocert:job:{self.job_id}:pieces:*:input"):
                set_id = key.decode().split(":")[-2]
                self.solved += workers_pieces.help_with(self.jobs, self.job_id, set_id)
            time.sleep(0.005)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.running = False
        self.thread.join(timeout=10)


ITEMS = [np.array([k, k + 0.5]) for k in range(24)]


class BesideHelpers(workers_pieces.SpreadOverSolvers):
    """The task's spreader with another solver live, whose helper is the test's (Helper)."""

    def __init__(self, jobs, job_id):
        super().__init__(jobs, job_id)
        self.jobs = OtherSolverLive(jobs)

    def queue_helpers(self, set_id, count):
        pass


class OtherSolverLive:
    def __init__(self, jobs):
        self._jobs = jobs

    def __getattr__(self, name):
        return getattr(self._jobs, name)

    def live_solvers(self):
        return 2


def spread(jobs, job_id, shared, stop=lambda k: False):
    spreader = BesideHelpers(jobs, job_id)
    with pieces.spread_by(spreader):
        return pieces.mapped(slow_square, shared, ITEMS, stop, in_process)


def test_a_helper_takes_a_share_and_the_results_are_the_in_process_ones_in_order(jobs):
    shared = {"sleep_s": 0.01, "offset": 3.0}
    expected = in_process(lambda item: slow_square(shared, item), ITEMS, None)
    with Helper(jobs, "spread") as helper:
        found = spread(jobs, "spread", shared)
    assert len(found) == len(expected)
    assert all(np.array_equal(a, b) for a, b in zip(found, expected))
    assert 0 < helper.solved < len(ITEMS)  # both took pieces
    assert not list(jobs.binary.scan_iter(match="geocert:job:spread:pieces:*:input"))  # dropped after


def test_with_no_other_solver_the_task_solves_every_piece_itself_without_redis(jobs):
    shared = {"sleep_s": 0.0, "offset": 4.0}
    spreader = workers_pieces.SpreadOverSolvers(jobs, "alone")  # no worker beats here: no other solver
    with pieces.spread_by(spreader):
        found = pieces.mapped(slow_square, shared, ITEMS, lambda k: k >= 10, in_process)
    assert len(found) == 10 and all(np.array_equal(a, item * item + 4.0) for a, item in zip(found, ITEMS))
    assert not list(jobs.binary.scan_iter(match="geocert:job:alone:*"))


def test_without_a_spreader_the_stage_maps_in_process(jobs):
    shared = {"sleep_s": 0.0, "offset": 1.0}
    assert not pieces.spreading()
    found = pieces.mapped(slow_square, shared, ITEMS, lambda k: False, in_process)
    assert all(np.array_equal(a, item * item + 1.0) for a, item in zip(found, ITEMS))


def test_a_piece_failing_in_a_helper_fails_the_task_with_its_error(jobs):
    shared = {"sleep_s": 0.01, "offset": 0.0}
    with Helper(jobs, "failing") as helper:
        original = workers_pieces.help_with

        def failing_first(jobs_, job_id, set_id):  # the helper's first piece raises
            taken = jobs_.take_piece(job_id, set_id)
            if taken is None:
                return 0
            jobs_.put_piece_result(job_id, set_id, taken[0], error="ValueError: bad item")
            return 0

        workers_pieces.help_with = failing_first
        try:
            with pytest.raises(workers_pieces.PieceFailed, match="ValueError: bad item"):
                spread(jobs, "failing", shared)
        finally:
            workers_pieces.help_with = original
        assert helper.solved == 0


def test_a_cancel_stops_the_pieces_and_the_helpers_take_no_more(jobs):
    shared = {"sleep_s": 0.02, "offset": 0.0}
    with Helper(jobs, "cancelled") as helper:
        assert spread(jobs, "cancelled", shared, stop=lambda k: None if k >= 4 else False) is None
    # the helper has stopped (joined), so everything it took is counted; the set takes no more
    for key in jobs.binary.scan_iter(match="geocert:job:cancelled:pieces:*:input"):
        assert jobs.take_piece("cancelled", key.decode().split(":")[-2]) is None
    assert 4 + helper.solved < len(ITEMS)  # the cancel left pieces untaken


def test_a_helper_takes_no_piece_of_a_cancelled_job(jobs):
    """The job's cancel reaches a helper by itself (it asks between pieces), whatever its task does."""
    shared = {"sleep_s": 0.0, "offset": 0.0}
    jobs.put_pieces("to-cancel", "set", pieces.name_of(slow_square), workers_pieces.encode(shared),
                    [workers_pieces.encode(item) for item in ITEMS], 60)
    assert workers_pieces.help_with(jobs, "to-cancel", "set") == len(ITEMS)  # not cancelled: it takes them all
    jobs.put_pieces("to-cancel", "again", pieces.name_of(slow_square), workers_pieces.encode(shared),
                    [workers_pieces.encode(item) for item in ITEMS], 60)
    jobs.request_cancel("to-cancel")
    assert workers_pieces.help_with(jobs, "to-cancel", "again") == 0
    assert jobs.take_piece("to-cancel", "again")[0] == 0  # left untaken


def test_a_time_stop_keeps_a_prefix_of_the_pieces(jobs):
    shared = {"sleep_s": 0.01, "offset": 2.0}
    with Helper(jobs, "timed"):
        found = spread(jobs, "timed", shared, stop=lambda k: k >= 6)
    assert 6 <= len(found) < len(ITEMS)
    assert all(np.array_equal(a, item * item + 2.0) for a, item in zip(found, ITEMS))


def test_a_piece_its_helper_never_returns_is_computed_by_the_task(jobs, monkeypatch):
    monkeypatch.setattr(workers_pieces, "LOST_AFTER_S", 0.2)
    shared = {"sleep_s": 0.0, "offset": 5.0}
    lost = []

    def lose_one(stop):  # a helper that takes piece 0 and dies
        def stopping(k):
            if not lost:
                for key in jobs.binary.scan_iter(match="geocert:job:lost:pieces:*:input"):
                    lost.append(jobs.take_piece("lost", key.decode().split(":")[-2]))
            return stop(k)
        return stopping

    found = spread(jobs, "lost", shared, stop=lose_one(lambda k: False))
    assert lost and lost[0][0] == 0
    assert all(np.array_equal(a, item * item + 5.0) for a, item in zip(found, ITEMS))


def test_what_a_helper_reads_is_data_never_code():
    class Code:
        def __reduce__(self):
            import os
            return (os.system, ("true",))

    with pytest.raises(pickle.UnpicklingError):
        workers_pieces.decode(pickle.dumps(Code()))
    from geocert.pipelines.reconstruction.features import FeatureOptions

    options = FeatureOptions(ratio=0.7)
    data = (np.arange(6.0).reshape(3, 2), [np.zeros((2, 128), np.float32)], options)
    back = workers_pieces.decode(workers_pieces.encode(data))
    assert back[2] == options and np.array_equal(back[0], data[0])
    with pytest.raises(KeyError):
        pieces.registered("os:system")


FAILING_HELPER = """
import base64, json, os
import cv2, numpy as np
from geocert.jobs.store import JobStore
from geocert.workers import pieces as workers_pieces, tasks

jobs = JobStore.from_url(os.environ["GEOCERT_REDIS_URL"])
rng = np.random.default_rng(0)
images = [{"name": f"p{k}.png", "content": base64.b64encode(cv2.imencode(".png", rng.integers(0, 255, (96, 128),
           dtype=np.uint8))[1].tobytes()).decode()} for k in range(4)]
meta = jobs.create("reconstruction", {"kind": "reconstruction", "data": {"images": images}, "options": {}}, 1, 1,
                   "someone")
helped = []

def failing_helper(name, args, **options):  # a helper on another solver process whose first piece raises
    job_id, set_id, _ = args
    taken = jobs.take_piece(job_id, set_id)
    if taken is not None:
        helped.append(taken[0])
        jobs.put_piece_result(job_id, set_id, taken[0], error="MemoryError: the helper ran out")

JobStore.live_solvers = lambda self: 2  # another solver process is live
from geocert.workers.celery_app import celery_app
celery_app.send_task = failing_helper
tasks._solve_chunk(meta["id"], 0, 1, None)
ended = jobs.get(meta["id"])
print(json.dumps({"status": ended["status"], "error": ended.get("error"), "helped": helped}))
"""


def test_a_piece_failing_in_a_helper_fails_the_job_through_the_task_keeping_its_error(tmp_path):
    from tests.support import run_with_redis

    ended = run_with_redis(tmp_path, FAILING_HELPER)
    assert ended["helped"], "the helper took no piece"
    assert ended["status"] == "failed"
    assert ended["error"]["status"] == 500 and "PieceFailed" in ended["error"]["detail"]
    assert "MemoryError: the helper ran out" in ended["error"]["detail"]


@pieces.piece
def meet(shared: threading.Barrier, item: int) -> int:
    """A piece that returns only once another piece is running beside it (the barrier's other party)."""
    shared.wait()
    return item


@pytest.mark.skipif((__import__("os").cpu_count() or 1) < 2, reason="threads at once need two processors")
def test_with_no_other_solver_the_task_runs_its_pieces_two_at_once_in_its_own_process(jobs):
    """As the command line's stages do (their threads): one solver process alone still uses two
    cores. Each piece waits for another to run beside it; one at a time, the first would wait in
    vain (the barrier's timeout breaks it)."""
    barrier = threading.Barrier(2, timeout=30)
    spreader = workers_pieces.SpreadOverSolvers(jobs, "two-at-once")  # no worker beats here: no other solver
    with pieces.spread_by(spreader):
        found = pieces.mapped(meet, barrier, [0, 1, 2, 3], lambda k: False, pieces.in_order)
    assert found == [0, 1, 2, 3]
    assert not list(jobs.binary.scan_iter(match="geocert:job:two-at-once:*"))  # nothing through Redis


def test_pieces_in_threads_keep_their_order_a_stops_prefix_a_cancel_and_an_error():
    def square(item):
        time.sleep(0.001 * (item % 3))  # pieces of unequal length end out of order
        return item * item

    items = list(range(20))
    assert pieces.in_threads(square, items, lambda k: False) == [k * k for k in items]
    assert pieces.in_threads(square, items, lambda k: k >= 7) == [k * k for k in range(7)]
    assert pieces.in_threads(square, items, lambda k: None if k >= 7 else False) is None
    asked = []
    pieces.in_threads(square, items, lambda k: asked.append(k) or False)
    assert asked == items  # each asked once, before its piece starts, in order

    def failing(item):
        if item == 5:
            raise ValueError("piece 5")
        return item

    with pytest.raises(ValueError, match="piece 5"):
        pieces.in_threads(failing, items, lambda k: False)


def test_a_helper_has_time_limits_ending_it_soon_after_its_task(jobs, monkeypatch):
    """A helper's Celery limits follow its task's last-resort deadline (the job's own limits and
    GEOCERT_TASK_TIME_MARGIN_S): a helper never outlives its task by more than the soft and hard
    margins queue.task_options gives the task itself."""
    import sys
    from types import SimpleNamespace

    from geocert.workers.queue import HARD_AFTER_S, SOFT_AFTER_S

    sent = []  # the tasks' options, as the Celery app would send them (its module needs a worker's broker)
    celery_app = SimpleNamespace(send_task=lambda name, args, **options: sent.append(options))
    monkeypatch.setitem(sys.modules, "geocert.workers.celery_app", SimpleNamespace(celery_app=celery_app))
    workers_pieces.SpreadOverSolvers(jobs, "limited", stop_by=time.monotonic() + 100).queue_helpers("set", 2)
    assert len(sent) == 2
    for options in sent:
        assert 100 - 5 + SOFT_AFTER_S <= options["soft_time_limit"] <= 100 + SOFT_AFTER_S
        assert options["time_limit"] == options["soft_time_limit"] + HARD_AFTER_S
    sent.clear()
    workers_pieces.SpreadOverSolvers(jobs, "unknown-deadline").queue_helpers("set", 1)
    from geocert.settings import get_settings

    settings = get_settings()
    longest = max(settings.max_job_time_limit_s, settings.chunk_time_budget_s + settings.max_item_time_limit_s)
    assert sent[0]["soft_time_limit"] == longest + settings.task_time_margin_s + SOFT_AFTER_S


@pieces.piece
def past_its_time(shared, item):
    from celery.exceptions import SoftTimeLimitExceeded

    raise SoftTimeLimitExceeded()


def test_a_helper_stopped_by_its_time_limit_leaves_its_piece_to_the_task(jobs):
    """Celery's soft limit raised in a helper's piece is the helper's end, not the piece's error:
    the job is not failed with it, and the task computes the piece (as one lost)."""
    from celery.exceptions import SoftTimeLimitExceeded

    jobs.put_pieces("timed-out", "set", pieces.name_of(past_its_time), workers_pieces.encode(None),
                    [workers_pieces.encode(k) for k in range(3)], 60)
    with pytest.raises(SoftTimeLimitExceeded):
        workers_pieces.help_with(jobs, "timed-out", "set")
    assert jobs.piece_results("timed-out", "set", [0, 1, 2]) == ({}, {})  # no error stored


def test_float32_byte_values_travel_as_bytes_and_come_back_the_same():
    """SIFT's descriptors (float32 holding whole numbers 0 to 255) are most of what the matches
    stage's pieces share: they travel as a quarter of the bytes and read back bit for bit; any
    other float32 array travels as it is."""
    rng = np.random.default_rng(0)
    descriptors = [rng.integers(0, 256, (500, 128)).astype(np.float32) for _ in range(3)]
    shared = (descriptors, np.asfortranarray(descriptors[0][:64]))
    data = workers_pieces.encode(shared)
    assert len(data) < 0.3 * sum(d.nbytes for d in descriptors)
    back = workers_pieces.decode(data)
    for found, sent in zip([*back[0], back[1]], [*descriptors, shared[1]]):
        assert found.dtype == np.float32 and found.shape == sent.shape and found.tobytes() == sent.tobytes()
        assert found.flags.f_contiguous == sent.flags.f_contiguous
    for other in (0.5, -0.0, 256.0, np.nan, -1.0):  # not a byte (or -0.0, whose sign a byte loses)
        array = descriptors[1].copy()
        array[7, 3] = other
        found = workers_pieces.decode(workers_pieces.encode(array))
        assert len(workers_pieces.encode(array)) > array.nbytes
        assert found.dtype == np.float32 and found.tobytes() == array.tobytes()
