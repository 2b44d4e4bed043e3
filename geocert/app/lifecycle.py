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
"""

from __future__ import annotations

import asyncio
import threading
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


def run(app: str, host: str, port: int) -> None:
    from geocert.settings import get_settings

    settings = get_settings()
    HeaderTimeoutH11.header_timeout_s = settings.header_timeout_s
    config = uvicorn.Config(app, host=host, port=port, log_level="warning", http=HeaderTimeoutH11,
                            timeout_keep_alive=5, timeout_graceful_shutdown=settings.shutdown_timeout_s,
                            h11_max_incomplete_event_size=16 * 1024)
    Server(config).run()
