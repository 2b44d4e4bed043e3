"""The autocalibration kind: a projective reconstruction (cameras, optional points) upgraded to a
metric one with constant intrinsics, each stage of the stratified method certified (thesis ch. 6).

A job is one reconstruction, so one item; its result is the document itself, and its
certificate's claims are the two stages (item 0 affine, item 1 metric)."""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, Field

from geocert.core import proven_reasons
from geocert.kinds.base import ProblemKind
from geocert.kinds.autocalibration_stages import ANALYSIS_GRACE_S, self_check_stages, stage_document, unproven
from geocert.kinds.documents import finite_or_none
from geocert.kinds.schema import Camera, CertificateDocument, Determinacy, Finite, JobBase, JobStats, Strict, options_model
from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.verify.autocalibration import STAGES, outcome, read_data
from geocert.core.determinacy import safely, within
from geocert.core.geometry import COORDINATE_LIMIT, MAX_IMAGE_SIDE_PX, MAX_INTRINSIC_PX, InputError
from geocert.core.self_check import enabled as self_check_enabled

Range = Annotated[list[Finite], Field(min_length=2, max_length=2, description="[lo, hi]")]
Point4 = Annotated[list[Finite], Field(min_length=4, max_length=4, description="[X, Y, Z, W]")]
Matrix3 = list[list[float]]


PIXEL_RANGES = ("focal", "skew", "principal_point")  # the ranges in pixels (aspect is a ratio)

# The pixel aspect ratio fy / fx an aspect range's ends (and a known K's) may state. A camera's
# pixels are square or nearly so, an anamorphic lens squeezes 2:1 and a line-scan set-up a few to
# one; a ratio beyond a thousand to one either way is no camera's pixel, only a typing error or
# units mixed up, and was queued up to COORDINATE_LIMIT (1e9), as the ranges in pixels were up to
# MAX_INTRINSIC_PX before their own limit.
MIN_ASPECT, MAX_ASPECT = 1e-3, 1e3


def image_side_refusal(size, where: str) -> None:
    """An image size with a side over MAX_IMAGE_SIDE_PX: the 422 naming ``where``."""
    for x in size if isinstance(size, (list, tuple, np.ndarray)) else ():
        if isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) > MAX_IMAGE_SIDE_PX:
            raise InputError(where, f"a side of {abs(x):g} px exceeds the limit of {MAX_IMAGE_SIDE_PX:g} px a side "
                                    "(far above any camera's: give the size in pixels)")


def ranges_within_limit(image_size, intrinsics: dict) -> None:
    """data/image_size and every intrinsics range within COORDINATE_LIMIT, as every kind's
    coordinates: beyond it K0 was singular in floating point and the queued job failed with
    "Solver failure: LinAlgError" instead of this 422 naming the field; the ranges in pixels
    (focal, skew, principal_point) within MAX_INTRINSIC_PX; the aspect range within MIN_ASPECT
    and MAX_ASPECT; and data/image_size within MAX_IMAGE_SIDE_PX a side."""
    named = [("data/image_size", image_size, None)] if image_size is not None else []
    for name, value in intrinsics.items():
        if name == "principal_point" and isinstance(value, (list, tuple)):
            named += [(f"options/intrinsics/{name}/{i}", pair, name) for i, pair in enumerate(value)]
        else:
            named.append((f"options/intrinsics/{name}", value, name))
    for where, values, _ in named:
        for x in values if isinstance(values, (list, tuple, np.ndarray)) else ():
            if isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) > COORDINATE_LIMIT:
                raise InputError(where, f"magnitude {abs(x):g} exceeds the limit {COORDINATE_LIMIT:g} "
                                        "(rescale the coordinates, e.g. to pixels)")
    for where, values, name in named:
        if name in PIXEL_RANGES and isinstance(values, (list, tuple)):
            for end, x in zip(("its lower end", "its upper end"), values):
                intrinsic_refusal(x, where, end)
        if name == "aspect" and isinstance(values, (list, tuple)):
            for end, x in zip(("its lower end", "its upper end"), values):
                aspect_refusal(x, where, end)
    if image_size is not None:
        image_side_refusal(image_size, "data/image_size")


