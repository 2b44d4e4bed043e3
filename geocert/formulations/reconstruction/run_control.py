"""The reconstruction's run-control options (limits, thresholds, counts, switches) and their
ranges, stated once here: pipelines.reconstruction.options.ReconstructionOptions takes its
OPTION_RANGES from these (its check() applies them, the API's model is built from them), and the
verifier refuses a certificate whose options echo states one the solver would refuse. None is
hashed (no claim depends on them), yet a document stating a node limit of 0, a time limit of -60 s
or 1e300 s, or a seed of 0.5 states a run that never was. (The verifier's, numpy free.)"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

from geocert.core.geometry import MAX_INTRINSIC_PX, is_number
from geocert.core.strict import Invalid
from geocert.formulations.fractional.options import FractionalOptions, SearchOptions
from geocert.formulations.reconstruction import camera_claim

CAMERA_MODELS = ("simple", "varying", "full")
REGISTRATIONS = ("incremental", "projective")
RADIAL_DISTORTIONS = ("auto", "on", "off")
PRINCIPAL_POINTS = ("auto", "per_view", "centre")
ON_CRITICAL_MOTION = ("skip", "search")

# pydantic Field keywords per option: the search's max_nodes and time_limit_s (every search's),
# and the reconstruction's own (its gaps capped: at rel_gap 0.999 or abs_gap 1e6 "certified" would
# hold whatever an item costs).
RANGES = {**{name: SearchOptions.OPTION_RANGES[name] for name in ("max_nodes", "time_limit_s")},
          "metric_rel_gap": {"ge": 0, "le": camera_claim.MAX_REL_GAP},
          "rel_gap": {"ge": 0, "le": camera_claim.MAX_REL_GAP},
          "abs_gap": {"ge": 0, "le": camera_claim.MAX_ABS_GAP},
          "camera_rel_gap": {"ge": 0, "le": camera_claim.MAX_REL_GAP},
          "autocalibration_rel_gap": {"ge": 0, "le": camera_claim.MAX_REL_GAP},
          "autocalibration_max_nodes": {"ge": 1, "le": 1_000_000},
          "autocalibration_time_limit_s": {"gt": 0, "le": 3600},
          "structure_time_limit_s": {"gt": 0, "le": 3600},
          "autocalibration_points": {"ge": 10, "le": 100_000},
          "threshold_px": {"gt": 0, "le": 1000}, "min_inliers": {"ge": 6, "le": 100_000},
          "focal_prior_factor": {"gt": 0, "le": 100}, "focal_prior_rounds": {"ge": 1, "le": 10},
          "seed": {"ge": 0, "le": 2**31 - 1}}
INTEGERS = ("max_nodes", "autocalibration_max_nodes", "autocalibration_points", "min_inliers", "focal_prior_rounds",
            "seed")
# focal_prior_px, when given: a positive number of pixels at most the largest focal length a range
# or a known K may state (core.geometry.MAX_INTRINSIC_PX): a prior is a focal length like theirs,
# and a job whose range reaches that limit could not be given its prior there otherwise.
FOCAL_PRIOR_LIMIT = MAX_INTRINSIC_PX
FLAGS = ("bundle_adjustment", "resect_cameras", "bound_every_camera", "merge_components")
CHOICES = {"camera_model": CAMERA_MODELS, "registration": REGISTRATIONS, "radial_distortion": RADIAL_DISTORTIONS,
           "principal_point": PRINCIPAL_POINTS, "autocalibration_on_critical_motion": ON_CRITICAL_MOTION}


# Every option a reconstruction's certificate states: the fields of pipelines.reconstruction.options.
# ReconstructionOptions (certificate_document writes dataclasses.asdict of them; that class sits
# above the verifier, so they are named here, and tests/verify/test_option_names.py checks the two
# agree), the search options' (FractionalOptions) and the reconstruction's own. No option was
# renamed or removed since the first stored document: a document of an earlier form lacks some
# (radial_distortion), it states none outside these.
OPTION_NAMES = tuple(entry.name for entry in fields(FractionalOptions)) + (
    "intrinsics", "autocalibration", "metric_rel_gap", "autocalibration_rel_gap", "autocalibration_max_nodes",
    "autocalibration_time_limit_s", "autocalibration_points", "autocalibration_on_critical_motion", "chirality",
    "threshold_px", "min_inliers", "bundle_adjustment", "camera_model", "resect_cameras", "camera_rel_gap",
    "bound_every_camera", "features", "merge_components", "registration", "principal_point", "radial_distortion",
    "focal_prior_px", "focal_prior_factor", "focal_prior_rounds", "structure_time_limit_s", "seed")


def within(value: float, bounds: dict) -> bool:
    return (value >= bounds.get("ge", -math.inf) and value > bounds.get("gt", -math.inf)
            and value <= bounds.get("le", math.inf) and value < bounds.get("lt", math.inf))


def check(options: dict) -> None:
    """Refuse an options echo stating a run-control option the solver refuses (absent or null:
    the solver's default, not checked here; the gaps are checked as the claims read them)."""
    for name, bounds in RANGES.items():
        value = options.get(name)
        if value is None:
            continue
        if not (is_number(value) and within(float(value), bounds)):
            raise Invalid("options", f"options/{name}: must be a finite number within {bounds}, got {value!r:.40}")
        if name in INTEGERS and not float(value).is_integer():
            raise Invalid("options", f"options/{name}: must be an integer, got {value!r:.40}")
    prior = options.get("focal_prior_px")
    if prior is not None and not (is_number(prior) and 0 < prior <= FOCAL_PRIOR_LIMIT):
        raise Invalid("options", f"options/focal_prior_px: must be null or a positive number of pixels (at most "
                                 f"{FOCAL_PRIOR_LIMIT:g}), got {prior!r:.40}")
    for name in FLAGS:
        if options.get(name) is not None and not isinstance(options[name], bool):
            raise Invalid("options", f"options/{name}: must be true or false, got {options[name]!r:.40}")
    for name, words in CHOICES.items():
        value: Any = options.get(name)
        if value is not None and not (isinstance(value, str) and value in words):
            raise Invalid("options", f"options/{name}: must be one of {', '.join(words)}, got {value!r:.40}")
