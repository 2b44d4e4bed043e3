"""The reconstruction kind (issue 14): from tracks (matches, no cameras) or photos to a metric
reconstruction, stage by stage (geocert.pipelines.reconstruction.pipeline), with the certified
solvers where the thesis gives them: the metric upgrade (autocalibration, ch. 6-7), every
point (triangulation, ch. 5) and a bound for every camera (resection, ch. 5).

A job is one reconstruction, so one item. A full certificate's claims are the points: each a
triangulation in the metric cameras the result returns (the certificate's data are those
cameras and the observations each point kept), checked by ``geocert verify`` like any
triangulation; the cameras' bounds come with their own resection certificate
(``camera_certificate``), a document of the resection kind."""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import asdict
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, Field

from geocert.kinds.base import ProblemKind
from geocert.kinds.autocalibration import (KIND as AUTOCALIBRATION, IntrinsicsIn, image_side_refusal,
                                           known_K_within_limit, ranges_within_limit)
from geocert.kinds.documents import certificate_document
from geocert.kinds.resection_homography import RESECTION, map_document
from geocert.kinds.schema import CertificateDocument, Finite, JobBase, JobStats, Pixel, Strict, options_model
from geocert.kinds.triangulation import TrackOut, track_document
from geocert.formulations.autocalibration.problem import StageProgress
from geocert.formulations.reconstruction import run_control
from geocert.core.geometry import COORDINATE_LIMIT, NUMBER_TYPES, InputError, number_array
from geocert.pipelines.reconstruction.options import ReconstructionOptions
from geocert.verify.reconstruction import RECONSTRUCTION
from geocert.core.records import keep_declared
from geocert.verify.reconstruction_stages import IMAGES, STAGE_RECORDS

MAX_VIEWS = 1000
MAX_TRACKS = 200_000
MAX_OBSERVATIONS = 2_000_000
NUMBER_LISTS = frozenset((list,))  # JSON arrays, as parsed
Matrix3 = list[list[float]]
Size = Annotated[list[Finite], Field(min_length=2, max_length=2, description="[width, height] in pixels")]


class ReconstructionTrack(Strict):
    views: list[Annotated[int, Field(ge=0)]] = Field(min_length=2, description="view indices (into data.views)")
    points: list[Pixel] = Field(min_length=2, description="one observation per view, in the same order")


# A view's name: no control characters (a line break would end a record of an exported file).
NO_CONTROL_CHARACTERS = r"^[^\x00-\x1f\x7f]*$"
ViewName = Annotated[str, Field(max_length=200, pattern=NO_CONTROL_CHARACTERS)]


class ReconstructionView(Strict):
    name: ViewName | None = None
    image_size: Size


class ReconstructionImage(Strict):
    name: ViewName | None = None
    content: str = Field(description="base64 PNG or JPEG")


class ReconstructionData(Strict):
    tracks: list[ReconstructionTrack] | None = Field(None, description="matches across views (no cameras)")
    views: list[ReconstructionView] | None = Field(None, description="the views the tracks index, with their image sizes")
    images: list[ReconstructionImage] | None = Field(None, description="instead of tracks and views: the photos")


class KnownCalibration(Strict):
    K: Annotated[list[Annotated[list[Finite], Field(min_length=3, max_length=3)]], Field(min_length=3, max_length=3)]


ReconstructionOptionsIn = options_model(
    "ReconstructionOptionsIn", ReconstructionOptions,
    wire={"intrinsics": (Literal["unknown"] | KnownCalibration | IntrinsicsIn, IntrinsicsIn)})


class ReconstructionJob(JobBase):
    kind: Literal["reconstruction"]
    data: ReconstructionData
    options: ReconstructionOptionsIn = Field(default_factory=ReconstructionOptionsIn)