def intrinsic_refusal(x, where: str, what: str) -> None:
    """A focal length, skew or principal point coordinate ``x`` (``what``: which, in words) over
    MAX_INTRINSIC_PX in magnitude: the 422 naming ``where``."""
    if isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) > MAX_INTRINSIC_PX:
        raise InputError(where, f"{what} {x:g} px exceeds the limit of {MAX_INTRINSIC_PX:g} px in magnitude for a "
                                f"focal length, skew or principal point: ten times the largest image side taken "
                                f"({MAX_IMAGE_SIDE_PX:g} px; a focal length of 1e7 px is a pixel of 0.02 arc "
                                "seconds): give it in pixels")


def aspect_refusal(x, where: str, what: str) -> None:
    """A pixel aspect ratio fy / fx ``x`` (``what``: which end, in words) outside [MIN_ASPECT,
    MAX_ASPECT]: the 422 naming ``where``."""
    if isinstance(x, (int, float)) and not isinstance(x, bool) and not MIN_ASPECT <= x <= MAX_ASPECT:
        raise InputError(where, f"{what} {x:g} lies outside [{MIN_ASPECT:g}, {MAX_ASPECT:g}]: a pixel aspect ratio "
                                f"fy / fx beyond a thousand to one either way is no camera's (its pixels are square "
                                "or nearly so; an anamorphic lens squeezes 2:1)")


# A known K's entries in pixels, as intrinsic_refusal says them: [row, column, in words].
K_ENTRIES = ((0, 0, "the focal length fx"), (0, 1, "the skew"), (0, 2, "the principal point's u"),
             (1, 1, "the focal length fy"), (1, 2, "the principal point's v"))


def known_K_within_limit(K, where: str = "options/intrinsics/K") -> None:
    """A known K (a 3x3 list of numbers, its shape already checked) with every entry in pixels
    within MAX_INTRINSIC_PX, and its aspect ratio fy / fx (both positive) within MIN_ASPECT and
    MAX_ASPECT: the 422 naming the entry (``where``/row/column; fy for the aspect ratio)."""
    for i, j, what in K_ENTRIES:
        intrinsic_refusal(K[i][j], f"{where}/{i}/{j}", what)
    fx, fy = K[0][0], K[1][1]
    if all(isinstance(f, (int, float)) and not isinstance(f, bool) and f > 0 for f in (fx, fy)):
        aspect_refusal(fy / fx, f"{where}/1/1", "the aspect ratio fy / fx")


class AutocalibrationData(Strict):
    cameras: list[Camera] = Field(min_length=3, description="3x4 projective cameras of one reconstruction")
    points: list[Point4] | None = Field(None, description="homogeneous points of the same reconstruction "
                                                          "(bound the plane at infinity by chirality)")
    image_size: Range | None = Field(None, description="[width, height] in pixels: the intrinsics ranges' defaults")


class IntrinsicsIn(Strict):
    focal: Range | None = Field(None, description="pixels; default 0.3 to 5 times the larger image side")
    aspect: Range | None = Field(None, description="fy / fx, within 1e-3 to 1e3; default 0.95 to 1.05")
    skew: Range | None = Field(None, description="pixels; default within 1% of the larger side")
    principal_point: Annotated[list[Range], Field(min_length=2, max_length=2)] | None = Field(
        None, description="[[u_lo, u_hi], [v_lo, v_hi]] pixels; default the middle half of the image")


AutocalibrationOptionsIn = options_model("AutocalibrationOptionsIn", autocalibration_problem.AutocalibrationOptions,
                                         wire={"intrinsics": (IntrinsicsIn, IntrinsicsIn)})


class AutocalibrationJob(JobBase):
    kind: Literal["autocalibration"]
    data: AutocalibrationData
    options: AutocalibrationOptionsIn = Field(default_factory=AutocalibrationOptionsIn)


class StageOut(BaseModel):
    name: Literal["affine", "metric", "direct"]
    cost: float | None
    lower_bound: float | None
    gap: float | None
    status: str
    certified: bool
    nodes: int
    elapsed_s: float
    reason: str | None = None
    plane_at_infinity: list[float] | None = None
    K: Matrix3 | None = None
    dual_absolute_quadric: list[list[float]] | None = None
    certificate: dict[str, Any] | None = None
    determinacy: Determinacy | None = Field(None, description="how well the data fix the stage's answer "
                                                              "(estimated), and critical motions recognised")


