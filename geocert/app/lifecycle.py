"""The API process's way out and its guard against slow clients.

``stopping`` is set the moment the server is told to stop (SIGTERM or SIGINT), and every event
loop's ``stop_event()`` with it: open event streams, which wait on it beside their blocking read,
tell their clients to reconnect (``retry``) and end at once, so the server exits in about a second
instead of waiting on every stream; ``GEOCERT_SHUTDOWN_TIMEOUT_S`` cancels whatever is still
running after that.

``HeaderTimeoutH11`` is uvicorn's h11 protocol with one addition: a connection must complete a
request's headers within ``GEOCERT_HEADER_TIMEOUT_S`` of opening, or of its previous response, or
it is closed. uvicorn by itself times out only idle keep-alive connections, so a client sending
its headers a byte at a time (slowloris) would hold a connection for ever.

``run`` with ``processes`` > 1 (``GEOCERT_API_PROCESSES``): that many API processes accept on one
listening socket, bound here: this process serves on it and starts the others
(``python -m geocert.app.lifecycle APP FD``), each with its own event loop, the same guard and the
same way out. One event loop is one core at most, and on a loaded machine the scheduler gives a
process its share, whatever its queue of requests. What a request needs from another is in
Redis (jobs, events, idempotency keys, the rate limit); the limits counted in a process (open
event streams a key, verifications, exports and orientations at once, and the processes that
take large bodies) are counted in each.
"""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import weakref

import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

stopping = threading.Event()
_STOP_EVENTS: "weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Event]" = weakref.WeakKeyDictionary()


def stop_event() -> asyncio.Event:
    """This event loop's view of ``stopping``: set (thread-safely) when the server is told to stop."""
    loop = asyncio.get_running_loop()
    event = _STOP_EVENTS.get(loop)
    if event is None:
        event = _STOP_EVENTS[loop] = asyncio.Event()
        if stopping.is_set():
            event.set()
    return event


def stop() -> None:
    stopping.set()
    for loop, event in list(_STOP_EVENTS.items()):
        if not loop.is_closed():
            loop.call_soon_threadsafe(event.set)  # from a signal handler, never event.set() directly


class Server(uvicorn.Server):
    def handle_exit(self, sig, frame) -> None:
        stop()
        super().handle_exit(sig, frame)


class HeaderTimeoutH11(H11Protocol):
    header_timeout_s = 10.0

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._header_timer: asyncio.TimerHandle | None = None
        self._arm_header_timer()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._arm_header_timer()

    def connection_lost(self, exc: Exception | None) -> None:
        if getattr(self, "_header_timer", None) is not None:
            self._header_timer.cancel()
        super().connection_lost(exc)

    def _arm_header_timer(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
        waiting_after = self.cycle  # the request before the one whose headers must now arrive
        self._header_timer = self.loop.call_later(self.header_timeout_s, self._headers_too_slow, waiting_after)

    def _headers_too_slow(self, waiting_after) -> None:
        self._header_timer = None
        if self.cycle is waiting_after and not self.transport.is_closing():  # no new request began
            self.transport.close()


def _config(app: str, **where) -> uvicorn.Config:
    from geocert.settings import get_settings

    settings = get_settings()
    HeaderTimeoutH11.header_timeout_s = settings.header_timeout_s
    return uvicorn.Config(app, log_level="warning", http=HeaderTimeoutH11, timeout_keep_alive=5,
                          timeout_graceful_shutdown=settings.shutdown_timeout_s,
                          h11_max_incomplete_event_size=16 * 1024, **where)


def run(app: str, host: str, port: int, processes: int = 1) -> None:
    """Serve ``app`` on host:port until told to stop: in this process alone, or with
    ``processes`` - 1 more API processes on the same listening socket (stopped with this one, and
    by the kernel if this one dies, and by themselves if that fails)."""
    config = _config(app, host=host, port=port)
    if processes <= 1:
        Server(config).run()
        return
    listening = config.bind_socket()
    others = [subprocess.Popen([sys.executable, "-m", "geocert.app.lifecycle", app, str(listening.fileno()),
                                str(os.getpid())], pass_fds=[listening.fileno()])
              for _ in range(processes - 1)]
    try:
        Server(config).run(sockets=[listening])
    finally:
        for other in others:
            other.send_signal(signal.SIGTERM)
        for other in others:
            try:
                other.wait(timeout=(config.timeout_graceful_shutdown or 5) + 5)
            except subprocess.TimeoutExpired:
                other.kill()
        listening.close()


def _serve_inherited(app: str, fd: int, parent: int) -> None:
    """One of ``run``'s other API processes: serves ``app`` on the listening socket ``fd`` until
    told to stop, or until ``parent`` (the process that started it) dies. The kernel is asked for
    that here, not in a preexec_fn (unsafe in a process with threads, as `geocert serve` has)."""
    _die_with_parent()
    if os.getppid() != parent:  # it died before the request took effect
        return
    listening = socket.socket(fileno=fd)
    config = _config(app, host=listening.getsockname()[0], port=listening.getsockname()[1])
    server = Server(config)
    _end_when_orphaned(server, parent, grace_s=(config.timeout_graceful_shutdown or 5) + 5)
    server.run(sockets=[listening])


def _end_when_orphaned(server: Server, parent: int, grace_s: float, poll_s: float = 0.5) -> None:
    """Beside the kernel's signal: a thread that, once ``parent`` is gone, asks ``server`` to stop
    and, if it has not ended ``grace_s`` later, ends the process. An API process must never outlive
    `geocert serve` (it would hold the port), whatever kept the signal from working or the shutdown
    from finishing."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        server.should_exit = True
        stop()
        time.sleep(grace_s)
        os._exit(0)

    threading.Thread(target=watch, name="geocert-orphan-watch", daemon=True).start()


def _die_with_parent() -> None:
    """Ask Linux to send this process SIGTERM when its parent dies, even by SIGKILL."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


if __name__ == "__main__":
    _serve_inherited(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
