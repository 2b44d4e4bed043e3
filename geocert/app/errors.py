"""RFC 9457 problem+json for every error the API returns."""

from __future__ import annotations

import json
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from geocert.core.geometry import InputError
from geocert.core.strict import printable_tree
from geocert.kinds import KINDS
from geocert.kinds.reconstruction import NO_CONTROL_CHARACTERS
from geocert.jobs.store import REDIS_GONE

PROBLEM_JSON = "application/problem+json"
REDIS_RETRY_AFTER_S = 5  # Retry-After of a 503 while Redis does not answer


class ApiProblem(Exception):
    """An error answer with a field named (when one is to blame) and optional headers."""

    def __init__(self, status: int, detail: str, field: str | None = None, headers: dict | None = None):
        super().__init__(detail)
        self.status, self.detail, self.field, self.headers = status, detail, field, headers


def problem(status: int, title: str, detail: str | None = None, errors: list[dict] | None = None,
            instance: str | None = None, headers: dict | None = None) -> JSONResponse:
    body = {"type": "about:blank", "title": title, "status": status}
    if detail is not None:
        body["detail"] = detail
    if instance is not None:
        body["instance"] = instance
    if errors:
        body["errors"] = errors
    return problem_response(body, status, headers)


def problem_response(body: dict, status: int, headers: dict | None = None) -> JSONResponse:
    """A problem document as the answer; its texts may quote the request (a member name), so a
    lone surrogate there (valid as a JSON escape, not encodable as UTF-8) is written as its escape."""
    return JSONResponse(printable_tree(body), status_code=status, media_type=PROBLEM_JSON, headers=headers)


def field_path(loc: tuple) -> str:
    """A pydantic error location as the field path we name in problems (``data/tracks/0/views``):
    without the request part and without the tag of the job's kind (the union's branch)."""
    parts = [str(p) for p in loc]
    if parts and parts[0] in ("body", "query", "path", "header"):
        parts = parts[1:]
    if parts and parts[0] in KINDS:
        parts = parts[1:]
    return "/".join(parts) or "body"


_JSON_TYPES = {str: "a string", bool: "a boolean", float: "a decimal number", type(None): "null",
               list: "an array", dict: "an object"}


# What a pattern of the wire contract asks, in words (pydantic's message quotes the expression).
_PATTERN_REASONS = {NO_CONTROL_CHARACTERS: "must not contain control characters (a line break, a tab, ...): names "
                                           "are written into exported files"}


def _reason(error: dict) -> str:
    """pydantic's message (a pattern's in words), and for a strict type error what the JSON held
    instead."""
    reason = error.get("msg", "invalid")
    if error.get("type") == "string_pattern_mismatch":
        reason = _PATTERN_REASONS.get((error.get("ctx") or {}).get("pattern"), reason)
    if error.get("type") in ("float_type", "int_type", "int_from_float", "bool_type", "string_type"):
        given = error.get("input")
        if type(given) in _JSON_TYPES:
            shown = json.dumps(given) if isinstance(given, (str, bool, float)) else ""
            reason += f" (got {_JSON_TYPES[type(given)]}{' ' + shown if shown else ''})"
    return reason


def _given(value: Any) -> str:
    """A JSON value as a reason quotes it: its type in words and the value (``a number 5``), so a
    number is never shown as the string pydantic's tag makes of it ('5')."""
    if isinstance(value, str):
        return f"the string {json.dumps(value)}"
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, (int, float)):
        return f"the number {json.dumps(value)}"
    return _JSON_TYPES.get(type(value), "a value of another type")


def _field(error: dict) -> dict:
    """One pydantic error as the field it names and why. The job's kind (the union's tag) missing
    or not one served is the field ``kind``, not ``body`` (pydantic places it on the union), and
    the reason says it must be one of the kinds served, quoting what was given as JSON (a number
    5 is not the string '5' pydantic's tag makes of it)."""
    loc = tuple(error.get("loc", ()))
    if error.get("type") in ("union_tag_not_found", "union_tag_invalid"):
        ctx = error.get("ctx") or {}
        tag = str(ctx.get("discriminator", "kind")).strip("'")
        served = ", ".join(json.dumps(name) for name in dict.fromkeys(kind.name for kind in KINDS))
        reason = f"must be one of the kinds served, a string: {served}"
        if error["type"] == "union_tag_not_found":
            reason = f"Field required: {reason}"
        else:
            body = error.get("input")
            given = body[tag] if isinstance(body, dict) and tag in body else ctx.get("tag")
            reason += f" (got {_given(given)})"
        return {"field": field_path(loc + (tag,)), "reason": reason}
    return {"field": field_path(loc), "reason": _reason(error)}


