"""Imported before numpy by a bench that solves in its own process: one BLAS thread, as the
service's solver processes have (`geocert.app.cli.SINGLE_THREADED_BLAS`), unless the environment
already says otherwise.

Why: the solvers are single-threaded, and on a shared 2-core machine OpenBLAS's threads spin while
they wait for a core, charging the process CPU it does not use. Measured: a thin SVD of a 2000 x 9
matrix (a 1000-point homography's linear estimate) 64 ms of CPU with two threads at load 3.7
against 0.3 ms with one; a 432 x 432 Cholesky 150 ms under load; the Dinosaur's projective stage
25.5 s against 13.2 s."""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
