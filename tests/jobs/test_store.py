"""The job store's request and progress, in a real Redis: a task reads its own chunk's items only,
the whole request comes back byte for byte, and the job's progress is the sum of its tasks' last
figures however they arrive."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from geocert.kinds import get_kind
from geocert.jobs.store import JobStore
from tests.support import embedded_redis_client


@pytest.fixture(scope="module")
def jobs(tmp_path_factory):
    for client in embedded_redis_client(tmp_path_factory, decode_responses=True):
        yield JobStore(client)


def request_of(tracks: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    return {"kind": "triangulation",
            "data": {"cameras": rng.normal(size=(5, 3, 4)).tolist(),
                     "tracks": [{"views": [0, 1, 2], "points": rng.normal(size=(3, 2)).tolist()} for _ in range(tracks)],
                     "note": "geocert-items-"},  # a string like the placeholder's stays as it is
            "options": {"norm": "L2L2"}}


def output_bytes(jobs: JobStore) -> int:
    return int(jobs.r.info("stats")["total_net_output_bytes"])


class TestRequestByChunk:
    def test_the_whole_request_comes_back_byte_for_byte(self, jobs):
        request = request_of(250)
        meta = jobs.create("triangulation", request, 250, 100, "someone", chunk_key="tracks")
        assert jobs.request_text(meta["id"]) == json.dumps(request)
        assert jobs.request(meta["id"]) == request

    def test_a_chunk_holds_its_items_at_their_indices_and_none_elsewhere(self, jobs):
        request = request_of(250)
        meta = jobs.create("triangulation", request, 250, 100, "someone", chunk_key="tracks")
        chunk = jobs.chunk_request(meta["id"], 100, 200)
        tracks = chunk["data"]["tracks"]
        assert len(tracks) == 250
        assert tracks[100:200] == request["data"]["tracks"][100:200]
        assert all(track is None for track in tracks[:100] + tracks[200:])
        assert chunk["data"]["cameras"] == request["data"]["cameras"] and chunk["options"] == request["options"]
        last = jobs.chunk_request(meta["id"], 200, 250)["data"]["tracks"]
        assert len(last) == 250 and last[249] == request["data"]["tracks"][249]

    def test_a_chunks_items_are_one_element_and_any_range_reads_across_them(self, jobs):
        """The items are kept a chunk an element (one text a task reads and parses once); a task
        cut elsewhere by its budget, or reaching into the next chunk, still reads its own items."""
        request = request_of(250)
        meta = jobs.create("triangulation", request, 250, 100, "someone", chunk_key="tracks")
        assert jobs.r.llen(jobs.key(meta["id"], "request:items")) == 3
        for start, stop in ((37, 100), (37, 163), (99, 101), (200, 250), (249, 250), (0, 250)):
            tracks = jobs.chunk_request(meta["id"], start, stop)["data"]["tracks"]
            assert len(tracks) == 250
            assert tracks[start:stop] == request["data"]["tracks"][start:stop]
            assert all(track is None for track in tracks[:start] + tracks[stop:])

    def test_an_empty_chunk_reads_the_requests_head_and_no_item(self, jobs):
        """What reads a job's kind and options (an ending job's: tasks._kind_and_options) asks for
        no item; it read every one (LRANGE 0 -1), 20,000 tracks decoded to end a job."""
        request = request_of(250)
        meta = jobs.create("triangulation", request, 250, 100, "someone", chunk_key="tracks")
        head = jobs.chunk_request(meta["id"], 0, 0)
        assert head["data"]["tracks"] == [None] * 250 and head["options"] == request["options"]

    def test_a_chunk_reads_about_its_share_of_the_request(self, jobs):
        request = request_of(4000)
        size = len(json.dumps(request))
        meta = jobs.create("triangulation", request, 4000, 100, "someone", chunk_key="tracks")
        before = output_bytes(jobs)
        jobs.chunk_request(meta["id"], 0, 100)
        read = output_bytes(jobs) - before
        # 1/40 of the tracks, plus the cameras and what INFO itself writes: far below the whole.
        assert read < 0.1 * size

    def test_without_a_chunk_key_the_request_is_kept_whole(self, jobs):
        request = request_of(10)
        meta = jobs.create("triangulation", request, 10, 100, "someone")
        assert jobs.chunk_request(meta["id"], 0, 5) == request
        assert jobs.request_text(meta["id"]) == json.dumps(request)


class TestChunkStart:
    def test_a_task_starts_in_one_round_trip_with_what_the_separate_reads_give(self, jobs, monkeypatch):
        import redis.connection

        request = request_of(250)
        meta = jobs.create("triangulation", request, 250, 100, "someone", chunk_key="tracks", item_time_bound_s=3.0)
        jobs.r.ping()
        writes = []
        send = redis.connection.AbstractConnection.send_packed_command
        monkeypatch.setattr(redis.connection.AbstractConnection, "send_packed_command",
                            lambda self, *args, **kwargs: writes.append(1) or send(self, *args, **kwargs))
        fields, chunk = jobs.start_chunk(meta["id"], 100, 200, "items_total", "kind", "item_time_bound_s")
        assert len(writes) == 1
        monkeypatch.undo()
        assert fields == {"status": "queued", "items_total": 250, "kind": "triangulation", "item_time_bound_s": 3.0}
        assert chunk == jobs.chunk_request(meta["id"], 100, 200)
        assert jobs.field(meta["id"], "status") == "running" and jobs.field(meta["id"], "started_at") is not None
        assert jobs.r.zscore(JobStore.RUNNING, meta["id"]) is not None  # touched: the reaper sees it alive
        # A second task: the job stays running, with one running event in its stream.
        assert jobs.start_chunk(meta["id"], 0, 100, "kind")[0] == {"status": "running", "kind": "triangulation"}
        statuses = [json.loads(fields["data"])["status"] for _, fields in jobs.r.xrange(JobStore.key(meta["id"], "events"))
                    if fields["event"] == "status"]
        assert statuses == ["queued", "running"]

    def test_a_job_is_created_by_one_command_and_a_refused_one_writes_nothing(self, jobs, monkeypatch):
        """Its admission, writes and tasks' messages are one script (JobStore._CREATE), not a
        transaction of a dozen commands; a job refused is refused before anything of it is
        written (nothing to delete)."""
        import redis.connection

        writes = []
        send = redis.connection.AbstractConnection.send_packed_command
        monkeypatch.setattr(redis.connection.AbstractConnection, "send_packed_command",
                            lambda self, *args, **kwargs: writes.append(1) or send(self, *args, **kwargs))
        run = lambda: {name.removeprefix("cmdstat_") for name in jobs.r.info("commandstats")} - {"config", "info"}
        enqueue = lambda meta: [("LPUSH", ("test-queue", f"message of {task}")) for task in meta["task_ids"]]
        jobs.r.config_resetstat()
        writes.clear()
        meta = jobs.create("triangulation", request_of(3), 3, 2, "one-command", active_limit=1, chunk_key="tracks",
                           enqueue=enqueue)
        assert len(writes) == 1 and "eval" in run() and not run() & {"multi", "exec"}
        assert jobs.r.lrange("test-queue", 0, -1) == [f"message of {task}" for task in reversed(meta["task_ids"])]
        assert jobs.request(meta["id"]) == request_of(3) and jobs.get(meta["id"])["status"] == "queued"
        jobs.r.config_resetstat()
        assert jobs.create("triangulation", request_of(3), 3, 2, "one-command", active_limit=1, chunk_key="tracks",
                           enqueue=enqueue) is None  # its one active job already
        assert not run() & {"set", "hset", "rpush", "lpush", "xadd", "zadd", "sadd", "rename", "del", "incrby"}
        assert jobs.r.llen("test-queue") == 2 and jobs.r.zcard(JobStore.owner_key("one-command", "jobs")) == 1

    @pytest.mark.parametrize("on_the_loop", [False, True])
    def test_a_large_request_is_written_beside_the_script_and_taken_back_if_refused(self, jobs, on_the_loop):
        """Its text and items (over _Commands.BULK) go as commands of their own in a transaction
        with the script, not through it; a job refused leaves none of them."""
        import asyncio

        import redis.asyncio

        def create(*args, **kwargs):
            if not on_the_loop:
                return jobs.create(*args, **kwargs)

            async def run():
                client = redis.asyncio.Redis(connection_pool=redis.asyncio.ConnectionPool(
                    connection_class=redis.asyncio.UnixDomainSocketConnection if "path" in
                    jobs.r.connection_pool.connection_kwargs else redis.asyncio.Connection,
                    **jobs.r.connection_pool.connection_kwargs))
                try:
                    return await jobs.create_async(client, *args, **kwargs)
                finally:
                    await client.aclose()

            return asyncio.run(run())

        owner = f"bulk-{on_the_loop}"
        large = request_of(300) | {"note": "x" * 40_000}
        kept = create("triangulation", large, 300, 100, owner, active_limit=1, chunk_key="tracks")
        assert jobs.request(kept["id"]) == large and len(jobs.chunk_request(kept["id"], 100, 200)["data"]["tracks"]) == 300
        whole = create("reconstruction", large, 1, 1, owner + "-whole")
        assert jobs.request_text(whole["id"]) == json.dumps(large)
        before = set(jobs.r.scan_iter("geocert:job:*"))
        assert create("triangulation", large, 300, 100, owner, active_limit=1, chunk_key="tracks") is None
        assert set(jobs.r.scan_iter("geocert:job:*")) == before  # nothing of the refused job

    def test_a_job_of_more_tasks_and_items_than_a_lua_unpack_takes_is_created_whole(self, jobs):
        meta = jobs.create("triangulation", request_of(9000), 9000, 1, "many-tasks", chunk_key="tracks")
        assert jobs.r.lrange(JobStore.key(meta["id"], "tasks"), 0, -1) == meta["task_ids"] and len(meta["task_ids"]) == 9000
        assert jobs.request(meta["id"]) == request_of(9000)

    def test_what_the_creation_script_writes_reads_back_exactly(self, jobs):
        """The script's commands travel as one JSON array (decoded by Redis's cjson): non-ASCII
        and astral text, quotes and backslashes, and the created time's float come back as sent."""
        request = request_of(2) | {"callback_url": "https://example.com/\u00e9?q=\"\\", "label": "clé 😀 \\ \" \u0001"}
        owner = "clé-😀"
        meta = jobs.create("triangulation", request, 2, 1, owner, chunk_key="tracks",
                           enqueue=lambda meta: [("LPUSH", ("test-queue-exact", b"bytes \xc3\xa9", 7, 0.1 + 0.2))])
        assert jobs.request(meta["id"]) == request and jobs.request_text(meta["id"]) == json.dumps(request)
        assert jobs.r.zscore(JobStore.owner_key(owner, "jobs"), meta["id"]) == meta["created_at"]
        assert jobs.get(meta["id"])["owner"] == owner
        assert jobs.r.lrange("test-queue-exact", 0, -1) == [repr(0.1 + 0.2), "7", "bytes é"]

    def test_a_task_of_an_ended_or_gone_job_starts_nothing(self, jobs):
        meta = jobs.create("triangulation", request_of(10), 10, 5, "someone", chunk_key="tracks")
        assert jobs.cancel_if_queued(meta["id"])
        assert jobs.start_chunk(meta["id"], 0, 5, "kind") is None
        assert jobs.field(meta["id"], "status") == "cancelled"
        assert jobs.start_chunk("no-such-job", 0, 5, "kind") is None
        assert jobs.r.zscore(JobStore.RUNNING, "no-such-job") is None