class ReconstructionCamera(BaseModel):
    view: int
    name: str | None
    registered: bool
    reason: str | None = Field(description="why the view is not registered (null when it is)")
    image_size: list[float] | None
    K: Matrix3 | None
    R: Matrix3 | None
    t: list[float] | None
    center: list[float] | None
    P: list[list[float]] | None = Field(description="3x4 pixels: K [R | t] (the projective camera when no metric "
                                                    "upgrade was found)")
    k1: float | None = Field(None, description="the radial distortion term the view's pixels were undistorted with "
                                               "(null: none): the photo shows a point at normalised coordinates n "
                                               "(of K [R | t]) at K's pixel of n (1 + k1 |n|^2) about "
                                               "distortion_centre; P, the points' observations and every "
                                               "certificate are about the undistorted pixels, so conditional on k1")
    distortion_centre: list[float] | None = Field(None, description="pixels: the centre of the radial term k1")
    cost: float | None = Field(description="the camera's reprojection cost on the returned points (the norm's)")
    lower_bound: float | None = Field(description="proven: no 3x4 camera putting those points in front costs less")
    gap: float | None
    optimal_cost: float | None = Field(description="the certified resection's own optimum")
    certified: bool = Field(description="the certified resection bounds this camera's fit to its own certified points: "
                                        "no 3x4 camera putting them in front costs less than lower_bound, and this one "
                                        "costs within its tolerance of it. It says the camera agrees with its points, "
                                        "not that its pose is right in a rig that might be wrong as a whole "
                                        "(pose_determined and summary.warnings say that)")
    pose_determined: bool | None = Field(None, description="false when the depth-reversed twin of the returned rig "
                                                           "(a long lens sees nearly affinely) fits the observations "
                                                           "about as well: this pose is then one of two the data "
                                                           "cannot tell apart, certified or not; null when not checked "
                                                           "(summary.depth_reversal)")
    mirror_rotation_deg: float | None = Field(None, description="by how much the depth-reversed twin's rotation of "
                                                                "this camera relative to the reference view differs "
                                                                "from the returned one, degrees: the twin as "
                                                                "constructed from the returned cameras, before its "
                                                                "adjustment (the verifier recomputes it)")
    status: str
    bound_reason: str | None = Field(None, description="why the camera has no bound or is not certified (not "
                                                       "searched, not certified by the search, a point behind it, "
                                                       "a gap beyond the tolerance, cancelled); null when certified")
    points: int = Field(description="points the resection used")
    set_aside: int | None = Field(None, description="observations of certified points set aside as outliers before "
                                                    "its bound (missed by more than 8 noise scales, at most 5% of "
                                                    "them; camera_claim.outliers, recomputed by the verifier): points "
                                                    "counts those kept; 0 when judged on all; null when not judged")
    degrees_of_freedom: int | None = Field(None, description="the returned camera's own: its pose (6) plus each "
                                                             "intrinsic the registered cameras do not share")
    tolerance: float | None = Field(None, description="certified means cost <= (1 + tolerance) lower_bound + abs_gap: "
                                                      "(1 + chi2_0.999(11 - degrees_of_freedom) / (k (2 points - 11))) "
                                                      "/ (1 - camera_rel_gap) - 1, k 1 for L2L2 and 2 for the L1 "
                                                      "norms (what its fewer degrees of freedom than a 3x4 camera's "
                                                      "cost); null when too few points allow none")
    searched: bool = Field(False, description="the certified resection ran for this camera: with certificate "
                                              "\"full\", its map is in camera_certificate (one per searched camera, "
                                              "in view order); a camera not searched claims no bound")
    free_camera: list[list[float]] | None = Field(
        None, description="the 3x4 camera, all 12 entries free, found locally from this one, that beats it on its "
                          "points by more than its tolerance (every point in front of it): why a camera not searched "
                          "is not certified when its own figures do not say so (no bound, at most this camera's "
                          "cost, can certify it; the verifier recomputes both costs); null otherwise")


class ReconstructionPoint(TrackOut):
    track: int = Field(description="index into data.tracks")
    observations: list[tuple[int, float, float]] = Field(
        description="[[view, u, v], ...] the observations the point was solved from (view: an index into data.views)")


class ReconstructionResult(BaseModel):
    kind: Literal["reconstruction"]
    norm: str
    cameras: list[ReconstructionCamera]
    points: list[ReconstructionPoint]
    stages: list[dict[str, Any]]
    summary: dict[str, Any]
    images: dict[str, Any] | None = Field(None, description="stage 1's figures when photos were given")
    stats: JobStats
    certificate: CertificateDocument | None = Field(None, description='with options.certificate = "full": the points')
    camera_certificate: CertificateDocument | None = Field(
        None, description='with options.certificate = "full": the cameras\' bounds, a resection certificate')
    calibration_certificate: CertificateDocument | None = Field(
        None, description='with options.certificate = "full" and a certified K: the stratified autocalibration '
                          "certificate proving summary.calibration.certified_K optimal for the projective "
                          "reconstruction in its data")


