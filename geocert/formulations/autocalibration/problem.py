"""Stratified autocalibration's problem, numpy only (the verifier reads it too): options, the
intrinsics ranges and preconditioning, the frames, and the metric reconstruction an answer gives."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import metric_relaxation
from geocert.core.bnb import BnbOptions, Progress
from geocert.core.declared_options import option, redeclared
from geocert.core.geometry import InputError
from geocert.formulations.fractional.options import MAX_REL_GAP, SearchOptions

METHODS = ("stratified", "direct")
STRATIFIED_ABS_GAP = 1e-12
# abs_gap's cap, in the costs' own units: both methods' costs are normalised and small (the stored
# stratified scenes' metric costs are 2e-12 and 0.021, the direct one's 1.4e-4), and at abs_gap 1 a
# K 17% off its certified focal length (costing 37 times the proven minimum) verified "certified
# optimal". On the stored stratified scenes the metric cost rises by about 27 e^2 for a focal
# length off by a fraction e: 1e-8 is e = 2e-5, a fiftieth of a pixel at 1,000 px. It admits both
# defaults and the direct method's noiseless scenes' 1e-8.
MAX_ABS_GAP = 1e-8
# The direct stage's default abs_gap. Its cost (7.12) is dimensionless (image coordinates
# preconditioned so that K ~ I, cameras scaled to Frobenius norm sqrt 3, Q of trace 1): about
# 1.9e-4 per px^2 of image noise on an 800 px camera (measured: 4.8e-5 at 0.5 px). The
# interior-point bound is accurate to a few 1e-10 in these units whatever the cost (gaps of 4e-11 to
# 5.5e-10 at rank one, measured on 0.5 px, 0.02 px and Table 7.1 scenes), so 1e-12 left
# every scene with a cost below about 1e-6 uncertifiable (0.02 px: costs 3e-8 and 8e-8, gaps 8e-11
# and 2.2e-10, "not certified" at the tolerances 3e-12 and 8e-12). 1e-9 is the cost of about 0.002 px
# of noise there: a quadric certified with it is within that of the optimum, far below any
# measurement's noise. (The bound itself stays safe at any tolerance: the verifier recomputes it.)
DIRECT_ABS_GAP = 1e-9
RANGE_NAMES = ("focal", "aspect", "skew", "principal_point")


# The direct method's options (direct.py reads them).
CHIRALITY = ("points", "centers", "none")
# Relaxation orders served. Order 3 was measured not to fit: in 9 variables it has 5004 moments and
# 57865 constraint rows (built in 0.07 s), with two 220 x 220 PSD cones (the moment matrix and Q's
# localizing matrix), each a dense 24310-row block of Clarabel's KKT system (about 2.4 GB each as
# a triangle, some 5e12 flops a factorisation); order 2 has 714 moments and a 55 x 55 moment matrix.
ORDERS = (2,)


def check_direct_options(chirality, varying_focal, order) -> None:
    if chirality not in CHIRALITY:
        raise InputError("options/chirality", f"must be one of {', '.join(CHIRALITY)}")
    if not isinstance(varying_focal, bool):
        raise InputError("options/varying_focal", "must be true or false")
    if not (isinstance(order, int) and not isinstance(order, bool) and order in ORDERS):
        raise InputError("options/relaxation_order", f"must be one of {', '.join(map(str, ORDERS))} (order 3's "
                                                     "moment matrix is 220 x 220: too large to solve here)")


@dataclass
class AutocalibrationOptions(SearchOptions):
    """``rel_gap`` is the affine stage's, ``metric_rel_gap`` the metric stage's (the thesis's
    targets: 1e-5 and 1e-4); ``max_nodes`` and ``time_limit_s`` apply to each stage.
    ``intrinsics``: ranges in pixels, {"focal": [lo, hi], "aspect": [lo, hi], "skew": [lo, hi],
    "principal_point": [[u_lo, u_hi], [v_lo, v_hi]]}; a range not given follows from
    data.image_size (see default_ranges).
    The direct method (thesis ch. 7, geocert.formulations.autocalibration.direct) reads ``chirality``
    ("points", "centers" or "none"), ``varying_focal`` (one K, or one per view) and
    ``relaxation_order``; its one stage returns the metric upgrade and is certified with
    ``metric_rel_gap`` and ``abs_gap`` (its conic solves reach about 1e-5 relative: measured, the
    safe bound 1.3e-5 below the polished optimum on a 0.2% noise scene); the intrinsics ranges
    precondition it and bound a combination of each view's intrinsics (direct.focal_rows)."""

    method: str = option("stratified", choices=METHODS)
    # the API's model writes it as the kind's IntrinsicsIn (kinds/autocalibration.py)
    intrinsics: dict = option(default_factory=dict)
    chirality: str = option("centers", choices=CHIRALITY, description=(
        "direct method: which rows must lie on one side of the plane at infinity"))
    varying_focal: bool = option(False, description="direct method: one focal length per view")
    relaxation_order: int = option(2, ge=min(ORDERS), le=max(ORDERS), description=(
        "direct method: the moment relaxation's order (order 3 does not fit)"))
    # The direct method's proven focal interval (direct_sublevel) costs tens of seconds of CPU
    # against a solve's second: asked for, not implied by a full certificate.
    prove_focal_interval: bool = option(False, description=(
        "direct method, certificate full: prove an interval of the focal length (each view's, with "
        "varying_focal) over every quadric within a stated cost increase of the certified one (tens of "
        "seconds of CPU; with varying_focal 6 to 60 s a view)"))
    # The direct method's other intrinsics (direct_intrinsics): five more ratios, each end its own
    # Dinkelbach search, several times the focal length's CPU: asked for on its own.
    prove_intrinsics_intervals: bool = option(False, description=(
        "direct method, one focal length (varying_focal false), certificate full: prove intervals of the "
        "principal point, the second focal length, the skew and the aspect ratio over every quadric within "
        "the stated cost increase, beside the focal length's (implies prove_focal_interval; several times its "
        "CPU; an end no dual proves is stated null with its reason)"))
    # The stratified metric stage's intervals proven over the plane at infinity's own uncertainty
    # (plane_sublevel) cost 2.5 to 3.5 times a full certificate's solve (2 to 3.5 times its
    # verification), and on real near-critical rings come out as the ranges: asked for, not implied
    # by a full certificate.
    prove_intervals_over_planes: bool = option(False, description=(
        "stratified method, certificate full: prove the metric stage's intervals of K over every plane "
        "at infinity within a stated cost increase of the affine stage's too, not only the plane stated "
        "(2.5 to 3.5 times a full certificate's solve CPU; on near-critical real data often the "
        "ranges themselves)"))
    rel_gap: float = redeclared(SearchOptions, "rel_gap", 1e-5, description="the affine stage's")
    metric_rel_gap: float = option(1e-4, ge=0, le=MAX_REL_GAP, description="the metric stage's")
    # None: STRATIFIED_ABS_GAP or DIRECT_ABS_GAP, by the method
    abs_gap: float | None = option(None, ge=0, le=MAX_ABS_GAP, description=(
        f"default {STRATIFIED_ABS_GAP:g} (stratified), {DIRECT_ABS_GAP:g} (direct: its cost's units, problem.py)"))
    max_nodes: int = redeclared(SearchOptions, "max_nodes", 20_000, description="per stage")
    time_limit_s: float = redeclared(SearchOptions, "time_limit_s", 60.0, description="per stage")

    def __post_init__(self) -> None:
        if self.abs_gap is None:
            self.abs_gap = DIRECT_ABS_GAP if self.method == "direct" else STRATIFIED_ABS_GAP

    def check(self) -> None:
        SearchOptions.check(self)
        if self.method not in METHODS:
            raise InputError("options/method", f"must be one of {', '.join(METHODS)}")
        check_direct_options(self.chirality, self.varying_focal, self.relaxation_order)
        for name in ("prove_focal_interval", "prove_intervals_over_planes", "prove_intrinsics_intervals"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"options/{name}", "must be true or false")
        if self.prove_intrinsics_intervals and self.varying_focal:
            raise InputError("options/prove_intrinsics_intervals", "with varying_focal the direct method states one "
                                                                   "focal length a view and no other intrinsic to prove")
        if not (isinstance(self.metric_rel_gap, (int, float)) and 0 <= self.metric_rel_gap <= 1):
            raise InputError("options/metric_rel_gap", "must be a finite number >= 0 and <= 1")
        if not isinstance(self.intrinsics, dict):
            raise InputError("options/intrinsics", "must be an object of ranges")
        self.intrinsics = {name: value for name, value in self.intrinsics.items() if value is not None}
        for name, value in self.intrinsics.items():
            where = f"options/intrinsics/{name}"
            if name not in RANGE_NAMES:
                raise InputError(where, f"unknown range (known: {', '.join(RANGE_NAMES)})")
            pairs = value if name == "principal_point" else [value]
            if name == "principal_point" and (not isinstance(value, list) or len(value) != 2):
                raise InputError(where, "must be [[u_lo, u_hi], [v_lo, v_hi]]")
            for i, pair in enumerate(pairs):
                at = where if name != "principal_point" else f"{where}/{i}"
                if not (isinstance(pair, list) and len(pair) == 2 and all(_finite(x) for x in pair)):
                    raise InputError(at, "must be [lo, hi] with finite numbers")
                if not pair[0] <= pair[1]:
                    raise InputError(at, f"is empty: lo {pair[0]!r} > hi {pair[1]!r}")
            if name in ("focal", "aspect") and not value[0] > 0:
                raise InputError(where, "must be positive")


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def default_ranges(image_size: tuple[float, float] | None) -> dict:
    """Focal length 0.3 to 5 times the larger side, principal point in the middle half of the
    image, aspect ratio 0.95 to 1.05, skew within 1% of the larger side (pixels)."""
    if image_size is None:
        return {}
    width, height = image_size
    side = max(width, height)
    return {"focal": [0.3 * side, 5.0 * side], "aspect": [0.95, 1.05], "skew": [-0.01 * side, 0.01 * side],
            "principal_point": [[width / 4, 3 * width / 4], [height / 4, 3 * height / 4]]}


