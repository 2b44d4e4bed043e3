"""Workers started by `geocert serve` and `geocert worker` run their BLAS single-threaded unless
the operator says otherwise (a worker solves one item at a time; BLAS threads spinning against
other workers' cost more than they give)."""

from __future__ import annotations

from geocert.app.cli import worker_environment


def test_blas_is_single_threaded_by_default():
    environment = worker_environment({"PATH": "/bin"})
    assert environment["OPENBLAS_NUM_THREADS"] == environment["OMP_NUM_THREADS"] == "1"
    assert environment["PATH"] == "/bin"


def test_the_operators_setting_wins():
    assert worker_environment({"OPENBLAS_NUM_THREADS": "4"})["OPENBLAS_NUM_THREADS"] == "4"


def test_geocert_solve_runs_one_blas_thread_as_a_solver_process_does():
    """`geocert solve` sets the workers' environment before numpy loads: OpenBLAS runs one thread
    in it (by default it runs one a core); the operator's setting, when given, wins as for the
    workers."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    code = "\n".join([
        "import os, sys, json, threadpoolctl",
        "from geocert.app import cli",
        "sys.argv = ['geocert', 'solve', '--compact', 'examples/triangulation.json']",
        "try:",
        "    cli.main()",
        "except SystemExit:",
        "    pass",
        "blas = [p['num_threads'] for p in threadpoolctl.threadpool_info() if p['user_api'] == 'blas']",
        "print(json.dumps([os.environ.get('OPENBLAS_NUM_THREADS'), blas]), file=sys.stderr)",
    ])
    bare = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    for environment, setting in ((bare, "1"), ({**bare, "OPENBLAS_NUM_THREADS": "2"}, "2")):
        done = subprocess.run([sys.executable, "-c", code], cwd=root, env=environment, capture_output=True, text=True,
                              timeout=300)
        seen, threads = json.loads(done.stderr.strip().splitlines()[-1])
        assert seen == setting and threads, done.stderr[-2000:]
        if setting == "1":
            assert all(count == 1 for count in threads), threads
