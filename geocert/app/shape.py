"""A request's budget figures from its body's shape, before the body is parsed.

Parsed whole (a dict, then the route's pydantic model), a body of numbers costs the API's one
process some 0.1 s of CPU and 25 bytes of memory a byte (a 6.5 MB /v1/orient body: 0.65 s), and
a job over its budget (settings.BUDGETS) was refused only after that. Here a large body is read
as a ``Lazy`` document instead: msgspec (a C parser) checks the JSON and cuts each object into
its members and each array into its elements as raw byte slices, decoding a value only when it
is looked at. The kinds' own ``request_figures`` (and /v1/orient's figures) then run on it as on
the parsed data, looking only at what they count (lengths, a photo's header), so a body over a
limit is refused for a few milliseconds a megabyte, having built none of its numbers.

Anything unexpected (not JSON, a member of the wrong type, a figure that raises) leaves the body
to the ordinary path, which then answers as it always does: this check only refuses early what
that path would refuse once parsed.
"""

from __future__ import annotations

from typing import Any

import msgspec

from geocert.settings import over_budget

# Bodies up to this many bytes are parsed at once (a few milliseconds): the check reads larger ones.
CHECK_ABOVE_BYTES = 1 << 16
_MEMBERS = msgspec.json.Decoder(dict[str, msgspec.Raw])
_ELEMENTS = msgspec.json.Decoder(list[msgspec.Raw])
_VALUE = msgspec.json.Decoder()


def _lazy(raw: msgspec.Raw) -> Any:
    """A value: an object or array as a Lazy one, anything else decoded (a number, a string)."""
    first = bytes(memoryview(raw)[:1])
    if first == b"{":
        return LazyObject(_MEMBERS.decode(raw))
    if first == b"[":
        return LazyArray(_ELEMENTS.decode(raw))
    return _VALUE.decode(raw)


class LazyObject(dict):
    """A JSON object whose members are decoded when read (a dict, for isinstance checks)."""

    def __getitem__(self, key):
        return _lazy(dict.__getitem__(self, key))

    def get(self, key, default=None):
        return self[key] if key in self else default

    def values(self):
        return [self[key] for key in self]

    def items(self):
        return [(key, self[key]) for key in self]


class LazyArray(list):
    """A JSON array whose elements are decoded when read (a list, for isinstance checks): its
    length costs nothing beyond the slices."""

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [_lazy(raw) for raw in list.__getitem__(self, index)]
        return _lazy(list.__getitem__(self, index))

    def __iter__(self):
        return (_lazy(raw) for raw in list.__iter__(self))


def read(body: bytes | bytearray) -> LazyObject | None:
    """The body as a Lazy document, or None when it is not a JSON object."""
    try:
        return LazyObject(_MEMBERS.decode(body))
    except msgspec.DecodeError:
        return None


def over_budget_by_shape(body: bytes | bytearray, figures) -> tuple[str, str] | None:
    """The first of ``figures(document)`` (settings.BUDGETS's figures: {figure: (value, field)})
    over its limit, read from the body's shape: the reason and the field, as the route refuses
    it once parsed (settings.over_budget). None when within every limit, or when the body is
    not what ``figures`` reads (the ordinary path decides)."""
    document = read(body)
    if document is None:
        return None
    try:
        return over_budget(figures(document))
    except Exception:  # noqa: BLE001 - any surprise: the ordinary path answers
        return None


def job_figures(document: LazyObject) -> dict:
    """A job's figures: its kind's request_figures of its data."""
    from geocert.kinds import KINDS

    kind, data = document.get("kind"), document.get("data")
    if not isinstance(kind, str) or kind not in KINDS or not isinstance(data, LazyObject):
        return {}
    return KINDS.get(kind).request_figures(data)


def orient_figures(document: LazyObject) -> dict:
    """/v1/orient's: cameras times points (its dense arrays, whichever views are given)."""
    return {"view_points": (len(document.get("cameras") or ()) * len(document.get("points") or ()), "points")}


async def check_body(request, figures, above: int = CHECK_ABOVE_BYTES) -> bytearray | None:
    """A JSON body of more than ``above`` bytes with a content-length, or any sent in chunks
    without one, is read here (the caller hands its bytes on as the request's body) and refused
    with a 413 naming the figure when its shape is over budget. Returns the body read, or None when
    it was left to be read as usual."""
    from geocert.app import streamed
    from geocert.app.errors import ApiProblem, is_json_media_type

    if not is_json_media_type(request.headers.get("content-type")):
        return None
    length = request.headers.get("content-length")
    if length is not None and not (length.isdigit() and int(length) > above):
        return None
    # Without a length (chunked), its size is known once read: read here, so that a large one
    # takes the large bodies' ways too (the server's body limit bounds it as it arrives).
    body = await streamed.read_body(request, int(length) if length is not None else 0)
    exceeded = over_budget_by_shape(body, figures)
    if exceeded is not None:
        raise ApiProblem(413, *exceeded)
    return body
