"""The mission's desk and inbox without Zenoh: requests in, the tree driven, statuses out.

A `Desk` over the scripted robot (`mission_fakes`), liveliness fed by hand
(`common.lifelines`), statuses collected from its `send`: what a client of
`mission/submit`, `mission/request` and `mission/cancel` sees on `mission/status`.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
import rerun as rr

from common.lifelines import HOLD_S, LOST_GRACE_S, Dependencies, Lifelines
from common.messages import encode
from common.messages.mission import MissionCancel, MissionRequest, MissionStatus
from services.mission.desk import Desk
from services.mission.inbox import Inbox, RequestInbox
from services.mission.journal import FILE, Journal
from services.mission.mission_log import MissionLogger
from services.mission.node import DEPENDENCIES
from services.mission.requests import StatusBoard
from services.mission.tree import MissionTree
from tests.unit.mission_fakes import TICK_NS, FakeRobot, context, small_world

REQUEST = MissionRequest(request_id="r1", object="bottle_1", person="person_1")
LOG = logging.getLogger("test.mission.desk")


def key_of(name: str) -> str:
    return f"dume/alive/b1/{name}"


class WallClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class Rig:
    """A desk, its inboxes, the liveliness it watches and every status it sent."""

    def __init__(
        self,
        robot: FakeRobot | None = None,
        every_s: float = 100.0,
        journal: Journal | None = None,
        wall: WallClock | None = None,
    ) -> None:
        """`wall`: the dependencies, each with its run, doubted and held as the node's
        are (`LOST_GRACE_S`, `HOLD_S`) on that clock; else lost at once, runs unknown."""
        self.robot = robot or small_world()
        self.lifelines = Lifelines() if wall is None else Lifelines(wall)
        for name in DEPENDENCIES:
            if wall is not None:
                self.lifelines.run_up(key_of(name), f"{name}-1")
            self.lifelines.up(key_of(name))
        deps = (
            Dependencies(self.lifelines, DEPENDENCIES, key_of, grace_s=0.0, link_grace_s=0.0)
            if wall is None
            else Dependencies(self.lifelines, DEPENDENCIES, key_of, clock=wall, hold_s=HOLD_S)
        )
        self.tree = MissionTree(context(self.robot))
        self.requests, self.cancels = RequestInbox(), Inbox()
        self.sent: list[MissionStatus] = []
        self.desk = Desk(
            self.tree,
            self.robot,
            deps,
            StatusBoard(round(every_s * 1e9)),
            self.requests,
            self.cancels,
            MissionLogger(rr.RecordingStream("test", default_enabled=False), LOG),
            self.sent.append,
            LOG,
            journal=journal,
        )

    def tick(self, n: int = 1) -> list[MissionStatus]:
        """n ticks as the node runs them; the statuses they sent."""
        before = len(self.sent)
        for _ in range(n):
            b = self.robot.now_ns
            changed = self.desk.step(b)
            self.robot.advance()  # the robot's outputs of tick b
            self.desk.flush(b, changed)
        return self.sent[before:]

    def running(self) -> None:
        """r1 submitted and walking to the object."""
        self.tick()
        self.requests.submit(REQUEST, "")
        self.tick(10)
        assert self.sent[-1].state == "running"


def test_the_first_tick_says_the_mission_started_with_no_request() -> None:
    rig = Rig()
    rig.robot.t = 3 * TICK_NS
    (status,) = rig.tick()
    assert (status.request_id, status.state, status.stamp_ns) == ("", "idle", 3 * TICK_NS)
    assert status.detail == "mission started at t=0.15 s"
    assert rig.tick(5) == []  # nothing changed, the periodic repeat is not due


def test_a_restarted_mission_fails_the_request_its_last_run_held(tmp_path: Path) -> None:
    """Killed with r1 running, the mission's next start fails r1 by its id, with the
    stage it was in, before its `idle`: nothing is re-run, nothing silently dropped."""
    first = Rig(journal=Journal(tmp_path))
    first.running()
    assert (tmp_path / FILE).exists()
    stage = first.sent[-1].behaviour
    restarted = Rig(journal=Journal(tmp_path))  # the mission process starts again
    restarted.robot.t = 40 * TICK_NS
    lost, idle = restarted.tick()
    assert (lost.request_id, lost.state, lost.reason) == ("r1", "failed", "dependency_lost")
    assert lost.behaviour == stage and lost.stamp_ns == 40 * TICK_NS
    assert lost.detail.startswith("mission restarted at t=2.00 s: the request was interrupted in")
    assert (idle.request_id, idle.state) == ("", "idle")
    assert not (tmp_path / FILE).exists()
    assert Rig(journal=Journal(tmp_path)).tick()[0].state == "idle"  # said once


def test_a_request_that_ended_leaves_nothing_for_the_next_start(tmp_path: Path) -> None:
    rig = Rig(journal=Journal(tmp_path))
    rig.running()
    rig.cancels.push(encode(MissionCancel(request_id="r1", reason="changed my mind")))
    rig.tick(3)
    assert rig.sent[-1].state == "cancelled"
    assert not (tmp_path / FILE).exists()
    (status,) = Rig(journal=Journal(tmp_path)).tick()
    assert status.state == "idle"


def test_an_unreadable_journal_is_reported_and_removed(tmp_path: Path) -> None:
    (tmp_path / FILE).write_bytes(b"\x00garbage")
    lost, idle = Rig(journal=Journal(tmp_path)).tick()
    assert (lost.request_id, lost.state, lost.reason) == ("unknown", "failed", "dependency_lost")
    assert "a stage not known (its record unreadable: " in lost.detail
    assert idle.state == "idle" and not (tmp_path / FILE).exists()


def test_a_request_submitted_by_query_is_in_the_inbox_before_the_reply_goes() -> None:
    inbox = RequestInbox()
    receipt = inbox.submit(REQUEST, "")
    assert inbox.drain() == [encode(REQUEST)]  # held when the receipt is handed back
    assert receipt.request_id == "r1"
    assert inbox.drain() == []


def test_an_inbox_keeps_the_arrival_order_and_drops_the_oldest_when_full() -> None:
    inbox = Inbox(maxlen=3)
    for k in range(5):
        inbox.push(bytes([k]))
    assert inbox.drain() == [b"\x02", b"\x03", b"\x04"]


def test_a_submitted_request_is_accepted_then_runs() -> None:
    rig = Rig()
    rig.tick()
    rig.requests.submit(REQUEST, "")
    accepted, running = rig.tick()
    assert (accepted.request_id, accepted.state) == ("r1", "accepted")
    assert accepted.detail == "checked against the map"
    assert (running.state, running.behaviour) == ("running", "navigate_to_object")
    assert rig.tree.request == REQUEST


def test_a_request_sent_ahead_of_its_time_is_held_until_the_tick_reaches_it() -> None:
    """A shift's next request arrives before its `at_ns`: nothing happens until the
    mission's tick is there, then it is taken as if it arrived then."""
    rig = Rig()
    rig.tick()
    at = rig.robot.now_ns + 5 * TICK_NS
    rig.requests.submit(MissionRequest(request_id="r2", object="bottle_1",
                                       person="person_1", at_ns=at), "")  # fmt: skip
    assert rig.tick(5) == [] and rig.desk.held
    assert rig.robot.now_ns == at
    accepted, running = rig.tick()
    assert (accepted.stamp_ns, accepted.request_id, accepted.state) == (at, "r2", "accepted")
    assert running.state == "running" and not rig.desk.held


