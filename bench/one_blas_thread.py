"""Imported before numpy by a bench that solves in its own process: one BLAS thread, as the
service's solver processes have (`geocert.app.cli.SINGLE_THREADED_BLAS`), unless the environment
already says otherwise.

Why: the solvers are single-threaded, and on a shared 2-core machine OpenBLAS's threads spin while
they wait for a core, charging the process CPU it does not use. While other work held the cores,
a thin SVD of a 2000 x 9 matrix (a 1000-point homography's linear estimate) took some two hundred
times the CPU with two threads as with one (bench/results/homography.md, "One BLAS thread"), and
the Dinosaur's projective stage about twice."""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
