"""Every payload dume sends, one module per domain, and the codec.

`encode(msg)` and `decode(data, Type)` pick msgpack or JSON from the type's `WIRE`
(JSON for the user-facing mission keys). A payload that does not decode raises
`PayloadError`, which says which key, which type, and what was wrong, with the path
of the bad field (`Expected float, got str - at $.x`).
"""

from __future__ import annotations

from collections.abc import Hashable
from functools import cache
from typing import Any, TypeVar, cast

import msgspec

from common.messages.arrays import Array, ArrayError, as_numpy, to_wire
from common.messages.base import Message, Pose, Pose2D, seconds, to_ns
from common.messages.errors import ErrorReply

__all__ = [
    "Array",
    "ArrayError",
    "ErrorReply",
    "Message",
    "PayloadError",
    "Pose",
    "Pose2D",
    "as_numpy",
    "decode",
    "encode",
    "seconds",
    "to_ns",
    "to_wire",
]

T = TypeVar("T")

_MSGPACK = msgspec.msgpack.Encoder()
_JSON = msgspec.json.Encoder()


class PayloadError(ValueError):
    """A payload that is not a valid `type_name`: what arrived, on which key, and why."""

    def __init__(self, type_name: str, detail: str, key: str = "") -> None:
        self.type_name = type_name
        self.detail = detail
        self.key = key
        where = f" on {key}" if key else ""
        super().__init__(f"invalid {type_name}{where}: {detail}")


def wire_of(type_: type[Any]) -> str:
    return str(getattr(type_, "WIRE", "msgpack"))


def encode(msg: Any) -> bytes:
    """Serialize a message for the wire (msgpack, or JSON for `WIRE = "json"` types)."""
    return _JSON.encode(msg) if wire_of(type(msg)) == "json" else _MSGPACK.encode(msg)


@cache
def _decoder(type_: Any, wire: str) -> msgspec.msgpack.Decoder[Any] | msgspec.json.Decoder[Any]:
    if wire == "json":
        return msgspec.json.Decoder(type_)
    return msgspec.msgpack.Decoder(type_)


def decode(data: bytes | bytearray | memoryview, type_: type[T], *, key: str = "") -> T:
    """Deserialize and validate `data` as `type_`; raise `PayloadError` with the reason."""
    try:
        decoder: Any = _decoder(cast(Hashable, type_), wire_of(type_))
        return cast(T, decoder.decode(data))
    except msgspec.DecodeError as exc:
        raise PayloadError(getattr(type_, "__name__", str(type_)), str(exc), key) from None
