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