def test_a_dependency_that_goes_down_fails_the_running_request_and_refuses_new_ones() -> None:
    rig = Rig()
    rig.running()
    rig.lifelines.down(key_of("navigation"))
    (failed,) = rig.tick()
    assert (failed.request_id, failed.state, failed.reason) == ("r1", "failed", "dependency_lost")
    assert failed.detail == "navigation is gone"
    assert rig.robot.cmds[-1] == (0.0, 0.0, 0.0)  # halted
    assert "" in rig.robot.nav_cancels
    assert not rig.tree.busy
    rig.requests.push(encode(MissionRequest(request_id="r2", object="bottle_1", person="person_1")))
    (refused,) = rig.tick()
    assert (refused.request_id, refused.state, refused.reason) == ("r2", "rejected", "unavailable")
    assert refused.detail == "not running: navigation"


def test_a_dependency_not_heard_is_said_at_once_and_held_for_while_it_may_come_back() -> None:
    """The sim's link lapsed for 0.5 s in a shift (the router cut it off under load):
    the mission says within the grace that it holds for it, and goes on when it is back
    as the same process; a second loss not back within `HOLD_S` fails the request."""
    wall = WallClock()
    rig = Rig(wall=wall)
    rig.running()
    rig.lifelines.down(key_of("navigation"))
    assert rig.tick() == []  # doubted: not yet said
    wall.t += LOST_GRACE_S + 0.01
    (holding,) = rig.tick()
    assert (holding.request_id, holding.state) == ("r1", "running")
    assert holding.detail.startswith("holding: navigation not heard")
    assert all(s.detail.startswith("holding: navigation") for s in rig.tick(3))
    wall.t += 0.2
    rig.lifelines.up(key_of("navigation"))  # back as the same run: its link lapsed
    rig.tick(3)
    assert rig.sent[-1].state == "running" and rig.desk.waiting == []
    rig.lifelines.down(key_of("navigation"))
    rig.tick()
    wall.t += HOLD_S - 0.01
    (held,) = rig.tick()
    assert (held.state, held.detail[:30]) == ("running", "holding: navigation not heard ")
    wall.t += 0.02
    (failed,) = rig.tick()
    assert (failed.state, failed.reason) == ("failed", "dependency_lost")
    assert failed.detail.startswith("navigation is gone")