def validation_problem(errors: list[dict], instance: str | None = None) -> dict:
    """422 problem details from pydantic errors."""
    fields = [_field(e) for e in errors]
    first = fields[0] if fields else {"field": "body", "reason": "invalid"}
    body = {"type": "about:blank", "title": "Invalid request", "status": 422,
            "detail": f"{first['field']}: {first['reason']}", "errors": fields}
    if instance:
        body["instance"] = instance
    return body


def long_number_reason(exc: ValueError) -> str:
    """Why a body Python's JSON parser refused with a plain ValueError cannot be read: valid JSON
    (so not a syntax error, 400) holding an integer of more digits than ``int`` converts
    (sys.get_int_max_str_digits, a guard against quadratic conversion); no value the API takes
    is written with so many. Answered 422 naming the body, as /v1/certificates/verify does, in the
    verifier's reader's words (core.strict.Unreadable), less Python's advice to raise the limit."""
    from geocert.core.strict import Unreadable

    return str(Unreadable(str(exc).split("; use sys.set_int_max_str_digits", 1)[0]))


def is_json_media_type(value: str | None) -> bool:
    """``application/json`` or ``application/<anything>+json``, parameters allowed."""
    if not value:
        return False
    media = value.split(";", 1)[0].strip().lower()
    return media == "application/json" or (media.startswith("application/") and media.endswith("+json"))


def json_syntax_problem(error: dict, document: Any, instance: str | None = None) -> dict:
    """400 problem details for a body the JSON parser refused: its message, line and column."""
    position = error.get("loc", ("body", 0))[-1]
    position = position if isinstance(position, int) else 0
    text = document.decode("utf-8", "replace") if isinstance(document, (bytes, bytearray)) else str(document or "")
    line = text.count("\n", 0, position) + 1
    column = position - (text.rfind("\n", 0, position) + 1) + 1
    message = (error.get("ctx") or {}).get("error") or "invalid JSON"
    reason = f"not valid JSON: {message} at line {line}, column {column}"
    body = {"type": "about:blank", "title": "Bad request", "status": 400, "detail": f"the request body is {reason}",
            "errors": [{"field": "body", "reason": reason}], "line": line, "column": column}
    if instance:
        body["instance"] = instance
    return body


def install(app: FastAPI) -> None:
    @app.exception_handler(RequestValidationError)
    async def validation(request: Request, exc: RequestValidationError):
        errors = list(exc.errors())
        instance = str(request.url.path)
        syntax = next((e for e in errors if e.get("type") == "json_invalid"), None)
        if syntax is not None:
            return problem_response(json_syntax_problem(syntax, exc.body, instance), 400)
        content_type = request.headers.get("content-type")
        if request.method in ("POST", "PUT", "PATCH") and not is_json_media_type(content_type) and any(
                tuple(e.get("loc", ()))[:1] == ("body",) for e in errors):
            given = f"it was {content_type!r}" if content_type else "it was missing"
            return problem(415, "Unsupported media type",
                           f"the body must be JSON sent with the header content-type: application/json ({given})",
                           [{"field": "content-type", "reason": "must be application/json"}], instance=instance)
        return problem_response(validation_problem(errors, instance=instance), 422)

    @app.exception_handler(InputError)
    async def input_error(request: Request, exc: InputError):
        return problem(422, "Invalid request", str(exc), [{"field": exc.field, "reason": exc.reason}],
                       instance=str(request.url.path))

    @app.exception_handler(ApiProblem)
    async def api_problem(request: Request, exc: ApiProblem):
        errors = [{"field": exc.field, "reason": exc.detail}] if exc.field else None
        return problem(exc.status, _TITLES.get(exc.status, "Error"), exc.detail, errors,
                       instance=str(request.url.path), headers=exc.headers)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException):
        return problem(exc.status_code, _TITLES.get(exc.status_code, "Error"), str(exc.detail),
                       instance=str(request.url.path), headers=getattr(exc, "headers", None))

    async def redis_unavailable(request: Request, exc: Exception):
        # Redis restarting, loading its append-only file or unreachable: a passing state the
        # client can retry, not a server fault.
        return problem(503, "Service unavailable",
                       f"the job store (Redis) is not answering ({type(exc).__name__}); retry shortly",
                       instance=str(request.url.path), headers={"Retry-After": str(REDIS_RETRY_AFTER_S)})

    for unavailable in REDIS_GONE:
        app.add_exception_handler(unavailable, redis_unavailable)

    @app.exception_handler(Exception)
    async def unexpected(request: Request, exc: Exception):
        return problem(500, "Internal error", f"{type(exc).__name__}", instance=str(request.url.path))


_TITLES = {400: "Bad request", 401: "Unauthorized", 403: "Forbidden", 404: "Not found", 405: "Method not allowed",
           409: "Conflict", 413: "Payload too large", 415: "Unsupported media type", 422: "Invalid request",
           429: "Too many requests", 503: "Service unavailable"}
