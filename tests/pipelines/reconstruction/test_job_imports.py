"""What a reconstruction job imports before it needs it: scipy.optimize (about 0.15 s of CPU, a
process's start-up that the bench counts beside COLMAP's; bench/results/reconstruction_vs_colmap.md) is
imported where it is called, which a K-known job on real photos never does."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

CHILD = """
import json, sys
import geocert.kinds.reconstruction, geocert.pipelines.reconstruction.pipeline, geocert.jobs.runner
print(json.dumps(sorted(m for m in sys.modules if m.startswith("scipy.optimize"))[:3]))
"""


def test_the_reconstruction_path_does_not_import_scipy_optimize():
    root = Path(__file__).resolve().parents[3]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, env=env, timeout=300,
                          cwd=root, check=True)
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