class Parsed:
    def __init__(self, tracks, image_sizes, names, images_stats=None):
        self.tracks, self.image_sizes, self.names, self.images_stats = tracks, image_sizes, names, images_stats


def _example_data() -> dict:
    """A small scene (6 views, 24 points, f = 800 px, pixels rounded to 1e-6: synthetic.scene seed 3)."""
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=6, points=24, seed=3)
    return {"views": [{"name": f"view{v}", "image_size": list(scene.image_size)} for v in range(6)],
            "tracks": [{"views": [int(v) for v in views], "points": [[round(float(u), 6), round(float(w), 6)]
                                                                     for u, w in pixels]}
                       for views, pixels in scene.tracks]}


def _read_views(data: dict) -> tuple[list, list]:
    views = data.get("views")
    if not isinstance(views, list) or not views:
        raise InputError("data/views", "must be a non-empty list of {name, image_size}")
    if len(views) > MAX_VIEWS:
        raise InputError("data/views", f"{len(views)} views exceed the limit of {MAX_VIEWS}")
    sizes, names = [], []
    for i, view in enumerate(views):
        if not isinstance(view, dict) or "image_size" not in view:
            raise InputError(f"data/views/{i}", "must be an object with image_size [width, height]")
        size = number_array(view["image_size"], f"data/views/{i}/image_size", "[width, height]", 1, COORDINATE_LIMIT)
        if size.shape != (2,) or not np.all(size > 0):
            raise InputError(f"data/views/{i}/image_size", "must be [width, height], both positive")
        image_side_refusal(size, f"data/views/{i}/image_size")
        name = view.get("name")
        if name is not None and not isinstance(name, str):
            raise InputError(f"data/views/{i}/name", "must be a string")
        sizes.append((float(size[0]), float(size[1])))
        names.append(name)
    return sizes, names


def _tracks_in_bulk(tracks: list, n_views: int) -> list | None:
    """The tracks as ``_read_tracks`` returns them, checked all at once (a few flat passes in C
    over every observation), or None when anything is amiss or unusual: the track-by-track
    check then names the first offending field. Track by track, each observation's row took some
    microseconds of Python, the API's largest part of a large reconstruction's submission."""
    if not all(type(track) is dict and "views" in track and "points" in track for track in tracks):
        return None
    views, points = [track["views"] for track in tracks], [track["points"] for track in tracks]
    if not (NUMBER_LISTS.issuperset(map(type, views)) and NUMBER_LISTS.issuperset(map(type, points))):
        return None
    lengths = np.fromiter(map(len, views), dtype=np.int64, count=len(views))
    if int(lengths.sum()) > MAX_OBSERVATIONS or lengths.min() < 2 \
            or not np.array_equal(lengths, np.fromiter(map(len, points), dtype=np.int64, count=len(points))):
        return None
    flat_views = list(itertools.chain.from_iterable(views))
    rows = list(itertools.chain.from_iterable(points))
    if set(map(type, flat_views)) != {int} or not NUMBER_LISTS.issuperset(map(type, rows)) \
            or set(map(len, rows)) != {2}:
        return None
    entries = list(itertools.chain.from_iterable(rows))
    if not NUMBER_TYPES.issuperset(map(type, entries)):
        return None
    try:
        view = np.array(flat_views, dtype=np.int64)
        pixel = np.array(entries, dtype=float).reshape(-1, 2)
    except (OverflowError, ValueError):
        return None
    if not (np.all((view >= 0) & (view < n_views)) and np.isfinite(pixel).all()
            and (np.abs(pixel) <= COORDINATE_LIMIT).all()):
        return None
    track = np.repeat(np.arange(len(views)), lengths)
    order = np.lexsort((view, track))
    if np.any((np.diff(track[order]) == 0) & (np.diff(view[order]) == 0)):  # a view twice in a track
        return None
    if len(np.unique(view)) < 2:
        return None
    cuts = np.cumsum(lengths)[:-1]
    return list(zip(np.split(view.astype(int), cuts), np.split(pixel, cuts)))


