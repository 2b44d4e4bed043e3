"""A result checked as a third party checks it: ``geocert verify`` in a child process, reading
only the result's file (the benches' --verify, and the tests of that)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path


def verify_result(result: dict, timeout_s: float) -> str:
    """``geocert verify`` on a result (its certificate full) in a child process, as a third party
    would check it: "yes", or "no" and the report's first reason."""
    geocert = Path(sys.executable).with_name("geocert")
    with tempfile.TemporaryDirectory(prefix="geocert-bench-") as work:
        path = Path(work) / "result.json"
        path.write_text(json.dumps(result))
        try:
            done = subprocess.run([str(geocert), "verify", "--compact", str(path)], capture_output=True, text=True,
                                  timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return f"no (verifier past {timeout_s:.0f} s)"
    if done.returncode == 0:
        return "yes"
    try:
        report = json.loads(done.stdout)
        reason = report.get("first_failure") or "a check failed"
    except json.JSONDecodeError:
        reason = (done.stderr or done.stdout).strip()[-200:]
    return f"no ({str(reason)[:200]})"