def resolve_ranges(intrinsics: dict, image_size) -> dict:
    ranges = {**default_ranges(image_size), **intrinsics}
    for name in RANGE_NAMES:
        if name not in ranges:
            raise InputError(f"options/intrinsics/{name}", "give this range, or data/image_size for its default")
    return ranges


def preconditioner(ranges: dict) -> np.ndarray:
    """K0 (3x3): the geometric middle of the focal range, the middle of the principal point's."""
    (fl, fu), ((ul, uu), (vl, vu)) = ranges["focal"], ranges["principal_point"]
    f0 = math.sqrt(fl * fu)
    return np.array([[f0, 0.0, (ul + uu) / 2], [0.0, f0, (vl + vu) / 2], [0.0, 0.0, 1.0]])


def normalised_ranges(ranges: dict, K0: np.ndarray) -> dict:
    """The ranges of K0^-1 K's entries: focal / f0, aspect, skew / f0, (u - u0) / f0, (v - v0) / f0."""
    f0, u0, v0 = K0[0, 0], K0[0, 2], K0[1, 2]
    (ul, uu), (vl, vu) = ranges["principal_point"]
    return {"focal": [ranges["focal"][0] / f0, ranges["focal"][1] / f0], "aspect": list(ranges["aspect"]),
            "skew": [ranges["skew"][0] / f0, ranges["skew"][1] / f0],
            "u": [(ul - u0) / f0, (uu - u0) / f0], "v": [(vl - v0) / f0, (vu - v0) / f0]}


