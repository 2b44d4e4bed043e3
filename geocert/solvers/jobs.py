"""Problem kinds and the job model shared by the CLI, the workers and the API.

A job is ``{"kind", "data", "options"}``. Each kind parses its data (raising InputError that names
the field), says how many independent items it holds (tracks, maps, ...), solves one item, and
assembles the result document. Items are solved on their own, so a batch can be split into
chunks that run anywhere and are put back together in input order.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from geocert.solvers.core.bnb import Progress
from geocert.solvers.core.certificates import FORMAT, VERSION, data_hash, problem_hash
from geocert.solvers.core.geometry import COORDINATE_LIMIT, InputError, check_cameras, number_array
from geocert.solvers.fractional.maps import MapOptions, MapResult, check_correspondences, fit_map
from geocert.solvers.fractional.triangulation import NORMS, TrackResult, TriangulationOptions, triangulate
from geocert.solvers.verify import proof_of

ProgressSink = Callable[[dict], None]
MAX_VIEWS = 1000  # views in one track: a chart's choice of reference takes views^2 work
StopCheck = Callable[[], bool]


def finite_or_none(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None


def options_from(options_type: type, given: dict | None, field: str = "options"):
    """Build an options dataclass from a dict, naming any unknown or ill-typed option."""
    given = dict(given or {})
    names = {f.name for f in dataclasses.fields(options_type)}
    for key in given:
        if key not in names:
            raise InputError(f"{field}/{key}", f"unknown option (known: {', '.join(sorted(names))})")
    defaults = options_type()
    for key, value in given.items():
        default = getattr(defaults, key)
        if isinstance(default, str) and not isinstance(value, str):
            raise InputError(f"{field}/{key}", "must be a string")
        numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
        if (isinstance(default, (int, float)) or (default is None and value is not None)) and not numeric:
            raise InputError(f"{field}/{key}", "must be a number")
        if isinstance(default, int) and not isinstance(default, bool) and not isinstance(value, int):
            raise InputError(f"{field}/{key}", "must be an integer")
    options = options_type(**given)
    options.check()
    return options


@dataclass
class TriangulationData:
    cameras: np.ndarray  # (N, 3, 4)
    tracks: list[tuple[list[int], np.ndarray]]


class TriangulationKind:
    name = "triangulation"
    options_type = TriangulationOptions
    item_name = "tracks"
    description = "N-view triangulation: the 3D point minimising reprojection error, certified globally optimal."

    def parse(self, data: Any, items: range | None = None) -> TriangulationData:
        """Checked problem data; with ``items``, only those tracks are read (the rest stay None),
        which is how a worker takes its chunk of a large batch."""
        if not isinstance(data, dict):
            raise InputError("data", "must be an object with 'cameras' and 'tracks'")
        for key in ("cameras", "tracks"):
            if key not in data:
                raise InputError(f"data/{key}", "is required")
        cameras = check_cameras(number_array(data["cameras"], "data/cameras", "a list of 3x4 numeric matrices", 3),
                                "data/cameras")
        if not isinstance(data["tracks"], list) or not data["tracks"]:
            raise InputError("data/tracks", "must be a non-empty list")
        tracks: list = [None] * len(data["tracks"])
        for i in items if items is not None else range(len(data["tracks"])):
            track = data["tracks"][i]
            where = f"data/tracks/{i}"
            if not isinstance(track, dict) or "views" not in track or "points" not in track:
                raise InputError(where, "must be an object with 'views' and 'points'")
            views, points = track["views"], track["points"]
            if not isinstance(views, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in views):
                raise InputError(f"{where}/views", "must be a list of camera indices")
            pts = number_array(points, f"{where}/points", "a list of [u, v] pairs", 2, COORDINATE_LIMIT)
            if pts.shape[1] != 2:
                raise InputError(f"{where}/points", "must be a list of [u, v] pairs")
            if len(views) < 2:
                raise InputError(f"{where}/views", "a track needs at least 2 views")
            if len(views) > MAX_VIEWS:
                raise InputError(f"{where}/views", f"{len(views)} views exceed the limit of {MAX_VIEWS} per track")
            if len(views) != len(pts):
                raise InputError(where, f"has {len(views)} views but {len(pts)} points")
            for j, v in enumerate(views):
                if not 0 <= v < len(cameras):
                    raise InputError(f"{where}/views/{j}", f"camera index {v} out of range 0..{len(cameras) - 1}")
            if len(set(views)) != len(views):
                raise InputError(f"{where}/views", "a camera appears twice in the track")
            bad = np.argwhere(~np.isfinite(pts))
            if len(bad):
                raise InputError(f"{where}/points/{bad[0][0]}", "contains a non-finite number")
            tracks[i] = (list(views), pts)
        return TriangulationData(cameras, tracks)

    def count(self, parsed: TriangulationData) -> int:
        return len(parsed.tracks)

    def observations(self, parsed: TriangulationData) -> int:
        return sum(len(track[1]) for track in parsed.tracks if track is not None)  # parsed items only

    def solve_item(self, parsed: TriangulationData, index: int, options: TriangulationOptions,
                   callback: Callable[[Progress], bool | None] | None) -> dict:
        views, points = parsed.tracks[index]
        return track_document(triangulate(parsed.cameras[views], points, options, callback))

    def cancelled_item(self) -> dict:
        return track_document(TrackResult("cancelled", False, reason="the job was cancelled before this track started"))

    def assemble(self, options: TriangulationOptions, items: list[dict], stats: dict) -> dict:
        return {"kind": self.name, "norm": options.norm, "tracks": items, "stats": stats}


def certificate_document(result, region: dict, meaning: str, scope: str) -> dict | None:
    """The certificate part of an item: the search's (when there was one), or the note that the
    incumbent met the trivial bound 0. With a full certificate, ``proof`` too (moved into the
    job's certificate document when the result is assembled)."""
    c = result.certificate
    proof = proof_of(result)
    extra = {"proof": proof} if proof is not None else {}
    if c is not None:
        return {**extra,
            "scope": c.scope,
            "root_region": {**region, "functionals": c.functionals, "denominator": c.denominator,
                            "lower": c.lower, "upper": c.upper, "meaning": meaning},
            "tolerance": finite_or_none(c.tolerance),
            "tolerance_met": c.tolerance_met,
            "leaves": c.leaves,
        }
    if result.certified:
        return {"scope": scope, "root_region": None, "tolerance": 0.0, "tolerance_met": True, "leaves": 0,
                "note": "the incumbent's cost is within abs_gap of the trivial bound 0", **extra}
    return None


def outcome_document(result) -> dict:
    """The fields every item (track, map) reports about its solve."""
    return {
        "cost": finite_or_none(result.cost),
        "lower_bound": finite_or_none(result.lower_bound),
        "gap": finite_or_none(result.gap),
        "status": result.status,
        "certified": result.certified,
        "nodes": result.nodes,
        "elapsed_s": result.elapsed_s,
        "reason": result.reason,
    }


def track_document(result: TrackResult) -> dict:
    region = {"reference_view": result.certificate.reference} if result.certificate else {}
    certificate = certificate_document(
        result, region,
        "lower <= (F X) / (d . X) <= upper for every point X of the scope, "
        "F = functionals (one per direction the other views' depths vary along), "
        "d = denominator (positive in front of the reference view)",
        "every point in front of every camera")
    return {"point": result.point, "at_infinity": result.at_infinity, **outcome_document(result),
            "certificate": certificate}


@dataclass
class MapsData:
    maps: list[tuple[np.ndarray, np.ndarray] | None]


class MapKind:
    """Resection (3D -> 2D) and homographies (2D -> 2D, 3D -> 3D): independent maps, one item each."""

    options_type = MapOptions
    item_name = "maps"

    def __init__(self, name: str, dimensions: set[tuple[int, int]], description: str):
        self.name, self.dimensions, self.description = name, dimensions, description

    def parse(self, data: Any, items: range | None = None) -> MapsData:
        if not isinstance(data, dict) or "maps" not in data:
            raise InputError("data/maps", "is required: a list of {source, target} correspondences")
        if not isinstance(data["maps"], list) or not data["maps"]:
            raise InputError("data/maps", "must be a non-empty list")
        maps: list = [None] * len(data["maps"])
        for i in items if items is not None else range(len(data["maps"])):
            where = f"data/maps/{i}"
            entry = data["maps"][i]
            if not isinstance(entry, dict) or "source" not in entry or "target" not in entry:
                raise InputError(where, "must be an object with 'source' and 'target'")
            arrays = []
            for key in ("source", "target"):
                array = number_array(entry[key], f"{where}/{key}", "a list of points (lists of numbers)", 2,
                                     COORDINATE_LIMIT)
                if array.shape[0] == 0:
                    raise InputError(f"{where}/{key}", "must be a non-empty list of points of one dimension")
                arrays.append(array)
            source, target = arrays
            if (source.shape[1], target.shape[1]) not in self.dimensions:
                allowed = " or ".join(f"{n}D -> {m}D" for n, m in sorted(self.dimensions))
                raise InputError(where, f"{source.shape[1]}D -> {target.shape[1]}D points; {self.name} takes {allowed}")
            check_correspondences(source, target, where)
            maps[i] = (source, target)
        return MapsData(maps)

    def count(self, parsed: MapsData) -> int:
        return len(parsed.maps)

    def observations(self, parsed: MapsData) -> int:
        return sum(len(pair[0]) for pair in parsed.maps if pair is not None)  # parsed items only

    def solve_item(self, parsed: MapsData, index: int, options: MapOptions, callback) -> dict:
        source, target = parsed.maps[index]
        return map_document(fit_map(source, target, options, callback))

    def cancelled_item(self) -> dict:
        return map_document(MapResult("cancelled", False, reason="the job was cancelled before this map started"))

    def assemble(self, options: MapOptions, items: list[dict], stats: dict) -> dict:
        return {"kind": self.name, "norm": options.norm, "maps": items, "stats": stats}


def map_document(result: MapResult) -> dict:
    region = {"reference_point": result.certificate.reference} if result.certificate else {}
    certificate = certificate_document(
        result, region,
        "lower <= (F l) / (d . l) <= upper for the last row l of every map in the scope, "
        "F = functionals, d = denominator (the reference point, homogeneous)",
        "every map that puts every point at positive depth")
    return {"matrix": result.matrix, "residuals": result.residuals, **outcome_document(result),
            "certificate": certificate}


KINDS = {kind.name: kind for kind in (
    TriangulationKind(),
    MapKind("resection", {(3, 2)}, "Camera resectioning: the projective camera (3x4) from 3D-2D matches, "
                                   "certified globally optimal."),
    MapKind("homography", {(2, 2), (3, 3)}, "Homographies of P^2 (from 2D-2D matches) or P^3 (from 3D-3D "
                                            "matches), certified globally optimal."),
)}


def get_kind(name: Any):
    if name not in KINDS:
        raise InputError("kind", f"unknown problem kind {name!r} (served: {', '.join(KINDS)})")
    return KINDS[name]


def default_options(kind) -> dict:
    return dataclasses.asdict(kind.options_type())


class ItemProgress:
    """Aggregates progress over the items of a chunk: finished items plus the one running."""

    def __init__(self, total: int, sink: ProgressSink | None, should_stop: StopCheck | None):
        self.total = total
        self.sink = sink
        self.should_stop = should_stop
        self.done = 0
        self.nodes_done = 0
        self.lower_done = 0.0
        self.upper_done = 0.0
        self.worst_gap_rel = 0.0
        self.start = time.perf_counter()
        self.stopped = False

    def finished(self, item: dict) -> None:
        self.done += 1
        self.nodes_done += item["nodes"]
        if item.get("cost") is not None and item.get("lower_bound") is not None:
            self.lower_done += item["lower_bound"]
            self.upper_done += item["cost"]
            if item["cost"] > 0:
                self.worst_gap_rel = max(self.worst_gap_rel, (item["cost"] - item["lower_bound"]) / item["cost"])
        self.emit(None)

    def emit(self, running: Progress | None) -> None:
        if self.sink is None:
            return
        lower, upper, nodes, gap_rel, open_boxes = self.lower_done, self.upper_done, self.nodes_done, self.worst_gap_rel, 0
        if running is not None:
            nodes += running.nodes
            open_boxes = running.open_boxes
            if math.isfinite(running.lower_bound) and math.isfinite(running.upper_bound):
                lower += running.lower_bound
                upper += running.upper_bound
                gap_rel = max(gap_rel, running.gap_rel)
        self.sink({
            "nodes": nodes, "open_boxes": open_boxes,
            "lower_bound": lower, "upper_bound": upper, "gap_abs": max(0.0, upper - lower),
            "gap_rel": finite_or_none(gap_rel), "tracks_done": self.done, "tracks_total": self.total,
            "elapsed_s": time.perf_counter() - self.start,
        })

    def engine_callback(self, progress: Progress) -> bool:
        if self.should_stop is not None and self.should_stop():
            self.stopped = True
            return True
        self.emit(progress)
        return False


def solve_items(kind, parsed, options, indices: range, sink: ProgressSink | None = None,
                should_stop: StopCheck | None = None, total: int | None = None,
                stop_at: float | None = None) -> list[dict]:
    """Solve the given items in order; once stopped, the rest are marked cancelled unsolved.
    After the ``time.monotonic()`` value ``stop_at`` no new item is started (at least one is
    always solved): the list returned is then shorter, and the caller solves the rest later."""
    tracker = ItemProgress(total if total is not None else len(indices), sink, should_stop)
    items = []
    for index in indices:
        if stop_at is not None and items and not tracker.stopped and time.monotonic() > stop_at:
            break
        if tracker.stopped or (should_stop is not None and should_stop()):
            tracker.stopped = True
            items.append(kind.cancelled_item())
            continue
        item = kind.solve_item(parsed, index, options, tracker.engine_callback)
        items.append(item)
        tracker.finished(item)
    return items


def job_stats(items: list[dict], elapsed_s: float) -> dict:
    statuses: dict[str, int] = {}
    for item in items:
        statuses[item["status"]] = statuses.get(item["status"], 0) + 1
    return {
        "items": len(items),
        "certified": sum(1 for item in items if item["certified"]),
        "nodes": sum(item["nodes"] for item in items),
        "solve_s": sum(item["elapsed_s"] for item in items),
        "elapsed_s": elapsed_s,
        "statuses": statuses,
    }


def solve_job(job: dict, sink: ProgressSink | None = None, should_stop: StopCheck | None = None) -> dict:
    """Run a whole job in this process (the CLI's path): parse, solve every item, assemble."""
    kind, parsed, options = parse_job(job)
    start = time.perf_counter()
    items = solve_items(kind, parsed, options, range(kind.count(parsed)), sink, should_stop)
    return assemble(kind, job, options, items, job_stats(items, time.perf_counter() - start))


def assemble(kind, job: dict, options, items: list[dict], stats: dict) -> dict:
    """The result document; with ``options.certificate == "full"`` it carries the certificate
    document too (the items' proofs move there)."""
    if options.certificate == "full":
        certificate = full_certificate(kind.name, job["data"], options, items)
    else:
        certificate = None
        for item in items:
            (item.get("certificate") or {}).pop("proof", None)
    result = kind.assemble(options, items, stats)
    if certificate is not None:
        result["certificate"] = certificate
    return result


def full_certificate(kind_name: str, data: Any, options, items: list[dict]) -> dict:
    """The certificate document (docs/certificate.md): the problem data and its hash, the options,
    and each item's claim (solution, cost, gap) with its proof."""
    claims = []
    for index, item in enumerate(items):
        proof = (item.get("certificate") or {}).pop("proof", None)
        solution = {key: item[key] for key in ("point", "at_infinity", "matrix") if key in item}
        claims.append({"index": index, "status": item["status"], "certified": item["certified"] and proof is not None,
                       "cost": item["cost"], "lower_bound": item["lower_bound"], "gap": item["gap"],
                       **solution, "proof": proof})
    options = dataclasses.asdict(options)
    return {"format": FORMAT, "version": VERSION, "kind": kind_name, "options": options,
            "data": data, "data_sha256": data_hash(kind_name, data),
            "problem_sha256": problem_hash(kind_name, data, options), "items": claims}


def parse_job(job: Any):
    if not isinstance(job, dict):
        raise InputError("", "a job must be an object with 'kind', 'data' and optional 'options'")
    kind = get_kind(job.get("kind"))
    options = options_from(kind.options_type, job.get("options"))
    parsed = kind.parse(job.get("data"))
    return kind, parsed, options


__all__ = ["KINDS", "NORMS", "get_kind", "parse_job", "solve_job", "solve_items", "job_stats", "default_options"]
