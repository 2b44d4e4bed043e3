"""The estimators import nothing above them: no module of geocert/solvers imports the verifier,
the kinds, the app, the workers or the job runner (kinds call solvers, never the reverse), and
only core.conic imports the conic solver; only the conic boundary's modules (conic.py and
the hand-written back-ends beside it) name a back-end's status, each mapped to ours in conic.py. The
verifier (geocert/verify) imports nothing above it either: it finds each kind's adapter in its own
registry (verify/adapters.py), not the kinds', and no estimator: what it shares with the writers is
in geocert/formulations, which imports only geocert.core. The service's app asks the job store by name, never
through its Redis client, and neither do the workers."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "geocert"
ABOVE = ("geocert.kinds", "geocert.app", "geocert.workers", "geocert.jobs", "geocert.pipelines")
ABOVE_SOLVERS = ("geocert.verify", *ABOVE)
KNOWN: dict = {}


def imported(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names


def imports_above(folder: str, above: tuple) -> dict:
    """Each module of ``folder`` that imports a module of ``above``, with those it imports."""
    found = {}
    for path in sorted((ROOT / folder).rglob("*.py")):
        names = {name for name in imported(path) if name.startswith(above)}
        if names:
            found[str(path.relative_to(ROOT))] = names
    return found


STORE_CLIENTS = ("r", "binary")  # a JobStore's Redis clients (geocert/jobs/store/base.py)


def store_client_uses(folder: str) -> dict:
    """Each module of ``folder`` that names an attribute ``r`` or ``binary`` (a job store's Redis
    clients), with the lines where it does."""
    found = {}
    for path in sorted((ROOT / folder).rglob("*.py")):
        lines = sorted(node.lineno for node in ast.walk(ast.parse(path.read_text()))
                       if isinstance(node, ast.Attribute) and node.attr in STORE_CLIENTS)
        if lines:
            found[str(path.relative_to(ROOT))] = lines
    return found


def test_no_app_module_reaches_into_the_stores_redis_client():
    """Routes and app code ask the job store by name (``ping``, ``live_workers``, an upload's
    ``drop_upload``...), never through its Redis client (``store.r``, ``store.binary``)."""
    assert store_client_uses("app") == {}


def test_no_worker_module_reaches_into_the_stores_redis_client():
    """Workers too: the reaper's lock and stranded marks, a job's metrics, the webhook secret and
    Redis's answer are the store's named methods (``take_reaper_lock``, ``record_items``,
    ``webhook_secret``, ``ping``...), never ``store.r`` or ``store.binary``."""
    assert store_client_uses("workers") == {}


def test_the_shared_core_imports_nothing_above_it():
    """geocert.core lies below the formulations, the estimators and the verifier: it imports none (nor
    anything above them), so both may build on it without a circle."""
    assert imports_above("core", ("geocert.formulations", "geocert.solvers", *ABOVE_SOLVERS)) == {}


def test_no_solver_module_imports_a_layer_above_it():
    """The verifier included: a solver's self-check reaches it through core.self_check."""
    assert imports_above("solvers", ABOVE_SOLVERS) == KNOWN


def test_only_the_conic_boundary_talks_to_the_conic_solver():
    """One place builds Clarabel's solvers and reads its statuses (core.conic), so the
    map from its statuses to ours, where an inaccurate answer is never certified, is the only one."""
    talking = {str(path.relative_to(ROOT)) for path in sorted(ROOT.rglob("*.py"))
               if any(name == "clarabel" or name.startswith("clarabel.") for name in imported(path))}
    assert talking == {"core/conic.py"}


CONIC_BOUNDARY = {"core/conic.py", "core/interior_point.py", "core/barrier.py"}


def backend_statuses() -> dict[str, set[str]]:
    """conic.py's status maps (module-level dicts whose values are all ``ConicStatus.X``), by name,
    with their keys: every back-end's statuses."""
    maps = {}
    for node in ast.parse((ROOT / "core/conic.py").read_text()).body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict) and node.value.values and all(
                isinstance(v, ast.Attribute) and isinstance(v.value, ast.Name) and v.value.id == "ConicStatus"
                for v in node.value.values):
            maps[node.targets[0].id] = {key.value for key in node.value.keys}
    return maps


