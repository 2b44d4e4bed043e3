"""The options a reconstruction's problem_sha256 covers (numpy only, the verifier's).

A reconstruction's claims and checks read more than the points' options (norm, max_residual,
rel_gap, abs_gap): ``camera_rel_gap`` gives every certified camera's tolerance, ``intrinsics`` a
known K (the returned K's source) and the ranges the calibration certificate searched,
``radial_distortion`` whether a radial term may be stated, and ``autocalibration``,
``autocalibration_rel_gap`` and ``metric_rel_gap`` the calibration certificate's method and gaps.
The hash covers them all (CLAIM_OPTIONS), so a user hashing their own request learns that the
document is about their tolerance too.

Documents written before it covered them (format version 2, the earlier form: the points' four
options only) still verify, as a third party's stored certificates must: such a document cannot
be told from one whose camera_rel_gap (or another option the form leaves out) was changed after it
was written, so the report's scope states that the hash does not cover those options and what the
document states for each, for the user to compare with their request. Every claim is then read at
the values stated (a certified camera's tolerance from the camera_rel_gap stated, which its camera
certificate must prove), so what the report says is true of the document.

The second form (CLAIM_OPTIONS but resect_cameras, bundle_adjustment, camera_model and
principal_point: SECOND_CLAIM_OPTIONS) left out the options that decide whether the cameras stage
and the adjustment run, and those choosing the camera model whose intrinsics each camera's
tolerance counts: a cameras stage a cancel stopped could be restated "skipped" by resect_cameras,
the echo restated false, and the hash stayed the request's. The hash covers them since
(CLAIM_OPTIONS); documents of the second
form still verify, as those of the first do, the report's scope stating what the document states
for each option its form leaves out (check_earlier_form: the first form's scope lists both sets).
The third form (THIRD_CLAIM_OPTIONS) left out ``registration``; the hash covers it since, and
the pipeline of that form states the registration's principal-point record wherever its test runs
(states_records, with the certificate data's input_labels and the autocalibration stage's
cameras_built_with_one_K): a document of the third form or earlier may lack it, and is read
without it, its report's scope saying so (check_third_form; the calibration tie's
registration_record). A document of either of the first two forms also states no free camera for a camera judged uncertifiable by
one (the kind states it since the hash covers these options): that judgement is then unchecked,
and the report's scope says which cameras (verify.reconstruction).
"""

from __future__ import annotations

from typing import Any

from geocert.core.certificates import CLAIM_OPTIONS as EARLIER_CLAIM_OPTIONS
from geocert.core.strict import Invalid, number
from geocert.formulations.reconstruction.camera_claim import MAX_REL_GAP
from geocert.formulations.reconstruction.run_control import CAMERA_MODELS, PRINCIPAL_POINTS, REGISTRATIONS

# What the earlier form left out, at the value a request naming none of them got while that form
# was written (ReconstructionOptions' defaults then; tests/solvers/reconstruction/test_reconstruction_hash.py
# checks they agree but for radial_distortion, whose default became "auto" after that form).
EARLIER_DEFAULTS: dict[str, Any] = {"camera_rel_gap": 1e-2, "intrinsics": {}, "radial_distortion": "off",
                                    "autocalibration": "stratified", "autocalibration_rel_gap": 1e-5,
                                    "metric_rel_gap": 1e-4}
SECOND_CLAIM_OPTIONS = EARLIER_CLAIM_OPTIONS + tuple(EARLIER_DEFAULTS)
# What the second form left out, at the value a request naming none got while it was written: the
# options deciding whether a stage runs, and those choosing the camera model whose intrinsics the
# cameras' tolerances count (ReconstructionOptions' defaults then; tests/solvers/reconstruction/
# test_reconstruction_hash.py checks they agree but for principal_point, "per_view" since).
SECOND_DEFAULTS: dict[str, Any] = {"resect_cameras": True, "bundle_adjustment": True, "camera_model": "simple",
                                   "principal_point": "auto"}
