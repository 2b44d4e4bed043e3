"""A job's items, solved in order, and its result document: what the CLI runs in-process and a
worker runs on its chunk. A job is ``{"kind", "data", "options"}``; its kind (geocert.kinds) parses
the data, solves one item and assembles the result. Items are solved on their own, so a batch can
be split into chunks that run anywhere and are put back together in input order."""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Any, Callable

from geocert.kinds import get_kind, options_from
from geocert.kinds.documents import certificate_document, finite_or_none
from geocert.core.bnb import Progress
from geocert.core.geometry import InputError
from geocert.jobs.finite import refuse_non_finite

ProgressSink = Callable[[dict], None]
StopCheck = Callable[[], bool]


def item_counts(done: int, total: int | None) -> dict:
    """Progress's item counts: ``items_done`` and ``items_total``, and the same values under their
    deprecated names ``tracks_done`` and ``tracks_total`` (which count maps too)."""
    return {"items_done": done, "items_total": total, "tracks_done": done, "tracks_total": total}


def abs_gap_of(options: Any) -> float:
    """The job's absolute gap tolerance (0 for a kind without one)."""
    return float(getattr(options, "abs_gap", None) or 0.0)


def gap_beyond_tolerance(cost: float, lower: float, abs_gap: float) -> float:
    """An item's relative gap as the job's worst counts it: the part of its gap beyond the
    absolute tolerance, relative to its cost. A near-zero cost certified by the absolute tolerance
    (the Dinosaur's exact two-view tracks: cost 1e-13, bound 0) counts 0, not a relative gap of 1
    that says nothing; any item not within its tolerance counts what it misses by."""
    if not cost > 0:
        return 0.0
    return max(0.0, cost - lower - abs_gap) / cost


class ItemProgress:
    """Aggregates progress over the items of a chunk: finished items plus the one running."""

    def __init__(self, total: int, sink: ProgressSink | None, should_stop: StopCheck | None, abs_gap: float = 0.0):
        self.total = total
        self.abs_gap = abs_gap
        self.sink = sink
        self.should_stop = should_stop
        self.done = 0
        self.nodes_done = 0
        self.lower_done = 0.0
        self.upper_done = 0.0
        self.bounded_done = 0  # finished items with both bounds: what lower_done and upper_done add
        self.worst_gap_rel = 0.0
        self.start = time.perf_counter()
        self.stopped = False

    def finished(self, item: dict, emit: bool = True) -> None:
        """Count a finished item; ``emit=False`` when more of its group end at the same moment
        (solve_batch returns them together), so that the group's progress is sent once."""
        self.done += 1
        self.nodes_done += item["nodes"]
        if item.get("cost") is not None and item.get("lower_bound") is not None:
            self.lower_done += item["lower_bound"]
            self.upper_done += item["cost"]
            self.bounded_done += 1
            self.worst_gap_rel = max(self.worst_gap_rel,
                                     gap_beyond_tolerance(item["cost"], item["lower_bound"], self.abs_gap))
        if emit:
            self.emit(None)

    def emit(self, running: Progress | None) -> None:
        """Sends the progress. The bounds sum real figures only (the finished items' and the
        running search's); with none (an item with no bounds, as a reconstruction, or a stage
        that reports its count only) they are null, not 0, which a chart would draw."""
        if self.sink is None:
            return
        lower, upper, nodes, gap_rel, open_boxes = self.lower_done, self.upper_done, self.nodes_done, self.worst_gap_rel, 0
        bounded = self.bounded_done > 0
        if running is not None:
            nodes += running.nodes
            open_boxes = running.open_boxes
            if math.isfinite(running.lower_bound) and math.isfinite(running.upper_bound):
                bounded = True
                lower += running.lower_bound
                upper += running.upper_bound
                gap_rel = max(gap_rel, gap_beyond_tolerance(running.upper_bound, running.lower_bound, self.abs_gap))
        stage = {"stage": running.stage} if getattr(running, "stage", None) else {}
        self.sink({
            **stage,
            "nodes": nodes, "open_boxes": open_boxes,
            "lower_bound": lower if bounded else None, "upper_bound": upper if bounded else None,
            "gap_abs": max(0.0, upper - lower) if bounded else None,
            "gap_rel": finite_or_none(gap_rel) if bounded else None, **item_counts(self.done, self.total),
            "elapsed_s": time.perf_counter() - self.start,
        })

    def engine_callback(self, progress: Progress) -> bool:
        if self.should_stop is not None and self.should_stop():
            self.stopped = True
            return True
        self.emit(progress)
        return False