class TestProgressSums:
    def test_the_aggregate_is_the_sum_of_each_tasks_last_figures(self, jobs):
        meta = jobs.create("triangulation", request_of(30), 30, 10, "someone", chunk_key="tracks")
        rng = np.random.default_rng(1)
        last: dict[int, dict] = {}
        for _ in range(40):
            start = int(rng.choice([0, 10, 20]))
            lower = float(rng.uniform(0, 100))
            gap_rel = None if rng.uniform() < 0.2 else float(rng.uniform(0, 0.5))
            progress = {"nodes": int(rng.integers(0, 500)), "open_boxes": int(rng.integers(0, 9)),
                        "lower_bound": lower, "upper_bound": lower + float(rng.uniform(0, 5)),
                        "gap_abs": float(rng.uniform(0, 5)), "gap_rel": gap_rel}
            last[start] = progress
            aggregate = jobs.save_progress(meta["id"], start, progress)
            for name in ("nodes", "open_boxes", "lower_bound", "upper_bound", "gap_abs"):
                assert math.isclose(aggregate[name], sum(p[name] for p in last.values()), rel_tol=1e-12, abs_tol=1e-9)
            gaps = [p["gap_rel"] for p in last.values() if p["gap_rel"] is not None]
            assert aggregate["gap_rel"] == (max(gaps) if gaps else None)
        assert json.loads(jobs.r.hget(jobs.key(meta["id"]), "progress")) == aggregate

    def test_bounds_no_task_has_are_null_not_zero(self, jobs):
        """A task reporting no bounds (a reconstruction's stages) leaves the aggregate's bounds
        null: not 0, nor the residue of a stage's bounds added and taken away (1e-17), which the
        page drew."""
        meta = jobs.create("reconstruction", request_of(1), 1, 1, "someone")
        none = {"nodes": 0, "open_boxes": 0, "lower_bound": None, "upper_bound": None, "gap_abs": None,
                "gap_rel": None}
        aggregate = jobs.save_progress(meta["id"], 0, none)
        assert (aggregate["lower_bound"], aggregate["upper_bound"], aggregate["gap_abs"]) == (None, None, None)
        staged = {**none, "lower_bound": 0.1, "upper_bound": 0.3, "gap_abs": 0.2, "gap_rel": 0.6}
        aggregate = jobs.save_progress(meta["id"], 0, staged)
        assert math.isclose(aggregate["lower_bound"], 0.1) and math.isclose(aggregate["upper_bound"], 0.3)
        aggregate = jobs.save_progress(meta["id"], 0, none)
        assert (aggregate["lower_bound"], aggregate["upper_bound"], aggregate["gap_abs"], aggregate["gap_rel"]) == (
            None, None, None, None)