class CameraOut(BaseModel):
    K: Matrix3
    R: Matrix3
    t: list[float]
    center: list[float]


class Baseline(BaseModel):
    method: Literal["linear"]
    K: Matrix3 | None
    psd: bool
    cost: float | None


class AutocalibrationResult(BaseModel):
    kind: Literal["autocalibration"]
    method: str
    status: str = Field(description='"optimal" when every stage is certified; "failed" (or "cancelled") when no '
                                    "metric upgrade was found (K and the quadric null); else the status of the "
                                    "first stage not certified (time_limit, node_limit, not_certified)")
    reason: str | None = Field(description="why the status is not optimal: the stage and its reason")
    plane_at_infinity: list[float] | None = Field(description="in the input frame, unit norm")
    K: Matrix3 | None
    Ks: list[Matrix3 | None] | None = Field(None, description="direct method with varying_focal: one K per view")
    dual_absolute_quadric: list[list[float]] | None = Field(description="4x4, input frame, unit Frobenius norm")
    upgrade: list[list[float]] | None = Field(description="H: metric cameras P_i H, metric points H^-1 X")
    cameras: list[CameraOut] | None
    points: list[list[float] | None] | None
    intrinsics: dict[str, Any] = Field(description="the ranges solved with (pixels; defaults filled in)")
    stages: list[StageOut]
    baseline: Baseline | None
    stats: JobStats
    certificate: CertificateDocument | None = Field(None, description='with options.certificate = "full"')


# The options one method reads and the other ignores, with the method that reads each: asked for
# (other than its default) with the other method, a job is refused (check_options). ``chirality``
# is the direct method's: the stratified affine stage searches the planes its own rows allow (the
# points and the camera centres, frames.chirality_rows), so a stratified job asking "none" got a
# certificate of fewer planes than asked for, under a hash saying "none" (review 51).
METHOD_OPTIONS = {"varying_focal": "direct", "prove_focal_interval": "direct", "prove_intrinsics_intervals": "direct",
                  "prove_intervals_over_planes": "stratified", "chirality": "direct"}


class Parsed:
    def __init__(self, cameras, points, image_size):
        self.cameras, self.points, self.image_size = cameras, points, image_size


# A small reconstruction (6 views of 12 points, synthetic: geocert.solvers.autocalibration.scenes, seed 11)
EXAMPLE_DATA = {
    "cameras": [
        [[-0.02816711, -0.009239009, -0.02841612, 0.6616719], [0.02921911, -0.05869841, -0.02266608, 0.7454456], [-2.161665e-05, -3.637794e-05, -3.507275e-06, 0.001366901]],
        [[-0.01639864, 0.05228969, 0.03011414, 0.7416068], [0.05670724, -0.01258258, 0.01681269, 0.6651694], [5.169981e-05, 3.695175e-05, -9.116066e-06, 0.001542663]],
        [[-0.000716687, 0.04823162, 0.0229049, 0.7190031], [0.04661264, 0.02747577, -0.02408013, 0.6904156], [-1.052211e-05, 4.326086e-05, -1.524159e-05, 0.001367951]],
        [[0.05799904, -0.007353172, 0.01092701, 0.678145], [-0.01623979, 0.04343117, 0.0298118, 0.730439], [5.857866e-06, -2.115806e-05, 2.196089e-05, 0.001468231]],
        [[-0.02372678, 0.01123949, -0.02693955, 0.7658457], [0.04526395, 0.01056192, -0.02989863, 0.6395385], [2.457204e-05, -3.316495e-05, -3.736134e-05, 0.001244715]],
        [[-0.04200139, -0.008769303, -0.01904658, 0.6552572], [-0.04233386, 0.02963408, 0.02483423, 0.7517615], [-1.681433e-05, 4.054183e-05, -1.430714e-05, 0.001355983]],
    ],
    "points": [
        [-0.9308024, 0.2377182, 0.1422046, 0.2384842], [-0.6067509, -0.3816615, 0.6891877, 0.1058683],
        [-0.5487213, -0.4062356, 0.7233545, 0.1031301], [0.5494556, -0.6881953, 0.1129505, 0.460139],
        [0.08864005, -0.2673143, -0.9516883, 0.1223742], [0.8806039, 0.4119633, 0.1359677, 0.1906193],
        [0.4330033, -0.03800767, 0.8963123, 0.08768026], [-0.7644421, 0.4471554, -0.3906084, 0.2512079],
        [-0.2213906, 0.3561306, -0.8969624, 0.1400561], [0.4759324, 0.5224634, -0.7017487, 0.08982815],
        [-0.1883752, -0.1630011, -0.9631133, 0.1017757], [0.5379696, -0.06936636, -0.8317444, 0.1182295],
    ],
    "image_size": [1000, 1000],
}