def job_time_limit_of(options: Any) -> float | None:
    """The job's own time limit in all (``job_time_limit_s``, the many-item kinds' option), None
    for a kind without one (a one-item kind, bounded by its own stage limits: time_bound_s)."""
    limit = getattr(options, "job_time_limit_s", None)
    return None if limit is None else float(limit)


def job_deadline(options: Any, started: float) -> float | None:
    """The ``time.monotonic()`` value past which a job begun at ``started`` (the same clock)
    starts no item and stops the running ones: None without a job time limit."""
    limit = job_time_limit_of(options)
    return None if limit is None else started + limit


def not_started_item(kind, options) -> dict:
    """An item the job's time limit ended before it started: status ``time_limit``, never
    certified, no solution, saying so (the kind's unsolved item)."""
    item = kind.cancelled_item(options)
    reason = (f"not started: the job's time limit (options.job_time_limit_s, "
              f"{job_time_limit_of(options):g} s) passed before this item started")
    return {**item, "status": "time_limit", "reason": reason}


def within_deadline(options: Any, deadline: float | None) -> Any:
    """The options an item started now runs with: its ``time_limit_s`` no longer than what is
    left before the job's deadline, so its search stops there with status ``time_limit`` and its
    best answer so far."""
    if deadline is None or not hasattr(options, "time_limit_s"):
        return options
    left = deadline - time.monotonic()
    if left >= options.time_limit_s:
        return options
    return dataclasses.replace(options, time_limit_s=max(1e-3, left))


def solve_items(kind, parsed, options, indices: range, sink: ProgressSink | None = None,
                should_stop: StopCheck | None = None, total: int | None = None,
                stop_at: float | None = None, on_item: Callable[[int, dict], None] | None = None,
                deadline: float | None = None) -> list[dict]:
    """Solve the given items in order; once stopped, the rest are marked cancelled unsolved.
    After the ``time.monotonic()`` value ``stop_at`` no new item is started (at least one is
    always solved): the list returned is then shorter, and the caller solves the rest later.
    ``deadline`` (the same clock: the job's, job_deadline) is one clock every item shares: an
    item started before it runs at most to it (within_deadline; a batch of items too), and the
    items not started by then read ``time_limit``, not started (not_started_item): the job ends
    there with what it finished.
    ``on_item(index, item)`` sees each item as it ends, before the progress that counts it."""
    tracker = ItemProgress(total if total is not None else len(indices), sink, should_stop, abs_gap_of(options))
    items = []
    # A kind that solves many items at once (solve_batch) takes them a group at a time: the
    # budget and a cancel are seen between groups, progress once a group (its items end at the
    # same moment: a progress per item made and sent 500 documents of progress a group, and the
    # worker's throttle stored the group's first item on its own, a round trip and a fragment
    # more); the deadline inside a group too (solve_batch's own). ``on_item`` still sees each.
    group = kind.batch_size if kind.solve_batch is not None else 1
    for begin in range(0, len(indices), group):
        if stop_at is not None and items and not tracker.stopped and time.monotonic() > stop_at:
            break
        chosen = indices[begin:begin + group]
        if tracker.stopped or (should_stop is not None and should_stop()):
            tracker.stopped = True
            for index in chosen:  # never started: not counted as done
                items.append(kind.cancelled_item(options))
                if on_item is not None:
                    on_item(index, items[-1])
            continue
        if deadline is not None and time.monotonic() >= deadline:
            solved = [not_started_item(kind, options) for _ in chosen]
        elif group == 1:
            solved = [kind.solve_item(parsed, chosen[0], within_deadline(options, deadline), tracker.engine_callback)]
        else:
            solved = kind.solve_batch(parsed, list(chosen), options, tracker.engine_callback, deadline=deadline)
        last = min(len(chosen), len(solved))
        for index, item in zip(chosen, solved):  # before any is stored or streamed (jobs.finite)
            refuse_non_finite(item, f"/{getattr(kind, 'item_key', 'items')}/{index}")
        for position, (index, item) in enumerate(zip(chosen, solved), 1):
            items.append(item)
            if on_item is not None:
                on_item(index, item)
            tracker.finished(item, emit=position == last)
    return items