@dataclass
class Problem:
    """Everything both stages and the verifier derive from the data and the options."""

    norm: frames.Normalised
    ranges: dict  # pixels, as solved (defaults filled in)
    K0: np.ndarray
    unit_ranges: dict  # preconditioned
    image_size: tuple[float, float] | None = None  # data.image_size, when stated


def prepare(cameras: np.ndarray, points: np.ndarray | None, image_size, intrinsics: dict,
            reference: int | None = None, unit_reference: bool = True, world: bool | float | None = None) -> Problem:
    """The problem in its normalised frame; ``reference`` (default: frames.reference_camera, the
    lowest-indexed of the best-conditioned cameras) the camera moved to [I | 0], whose view the
    modulus constraints leave out. ``unit_reference`` (the stratified method's frame) brings that
    camera to unit scale first, so that the frame does not depend on the scale it was given at
    (frames.unit_reference_scale); the direct method, and documents written before proofs stated
    ``reference_scale``, pass False: the reference as given. ``world`` is frames.normalise's: by
    default the unit reference frame brings the world to unit scale too (frames.world_unit_scale);
    False takes the world as given (documents written before proofs stated ``world_scale``), a
    number is a stated world_scale."""
    ranges = resolve_ranges(intrinsics, image_size)
    K0 = preconditioner(ranges)
    norm = frames.normalise(cameras, points, np.linalg.inv(K0), reference, unit_reference, world)
    return Problem(norm, ranges, K0, normalised_ranges(ranges, K0),
                   None if image_size is None else (float(image_size[0]), float(image_size[1])))


def reference_candidates(cameras: np.ndarray, image_size, intrinsics: dict) -> list[int]:
    """The references prepare may take for these data on any machine (frames.reference_candidates):
    one, unless a camera's conditioning lies on the tie's edge."""
    return frames.reference_candidates(cameras, np.linalg.inv(preconditioner(resolve_ranges(intrinsics, image_size))))


def earlier_references(cameras: np.ndarray, image_size, intrinsics: dict) -> list[int]:
    """The frames a proof naming no reference may be posed in (frames.earlier_references)."""
    return frames.earlier_references(cameras, np.linalg.inv(preconditioner(resolve_ranges(intrinsics, image_size))))


@dataclass
class StageProgress(Progress):
    stage: str = "affine"


def stage_callback(callback, stage: str):
    if callback is None:
        return None

    def report(progress: Progress):
        return callback(StageProgress(**progress.__dict__, stage=stage))

    return report


