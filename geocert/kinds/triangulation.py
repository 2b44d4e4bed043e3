"""The triangulation kind: tracks of pixel observations seen by known projective cameras."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import accumulate, chain, repeat
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, Field

from geocert.kinds.base import ProblemKind
from geocert.kinds.documents import brief_certificate, certificate_summary, local_summary, outcome_document
from geocert.kinds.schema import Camera, CertificateDocument, ItemOutcome, JobBase, JobStats, Pixel, Strict, options_model
from geocert.core.geometry import COORDINATE_LIMIT, NUMBER_TYPES, InputError, check_cameras, number_array
from geocert.verify.fractional import MAX_VIEWS, TRACK_REGION_MEANING, TRACKS
from geocert.formulations.fractional.options import TriangulationOptions
from geocert.formulations.fractional.columns import SCOPE, TrackResults
from geocert.formulations.fractional.results import SearchCertificate, TrackResult



class TrackIn(Strict):
    views: list[Annotated[int, Field(ge=0)]] = Field(min_length=2, description="camera indices")
    points: list[Pixel] = Field(min_length=2, description="one observation per view, in the same order")


class TriangulationData(Strict):
    cameras: list[Camera] = Field(min_length=1)
    tracks: list[TrackIn] = Field(min_length=1)


TriangulationOptionsIn = options_model("TriangulationOptionsIn", TriangulationOptions)


class TriangulationJob(JobBase):
    kind: Literal["triangulation"]
    data: TriangulationData
    options: TriangulationOptionsIn = Field(default_factory=TriangulationOptionsIn)


class TrackOut(ItemOutcome):
    point: list[float] | None = Field(description="[x, y, z], or a homogeneous 4-vector when at_infinity")
    at_infinity: bool


class TriangulationResult(BaseModel):
    kind: Literal["triangulation"]
    norm: str
    tracks: list[TrackOut]
    stats: JobStats
    certificate: CertificateDocument | None = Field(None, description='with options.certificate = "full"')


@dataclass
class ParsedTracks:
    cameras: np.ndarray  # (N, 3, 4)
    tracks: list[tuple[list[int], np.ndarray] | None]


def track_document(result: TrackResult, detail: str = "full", full_certificate: bool = False) -> dict:
    region = {"reference_view": result.certificate.reference} if isinstance(result.certificate, SearchCertificate) \
        else {}
    certificate = brief_certificate(result, full_certificate) if detail == "brief" else certificate_summary(
        result, region, TRACK_REGION_MEANING, "every point in front of every camera")
    return {"point": result.point, "at_infinity": result.at_infinity, **outcome_document(result),
            "certificate": certificate}


def track_documents(results: TrackResults, detail: str, full_certificate: bool) -> list[dict]:
    """track_document of every result, the convexity path's columns read as arrays (no
    TrackResult made for them): the same documents."""
    documents: list = [None] * len(results)
    local, rows = results.local, results.in_columns()
    if local is not None and len(local.index):
        proof = local.proof and (full_certificate or detail != "brief")
        columns = zip(local.index.tolist(), local.point.tolist(), local.cost.tolist(), local.lower_bound.tolist(),
                      local.gap.tolist(), local.tolerance.tolist(), local.radius.tolist(),
                      local.sublevels() if proof else repeat(None))
        for i, point, cost, lower, gap, tolerance, radius, sublevel in columns:
            if not rows[i]:
                continue  # replaced by an object, made below
            extra = {"proof": {"type": "convexity", "radius": radius}} if proof else {}
            if sublevel is not None:
                extra["proof"]["sublevel"] = sublevel
            certificate = (extra or None) if detail == "brief" else \
                local_summary(SCOPE, tolerance, radius, True, extra)
            documents[i] = {"point": point, "at_infinity": False, "cost": cost, "lower_bound": lower, "gap": gap,
                            "status": "optimal", "certified": True, "nodes": 0, "elapsed_s": local.elapsed_s,
                            "reason": None, "certificate": certificate}
    for i in np.flatnonzero(~rows).tolist():
        documents[i] = track_document(results[i], detail, full_certificate)
    return documents


def tracks_in_bulk(entries: list, chosen, cameras: int) -> list | None:
    """The tracks ``chosen`` of ``entries`` (the request's data.tracks) as TriangulationKind.parse
    reads them, ``(views, points (n, 2))``, every check of its per-track loop made on all of
    them at once (a few passes over flat lists and one array, instead of a number_array call a
    track); None when any check fails, and the per-track loop then names the entry."""
    try:
        picked = [entries[i] for i in chosen]
        if not all(type(track) is dict for track in picked):
            return None
        views = [track["views"] for track in picked]
        points = [track["points"] for track in picked]
    except (KeyError, IndexError, TypeError):
        return None
    if not picked or not all(type(v) is list for v in views) or not all(type(p) is list for p in points):
        return None
    sizes = [len(v) for v in views]
    if min(sizes) < 2 or max(sizes) > MAX_VIEWS or [len(p) for p in points] != sizes:
        return None
    indices = list(chain.from_iterable(views))
    rows = list(chain.from_iterable(points))
    if not all(type(v) is int for v in indices) or not all(type(row) is list and len(row) == 2 for row in rows):
        return None
    if not NUMBER_TYPES.issuperset(map(type, chain.from_iterable(rows))):
        return None
    try:
        pixels = np.array(rows, dtype=float)  # (observations, 2)
    except (OverflowError, ValueError):
        return None
    magnitude = np.abs(pixels)
    if not (np.isfinite(pixels).all() and (magnitude <= COORDINATE_LIMIT).all()):
        return None
    try:
        index = np.array(indices, dtype=np.int64)
    except OverflowError:  # an index beyond int64: out of range, which the loop names
        return None
    if not ((index >= 0) & (index < cameras)).all():
        return None
    owner = np.repeat(np.arange(len(sizes)), sizes)
    order = np.lexsort((index, owner))  # each track's views sorted: a view twice sits next to itself
    if ((owner[order][1:] == owner[order][:-1]) & (index[order][1:] == index[order][:-1])).any():
        return None
    # each track's rows sliced off in turn: np.split made the same views at 2.5 times the cost
    ends = list(accumulate(sizes))
    return [(list(v), pixels[end - size:end]) for v, size, end in zip(views, sizes, ends)]


class TriangulationKind(ProblemKind):
    name = "triangulation"
    description = "N-view triangulation: the 3D point minimising reprojection error, certified globally optimal."
    item_key = "tracks"
    chunk_key = "tracks"  # data["tracks"][i] is item i: a task reads only its chunk's
    streamed_result = True  # the result: its items, the norm and stats (batch.streams_result)
    # Tracks are solved together (solvers.fractional.many_tracks): most of a track's work is shared
    # by the tracks of a group, about 0.9 ms a track in groups of 500 against 1.4 in groups of 100.
    chunk_size = 500
    batch_size = 500
    options_type = TriangulationOptions
    request_model = TriangulationJob
    result_model = TriangulationResult
    solution_fields = ("point", "at_infinity")
    verification = TRACKS
    # The web page's first template: the points (0.1, 0.1, 10) and (0, 0.3, 12) seen with 0.1 to
    # 0.3 px of noise, so both tracks are certified, determined and unwarned. The observations
    # before fitted no point closely (costs 4.5 and 251 px^2): the variance pooled from them left
    # both tracks "not determined by the data", the page's first answer a warning.
    example = {"kind": "triangulation", "options": {"norm": "L2L2"}, "data": {
        "cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
                    [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]],
                    [[800, 0, 320, 0], [0, 800, 240, -800], [0.3, 0, 1, 0]]],
        "tracks": [{"views": [0, 1], "points": [[328.2, 247.9], [247.8, 248.1]]},
                   {"views": [0, 1, 2], "points": [[320.1, 259.8], [253.5, 260.2], [319.8, 193.4]]}]}}

    def parse(self, data: Any, items: range | None = None) -> ParsedTracks:
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
        chosen = items if items is not None else range(len(data["tracks"]))
        bulk = tracks_in_bulk(data["tracks"], chosen, len(cameras))
        if bulk is not None:
            for i, track in zip(chosen, bulk):
                tracks[i] = track
            return ParsedTracks(cameras, tracks)
        for i in chosen:  # some track fails a check: the first one is named
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
            tracks[i] = (list(views), pts)
        return ParsedTracks(cameras, tracks)

    def count(self, parsed: ParsedTracks) -> int:
        return len(parsed.tracks)

    def observations(self, parsed: ParsedTracks) -> int:
        return sum(len(track[1]) for track in parsed.tracks if track is not None)  # parsed items only

    def solve_item(self, parsed: ParsedTracks, index: int, options: TriangulationOptions, callback) -> dict:
        from geocert.solvers.fractional.triangulation import triangulate  # the conic solver, only to solve

        views, points = parsed.tracks[index]
        return self._document(parsed, views, points, triangulate(parsed.cameras[views], points, options, callback),
                              options)

    @staticmethod
    def _document(parsed: ParsedTracks, views, points, result: TrackResult, options: TriangulationOptions) -> dict:
        from geocert.core.determinacy import safely
        from geocert.formulations.fractional import determinacy
        from geocert.formulations.fractional.columns import certified_sublevel

        document = track_document(result, options.detail, options.certificate == "full")
        if options.detail == "full":  # brief: not computed
            document["determinacy"] = safely(determinacy.track, parsed.cameras[views], points, result.point,
                                             result.at_infinity, result.cost, determinacy.stated_lower_bound(result),
                                             certified_sublevel(result))
        return document

    def solve_batch(self, parsed: ParsedTracks, indices: list[int], options: TriangulationOptions, callback,
                    deadline: float | None = None) -> list[dict]:
        from geocert.formulations.fractional import determinacy
        from geocert.solvers.fractional.many_tracks import triangulate_many  # the conic solver, only to solve
        from geocert.formulations.fractional.convexity_path import raise_sublevels

        tracks = [parsed.tracks[index] for index in indices]
        not_started = None if deadline is None else (
            "not started: the job's time limit (options.job_time_limit_s, "
            f"{options.job_time_limit_s:g} s) passed before this track started")
        # A stop (the job's cancel) ends the batch where it is: its tracks not finished read cancelled.
        results = triangulate_many(parsed.cameras, tracks, options, callback, deadline=deadline, not_started=not_started,
                                   stop_ends_batch=True)
        projected = None
        if "full" in (options.detail, options.certificate):  # intervals proven at the level they are read at
            projected = determinacy.projected_tracks(parsed.cameras, tracks, results)
            pooled = determinacy.pooled_for(parsed.cameras, tracks, results, projected)
            if pooled is not None:
                raise_sublevels(parsed.cameras, tracks, results, pooled[0], options.norm)
        documents = track_documents(results, options.detail, options.certificate == "full")
        if options.detail == "full":  # the same documents as _document's, for the whole batch at once
            runs = determinacy.pool_runs(indices)
            for document, found in zip(documents, determinacy.tracks_many(parsed.cameras, tracks, results,
                                                                          projected)):
                if found is not None and determinacy.pooled_dof(found.get("level")) is not None:
                    found["pooled_tracks"] = runs  # whose residuals its level is pooled from (the verifier's)
                document["determinacy"] = found
        return documents

    def cancelled_item(self, options: Any) -> dict:
        return track_document(TrackResult("cancelled", False, reason="the job was cancelled before this track started"))

    def assemble(self, options: TriangulationOptions, items: list[dict], stats: dict) -> dict:
        return {"kind": self.name, "norm": options.norm, "tracks": items, "stats": stats}


KIND = TriangulationKind()
