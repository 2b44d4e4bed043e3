"""The production reverse proxy's configuration (deploy/nginx.conf, the `proxy` service of
docker-compose.yml) run by nginx in front of a real API on loopback: the checked-in file, with only
the compose names (the API's host, the ports, the certificate's directory) replaced by local ones.
Skipped where nginx or openssl is not installed."""

from __future__ import annotations

import shutil
import socket
import ssl
import subprocess
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.servers import cluster, free_port
from tests.support import ROOT, service_job

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not (shutil.which("nginx") and shutil.which("openssl")), reason="needs nginx and openssl")]


def render(directory: Path, api_port: int, http_port: int, https_port: int) -> Path:
    text = (ROOT / "deploy" / "nginx.conf").read_text()
    for old, new in (("server api:8000;", f"server 127.0.0.1:{api_port};"),
                     ("listen 80;", f"listen 127.0.0.1:{http_port};"),
                     ("listen 443 ssl http2;", f"listen 127.0.0.1:{https_port} ssl http2;"),
                     ("/etc/nginx/tls/", f"{directory}/"),
                     ("pid /tmp/nginx.pid;", f"pid {directory}/nginx.pid;")):
        assert old in text, f"deploy/nginx.conf no longer has {old!r}: update this test with it"
        text = text.replace(old, new)
    text = "\n".join(line for line in text.splitlines() if "listen [::]" not in line)
    path = directory / "nginx.conf"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def proxied(tmp_path_factory):
    directory = tmp_path_factory.mktemp("proxy")
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", "/CN=localhost",
                    "-keyout", str(directory / "privkey.pem"), "-out", str(directory / "fullchain.pem")],
                   check=True, capture_output=True)
    with cluster(directory / "service", workers=0, geocert_rate_limit_per_minute="5") as (running, _):
        http_port, https_port = free_port(), free_port()
        config = render(directory, running.port, http_port, https_port)
        checked = subprocess.run(["nginx", "-t", "-e", "stderr", "-p", str(directory), "-c", str(config)],
                                 capture_output=True, text=True)
        assert checked.returncode == 0, checked.stderr
        nginx = subprocess.Popen(["nginx", "-e", "stderr", "-p", str(directory), "-c", str(config),
                                  "-g", "daemon off;"], stderr=subprocess.PIPE)
        base = f"https://127.0.0.1:{https_port}"
        try:
            deadline = time.monotonic() + 20
            while True:
                try:
                    if httpx.get(base + "/healthz", verify=False).status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                assert nginx.poll() is None, nginx.stderr.read().decode()
                assert time.monotonic() < deadline, "nginx did not answer"
                time.sleep(0.2)
            yield base, http_port, https_port
        finally:
            nginx.terminate()
            nginx.wait(timeout=10)


def client_from(base: str, address: str = "127.0.0.1") -> httpx.Client:
    return httpx.Client(base_url=base, timeout=30, verify=False,
                        transport=httpx.HTTPTransport(local_address=address, verify=False))


def test_tls_in_front_and_http_redirected(proxied):
    base, http_port, _ = proxied
    with client_from(base) as client:
        assert client.get("/healthz").status_code == 200
    redirect = httpx.get(f"http://127.0.0.1:{http_port}/healthz")
    assert redirect.status_code == 308 and redirect.headers["location"].startswith("https://")


def test_a_body_over_the_limit_is_the_proxys_413_problem(proxied):
    base, _, _ = proxied
    with client_from(base) as client:
        response = client.post("/v1/jobs", content=b" " * (33 * 2**20), headers={"content-type": "application/json"})
    assert response.status_code == 413
    assert response.headers["content-type"] == "application/problem+json"
    assert "client_max_body_size" in response.json()["detail"]  # the proxy's answer, not the API's


def test_slow_headers_are_closed_by_the_proxy(proxied):
    _, _, https_port = proxied
    context = ssl.create_default_context()
    context.check_hostname, context.verify_mode = False, ssl.CERT_NONE
    sock = context.wrap_socket(socket.create_connection(("127.0.0.1", https_port)), server_hostname="localhost")
    sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n")
    sock.settimeout(1)
    start, closed = time.monotonic(), None
    while closed is None and time.monotonic() - start < 40:
        try:
            sock.sendall(b"X-Slow: 1\r\n")
            if sock.recv(100) == b"":
                closed = time.monotonic() - start
        except socket.timeout:
            pass
        except OSError:
            closed = time.monotonic() - start
    sock.close()
    assert closed is not None, "a slow-header connection was still open after 40 s"
    print(f"\nslow headers through the proxy: closed after {closed:.1f} s")


def test_each_client_address_keeps_its_own_budget_through_the_proxy(proxied):
    """The proxy passes the client's address (X-Forwarded-For), so without keys the API's
    per-address budget (5 a minute here) sees two clients, not one proxy."""
    base, _, _ = proxied
    if time.time() % 60 > 50:  # a fixed window per minute: start well inside one
        time.sleep(61 - time.time() % 60)
    with client_from(base, "127.0.0.5") as flooder, client_from(base, "127.0.0.6") as other:
        assert [flooder.get("/v1/problems").status_code for _ in range(6)] == [200] * 5 + [429]
        assert other.get("/v1/problems").status_code == 200


def test_event_streams_come_through_unbuffered(proxied):
    base, _, _ = proxied
    with client_from(base, "127.0.0.7") as client:
        job_id = client.post("/v1/jobs", json=service_job(np.random.default_rng(5), 2)).json()["id"]
        with client.stream("GET", f"/v1/jobs/{job_id}/events") as stream:
            assert stream.status_code == 200
            lines = stream.iter_lines()
            assert next(lines) == "event: status"  # the first event arrives while the stream is open