class AutocalibrationKind(ProblemKind):
    name = "autocalibration"
    description = ("Autocalibration of a projective reconstruction: stratified (constant intrinsics; the plane at "
                   "infinity, then the DIAC, each certified globally optimal) or direct (the absolute dual quadric "
                   "by a moment relaxation, certified when the relaxation is tight).")
    item_key = "stages"  # the certificate's claims; a job is one reconstruction
    chunk_size = 1
    options_type = autocalibration_problem.AutocalibrationOptions
    request_model = AutocalibrationJob
    result_model = AutocalibrationResult
    solution_fields = ("plane_at_infinity", "K", "dual_absolute_quadric")  # the last: the direct stage's
    verification = STAGES
    example = {"kind": "autocalibration", "options": {}, "data": EXAMPLE_DATA}

    def parse(self, data: Any, items: range | None = None) -> Parsed:
        return Parsed(*read_data(data))

    @staticmethod
    def request_figures(data: dict) -> dict:
        """Views, and views times points (the chirality rows of both stages' programs)."""
        views, points = len(data.get("cameras") or ()), len(data.get("points") or ())
        return {"autocalibration_views": (views, "data/cameras"), "view_points": (views * points, "data/points")}

    def check_options(self, parsed: Parsed, options: autocalibration_problem.AutocalibrationOptions) -> None:
        """Every intrinsics range given or defaulted from data/image_size, and the direct method's
        chirality pairs counted (before the job is queued: the solve cannot start without them,
        and nothing is built past the size limits). An option of the other method asked for is
        refused, naming it: the method would ignore it (varying_focal with the default stratified
        method would return one K), a silent wrong answer to what was asked."""
        defaults = autocalibration_problem.AutocalibrationOptions()
        for name, method in METHOD_OPTIONS.items():
            if getattr(options, name) != getattr(defaults, name) and options.method != method:
                raise InputError(f"options/{name}", f"applies to the {method} method only (options/method "
                                                    f"\"{method}\"); the {options.method} method would ignore it")
        ranges_within_limit(parsed.image_size, options.intrinsics)
        autocalibration_problem.resolve_ranges(options.intrinsics, parsed.image_size)
        if options.method != "direct":
            from geocert.formulations.autocalibration import frames

            # the cameras alone fix the frame's world scale and spread (the points only its signs)
            norm = autocalibration_problem.prepare(parsed.cameras, None, parsed.image_size, options.intrinsics).norm
            if not frames.world_frame_bounded(norm):
                raise InputError("data/cameras", f"the cameras' distances from the reference camera spread too far "
                                                 f"for the stratified frame: their median brought to unit scale, the "
                                                 f"farthest lies {norm.world_scale * norm.world_ratio_highest:.3g} "
                                                 f"away, beyond 2^{frames.EARLIER_WORLD_HIGHEST} (a K could be "
                                                 "certified wrong there); solve with fewer views near the reference")
        if options.method == "direct":
            from geocert.formulations.autocalibration import direct

            direct.check_size(len(parsed.cameras), 0 if parsed.points is None else len(parsed.points),
                              options.chirality)

    def time_bound_s(self, parsed: Parsed, options: autocalibration_problem.AutocalibrationOptions) -> float:
        return options.time_limit_s * (1 if options.method == "direct" else 2)  # per stage

    def count(self, parsed: Parsed) -> int:
        return 1

    def observations(self, parsed: Parsed) -> int:
        return len(parsed.cameras) * (1 + (0 if parsed.points is None else len(parsed.points)))

    def solve_item(self, parsed: Parsed, index: int, options: autocalibration_problem.AutocalibrationOptions,
                   callback) -> dict:
        from geocert.solvers.autocalibration import stratified  # the conic solver, only to solve

        if options.method == "direct":  # thesis ch. 7: one stage
            from geocert.kinds.direct_autocalibration import solve_document

            return solve_document(parsed, options, callback)
        began = time.monotonic()
        problem = autocalibration_problem.prepare(parsed.cameras, parsed.points, parsed.image_size, options.intrinsics)
        checking = self_check_enabled()  # GEOCERT_SELF_VERIFY=1: proofs made, and checked below
        result = stratified.solve(problem, dataclasses.replace(options, certificate="full") if checking else options,
                                  callback)
        item = stratified_item(parsed, options, problem, result, options.certificate == "full" or checking,
                               deadline=began + self.time_bound_s(parsed, options) + ANALYSIS_GRACE_S,
                               prove_intervals=options.certificate == "full")
        if checking:
            self_check_stages(parsed, options, item["stages"])
        return item

    def cancelled_item(self, options: autocalibration_problem.AutocalibrationOptions) -> dict:
        """Never started: the stages of the job's method (the direct method's one, the stratified
        method's two), each cancelled."""
        stage = {"cost": None, "lower_bound": None, "gap": None, "status": "cancelled", "certified": False,
                 "nodes": 0, "elapsed_s": 0.0, "reason": "the job was cancelled before it started"}
        method = getattr(options, "method", "stratified")
        names = ("direct",) if method == "direct" else ("affine", "metric")
        return {"method": method, "intrinsics": {}, "plane_at_infinity": None, "K": None,
                "dual_absolute_quadric": None, "upgrade": None, "cameras": None, "points": None, "baseline": None,
                "stages": [{"name": name, **stage} for name in names], "status": "cancelled",
                "certified": False, "nodes": 0, "elapsed_s": 0.0, "cost": None, "lower_bound": None}

    def claimed_items(self, items: list[dict]) -> list[dict]:
        return items[0]["stages"]

    def assemble(self, options, items: list[dict], stats: dict) -> dict:
        item = dict(items[0])
        for key in ("status", "certified", "nodes", "elapsed_s", "cost", "lower_bound"):
            item.pop(key, None)
        for stage in item["stages"]:
            (stage.get("certificate") or {}).pop("proof", None)
        return {"kind": self.name, "method": item.pop("method"), **outcome(item), **item, "stats": stats}


