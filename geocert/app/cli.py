"""The ``geocert`` command: solve in-process, verify a certificate, serve the API, run a worker, export
the OpenAPI spec."""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from pydantic import ValidationError


def _progress_bar(progress: dict) -> None:
    done, total = progress["items_done"], progress["items_total"]
    width = 30
    filled = int(width * done / total) if total else width
    gap = progress.get("gap_rel")
    gap_text = f"{gap:.2e}" if gap is not None else "-"
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} items, "
                     f"{progress['nodes']} nodes, worst gap {gap_text}, {progress['elapsed_s']:.1f} s")
    sys.stderr.flush()


def job_request_adapter(body: object):
    """What validates a job: its kind's request model when the body names a served kind (the branch
    of the API's union its tag selects: the same checks, and the same fields named in errors),
    without importing every kind; otherwise the API's union, which says what is wrong with the kind."""
    from pydantic import TypeAdapter

    from geocert.kinds import KINDS

    name = body.get("kind") if isinstance(body, dict) else None
    if isinstance(name, str) and name in KINDS:
        return TypeAdapter(KINDS.get(name).request_model)
    from geocert.app.schemas import JOB_REQUEST

    return JOB_REQUEST


def cmd_solve(args: argparse.Namespace) -> int:
    # As a solver process of the service: one BLAS thread unless the environment says otherwise,
    # set before numpy loads. The solvers are single-threaded, and on a busy machine OpenBLAS's
    # threads spin waiting for a core: a 2000 x 9 SVD (a 1000-point map's linear estimate) took
    # some two hundred times the CPU with two threads as with one while other work held the cores
    # (bench/results/homography.md).
    os.environ.update(worker_environment(dict(os.environ)))
    from geocert.core.geometry import InputError
    from geocert.jobs.collection import start_up_heap_frozen
    from geocert.jobs.finite import NonFiniteResult
    from geocert.jobs.runner import solve_job

    try:
        text = sys.stdin.read() if args.job == "-" else Path(args.job).read_text()
        body = json.loads(text)
    except (OSError, json.JSONDecodeError) as exc:
        print(json.dumps({"type": "about:blank", "title": "Unreadable job", "status": 400, "detail": str(exc)}),
              file=sys.stderr)
        return 2
    except ValueError as exc:  # valid JSON, an integer longer than the parser converts (as the API answers it)
        from geocert.app.errors import long_number_reason

        reason = long_number_reason(exc)
        print(json.dumps({"type": "about:blank", "title": "Invalid request", "status": 422, "detail": f"body: {reason}",
                          "errors": [{"field": "body", "reason": reason}]}), file=sys.stderr)
        return 2
    try:
        adapter = job_request_adapter(body)
        # The job's kind is loaded: what the process holds now (modules, the kind) lives as long as
        # it does, so the collector's full runs during the solve need not scan it again (as a
        # solver process's heap once its solvers are loaded)
        start_up_heap_frozen()
        request = adapter.dump_python(adapter.validate_python(body), mode="json")
        sink = _progress_bar if sys.stderr.isatty() else None
        result = solve_job(request, sink=sink)
    except ValidationError as exc:
        from geocert.app.errors import validation_problem

        print(json.dumps(validation_problem(exc.errors())), file=sys.stderr)
        return 2
    except InputError as exc:
        print(json.dumps({"type": "about:blank", "title": "Invalid request", "status": 422, "detail": str(exc),
                          "errors": [{"field": exc.field, "reason": exc.reason}]}), file=sys.stderr)
        return 2
    except NonFiniteResult as exc:  # jobs.finite: refused rather than written
        print(json.dumps(exc.problem()), file=sys.stderr)
        return 1
    if sys.stderr.isatty():
        sys.stderr.write("\n")
    # json.dumps, not json.dump: dump writes piece by piece through the pure-Python encoder, dumps
    # uses the C one for compact output (the same text, several times less CPU on a large result)
    sys.stdout.write(json.dumps(result, indent=None if args.compact else 2) + "\n")
    return 0