def test_only_the_conic_boundary_names_a_back_ends_status():
    """A module outside the boundary reads our statuses (ConicStatus) only: no string in its code
    (docstrings and comments aside) is a back-end's status, such as Clarabel's "AlmostSolved" or
    the interior-point method's "Solved", so conic.py's map is the one list of them."""
    names = set().union(*backend_statuses().values())
    assert {"Solved", "AlmostSolved", "MaxIterations"} <= names
    naming = {}
    for path in sorted(ROOT.rglob("*.py")):
        module = str(path.relative_to(ROOT))
        if module in CONIC_BOUNDARY:
            continue
        tree = ast.parse(path.read_text())
        docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                      if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
                      and node.body and isinstance(node.body[0], ast.Expr)}
        found = sorted({node.value for node in ast.walk(tree) if isinstance(node, ast.Constant)
                        and isinstance(node.value, str) and id(node) not in docstrings and node.value in names})
        if found:
            naming[module] = found
    assert naming == {}


def test_every_status_a_hand_written_back_end_ends_with_is_in_the_map():
    """The interior-point method's statuses (the strings it assigns to ``status``) and the
    barrier's endings are exactly the keys of their maps in conic.py: a new one not mapped fails
    here, rather than falling to FAILED unseen."""
    from geocert.core import barrier

    maps = backend_statuses()
    tree = ast.parse((ROOT / "core/interior_point.py").read_text())
    assigned = {node.value.value for node in ast.walk(tree) if isinstance(node, ast.Assign)
                and any(isinstance(t, ast.Name) and t.id == "status" for t in node.targets)
                and isinstance(node.value, ast.Constant)}
    assert assigned == maps["_INTERIOR_POINT_STATUS"]
    assert set(barrier.ENDINGS) == maps["_BARRIER_STATUS"]


def test_no_verifier_module_imports_a_layer_above_it():
    assert imports_above("verify", ABOVE) == {}


def test_the_verifier_imports_no_estimator():
    """The verifier imports nothing it checks: what it shares with the writers (programs, frames,
    proofs' forms and their checks) is in geocert/formulations, below both."""
    assert imports_above("verify", ("geocert.solvers",)) == {}


def test_the_formulations_import_nothing_above_them():
    """geocert/formulations lies below the estimators and the verifier alike, on geocert.core."""
    assert imports_above("formulations", ("geocert.solvers", *ABOVE_SOLVERS)) == {}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path, known: set) -> set[str]:
    """The modules of ``known`` that ``path`` imports: ``from a.b import c`` counts ``a.b.c`` when
    c is a module, and ``a.b`` always."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names & known


def test_no_solver_module_is_the_verifiers_alone():
    """What only the verifier reads is the verifier's: a module of geocert/solvers or
    geocert/formulations that no module but the verifier's imports belongs in geocert/verify,
    beside what it checks with."""
    paths = {module_name(path): path for path in sorted(ROOT.rglob("*.py"))}
    importers: dict = {name: set() for name in paths}
    for name, path in paths.items():
        for used in imported_modules(path, set(paths)) - {name}:
            importers[used].add(name)
    verifiers_alone = sorted(name for name, users in importers.items()
                             if name.startswith(("geocert.solvers.", "geocert.formulations.")) and users
                             and all(user.startswith("geocert.verify") for user in users))
    assert verifiers_alone == []


def test_a_solvers_self_check_is_the_verifiers(monkeypatch):
    """With GEOCERT_SELF_VERIFY=1 (the suites run so), a certified solve is checked by the verifier
    through the hook it installs: a verifier that refuses fails the solve."""
    import numpy as np
    import pytest

    from geocert.core import self_check
    from geocert.solvers.fractional.triangulation import triangulate

    cameras = np.array([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], [[1, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0]]],
                       dtype=float)
    points = np.array([[0.01, 0.02], [-0.19, 0.021]])
    monkeypatch.setenv("GEOCERT_SELF_VERIFY", "1")
    assert triangulate(cameras, points).certified
    installed, seen = self_check._check, []

    def refusing(kind, arrays, options, claim):
        seen.append(kind)
        raise self_check.SelfCheckFailed("refused")
    self_check.install(refusing)
    try:
        with pytest.raises(self_check.SelfCheckFailed):
            triangulate(cameras, points)
    finally:
        self_check.install(installed)
    assert seen == ["triangulation"]
    assert installed.__module__ == "geocert.verify.checks"


# The kind whose programs the verifier still assembles with scipy.sparse (the direct method's
# direct_relaxation.py and direct_sublevel.py) and whose stratified estimates it replays with
# scipy.optimize.least_squares (determinacy.refit): shared with the writers, not yet numpy alone.
# Every other kind's certificates verify with numpy alone (bilinear's relaxations are built on
# core/csc.py for the verifier; metric cameras are split by problem.rq, on numpy's QR).
SCIPY_KINDS = ("autocalibration",)


def test_the_verifier_checks_every_kind_without_the_service():
    """A third party's verifier: stored certificates of every certifying kind verify, and a
    stereo_lines document is refused saying why, without geocert.kinds (or anything above the
    solvers) ever imported, nor a conic solver or OpenCV; and those of every kind but
    SCIPY_KINDS without scipy."""
    import subprocess
    import sys

    code = """