class TestResultKeptCompressed:
    """A finished job's result is kept compressed: what Redis holds and sends for it is a
    fraction of its text, and it reads back exactly."""

    def test_the_result_reads_back_exactly_and_is_stored_small(self, jobs):
        request = request_of(300)
        meta = jobs.create("triangulation", request, 300, 100, "someone", chunk_key="tracks")
        items = [{"point": np.random.default_rng(i).normal(size=3).tolist(), "status": "optimal",
                  "certificate": {"meaning": "lower <= (F X) / (d . X) <= upper for every point X of the scope"}}
                 for i in range(300)]
        result = {"kind": "triangulation", "tracks": items}
        text = json.dumps(result, separators=(",", ":"))
        jobs.end(meta["id"], "succeeded", result=result, result_text=text)
        assert jobs.result_text(meta["id"]) == text
        assert jobs.result(meta["id"]) == result
        assert jobs.document(jobs.get(meta["id"]))["result"] == result
        stored = jobs.r.strlen(jobs.key(meta["id"], "result"))
        assert stored < 0.6 * len(text)  # the floats' digits alone compress about 2x

    def test_the_result_is_sent_in_pieces_that_join_to_its_text(self, jobs, monkeypatch):
        meta = jobs.create("triangulation", request_of(3), 3, 100, "someone", chunk_key="tracks")
        result = {"kind": "triangulation", "tracks": [{"point": [float(i), 1.0 / (i + 1)]} for i in range(2000)]}
        jobs.end(meta["id"], "succeeded", result=result)
        monkeypatch.setattr(JobStore, "RESULT_PIECE_BYTES", 1000)  # many pieces
        pieces = list(jobs.result_pieces(meta["id"]))
        assert len(pieces) > 10 and b"".join(pieces).decode() == json.dumps(result)
        assert jobs.result_pieces("no-such-job") is None

    def test_a_result_stored_as_text_before_compression_still_reads(self, jobs):
        meta = jobs.create("triangulation", request_of(3), 3, 100, "someone", chunk_key="tracks")
        jobs.r.set(jobs.key(meta["id"], "result"), json.dumps({"kind": "triangulation", "tracks": []}))
        assert jobs.result(meta["id"]) == {"kind": "triangulation", "tracks": []}

    def test_items_wait_compressed_and_read_back_exactly(self, jobs):
        meta = jobs.create("triangulation", request_of(40), 40, 20, "someone", chunk_key="tracks")
        items = {i: {"point": [float(i), 0.5, -1.25], "status": "optimal", "reason": None,
                     "determinacy": {"level": "parameters whose squared residuals exceed the optimum's by at most"},
                     "intervals": [{"name": f"q{k}", "value": k * 0.5} for k in range(40)]}
                 for i in range(40)}
        jobs.save_items(meta["id"], {i: items[i] for i in range(20)})
        # an item stored as JSON text (by an earlier version, during an upgrade) reads as well
        jobs.r.hset(jobs.key(meta["id"], "items"), "20", json.dumps(items[20]))
        assert jobs.save_items(meta["id"], {i: items[i] for i in range(21, 40)}) == 40
        assert jobs.all_items(meta["id"], 40) == [items[i] for i in range(40)]
        assert jobs.r.hstrlen(jobs.key(meta["id"], "items"), "0") < len(json.dumps(items[0]))

    def test_an_item_is_stored_about_as_small_as_zlibs_defaults_store_it(self, jobs):
        """The items' small window (JobStore.ITEM_WINDOW_BITS) costs nothing in size on items of
        a track document's sizes (a few hundred bytes to several KB)."""
        import zlib

        meta = jobs.create("triangulation", request_of(3), 3, 3, "someone", chunk_key="tracks")
        rng = np.random.default_rng(7)
        items = {i: {"point": rng.normal(size=3).tolist(), "status": "optimal",
                     "intervals": [{"name": f"q{k}", "value": float(v), "lower": float(v) - 0.1, "upper": float(v) + 0.1}
                                   for k, v in enumerate(rng.normal(size=size))]}
                 for i, size in enumerate((2, 40, 200))}
        jobs.save_items(meta["id"], items)
        assert jobs.all_items(meta["id"], 3) == [items[i] for i in range(3)]
        for i, item in items.items():
            text = json.dumps(item).encode()
            stored = jobs.r.hstrlen(jobs.key(meta["id"], "items"), str(i))
            if len(text) > jobs.ITEM_STORED_AS_TEXT:
                assert stored <= 1.02 * len(zlib.compress(text, jobs.RESULT_COMPRESSION_LEVEL)) + 8, (i, len(text))

    def test_a_small_item_waits_as_its_text_a_large_one_compressed(self, jobs):
        """Compressing a brief track (a few hundred bytes) cost the workers more than encoding it
        and saved a third of it, for the time its job runs: an item up to ITEM_STORED_AS_TEXT bytes
        waits as its JSON text, a larger one compressed; both read back exactly."""
        meta = jobs.create("triangulation", request_of(2), 2, 2, "someone", chunk_key="tracks")
        small = {"point": [0.1, 0.2, 0.3], "status": "optimal", "cost": 0.05, "gap": 1e-8}
        large = {**small, "intervals": [{"name": f"q{k}", "value": k * 0.25} for k in range(60)]}
        assert len(json.dumps(small)) <= jobs.ITEM_STORED_AS_TEXT < len(json.dumps(large))
        jobs.save_items(meta["id"], {0: small, 1: large})
        raw = jobs.binary.hgetall(jobs.key(meta["id"], "items"))
        assert raw[b"0"][:1] == b"{" and json.loads(raw[b"0"]) == small  # its text, as stored
        assert raw[b"1"][:1] != b"{" and len(raw[b"1"]) < len(json.dumps(large)) / 2
        assert jobs.all_items(meta["id"], 2) == [small, large]


