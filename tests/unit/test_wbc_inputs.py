"""cmd_vel arbitration and staleness, modes on sim time, the base pose history, the wrench."""

from __future__ import annotations

import numpy as np
import pytest

from common import robot
from common.geometry import make_T
from common.messages.wbc import CmdVel, WbcMode
from services.wbc.inputs import CmdVelArbiter, ModeQueue, PoseHistory
from services.wbc.model import RobotModel
from services.wbc.wrench import WrenchEstimator, wrench_from_residual

MS = 1_000_000


def cmd(t_ms: int, vx: float, source: str = "navigation") -> CmdVel:
    return CmdVel(stamp_ns=t_ms * MS, vx=vx, vy=0.0, wz=0.0, source=source)


def test_only_the_source_named_by_the_mode_is_obeyed_and_the_others_are_counted() -> None:
    arb = CmdVelArbiter({}, 500 * MS)
    arb.select("navigation")
    arb.push(cmd(0, 0.5))
    arb.push(cmd(1, -0.7, source="mission"))
    arb.push(cmd(2, -0.7, source="mission"))
    assert arb.command(10 * MS)[0] == 0.5
    assert arb.ignored == {"mission": 2}
    arb.select("mission")
    assert arb.command(10 * MS)[0] == -0.7  # its newest, sent before it was chosen


def test_a_switch_of_source_obeys_the_same_samples_whenever_they_arrived() -> None:
    early, late = CmdVelArbiter({}, 500 * MS), CmdVelArbiter({}, 500 * MS)
    for arb in (early, late):
        arb.select("navigation")
    early.push(cmd(5, 0.4, source="mission"))  # arrived before the switch …
    early.select("mission")
    late.select("mission")
    late.push(cmd(5, 0.4, source="mission"))  # … or after it
    assert early.command(10 * MS)[0] == late.command(10 * MS)[0] == 0.4


def test_a_command_takes_effect_at_its_stamp_plus_the_sources_latency() -> None:
    arb = CmdVelArbiter({"navigation": 50 * MS}, 500 * MS)
    arb.select("navigation")
    arb.push(cmd(100, 0.3))
    assert arb.command(149 * MS)[0] == 0.0
    assert arb.command(150 * MS)[0] == 0.3


def test_a_command_older_than_the_timeout_means_stop() -> None:
    arb = CmdVelArbiter({}, 500 * MS)
    arb.select("navigation")
    arb.push(cmd(0, 0.3))
    assert arb.command(500 * MS)[0] == 0.3 and not arb.stale
    assert arb.command(501 * MS)[0] == 0.0 and arb.stale


def test_modes_apply_in_order_at_stamp_plus_latency() -> None:
    modes = ModeQueue(20 * MS)
    modes.push(WbcMode(stamp_ns=0, mode="walk"))
    modes.push(WbcMode(stamp_ns=10 * MS, mode="manipulate"))
    assert modes.due(19 * MS) == []
    assert [m.mode for m in modes.due(30 * MS)] == ["walk", "manipulate"]
    assert modes.due(40 * MS) == []


def test_the_pose_history_gives_the_pose_at_or_before_a_stamp() -> None:
    hist = PoseHistory(span_ns=10 * MS, every_ns=MS)
    for k in range(30):
        hist.add(k * MS, make_T(np.eye(3), np.array([k, 0.0, 0.0])))
    assert hist.at(25 * MS + 500) is not None
    assert hist.at(25 * MS + 500)[0, 3] == 25  # type: ignore[index]
    assert hist.at(99 * MS)[0, 3] == 29  # type: ignore[index]
    assert hist.at(5 * MS) is None  # older than the history


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


def test_the_wrench_is_recovered_from_the_torques_it_causes(model: RobotModel) -> None:
    q = robot.standing_q("ready")
    model.update(q, np.zeros(model.nv))
    J = model.frames[robot.TCP_FRAME].J
    F = np.array([3.0, -10.0, -5.0, 0.2, 0.1, -0.3])
    # static: the joints hold gravity and push back on F, so τ = h − Jᵀ F
    tau = np.zeros(19)
    tau[12:18] = model.h[18:24] - J[:, 18:24].T @ F
    est = WrenchEstimator(np.zeros(19), np.zeros(19), damping=1e-4, alpha=1.0)
    out = est.update(model.h, model.v, tau, J, np.eye(3))
    np.testing.assert_allclose(out, F, atol=0.05)


