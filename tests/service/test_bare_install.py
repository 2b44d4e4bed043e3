"""The README's first command on a bare machine: the project installed WITHOUT extras into a new
virtual environment (nothing from the test extras to lean on), `geocert serve` started from it,
the README's example job solved over HTTP, and everything stopped. A runtime import that
`[project].dependencies` does not bring in makes the worker die, `/readyz` never answers ready,
and this test fails."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import httpx
import pytest

from tests.servers import free_port
from tests.support import ROOT

README_JOB = {
    "kind": "triangulation",
    "data": {"cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
                         [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]],
             "tracks": [{"views": [0, 1], "points": [[330, 250], [250, 251]]}]},
    "options": {"norm": "L2L2", "rel_gap": 1e-3},
}


def source_copy(root: Path, target: Path) -> Path:
    """What `pip install <checkout>` builds from: pyproject.toml, README.md and the packages it
    names (copied, so that the build leaves nothing in the checkout)."""
    project = tomllib.loads((root / "pyproject.toml").read_text())
    includes = project["tool"]["setuptools"]["packages"]["find"]["include"]
    target.mkdir(parents=True)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(root / name, target / name)
    for entry in root.iterdir():
        if entry.is_dir() and any(entry.name == pattern.rstrip("*") for pattern in includes):
            shutil.copytree(entry, target / entry.name, ignore=shutil.ignore_patterns("__pycache__"))
    return target


def bare_environment(extra: dict[str, str]) -> dict[str, str]:
    """The environment of a new user: none of our settings, no PYTHONPATH, no active venv."""
    env = {key: value for key, value in os.environ.items()
           if not key.startswith(("GEOCERT_", "PYTHON", "VIRTUAL_ENV"))}
    return {**env, **extra}


def install_bare(root: Path, work: Path) -> Path:
    """A new virtual environment with the project from ``root`` installed, no extras."""
    venv = work / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    source = source_copy(root, work / "src")
    done = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet",
                           "--disable-pip-version-check", str(source)],
                          env=bare_environment({}), cwd=work, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, f"pip install failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return venv


def serve_and_solve(venv: Path, work: Path, ready_within_s: float = 120) -> dict:
    """Start `geocert serve` from ``venv``, wait for /readyz, solve the README's job; return the
    job document. Stops every process it started (the whole process group)."""
    port = free_port()
    log = open(work / "serve.log", "w+")
    env = bare_environment({"GEOCERT_DATA_DIR": str(work / "data")})
    # Not in the checkout: `python -m celery` (the worker) must import the installed packages.
    process = subprocess.Popen([str(venv / "bin" / "geocert"), "serve", "--port", str(port), "--workers", "1"],
                               env=env, cwd=work, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)

    def log_tail() -> str:  # the service's own lines and any traceback, not its access log
        log.flush()
        lines = (work / "serve.log").read_text().splitlines()
        return "\n".join(line for line in lines if '"message": "request"' not in line)[-4000:]

    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as client:
            deadline = time.monotonic() + ready_within_s
            ready = None
            while True:
                try:
                    ready = client.get("/readyz")
                    if ready.status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                assert process.poll() is None, f"geocert serve exited ({process.returncode}):\n{log_tail()}"
                assert time.monotonic() < deadline, (
                    f"not ready within {ready_within_s} s ({ready.text if ready is not None else 'no answer'}):\n"
                    f"{log_tail()}")
                time.sleep(0.5)
            for page, text in (("/", "index.js"), ("/web/job.js", "GC_STATE")):  # the web page's files: package data
                answer = client.get(page)
                assert answer.status_code == 200 and text in answer.text, f"{page}: {answer.status_code}"
            created = client.post("/v1/jobs", json=README_JOB)
            assert created.status_code == 202, created.text
            location = created.headers["location"]
            deadline = time.monotonic() + 120
            while (job := client.get(location).json())["status"] not in ("succeeded", "failed", "cancelled"):
                assert time.monotonic() < deadline, f"job still {job['status']}:\n{log_tail()}"
                time.sleep(0.2)
            return job
    finally:
        try:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=10)
        except ProcessLookupError:
            pass
        try:  # anything of the group still alive (a worker's pool, the embedded Redis)
            os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        log.close()


@pytest.mark.slow
def test_a_bare_install_serves_the_readme_example(tmp_path):
    venv = install_bare(ROOT, tmp_path)
    # Nothing of the test extras came along: what the service imports must be declared.
    probe = subprocess.run([str(venv / "bin" / "python"), "-c", "import pytest"], capture_output=True)
    assert probe.returncode != 0, "the bare environment has the test extras"
    job = serve_and_solve(venv, tmp_path)
    assert job["status"] == "succeeded", job
    track = job["result"]["tracks"][0]
    assert track["certified"] and track["status"] == "optimal"
    assert track["cost"] == pytest.approx(0.5, rel=1e-3)


# Distribution names whose import name differs.
IMPORT_NAMES = {"opencv-python-headless": "cv2", "pydantic-settings": "pydantic_settings",
                "prometheus-client": "prometheus_client", "fastapi-offline": "fastapi_offline"}


def test_every_module_the_package_imports_is_declared():
    """A module that comes along only as another package's dependency (starlette under fastapi,
    billiard under celery) may leave with that package's next release: each third-party module
    geocert imports is declared itself."""
    import ast
    import re

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    declared = set()
    for requirement in project["dependencies"]:
        name = re.match(r"[A-Za-z0-9_.-]+", requirement).group(0).lower()
        declared.add(IMPORT_NAMES.get(name, name.replace("-", "_")))
    imported = set()
    for path in (ROOT / "geocert").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                imported.add(node.module.split(".")[0])
            elif isinstance(node, ast.Import):
                imported.update(alias.name.split(".")[0] for alias in node.names)
    third_party = {name for name in imported if name not in sys.stdlib_module_names and name != "geocert"}
    assert third_party - declared == set()