def _read_tracks(data: dict, n_views: int) -> list:
    tracks = data.get("tracks")
    if not isinstance(tracks, list) or not tracks:
        raise InputError("data/tracks", "must be a non-empty list of {views, points}")
    if len(tracks) > MAX_TRACKS:
        raise InputError("data/tracks", f"{len(tracks)} tracks exceed the limit of {MAX_TRACKS}")
    bulk = _tracks_in_bulk(tracks, n_views)
    if bulk is not None:
        return bulk
    out, total = [], 0
    for i, track in enumerate(tracks):
        where = f"data/tracks/{i}"
        if not isinstance(track, dict) or "views" not in track or "points" not in track:
            raise InputError(where, "must be an object with 'views' and 'points'")
        views = track["views"]
        if not isinstance(views, list) or not all(type(v) is int for v in views):
            raise InputError(f"{where}/views", "must be a list of view indices")
        for j, v in enumerate(views):
            if not 0 <= v < n_views:
                raise InputError(f"{where}/views/{j}", f"view {v} is not one of data/views (0..{n_views - 1})")
        if len(views) < 2:
            raise InputError(f"{where}/views", "a track needs at least 2 views")
        if len(set(views)) != len(views):
            raise InputError(f"{where}/views", "a view appears twice in the track")
        points = number_array(track["points"], f"{where}/points", "a list of [u, v] pairs", 2, COORDINATE_LIMIT)
        if points.shape != (len(views), 2):
            raise InputError(where, f"has {len(views)} views but points of shape {list(points.shape)} "
                                    "(one [u, v] per view)")
        total += len(views)
        if total > MAX_OBSERVATIONS:
            raise InputError("data/tracks", f"more than {MAX_OBSERVATIONS} observations")
        out.append((np.array(views, dtype=int), points))
    seen = {int(v) for views, _ in out for v in views}
    if len(seen) < 2:
        raise InputError("data/tracks", f"fewer than 2 views have matches ({len(seen)})")
    return out


def _read_images(data: dict):
    """The photos' sizes from their headers, and their bytes (decoded into pixels only when the
    reconstruction runs: ``_decode``), refused as ``features.image_header`` refuses."""
    try:  # stage 1 (features.py): matches from photos
        from geocert.pipelines.reconstruction import features
    except ImportError as exc:  # pragma: no cover - until the features module is merged
        raise InputError("data/images", "photos are not read by this build: give tracks and views") from exc
    images = data["images"]
    if not isinstance(images, list) or len(images) < 2:
        raise InputError("data/images", "must be a list of at least 2 {name, content} objects")
    if len(images) > MAX_VIEWS:
        raise InputError("data/images", f"{len(images)} images exceed the limit of {MAX_VIEWS}")
    sizes, names = [], []
    for i, image in enumerate(images):
        if not isinstance(image, dict) or not isinstance(image.get("content"), str):
            raise InputError(f"data/images/{i}", "must be an object with content (base64 PNG or JPEG)")
        w, h, _ = features.image_header(image["content"], f"data/images/{i}/content")
        sizes.append((float(w), float(h)))
        names.append(image.get("name"))
    return sizes, names


def _decode(images: list) -> list:
    from geocert.pipelines.reconstruction import features

    return [features.decode_image(image["content"], f"data/images/{i}/content") for i, image in enumerate(images)]


def request_figures(data: dict) -> dict:
    """What the job asks of the service, from its request alone (its photos' headers): views (or
    photos), and the photos' pixels in all and of the largest."""
    if data.get("images") is not None:
        sizes, _ = _read_images(data)
        pixels = [int(w) * int(h) for w, h in sizes]
        return {"reconstruction_views": (len(sizes), "data/images"),
                "image_pixels": (sum(pixels), "data/images"),
                "largest_image_pixels": (max(pixels), f"data/images/{pixels.index(max(pixels))}/content")}
    views = data.get("views")
    return {"reconstruction_views": (len(views) if isinstance(views, list) else 0, "data/views")}


