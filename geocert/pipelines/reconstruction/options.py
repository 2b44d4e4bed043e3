"""The reconstruction's options: the structure stage's search options (FractionalOptions: the
norm, gaps and limits of each certified triangulation and resection), the metric upgrade's, and
the projective stage's thresholds. Ranges are stated once, in OPTION_RANGES."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from geocert.formulations.autocalibration.problem import CHIRALITY, AutocalibrationOptions
from geocert.core.declared_options import option, option_ranges, redeclared
from geocert.core.geometry import InputError
from geocert.formulations.fractional.options import FractionalOptions, ResidualOptions, SearchOptions
from geocert.formulations.reconstruction import run_control

AUTOCALIBRATION_METHODS = ("stratified", "direct", "auto")
MAX_EXHAUSTIVE = 200  # images matched every pair with every other at most (19,900 pairs)
PAIR_RULES = ("auto", "exhaustive", "retrieval", "sequential")  # FeatureOptions.pairs
# The run-control options' ranges and words are stated in the solvers' layer, where the verifier
# reads them too (formulations.reconstruction.run_control).
CAMERA_MODELS, REGISTRATIONS, RADIAL_DISTORTIONS = run_control.CAMERA_MODELS, run_control.REGISTRATIONS, \
    run_control.RADIAL_DISTORTIONS
RANGES = run_control.RANGES


@dataclass
class FeatureOptions:
    """Stage 1's matching, photos only (null: the default; the defaults are OpenCV's SIFT's and
    suit textured scenes)."""

    # (features.py reads all of these; a job sets the declared ones, ``options.features``, which
    # the API writes as null when not given.)

    # keypoints kept per image (the largest-scale: select_keypoints); 0 keeps all
    max_features: int = option(4000, ge=0, le=1_000_000, wire_default=None, description=(
        "keypoints kept per image, the largest-scale (0: all; default 4000)"))
    # SIFT's DoG contrast threshold; lower finds fainter keypoints. OpenCV keeps a keypoint whose
    # contrast exceeds this over its 3 layers per octave (on intensities in [0, 1]); COLMAP's SIFT
    # keeps it above 0.02 / 3, so 0.02 here is COLMAP's default (OpenCV's own, 0.04, loses the faint
    # keypoints of untextured objects: 4 of templeSparseRing's 16 views register instead of 16).
    contrast_threshold: float = option(0.02, gt=0, le=1, wire_default=None, description=(
        "SIFT's contrast threshold (default 0.02, COLMAP's; lower finds fainter keypoints)"))
    edge_threshold: float = 10.0  # SIFT's edge-response threshold (OpenCV's default)
    # Lowe's ratio test: nearest / second nearest descriptor distance below this
    ratio: float = option(0.8, gt=0, le=1, wire_default=None, description="Lowe's ratio test (default 0.8)")
    mutual: bool = True  # keep a match only when the two features are each other's nearest
    # epipolar distance (pixels) of a fundamental-matrix inlier
    ransac_threshold_px: float = option(1.0, gt=0, le=100, wire_default=None, description=(
        "epipolar distance of a verified match, pixels (default 1)"))
    ransac_confidence: float = 0.999
    ransac_max_iters: int = 5_000
    min_inliers: int = 15  # a verified pair has at least this many inliers
    min_track_length: int = 2  # views per kept track
    # "auto", "exhaustive", "retrieval" or "sequential" (see features.py's docstring)
    pairs: str = option("auto", choices=PAIR_RULES, wire_default=None, description=(
        'which image pairs are matched: "exhaustive" every pair, "retrieval" each image with the images most alike '
        'it (a bag of visual words), "auto" (default) exhaustive up to exhaustive_limit images and retrieval beyond, '
        '"sequential" each image with its neighbour_window successors in the order given (video)'))
    # "auto": every pair for at most this many images, retrieval beyond
    exhaustive_limit: int = option(40, ge=2, le=MAX_EXHAUSTIVE, wire_default=None, description=(
        '"auto": every pair up to this many images (default 40)'))
    # "retrieval": each image with this many most alike
    retrieval_neighbours: int = option(20, ge=1, le=1000, wire_default=None, description=(
        '"retrieval": images matched with each (default 20)'))
    # "retrieval": visual words clustered from the images' descriptors
    vocabulary_size: int = option(1024, ge=8, le=100_000, wire_default=None, description=(
        '"retrieval": visual words, clustered from the images\' own descriptors (default 1024)'))
    # "sequential": each image with this many successors
    neighbour_window: int = option(5, ge=1, le=1000, wire_default=None, description=(
        '"sequential": successors matched with each (default 5)'))
    # "sequential": the successors wrap round (a turntable or a closed loop)
    ring: bool = option(False, wire_default=None, description=(
        '"sequential": the last images wrap round to the first (default false)'))
    # guided matching's ratio test (0: no guided matching; see features.py's docstring)
    guided_ratio: float = option(0.0, ge=0, lt=1, wire_default=None, description=(
        "after a pair is verified, match it again along its epipolar lines with this ratio test (default 0: off)"))
    guided_min_inliers: int = 30  # a pair is matched again, guided, when it has at least this many inliers
    guided_threshold_px: float | None = None  # epipolar distance of a guided candidate (None: ransac_threshold_px)
    # Features and matching stop past this many seconds (the clock checked between images and
    # between pairs); the tracks of what was matched by then are kept.
    time_limit_s: float = option(300.0, gt=0, le=3600, wire_default=None, description=(
        "seconds for reading features and matching (default 300): past it the images and pairs not yet done are "
        "left out, and the matches stage says time_limit"))


@dataclass
class ReconstructionOptions(FractionalOptions):
    """``intrinsics``: "unknown" (ranges from the image size, as autocalibration's defaults), the
    ranges themselves ({"focal", "aspect", "skew", "principal_point"}, pixels), or {"K": 3x3}
    (known calibration). ``rel_gap``, ``abs_gap``, ``max_nodes`` and ``time_limit_s`` apply to
    each track's and each camera's certified solve; the ``autocalibration_*`` options to each
    stage of the metric upgrade (its rel_gap the affine stage's, ``metric_rel_gap`` the metric
    stage's)."""

    # the API's model writes it as the kind's union of "unknown", KnownCalibration and IntrinsicsIn
    intrinsics: dict = option(default_factory=dict, description=(
        '"unknown" (ranges from the image size), {"K": 3x3}, or ranges'))
    autocalibration: str = option("stratified", choices=AUTOCALIBRATION_METHODS)
    metric_rel_gap: float = option(1e-4, **RANGES["metric_rel_gap"])
    autocalibration_rel_gap: float = option(1e-5, **RANGES["autocalibration_rel_gap"])
    autocalibration_max_nodes: int = option(20_000, **RANGES["autocalibration_max_nodes"])
    autocalibration_time_limit_s: float = option(60.0, **RANGES["autocalibration_time_limit_s"])
    # points whose chirality bounds the plane at infinity
    autocalibration_points: int = option(300, **RANGES["autocalibration_points"])
    # "skip": no certified upgrade search when the linear estimate's motion is critical (the tracks
    # do not determine K there; the adjustment starts from the linear estimate); "search": run it.
    autocalibration_on_critical_motion: str = option("skip", choices=run_control.ON_CRITICAL_MOTION, description=(
        '"skip": no certified upgrade search when the linear estimate\'s motion is critical (a turntable, an orbit, '
        'a translating camera: the tracks do not determine K); "search": run it anyway'))
    chirality: str = option("centers", choices=CHIRALITY)  # the direct method's
    # an observation farther than this from its reprojection is an outlier
    threshold_px: float = option(2.0, **RANGES["threshold_px"], description="outlier threshold, pixels")
    min_inliers: int = option(12, **RANGES["min_inliers"])  # 3D-2D inliers a view needs to register
    bundle_adjustment: bool = option(True)  # a metric bundle adjustment before the certified structure
    # The adjustment's calibration: "simple" one focal length (square pixels, no skew, the principal
    # point at the image centre), "varying" one focal length per view (the same otherwise), "full"
    # one K with all five entries free.
    camera_model: str = option("simple", choices=CAMERA_MODELS, description=(
        "the metric adjustment's calibration: one focal length (principal point at the image centre, square "
        "pixels), one per view, or one K with five free entries"))
    resect_cameras: bool = option(True)  # the certified resection of every camera
    # the resections' gap (a part of the returned camera's tolerance: camera_claim)
    camera_rel_gap: float = option(1e-2, **RANGES["camera_rel_gap"], description=(
        "each camera's resection's gap, a part of the returned camera's tolerance"))
    # False: no certified resection for a camera that cannot be certified (a point behind it, or a
    # free 3x4 camera found locally beats it by more than its tolerance); True: every camera's bound.
    bound_every_camera: bool = option(False, description=(
        "false: no certified resection for a camera a free camera found locally proves uncertifiable (it is "
        "reported without a bound)"))
    # Photos only: stage 1's matching (FeatureOptions' declared options; the API's model is built
    # from them, each null when not given).
    features: dict = option(default_factory=dict, wire=FeatureOptions)
    # K known only: when the views split into groups that do not register from one start, start
    # again among the unregistered views and merge (calibrated.CalibratedOptions.merge_components).
    # Off by default, as guided matching is: the Middlebury ring needs both to register 14 of 14
    # views within a degree, and its figures depend on them (bench/reconstruction_images.py).
    merge_components: bool = option(False, description=(
        "K known only: views that do not register from the first start are reconstructed from a second start "
        "and merged"))
    # K unknown: how the views are registered. "incremental", COLMAP's way: the K-known path from a
    # prior focal length (focal_prior_px, or focal_prior_factor times the larger image side, COLMAP's
    # default 1.2), refined by its adjustments as views are placed and by a bundle adjustment after,
    # the path run again from it when that moved it (at most focal_prior_rounds times); its cameras
    # then go to the certified upgrade as a projective
    # reconstruction. "projective": a projective reconstruction from the tracks alone (projective.py).
    registration: str = option("incremental", choices=REGISTRATIONS, description=(
        'K unknown: "incremental" (COLMAP\'s way: the K-known path from a prior focal length, refined by bundle '
        'adjustment; its cameras start the certified upgrade) or "projective" (a projective reconstruction from the '
        'tracks alone)'))
    # K unknown, camera_model "simple": "auto" frees the principal point in the adjustment when the
    # data fix it (a chi-square test on the cost it saves; pipeline._principal_point), "per_view"
    # (the default) as "auto", then a principal point for each view when the data fix them (the
    # same test for their 2 (views - 1) parameters, and each fixed to 5 px:
    # pipeline._principal_points_per_view; a stabilised lens shifts it from shot to shot: Sceaux's
    # cameras certified 9 of 11 instead of 4, the Middlebury sparse rings unchanged), "centre"
    # holds it at the image centre (COLMAP's default).
    principal_point: str = option("per_view", choices=run_control.PRINCIPAL_POINTS, description=(
        'K unknown, camera_model "simple": "auto" frees the principal point when the data fix it (a chi-square '
        'test), "per_view" (the default) as "auto" and then one for each view when the data fix them (the same '
        'test, and each view\'s fixed to 5 px), "centre" holds it at the image centre'))
    # K unknown, "incremental": one radial distortion term k1 (COLMAP's SIMPLE_RADIAL) estimated with
    # the focal length. "auto" (the default) keeps it when the data fix it (a chi-square test on the
    # cost it saves; pipeline._radial_test), "on" always, "off" never. "auto" brings Sceaux's focal
    # length within 3% (COLMAP's +2.3%) and keeps no term on the rings, at the CPU of the test's
    # adjustments (bench/results/reconstruction_vs_colmap.md). When kept, the observations are undistorted
    # with it before the metric stages: every certificate is conditional on that k1. K known: one
    # k1 about K's principal point, K held as given, by the same test (pipeline._fixed_radial_test).
    radial_distortion: str = option("auto", choices=RADIAL_DISTORTIONS, description=(
        'K unknown, "incremental": one radial distortion term k1 (COLMAP\'s SIMPLE_RADIAL) with the focal length; '
        '"auto" keeps it when the data fix it (a chi-square test); K known: one k1 about K\'s principal point, K '
        'held as given, by the same test. When kept, the observations are undistorted with it before the metric '
        'stages, and every certificate is conditional on that k1'))
    focal_prior_px: float | None = option(None, gt=0, le=run_control.FOCAL_PRIOR_LIMIT, description=(
        '"incremental": the prior focal length (pixels; a prior, refined, not a fact: e.g. from the photos\' EXIF)'))
    focal_prior_factor: float = option(1.2, **RANGES["focal_prior_factor"], description=(
        '"incremental" without focal_prior_px: the prior focal length as this times the larger image side '
        '(COLMAP\'s 1.2)'))
    focal_prior_rounds: int = option(3, **RANGES["focal_prior_rounds"], description=(
        '"incremental": runs from a refined focal length, at most'))
    time_limit_s: float = redeclared(SearchOptions, "time_limit_s", 10.0, bounds=RANGES["time_limit_s"],
                                     description="per point and per camera")
    # The certified points and cameras together (each also within time_limit_s): past it the
    # searches running stop at their next check, the tracks and cameras not started are left out,
    # and the stages say time_limit. With the other stages' limits it bounds the job's length.
    structure_time_limit_s: float = option(600.0, **RANGES["structure_time_limit_s"], description=(
        "seconds for the certified points and cameras together: past it the tracks and cameras not yet done are "
        "left out and the structure and cameras stages say time_limit"))
    seed: int = option(0, **RANGES["seed"])
    # The structure stage's search options (FractionalOptions'), with the reconstruction's caps
    # (run_control.RANGES) and words; it takes no ``detail``.
    rel_gap: float = redeclared(SearchOptions, "rel_gap", bounds=RANGES["rel_gap"],
                                description="each point's certified solve")
    abs_gap: float = redeclared(SearchOptions, "abs_gap", bounds=RANGES["abs_gap"], description=None)
    max_nodes: int = redeclared(SearchOptions, "max_nodes", bounds=RANGES["max_nodes"],
                                description="per point and per camera")
    max_residual: float | None = redeclared(ResidualOptions, "max_residual",
                                            description="pixels; narrows the scope")
    detail: str = redeclared(FractionalOptions, "detail", api=False)

    # What a user may set of stage 1's matching, and where (for untextured objects: fainter
    # keypoints, a looser ratio test, a wider epipolar threshold, guided matching): FeatureOptions'
    # declarations.
    FEATURE_RANGES = option_ranges(FeatureOptions)
    FEATURE_INTEGERS = tuple(name for name in option_ranges(FeatureOptions)
                             if FeatureOptions.__dataclass_fields__[name].type == "int")
    # Stage 1's options that are not numbers: their allowed values.
    FEATURE_CHOICES = {"pairs": PAIR_RULES, "ring": (True, False)}

    def check(self) -> None:
        FractionalOptions.check(self)
        if isinstance(self.intrinsics, dict):  # ranges not given (null, as the API's model writes them) are absent
            self.intrinsics = {name: value for name, value in self.intrinsics.items() if value is not None}
        if self.camera_model not in CAMERA_MODELS:
            raise InputError("options/camera_model", f"must be one of {', '.join(CAMERA_MODELS)}")
        if self.autocalibration_on_critical_motion not in run_control.ON_CRITICAL_MOTION:
            raise InputError("options/autocalibration_on_critical_motion", 'must be "skip" or "search"')
        if self.autocalibration not in AUTOCALIBRATION_METHODS:
            raise InputError("options/autocalibration", f"must be one of {', '.join(AUTOCALIBRATION_METHODS)}")
        if self.principal_point not in run_control.PRINCIPAL_POINTS:
            raise InputError("options/principal_point", 'must be "auto", "per_view" or "centre"')
        if self.radial_distortion not in RADIAL_DISTORTIONS:
            raise InputError("options/radial_distortion", f"must be one of {', '.join(RADIAL_DISTORTIONS)}")
        if self.registration not in REGISTRATIONS:
            raise InputError("options/registration", f"must be one of {', '.join(REGISTRATIONS)}")
        if self.focal_prior_px is not None and not (isinstance(self.focal_prior_px, (int, float))
                                                    and math.isfinite(self.focal_prior_px)
                                                    and 0 < self.focal_prior_px <= run_control.FOCAL_PRIOR_LIMIT):
            raise InputError("options/focal_prior_px", f"must be a positive number of pixels (at most "
                                                       f"{run_control.FOCAL_PRIOR_LIMIT:g}, as a focal range's ends), "
                                                       "or null")
        for name in ("metric_rel_gap", "camera_rel_gap", "autocalibration_rel_gap", "autocalibration_max_nodes",
                     "autocalibration_time_limit_s", "structure_time_limit_s", "autocalibration_points", "threshold_px", "min_inliers",
                     "focal_prior_factor", "focal_prior_rounds", "seed"):
            value, bounds = getattr(self, name), self.OPTION_RANGES[name]
            if not (math.isfinite(value) and value >= bounds.get("ge", -math.inf) and value > bounds.get("gt", -math.inf)
                    and value <= bounds.get("le", math.inf)):
                raise InputError(f"options/{name}", f"must be a finite number within {bounds}")
        self.known_K()  # validates {"K": ...}
        self.feature_options()  # validates the matching's
        self.autocalibration_options().check()  # validates the ranges and the direct method's options

    def feature_options(self):
        """Stage 1's options: FeatureOptions with the ones given in ``features`` (None: default)."""
        if not isinstance(self.features, dict):
            raise InputError("options/features", "must be an object")
        given = {name: value for name, value in self.features.items() if value is not None}
        for name, value in given.items():
            if name in self.FEATURE_CHOICES:
                if not any(value is choice or (isinstance(value, str) and value == choice)
                           for choice in self.FEATURE_CHOICES[name]):
                    raise InputError(f"options/features/{name}",
                                     f"must be one of {', '.join(map(str, self.FEATURE_CHOICES[name]))}")
                continue
            bounds = self.FEATURE_RANGES.get(name)
            if bounds is None:
                known = [*self.FEATURE_RANGES, *self.FEATURE_CHOICES]
                raise InputError(f"options/features/{name}", f"unknown (known: {', '.join(known)})")
            integer = name in self.FEATURE_INTEGERS
            if (isinstance(value, bool) or not isinstance(value, int if integer else (int, float))
                    or not math.isfinite(value) or not (value >= bounds.get("ge", -math.inf)
                                                        and value > bounds.get("gt", -math.inf)
                                                        and value <= bounds.get("le", math.inf)
                                                        and value < bounds.get("lt", math.inf))):
                raise InputError(f"options/features/{name}",
                                 f"must be {'an integer' if integer else 'a finite number'} within {bounds}")
        return FeatureOptions(**given)

    def known_K(self) -> np.ndarray | None:
        if self.intrinsics == "unknown" or not isinstance(self.intrinsics, dict) or "K" not in self.intrinsics:
            if not (self.intrinsics == "unknown" or isinstance(self.intrinsics, dict)):
                raise InputError("options/intrinsics", 'must be "unknown", {"K": 3x3} or the ranges of autocalibration')
            return None
        if set(self.intrinsics) != {"K"}:
            raise InputError("options/intrinsics", 'give either {"K": 3x3} or ranges, not both')
        K = self.intrinsics["K"]
        ok = (isinstance(K, list) and len(K) == 3 and all(isinstance(r, list) and len(r) == 3 for r in K)
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for r in K for x in r))
        if not ok:
            raise InputError("options/intrinsics/K", "must be a 3x3 matrix of finite numbers")
        K = np.array(K, dtype=float)
        if not (K[0, 0] > 0 and K[1, 1] > 0 and K[1, 0] == 0 and K[2, 0] == 0 and K[2, 1] == 0 and K[2, 2] == 1):
            raise InputError("options/intrinsics/K", "must be upper triangular with a positive diagonal and K[2][2] = 1")
        return K

    def ranges(self, image_size=None) -> dict:
        """The intrinsics ranges the metric upgrade searches (none with a known K: the calibrated
        path needs no upgrade)."""
        if self.known_K() is not None or self.intrinsics == "unknown":
            return {}
        return dict(self.intrinsics)

    def autocalibration_options(self, image_size=None) -> AutocalibrationOptions:
        return AutocalibrationOptions(
            method="direct" if self.autocalibration == "direct" else "stratified",
            intrinsics=self.ranges(image_size), chirality=self.chirality, rel_gap=self.autocalibration_rel_gap,
            metric_rel_gap=self.metric_rel_gap, abs_gap=1e-12, max_nodes=self.autocalibration_max_nodes,
            time_limit_s=self.autocalibration_time_limit_s, certificate=self.certificate)