def test_a_dependency_that_restarted_fails_the_running_request() -> None:
    rig = Rig()
    rig.running()
    rig.lifelines.down(key_of("perception"))
    rig.lifelines.up(key_of("perception"))
    (failed,) = rig.tick()
    assert (failed.reason, failed.detail) == ("dependency_lost", "perception restarted")
    rig.requests.push(encode(REQUEST))
    assert rig.tick()[0].state == "accepted"  # alive again: a new request may start


def test_a_request_while_one_runs_is_busy_and_a_malformed_one_keeps_its_id() -> None:
    rig = Rig()
    rig.running()
    rig.requests.push(encode(MissionRequest(request_id="r2", object="bottle_1", person="person_1")))
    rig.requests.push(b'{"request_id": "r3", "object": 7}')
    busy, malformed = rig.tick()
    assert (busy.request_id, busy.reason, busy.detail) == ("r2", "busy", "mission r1 is running")
    assert (malformed.request_id, malformed.state, malformed.reason) == (
        "r3",
        "rejected",
        "malformed",
    )
    assert rig.tree.request == REQUEST


def test_an_unknown_object_is_refused_before_the_robot_moves() -> None:
    rig = Rig()
    rig.tick()
    rig.requests.submit(MissionRequest(request_id="r1", object="cup_9", person="person_1"), "")
    (refused,) = rig.tick()
    assert (refused.state, refused.reason) == ("rejected", "unknown_object")
    assert rig.robot.nav_goals == []


def test_a_put_back_with_nothing_held_is_accepted_unchecked_and_succeeds_saying_so() -> None:
    rig = Rig()
    rig.tick()
    rig.requests.submit(MissionRequest(request_id="p1", task="put_back"), "")
    statuses = rig.tick(5)
    assert (statuses[0].state, statuses[0].detail) == ("accepted", "put back what it holds")
    done = statuses[-1]
    assert (done.request_id, done.state, done.detail) == (
        "p1",
        "succeeded",
        "nothing held to put back",
    )
    assert rig.robot.nav_goals == [] and rig.robot.arm_goals == []


def test_only_a_cancel_of_the_running_request_stops_it() -> None:
    rig = Rig()
    rig.running()
    rig.cancels.push(encode(MissionCancel(request_id="other")))
    rig.cancels.push(b"not json")
    assert rig.tick() == []  # both ignored: still running, nothing changed
    rig.cancels.push(encode(MissionCancel(request_id="r1", reason="changed my mind")))
    (cancelled,) = rig.tick()
    assert (cancelled.state, cancelled.reason, cancelled.detail) == (
        "cancelled",
        "cancelled",
        "changed my mind",
    )
    assert not rig.tree.busy


def test_a_behaviour_that_raises_fails_the_mission_internal_and_halts(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rig = Rig()
    rig.running()

    def boom() -> None:
        raise RuntimeError("a bug")

    monkeypatch.setattr(rig.tree, "tick", boom)
    (failed,) = rig.tick()
    assert (failed.state, failed.reason) == ("failed", "internal")
    assert rig.robot.cmds[-1] == (0.0, 0.0, 0.0)
    assert not rig.tree.busy


def test_the_status_repeats_every_period_while_nothing_changes() -> None:
    rig = Rig(every_s=0.2)
    assert [s.stamp_ns for s in rig.tick(9)] == [0, 4 * TICK_NS, 8 * TICK_NS]


def test_a_loss_noticed_while_a_tick_waits_on_inputs_is_said_between_ticks() -> None:
    """The tick waits on the lost one's inputs (a killed WBC sends no odom): the node asks
    `lost()` every slice of the wait and the desk says the hold then, not at the tick."""
    wall = WallClock()
    rig = Rig(wall=wall)
    rig.running()
    before = len(rig.sent)
    rig.lifelines.down(key_of("wbc"))
    assert rig.desk.deps.lost() is None
    rig.desk.notice(rig.robot.now_ns)
    assert len(rig.sent) == before  # doubted, not noticed yet: nothing said
    wall.t += LOST_GRACE_S + 0.01
    assert rig.desk.deps.lost() is None
    rig.desk.notice(rig.robot.now_ns)
    (held,) = rig.sent[before:]
    assert (held.request_id, held.state) == ("r1", "running")
    assert held.detail.startswith("holding: wbc not heard")
    rig.desk.notice(rig.robot.now_ns)
    assert len(rig.sent) == before + 1  # said once