def bnb_options(options: AutocalibrationOptions, rel_gap: float) -> BnbOptions:
    return BnbOptions(rel_gap=rel_gap, abs_gap=options.abs_gap, max_nodes=options.max_nodes,
                      time_limit_s=options.time_limit_s)


def upper_triangular_root(omega: np.ndarray) -> np.ndarray:
    """K upper triangular with K K^T = omega and K[2, 2] = 1 (omega positive definite)."""
    J = np.eye(3)[::-1]
    L = np.linalg.cholesky(J @ omega @ J)
    K = J @ L @ J
    K = K * np.sign(np.diag(K))[None, :]
    return K / K[2, 2]


def upgrade(problem: Problem, p: np.ndarray, K_unit: np.ndarray) -> np.ndarray:
    """H (4x4) in the input frame: metric cameras P_i H, metric points H^-1 X (thesis 6.4)."""
    H = np.zeros((4, 4))
    H[:3, :3] = K_unit
    H[3, :3] = -p @ K_unit
    H[3, 3] = 1.0
    return problem.norm.T0 @ H


def rq(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A = K R with K upper triangular (exactly: zeros below its diagonal) and R orthogonal, from
    numpy's QR of A's rows reversed and transposed, so that the verifier splits cameras with numpy
    alone: with J the exchange matrix, (J A)' = Q1 R1 gives A = (J R1' J)(J Q1')."""
    Q1, R1 = np.linalg.qr(A[::-1].T)
    return R1.T[::-1, ::-1], Q1.T[::-1]


def metric_cameras(cameras: np.ndarray, H: np.ndarray) -> list[dict]:
    """Each metric camera as K [R | t] (R a rotation, K with K[2, 2] = 1) and its centre."""
    out = []
    for P in cameras:
        Q = P @ H
        K, R = rq(Q[:, :3])
        D = np.diag(np.sign(np.diag(K)))
        K, R = K @ D, D @ R
        scale = K[2, 2]
        t = np.linalg.solve(K, Q[:, 3])
        if np.linalg.det(R) < 0:
            R, t = -R, -t
        K = K / scale  # (t = K^-1 Q[:, 3] does not depend on Q's scale: dividing it by K's moved each centre)
        out.append({"K": K.tolist(), "R": R.tolist(), "t": t.tolist(), "center": (-R.T @ t).tolist()})
    return out


def metric_points(H: np.ndarray, points: np.ndarray | None) -> list | None:
    """H^-1 X dehomogenised (None for a point the upgrade sends to infinity)."""
    if points is None:
        return None
    X = np.linalg.solve(H, points.T).T
    with np.errstate(divide="ignore", invalid="ignore"):
        xyz = X[:, :3] / X[:, 3:4]
    return [row.tolist() if np.all(np.isfinite(row)) else None for row in xyz]


def dual_absolute_quadric(H: np.ndarray) -> np.ndarray:
    Q = H @ np.diag([1.0, 1.0, 1.0, 0.0]) @ H.T
    return Q / np.linalg.norm(Q)


def w_of_K(problem: Problem, K_pixels: np.ndarray) -> np.ndarray:
    """omega's five free entries (preconditioned) for a calibration in pixels."""
    K_unit = np.linalg.solve(problem.K0, K_pixels)
    omega = K_unit @ K_unit.T
    omega = omega / omega[2, 2]
    return np.array([omega[a, b] for a, b in metric_relaxation.ENTRIES])


def plane_in_input(problem: Problem, p: np.ndarray) -> np.ndarray:
    """The plane at infinity (p, 1) of the reference frame, in the input frame, unit norm."""
    plane = np.linalg.solve(problem.norm.T0.T, np.append(p, 1.0))
    return plane / np.linalg.norm(plane)


def plane_from_input(problem: Problem, plane: np.ndarray) -> np.ndarray | None:
    """p for a plane given in the input frame (None when it passes through the reference camera's
    centre: not a plane at infinity of this reconstruction)."""
    reference = problem.norm.T0.T @ plane
    if not abs(reference[3]) > 1e-300 or not np.all(np.isfinite(reference[:3] / reference[3])):
        return None
    return reference[:3] / reference[3]


def affine_cost(problem: Problem, p: np.ndarray) -> float:
    coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
    residuals = frames.modulus_residuals(coef, p)
    return float(residuals @ residuals)


def allowed_by_chirality(problem: Problem, p: np.ndarray) -> bool:
    """Whether (p, 1) (either sign) is strictly positive on every chirality row of some
    orientation (strictly: the orientations a proof excludes are excluded strictly)."""
    plane = np.append(p, 1.0)
    for delta in (1.0, -1.0):
        values = frames.chirality_rows(problem.norm, delta) @ plane
        if np.all(values > 0) or np.all(values < 0):
            return True
    return False
