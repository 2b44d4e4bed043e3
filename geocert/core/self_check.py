"""A certified result checked by the verifier before a solver returns it (GEOCERT_SELF_VERIFY=1),
without the solvers importing the verifier: the verifier sits above them (it imports what it
checks), so it installs its check here when it is imported (geocert.verify.checks does, and the
kinds import it), and a solver calls ``check``. The test suites run so; an operator may too, at
about twice the solve time."""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Callable


class SelfCheckFailed(AssertionError):
    """A certified result its own certificate does not prove (GEOCERT_SELF_VERIFY=1)."""


_check: Callable[[str, tuple, dict, dict], None] | None = None


def install(check: Callable[[str, tuple, dict, dict], None]) -> None:
    """The verifier's check of one claim: ``check(kind, arrays, options, claim)`` raises
    SelfCheckFailed when the claim does not verify."""
    global _check
    _check = check


def enabled() -> bool:
    return os.environ.get("GEOCERT_SELF_VERIFY") == "1"


def check(kind: str, arrays: tuple, options: dict, claim: dict) -> None:
    if _check is None:
        raise RuntimeError("GEOCERT_SELF_VERIFY=1 but no verifier is installed: import geocert.verify")
    _check(kind, arrays, options, claim)


def checked_solve(kind: str, arrays: tuple, options, solve: Callable, claim: Callable[[Any], dict]) -> Any:
    """``solve(options)``, self-checked when enabled: then it runs with a full certificate and the
    verifier checks a certified result's ``claim(result)``; the proof is kept only when the caller
    asked for it."""
    checking = enabled()
    run = dataclasses.replace(options, certificate="full") if checking else options
    result = solve(run)
    if checking and result.certified:
        check(kind, arrays, dataclasses.asdict(run), claim(result))
    if options.certificate != "full" and result.certificate is not None:
        result.certificate.proof = None
    return result
