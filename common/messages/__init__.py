"""Every payload dume sends, one module per domain, and the codec.

`encode(msg)` and `decode(data, Type)` pick msgpack or JSON from the type's `WIRE`
(JSON for the user-facing mission keys). A payload that does not decode raises
`PayloadError`, which says which key, which type, and what was wrong, with the path
of the bad field (`Expected float, got str - at $.x`).

Decoders are built once per type, one at a time (`decoder`): msgspec 0.22 publishes a
Struct's type information on the class before it has finished building it (it evaluates
the annotations in Python, and another thread runs meanwhile), so a second thread that
builds or uses a decoder of that type then reads it half-made and crashes the process
(SIGSEGV). Two Zenoh callback threads receiving their first `Detections` at once did
exactly that: the mission and navigation died on their first inputs
(`dume bench decoders` reproduces it).
"""

from __future__ import annotations

import threading
from collections.abc import Hashable
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
    "decoder",
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


Decoder = msgspec.msgpack.Decoder[Any] | msgspec.json.Decoder[Any]
_DECODERS: dict[tuple[Hashable, str], Decoder] = {}
_BUILDING = threading.Lock()


def decoder(type_: Any, wire: str | None = None) -> Decoder:
    """The one decoder of `type_` for `wire` (its `WIRE` by default), built under a
    process-wide lock: never two at once (see the module docstring)."""
    key = (cast(Hashable, type_), wire or wire_of(type_))
    found = _DECODERS.get(key)
    if found is None:
        with _BUILDING:
            found = _DECODERS.get(key)
            if found is None:
                found = (
                    msgspec.json.Decoder(type_)
                    if key[1] == "json"
                    else msgspec.msgpack.Decoder(type_)
                )
                _DECODERS[key] = found
    return found


def decode(data: bytes | bytearray | memoryview, type_: type[T], *, key: str = "") -> T:
    """Deserialize and validate `data` as `type_`; raise `PayloadError` with the reason."""
    try:
        return cast(T, decoder(type_).decode(data))
    except (msgspec.DecodeError, ValueError, RecursionError) as exc:
        # ValueError: msgpack strings that are not UTF-8 raise UnicodeDecodeError, not
        # DecodeError (found by `dume trial fuzz`); RecursionError: nesting past the limit.
        why = str(exc) if isinstance(exc, msgspec.DecodeError) else f"{type(exc).__name__}: {exc}"
        raise PayloadError(getattr(type_, "__name__", str(type_)), why, key) from None