def cmd_verify(args: argparse.Namespace) -> int:
    """Exit 0 when the certificate is valid, 1 when it is not, 2 when the input cannot be read
    (unreadable, not JSON, a member name repeated in one object, a number too long to read, nested
    too deeply, or carrying no certificate)."""
    from geocert.core.strict import RepeatedName, Unreadable, load_document
    from geocert.verify.checks import estimates_kind, find_certificate, verify_any

    try:
        text = sys.stdin.read() if args.file == "-" else Path(args.file).read_text()
        document = load_document(text)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RepeatedName, Unreadable, RecursionError) as exc:
        reason = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
        print(f"geocert verify: cannot read {args.file}: {reason}", file=sys.stderr)
        return 2
    # A result (geocert solve's output) or a job document carry the certificate inside; then the
    # items they return are checked against it too.
    if find_certificate(document) is None:
        uncertified = estimates_kind(document)  # a kind with no certificate option: say so, suggest nothing
        print(f"geocert verify: {args.file} holds no certificate " + (
              f"({uncertified} results are estimates, never certified: there is nothing to verify)"
              if uncertified is not None else "(solve with options.certificate = \"full\")"), file=sys.stderr)
        return 2
    report = verify_any(document).as_dict()
    json.dump(report, sys.stdout, indent=None if args.compact else 2)
    sys.stdout.write("\n")
    return 0 if report["valid"] else 1


def default_concurrency() -> int:
    """Solver processes of `geocert serve`'s worker: one per core, so that jobs use the machine, and
    at least two, so that one long job never holds every solver while short ones wait (on one core
    the two share it). Each is a process of its own (about 150 MB with numpy, scipy and the conic
    solver loaded)."""
    return max(2, os.cpu_count() or 1)


WEBHOOK_THREADS = 8  # deliveries at once per webhook worker: each mostly waits on its receiver


def _worker_command(concurrency: int, name: str, role: str = "solve") -> list[str]:
    """A Celery worker of one role: ``solve`` (the solve queue, one process per solver) or
    ``webhooks`` (the webhook queue, threads: deliveries wait on the network, not the CPU)."""
    from geocert.workers.celery_app import SOLVE_QUEUE, WEBHOOK_QUEUE

    pool = ["--concurrency", str(concurrency), "--pool", "prefork", "-Q", SOLVE_QUEUE] if role == "solve" else \
        ["--concurrency", str(WEBHOOK_THREADS), "--pool", "threads", "-Q", WEBHOOK_QUEUE]
    return [sys.executable, "-m", "celery", "-A", "geocert.workers.celery_app", "worker", "--loglevel", "WARNING",
            *pool, "-n", f"{name}@%h", "--without-gossip", "--without-mingle"]


# A worker solves one item at a time on small matrices; the BLAS libraries' own threads then
# spin against the other workers' instead of helping (a 432 x 432 Cholesky of a reconstruction's
# adjustment took 150 ms of CPU under load, half the projective stage). One thread each unless
# the operator says otherwise.
SINGLE_THREADED_BLAS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def worker_environment(base: dict[str, str]) -> dict[str, str]:
    """The environment of the worker processes `geocert serve` starts."""
    return {**SINGLE_THREADED_BLAS, **base}


