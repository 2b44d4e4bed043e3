"""A webhook receiver on loopback, for the abuse tests and bench/abuse.py."""

from __future__ import annotations

import http.server
import threading


class Receiver:
    """A webhook receiver on loopback: ``answer(handler)`` answers each POST (tests use it too)."""

    def __init__(self, answer):
        outer = self
        self.received = 0

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def do_POST(self):
                self.rfile.read(int(self.headers["Content-Length"]))
                outer.received += 1
                answer(self)

            def log_message(self, *args):
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"

    def close(self):
        self.server.shutdown()
