"""Every bench module imports with the test extras alone (pycolmap, the bench extra, is imported
only where a COLMAP run is asked for), so a renamed or moved function breaks a test, not the next
person's bench run; and the benches that solve in their own process run one BLAS thread, as the
service's solver processes do, unless the environment says otherwise."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MODULES = sorted(path.stem for path in (ROOT / "bench").glob("*.py") if path.stem != "__init__")
SOLVING_IN_PROCESS = ["autocalibration", "bilinear", "direct_autocalibration", "homography", "reconstruction",
                      "reconstruction_images", "resection"]


def test_every_bench_module_imports():
    # One child process for them all: a fresh interpreter (what `python -m bench.X` meets), not this
    # one's already imported modules.
    code = "import importlib, sys\nfor name in sys.argv[1:]:\n    importlib.import_module('bench.' + name)\n"
    done = subprocess.run([sys.executable, "-c", code, *MODULES], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]


@pytest.mark.parametrize("name", SOLVING_IN_PROCESS)
def test_a_bench_solving_in_its_own_process_runs_one_blas_thread(name):
    environment = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    code = f"import os, bench.{name}; print(os.environ.get('OPENBLAS_NUM_THREADS'), os.environ.get('OMP_NUM_THREADS'))"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, env=environment,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == ["1", "1"]
