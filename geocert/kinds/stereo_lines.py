"""The stereo_lines kind: the motion of a calibrated stereo rig from lines (thesis chapter 9).

Items are frame pairs (frames k and k + 1): each is solved on its own (matching included), so a
long sequence is split across workers like any batch, and a robot's one-pair job is one item; the
trajectory is composed from the pairs when the result is assembled. Results are estimates
(RANSAC around an algebraic solver): every item says ``"status": "estimate"`` (or ``"failed"``
with the reason) and ``certified: false``; this kind issues no certificate, and the verifier says
so rather than checking anything.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, Field

from geocert.kinds.base import ProblemKind
from geocert.kinds.schema import Determinacy, Finite, JobBase, JobStats, Strict, options_model
from geocert.core.bnb import Progress
from geocert.core.determinacy import safely
from geocert.core.geometry import COORDINATE_LIMIT, InputError, number_array
from geocert.verify.adapters import NOT_CERTIFIED, VERIFIED_KINDS
from geocert.solvers.lines.geometry import Rig
from geocert.solvers.lines.pipeline import SOLVERS, StereoLinesOptions, compose, estimate_pair

Segment = Annotated[list[Finite], Field(min_length=4, max_length=4, description="[x0, y0, x1, y1] pixels")]
Row3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
Matrix3 = Annotated[list[Row3], Field(min_length=3, max_length=3)]
Quad = Annotated[list[Segment], Field(min_length=4, max_length=4,
                                      description="one line's segments: left k, right k, left k+1, right k+1")]


class RigIn(Strict):
    K_left: Matrix3 = Field(description="left intrinsics (pixels)")
    K_right: Matrix3 = Field(description="right intrinsics (pixels)")
    R: Matrix3 = Field(description="rotation of the right camera: right = K_right [R | t] in the left frame")
    t: Row3 = Field(description="translation of the right camera (the baseline's units: the motion's)")


class FrameIn(Strict):
    left: list[Segment] = Field(description="segments detected in the left image")
    right: list[Segment] = Field(description="segments detected in the right image")


class StereoLinesData(Strict):
    rig: RigIn
    frames: list[FrameIn] | None = Field(None, min_length=2, description="segments per frame: matched here "
                                                                          "(left-right, then frame to frame)")
    matches: list[Annotated[list[Quad], Field(min_length=1)]] | None = Field(
        None, min_length=1, description="or, per consecutive frame pair, the lines matched across its four views")


StereoLinesOptionsIn = options_model("StereoLinesOptionsIn", StereoLinesOptions)


class StereoLinesJob(JobBase):
    kind: Literal["stereo_lines"]
    data: StereoLinesData
    options: StereoLinesOptionsIn = Field(default_factory=StereoLinesOptionsIn)


class PairOut(BaseModel):
    frames: list[int] = Field(description="[k, k + 1]")
    status: Literal["estimate", "failed", "cancelled"]
    certified: Literal[False] = Field(description="always false: an estimate, not a certified optimum")
    R: list[list[float]] | None = Field(description="X_{k+1} = R X_k + t (left camera coordinates)")
    t: list[float] | None
    inliers: list[int] = Field(description="indices into this pair's lines (matches, or the given matches)")
    inlier_ratio: float
    lines: int = Field(description="lines seen in the four views")
    matches: list[list[int]] | None = Field(description="from segments: per line [left k, right k, left k+1, "
                                                        "right k+1] segment indices")
    degenerate: list[int] = Field(description="lines the stereo pair does not fix (in or near an epipolar plane)")
    solver: str
    iterations: int = Field(description="RANSAC samples drawn")
    time_ms: float = Field(description="matching, RANSAC and refinement of this pair")
    rms_px: float | None = Field(description="RMS reprojection distance of the inliers' endpoints (pixels)")
    refined: bool
    translation_determined: bool | None = Field(
        None, description="whether the inlier lines fix t to within 10% of its length (its determinacy intervals, 3 "
                          "standard errors); false: the reason says how far they leave it open (null: no estimate)")
    reason: str | None
    nodes: int = 0
    elapsed_s: float
    cost: None = None
    lower_bound: None = None
    determinacy: Determinacy | None = Field(None, description="how well the inlier lines fix the motion "
                                                              "(estimated from the refinement's curvature)")


class PoseOut(BaseModel):
    R: list[list[float]]
    t: list[float] = Field(description="X_k = R X_0 + t")
    center: list[float] = Field(description="the left camera's centre in frame 0's coordinates")


class StereoLinesResult(BaseModel):
    kind: Literal["stereo_lines"]
    status: Literal["estimate"] = Field(description="estimates, never certified")
    solver: str
    pairs: list[PairOut]
    trajectory: list[PoseOut | None] = Field(description="one pose per frame (frame 0: the identity); null after "
                                                         "a pair without a motion")
    stats: JobStats


@dataclass
class ParsedLines:
    rig: Rig
    frames: list[dict] | None
    matches: list[np.ndarray] | None

    @property
    def pairs(self) -> int:
        return len(self.frames) - 1 if self.frames is not None else len(self.matches)


def _matrix(value: Any, field: str) -> np.ndarray:
    array = number_array(value, field, "a 3x3 matrix (3 rows of 3 numbers)", 2, COORDINATE_LIMIT)
    if array.shape != (3, 3):
        raise InputError(field, "must be a 3x3 matrix (3 rows of 3 numbers)")
    return array


def read_rig(value: Any) -> Rig:
    if not isinstance(value, dict):
        raise InputError("data/rig", "must be an object with K_left, K_right, R and t")
    for key in ("K_left", "K_right", "R", "t"):
        if key not in value:
            raise InputError(f"data/rig/{key}", "is required")
    for key in value:
        if key not in ("K_left", "K_right", "R", "t"):
            raise InputError(f"data/rig/{key}", "unknown member (known: K_left, K_right, R, t)")
    Ks = []
    for key in ("K_left", "K_right"):
        K = _matrix(value[key], f"data/rig/{key}")
        # Singular relative to its own columns (|det| over their lengths' product, Hadamard: 1
        # for orthogonal ones), so that focal lengths in any unit are intrinsics.
        columns = float(np.prod(np.linalg.norm(K / max(np.abs(K).max(), 1e-300), axis=0)))
        if not abs(np.linalg.det(K / max(np.abs(K).max(), 1e-300))) > 1e-12 * columns:
            raise InputError(f"data/rig/{key}", "is singular: not an intrinsics matrix")
        Ks.append(K)
    R = _matrix(value["R"], "data/rig/R")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise InputError("data/rig/R", "is not a rotation (R^T R = I within 1e-6 and det R = +1)")
    t = number_array(value["t"], "data/rig/t", "a list of 3 numbers", 1, COORDINATE_LIMIT)
    if t.shape != (3,):
        raise InputError("data/rig/t", "must be a list of 3 numbers")
    if not np.abs(t).max() > 0:  # not its norm: the squares of a baseline of 1e-300 underflow
        raise InputError("data/rig/t", "is zero: a stereo rig needs a baseline")
    return Rig(Ks[0], Ks[1], R, t)


def _segments(value: Any, field: str, allow_empty: bool = True) -> np.ndarray:
    array = number_array(value, field, "a list of segments [x0, y0, x1, y1]", 2, COORDINATE_LIMIT)
    if array.size == 0:
        if not allow_empty:
            raise InputError(field, "must not be empty")
        return np.zeros((0, 4))
    if array.ndim != 2 or array.shape[1] != 4:
        raise InputError(field, "must be a list of segments [x0, y0, x1, y1]")
    length = np.hypot(array[:, 2] - array[:, 0], array[:, 3] - array[:, 1])
    short = np.flatnonzero(~(length > 1e-9 * (1 + np.abs(array).max(axis=1))))
    if len(short):
        raise InputError(f"{field}/{int(short[0])}", "is a segment of zero length (its endpoints coincide)")
    return array


class StereoLinesKind(ProblemKind):
    name = "stereo_lines"
    description = ("Stereo line structure and motion (thesis ch. 9): the motion of a calibrated stereo rig between "
                   "frames from lines; estimates (RANSAC), never certified.")
    item_key = "pairs"  # frame pairs: frames k, k + 1 (data: frames, or matches per pair)
    chunk_size = 20
    options_type = StereoLinesOptions
    request_model = StereoLinesJob
    result_model = StereoLinesResult
    solution_fields = ("R", "t")
    certifies = False  # estimates only: no certificate, nothing for the verifier to check
    verification = VERIFIED_KINDS["stereo_lines"].verification  # refuses any certificate, saying why
    example: dict = {}  # set below (a synthetic scene)

    def parse(self, data: Any, items: range | None = None) -> ParsedLines:
        if not isinstance(data, dict):
            raise InputError("data", "must be an object with 'rig' and 'frames' (or 'matches')")
        for key in data:
            if key not in ("rig", "frames", "matches"):
                raise InputError(f"data/{key}", "unknown member (known: rig, frames, matches)")
        if "rig" not in data:
            raise InputError("data/rig", "is required")
        rig = read_rig(data["rig"])
        has_frames, has_matches = data.get("frames") is not None, data.get("matches") is not None  # null: absent
        if has_frames == has_matches:
            raise InputError("data/frames", "give either frames (segments per frame) or matches (per frame pair)")
        if has_frames:
            frames = data["frames"]
            if not isinstance(frames, list) or len(frames) < 2:
                raise InputError("data/frames", "must be a list of at least 2 frames")
            parsed = []
            for k, frame in enumerate(frames):
                where = f"data/frames/{k}"
                if not isinstance(frame, dict) or set(frame) != {"left", "right"}:
                    raise InputError(where, "must be an object with 'left' and 'right' segment lists")
                parsed.append({side: _segments(frame[side], f"{where}/{side}") for side in ("left", "right")})
            return ParsedLines(rig, parsed, None)
        matches = data["matches"]
        if not isinstance(matches, list) or not matches:
            raise InputError("data/matches", "must be a non-empty list (one entry per frame pair)")
        parsed_matches = []
        for k, pair in enumerate(matches):
            where = f"data/matches/{k}"
            if not isinstance(pair, list) or not pair:
                raise InputError(where, "must be a non-empty list of lines, each 4 segments (left k, right k, "
                                        "left k+1, right k+1)")
            quads = []
            for i, quad in enumerate(pair):
                if not isinstance(quad, list) or len(quad) != 4:
                    raise InputError(f"{where}/{i}", "must be 4 segments: left k, right k, left k+1, right k+1")
                quads.append(_segments(quad, f"{where}/{i}", allow_empty=False))
            parsed_matches.append(np.stack(quads))
        return ParsedLines(rig, None, parsed_matches)

    @staticmethod
    def request_figures(data: dict) -> dict:
        """The most segments in one image of a frame (matching compares every pair of them), or
        lines matched in one frame pair."""
        largest, field = 0, "data/frames"
        for k, frame in enumerate(data.get("frames") or ()):
            for side in ("left", "right"):
                if len(frame.get(side) or ()) > largest:
                    largest, field = len(frame[side]), f"data/frames/{k}/{side}"
        for k, pair in enumerate(data.get("matches") or ()):
            if len(pair) > largest:
                largest, field = len(pair), f"data/matches/{k}"
        return {"segments_per_frame": (largest, field)}

    def check_options(self, parsed: ParsedLines, options: StereoLinesOptions) -> None:
        """What the data must give the solver chosen: enough lines per frame pair (a 422 naming
        the field, rather than a pair that cannot but fail)."""
        need = options.samples
        if parsed.matches is not None:
            for k, quads in enumerate(parsed.matches):
                if len(quads) < need:
                    raise InputError(f"data/matches/{k}", f"{len(quads)} lines; the {options.solver} solver with "
                                                          f"samples of {need} needs at least {need}")
            return
        for k, frame in enumerate(parsed.frames):
            for side in ("left", "right"):
                if len(frame[side]) < need:
                    raise InputError(f"data/frames/{k}/{side}", f"{len(frame[side])} segments; the {options.solver} "
                                                                f"solver with samples of {need} needs at least {need}")

    def count(self, parsed: ParsedLines) -> int:
        return parsed.pairs

    def observations(self, parsed: ParsedLines) -> int:
        if parsed.matches is not None:
            return sum(4 * len(quads) for quads in parsed.matches)
        return sum(len(frame["left"]) + len(frame["right"]) for frame in parsed.frames)

    def solve_item(self, parsed: ParsedLines, index: int, options: StereoLinesOptions, callback) -> dict:
        start = time.perf_counter()
        stopped, timed_out = [], []

        def should_stop() -> bool:
            if callback is not None and not stopped and callback(Progress(0, 0, 0.0, 0.0, 0.0, 0.0,
                                                                          time.perf_counter() - start)):
                stopped.append(True)
            if not timed_out and time.perf_counter() - start > options.time_limit_s:
                timed_out.append(True)  # the pair's own limit: what was found so far is kept
            return bool(stopped or timed_out)

        if parsed.matches is not None:
            estimate, quads, seconds = estimate_pair(parsed.rig, None, None, parsed.matches[index], options,
                                                     should_stop)
        else:
            estimate, quads, seconds = estimate_pair(parsed.rig, parsed.frames[index], parsed.frames[index + 1],
                                                     None, options, should_stop)
        status, reason = estimate.status, estimate.reason
        if stopped:
            status, reason = "cancelled", "the job was cancelled while this pair was solved"
        elif timed_out:
            reason = (f"time_limit: stopped at options.time_limit_s ({options.time_limit_s:g} s) after "
                      f"{estimate.iterations} RANSAC samples" + (f"; {reason}" if reason else ""))
        determinacy = translation_determined = None
        if status == "estimate" and estimate.R is not None and estimate.inliers:
            determinacy = safely(_motion_determinacy, parsed, index, quads, estimate)
            translation_determined, why = translation_judged(determinacy, estimate.t)
            if why is not None:
                reason = why if reason is None else f"{reason}; {why}"
        return {
            "frames": [index, index + 1], "status": status, "certified": False,
            "R": None if estimate.R is None or status == "cancelled" else estimate.R.tolist(),
            "t": None if estimate.t is None or status == "cancelled" else estimate.t.tolist(),
            "inliers": estimate.inliers, "inlier_ratio": estimate.inlier_ratio, "lines": estimate.lines,
            "matches": None if quads is None else quads.tolist(), "degenerate": estimate.degenerate,
            "solver": options.solver, "iterations": estimate.iterations, "time_ms": 1000 * seconds,
            "rms_px": estimate.rms_px, "refined": estimate.refined, "translation_determined": translation_determined,
            "reason": reason,
            "nodes": 0, "elapsed_s": seconds, "cost": None, "lower_bound": None, "determinacy": determinacy,
        }

    def cancelled_item(self, options: Any) -> dict:
        return {"frames": [-1, -1], "status": "cancelled", "certified": False, "R": None, "t": None, "inliers": [],
                "inlier_ratio": 0.0, "lines": 0, "matches": None, "degenerate": [], "solver": "", "iterations": 0,
                "time_ms": 0.0, "rms_px": None, "refined": False,
                "reason": "the job was cancelled before this pair started", "nodes": 0, "elapsed_s": 0.0,
                "cost": None, "lower_bound": None}

    def assemble(self, options: StereoLinesOptions, items: list[dict], stats: dict) -> dict:
        for index, item in enumerate(items):
            item["frames"] = [index, index + 1]
        motions = [(np.array(item["R"]), np.array(item["t"])) if item["status"] == "estimate" else None
                   for item in items]
        return {"kind": self.name, "status": "estimate", "solver": options.solver, "pairs": items,
                "trajectory": compose(motions), "stats": stats}


def translation_judged(determinacy: dict | None, t) -> tuple[bool, str | None]:
    """Whether the pair's determinacy fixes t to 10% of its length, and if not, why (a narrow
    baseline seeing distant lines fixes the rotation long before the translation)."""
    from geocert.core.determinacy import fixes

    if determinacy is None:
        return False, "the translation's determinacy could not be estimated: it is not known to be fixed"
    found = [i for i in determinacy["intervals"] if i["name"] in ("t_x", "t_y", "t_z")]
    if found and all(fixes(i) for i in found):
        return True, None
    length = float(np.linalg.norm(t))
    if any(i["lower"] is None for i in found):
        spans = "unbounded along some direction"
    else:
        spans = "; ".join(f"{i['name']} {i['lower']:.3g} to {i['upper']:.3g}" for i in found)
    return False, (f"the translation is not determined: the inlier lines leave it open to within 3 standard errors "
                   f"({spans}) against a length of {length:.3g}, beyond 10% of it (the rotation may still be fixed: "
                   "see determinacy)")


def _motion_determinacy(parsed: ParsedLines, index: int, quads, estimate) -> dict | None:
    """How well the pair's inlier lines fix its motion (solvers/lines/determinacy.py)."""
    from geocert.solvers.lines import determinacy
    from geocert.solvers.lines.geometry import line_set

    if parsed.matches is not None:
        segments = np.asarray(parsed.matches[index], dtype=float)
    else:
        a, b = parsed.frames[index], parsed.frames[index + 1]
        q = np.asarray(quads, dtype=int)
        segments = np.stack([a["left"][q[:, 0]], a["right"][q[:, 1]], b["left"][q[:, 2]], b["right"][q[:, 3]]], axis=1)
    inliers = np.asarray(estimate.inliers, dtype=int)
    return determinacy.motion(line_set(parsed.rig, segments[inliers]), np.asarray(estimate.R), np.asarray(estimate.t))


def example_job() -> dict:
    """A small job: one frame pair of 12 lines, matched, seen by the thesis's rig (synthetic)."""
    from geocert.solvers.lines.scenes import pair_scene

    scene = pair_scene(np.random.default_rng(7), 12, noise_px=0.0, degrees=2.0, metres=0.05)
    rig = scene.rig
    return {"kind": "stereo_lines", "options": {"solver": "polynomial", "sample_size": 2},
            "data": {"rig": {"K_left": rig.K_left.tolist(), "K_right": rig.K_right.tolist(), "R": rig.R.tolist(),
                             "t": rig.t.tolist()},
                     "matches": [np.round(scene.segments, 4).tolist()]}}


KIND = StereoLinesKind()
KIND.example = example_job()
__all__ = ["KIND", "NOT_CERTIFIED", "SOLVERS"]
