"""Where a webhook may go (geocert/jobs/destinations.py): every address not globally routable is
refused unless its network is allowed, on the address connected to (a name that resolves to
loopback is refused without a connection), and an attempt ends at its deadline however slowly
the other side sends. Nothing here leaves 127.0.0.1."""

from __future__ import annotations

import ipaddress
import socket
import threading
import time

import httpcore
import pytest

from geocert.jobs import destinations
from geocert.jobs.destinations import CheckedBackend, Refused, allowed_networks, literal_refusal, refusal


@pytest.mark.parametrize("address, reason", [
    ("127.0.0.1", "loopback"), ("10.0.0.1", "private"), ("192.168.1.2", "private"), ("172.16.0.1", "private"),
    ("169.254.169.254", "link-local"), ("0.0.0.0", "unspecified"), ("224.0.0.1", "multicast"),
    ("100.100.100.200", "not public"), ("::1", "loopback"), ("fe80::1", "link-local"), ("fd00:ec2::254", "private"),
    ("::ffff:127.0.0.1", "loopback"), ("ff02::1", "multicast"), ("8.8.8.8", None), ("2001:4860:4860::8888", None),
    ("64:ff9b::a9fe:a9fe", "link-local"), ("64:ff9b::a00:1", "private"), ("2002:7f00:1::", "loopback"),
    ("::ffff:0:7f00:1", "loopback"), ("::7f00:1", "loopback"), ("64:ff9b:1::a00:1", "not public"),
    ("64:ff9b::808:808", None), ("2002:808:808::1", None),
])
def test_addresses_not_globally_routable_are_refused(address, reason):
    assert refusal(ipaddress.ip_address(address)) == reason


def test_an_allowed_network_lets_its_addresses_through():
    allowed = allowed_networks("127.0.0.1/32, 10.1.0.0/16")
    assert refusal(ipaddress.ip_address("127.0.0.1"), allowed) is None
    assert refusal(ipaddress.ip_address("10.1.2.3"), allowed) is None
    assert refusal(ipaddress.ip_address("10.2.0.1"), allowed) == "private"
    assert refusal(ipaddress.ip_address("127.0.0.2"), allowed) == "loopback"


def test_hosts_written_as_addresses_are_judged_at_once_and_names_later():
    assert literal_refusal("127.0.0.1") == "loopback" and literal_refusal("[::1]") == "loopback"
    assert literal_refusal("localhost") == "loopback" and literal_refusal("api.localhost") == "loopback"
    assert literal_refusal("hooks.example.com") is None and literal_refusal("93.184.215.14") is None


@pytest.fixture
def listener():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    accepted = []

    def accept():
        try:
            while True:
                connection, _ = server.accept()
                accepted.append(connection)
        except OSError:
            pass

    threading.Thread(target=accept, daemon=True).start()
    yield server.getsockname()[1], accepted
    server.close()
    for connection in accepted:
        connection.close()


def test_a_name_resolving_to_loopback_is_refused_before_any_connection(listener, monkeypatch):
    """DNS rebinding: the name passed the submission's check, and resolves to loopback when the
    webhook is delivered; the address is checked before connecting to it."""
    port, accepted = listener
    monkeypatch.setattr(destinations.socket, "getaddrinfo", lambda host, port, *_, **__: [
        (socket.AF_INET, socket.SOCK_STREAM, 6, "", ("127.0.0.1", port))])
    with pytest.raises(Refused):
        CheckedBackend(time.monotonic() + 5).connect_tcp("rebinding.example", port)
    time.sleep(0.2)
    assert accepted == []
    stream = CheckedBackend(time.monotonic() + 5, allowed_networks("127.0.0.1/32")).connect_tcp("rebinding.example", port)
    stream.close()
    time.sleep(0.2)
    assert len(accepted) == 1


def test_an_exchange_ends_at_its_deadline_however_slowly_the_other_side_sends(listener):
    """A per-read timeout is reset by every byte; the deadline is not."""
    port, accepted = listener
    stream = CheckedBackend(time.monotonic() + 1.0, allowed_networks("127.0.0.1/32")).connect_tcp("127.0.0.1", port)
    while not accepted:
        time.sleep(0.01)
    stop = threading.Event()

    def dribble():
        while not stop.wait(0.2):
            try:
                accepted[0].sendall(b"x")
            except OSError:
                return

    threading.Thread(target=dribble, daemon=True).start()
    received = b""
    try:
        with pytest.raises(httpcore.ReadTimeout):
            while True:
                received += stream.read(1024, timeout=0.5)  # each read is answered within its own timeout
    finally:
        stop.set()
        stream.close()
    assert 1 <= len(received) <= 10
