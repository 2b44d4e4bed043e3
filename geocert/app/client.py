"""A Python client for the geocert HTTP API (on httpx).

    from geocert.app.client import Client

    with Client("http://127.0.0.1:8000") as geocert:        # API key: argument or GEOCERT_API_KEY
        job = geocert.submit("triangulation", {"cameras": [...], "tracks": [...]}, {"norm": "L2L2"})
        for event in job.stream():                          # progress as Server-Sent Events
            print(event.event, event.data)
        result = job.result(timeout=60)                     # waits; raises JobFailed if it failed
        certificate = job.certificate()                     # with options {"certificate": "full"}

Every error answer raises a subclass of ``GeocertError`` carrying the RFC 9457 problem document
(``error.problem``, ``error.status``, ``error.detail``, ``error.fields``). Requests that are safe
to repeat are retried on connection errors, 429 (after ``Retry-After``) and 502/503/504;
``submit`` sends an ``Idempotency-Key`` (made up unless given) so a retried submission never makes
a second job. ``stream`` reconnects after a dropped connection with ``Last-Event-ID`` and goes on
from the event after the last one it yielded.
"""

from __future__ import annotations

import json
import os
import time
import uuid
from dataclasses import dataclass
from typing import Any, Iterator

import httpx

TERMINAL = ("succeeded", "failed", "cancelled")
_RETRY_STATUSES = (429, 502, 503, 504)


# --- errors -----------------------------------------------------------------------------------
class GeocertError(Exception):
    """An error answer from the service; ``problem`` is its problem+json document."""

    def __init__(self, status: int, problem: dict | None, message: str | None = None, headers: dict | None = None):
        self.status = status
        self.problem = problem or {}
        self.headers = dict(headers or {})
        self.title = self.problem.get("title")
        self.detail = self.problem.get("detail")
        super().__init__(message or f"HTTP {status}: {self.detail or self.title or 'error'}")

    @property
    def fields(self) -> list[dict]:
        """The ``errors`` member: ``[{"field": "data/tracks/0/views", "reason": "..."}, ...]``."""
        return list(self.problem.get("errors") or [])


class BadRequest(GeocertError):
    """400: the body is not JSON (``problem`` has ``line`` and ``column``)."""


class Unauthorized(GeocertError):
    """401: no API key (pass ``api_key`` or set GEOCERT_API_KEY)."""


class Forbidden(GeocertError):
    """403: the API key is not valid."""


class NotFound(GeocertError):
    """404: no such job for this key."""


class Conflict(GeocertError):
    """409: the job's state does not allow this (e.g. cancelling a finished job)."""


class PayloadTooLarge(GeocertError):
    """413: a limit of the service (named in ``detail``)."""


class UnsupportedMediaType(GeocertError):
    """415."""


class InvalidRequest(GeocertError):
    """422: invalid input; ``fields`` names each field and the reason."""


class RateLimited(GeocertError):
    """429: a rate or active-job limit; ``retry_after`` seconds."""

    @property
    def retry_after(self) -> float | None:
        value = self.headers.get("retry-after")
        return float(value) if value is not None else None


class ServerError(GeocertError):
    """5xx."""


class JobFailed(GeocertError):
    """The job ended ``failed``: ``problem`` is its error, ``job`` the job document."""

    def __init__(self, job: dict):
        self.job = job
        error = job.get("error") or {}
        super().__init__(int(error.get("status") or 500), error,
                         f"job {job.get('id')} failed: {error.get('detail') or error.get('title') or 'no reason given'}")


class WaitTimeout(TimeoutError):
    """``wait`` ran out of time; ``job`` is the last job document seen."""

    def __init__(self, job: dict, timeout: float):
        self.job = job
        super().__init__(f"job {job.get('id')} still {job.get('status')} after {timeout:g} s")


_BY_STATUS = {400: BadRequest, 401: Unauthorized, 403: Forbidden, 404: NotFound, 409: Conflict, 413: PayloadTooLarge,
              415: UnsupportedMediaType, 422: InvalidRequest, 429: RateLimited}


def error_for(response: httpx.Response) -> GeocertError:
    try:
        problem = response.json()
        if not isinstance(problem, dict):
            problem = {"detail": str(problem)}
    except ValueError:
        problem = {"detail": response.text[:500] or None}
    cls = _BY_STATUS.get(response.status_code, ServerError if response.status_code >= 500 else GeocertError)
    return cls(response.status_code, problem, headers={k.lower(): v for k, v in response.headers.items()})


# --- events -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Event:
    """One Server-Sent Event of a job: ``status``, ``progress`` or ``end``; ``data`` is parsed JSON."""

    id: str
    event: str
    data: Any