THIRD_CLAIM_OPTIONS = SECOND_CLAIM_OPTIONS + tuple(SECOND_DEFAULTS)
# What the third form left out: ``registration``, which decides whether the registration tests the
# principal point (the incremental path only: pipeline._registration_principal_point) and so
# whether stages.projective.principal_point is stated. The pipeline states that record wherever
# its test runs since the hash covers it, so the form declares it: a document of this form
# lacking the record, where the test runs, is refused, while one of an earlier form was written
# before the record (or before it was always stated) and is read without it (verify.reconstruction:
# the calibration tie, and the report's scope, say so).
THIRD_DEFAULTS: dict[str, Any] = {"registration": "incremental"}
CLAIM_OPTIONS = THIRD_CLAIM_OPTIONS + tuple(THIRD_DEFAULTS)
RADIAL_DISTORTIONS = ("auto", "on", "off")
AUTOCALIBRATION_METHODS = ("stratified", "direct", "auto")


def checked(options: dict) -> dict:
    """The hashed options beyond the points', each of its type (a number, the words the kind
    takes, an object or "unknown" for intrinsics, true or false), as stated (absent: None)."""
    out: dict[str, Any] = {}
    for name in ("autocalibration_rel_gap", "metric_rel_gap"):
        if options.get(name) is not None:
            out[name] = number(options[name], f"options/{name}", "options")
            if not 0 <= out[name] <= MAX_REL_GAP:
                raise Invalid("options", f"options/{name} {out[name]!r} is beyond {MAX_REL_GAP}")
    for name, words in (("radial_distortion", RADIAL_DISTORTIONS), ("autocalibration", AUTOCALIBRATION_METHODS),
                        ("camera_model", CAMERA_MODELS), ("principal_point", PRINCIPAL_POINTS),
                        ("registration", REGISTRATIONS)):
        if options.get(name) is not None:
            if options[name] not in words:
                raise Invalid("options", f"options/{name} must be one of {', '.join(words)}, not {options[name]!r:.40}")
            out[name] = options[name]
    intrinsics = options.get("intrinsics")
    if intrinsics is not None and not (intrinsics == "unknown" or isinstance(intrinsics, dict)):
        raise Invalid("options", "options/intrinsics must be \"unknown\" or an object")
    if intrinsics is not None:
        out["intrinsics"] = intrinsics
    for name in ("resect_cameras", "bundle_adjustment"):
        if options.get(name) is not None:
            if not isinstance(options[name], bool):
                raise Invalid("options", f"options/{name}: must be true or false, got {options[name]!r:.40}")
            out[name] = options[name]
    return out


def _at_default(name: str, value: Any) -> bool:
    """Whether an option an earlier form leaves out is what a request naming none gets."""
    if value is None:  # absent: read as the earlier form read it
        return True
    if name == "intrinsics":  # ranges from the image size: "unknown", or no K and no range stated
        return value == "unknown" or (isinstance(value, dict) and all(v is None for v in value.values()))
    return value == {**EARLIER_DEFAULTS, **SECOND_DEFAULTS, **THIRD_DEFAULTS}[name]


def _stated(options: dict, defaults: dict) -> list[str]:
    """Each option of ``defaults`` as the document states it (absent: read as its default;
    camera_rel_gap absent is read as rel_gap, as documents from before it was an option are)."""
    stated = []
    for name in defaults:
        value = options.get(name)
        if name == "camera_rel_gap" and value is None:
            stated.append(f"camera_rel_gap absent, read as rel_gap {options['rel_gap']!r}")
        elif value is None:
            stated.append(f"{name} absent, read as {defaults[name]!r}")
        else:
            stated.append(f"{name} {value!r:.80}" + ("" if _at_default(name, value) else " (not its default)"))
    return stated


def check_earlier_form(options: dict) -> str:
    """What the report's scope says of a document hashed the earliest way (the points' four
    options only): the options that form does not cover, each as the document states it."""
    stated = _stated(options, {**EARLIER_DEFAULTS, **SECOND_DEFAULTS, **THIRD_DEFAULTS})
    return (f"the earlier form: it covers the kind, the data and {', '.join(EARLIER_CLAIM_OPTIONS)} only, not the "
            f"options these claims also read, nor those deciding whether the adjustment and the cameras stage run "
            f"or choosing the camera model the cameras' tolerances count, "
            f"which the document states as: {'; '.join(stated)}. Compare them with your request: a hash of this form "
            "does not tell them from values changed after it was written")


