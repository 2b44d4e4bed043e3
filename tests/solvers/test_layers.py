"""The estimators import nothing above them: no module of geocert/solvers imports the kinds, the
app, the workers or the job runner (kinds call solvers, never the reverse). The verifier's module
(solvers/verify.py) still finds each kind's adapter through the kinds' registry: the one exception,
listed here until the verifier has a registry of its own."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2] / "geocert"
ABOVE = ("geocert.kinds", "geocert.app", "geocert.workers", "geocert.batch", "geocert.service", "geocert.pipelines")
KNOWN = {"solvers/verify.py": {"geocert.kinds"}}


def imported(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names


def test_no_solver_module_imports_a_layer_above_it():
    found = {}
    for path in sorted((ROOT / "solvers").rglob("*.py")):
        above = {name for name in imported(path) if name.startswith(ABOVE)}
        if above:
            found[str(path.relative_to(ROOT))] = above
    assert found == KNOWN
