"""Why an autocalibration stage's proven intervals, asked for, are null: its determinacy's
``proven_reason``, in one of these forms of words only. The writers (kinds.autocalibration,
kinds.autocalibration_stages, kinds.direct_autocalibration) state ``reason(key, ...)``; the
verifier (verify.estimates.check_proven_reason) accepts a text only where ``is_reason`` finds it
one of them, its fields each of its own kind (a number where the template has one, a status's
word, a name from a closed set): free text reading as a proof ("proven: every intrinsic within
0.01%") is no reason its writer gives (review 63 class 2)."""

from __future__ import annotations

import re

# The direct method's proofs: of one focal length or of each view's
WHAT = ("the focal length", "each view's focal length")
AFTER = ("", " (the other intrinsics' proofs, asked for, come after it and were not started)")
# A proof's linear algebra failing: the exception's class, its message left out (free text)
ERRORS = ("ValueError", "ArithmeticError", "ZeroDivisionError", "OverflowError", "FloatingPointError",
          "LinAlgError")

TEMPLATES = {
    "not_full": ("proven intervals are read off the proof's duals, which only a full certificate carries: ask "
                 "certificate 'full'"),
    "not_certified": "the stage is not certified (status {status}): there is no proof to read intervals from",
    # the stratified metric stage's (kinds.autocalibration)
    "metric_late": ("the job's time limit (options.time_limit_s) had passed before the proof of K's intervals could "
                    "start: the solve and its determinacy took it"),
    "metric_no_level": "the stage states no cost or no cost increase to prove intervals at (its analysis did not finish)",
    "metric_failed": "the proof of K's intervals failed ({error})",
    "metric_none": ("the search for K's intervals proved none within its {seconds} s (the least of the job's time "
                    "limit, 20 s and the time left): no finite level, a tightening that failed, or a proof its own "
                    "check refused"),
    # the direct method's (kinds.direct_autocalibration)
    "direct_late": ("the job's time limit (options.time_limit_s) had passed before the proof of {what}'s interval "
                    "could start: the solve and its determinacy took it{after}"),
    "direct_stopped": ("the job's time limit (options.time_limit_s) ran out {seconds} s into the proof of {what}'s "
                       "interval, before it finished: nothing was proven{after}"),
    "direct_failed": "the proof of {what}'s interval failed ({error}){after}",
    "direct_none": ("no dual of {what}'s interval programs proved an end (their solves stalled, or no safe bound was "
                    "above 0){after}"),
}
# The stratified metric stage's proof searches at most this long (kinds.autocalibration: the least of the
# job's time limit, this and the time left), the number its "metric_none" reason states
METRIC_PROOF_S = 20.0
# The stages' determinacy analyses and the direct proof run this long past the job's time limit
# (kinds.autocalibration_stages): the direct proof's deadline, which "direct_stopped" measures from
ANALYSIS_GRACE_S = 2.0
# Which a stage may state: the stratified metric stage's, the direct stage's
STRATIFIED = ("not_full", "not_certified", "metric_late", "metric_no_level", "metric_failed", "metric_none")
DIRECT = ("not_full", "not_certified", "direct_late", "direct_stopped", "direct_failed", "direct_none")

_NUMBER = r"(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:e[+-][0-9]+)?"  # a "{:.3g}" of a number at least 0
FIELDS = {"status": r"[a-z_]+", "seconds": _NUMBER, "error": "|".join(map(re.escape, ERRORS)),
          "what": "|".join(map(re.escape, WHAT)), "after": "|".join(map(re.escape, AFTER))}


def error_name(exc: BaseException) -> str:
    """The exception's class as a reason names it: the first of ERRORS among its classes."""
    return next((c.__name__ for c in type(exc).__mro__ if c.__name__ in ERRORS), "ArithmeticError")


def reason(key: str, **fields) -> str:
    """The text of TEMPLATES[key] with its fields (``seconds`` a number, written as "{:.3g}")."""
    if "seconds" in fields:
        fields["seconds"] = f"{max(float(fields['seconds']), 0.0):.3g}"
    return TEMPLATES[key].format(**fields)


def _pattern(template: str) -> re.Pattern:
    parts = re.split(r"\{(\w+)\}", template)
    return re.compile("".join(re.escape(part) if k % 2 == 0 else f"(?P<{part}>{FIELDS[part]})"
                              for k, part in enumerate(parts)))


PATTERNS = {key: _pattern(template) for key, template in TEMPLATES.items()}


def is_reason(text: object, keys: tuple[str, ...]) -> str | None:
    """The key of the template among ``keys`` that ``text`` is, whole (None: none is)."""
    if not isinstance(text, str):
        return None
    return next((key for key in keys if PATTERNS[key].fullmatch(text)), None)


def fields(text: str, key: str) -> dict[str, str]:
    """The fields of ``text``, a reason of TEMPLATES[key] (is_reason), as written."""
    found = PATTERNS[key].fullmatch(text)
    return {} if found is None else found.groupdict()