def _exif_focal_prior(images: list[dict], sizes: list[tuple[float, float]]) -> dict | None:
    """The photos' EXIF focal lengths (pixels, from the 35 mm equivalent) and their median, when
    every photo states one, they agree within 1% (one camera and zoom) and the median is a prior
    the options may state (at most run_control.FOCAL_PRIOR_LIMIT: a larger one, from a tag near
    its 9,999 mm cap on a very wide photo, would make a document the verifier's option check
    refuses); else None."""
    import base64

    from geocert.pipelines.reconstruction import features

    found = []
    for image, (width, height) in zip(images, sizes):
        text = image["content"].strip()
        text = text.partition(",")[2] if text.startswith("data:") else text
        try:
            data = base64.b64decode("".join(text.split()), validate=True)
        except ValueError:
            return None
        focal = features.exif_focal_px(data, (int(width), int(height)))
        if focal is None:
            return None
        found.append(focal)
    median = float(np.median(found))
    if not found or max(abs(f / median - 1) for f in found) > 0.01 or not median <= run_control.FOCAL_PRIOR_LIMIT:
        return None
    return {"focal_px": median, "images": len(found)}


class ReconstructionKind(ProblemKind):
    name = "reconstruction"
    description = ("From matches (tracks across views, no cameras) or photos to a metric reconstruction: a "
                   "projective reconstruction, the certified metric upgrade (autocalibration), a metric bundle "
                   "adjustment, then every point triangulated and every camera bounded by the certified solvers.")
    item_key = "points"  # the certificate's claims; a job is one reconstruction
    chunk_size = 1
    options_type = ReconstructionOptions
    request_model = ReconstructionJob
    result_model = ReconstructionResult
    solution_fields = ("point", "at_infinity")
    verification = RECONSTRUCTION  # points as triangulations in the cameras stated; the returned cameras checked
    example = {"kind": "reconstruction", "options": {}, "data": _example_data()}
    request_figures = staticmethod(request_figures)

    def parse(self, data: Any, items: range | None = None) -> Parsed:
        if not isinstance(data, dict):
            raise InputError("data", "must be an object with 'tracks' and 'views', or 'images'")
        for key in data:
            if key not in ("tracks", "views", "images"):
                raise InputError(f"data/{key}", "unknown field (known: tracks, views, images)")
        if data.get("images") is not None:
            if data.get("tracks") is not None:
                raise InputError("data/images", "give images, or tracks and views, not both")
            sizes, names = _read_images(data)
            return Parsed(None, sizes, names, {"images": data["images"],
                                               "exif_focal": _exif_focal_prior(data["images"], sizes)})
        if "tracks" not in data:
            raise InputError("data/tracks", "is required (or data/images)")
        sizes, names = _read_views(data) if "views" in data else (None, None)
        if sizes is None:
            raise InputError("data/views", "is required with tracks: [{name, image_size}, ...] per view")
        return Parsed(_read_tracks(data, len(sizes)), sizes, names)

    def check_options(self, parsed: Parsed, options: ReconstructionOptions) -> None:
        ranges = options.intrinsics if isinstance(options.intrinsics, dict) else {}
        if "K" not in ranges:
            ranges_within_limit(None, ranges)  # beyond it the job failed with LinAlgError
        else:
            known_K_within_limit(ranges["K"])
        complete = "K" in ranges or all(name in ranges for name in ("focal", "aspect", "skew", "principal_point"))
        if not complete and options.camera_model != "varying":
            first = parsed.image_sizes[0]
            for i, size in enumerate(parsed.image_sizes):
                if size != first:
                    raise InputError(f"data/views/{i}/image_size", f"{list(size)} differs from view 0's {list(first)}: "
                                     "images of different sizes claimed as one camera (give options.intrinsics "
                                     "ranges, or camera_model \"varying\")")

    def time_bound_s(self, parsed: Parsed, options: ReconstructionOptions) -> float:
        """Its limits, whatever its size: the features' time limit (photos), two autocalibration
        stages, structure_time_limit_s for the points and cameras together, and time_limit_s for
        each of the last point and camera searches started before it. It is also the job's clock
        in all (solve_item): the registration and the adjustments, which have no limit of their
        own, stop at it between iterations, as every later stage does."""
        matching = options.feature_options().time_limit_s if parsed.tracks is None else 0.0
        return matching + 2 * options.autocalibration_time_limit_s + options.structure_time_limit_s \
            + 2 * options.time_limit_s

    def count(self, parsed: Parsed) -> int:
        return 1

    def observations(self, parsed: Parsed) -> int:
        return sum(len(v) for v, _ in parsed.tracks) if parsed.tracks is not None else len(parsed.image_sizes)

    def solve_item(self, parsed: Parsed, index: int, options: ReconstructionOptions, callback) -> dict:
        from geocert.pipelines.reconstruction import pipeline

        start = time.perf_counter()
        limit_s = self.time_bound_s(parsed, options)
        clock = {"passed": False}  # the job's time limit in all passed: the run stops where it is

        def report(stage: str, done: int, total: int, progress=None) -> bool:
            if time.perf_counter() - start > limit_s:
                clock["passed"] = True
                return True
            if callback is None:
                return False
            label = f"{stage} {done}/{total}" if total > 1 else stage
            if progress is not None:
                return bool(callback(StageProgress(**{**progress.__dict__, "stage": label})))
            return bool(callback(StageProgress(0, 0, -math.inf, math.inf, math.inf, math.inf,
                                               time.perf_counter() - start, stage=label)))

        images_document = matches = out = None
        tracks = parsed.tracks
        if tracks is None:  # photos: stage 1
            from geocert.pipelines.reconstruction import features

            def matching(progress: dict) -> bool:
                return report("matches", progress.get("done", 0), progress.get("total", 1))

            began, cpu = time.perf_counter(), time.process_time()
            found = features.tracks_from_images(_decode(parsed.images_stats["images"]), options.feature_options(),
                                                matching)
            tracks = [(np.asarray(v, dtype=int), np.asarray(p, dtype=float)) for v, p in found.tracks]
            images_document = _jsonable(dict(found.stats))
            matches = {"name": "matches", **images_document, "status": "done", "reason": None,
                       "elapsed_s": time.perf_counter() - began,
                       "cpu_s": time.process_time() - cpu}  # this process's CPU time, as the other stages'
            matched = len({int(v) for views, _ in tracks for v in views})
            if found.status == "time_limit":
                matches.update(status="time_limit", reason="time_limit: " + found.stats["stopped"])
            if found.status == "cancelled":
                matches.update(status="cancelled", reason="the job was cancelled")
                out = pipeline.not_reconstructed(len(parsed.image_sizes), "cancelled", "the job was cancelled",
                                                 "the job was cancelled before the views were matched", parsed.names)
            elif matched < 2:
                # As a projective stage that fails (pipeline._run): the job succeeds with a
                # result whose failed stage says why, the later stages skipped, the summary filled.
                reason = f"fewer than 2 images have verified matches ({matched})"
                if found.status == "time_limit":
                    reason += "; " + matches["reason"]
                matches.update(status="failed", reason=reason)
                out = pipeline.not_reconstructed(len(parsed.image_sizes), "skipped", "the matches stage failed: "
                                                 + reason, "no verified matches with another image", parsed.names)
        if out is None:
            exif = (parsed.images_stats or {}).get("exif_focal")
            if exif is not None and options.focal_prior_px is None and options.known_K() is None:
                from dataclasses import replace

                options = replace(options, focal_prior_px=exif["focal_px"])  # a prior the adjustment refines
                images_document["focal_prior_from_exif"] = exif
            out = pipeline.reconstruct(tracks, parsed.image_sizes, options, report, parsed.names)
        if clock["passed"]:
            _stopped_by_clock(out, limit_s)
        calibration_proof = self._calibration_proof(out, options)
        cameras = [self._camera(camera, parsed) for camera in out.cameras]
        points = [{"track": p.track, **track_document(p.result), "observations": p.observations} for p in out.points]
        for point in points:
            point["determinacy"] = None
        # each stage as the verifier reads it (stage_checks.STAGE_RECORDS: what it declares)
        stages = [keep_declared(_jsonable(stage), STAGE_RECORDS) for stage in out.stages]
        if matches is not None:
            stages.insert(0, keep_declared(_jsonable(matches), STAGE_RECORDS))
            # the matches stage first, as in stages
            out.summary["time_s"] = {"matches": matches["elapsed_s"], **out.summary["time_s"]}
            out.summary["cpu_s"] = {"matches": matches["cpu_s"], **out.summary["cpu_s"]}
        camera_maps = {c.view: c.bound for c in out.cameras if c.bound is not None and c.bound.result is not None}
        return {"calibration_proof": calibration_proof, "cameras": cameras, "points": points, "stages": stages, "summary": _jsonable(out.summary),
                "images": keep_declared(images_document, IMAGES), "camera_results": self._camera_items(out, options, camera_maps),
                # A cancelled run keeps what it did (pipeline.reconstruct); the item says it was
                # stopped, so the job ends "cancelled" (workers.tasks._end), not "succeeded".
                "status": "cancelled" if out.cancelled else "time_limit" if clock["passed"] else (
                    "optimal" if all(p["certified"] for p in points) and points else "not_certified"),
                "certified": bool(points) and all(p["certified"] for p in points),
                "nodes": sum(p["nodes"] for p in points), "elapsed_s": time.perf_counter() - start,
                "cost": None, "lower_bound": None}

    @staticmethod
    def _calibration_proof(out, options: ReconstructionOptions) -> dict | None:
        """What the certified K's certificate is made of, as the autocalibration kind states it:
        the data, options and item of the pipeline's stratified solve (plain JSON: an item may be
        stored between solve and assembly), when the result claims a certified K and a full
        certificate is asked for. The stages' determinacy analyses are not run (a deadline already
        past): the certificate does not carry them, and the pipeline's own stage states its own."""
        proven, claim = out.proven, out.summary.get("calibration") or {}
        if options.certificate != "full" or proven is None or not claim.get("certified"):
            return None
        from geocert.kinds.autocalibration import Parsed as Projective, stratified_item

        data = {"cameras": proven.cameras.tolist(), "points": proven.points.tolist(),
                "image_size": None if proven.image_size is None else list(proven.image_size)}
        item = stratified_item(Projective(proven.cameras, proven.points, proven.image_size), proven.options,
                               proven.problem, proven.result, True, deadline=-math.inf)
        # The stage's figures are the certificate's claims (costs at the solution as returned)
        for stated, claimed in zip(out.stages[1].get("stages") or [], item["stages"]):
            stated.update({name: claimed[name] for name in ("cost", "lower_bound", "gap", "status", "certified")})
        return _jsonable({"data": data, "options": asdict(proven.options), "item": item})

    @staticmethod
    def _camera(camera, parsed: Parsed) -> dict:
        b = camera.bound
        lst = (lambda a: None if a is None else np.asarray(a, dtype=float).tolist())
        return {"view": camera.view, "name": parsed.names[camera.view] if parsed.names else None,
                "registered": camera.registered, "reason": camera.reason,
                "image_size": list(parsed.image_sizes[camera.view]), "K": lst(camera.K), "R": lst(camera.R),
                "t": lst(camera.t), "center": lst(camera.center), "P": lst(camera.P),
                "k1": camera.k1, "distortion_centre": camera.distortion_centre,
                "cost": None if b is None else b.cost, "lower_bound": None if b is None else b.lower_bound,
                "gap": None if b is None else b.gap, "optimal_cost": None if b is None else b.optimal_cost,
                "certified": bool(b is not None and b.certified), "status": "not_run" if b is None else b.status,
                "pose_determined": camera.pose_determined, "mirror_rotation_deg": camera.mirror_rotation_deg,
                "bound_reason": None if b is None else b.reason,
                "points": 0 if b is None else b.points, "searched": bool(b is not None and b.result is not None),
                "degrees_of_freedom": None if b is None else b.dof, "tolerance": None if b is None else b.tolerance,
                "set_aside": None if b is None else b.set_aside,
                "free_camera": None if b is None else lst(b.free_camera)}

    @staticmethod
    def _camera_items(out, options, bounds: dict) -> list[dict]:
        """Each camera's resection as a resection item (with its data), for the camera certificate."""
        from geocert.pipelines.reconstruction.pipeline import point_entries
        from geocert.formulations.reconstruction.camera_claim import kept, sources

        views = sorted(bounds)
        found = [kept(source, target, out.cameras[view].P, bounds[view].set_aside)
                 for view, (source, target) in zip(views, sources(point_entries(out.points), views))]
        return [{"view": view, "map": {"source": source, "target": target}, **map_document(bounds[view].result)}
                for view, (source, target) in zip(views, found)]

    def cancelled_item(self, options: Any) -> dict:
        return {"cameras": [], "points": [], "summary": {}, "images": None, "camera_results": [],
                "stages": [{"name": "projective", "status": "cancelled", "reason": "the job was cancelled"}],
                "status": "cancelled", "certified": False, "nodes": 0, "elapsed_s": 0.0, "cost": None,
                "lower_bound": None}

    def claimed_items(self, items: list[dict]) -> list[dict]:
        return items[0]["points"]

    def certificate_data(self, data: Any, items: list[dict]) -> dict:
        """The data the points' claims are about: the metric cameras returned (registered views,
        in view order) and each point's kept observations as a triangulation track; and the
        input's labels (every view's name and image size, each point's input track number),
        hashed with them, which the verifier ties the result's labels to."""
        item = items[0]
        views = [c["view"] for c in item["cameras"] if c["P"] is not None and c["K"] is not None]
        index = {v: k for k, v in enumerate(views)}
        cameras = [item["cameras"][v]["P"] for v in views]
        tracks = [{"views": [index[int(o[0])] for o in p["observations"]], "points": [[o[1], o[2]]
                                                                                     for o in p["observations"]]}
                  for p in item["points"]]
        labels = {"view_names": [c["name"] for c in item["cameras"]],
                  "image_sizes": [list(c["image_size"]) for c in item["cameras"]],
                  "track_numbers": [p["track"] for p in item["points"]]}
        return {"cameras": cameras, "views": views, "tracks": tracks, "input_labels": labels}

    def assemble(self, options: ReconstructionOptions, items: list[dict], stats: dict) -> dict:
        item = dict(items[0])
        camera_results = item.pop("camera_results", [])
        calibration_proof = item.pop("calibration_proof", None)
        for key in ("status", "certified", "nodes", "elapsed_s", "cost", "lower_bound"):
            item.pop(key, None)
        result = {"kind": self.name, "norm": options.norm, **item, "stats": stats}
        if options.certificate == "full" and camera_results:
            from geocert.formulations.fractional.options import MapOptions

            maps = [entry.pop("map") for entry in camera_results]
            for entry in camera_results:
                entry.pop("view", None)
            map_options = MapOptions(norm=options.norm, rel_gap=options.camera_rel_gap, abs_gap=options.abs_gap,
                                     max_nodes=options.max_nodes, time_limit_s=options.time_limit_s,
                                     max_residual=options.max_residual, certificate="full")
            result["camera_certificate"] = certificate_document(RESECTION, {"maps": maps}, map_options, camera_results)
        if options.certificate == "full" and calibration_proof is not None:
            result["calibration_certificate"] = certificate_document(
                AUTOCALIBRATION, calibration_proof["data"], AUTOCALIBRATION.options_type(**calibration_proof["options"]),
                [calibration_proof["item"]])
        return result


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    return value