class TestStreamedResult:
    """A streamed result (batch.streams_result) is stored as its tasks' runs of items, each one
    compressed fragment with its sums: the end reads the sums, not the items, and the result
    read back is byte for byte the result assembled whole."""

    @staticmethod
    def solved_items(count: int) -> tuple:
        from geocert.jobs.runner import parse_job, solve_job

        kind, _, options = parse_job(get_kind("triangulation").example)
        one = solve_job(kind.example)["tracks"]
        items = [dict(one[i % len(one)], nodes=i + 1) for i in range(count - 1)] + [kind.cancelled_item(options)]
        return kind, options, items

    def store_runs(self, jobs, job_id, kind, items, cuts) -> None:
        from geocert.jobs.runner import item_sums, result_fragment

        for begin, end in zip(cuts[:-1], cuts[1:]):
            jobs.save_fragment(job_id, begin, item_sums(items[begin:end]), result_fragment(kind, items[begin:end]))

    def test_fragments_join_to_the_result_assembled_whole(self, jobs, monkeypatch):
        from geocert.jobs.runner import assemble, merged_sums, result_json, result_shell, stats_from

        kind, options, items = self.solved_items(12)
        meta = jobs.create("triangulation", request_of(12), 12, 5, "someone", chunk_key="tracks")
        self.store_runs(jobs, meta["id"], kind, items, [0, 5, 9, 12])
        plan = jobs.fragment_plan(meta["id"], 12)
        assert [start for start, _ in plan] == [0, 5, 9]
        stats = stats_from(merged_sums([sums for _, sums in plan]), 1.5)
        assert stats["items"] == 12 and stats["nodes"] == sum(item["nodes"] for item in items)
        assert stats["statuses"] == {"optimal": 11, "cancelled": 1}
        jobs.end(meta["id"], "cancelled", fragments=(*result_shell(kind, options, stats), [0, 5, 9]))
        whole = result_json(kind, assemble(kind, None, options, items, stats))
        assert jobs.result_text(meta["id"]) == whole
        assert b"".join(jobs.result_pieces(meta["id"])).decode() == whole
        assert jobs.document(jobs.get(meta["id"]))["result"] == json.loads(whole)
        assert jobs.r.exists(jobs.key(meta["id"], "items"), jobs.key(meta["id"], "fragmentsums")) == 0
        jobs.delete(meta["id"])
        assert jobs.r.exists(jobs.key(meta["id"], "fragments")) == 0

    def test_a_result_that_expires_while_read_is_a_job_gone_not_a_cut_response(self, jobs, monkeypatch):
        """A result expiring between the job's status and its result's read (a GET at the end
        of its time to live) ended the response midway ("removed while it was sent", the client
        seeing an incomplete chunked body). A small result is now read whole before anything is
        sent: gone is ResultGone (the API's 404), never a half-sent body."""
        from geocert.jobs.runner import result_shell, stats_from, merged_sums
        from geocert.jobs.store import ResultGone

        kind, options, items = self.solved_items(12)
        meta = jobs.create("triangulation", request_of(12), 12, 5, "someone", chunk_key="tracks")
        self.store_runs(jobs, meta["id"], kind, items, [0, 5, 9, 12])
        stats = stats_from(merged_sums([sums for _, sums in jobs.fragment_plan(meta["id"], 12)]), 1.5)
        jobs.end(meta["id"], "done", fragments=(*result_shell(kind, options, stats), [0, 5, 9]))
        jobs.r.hdel(jobs.key(meta["id"], "fragments"), "5")  # one fragment expired first
        with pytest.raises(ResultGone):
            jobs.result_pieces(meta["id"])
        assert jobs.result_text(meta["id"]) is None

        plain = jobs.create("triangulation", request_of(1), 1, 1, "someone")
        jobs.end(plain["id"], "done", result={"kind": "triangulation", "tracks": []})
        binary = type(jobs.binary)
        monkeypatch.setattr(binary, "get", lambda self, key: None)  # gone between STRLEN and GET
        with pytest.raises(ResultGone):
            jobs.result_pieces(plain["id"])

    @pytest.mark.parametrize("cuts, plan", [
        ([0, 5, 9, 12], [0, 5, 9]),
        ([0, 5, 12], [0, 5]),
        ([0, 5], None),  # items 5 to 11 without a fragment
        ([5, 12], None),  # nothing from 0
    ])
    def test_a_plan_holds_every_item_once_or_is_none(self, jobs, cuts, plan):
        kind, _, items = self.solved_items(12)
        meta = jobs.create("triangulation", request_of(12), 12, 5, "someone", chunk_key="tracks")
        self.store_runs(jobs, meta["id"], kind, items, cuts)
        found = jobs.fragment_plan(meta["id"], 12)
        assert (None if found is None else [start for start, _ in found]) == plan

    def test_runs_that_overlap_are_no_plan(self, jobs):
        kind, _, items = self.solved_items(12)
        meta = jobs.create("triangulation", request_of(12), 12, 5, "someone", chunk_key="tracks")
        self.store_runs(jobs, meta["id"], kind, items, [0, 7, 12])  # a first split ...
        self.store_runs(jobs, meta["id"], kind, items, [0, 5])  # ... and a redelivered task's shorter run
        assert jobs.fragment_plan(meta["id"], 12) is None  # 5 leads to no fragment; 7 is never reached

    def test_reading_the_result_reads_its_fragments_once(self, jobs):
        from geocert.jobs.runner import merged_sums, result_shell, stats_from

        kind, options, items = self.solved_items(400)
        meta = jobs.create("triangulation", request_of(400), 400, 100, "someone", chunk_key="tracks")
        self.store_runs(jobs, meta["id"], kind, items, [0, 100, 200, 300, 400])
        plan = jobs.fragment_plan(meta["id"], 400)
        stats = stats_from(merged_sums([sums for _, sums in plan]), 1.0)
        jobs.end(meta["id"], "cancelled", fragments=(*result_shell(kind, options, stats), [s for s, _ in plan]))
        stored = sum(jobs.r.hstrlen(jobs.key(meta["id"], "fragments"), str(start)) for start, _ in plan)
        before = output_bytes(jobs)
        text = jobs.result_text(meta["id"])
        read = output_bytes(jobs) - before
        assert stored < read < stored + 2000 and stored < 0.2 * len(text)


    def store_runs_with_items(self, jobs, job_id, kind, items, cuts) -> list:
        from geocert.jobs.runner import item_sums, result_fragment

        return [jobs.save_items(job_id, {i: items[i] for i in range(begin, end)},
                                (begin, item_sums(items[begin:end]), result_fragment(kind, items[begin:end])))
                for begin, end in zip(cuts[:-1], cuts[1:])]

    def test_items_stored_with_their_fragment_are_written_once(self, jobs):
        """A task's items and the fragment that holds them were both written whole: each item is
        now written in its fragment only, its own field saying which fragment holds it, and read
        back as the result model writes it, which assembles the same result to the byte."""
        import copy

        from geocert.jobs.runner import assemble, item_sums, result_json, stats_from

        kind, options, items = self.solved_items(12)
        meta = jobs.create("triangulation", request_of(12), 12, 12, "someone", chunk_key="tracks")
        assert self.store_runs_with_items(jobs, meta["id"], kind, copy.deepcopy(items), [0, 5, 12]) == [5, 12]
        raw = jobs.binary.hgetall(jobs.key(meta["id"], "items"))
        assert sorted(int(index) for index in raw) == list(range(12))
        assert all(len(value) <= 4 for value in raw.values())  # "@<start>", not the item
        assert jobs.missing_items(meta["id"], 12) == []
        assert [start for start, _ in jobs.fragment_plan(meta["id"], 12)] == [0, 5]
        stored = jobs.all_items(meta["id"], 12)
        assert stored == [jobs.stored_items(meta["id"])[i] for i in range(12)]
        stats = stats_from(item_sums(items), 1.5)
        assert item_sums(stored) == item_sums(items)
        assert result_json(kind, assemble(kind, None, options, stored, stats)) == \
            result_json(kind, assemble(kind, None, options, copy.deepcopy(items), stats))

    def test_a_fragment_written_again_shorter_no_longer_holds_its_later_items(self, jobs):
        """A task delivered again and cut elsewhere by its budget writes its fragment again,
        shorter: its items past the new end are not stored any more (a task still to come solves
        them), never read from a fragment that does not hold them."""
        kind, _, items = self.solved_items(12)
        meta = jobs.create("triangulation", request_of(12), 12, 12, "someone", chunk_key="tracks")
        assert self.store_runs_with_items(jobs, meta["id"], kind, items, [0, 7]) == [7]
        assert self.store_runs_with_items(jobs, meta["id"], kind, items, [0, 5]) == [5]
        assert jobs.missing_items(meta["id"], 12) == list(range(5, 12))
        assert sorted(jobs.stored_items(meta["id"])) == list(range(5))
        assert self.store_runs_with_items(jobs, meta["id"], kind, items, [5, 12]) == [12]
        assert len(jobs.all_items(meta["id"], 12)) == 12


