"""A worker's lifecycle (Celery's signals, connected when Celery imports this module with the
tasks, in a worker only): JSON logs and a memory bound in each solver process, and a heartbeat
(with the reaper and the clock on past jobs) from the moment it takes tasks."""

from __future__ import annotations

from celery.signals import worker_process_init, worker_ready, worker_shutdown

from geocert.jobs.collection import start_up_heap_frozen
from geocert.settings import get_settings, redis_url
from geocert.workers.celery_app import SOLVE_QUEUE


@worker_process_init.connect
def _json_logs(**_) -> None:
    from geocert import logs

    logs.configure()
    limit_memory(get_settings().worker_memory_mb)


# The solvers the kinds import at their first solve (so that the API process, which imports the
# kinds, never loads them), loaded as a solver process starts instead: a fresh worker's first
# task of each process paid the import (some 0.08 s of CPU for triangulation's, on a job whose
# solve is 0.05 s). tests/workers/test_solvers_loaded.py checks that the kinds' imports find every
# geocert.solvers and geocert.formulations module they need loaded. Kept by hand rather than derived:
# walking geocert.solvers with pkgutil loads all its modules (OpenCV's among them) into every solver
# process, measured 0.12 s more CPU and 19 MB more peak memory at the start than this list (0.72
# against 0.59 s, 126 against 107 MB), and reading the kinds' imports from their source at the start
# costs 0.07 s of the 0.08 s a first task would pay.
SOLVER_MODULES = (
    "geocert.solvers.fractional.many_tracks", "geocert.solvers.fractional.triangulation",
    "geocert.formulations.fractional.convexity_path", "geocert.formulations.fractional.determinacy",
    "geocert.solvers.fractional.maps", "geocert.formulations.fractional.options", "geocert.core.bnb",
    "geocert.core.determinacy", "geocert.core.self_check", "geocert.solvers.bilinear.search",
    "geocert.solvers.autocalibration.stratified", "geocert.formulations.autocalibration.direct",
    "geocert.solvers.autocalibration.direct_solve", "geocert.formulations.autocalibration.direct_sublevel",
    "geocert.formulations.autocalibration.direct_intrinsics",
    "geocert.solvers.autocalibration.metric_sublevel", "geocert.formulations.autocalibration.plane_sublevel",
    "geocert.formulations.autocalibration.determinacy",
    "geocert.formulations.autocalibration.proofs", "geocert.solvers.lines.determinacy", "geocert.solvers.lines.geometry",
    "geocert.solvers.lines.scenes", "geocert.solvers.reconstruction.synthetic",
    "geocert.formulations.reconstruction.camera_claim",
)


@worker_process_init.connect
def _solvers_loaded(**_) -> None:
    import importlib

    for name in SOLVER_MODULES:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 (a head start only: the task that needs it fails and says why, as before)
            pass
    start_up_heap_frozen()  # after the imports above: what they loaded leaves the collector's generations


def limit_memory(megabytes: int) -> None:
    """Bound this solver process's address space (GEOCERT_WORKER_MEMORY_MB; 0: unbounded): an
    allocation past it fails (MemoryError, or OpenCV's "Insufficient memory") in the task that made
    it, whose job then fails with the reason (workers.tasks), instead of the kernel killing a
    process (or the machine swapping) for one client's job."""
    import resource

    if megabytes > 0:
        limit = megabytes << 20
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        resource.setrlimit(resource.RLIMIT_AS, (limit if hard == resource.RLIM_INFINITY else min(limit, hard), hard))


_HEARTBEAT = None


def beat_name(hostname: str | None) -> str:
    """The name this worker beats under: its Celery node name and its main process's id.
    Several workers on one host may share a node name (``geocert worker`` started twice, each
    ``geocert@host``): under one name their beats would count as one worker and its solver
    processes, so /readyz, the keys' fair share and the pieces' helpers would see too few."""
    import os

    return f"{hostname or 'geocert@unknown'}/{os.getpid()}"


@worker_ready.connect
def _start_heartbeat(sender=None, **_) -> None:
    """From the moment the worker takes tasks, it beats (``workers.heartbeat``; read by /readyz)."""
    global _HEARTBEAT
    from geocert.workers.heartbeat import Heartbeat

    from geocert.workers.reaper import reap
    from geocert.jobs.store import JobStore
    from geocert.workers.tasks import end_jobs_past_clock

    name = beat_name(getattr(sender, "hostname", None))
    settings = get_settings()
    if SOLVE_QUEUE not in sender.app.amqp.queues.consume_from:  # a webhook worker: it renews its leases only
        _HEARTBEAT = Heartbeat(redis_url(), name, solvers=None).start()
        return
    jobs = JobStore.from_url(redis_url(), settings.result_ttl_s, socket_timeout=10, socket_connect_timeout=5)
    every_s = 5.0
    solvers = getattr(getattr(sender, "controller", None), "concurrency", None) or 1
    _HEARTBEAT = Heartbeat(redis_url(), name, reaper=lambda: reap(jobs, settings.visibility_timeout_s, every_s),
                           reap_every_s=every_s, solvers=solvers, clock=lambda: end_jobs_past_clock(jobs)).start()


@worker_shutdown.connect
def _stop_heartbeat(**_) -> None:
    if _HEARTBEAT is not None:
        _HEARTBEAT.stop()
