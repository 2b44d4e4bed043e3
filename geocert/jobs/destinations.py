"""Where a webhook may go: public addresses only, checked on the address actually connected to.

A ``callback_url`` is chosen by the client, and the service POSTs to it from inside its own
network: without a check, a client could have the service reach its Redis (``127.0.0.1:6379``),
a cloud's metadata service (``169.254.169.254``) or any private host, and read from the delivery
record which ports answered. So every address a destination resolves to is checked, and the
connection is made to a checked address itself (not to the name again, which DNS could then
answer differently: rebinding). Refused: every address that is not globally routable (loopback,
private, link-local and so metadata, shared, reserved, unspecified, documentation) and every
multicast address, IPv4 written inside IPv6 included (mapped, NAT64, 6to4, SIIT), unless it
lies in one of the networks the operator allows (GEOCERT_WEBHOOK_ALLOWED_NETWORKS, e.g. a
receiver on the same host for tests).

The connection is made by an httpcore network backend (``CheckedBackend``), which also holds each
attempt to one deadline in all: every read and write is given what is left of it (a receiver
sending one byte every few seconds no longer resets a per-read timeout for ever).
"""

from __future__ import annotations

import ipaddress
import socket
import time
from functools import lru_cache
from typing import Iterable

import httpcore

Address = ipaddress.IPv4Address | ipaddress.IPv6Address


class Refused(httpcore.ConnectError):
    """The destination resolves to no address a webhook may go to (nothing was sent)."""


@lru_cache(maxsize=16)
def allowed_networks(text: str) -> tuple[ipaddress.IPv4Network | ipaddress.IPv6Network, ...]:
    """The networks of a comma-separated list of addresses or CIDR blocks (GEOCERT_WEBHOOK_ALLOWED_NETWORKS)."""
    return tuple(ipaddress.ip_network(part.strip(), strict=False) for part in text.split(",") if part.strip())


# IPv6 addresses whose last 32 bits are an IPv4 address that a translator or tunnel delivers
# to: NAT64's well-known prefix (a cloud's NAT64 gateway takes 64:ff9b::a00:1 to 10.0.0.1 in
# its network), IPv4-translated (SIIT) and the deprecated IPv4-compatible addresses. Each is
# judged by the IPv4 address inside it, as the IPv4-mapped ones and 6to4's (2002::/16) are.
_EMBEDDING_IPV4 = tuple(ipaddress.ip_network(n) for n in ("64:ff9b::/96", "::ffff:0:0:0/96", "::/96"))
# NAT64's local-use prefix (RFC 8215) places the IPv4 address where its operator chose, and is
# never globally reachable.
_LOCAL_NAT64 = ipaddress.ip_network("64:ff9b:1::/48")


def embedded_ipv4(address: ipaddress.IPv6Address) -> ipaddress.IPv4Address | None:
    """The IPv4 address an IPv6 address reaches through a translator or tunnel, if any."""
    if address.is_loopback or address.is_unspecified:  # ::1 and :: are themselves, not 0.0.0.1
        return None
    if address.ipv4_mapped is not None:
        return address.ipv4_mapped
    if address.sixtofour is not None:
        return address.sixtofour
    if any(address in network for network in _EMBEDDING_IPV4):
        return ipaddress.IPv4Address(int(address) & 0xFFFFFFFF)
    return None


def refusal(address: Address, allowed: Iterable = ()) -> str | None:
    """Why a webhook may not go to this address (None: it may)."""
    if any(address.version == network.version and address in network for network in allowed):
        return None
    if isinstance(address, ipaddress.IPv6Address):
        if address in _LOCAL_NAT64:
            return "not public"
        inner = embedded_ipv4(address)
        if inner is not None:
            return refusal(inner, allowed)
    if address.is_multicast:
        return "multicast"
    if not address.is_global:
        for name in ("unspecified", "loopback", "link_local", "private", "reserved"):
            if getattr(address, f"is_{name}"):
                return name.replace("_", "-")
        return "not public"
    return None


def literal_refusal(host: str, allowed: Iterable = ()) -> str | None:
    """For a URL's host written as an address (or ``localhost``): why it is refused, else None
    (a name is resolved, and checked, only when a delivery is made)."""
    host = host.strip("[]")
    if host.lower() == "localhost" or host.lower().endswith(".localhost"):
        return refusal(ipaddress.ip_address("127.0.0.1"), allowed)
    try:
        return refusal(ipaddress.ip_address(host), allowed)
    except ValueError:
        return None


class DeadlineStream(httpcore.NetworkStream):
    """A connection whose every read and write is given at most what is left before ``deadline``
    (time.monotonic()), so the whole exchange ends by then however slowly the other side sends."""

    def __init__(self, stream: httpcore.NetworkStream, deadline: float):
        self.stream, self.deadline = stream, deadline

    def _left(self, timeout: float | None) -> float:
        left = self.deadline - time.monotonic()
        if left <= 0:
            raise httpcore.ReadTimeout("the delivery's deadline passed")
        return left if timeout is None else min(timeout, left)

    def read(self, max_bytes: int, timeout: float | None = None) -> bytes:
        return self.stream.read(max_bytes, self._left(timeout))

    def write(self, buffer: bytes, timeout: float | None = None) -> None:
        self.stream.write(buffer, self._left(timeout))

    def close(self) -> None:
        self.stream.close()

    def start_tls(self, ssl_context, server_hostname: str | None = None, timeout: float | None = None):
        return DeadlineStream(self.stream.start_tls(ssl_context, server_hostname, self._left(timeout)), self.deadline)

    def get_extra_info(self, info: str):
        return self.stream.get_extra_info(info)


class CheckedBackend(httpcore.NetworkBackend):
    """Connects only to addresses ``refusal`` lets through, and holds the connection to ``deadline``."""

    def __init__(self, deadline: float, allowed: Iterable = ()):
        self.deadline, self.allowed = deadline, tuple(allowed)

    def connect_tcp(self, host: str, port: int, timeout: float | None = None, local_address: str | None = None,
                    socket_options=None) -> httpcore.NetworkStream:
        try:
            found = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as exc:
            raise httpcore.ConnectError(f"the name did not resolve: {exc}") from None
        reasons = []
        for *_, address in found:
            checked = ipaddress.ip_address(address[0].split("%")[0])
            reason = refusal(checked, self.allowed)
            if reason is not None:
                reasons.append(reason)
                continue
            left = self.deadline - time.monotonic()
            if left <= 0:
                raise httpcore.ConnectTimeout("the delivery's deadline passed")
            try:  # to the address checked, not to the name (which could resolve elsewhere now)
                stream = httpcore.SyncBackend().connect_tcp(str(checked), port, left if timeout is None else
                                                            min(timeout, left), socket_options=socket_options)
            except (httpcore.ConnectError, httpcore.ConnectTimeout):
                continue
            peer = ipaddress.ip_address(stream.get_extra_info("socket").getpeername()[0].split("%")[0])
            if refusal(peer, self.allowed) is not None:
                stream.close()
                continue
            return DeadlineStream(stream, self.deadline)
        if reasons and len(reasons) == len(found):
            raise Refused(f"the destination resolves only to refused addresses ({', '.join(sorted(set(reasons)))})")
        raise httpcore.ConnectError("no address of the destination accepted a connection")
