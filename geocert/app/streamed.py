"""Large job bodies taken item by item, so that the API's memory stays near the body's size.

A job of 200,000 tracks is a 26 MiB body; parsed whole (a dict, then a pydantic model, then its
dump, then the parsed arrays), it raised the API's peak memory by 44 times that (measured with
bench.large_job; taken item by item, 2.2 times). For a kind whose
items sit in one list of its data (its ``chunk_key``), a body over ``stream_threshold_bytes`` (a
setting) is instead:

1. read into one buffer of its announced length (``read_body``), then scanned once
   (``split_items``): the top-level object and its ``data`` member are walked, the item list's
   elements located (their offsets only) without keeping them. An ASCII body (any JSON whose
   strings are ASCII or escaped) is scanned as bytes, decoded a window at a time, so the API holds
   the body once, not its bytes and their text;
2. handed to the route as its *head*, the body with that list cut to its first item, so that the
   kind's request model checks everything but the items as for any body (the same errors, the
   same defaults);
3. the items then validated by the same model's item type, checked by the kind's own parser and
   written to Redis a batch at a time (``upload_items``), under a temporary key that becomes the
   job's item list when the job is created (``JobStore.create(items_key=...)``).

Anything unexpected in the scan (not JSON, a repeated key, no item list) leaves the body to the
ordinary path, which then answers as it always does. Errors name the item as the ordinary path
does (``data/tracks/123/points``).
"""

from __future__ import annotations

import functools
import hashlib
import json
import re
from array import array
from dataclasses import dataclass, field
from typing import Any

import msgspec
from fastapi.exceptions import RequestValidationError
from pydantic import TypeAdapter, ValidationError

from geocert.kinds import KINDS

BATCH = 2000  # items validated, parsed and written at a time
UPLOAD_TTL_S = 3600  # a temporary item list outlives an API process that died mid-upload by this

_WHITESPACE = re.compile(r"[ \t\n\r]*")
_WHITESPACE_BYTES = re.compile(rb"[ \t\n\r]*")
_DECODER = json.JSONDecoder()  # what json.loads uses, so values decode as on the ordinary path


class _Text:
    """A body as text, to the scan."""

    def __init__(self, text: str):
        self.text = text

    def __len__(self) -> int:
        return len(self.text)

    def char(self, i: int) -> str:
        return self.text[i:i + 1]  # "" past the end

    def skip(self, i: int) -> int:
        return _WHITESPACE.match(self.text, i).end()

    def decode(self, i: int) -> tuple[Any, int]:
        return _DECODER.raw_decode(self.text, i)

    def slice(self, start: int, end: int) -> str:
        return self.text[start:end]


class _AsciiBytes(_Text):
    """An ASCII body as bytes, decoded a window at a time (in ASCII, byte and character offsets
    agree): the scan never holds the body's text beside its bytes."""

    WINDOW = 1 << 16

    def __init__(self, data: bytes | bytearray):
        self.data, self.start, self.window = data, 0, ""

    def __len__(self) -> int:
        return len(self.data)

    def char(self, i: int) -> str:
        return chr(self.data[i]) if i < len(self.data) else ""

    def skip(self, i: int) -> int:
        return _WHITESPACE_BYTES.match(self.data, i).end()

    def decode(self, i: int) -> tuple[Any, int]:
        size = self.WINDOW
        while True:
            offset = i - self.start
            if 0 <= offset < len(self.window):
                whole = self.start + len(self.window) >= len(self.data)  # the window runs to the body's end
                try:
                    value, end = _DECODER.raw_decode(self.window, offset)
                except ValueError:
                    if whole:
                        raise
                else:
                    # A value ending at the window's edge may go on past it (a number cut short).
                    if end < len(self.window) or whole:
                        return value, self.start + end
                # The value may run past the window: a new one from i, longer than what was left.
                size = max(self.WINDOW, 2 * (len(self.window) - offset))
            self.start, self.window = i, self.data[i:i + size].decode("ascii")

    def slice(self, start: int, end: int) -> str:
        return self.data[start:end].decode("ascii")