def _prove_intervals(problem: autocalibration_problem.Problem, result, stage: dict, proof: dict,
                     time_limit_s: float) -> None:
    """The metric stage's proven intervals at its determinacy's cost increase: into its proof
    (``sublevel``) and its determinacy (``proven_intervals``), when the search proves any.
    Returns why none was proven (None: proven)."""
    from geocert.solvers.autocalibration import metric_sublevel
    from geocert.verify.autocalibration import proven_metric

    document = stage["determinacy"]
    increase = document.get("cost_increase")
    if increase is None or stage["cost"] is None:
        return proven_reasons.reason("metric_no_level")
    try:
        found = metric_sublevel.prove(problem, result.p, result.metric.unit, stage["cost"], increase, time_limit_s)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return proven_reasons.reason("metric_failed", error=proven_reasons.error_name(exc))
    if found is None:
        return proven_reasons.reason("metric_none", seconds=time_limit_s)
    proof["sublevel"] = found
    document["proven_intervals"] = proven_metric(proof["sublevel"])
    document["proven"] = True
    return None


def _prove_over_planes(problem: autocalibration_problem.Problem, result, affine_stage: dict, stage: dict,
                       proof: dict) -> None:
    """The metric stage's intervals proven over the plane at infinity's own uncertainty
    (plane_sublevel), at both stages' estimated cost increases: into its proof
    (``plane_sublevel``) and its determinacy (``proven_over_planes``), when the search proves any."""
    from geocert.formulations.autocalibration import plane_sublevel

    affine_increase = affine_stage["determinacy"].get("cost_increase")
    increase = stage["determinacy"].get("cost_increase")
    if affine_increase is None or increase is None or stage["cost"] is None or result.p is None:
        return
    regions = [(r.delta, r.G, r.lo, r.hi, r.basis) for r in result.affine.regions]
    excluded = [{"delta": item["delta"], "rows": item["rows"]} for item in result.affine.excluded]
    try:
        found = plane_sublevel.prove(problem, regions, excluded, autocalibration_problem.affine_cost(problem, result.p),
                                     affine_increase, stage["cost"], increase)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        found = None
    if found is None:
        return
    proof["plane_sublevel"] = found
    stage["determinacy"]["proven_over_planes"] = plane_sublevel.proven_document(found)
    stage["determinacy"]["proven"] = True