def test_the_wrench_comes_out_in_the_base_frame(model: RobotModel) -> None:
    q = robot.standing_q("ready", yaw=np.pi / 2)
    model.update(q, np.zeros(model.nv))
    J = model.frames[robot.TCP_FRAME].J
    F_world = np.array([0.0, 10.0, 0.0, 0.0, 0.0, 0.0])  # pulled along world y
    tau = np.zeros(19)
    tau[12:18] = model.h[18:24] - J[:, 18:24].T @ F_world
    R = model.frames[robot.BASE_FRAME].R
    out = WrenchEstimator(np.zeros(19), np.zeros(19), damping=1e-4, alpha=1.0).update(
        model.h, model.v, tau, J, R
    )
    np.testing.assert_allclose(out[:3], [10.0, 0.0, 0.0], atol=0.05)  # = forward in the base


def test_damped_least_squares_stays_finite_at_a_singular_jacobian() -> None:
    J = np.zeros((6, 6))
    J[0, 0] = 1.0
    F = wrench_from_residual(J, np.ones(6), 0.02)
    assert np.all(np.isfinite(F))


class _Fifo:
    """The part of `common.bus.Fifo` the feed uses, filled by the test."""

    def __init__(self, *msgs: CmdVel) -> None:
        self.q = list(msgs)

    def drain(self) -> list[CmdVel]:
        out, self.q = self.q, []
        return out

    def pop(self, timeout_s: float = 0.0) -> CmdVel | None:
        return self.q.pop(0) if self.q else None


def test_the_gate_is_met_only_by_samples_the_arbiter_holds() -> None:
    from common.bus import WaitTimeout
    from services.wbc.inputs import ArbiterFeed

    arb = CmdVelArbiter({"navigation": 50 * MS}, 500 * MS)
    arb.select("navigation")
    modes = ModeQueue(50 * MS)
    walk = WbcMode(stamp_ns=0, mode="walk", cmd_vel_source="navigation")
    with_mode = CmdVel(stamp_ns=0, vx=0.9, vy=0.0, wz=0.0, source="mission", mode=walk)
    fifo = _Fifo(cmd(0, 0.1), with_mode)
    feed = ArbiterFeed(fifo, arb, "navigation", modes)  # type: ignore[arg-type]
    assert feed.get() == cmd(0, 0.1) and arb.newest("mission") == with_mode
    assert modes.due(49 * MS) == [] and modes.due(50 * MS) == [walk]  # the mode it carried
    with pytest.raises(WaitTimeout):
        feed.wait_stamp(50 * MS, 0.01)
    fifo.q.append(cmd(50, 0.3))
    assert feed.wait_stamp(50 * MS, 0.01).vx == 0.3
    assert arb.command(100 * MS)[0] == 0.3  # what met the gate is what the arbiter obeys


def test_a_sample_sent_again_after_a_cut_link_carries_its_mode_once() -> None:
    """A source sends its last cmd_vel again when its link to the router comes back
    (`common.bus.LinkBack`): the mode it carries is applied once, not twice."""
    from services.wbc.inputs import ArbiterFeed

    arb = CmdVelArbiter({"mission": 50 * MS}, 500 * MS)
    arb.select("mission")
    modes = ModeQueue(50 * MS)
    walk = WbcMode(stamp_ns=0, mode="walk", cmd_vel_source="mission")
    with_mode = CmdVel(stamp_ns=0, vx=0.2, vy=0.0, wz=0.0, source="mission", mode=walk)
    fifo = _Fifo(with_mode, with_mode)
    feed = ArbiterFeed(fifo, arb, "mission", modes)  # type: ignore[arg-type]
    assert feed.get() == with_mode
    fifo.q.append(with_mode)
    assert feed.get() == with_mode
    assert modes.due(50 * MS) == [walk]
    fifo.q.append(CmdVel(stamp_ns=50 * MS, vx=0.2, vy=0.0, wz=0.0, source="mission", mode=walk))
    feed.get()
    assert modes.due(100 * MS) == [walk]  # a new sample's mode is still obeyed
