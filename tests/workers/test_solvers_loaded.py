"""A solver process loads the kinds' solvers and their formulations as it starts
(workers.signals.SOLVER_MODULES), not at its first task: after that, the imports the kinds make
when they solve load nothing more."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

KINDS = Path(__file__).resolve().parents[2] / "geocert" / "kinds"
NUMERICS = ("geocert.solvers", "geocert.formulations")  # what a kind imports when it solves


def lazy_solver_imports() -> list[str]:
    """The ``from geocert.solvers... import ...`` and ``from geocert.formulations... import ...``
    statements inside the kinds' functions."""
    found = set()
    for path in sorted(KINDS.glob("*.py")):
        for function in ast.walk(ast.parse(path.read_text())):
            if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for node in ast.walk(function):
                    if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(NUMERICS):
                        found.add(ast.unparse(node))
    return sorted(found)


_CHECK = """
import json, sys
from geocert.workers import signals
signals._solvers_loaded()
NUMERICS = ("geocert.solvers", "geocert.formulations")
loaded = {name for name in sys.modules if name.startswith(NUMERICS)}
added = {}
for statement in json.loads(sys.argv[1]):
    exec(statement, {})
    new = sorted({name for name in sys.modules if name.startswith(NUMERICS)} - loaded)
    if new:
        added[statement] = new
        loaded.update(new)
print(json.dumps({"added": added, "listed_loaded": all(name in sys.modules for name in signals.SOLVER_MODULES)}))
"""


def test_the_kinds_solver_imports_find_their_modules_loaded_at_the_solver_process_start(tmp_path):
    statements = lazy_solver_imports()
    assert any("many_tracks" in statement for statement in statements)  # the scan sees them
    out = subprocess.run([sys.executable, "-c", _CHECK, json.dumps(statements)], capture_output=True, text=True,
                         timeout=300, env={"GEOCERT_REDIS_URL": f"unix://{tmp_path}/none.sock", "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["listed_loaded"]
    assert seen["added"] == {}, "kinds import solver modules not loaded at the solver process's start " \
                                "(add them to workers.signals.SOLVER_MODULES)"


_FROZEN = """
import gc, json
from geocert.workers import signals
before = gc.get_freeze_count()
signals._solvers_loaded()
print(json.dumps({"before": before, "after": gc.get_freeze_count(), "enabled": gc.isenabled()}))
"""


def test_a_solver_process_start_up_heap_is_frozen_out_of_the_collector(tmp_path):
    """Once its solvers are loaded, what a solver process holds leaves the cyclic collector's
    generations (gc.freeze): its collections then scan only what the tasks make; the collector
    itself stays on, for the cycles tasks make."""
    out = subprocess.run([sys.executable, "-c", _FROZEN], capture_output=True, text=True, timeout=300,
                         env={"GEOCERT_REDIS_URL": f"unix://{tmp_path}/none.sock", "PATH": "/usr/bin:/bin",
                              "PYTHONPATH": os.environ.get("PYTHONPATH", "")})
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["before"] == 0
    assert seen["after"] > 10_000  # the modules' objects, not a handful
    assert seen["enabled"]