class TestJobRecord:
    def test_the_record_a_poll_reads_does_not_grow_with_the_chunks(self, jobs):
        small = jobs.create("triangulation", request_of(3), 3, 100, "someone", chunk_key="tracks")
        large = jobs.create("triangulation", request_of(3), 200_000, 100, "someone", chunk_key="tracks")
        size = lambda meta: sum(len(k) + len(v) for k, v in jobs.r.hgetall(jobs.key(meta["id"])).items())
        assert size(large) < size(small) + 20  # 2,000 chunks: none of them in the record
        assert large["chunks"][:2] == [(0, 100), (100, 200)] and len(large["chunks"]) == 2000
        assert JobStore.chunks(jobs.get(large["id"])) == large["chunks"]
        assert JobStore.chunks({"items_total": 250, "chunk_size": 100}) == [(0, 100), (100, 200), (200, 250)]
        assert JobStore.chunks({"chunks": [[0, 7], [7, 9]]}) == [(0, 7), (7, 9)]  # as an earlier version stored them


def test_the_stores_encoder_writes_json_dumps_text_to_the_byte():
    """What the store writes (the request's head and items, the record's fields, events) is
    json.dumps's text, by one shared C encoder: the floats JSON spells oddly, NaN and infinities,
    non-ASCII and control characters, nesting, keys that are not strings."""
    from geocert.jobs.store import dumps

    rng = np.random.default_rng(5)
    values = [None, True, 0, -7, 2 ** 70, 1e-05, 1e16, 1e-320, -0.0, 0.1 + 0.2, math.nan, math.inf, -math.inf,
              "é\u2028\x00\"\\/", "", [], {}, {3: "int key", 2.5: "float key", None: "none key", True: "bool key"},
              request_of(40, seed=5), {"nested": [[[{"a": [rng.normal(size=3).tolist()]}]]]},
              rng.normal(size=200).tolist(), (1, 2)]
    for value in values:
        assert dumps(value) == json.dumps(value), value