def _source(body: str | bytes | bytearray) -> _Text | None:
    if isinstance(body, str):
        return _Text(body)
    if body.isascii():
        return _AsciiBytes(body)
    try:  # UTF-8 beyond ASCII: byte and character offsets differ, so scanned as text
        return _Text(body.decode())
    except UnicodeDecodeError:
        return None


async def read_body(request, length: int) -> bytearray:
    """The request's body in one buffer of its announced ``length``, filled as it arrives
    (Starlette's ``body()`` joins a list of its chunks: twice the body at that moment)."""
    buffer = bytearray(length)
    filled = 0
    async for chunk in request.stream():
        end = filled + len(chunk)
        if end <= length:
            buffer[filled:end] = chunk
        else:  # more than announced (the server refuses that first; kept anyway)
            del buffer[filled:]
            buffer += chunk
        filled = end
    del buffer[filled:]
    return buffer


@dataclass
class Split:
    """A body split into its head and its items' places."""

    source: _Text
    kind: str
    chunk_key: str
    head: str  # the body with the item list cut to its first item
    spans: array  # start, end of each item in ``text``, flattened
    count: int = field(init=False)

    def __post_init__(self):
        self.count = len(self.spans) // 2

    def item_text(self, index: int) -> str:
        return self.source.slice(self.spans[2 * index], self.spans[2 * index + 1])


class _Unexpected(Exception):
    """The scan met something it does not handle: the ordinary path takes the body."""


def _skip(text: _Text, i: int) -> int:
    return text.skip(i)


def _expect(text: _Text, i: int, char: str) -> int:
    if text.char(i) != char:
        raise _Unexpected
    return i + 1


def _value_end(text: _Text, i: int) -> int:
    try:
        return text.decode(i)[1]
    except (ValueError, RecursionError) as exc:
        raise _Unexpected from exc


def _object(text: _Text, i: int, member) -> int:
    """Walks the object at ``i`` (``{``), calling ``member(key, start)`` for each member, which
    returns where the value ends; returns where the object ends. Repeated keys are refused (the
    ordinary parser keeps the last, which a single pass would have to undo)."""
    i = _skip(text, _expect(text, i, "{"))
    seen = set()
    if text.char(i) == "}":
        return i + 1
    while True:
        if text.char(i) != '"':
            raise _Unexpected
        key, i = text.decode(i)
        if key in seen:
            raise _Unexpected
        seen.add(key)
        i = _skip(text, _expect(text, _skip(text, i), ":"))
        i = _skip(text, member(key, i))
        if text.char(i) == ",":
            i = _skip(text, i + 1)
            continue
        return _expect(text, i, "}")


def _array_spans(text: _Text, i: int) -> tuple[array, int]:
    """The spans of the elements of the array at ``i`` (``[``), and where it ends."""
    spans = array("i" if len(text) < 2**31 else "q")  # 4-byte offsets where they fit: 8 bytes an item
    i = _skip(text, _expect(text, i, "["))
    if text.char(i) == "]":
        return spans, i + 1
    while True:
        end = _value_end(text, i)
        spans.append(i)
        spans.append(end)
        i = _skip(text, end)
        if text.char(i) == ",":
            i = _skip(text, i + 1)
            continue
        return spans, _expect(text, i, "]")


def split_items(body: str | bytes | bytearray) -> Split | None:
    """The body's head and its items' places, or None when the body is not a job of a kind with
    an item list (or is anything the scan does not handle, or not UTF-8)."""
    if not _may_have_items(body):
        return None
    text = _source(body)
    if text is None:
        return None
    top: dict[str, tuple[int, int]] = {}
    lists: dict[str, tuple[int, int, array]] = {}  # data's arrays: opening, end, element spans

    def data_member(key: str, start: int) -> int:
        if text.char(start) == "[":
            spans, end = _array_spans(text, start)
            lists[key] = (start, end, spans)
            return end
        return _value_end(text, start)

    def top_member(key: str, start: int) -> int:
        end = _object(text, start, data_member) if key == "data" and text.char(start) == "{" \
            else _value_end(text, start)
        top[key] = (start, end)
        return end

    try:
        end = _object(text, _skip(text, 0), top_member)
        if _skip(text, end) != len(text) or "kind" not in top:
            return None
        name = json.loads(text.slice(*top["kind"]))
    except (_Unexpected, ValueError, RecursionError):
        return None
    kind = KINDS.get(name) if isinstance(name, str) and name in KINDS else None
    chunk_key = getattr(kind, "chunk_key", None)
    if chunk_key is None or chunk_key not in lists or len(lists[chunk_key][2]) < 4:  # two items at least
        return None
    start, end, spans = lists[chunk_key]
    head = text.slice(0, start) + "[" + text.slice(spans[0], spans[1]) + "]" + text.slice(end, len(text))
    return Split(text, name, chunk_key, head, spans)


