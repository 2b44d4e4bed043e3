"""What a certificate of a kind whose cost is a norm of residuals (triangulation, resection,
homography, and the reconstruction's points) depends on and states: its options read strictly and
checked by the solver's own options class, and its scope in words. The verifier's, numpy only."""

from __future__ import annotations

from typing import Any

from geocert.core.certificates import BOUND_TOLERANCE, OBJECTIVE_TOLERANCE
from geocert.core.geometry import InputError
from geocert.core.strict import Invalid, number


# The options that control a run, not what it proves: not hashed, yet a document stating one the
# solver refuses (a node limit of 0, a time limit of -60 s or 1e300 s) states a run that never was.
RUN_CONTROL = ("max_nodes", "time_limit_s", "job_time_limit_s")


def checked_options(options_type: type, options: dict, run_control: bool = False) -> dict:
    """norm, gaps and max_residual, read strictly and validated as the solver validates them.
    ``run_control``: the run-control options the document states (RUN_CONTROL, those of
    ``options_type``) are validated with them, by its check() (the ranges its OPTION_RANGES state
    once, for the API's models too); they are not returned (no claim depends on them)."""
    norm = options.get("norm")
    if not isinstance(norm, str):
        raise Invalid("options", f"options/norm must be a string, got {norm!r:.40}")
    checked = {"norm": norm}
    for name in ("rel_gap", "abs_gap"):
        checked[name] = number(options.get(name), f"options/{name}", "options")
    max_residual = options.get("max_residual")
    checked["max_residual"] = None if max_residual is None else number(max_residual, "options/max_residual", "options")
    run = run_control_values(options_type, options) if run_control else {}
    try:
        options_type(**checked, **run).check()
    except InputError as exc:
        raise Invalid("options", f"{exc.field}: {exc.reason}") from exc
    return checked


def run_control_values(options_type: type, options: dict, names: tuple[str, ...] = RUN_CONTROL) -> dict:
    """The run-control options ``options`` states (of ``names``, those ``options_type`` has), read
    strictly: each a finite JSON number (not a boolean), a count (its default an int: max_nodes)
    a whole number, as the solver reads it. The caller passes them to ``options_type``'s check(),
    which applies its OPTION_RANGES (the bilinear and autocalibration kinds do so too)."""
    run = {name: number(options[name], f"options/{name}", "options") for name in names
           if name in options and hasattr(options_type, name)}
    for name, value in run.items():
        if type(getattr(options_type, name)) is int and not value.is_integer():
            raise Invalid("options", f"options/{name}: must be an integer, got {options[name]!r:.40}")
    return {name: int(value) if type(getattr(options_type, name)) is int else value for name, value in run.items()}


# Every limit on a run's work any kind's options state (the residual kinds' RUN_CONTROL, an
# autocalibration's, a reconstruction's stage limits): named in the report's scope, taken as stated.
RUN_LIMITS = RUN_CONTROL + ("autocalibration_max_nodes", "autocalibration_time_limit_s", "structure_time_limit_s")


def run_control_scope(options: Any) -> str | None:
    """What the report says of the run-control limits the document states (review 53): they are
    the request's, not hashed and checked for their ranges only, so nothing ties them to the proof
    (a max_nodes of 1 beside a proof of 30 leaves, a time limit of 5e-324 s beside a search that
    split its box, verify). No claim depends on them: a proof is checked whatever work found it, and
    a hash binds nothing a forger cannot make again. None where the document states none."""
    if not isinstance(options, dict):
        return None
    stated = [f"{name} {options[name]!r:.24}" for name in RUN_LIMITS if options.get(name) is not None]
    if not stated:
        return None
    return (f"taken as stated: {', '.join(stated)} are the request's run controls, not hashed and checked only "
            "for the ranges the solver accepts; they are not checked against the proof (its leaves, the items' "
            "nodes, statuses and times), so they say nothing of the work that found it, and no claim depends on "
            "them")


def scope(kind: str, domain: str, options: dict) -> dict:
    """What a valid certificate proves: no solution in the domain (narrowed by max_residual)
    costs less than each certified item's lower bound."""
    if options["max_residual"] is not None:
        domain += f" with every residual's length (pixel distance) at most {options['max_residual']!r}"
    return {"kind": kind, "norm": options["norm"], "max_residual": options["max_residual"],
            "rel_gap": options["rel_gap"], "abs_gap": options["abs_gap"],
            "statement": f"for each certified item: no solution in the scope ({domain}) costs less than "
                         f"lower_bound * (1 - {BOUND_TOLERANCE:g}); the solution returned is in the scope and "
                         f"costs cost (within a relative {OBJECTIVE_TOLERANCE:g})"}
