"""The mission's per-tick wait for its inputs, against fakes of the robot and the gate."""

from __future__ import annotations

import logging

import pytest

from common.bus import WaitTimeout
from common.config import Participant
from common.lockstep import AckGate
from services.mission.inputs import TickInputs

MS = 1_000_000
TICK = 50 * MS
WBC_KEY = "dume/alive/b1/wbc"


class FakeLatest:
    def __init__(self, arrives: bool = True) -> None:
        self.arrives = arrives
        self.waited: list[int] = []

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> object:
        self.waited.append(stamp_ns)
        if not self.arrives:
            raise WaitTimeout(f"nothing stamped {stamp_ns}")
        return object()


class FakeRobot:
    def __init__(self, wrist: bool = True) -> None:
        self.odom, self.wbc = FakeLatest(), FakeLatest()
        self.wrist = wrist
        self.calls: list[str] = []

    def begin(self, b: int) -> None:
        self.calls.append(f"begin {b}")

    def wait_wrist(self, timeout_s: float) -> bool:
        self.calls.append("wrist")
        return self.wrist


class FakeGate:
    """Perception every 100 ms with 50 ms latency, alive; the outputs in unless `missing`."""

    def __init__(self, lockstep: bool = True, missing: tuple[str, ...] = ()) -> None:
        self.lockstep = lockstep
        self.gate = AckGate({"perception": Participant(period_s=0.1, latency_s=0.05)}, MS)
        self.gate.join("perception", 0)
        self.missing = list(missing)
        self.waited: list[int] = []

    def latency_ns(self, producer: str) -> int:
        s = self.gate.schedules.get(producer)
        return s.latency_ns if s else 0

    def wait(self, t_ns: int, timeout_s: float) -> list[str]:
        self.waited.append(t_ns)
        return self.missing


class Rig:
    def __init__(
        self,
        robot: FakeRobot | None = None,
        gate: FakeGate | None = None,
        alive: frozenset[str] = frozenset({WBC_KEY}),
        wrist_published: bool = True,
    ) -> None:
        self.robot, self.gate = robot or FakeRobot(), gate or FakeGate()
        self.heard = 0
        self.inputs = TickInputs(
            self.robot,
            self.gate,
            lambda: alive,
            self.hear,
            WBC_KEY,
            20 * MS,  # the controller's status at 50 Hz
            wrist_published,
            0.5,
            logging.getLogger("test.mission.inputs"),
        )

    def hear(self) -> bool:
        self.heard += 1
        return True


def test_the_first_tick_in_lockstep_hears_who_runs_and_later_ones_do_not() -> None:
    rig = Rig()
    rig.inputs.wait(0, first=True)
    rig.inputs.wait(TICK, first=False)
    assert rig.heard == 1
    realtime = Rig(gate=FakeGate(lockstep=False))
    realtime.inputs.wait(0, first=True)
    assert realtime.heard == 0


def test_odom_at_b_and_the_controllers_status_before_b_then_the_gate_then_begin() -> None:
    rig = Rig()
    for b in (0, TICK, 2 * TICK):
        rig.inputs.wait(b, first=b == 0)
    assert rig.robot.odom.waited == [0, TICK, 2 * TICK]
    # b > 0 only: the newest 20 ms boundary strictly before b
    assert rig.robot.wbc.waited == [40 * MS, 80 * MS]
    assert rig.gate.waited == [0, TICK, 2 * TICK]
    assert [c for c in rig.robot.calls if c.startswith("begin")] == [
        "begin 0",
        f"begin {TICK}",
        f"begin {2 * TICK}",
    ]


def test_the_controllers_status_is_not_waited_for_while_it_is_not_alive() -> None:
    rig = Rig(alive=frozenset())
    rig.inputs.wait(TICK, first=False)
    assert rig.robot.wbc.waited == []


def test_the_wrist_is_waited_for_after_begin_at_the_ticks_perceptions_output_is_due() -> None:
    rig = Rig()
    for k in range(6):
        rig.inputs.wait(k * TICK, first=k == 0)
    # due = b − 50 ms must be one of perception's ticks (every 100 ms, from 0)
    waited_at = [
        int(rig.robot.calls[i - 1].split()[1]) // MS
        for i, c in enumerate(rig.robot.calls)
        if c == "wrist"
    ]
    assert waited_at == [50, 150, 250]


@pytest.mark.parametrize(
    "rig",
    [
        Rig(wrist_published=False),
        Rig(gate=FakeGate(lockstep=False)),
    ],
)
def test_the_wrist_is_not_waited_for_when_it_is_not_published_in_lockstep(rig: Rig) -> None:
    rig.inputs.wait(TICK, first=False)
    assert "wrist" not in rig.robot.calls


def test_the_wrist_is_not_waited_for_while_perception_is_not_alive() -> None:
    rig = Rig()
    rig.gate.gate.leave("perception")
    rig.inputs.wait(TICK, first=False)
    assert "wrist" not in rig.robot.calls


def test_missing_inputs_are_logged_and_the_tick_goes_on(caplog: pytest.LogCaptureFixture) -> None:
    robot = FakeRobot(wrist=False)
    robot.odom.arrives = robot.wbc.arrives = False
    rig = Rig(robot=robot, gate=FakeGate(missing=("navigation",)))
    with caplog.at_level(logging.WARNING, logger="test.mission.inputs"):
        rig.inputs.wait(TICK, first=False)
    assert [r.getMessage() for r in caplog.records] == [
        "no odom for t=0.05 s",
        "no wbc/status for t=0.04 s",
        "t=0.05 s: no output of ['navigation'] in time",
        "t=0.05 s: no wrist detections stamped 0",
    ]
    assert robot.calls[0] == f"begin {TICK}" and set(robot.calls[1:]) == {"wrist"}


def test_a_dependency_lost_while_waiting_gives_the_tick_up_at_once() -> None:
    """A killed WBC sends no odom for b: the wait ends when the loss is seen (within a
    slice or two), not after the whole timeout, and the robot still begins b."""
    robot = FakeRobot()
    robot.odom.arrives = False
    rig = Rig(robot=robot)
    rig.inputs.timeout_s = 30.0
    looks = iter([False, False, True])
    rig.inputs.lost = lambda: next(looks, True)
    assert rig.inputs.wait(TICK, first=False) is False
    assert len(robot.odom.waited) == 3, "three slices, then the loss"
    assert robot.calls == [f"begin {TICK}"] and rig.gate.waited == []
