"""API keys: ``X-API-Key``, checked in constant time against GEOCERT_API_KEYS.

Keys are kept only as SHA-256 digests (a key may be configured as ``sha256:<hex>`` so the
plain key never sits in the environment). A caller is known by its key's digest: that is the
owner recorded on its jobs, so a job is visible only to the key that created it.
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
from functools import lru_cache
from typing import Annotated

from fastapi import HTTPException, Security
from fastapi.security import APIKeyHeader

from geocert.settings import get_settings
from geocert.jobs.store import PUBLIC_OWNER  # every caller, when no keys are configured (loopback only)

api_key_header = APIKeyHeader(
    name="X-API-Key", auto_error=False, scheme_name="ApiKey",
    description="One of the keys in GEOCERT_API_KEYS; required on /v1 whenever keys are configured.",
)


def digest(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def parse_keys(setting: str) -> tuple[str, ...]:
    """The configured keys as hex digests; raises ValueError on a malformed ``sha256:`` entry."""
    digests = []
    for entry in (part.strip() for part in setting.split(",")):
        if not entry:
            continue
        if entry.startswith("sha256:"):
            hex_digest = entry[len("sha256:"):].lower()
            if len(hex_digest) != 64 or any(c not in "0123456789abcdef" for c in hex_digest):
                raise ValueError("GEOCERT_API_KEYS: a sha256: entry must be 64 hex digits")
            digests.append(hex_digest)
        else:
            digests.append(digest(entry))
    return tuple(digests)


@lru_cache
def configured_digests() -> tuple[str, ...]:
    return parse_keys(get_settings().api_keys)


async def caller(key: Annotated[str | None, Security(api_key_header)] = None) -> str:
    """The owner id of the caller: 401 without a key, 403 with a wrong one (when keys are configured).
    Pure computation, so it runs on the event loop (no thread pool round trip per request)."""
    digests = configured_digests()
    if not digests:
        return PUBLIC_OWNER
    if not key:
        raise HTTPException(401, "an X-API-Key header is required", headers={"WWW-Authenticate": "ApiKey"})
    presented = digest(key)
    matched = False
    for known in digests:  # compare with every key, so the time taken does not tell which matched
        matched |= hmac.compare_digest(presented, known)
    if not matched:
        raise HTTPException(403, "the X-API-Key is not valid")
    return presented[:32]


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False