class TestWhatTheAppAsksByName:
    """What the API once did through the store's Redis client, asked of the store by name."""

    def test_live_workers_counts_the_beats_within_fresh_s(self, jobs):
        from geocert.jobs.store import FRESH_S, WORKERS_KEY, now

        jobs.r.delete(WORKERS_KEY)
        assert jobs.live_workers() == 0
        jobs.r.zadd(WORKERS_KEY, {"a": now(), "b": now() - FRESH_S / 2, "gone": now() - 2 * FRESH_S})
        assert jobs.ping() is True
        assert jobs.live_workers() == 2
        jobs.r.delete(WORKERS_KEY)

    def test_an_upload_is_written_with_its_expiry_and_dropped(self, jobs):
        key = jobs.upload_key()
        assert key.startswith("geocert:upload:") and key != jobs.upload_key()
        jobs.append_upload(key, ['{"a": 1}', '{"b": 2}'], 60)
        jobs.append_upload(key, ['{"c": 3}'], 60)
        assert jobs.r.lrange(key, 0, -1) == ['{"a": 1}', '{"b": 2}', '{"c": 3}']
        assert 0 < jobs.r.ttl(key) <= 60
        jobs.drop_upload(key)
        assert not jobs.r.exists(key)
        jobs.drop_upload(key)  # gone already: nothing

    def test_the_head_is_the_document_without_result_and_links(self, jobs):
        meta = jobs.create("triangulation", request_of(3), 3, 2, "someone", chunk_key="tracks")
        document = jobs.document(meta)
        assert jobs.head(meta) == {key: value for key, value in document.items() if key not in ("result", "links")}


def test_create_async_takes_creates_arguments_exactly():
    """create_async binds its arguments with a plain function (creation._create_arguments) instead
    of inspect's binding at each submission: its parameters, defaults and order are create's."""
    import inspect

    from geocert.jobs.store.creation import Creation, _create_arguments

    create = list(inspect.signature(Creation.create).parameters.values())[1:]
    assert [(p.name, p.default) for p in inspect.signature(_create_arguments).parameters.values()] == \
           [(p.name, p.default) for p in create]
    names = [p.name for p in create]
    assert list(_create_arguments(*names)) == names  # in create's order, as _stage_create takes them
