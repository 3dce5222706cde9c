"""Typed errors that travel: the reply of a query that could not be served."""

from __future__ import annotations

from typing import Literal

from common.messages.base import Message

ErrorCode = Literal[
    "malformed",  # the payload did not decode into the expected type
    "invalid",  # it decoded, but a value is out of its domain
    "unknown_id",  # it names an id that does not exist
    "busy",  # the service is doing something that excludes this request
    "unavailable",  # the service cannot serve it now (not ready, a dependency is down)
    "timeout",  # something it waited on did not come in time
    "internal",  # a bug: the service logged the traceback and kept running
]


class ErrorReply(Message, frozen=True):
    """Why a request was refused.

    code: machine-readable reason (see `ErrorCode`).
    message: a sentence for a person, saying what was received and what was valid.
    key: the key expression the request came in on.
    """

    code: ErrorCode
    message: str
    key: str = ""
