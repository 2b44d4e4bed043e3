"""The reconstruction's options: the structure stage's search options (FractionalOptions: the
norm, gaps and limits of each certified triangulation and resection), the metric upgrade's, and
the projective stage's thresholds. Ranges are stated once, in OPTION_RANGES."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from geocert.solvers.autocalibration.problem import AutocalibrationOptions
from geocert.solvers.core.geometry import InputError
from geocert.solvers.fractional.options import FractionalOptions
from geocert.solvers.reconstruction import run_control

AUTOCALIBRATION_METHODS = ("stratified", "direct", "auto")
MAX_EXHAUSTIVE = 200  # images matched every pair with every other at most (19,900 pairs)
# The run-control options' ranges and words are stated in the solvers' layer, where the verifier
# reads them too (solvers.reconstruction.run_control).
CAMERA_MODELS, REGISTRATIONS, RADIAL_DISTORTIONS = run_control.CAMERA_MODELS, run_control.REGISTRATIONS, \
    run_control.RADIAL_DISTORTIONS


@dataclass
class ReconstructionOptions(FractionalOptions):
    """``intrinsics``: "unknown" (ranges from the image size, as autocalibration's defaults), the
    ranges themselves ({"focal", "aspect", "skew", "principal_point"}, pixels), or {"K": 3x3}
    (known calibration). ``rel_gap``, ``abs_gap``, ``max_nodes`` and ``time_limit_s`` apply to
    each track's and each camera's certified solve; the ``autocalibration_*`` options to each
    stage of the metric upgrade (its rel_gap the affine stage's, ``metric_rel_gap`` the metric
    stage's)."""

    intrinsics: dict = field(default_factory=dict)
    autocalibration: str = "stratified"
    metric_rel_gap: float = 1e-4
    autocalibration_rel_gap: float = 1e-5
    autocalibration_max_nodes: int = 20_000
    autocalibration_time_limit_s: float = 60.0
    autocalibration_points: int = 300  # points whose chirality bounds the plane at infinity
    # "skip": no certified upgrade search when the linear estimate's motion is critical (the tracks
    # do not determine K there; the adjustment starts from the linear estimate); "search": run it.
    autocalibration_on_critical_motion: str = "skip"
    chirality: str = "centers"  # the direct method's
    threshold_px: float = 2.0  # an observation farther than this from its reprojection is an outlier
    min_inliers: int = 12  # 3D-2D inliers a view needs to register
    bundle_adjustment: bool = True  # a metric bundle adjustment before the certified structure
    # The adjustment's calibration: "simple" one focal length (square pixels, no skew, the principal
    # point at the image centre), "varying" one focal length per view (the same otherwise), "full"
    # one K with all five entries free.
    camera_model: str = "simple"
    resect_cameras: bool = True  # the certified resection of every camera
    camera_rel_gap: float = 1e-2  # the resections' gap (a part of the returned camera's tolerance: camera_claim)
    # False: no certified resection for a camera that cannot be certified (a point behind it, or a
    # free 3x4 camera found locally beats it by more than its tolerance); True: every camera's bound.
    bound_every_camera: bool = False
    # Photos only: stage 1's matching (features.FeatureOptions; the names of FEATURE_RANGES).
    features: dict = field(default_factory=dict)
    # K known only: when the views split into groups that do not register from one start, start
    # again among the unregistered views and merge (calibrated.CalibratedOptions.merge_components).
    # Off by default, as guided matching is: the Middlebury ring needs both to register 14 of 14
    # views within a degree, and its figures depend on them (bench/reconstruction_images.py).
    merge_components: bool = False
    # K unknown: how the views are registered. "incremental", COLMAP's way: the K-known path from a
    # prior focal length (focal_prior_px, or focal_prior_factor times the larger image side, COLMAP's
    # default 1.2), refined by its adjustments as views are placed and by a bundle adjustment after,
    # the path run again from it when that moved it (at most focal_prior_rounds times); its cameras
    # then go to the certified upgrade as a projective
    # reconstruction. "projective": a projective reconstruction from the tracks alone (projective.py).
    registration: str = "incremental"
    # K unknown, camera_model "simple": "auto" frees the principal point in the adjustment when the
    # data fix it (a chi-square test on the cost it saves; pipeline._principal_point), "per_view"
    # (the default) as "auto", then a principal point for each view when the data fix them (the
    # same test for their 2 (views - 1) parameters, and each fixed to 5 px:
    # pipeline._principal_points_per_view; a stabilised lens shifts it from shot to shot: Sceaux's
    # cameras certified 9 of 11 instead of 4, the Middlebury sparse rings unchanged), "centre"
    # holds it at the image centre (COLMAP's default).
    principal_point: str = "per_view"
    # K unknown, "incremental": one radial distortion term k1 (COLMAP's SIMPLE_RADIAL) estimated with
    # the focal length. "auto" (the default) keeps it when the data fix it (a chi-square test on the
    # cost it saves; pipeline._radial_test), "on" always, "off" never. "auto" brings Sceaux's focal
    # length within 3% (COLMAP's +2.3%) and keeps no term on the rings, at the CPU of the test's
    # adjustments (docs/reconstruction-vs-colmap.md). When kept, the observations are undistorted
    # with it before the metric stages: every certificate is conditional on that k1. K known: one
    # k1 about K's principal point, K held as given, by the same test (pipeline._fixed_radial_test).
    radial_distortion: str = "auto"
    focal_prior_px: float | None = None
    focal_prior_factor: float = 1.2
    focal_prior_rounds: int = 3
    time_limit_s: float = 10.0
    # The certified points and cameras together (each also within time_limit_s): past it the
    # searches running stop at their next check, the tracks and cameras not started are left out,
    # and the stages say time_limit. With the other stages' limits it bounds the job's length.
    structure_time_limit_s: float = 600.0
    seed: int = 0

    # What a user may set of stage 1's matching, and where (for untextured objects: fainter
    # keypoints, a looser ratio test, a wider epipolar threshold, guided matching).
    FEATURE_RANGES = {"max_features": {"ge": 0, "le": 1_000_000}, "contrast_threshold": {"gt": 0, "le": 1},
                      "ratio": {"gt": 0, "le": 1}, "ransac_threshold_px": {"gt": 0, "le": 100},
                      "guided_ratio": {"ge": 0, "lt": 1}, "exhaustive_limit": {"ge": 2, "le": MAX_EXHAUSTIVE},
                      "retrieval_neighbours": {"ge": 1, "le": 1000}, "vocabulary_size": {"ge": 8, "le": 100_000},
                      "neighbour_window": {"ge": 1, "le": 1000}, "time_limit_s": {"gt": 0, "le": 3600}}
    FEATURE_INTEGERS = ("max_features", "exhaustive_limit", "retrieval_neighbours", "vocabulary_size",
                        "neighbour_window")
    # Stage 1's options that are not numbers: their allowed values.
    FEATURE_CHOICES = {"pairs": ("auto", "exhaustive", "retrieval", "sequential"), "ring": (True, False)}

    # (The gaps behind a certified point or camera are capped there: run_control.RANGES.)
    OPTION_RANGES = {**FractionalOptions.OPTION_RANGES, **run_control.RANGES}

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
            raise InputError("options/focal_prior_px", "must be a positive number of pixels (at most 1e6), or null")
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
        from geocert.pipelines.reconstruction.features import FeatureOptions

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