def task_time_bound_s(kind, item_bound_s: float, items: int, budget_s: float, job_limit_s: float | None = None) -> float:
    """The longest a task solving ``items`` items of a job runs when every item keeps its own
    time limits (``item_bound_s`` each: the kind's ``time_bound_s``): it starts no new group of
    items after ``budget_s`` (solve_items's ``stop_at``), and the group started last runs its
    limits; and no task of a job with a time limit in all (``job_limit_s``: its options'
    job_time_limit_s) runs past it, however large its group. The work between the solvers'
    clock checks is not counted."""
    group = min(items, kind.batch_size if kind.solve_batch is not None else 1)
    bound = min(items * item_bound_s, budget_s + group * item_bound_s)
    return bound if job_limit_s is None else min(bound, job_limit_s)


def item_sums(items: list[dict], abs_gap: float = 0.0) -> dict:
    """What a job's stats and final progress take from its items, as sums: a task stores these
    for the run of items it solved (a fragment of a streamed result), and the end adds them.
    ``gap_rel``: the worst item's gap beyond ``abs_gap`` relative to its cost (gap_beyond_tolerance)."""
    statuses: dict[str, int] = {}
    for item in items:
        statuses[item["status"]] = statuses.get(item["status"], 0) + 1
    bounded = [item for item in items if item.get("cost") is not None and item.get("lower_bound") is not None]
    return {
        "items": len(items),
        "certified": sum(1 for item in items if item["certified"]),
        "nodes": sum(item["nodes"] for item in items),
        "solve_s": sum(item["elapsed_s"] for item in items),
        "statuses": statuses,
        "ran": sum(1 for item in items if item["status"] != "cancelled"),  # ended on their own
        "bounded": len(bounded),  # items with both bounds: what the sums below add
        "lower": sum(item["lower_bound"] for item in bounded),
        "upper": sum(item["cost"] for item in bounded),
        "gap_rel": max((gap_beyond_tolerance(item["cost"], item["lower_bound"], abs_gap) for item in bounded),
                       default=0.0),
    }


def merged_sums(parts: list[dict]) -> dict:
    """item_sums of runs of items, added up (as item_sums of all of them, up to rounding)."""
    statuses: dict[str, int] = {}
    for part in parts:
        for status, count in part["statuses"].items():
            statuses[status] = statuses.get(status, 0) + count
    merged = {name: sum(part[name] for part in parts)
              for name in ("items", "certified", "nodes", "solve_s", "ran", "bounded", "lower", "upper")}
    return {**merged, "statuses": statuses, "gap_rel": max((part["gap_rel"] for part in parts), default=0.0)}


def stats_from(sums: dict, elapsed_s: float) -> dict:
    """The result's ``stats`` from item_sums."""
    return {"items": sums["items"], "certified": sums["certified"], "nodes": sums["nodes"], "solve_s": sums["solve_s"],
            "elapsed_s": elapsed_s, "statuses": sums["statuses"]}


def job_stats(items: list[dict], elapsed_s: float) -> dict:
    return stats_from(item_sums(items), elapsed_s)  # the stats hold no gap: no tolerance needed


