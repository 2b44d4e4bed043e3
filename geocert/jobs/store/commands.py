"""The writes of a job's creation recorded instead of sent (``_Commands``), for the one Lua script
that admits and writes a job (``creation.Creation._stage_create``)."""

from __future__ import annotations

import json

_COMMANDS_ENCODER = json.JSONEncoder(separators=(",", ":")).encode


def _text(value) -> str:
    """A command's argument as redis-py would send it, as text (bytes must be UTF-8)."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    raise TypeError(f"not a Redis argument: {type(value).__name__}")


class _Commands:
    """Stands where a pipeline stands for the writes of a job's creation (JobStore._stage_create):
    records each command as _CREATE takes it (its name, its argument count, its arguments, every
    one a string) instead of sending it. Only the commands that creation makes."""

    def __init__(self):
        self.arguments: list = []
        self.bulk: list[tuple] = []  # the large writes, sent as commands of their own (``BULK``)

    # _CREATE passes a command's arguments to redis.call by one Lua unpack, which takes at most
    # LUAI_MAXCSTACK (8000) values: a push of more is split.
    PUSHED_AT_ONCE = 1000
    # A SET or RPUSH of more bytes than this (a large request's text or items) is not run by the
    # script but sent as a command of its own, in a transaction with it (JobStore.create): a
    # script copies each value into Lua and back and decodes it from JSON, where Redis keeps a
    # command's argument as it read it (a 12 MB request: tens of ms of the server in the script,
    # against microseconds).
    BULK = 16 << 10

    def command(self, name: str, *args) -> None:
        self.arguments += (name, len(args), *(arg if isinstance(arg, str) else _text(arg) for arg in args))

    def text(self) -> str:
        """The commands as one JSON array (decoded by the script's cjson to the same strings): one
        argument for redis-py to pack instead of one a value, which cost it more than the rest of
        the submission's Redis work (some 80 values a 3-track job)."""
        return _COMMANDS_ENCODER(self.arguments)

    def set(self, key: str, value: str) -> None:
        if len(value) > self.BULK:
            self.bulk.append(("SET", key, value))
        else:
            self.command("SET", key, value)

    def hset(self, key: str, field: str | None = None, value: str | None = None, mapping: dict | None = None) -> None:
        pairs = [] if field is None else [field, value]
        self.command("HSET", key, *pairs, *(part for pair in (mapping or {}).items() for part in pair))

    def rpush(self, key: str, *values: str) -> None:
        if sum(map(len, values)) > self.BULK:
            self.bulk.append(("RPUSH", key, *values))
            return
        for begin in range(0, len(values), self.PUSHED_AT_ONCE):
            self.command("RPUSH", key, *values[begin:begin + self.PUSHED_AT_ONCE])

    def rename(self, source: str, target: str) -> None:
        self.command("RENAME", source, target)

    def persist(self, key: str) -> None:
        self.command("PERSIST", key)

    def zadd(self, key: str, mapping: dict) -> None:
        self.command("ZADD", key, *(part for member, score in mapping.items() for part in (float(score), member)))

    def xadd(self, key: str, fields: dict, maxlen: int, approximate: bool = True) -> None:
        self.command("XADD", key, "MAXLEN", *(("~",) if approximate else ()), maxlen, "*",
                     *(part for pair in fields.items() for part in pair))