def check_second_form(options: dict) -> str:
    """What the report's scope says of a document hashed the second way (SECOND_CLAIM_OPTIONS):
    the options deciding whether a stage runs and choosing the camera model, which it does not
    cover, as the document states them."""
    stated = _stated(options, {**SECOND_DEFAULTS, **THIRD_DEFAULTS})
    return (f"the second form: it covers the kind, the data and {', '.join(SECOND_CLAIM_OPTIONS)}, not the options "
            f"deciding whether the adjustment and the cameras stage run, nor those choosing the camera model the "
            f"cameras' tolerances count, which the document states as: "
            f"{'; '.join(stated)}. Compare them with your request: a hash of this form does not tell them from values "
            "changed after it was written (a stage a stop ended, restated as skipped by its option)")


def check_third_form(options: dict) -> str:
    """What the report's scope says of a document hashed the third way (THIRD_CLAIM_OPTIONS):
    ``registration``, which it does not cover, as the document states it, and that such a document
    may lack the registration's principal-point record (written before it was always stated)."""
    stated = _stated(options, THIRD_DEFAULTS)
    return (f"the third form: it covers the kind, the data and {', '.join(THIRD_CLAIM_OPTIONS)}, not registration, "
            f"which the document states as: {'; '.join(stated)}. Compare it with your request. A document of this "
            "form was written before the pipeline stated the registration's principal-point test "
            "(stages.projective.principal_point) wherever it runs, so one lacking that record is read as a "
            "registration at the images' centre (the calibration tie's centred reference and its room: "
            "scope.calibration_tie.registration_record says when)")


# The earlier forms, newest first, each with what the report's scope says of it (verify.checks)
EARLIER_FORMS = ((THIRD_CLAIM_OPTIONS, check_third_form), (SECOND_CLAIM_OPTIONS, check_second_form),
                 (EARLIER_CLAIM_OPTIONS, check_earlier_form))


def states_free_cameras(hashed: tuple[str, ...]) -> bool:
    """Whether a document whose problem_sha256 covers ``hashed`` was written by a kind that states
    the free camera of every camera judged uncertifiable by one (those of THIRD_CLAIM_OPTIONS' form
    and later)."""
    return set(THIRD_CLAIM_OPTIONS) <= set(hashed)


def states_records(hashed: tuple[str, ...]) -> bool:
    """Whether a document of that form was written by a pipeline that states every record an
    earlier form may lack, which the verifier reads a document without more loosely (those of
    CLAIM_OPTIONS' form: the hash covers registration): the registration's principal-point record
    (stages.projective.principal_point) wherever its test runs, the certificate data's
    input_labels, and the autocalibration stage's cameras_built_with_one_K beside a calibration
    certificate. A document of this form lacking one is refused."""
    return set(CLAIM_OPTIONS) <= set(hashed)


def states_depth_reversal(hashed: tuple[str, ...]) -> bool:
    """Whether a document of that form was written by a kind that states the depth-reversal
    check's record (every form since the first)."""
    return set(SECOND_CLAIM_OPTIONS) <= set(hashed)


def check_calibration_options(calibration: dict, options: dict) -> None:
    """The calibration certificate was solved with the gaps and ranges the reconstruction's options
    (which its hash covers) ask for: its rel_gap the autocalibration_rel_gap, its metric_rel_gap
    the metric_rel_gap, its intrinsics the ranges (none for "unknown" or a known K). An option the
    reconstruction's document does not state is read as its default (every document the kind
    writes states them; the earlier form's hash does not cover their absence)."""
    stated = {name: default if options.get(name) is None else options[name] for name, default in EARLIER_DEFAULTS.items()}
    intrinsics = stated["intrinsics"]
    ranges = {} if intrinsics == "unknown" or "K" in intrinsics else intrinsics
    for name, expected in (("rel_gap", stated["autocalibration_rel_gap"]), ("metric_rel_gap", stated["metric_rel_gap"]),
                           ("intrinsics", ranges)):
        if calibration.get(name) != expected:
            raise Invalid("returned", f"the calibration certificate's {name} is {calibration.get(name)!r:.80}, the "
                                      f"reconstruction's options ask for {expected!r:.80}")