def solve_job(job: dict, sink: ProgressSink | None = None, should_stop: StopCheck | None = None) -> dict:
    """Run a whole job in this process (the CLI's path): parse, solve every item, assemble."""
    kind, parsed, options = parse_job(job)
    start = time.perf_counter()
    items = solve_items(kind, parsed, options, range(kind.count(parsed)), sink, should_stop,
                        deadline=job_deadline(options, time.monotonic()))
    return assemble(kind, job, options, items, job_stats(items, time.perf_counter() - start))


def assemble(kind, job: dict, options, items: list[dict], stats: dict) -> dict:
    """The result document; with ``options.certificate == "full"`` it carries the certificate
    document too (the proofs move there from the items' certificate summaries)."""
    if kind.certifies and options.certificate == "full":  # a kind of estimates has no such option
        document = certificate_document(kind, job["data"], options, items)
    else:
        document = None
        for item in items:
            (item.get("certificate") or {}).pop("proof", None)
    result = kind.assemble(options, items, stats)
    if document is not None:
        result["certificate"] = document
    refuse_non_finite(result)  # every result is written from here or from solve_items' items
    return result


@functools.cache
def _result_adapter(model: type):
    from pydantic import TypeAdapter

    return TypeAdapter(model)


def result_json(kind, result: dict) -> str | None:
    """The result document as JSON written by its kind's result model: byte for byte what the API
    would send for it (a worker stores this, so serving a large result copies it instead of
    parsing, validating and writing it again). None if the model does not take it (then the
    API's own serializer decides)."""
    adapter = _result_adapter(kind.result_model)
    try:
        return adapter.dump_json(adapter.validate_python(result), by_alias=True).decode()
    except ValueError:
        return None


def streams_result(kind, options) -> bool:
    """Whether the job's result is stored a run of items at a time (``result_fragment``) and
    never assembled whole: for a kind whose result is its items in order plus members that depend
    on the options and stats alone (``streamed_result``), unless a full certificate must gather
    every item's proof."""
    return kind.streamed_result and not (kind.certifies and options.certificate == "full")


@functools.cache
def _items_adapter(kind):
    from pydantic import TypeAdapter

    return TypeAdapter(kind.result_model.model_fields[kind.item_key].annotation)


def result_fragment(kind, items: list[dict]) -> str | None:
    """Items as the result model writes them inside its item list (comma-separated, no
    brackets): the fragments of a streamed result, joined by commas between result_shell's two
    halves, are byte for byte result_json of the result assembled whole. None if the model does
    not take them."""
    adapter = _items_adapter(kind)
    try:
        return adapter.dump_json(adapter.validate_python(items), by_alias=True).decode()[1:-1]
    except ValueError:
        return None


def result_shell(kind, options, stats: dict) -> tuple[str, str] | None:
    """The result's JSON before and after its items (streamed results); None if its model does
    not write it, or the item list cannot be told apart."""
    text = result_json(kind, kind.assemble(options, [], stats))
    marker = f'"{kind.item_key}":[]'
    if text is None or text.count(marker) != 1:
        return None
    head, _, tail = text.partition(marker)
    return head + marker[:-1], "]" + tail


def parse_job(job: Any):
    if not isinstance(job, dict):
        raise InputError("", "a job must be an object with 'kind', 'data' and optional 'options'")
    kind = get_kind(job.get("kind"))
    options = options_from(kind.options_type, job.get("options"))
    parsed = kind.parse(job.get("data"))
    kind.check_options(parsed, options)  # what the data must give the options (e.g. enough lines)
    return kind, parsed, options


__all__ = ["parse_job", "solve_job", "solve_items", "job_stats", "assemble", "ItemProgress", "item_sums", "merged_sums",
           "stats_from", "streams_result", "result_fragment", "result_shell", "task_time_bound_s",
           "job_deadline", "job_time_limit_of", "not_started_item", "within_deadline"]