def _parse_events(lines: Iterator[str]) -> Iterator[Event]:
    fields: dict[str, str] = {}
    data: list[str] = []
    for line in lines:
        if line == "":
            if data or "event" in fields:
                text = "\n".join(data)
                yield Event(fields.get("id", ""), fields.get("event", "message"), json.loads(text) if text else None)
            fields, data = {}, []
        elif line.startswith(":"):
            continue  # a comment (keepalive)
        else:
            name, _, value = line.partition(":")
            value = value[1:] if value.startswith(" ") else value
            if name == "data":
                data.append(value)
            else:
                fields[name] = value


# --- the client -------------------------------------------------------------------------------
class Client:
    """The geocert API at ``base_url``. ``api_key`` defaults to the GEOCERT_API_KEY variable;
    ``retries`` repeats safe requests on connection errors, 429 and 502/503/504, waiting
    ``backoff_s`` doubling (or the server's ``Retry-After``, at most ``max_wait_s``)."""

    def __init__(self, base_url: str = "http://127.0.0.1:8000", api_key: str | None = None, *,
                 timeout: float = 30.0, retries: int = 4, backoff_s: float = 0.25, max_wait_s: float = 30.0,
                 transport: httpx.BaseTransport | None = None):
        api_key = api_key if api_key is not None else os.environ.get("GEOCERT_API_KEY") or None
        headers = {"User-Agent": "geocert-client", "Accept": "application/json"}
        if api_key:
            headers["X-API-Key"] = api_key
        self.retries, self.backoff_s, self.max_wait_s = retries, backoff_s, max_wait_s
        self.http = httpx.Client(base_url=base_url, headers=headers, timeout=timeout, transport=transport)

    def close(self) -> None:
        self.http.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *_) -> None:
        self.close()

    # --- plumbing ------------------------------------------------------------------------------
    def _request(self, method: str, path: str, *, retry: bool = True, **kwargs) -> httpx.Response:
        attempt = 0
        while True:
            try:
                response = self.http.request(method, path, **kwargs)
            except httpx.TransportError:
                if not retry or attempt >= self.retries:
                    raise
                self._sleep(attempt, None)
                attempt += 1
                continue
            if response.status_code < 400:
                return response
            error = error_for(response)
            in_progress = response.status_code == 409 and "Idempotency-Key" in kwargs.get("headers", {})
            if retry and attempt < self.retries and (response.status_code in _RETRY_STATUSES or in_progress):
                self._sleep(attempt, response.headers.get("Retry-After"))
                attempt += 1
                continue
            raise error

    def _sleep(self, attempt: int, retry_after: str | None) -> None:
        wait = self.backoff_s * 2 ** attempt
        if retry_after is not None:
            try:
                wait = max(wait, float(retry_after))
            except ValueError:
                pass
        time.sleep(min(wait, self.max_wait_s))

    # --- jobs ----------------------------------------------------------------------------------
    def submit(self, kind: str, data: dict, options: dict | None = None, *, callback_url: str | None = None,
               idempotency_key: str | None = None) -> "Job":
        """Queue a job and return its handle. The same ``idempotency_key`` and body always give
        the same job, so retries (ours or yours) never make a second one."""
        body: dict[str, Any] = {"kind": kind, "data": data}
        if options is not None:
            body["options"] = options
        if callback_url is not None:
            body["callback_url"] = callback_url
        key = idempotency_key or uuid.uuid4().hex
        response = self._request("POST", "/v1/jobs", json=body, headers={"Idempotency-Key": key})
        document = response.json()
        return Job(self, document["id"], document)

    def job(self, job_id: str) -> dict:
        """The job document: status, progress, and once finished the result or error."""
        return self._request("GET", f"/v1/jobs/{job_id}").json()

    def handle(self, job_id: str) -> "Job":
        """A handle on an existing job (for instance one found with ``jobs()``)."""
        return Job(self, job_id)

    def jobs(self, status: str | list[str] | None = None, page_size: int = 50) -> Iterator[dict]:
        """Every job of this key, newest first (summaries without results), page after page."""
        params: list[tuple[str, str]] = [("limit", str(page_size))]
        for one in [status] if isinstance(status, str) else status or []:
            params.append(("status", one))
        cursor = None
        while True:
            page = self._request("GET", "/v1/jobs", params=params + ([("cursor", cursor)] if cursor else [])).json()
            yield from page["jobs"]
            cursor = page.get("next_cursor")
            if not cursor:
                return

    def wait(self, job_id: str, timeout: float | None = None, poll_s: float = 0.1) -> dict:
        """Poll until the job ends and return its document; ``WaitTimeout`` after ``timeout`` s."""
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = poll_s
        while True:
            document = self.job(job_id)
            if document["status"] in TERMINAL:
                return document
            if deadline is not None and time.monotonic() >= deadline:
                raise WaitTimeout(document, timeout)
            pause = delay if deadline is None else min(delay, max(0.0, deadline - time.monotonic()))
            time.sleep(pause)
            delay = min(2 * delay, 2.0)

    def stream(self, job_id: str, last_event_id: str | None = None, timeout: float | None = None) -> Iterator[Event]:
        """The job's events until its ``end`` event. After ``last_event_id`` when given; a dropped
        connection is resumed from the last event yielded (``Last-Event-ID``)."""
        last = last_event_id
        attempt = 0
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            headers = {"Accept": "text/event-stream"}
            if last:
                headers["Last-Event-ID"] = last
            try:
                with self.http.stream("GET", f"/v1/jobs/{job_id}/events", headers=headers,
                                      timeout=httpx.Timeout(self.http.timeout.connect, read=30.0)) as response:
                    if response.status_code >= 400:
                        response.read()
                        raise error_for(response)
                    for event in _parse_events(response.iter_lines()):
                        attempt = 0
                        if event.id:
                            last = event.id
                        yield event
                        if event.event == "end":
                            return
                        if deadline is not None and time.monotonic() >= deadline:
                            raise WaitTimeout(self.job(job_id), timeout)
                return  # the server closed the stream (the job expired or was deleted)
            except httpx.TransportError:
                if attempt >= self.retries:
                    raise
                self._sleep(attempt, None)
                attempt += 1

    def cancel(self, job_id: str) -> dict:
        """Cancel a queued or running job; ``Conflict`` when it has already ended."""
        return self._request("POST", f"/v1/jobs/{job_id}/cancel").json()

    def delete(self, job_id: str) -> None:
        """Remove a finished job; ``Conflict`` while it is queued or running."""
        self._request("DELETE", f"/v1/jobs/{job_id}")

    def result(self, job_id: str, timeout: float | None = None) -> dict:
        """Wait for the job and return its result; ``JobFailed`` when it failed. A cancelled job
        returns the result it kept (items ``cancelled`` with their best answer and gap)."""
        document = self.wait(job_id, timeout)
        if document["status"] == "failed":
            raise JobFailed(document)
        return document["result"]

    def certificate(self, job_id: str) -> dict:
        """The full certificate of a finished job submitted with ``{"certificate": "full"}``."""
        return self._request("GET", f"/v1/jobs/{job_id}/certificate").json()

    # --- other routes --------------------------------------------------------------------------
    def verify(self, document: dict) -> dict:
        """Check a certificate, a result or a job document with the service's verifier."""
        return self._request("POST", "/v1/certificates/verify", json=document).json()

    def orient(self, cameras: list, points: list, views: list[list[int]] | None = None) -> dict:
        """Fix the signs (and if need be the frame) of a projective reconstruction."""
        body: dict[str, Any] = {"cameras": cameras, "points": points}
        if views is not None:
            body["views"] = views
        return self._request("POST", "/v1/orient", json=body).json()

    def problems(self) -> list[dict]:
        return self._request("GET", "/v1/problems").json()

    def ready(self) -> bool:
        try:
            return self.http.get("/readyz").status_code == 200
        except httpx.TransportError:
            return False