KIND = ReconstructionKind()


def _stopped_by_clock(out, limit_s: float) -> None:
    """A run the job's time limit in all stopped (the pipeline saw it as a cancel): what it
    finished is kept, and every stage, point or camera it stopped says ``time_limit``, not
    ``cancelled`` (the job was not cancelled: it ends succeeded, its item time_limit)."""
    passed = (f"time_limit: the job's time limit in all ({limit_s:g} s: its matching, two autocalibration stages, "
              "structure_time_limit_s and two time_limit_s) passed")
    for stage in out.stages:
        if stage.get("status") == "cancelled":
            kept = (stage.get("reason") or "").partition(": ")[2]  # what the stage kept, as a cancel says it
            stage.update(status="time_limit", reason=passed + (f": {kept}" if kept else ""))
    for point in out.points:
        if point.result.status == "cancelled":
            point.result.status, point.result.reason = "time_limit", passed
    for camera in out.cameras:
        bound = camera.bound
        if bound is not None and bound.status == "cancelled":
            bound.status, bound.reason = "time_limit", passed
        if bound is not None and bound.result is not None and bound.result.status == "cancelled":
            bound.result.status, bound.result.reason = "time_limit", passed
    out.cancelled = False
    stopped = next((stage["name"] for stage in out.stages if stage.get("status") == "time_limit"), None)
    warnings = out.summary.setdefault("warnings", [])
    for warning in warnings:
        if warning.get("code") == "no_metric_upgrade":  # not "none was found": none was sought
            warning["detail"] = warning["detail"].replace("no metric reconstruction was found",
                                                          "the time limit passed before a metric reconstruction")
    # first: the run did not finish, whatever else the result says
    warnings.insert(0, {"code": "time_limit", "detail": (
        f"the job's time limit in all ({limit_s:g} s) passed during the {stopped or 'last'} stage: what was "
        "finished before it is returned, and each stage after it says it was not run. Send the job again with "
        "larger limits (options.structure_time_limit_s, autocalibration_time_limit_s, features.time_limit_s) or "
        "fewer photos")})