class _Kind(msgspec.Struct):
    kind: msgspec.Raw = msgspec.Raw(b"null")


_KIND = msgspec.json.Decoder(_Kind)


def _may_have_items(body: str | bytes | bytearray) -> bool:
    """False when the body names a kind without an item list (a reconstruction, an
    autocalibration): read by msgspec, skipping every other value, in about a tenth of the
    scan's time (0.03 s against 0.29 s for a reconstruction's 11.9 MB), which the event loop
    would spend on it for nothing. True when the body cannot be read so (the scan decides)."""
    try:
        name = json.loads(bytes(_KIND.decode(body).kind))
    except (msgspec.DecodeError, msgspec.ValidationError, ValueError):
        return True
    kind = KINDS.get(name) if isinstance(name, str) and name in KINDS else None
    return kind is None or getattr(kind, "chunk_key", None) is not None


@functools.cache
def _items_adapter(kind_name: str) -> TypeAdapter:
    """The kind's request model's type for its item list (e.g. list[TrackIn])."""
    kind = KINDS.get(kind_name)
    data_model = kind.request_model.model_fields["data"].annotation
    return TypeAdapter(data_model.model_fields[kind.chunk_key].annotation)


@dataclass
class Upload:
    key: str  # the Redis list holding the items' JSON texts, in order
    count: int
    observations: int
    digest: str | None  # of the whole request (head with its items), when asked for (Idempotency-Key)
    bytes: int = 0  # of the items' JSON texts


def upload_items(store, split: Split, request: dict, with_digest: bool = False) -> Upload:
    """Every item validated by the kind's model, checked by its parser (with the rest of the
    request, whose ``data`` holds the checked head) and written as JSON to a temporary list of
    ``store`` (a JobStore: its uploads), a batch at a time; with ``with_digest``, the request's
    digest too (as for every body, only for an Idempotency-Key: hashing is not done on every
    submit). Raises RequestValidationError or InputError naming the item, after removing what was
    written."""
    kind = KINDS.get(split.kind)
    adapter = _items_adapter(split.kind)
    key = store.upload_key()
    placeholder = {**request, "data": {**request["data"], split.chunk_key: None}}
    digest = hashlib.sha256(json.dumps(placeholder, sort_keys=True).encode()) if with_digest else None
    slots: list[Any] = [None] * split.count
    data = {**request["data"], split.chunk_key: slots}
    observations = written = 0
    try:
        for begin in range(0, split.count, BATCH):
            stop = min(begin + BATCH, split.count)
            raw = [_DECODER.decode(split.item_text(i)) for i in range(begin, stop)]
            try:
                items = adapter.dump_python(adapter.validate_python(raw), mode="json")
            except ValidationError as exc:
                raise RequestValidationError([
                    {**error, "loc": ("body", "data", split.chunk_key, begin + error["loc"][0], *error["loc"][1:])}
                    for error in exc.errors(include_url=False)]) from None
            slots[begin:stop] = items
            parsed = kind.parse(data, range(begin, stop))  # raises InputError naming the item
            observations += kind.observations(parsed)
            slots[begin:stop] = [None] * (stop - begin)
            texts = [json.dumps(item) for item in items]
            written += sum(map(len, texts))
            for item in items if digest is not None else ():
                digest.update(json.dumps(item, sort_keys=True).encode())
            store.append_upload(key, texts, UPLOAD_TTL_S)
    except BaseException:
        store.drop_upload(key)
        raise
    return Upload(key, split.count, observations, None if digest is None else digest.hexdigest(), written)