class Job:
    """A submitted job: ``wait``, ``stream``, ``cancel``, ``result``, ``certificate``."""

    def __init__(self, client: Client, job_id: str, document: dict | None = None):
        self.client, self.id, self.document = client, job_id, document

    def __repr__(self) -> str:
        return f"Job({self.id!r}, status={(self.document or {}).get('status')!r})"

    def refresh(self) -> dict:
        self.document = self.client.job(self.id)
        return self.document

    @property
    def status(self) -> str:
        return self.refresh()["status"]

    def wait(self, timeout: float | None = None) -> dict:
        self.document = self.client.wait(self.id, timeout)
        return self.document

    def stream(self, last_event_id: str | None = None, timeout: float | None = None) -> Iterator[Event]:
        return self.client.stream(self.id, last_event_id, timeout)

    def cancel(self) -> dict:
        self.document = self.client.cancel(self.id)
        return self.document

    def result(self, timeout: float | None = None) -> dict:
        return self.client.result(self.id, timeout)

    def certificate(self) -> dict:
        return self.client.certificate(self.id)

    def delete(self) -> None:
        self.client.delete(self.id)


__all__ = ["Client", "Job", "Event", "GeocertError", "BadRequest", "Unauthorized", "Forbidden", "NotFound",
           "Conflict", "PayloadTooLarge", "UnsupportedMediaType", "InvalidRequest", "RateLimited", "ServerError",
           "JobFailed", "WaitTimeout", "error_for"]
