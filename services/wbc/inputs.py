"""The controller's slow inputs on sim time: cmd_vel arbitration, modes, base pose history.

- `CmdVelArbiter`: every `cmd_vel` sample is pushed in; only the source that `wbc/mode`
  names is obeyed (the others are kept, counted as ignored, for when one is named). A
  sample from a source takes effect at its stamp plus that source's configured latency
  (0 for a source that is not a lockstep participant, e.g. a user script), so the same
  run gives the same commands; a command older than `timeout_ns` means stop.
- `ModeQueue`: `wbc/mode` samples take effect the same way (stamp + the mode source's
  latency), in order.
- `PoseHistory`: the base pose at past ticks, so a goal in the base frame as of its
  stamp is fixed in the world from the pose the base had then.
- `ArbiterFeed`: one source's cmd_vel subscription as the arbiter holds it, what the
  lockstep `UpstreamGate` waits on (wall time).

Bookkeeping on the WBC's thread: the node drains its subscriptions into these each tick.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping

import numpy as np

from common.bus import Fifo, WaitTimeout
from common.geometry import FloatArray
from common.messages.wbc import CmdVel, WbcMode

ZERO3: FloatArray = np.zeros(3)


class CmdVelArbiter:
    """The obeyed source's newest effective command; stop when it is stale or missing.

    Every source's recent samples are kept, whichever is obeyed: a switch of source takes
    effect at a tick fixed by sim time, and the samples the new source sent before it
    must be there whether or not they happened to arrive before the switch.
    """

    def __init__(self, latency_ns: Mapping[str, int], timeout_ns: int, history: int = 64) -> None:
        self.latency_ns = dict(latency_ns)
        self.timeout_ns = timeout_ns
        self.history = history
        self.source = ""
        self.ignored: dict[str, int] = {}
        self._bufs: dict[str, deque[CmdVel]] = {}
        self.stale = False

    def select(self, source: str) -> None:
        """Obey `source` from now on (its samples already in are kept: they may be due)."""
        self.source = source

    def push(self, msg: CmdVel) -> None:
        if msg.source != self.source:
            self.ignored[msg.source] = self.ignored.get(msg.source, 0) + 1
        buf = self._bufs.get(msg.source)
        if buf is None:
            buf = self._bufs[msg.source] = deque(maxlen=self.history)
        buf.append(msg)

    def newest(self, source: str) -> CmdVel | None:
        """The newest sample `source` sent (obeyed or not)."""
        buf = self._bufs.get(source)
        return buf[-1] if buf else None

    def command(self, t_ns: int) -> FloatArray:
        """(vx, vy, ωz) in effect at t; zeros when none is due or the newest is stale."""
        latency = self.latency_ns.get(self.source, 0)
        due = None
        for msg in reversed(self._bufs.get(self.source, ())):
            if msg.stamp_ns + latency <= t_ns:
                due = msg
                break
        if due is None:
            self.stale = False
            return ZERO3
        self.stale = t_ns - due.stamp_ns > self.timeout_ns
        if self.stale:
            return ZERO3
        return np.array([due.vx, due.vy, due.wz])


class ModeQueue:
    """`wbc/mode` samples applied in order at stamp + latency."""

    def __init__(self, latency_ns: int) -> None:
        self.latency_ns = latency_ns
        self._pending: deque[WbcMode] = deque()

    def push(self, msg: WbcMode) -> None:
        self._pending.append(msg)

    def due(self, t_ns: int) -> list[WbcMode]:
        """Every sample that takes effect at or before t, oldest first."""
        out = []
        while self._pending and self._pending[0].stamp_ns + self.latency_ns <= t_ns:
            out.append(self._pending.popleft())
        return out


class PoseHistory:
    """T_world_base (4×4) at recent stamps, every `every_ns`, for `span_ns`."""

    def __init__(self, span_ns: int = 2_000_000_000, every_ns: int = 1_000_000) -> None:
        self.every_ns = every_ns
        self._buf: deque[tuple[int, FloatArray]] = deque(maxlen=max(2, span_ns // every_ns))

    def add(self, stamp_ns: int, T_world_base: FloatArray) -> None:
        if self._buf and stamp_ns - self._buf[-1][0] < self.every_ns:
            return
        self._buf.append((stamp_ns, np.array(T_world_base, dtype=float)))

    def at(self, stamp_ns: int) -> FloatArray | None:
        """The newest pose at or before the stamp (the newest one for a future stamp);
        None when the stamp is older than the history."""
        for t, T in reversed(self._buf):
            if t <= stamp_ns:
                return T
        return None


class ArbiterFeed:
    """One source's cmd_vel as the arbiter holds it: what `UpstreamGate` waits on. Reading
    it moves what arrived into the arbiter, and the modes they carry into `modes` (the
    WBC's thread only), so the gate is met by the very samples the arbiter will use,
    never by a copy that arrived first."""

    def __init__(
        self,
        fifo: Fifo[CmdVel],
        arbiter: CmdVelArbiter,
        source: str,
        modes: ModeQueue | None = None,
    ) -> None:
        self.fifo, self.arbiter, self.source, self.modes = fifo, arbiter, source, modes

    def _take(self, cmd: CmdVel) -> None:
        if cmd == self.arbiter.newest(cmd.source):
            return  # the same sample sent again (a cut link came back): its mode once
        self.arbiter.push(cmd)
        if cmd.mode is not None and self.modes is not None:
            self.modes.push(cmd.mode)

    def get(self) -> CmdVel | None:
        for cmd in self.fifo.drain():
            self._take(cmd)
        return self.arbiter.newest(self.source)

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> CmdVel:
        deadline = time.monotonic() + timeout_s
        while True:
            newest = self.get()
            if newest is not None and newest.stamp_ns >= stamp_ns:
                return newest
            left = deadline - time.monotonic()
            cmd = self.fifo.pop(timeout_s=left) if left > 0 else None
            if cmd is None:
                raise WaitTimeout(f"no cmd_vel from {self.source} stamped {stamp_ns}")
            self._take(cmd)