import json, sys
from pathlib import Path
from geocert.verify.checks import verify_any
SCIPY_KINDS = %r
folder = Path("tests/data/certificates")
names = sorted(p.stem for p in folder.glob("*.json") if not p.stem.startswith("make"))
names.sort(key=lambda name: name.startswith(SCIPY_KINDS))  # the numpy-only kinds first
def loaded():
    return sorted({m.split(".")[0] for m in sys.modules} & {"scipy", "clarabel", "cv2"})
valid, numpy_only = {}, None
for name in names:
    if numpy_only is None and name.startswith(SCIPY_KINDS):
        numpy_only = loaded()
    valid[name] = verify_any(json.loads((folder / f"{name}.json").read_text())).valid
estimate = verify_any({"kind": "stereo_lines", "status": "estimate", "pairs": []})
above = sorted({m.split(".")[1] for m in sys.modules if m.startswith("geocert.") and m.split(".")[1] in
                ("kinds", "app", "workers", "jobs", "pipelines")})
print(json.dumps({"valid": valid, "estimate": estimate.first_failure, "above": above,
                  "numpy_only": numpy_only, "loaded": loaded()}))
""" % (SCIPY_KINDS,)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT.parent)
    assert out.returncode == 0, out.stderr[-2000:]
    import json

    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(seen["valid"]) >= 7 and all(seen["valid"].values()), seen["valid"]
    assert seen["estimate"]["check"] == "format" and "never certified" in seen["estimate"]["detail"]
    assert seen["above"] == []
    assert seen["numpy_only"] == []  # no scipy, conic solver or OpenCV for the numpy-only kinds
    assert "clarabel" not in seen["loaded"] and "cv2" not in seen["loaded"]


def test_a_stratified_certificate_verifies_with_numpy_alone():
    """The stratified method's proofs and its metric cameras (split by problem.rq on numpy's QR)
    need no scipy: a stored stratified certificate whose estimates walk no plane family verifies
    with scipy never imported."""
    import json
    import subprocess
    import sys

    code = """
import json, sys
from pathlib import Path
from geocert.verify.checks import verify_any
document = json.loads(Path("tests/data/certificates/autocalibration_stratified.json").read_text())
report = verify_any(document)
print(json.dumps({"valid": report.valid, "method": document.get("method"),
                  "scipy": sorted(m for m in sys.modules if m == "scipy" or m.startswith("scipy."))[:3]}))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT.parent)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen == {"valid": True, "method": "stratified", "scipy": []}


def test_a_served_kind_registered_with_another_contract_is_refused():
    import dataclasses

    import pytest

    from geocert.verify.adapters import VERIFIED_KINDS, register

    known = VERIFIED_KINDS["triangulation"]
    assert register(known) is known
    with pytest.raises(ValueError):
        register(dataclasses.replace(known, item_key="points"))
    assert VERIFIED_KINDS["triangulation"] is known


def test_the_verifiers_result_members_are_the_kinds_result_models():
    """The members the verifier lets a result hold (VerifiedKind.members) are its kind's result
    model's, one level down included; a model with one more member is refused at registration."""
    import dataclasses

    import pytest
    from pydantic import create_model

    from geocert.kinds import KINDS
    from geocert.kinds.base import result_members
    from geocert.verify.adapters import VERIFIED_KINDS, register

    for kind in KINDS:
        expected = result_members(kind.result_model) if kind.certifies else ()
        assert VERIFIED_KINDS[kind.name].members == expected, kind.name
    model = KINDS.get("triangulation").result_model
    wider = create_model("WiderResult", __base__=model, certified=(bool, True))
    known = VERIFIED_KINDS["triangulation"]
    with pytest.raises(ValueError):
        register(dataclasses.replace(known, members=result_members(wider)))


def test_tests_and_benches_share_code_through_testing_only():
    """What tests and benches share lives in testing/ (not installed): no test imports a bench,
    no bench a test, and testing/ neither."""
    found = {}
    for folder, forbidden in (("tests", ("bench",)), ("bench", ("tests",)), ("testing", ("tests", "bench"))):
        for path in sorted((ROOT.parent / folder).rglob("*.py")):
            names = {name for name in imported(path) if name.split(".")[0] in forbidden}
            if names:
                found[str(path.relative_to(ROOT.parent))] = names
    assert found == {}
