"""A result's informational fields, typed (numpy free). docs/certificate.md: a field no check
reads is informational, "and each must be null or of its type (a finite number, an integer, a
string)", never a boolean where a number stands (JSON readers take true for 1 in arithmetic).
This module types those a result carries beside its items' own notes (verify._check_item_notes):
every determinacy estimate's members (proven and proven_intervals are read against the proof
elsewhere: fractional._check_proven, verify._check_estimates), the stats' times, and a reconstruction
camera's words: its reason and bound_reason (camera_misfit's diagnosis)."""

from __future__ import annotations

from typing import Any

from geocert.core.strict import Invalid, informational

# A determinacy document's members (core.determinacy.Determinacy.document) and their types; an
# interval's and a warning's.
DETERMINACY = {"method": "text", "level": "text", "cost_increase": "number", "redundancy": "integer"}
INTERVAL = {"name": "text", "value": "number", "lower": "number", "upper": "number", "tolerance": "number"}
WARNING = dict(code="text", detail="text")  # (not {"code": ...}: the warning-code scan reads that form)
STATS_TIMES = ("solve_s", "elapsed_s")
# A reconstruction camera's words: why it is not registered or certified, and its bound's diagnosis
CAMERA_WORDS = ("reason", "bound_reason")
# Members holding a certificate or its summary: read by the proof checks, not here.
CERTIFICATES = ("certificate", "camera_certificate", "calibration_certificate")


def check_notes(result: dict) -> None:
    """Refuse a result whose informational fields are not of their types (module docstring)."""
    _check_determinacies(result, "")
    stats = result.get("stats")
    if isinstance(stats, dict):
        for name in STATS_TIMES:
            if name in stats:
                _typed(stats[name], f"stats/{name}", "number")
    for index, camera in enumerate(result.get("cameras") or [] if isinstance(result.get("cameras"), list) else []):
        for name in CAMERA_WORDS:  # (kinds.reconstruction._camera: a string or null, each)
            if isinstance(camera, dict) and name in camera:
                _typed(camera[name], f"cameras/{index}/{name}", "text")


def _check_determinacies(value: Any, where: str) -> None:
    if isinstance(value, dict):
        for name, item in value.items():
            if name in CERTIFICATES:
                continue
            if name == "determinacy" and isinstance(item, dict):
                _check_determinacy(item, f"{where}{name}")
            elif name == "determinacy" and item is not None:
                # an object or null, as every writer gives it: any other value (true, a string, a
                # number, a list) was read by no check, the proven intervals' and the estimates' alike
                raise Invalid("returned", f"{where}{name} must be null or an object, got {item!r:.40}")
            else:
                _check_determinacies(item, f"{where}{name}/")
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _check_determinacies(item, f"{where}{index}/")


def _check_determinacy(determinacy: dict, where: str) -> None:
    for name, what in DETERMINACY.items():
        if name in determinacy:
            _typed(determinacy[name], f"{where}/{name}", what)
    if determinacy.get("determined") not in (None, True, False):
        raise Invalid("returned", f"{where}/determined must be null, true or false, "
                                  f"got {determinacy['determined']!r:.40}")
    for name, members in (("intervals", INTERVAL), ("warnings", WARNING)):
        entries = determinacy.get(name)
        if entries is None:
            continue
        if not (isinstance(entries, list) and all(isinstance(entry, dict) for entry in entries)):
            raise Invalid("returned", f"{where}/{name} must be null or a list of objects, got {entries!r:.40}")
        for index, entry in enumerate(entries):
            for member, what in members.items():
                if member in entry:
                    _typed(entry[member], f"{where}/{name}/{index}/{member}", what)


def _typed(value: Any, where: str, what: str) -> None:
    """strict.informational, its refusal counted under the check of what a result returns."""
    try:
        informational(value, where, what)
    except Invalid as exc:
        raise Invalid("returned", exc.detail) from exc
