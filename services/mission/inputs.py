"""The mission's inputs as of its tick b, waited for before the tree ticks.

`TickInputs.wait(b, first)` runs on the loop's thread, once a tick, in this order (every
wait bounded by `mission.input_timeout_s`, a miss logged as a warning, never raised):

1. on the first tick in lockstep: hear that the dependencies are alive (`hear`);
2. the odom stamped b (50 Hz);
3. for b > 0 while the controller is alive: the `wbc/status` stamped at its newest
   period boundary before b (`status_period_ns`, the controller's status period);
4. the outputs of navigation and perception that take effect by b (`UpstreamGate`);
5. `robot.begin(b)`: the robot reads its inputs as of b from here on;
6. the wrist camera's detections due at b (the gate may have been met by the head
   camera's: both share one key), when perception runs in lockstep, the wrist camera is
   both rendered and processed (`wrist_published`), and b − perception's latency is one
   of perception's ticks.

Every wait is taken in slices of `SLICE_S` and given up when `lost()` says a dependency
of the running job is gone (a killed WBC publishes no odom for b, and the tick waited
the whole timeout, 30 s, before the request could fail), or the service stops: `wait`
then returns False (after `robot.begin(b)`) and the loop fails the job
`dependency_lost` before its step. Odom and the WBC's status are not waited for while
their publisher is not alive (after a request failed so, the mission waited 30 s a tick
for the dead WBC's odom, deaf to a stop).

Times are sim time in integer ns; timeouts are wall-clock seconds. No Zenoh: the robot,
the gate and who is alive come in as small protocols (`BusRobot`, `UpstreamGate` and
`AliveWatch.alive` in the node).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Collection
from typing import Protocol

from common.bus import WaitTimeout
from common.lockstep import AckGate
from common.messages.base import NS_PER_S

#: The slice a wait is taken in between two looks at `lost()`, wall s.
SLICE_S = 0.02


class Lost(Exception):
    """A dependency went away during a wait: give the tick up."""


class Waitable(Protocol):
    """An input kept by stamp (a `Latest`)."""

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> object: ...


class InputRobot(Protocol):
    """What of the robot the inputs wait on (`BusRobot`)."""

    @property
    def odom(self) -> Waitable: ...

    @property
    def wbc(self) -> Waitable: ...

    def begin(self, b: int) -> None: ...

    def wait_wrist(self, timeout_s: float) -> bool: ...


class Gate(Protocol):
    """The lockstep gate on the periodic producers' outputs (`UpstreamGate`)."""

    lockstep: bool
    gate: AckGate

    def latency_ns(self, producer: str) -> int: ...

    def wait(self, t_ns: int, timeout_s: float) -> list[str]: ...


class TickInputs:
    """The per-tick wait for the mission's inputs (see the module docstring)."""

    def __init__(
        self,
        robot: InputRobot,
        gate: Gate,
        alive: Callable[[], Collection[str]],
        hear: Callable[[], object],
        wbc_alive_key: str,
        status_period_ns: int,
        wrist_published: bool,
        timeout_s: float,
        log: logging.Logger,
        lost: Callable[[], bool] = lambda: False,
        stopping: Callable[[], bool] = lambda: False,
        odom_alive_key: str = "",
    ) -> None:
        self.robot, self.gate = robot, gate
        self.lost, self.stopping = lost, stopping
        #: Who publishes odom (the WBC's estimate, or the sim's free joint), "" unknown.
        self.odom_alive_key = odom_alive_key
        self._alive, self._hear = alive, hear
        self.wbc_alive_key = wbc_alive_key
        self.status_period_ns = status_period_ns
        self.wrist_published = wrist_published
        self.timeout_s = timeout_s
        self.log = log

    def wait(self, b: int, first: bool) -> bool:
        """Wait for the inputs of tick b; `first`: the mission's first tick (since start).
        False when a dependency went away meanwhile (the tick is given up)."""
        try:
            self._wait(b, first)
        except Lost:
            self.log.warning("t=%.2f s: a dependency went away: inputs not awaited", b / NS_PER_S)
            self.robot.begin(b)
            return False
        return True

    def _sliced(
        self, attempt: Callable[[float], bool], timeout_s: float, producer: str = ""
    ) -> bool:
        """`attempt(slice)` until it succeeds or `timeout_s` has passed, or at once when
        `producer` (an alive key) is not alive: nothing will come; `Lost` when a dependency
        of the running job goes away or the service stops meanwhile."""
        deadline = time.monotonic() + timeout_s
        while True:
            start = time.monotonic()
            left = deadline - start
            piece = max(0.0, min(SLICE_S, left))
            if attempt(piece):
                return True
            if self.lost() or self.stopping():
                raise Lost
            if left <= SLICE_S or (producer and producer not in self._alive()):
                return False
            time.sleep(max(0.0, piece - (time.monotonic() - start)))  # one that gave up early

    def _wait(self, b: int, first: bool) -> None:
        timeout = self.timeout_s
        if first and self.gate.lockstep:  # its first tick: know who runs
            self._hear()
        odom, wbc = self.odom_alive_key, self.wbc_alive_key
        if not self._sliced(lambda s: _stamped(self.robot.odom, b, s), timeout, odom):
            self.log.warning("no odom for t=%.2f s", b / NS_PER_S)
        if b > 0 and self.wbc_alive_key in self._alive():
            need = ((b - 1) // self.status_period_ns) * self.status_period_ns
            if not self._sliced(lambda s: _stamped(self.robot.wbc, need, s), timeout, wbc):
                self.log.warning("no wbc/status for t=%.2f s", need / NS_PER_S)
        missing: list[str] = []

        def gate_met(slice_s: float) -> bool:
            missing[:] = self.gate.wait(b, slice_s)
            return not missing

        if not self._sliced(gate_met, timeout):
            self.log.warning("t=%.2f s: no output of %s in time", b / NS_PER_S, missing)
        self.robot.begin(b)
        self._wait_wrist(b, timeout)

    def _wait_wrist(self, b: int, timeout: float) -> None:
        """The wrist camera's detections due at b (the gate may have been met by the head
        camera's: both share one key), when perception runs and publishes them."""
        perception = self.gate.gate.schedules.get("perception")
        due = b - self.gate.latency_ns("perception")
        publishes = self.wrist_published
        if (
            perception is None
            or "perception" not in self.gate.gate.alive
            or not (self.gate.lockstep and publishes)
            or due < 0
            or due % perception.period_ns
        ):
            return
        if not self._sliced(self.robot.wait_wrist, timeout):
            self.log.warning("t=%.2f s: no wrist detections stamped %d", b / NS_PER_S, due)


def _stamped(waitable: Waitable, stamp_ns: int, timeout_s: float) -> bool:
    try:
        waitable.wait_stamp(stamp_ns, timeout_s)
    except WaitTimeout:
        return False
    return True