def stratified_item(parsed: Parsed, options: autocalibration_problem.AutocalibrationOptions,
                    problem: autocalibration_problem.Problem, result, full: bool,
                    deadline: float | None = None, prove_intervals: bool = False) -> dict:
    """The job's item (the result's stages and solution) from a stratified solve of ``problem``
    (stratified.solve's result), with each certified stage's proof when ``full``: the kind's own
    solve, and the reconstruction kind's calibration certificate (its pipeline's solve). With
    ``prove_intervals`` a certified metric stage's determinacy also states the intervals of K its
    proof's ``sublevel`` proves (metric_sublevel), at the estimate's cost increase, and with
    options.prove_intervals_over_planes those proven over the plane's own uncertainty too
    (plane_sublevel). ``deadline``
    (time.monotonic): the job's time limit in all, which the stages' determinacy analyses and that
    search keep (a stage's analysis not done by then says so: determinacy.not_analysed)."""
    from geocert.formulations.autocalibration import determinacy, proofs

    a = result.affine
    document: dict = {"method": options.method, "intrinsics": problem.ranges, "plane_at_infinity": None,
                      "K": None, "dual_absolute_quadric": None, "upgrade": None, "cameras": None, "points": None,
                      "baseline": None}
    affine_cost = math.inf
    if a.plane is not None:
        document["plane_at_infinity"] = autocalibration_problem.plane_in_input(problem, a.plane[:3]).tolist()
    if result.p is not None:  # the plane as returned, read back (None: through the reference camera's centre)
        affine_cost = autocalibration_problem.affine_cost(problem, result.p)
    status, certified, reason = a.status, a.certified, a.reason
    if certified and (result.p is None or not autocalibration_problem.allowed_by_chirality(problem, result.p)):
        status, certified, reason = "not_certified", False, (
            "the plane returned is not strictly inside the chirality polytope" if result.p is not None
            else "the plane returned passes through the reference camera's centre")
    affine_stage = stage_document("affine", status, certified, affine_cost, a.lower_bound, a.nodes,
                                  result.affine_s, reason, options.rel_gap, options.abs_gap,
                                  "every plane at infinity chirality allows",
                                  proofs.encode_affine(a, problem.norm)
                                  if full and certified else None)
    affine_stage["plane_at_infinity"] = document["plane_at_infinity"]
    m = result.metric
    not_run = "cancelled" if a.status == "cancelled" else "failed"
    metric_stage = stage_document("metric", not_run if m is None else m.status, False, math.inf, -math.inf,
                                  0 if m is None else m.nodes, result.metric_s,
                                  ("the job was cancelled" if not_run == "cancelled" else "no plane at infinity")
                                  if m is None else m.reason, options.metric_rel_gap, options.abs_gap, "", None)
    if m is not None and result.K_unit is not None:
        K = problem.K0 @ result.K_unit
        K = K / K[2, 2]
        K[1, 0] = K[2, 0] = K[2, 1] = 0.0
        K[2, 2] = 1.0
        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, result.p, problem.unit_ranges)
        w = autocalibration_problem.w_of_K(problem, K)
        lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
        inside = metric_relaxation.in_domain(setup, w, lo, hi)
        metric_stage = stage_document("metric", m.status if inside or not m.certified else "not_certified",
                                      m.certified and inside, metric_relaxation.cost(setup, w), m.lower_bound, m.nodes,
                                      result.metric_s, m.reason if inside else "the DIAC returned left its domain by rounding",
                                      options.metric_rel_gap, options.abs_gap,
                                      "every K within the intrinsics ranges, for the plane at infinity stated",
                                      proofs.encode_metric(m, problem.norm)
                                      if full and m.certified else None)
        metric_stage["K"] = K.tolist()
        H = autocalibration_problem.upgrade(problem, result.p, np.linalg.solve(problem.K0, K))
        document.update(K=K.tolist(), upgrade=H.tolist(),
                        dual_absolute_quadric=autocalibration_problem.dual_absolute_quadric(H).tolist(),
                        cameras=autocalibration_problem.metric_cameras(parsed.cameras, H))
        document["points"] = autocalibration_problem.metric_points(H, parsed.points)
    metric_stage["plane_at_infinity"] = document["plane_at_infinity"]
    centres = None if document["cameras"] is None else np.array([c["center"] for c in document["cameras"]])
    why = (f"the job's time limit (options.time_limit_s, {options.time_limit_s:g} s a stage) had passed, and "
           f"{ANALYSIS_GRACE_S:g} s more")
    # the motion judged at the returned K, stated even where a stage's analysis stops or fails
    judged = None if result.p is None or document["K"] is None else \
        safely(determinacy.judged_motion, problem, result.p, np.array(document["K"]), centres)
    if result.p is not None and math.isfinite(affine_cost):
        affine_stage["determinacy"] = determinacy.with_motion(
            within(deadline, "the affine stage's determinacy", why, determinacy.affine_stage, problem, result.p,
                   affine_stage["cost"], affine_stage["lower_bound"], centres,
                   None if document["K"] is None else np.array(document["K"])),
            judged, "the affine stage's determinacy")
    if document["K"] is not None:
        metric_stage["determinacy"] = determinacy.with_motion(
            within(deadline, "the metric stage's determinacy", why, determinacy.metric_stage, problem, result.p,
                   np.array(document["K"]), metric_stage["cost"], metric_stage["lower_bound"], centres),
            judged, "the metric stage's determinacy")
        proof = metric_stage["certificate"].get("proof")
        # every null proven_intervals the proof was asked for says why (issue 37 F5)
        why_not = unproven(full, metric_stage["certified"], proof, metric_stage["status"]) if prove_intervals else None
        if prove_intervals and why_not is None and metric_stage["determinacy"] is not None:
            left = math.inf if deadline is None else deadline - time.monotonic()
            why_not = proven_reasons.reason("metric_late") if left <= 0 else \
                _prove_intervals(problem, result, metric_stage, proof,
                                 min(options.time_limit_s, proven_reasons.METRIC_PROOF_S, left))
            # the planes' regions are proved side by side whether or not the affine search finished
            left = math.inf if deadline is None else deadline - time.monotonic()
            if options.prove_intervals_over_planes and isinstance(affine_stage.get("determinacy"), dict) \
                    and "sublevel" in proof and left > 0:
                _prove_over_planes(problem, result, affine_stage, metric_stage, proof)
        if why_not is not None and isinstance(metric_stage["determinacy"], dict):
            metric_stage["determinacy"]["proven_reason"] = why_not
    if result.baseline is not None:
        Kb = problem.K0 @ autocalibration_problem.upper_triangular_root(
            metric_relaxation.omega_of(result.baseline["w"])) \
            if np.linalg.eigvalsh(metric_relaxation.omega_of(result.baseline["w"]))[0] > 0 else None
        document["baseline"] = {"method": "linear", "K": None if Kb is None else (Kb / Kb[2, 2]).tolist(),
                                "psd": result.baseline["psd"], "cost": finite_or_none(result.baseline["cost"])}
    stages = [affine_stage, metric_stage]
    # What the job's statistics count: both stages (certified only when both are).
    return {**document, "stages": stages, "status": metric_stage["status"] if affine_stage["certified"]
            else affine_stage["status"], "certified": affine_stage["certified"] and metric_stage["certified"],
            "nodes": affine_stage["nodes"] + metric_stage["nodes"],
            "elapsed_s": result.affine_s + result.metric_s,
            "cost": metric_stage["cost"], "lower_bound": metric_stage["lower_bound"]}


KIND = AutocalibrationKind()
