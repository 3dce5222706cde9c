"""What waits for the mission's loop: requests and cancels as raw payloads.

Requests and cancels arrive as raw JSON and are kept raw (so a malformed one can still be
answered with its `request_id` when the loop parses it, `services.mission.requests`).

- `Inbox`: the payloads of one key in arrival order (at most `maxlen`: the oldest go
  first). Zenoh's threads only `push`; the loop `drain`s once a tick. One lock guards
  the queue; nothing else is shared.
- `RequestInbox.submit`: the `mission/submit` queryable's handler (called on the query
  server's thread): the request is in the inbox before the receipt is returned, so the
  reply tells a client that the mission holds it.

No Zenoh here: the node subscribes and hands each sample's bytes to `push`.
"""

from __future__ import annotations

import threading
from collections import deque

from common.messages import encode
from common.messages.mission import MissionReceipt, MissionRequest


class Inbox:
    """Payloads of one key, kept raw for the loop (Zenoh's thread only appends)."""

    def __init__(self, maxlen: int = 256) -> None:
        self._q: deque[bytes] = deque(maxlen=maxlen)
        self._lock = threading.Lock()

    def push(self, payload: bytes) -> None:
        with self._lock:
            self._q.append(payload)

    def drain(self) -> list[bytes]:
        """Every payload pushed since the last drain, oldest first (the loop's thread)."""
        with self._lock:
            out = list(self._q)
            self._q.clear()
        return out


class RequestInbox(Inbox):
    """The requests' inbox, which also takes requests sent as queries."""

    def submit(self, request: MissionRequest | None, _selector: str) -> MissionReceipt:
        """A request by query (the server's thread): in the inbox before the reply goes."""
        assert request is not None  # served with a request type: Server decoded it
        self.push(encode(request))
        return MissionReceipt(request_id=request.request_id)
