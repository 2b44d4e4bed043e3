"""`geocert serve --api-processes 2`: two API processes on one port, each request answered by
whichever accepted its connection. A job made through one is read, replayed by its
Idempotency-Key and streamed through the other; the other has the slow-header guard with the
configured timeout; both stop when `geocert serve` is told to, or is killed."""

from __future__ import annotations

import http.client
import json
import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from tests.servers import free_port
from tests.service.test_serve import ONE_TRACK, serve_env, wait_for_line

pytestmark = pytest.mark.slow  # real servers: the full run only


@contextmanager
def serving(data_dir: Path, port: int, *arguments: str, **env: str):
    """`geocert serve` (the port, data directory and ``env`` given), its standard error in a file;
    yields the process and a function reading that file. Stops its whole process group."""
    log_path = data_dir.parent / f"serve-{port}.log"
    with open(log_path, "w") as log:
        process = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port), *arguments],
                                   env={**serve_env(data_dir), **env}, stdout=log, stderr=log, start_new_session=True)
        try:
            yield process, log_path.read_text
        finally:
            try:
                os.killpg(process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            process.wait(timeout=10)


def api_processes(serve_pid: int) -> list[int]:
    """The serving processes: `geocert serve` itself and the API processes it started."""
    with open(f"/proc/{serve_pid}/task/{serve_pid}/children") as children:
        others = [int(pid) for pid in children.read().split()]
    return [serve_pid] + [pid for pid in others if b"geocert.app.lifecycle" in open(f"/proc/{pid}/cmdline", "rb").read()]


def accepted_by(port: int, client_port: int, pids: list[int]) -> int | None:
    """Which of ``pids`` holds the server's end of the loopback connection from ``client_port``."""
    inodes = set()
    with open("/proc/net/tcp") as table:
        for line in table.readlines()[1:]:
            fields = line.split()
            if int(fields[1].split(":")[1], 16) == port and int(fields[2].split(":")[1], 16) == client_port:
                inodes.add(fields[9])
    for pid in pids:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                if os.readlink(f"/proc/{pid}/fd/{fd}") in {f"socket:[{inode}]" for inode in inodes}:
                    return pid
            except OSError:
                continue
    return None


def connection_to(port: int, pid: int, pids: list[int], tries: int = 500) -> http.client.HTTPConnection:
    """A keep-alive connection that API process ``pid`` accepted (connections are opened until one
    lands there; a first request makes sure it was accepted)."""
    for _ in range(tries):
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        connection.request("GET", "/healthz")
        assert connection.getresponse().read()
        if accepted_by(port, connection.sock.getsockname()[1], pids) == pid:
            return connection
        connection.close()
    raise AssertionError(f"no connection landed in process {pid} in {tries} tries")


def call(connection: http.client.HTTPConnection, method: str, path: str, body: dict | None = None,
         headers: dict | None = None) -> tuple[int, dict]:
    connection.request(method, path, body=None if body is None else json.dumps(body),
                       headers={"content-type": "application/json", **(headers or {})})
    response = connection.getresponse()
    return response.status, json.loads(response.read())


def test_two_api_processes_serve_the_same_jobs_replays_and_streams(tmp_path):
    port = free_port()
    data = tmp_path / "data"
    with serving(data, port, "--workers", "1", "--concurrency", "1", "--api-processes", "2") as (process, read_log):
        wait_for_line(read_log, process, "ready at")
        pids = api_processes(process.pid)
        assert len(pids) == 2
        first, second = (connection_to(port, pid, pids) for pid in pids)

        status, made = call(first, "POST", "/v1/jobs", ONE_TRACK, {"Idempotency-Key": "order-1"})
        assert status == 202
        status, read = call(second, "GET", f"/v1/jobs/{made['id']}")
        assert status == 200 and read["id"] == made["id"] and read["kind"] == "triangulation"
        status, replayed = call(second, "POST", "/v1/jobs", ONE_TRACK, {"Idempotency-Key": "order-1"})
        assert status == 200 and replayed["id"] == made["id"]  # the key remembered across processes
        other = json.loads(json.dumps(ONE_TRACK))
        other["data"]["tracks"][0]["points"][0] = [331, 250]
        status, refused = call(second, "POST", "/v1/jobs", other, {"Idempotency-Key": "order-1"})
        assert status == 422 and "Idempotency-Key" in json.dumps(refused)

        second.request("GET", f"/v1/jobs/{made['id']}/events")
        stream = second.getresponse()
        assert stream.status == 200
        lines = []
        while not any("succeeded" in line for line in lines):
            line = stream.readline().decode()
            assert line, f"the stream ended before the job did: {lines}"
            lines.append(line)
        assert any(line.startswith("event: status") for line in lines)
        for connection in (first, second):
            connection.close()

        process.send_signal(signal.SIGTERM)  # `geocert serve` alone: it stops the other API process
        process.wait(timeout=60)
        assert_ends(pids[1:])


def test_every_api_process_closes_a_connection_whose_headers_are_too_slow(tmp_path):
    """The guard's timeout (GEOCERT_HEADER_TIMEOUT_S) in the API processes `geocert serve` starts
    as in itself: a connection of each, after one answer, sending half a request's headers is
    closed by the server well before the default 10 s."""
    port = free_port()
    data = tmp_path / "data"
    with serving(data, port, "--workers", "0", "--api-processes", "2", GEOCERT_HEADER_TIMEOUT_S="1") as (process, read_log):
        wait_for_line(read_log, process, "ready at")
        pids = api_processes(process.pid)
        assert len(pids) == 2
        for pid in pids:
            connection = connection_to(port, pid, pids)
            connection.sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
            connection.sock.settimeout(8)
            try:
                assert connection.sock.recv(1024) == b""  # closed by the server
            except socket.timeout:
                raise AssertionError(f"process {pid} kept a connection with half its headers for 8 s") from None
            connection.close()
        os.kill(process.pid, signal.SIGKILL)  # `geocert serve` killed: the other API process goes with it
        process.wait(timeout=10)
        assert_ends(pids[1:])


def assert_ends(pids: list[int], limit_s: float = 30) -> None:
    """Each of ``pids`` has ended (or is a zombie) within ``limit_s``; a process that reuses the
    number later (the start time tells it apart) is not it."""
    deadline = time.monotonic() + limit_s
    for pid in pids:
        started = _start_time(pid)
        while started is not None and _start_time(pid) == started and _state(pid) not in (None, "Z"):
            assert time.monotonic() < deadline, f"API process {pid} still runs after geocert serve stopped: {_described(pid)}"
            time.sleep(0.1)


def _described(pid: int) -> str:
    """What the kernel says of a process that should have ended: its state, parent, command and
    what it waits in, for a failure's message."""
    try:
        with open(f"/proc/{pid}/status") as status:
            lines = [line.strip() for line in status if line.startswith(("State", "PPid", "Threads", "SigCgt", "SigPnd", "ShdPnd"))]
        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
            command = cmdline.read().replace(b"\0", b" ").decode(errors="replace")
        with open(f"/proc/{pid}/wchan") as wchan:
            waits = wchan.read()
    except OSError as exc:
        return f"(gone while described: {exc})"
    return f"{command!r}; {'; '.join(lines)}; waiting in {waits!r}"


def _stat_fields(pid: int) -> list[str] | None:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()  # after the command's name, which may hold spaces
    except (FileNotFoundError, ProcessLookupError):
        return None


def _state(pid: int) -> str | None:
    fields = _stat_fields(pid)
    return None if fields is None else fields[0]


def _start_time(pid: int) -> str | None:
    fields = _stat_fields(pid)
    return None if fields is None else fields[19]  # starttime, field 22 of proc(5)