def _die_with_parent() -> None:
    """In a child: ask Linux to send SIGTERM when the parent dies, even by SIGKILL."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def cmd_serve(args: argparse.Namespace) -> int:
    from geocert.settings import get_settings
    from geocert.app.core.security import is_loopback, parse_keys

    try:
        keys = parse_keys(get_settings().api_keys)
    except (ValueError, ValidationError) as exc:  # a malformed key or setting
        print(f"geocert serve: {exc}", file=sys.stderr)
        return 2
    if not keys and not is_loopback(args.host):
        print(f"geocert serve: refusing to listen on {args.host} without API keys: set GEOCERT_API_KEYS, "
              "or listen on loopback (127.0.0.1)", file=sys.stderr)
        return 2
    if not _port_free(args.host, args.port):
        print(f"geocert serve: {args.host}:{args.port} is in use (another geocert serve?): stop it, or give this one "
              "--port", file=sys.stderr)
        return 2
    print("geocert: API keys required on /v1" if keys else
          "geocert: no API keys configured (GEOCERT_API_KEYS): serving loopback only, without authentication",
          file=sys.stderr)
    redis_process = None
    if not os.environ.get("GEOCERT_REDIS_URL"):
        from geocert.workers.redis_server import DataDirInUse, claim_data_dir, start_embedded_redis

        data_dir = get_settings().data_dir
        try:
            lock = claim_data_dir(data_dir)  # held while this process runs (closed when it exits)
        except DataDirInUse as exc:
            print(f"geocert serve: {exc}, with its embedded Redis: stop it, or give this one another directory "
                  "(GEOCERT_DATA_DIR)", file=sys.stderr)
            return 2
        redis_process, url = start_embedded_redis(data_dir, preexec_fn=_die_with_parent)
        os.environ["GEOCERT_REDIS_URL"] = url
        print(f"geocert: embedded Redis at {url} (data in {Path(data_dir).resolve()}, lock {lock.name})",
              file=sys.stderr)
    get_settings.cache_clear()
    workers = [subprocess.Popen(_worker_command(args.concurrency, f"geocert-{i}"), env=worker_environment(dict(os.environ)),
                                preexec_fn=_die_with_parent)
               for i in range(args.workers)]
    if args.workers:  # and one for webhooks (their own queue: a slow receiver never holds a solver)
        workers.append(subprocess.Popen(_worker_command(0, "geocert-webhooks", "webhooks"),
                                        env=worker_environment(dict(os.environ)), preexec_fn=_die_with_parent))
    # uvicorn re-raises SIGTERM after its own shutdown; make that an ordinary exit so that the
    # workers and the embedded Redis below are stopped too.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    print(f"geocert: {args.workers} worker process(es), {args.concurrency} solver process(es) each: up to "
          f"{args.workers * args.concurrency} jobs' tasks at once", file=sys.stderr)
    stopping = threading.Event()
    _watch_workers(workers, stopping)
    _announce_when_ready(args.host, args.port, args.workers > 0, stopping)
    try:
        from geocert.app import lifecycle

        lifecycle.run("geocert.app.main:app", host=args.host, port=args.port,
                      processes=args.api_processes or get_settings().api_processes)
    finally:
        stopping.set()
        for process in workers:
            process.send_signal(signal.SIGTERM)
        for process in workers:
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
        if redis_process is not None:
            redis_process.terminate()
            redis_process.wait(timeout=10)
    return 0


def _port_free(host: str, port: int) -> bool:
    """Whether the API could listen on host:port (checked before Redis and the workers start, so a
    second serve on a taken port leaves nothing of the first's touched)."""
    import socket

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn binds
        try:
            probe.bind((host, port))
        except OSError:
            return False
    return True


def service_url(host: str, port: int) -> str:
    shown = "127.0.0.1" if host in ("0.0.0.0", "") else f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/"


def _announce_when_ready(host: str, port: int, workers: bool, stopping: threading.Event, limit_s: float = 300) -> None:
    """Print the service's address on standard error once it answers (/readyz: Redis and a
    worker; /healthz without workers), or say what it still waits for."""
    import httpx

    url = service_url(host, port)

    def wait() -> None:
        deadline = time.monotonic() + limit_s
        said_waiting = False
        with httpx.Client(base_url=url, timeout=5) as client:
            while not stopping.is_set() and time.monotonic() < deadline:
                try:
                    if client.get("readyz" if workers else "healthz").status_code == 200:
                        print(f"geocert: ready at {url} (the web page; API documentation at {url}docs). "
                              "Ctrl-C stops it.", file=sys.stderr, flush=True)
                        return
                    if not said_waiting:
                        said_waiting = True
                        print(f"geocert: the API answers at {url}; waiting for a worker to start...", file=sys.stderr,
                              flush=True)
                except httpx.TransportError:
                    pass
                stopping.wait(0.5)
        if not stopping.is_set():
            print(f"geocert: {url} is not ready after {limit_s:.0f} s (see the messages above)", file=sys.stderr)

    threading.Thread(target=wait, name="geocert-ready", daemon=True).start()


def _watch_workers(workers: list[subprocess.Popen], stopping: threading.Event) -> None:
    """Say on standard error when an embedded worker exits on its own (a worker that dies at import,
    say, would otherwise leave only /readyz answering "not ready")."""

    def watch() -> None:
        reported: set[int] = set()
        while len(reported) < len(workers) and not stopping.is_set():
            for index, process in enumerate(workers):
                if index not in reported and process.poll() is not None and not stopping.is_set():
                    reported.add(index)
                    print(f"geocert: worker process geocert-{index} exited with status {process.returncode}; "
                          "/readyz answers not ready while no worker runs", file=sys.stderr)
            time.sleep(1.0)

    threading.Thread(target=watch, name="geocert-worker-watch", daemon=True).start()


def cmd_worker(args: argparse.Namespace) -> int:
    if not os.environ.get("GEOCERT_REDIS_URL"):
        print("geocert worker: set GEOCERT_REDIS_URL to the Redis the API uses", file=sys.stderr)
        return 2
    environment = worker_environment(dict(os.environ))
    if args.role == "webhooks":
        os.execve(sys.executable, _worker_command(0, "geocert-webhooks", "webhooks"), environment)
    if args.role == "both":  # the webhook worker dies with this one (a signal from the kernel)
        subprocess.Popen(_worker_command(0, "geocert-webhooks", "webhooks"), env=environment, preexec_fn=_die_with_parent)
    os.execve(sys.executable, _worker_command(args.concurrency, "geocert"), environment)
    return 0  # not reached


def cmd_webhook_secret(args: argparse.Namespace) -> int:
    """Print the key webhook signatures use (GEOCERT_WEBHOOK_SECRET, or the one kept in Redis)."""
    from geocert.jobs.store import JobStore
    from geocert.settings import redis_url
    from geocert.workers.webhooks import webhook_secret

    print(webhook_secret(JobStore.from_url(redis_url())))
    return 0


def openapi_document() -> dict:
    from geocert.app.main import create_app

    return create_app().openapi()


def cmd_openapi(args: argparse.Namespace) -> int:
    text = json.dumps(openapi_document(), indent=2, sort_keys=True) + "\n"
    if args.output:
        Path(args.output).write_text(text)
    else:
        sys.stdout.write(text)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="geocert", description="Certified globally optimal geometry solves.")
    sub = parser.add_subparsers(dest="command", required=True)
    solve = sub.add_parser("solve", help="solve a job file in this process and print the result JSON")
    solve.add_argument("job", help="path to a job JSON file, or - for standard input")
    solve.add_argument("--compact", action="store_true", help="print the result on one line")
    solve.set_defaults(func=cmd_solve)
    verify = sub.add_parser("verify", help="check a full certificate (a result, job or certificate JSON file)")
    verify.add_argument("file", help="path to the JSON file, or - for standard input")
    verify.add_argument("--compact", action="store_true", help="print the report on one line")
    verify.set_defaults(func=cmd_verify)
    serve = sub.add_parser("serve", help="run the API with embedded workers (and Redis unless GEOCERT_REDIS_URL)")
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8000)
    serve.add_argument("--workers", type=int, default=1, help="worker processes to start (0 allowed)")
    serve.add_argument("--api-processes", type=int, default=None,
                       help="API processes on the port (default: GEOCERT_API_PROCESSES, 1)")
    serve.add_argument("--concurrency", type=int, default=default_concurrency(),
                       help="solver processes per worker (default: one per core, at least 2)")
    serve.set_defaults(func=cmd_serve)
    worker = sub.add_parser("worker", help="run one Celery worker against GEOCERT_REDIS_URL")
    worker.add_argument("--concurrency", type=int, default=os.cpu_count() or 1, help="solver processes")
    worker.add_argument("--role", choices=("both", "solve", "webhooks"), default="both",
                        help="solve jobs, deliver webhooks (their own queue and threads), or both (default)")
    worker.set_defaults(func=cmd_worker)
    secret = sub.add_parser("webhook-secret", help="print the key that signs webhook deliveries")
    secret.set_defaults(func=cmd_webhook_secret)
    spec = sub.add_parser("openapi", help="print (or write) the OpenAPI document")
    spec.add_argument("--output", help="file to write instead of standard output")
    spec.set_defaults(func=cmd_openapi)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
