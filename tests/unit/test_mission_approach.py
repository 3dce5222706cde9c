"""The approach controller (eq. 3) on a simulated kinematic plant: a base in the plane,
an object at a fixed world point, sightings every 100 ms arriving 100 ms late."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.config import ApproachSettings
from common.robot import D_OPT_M, THETA_OPT_RAD
from services.mission.approach import (
    ApproachCommand,
    ApproachController,
    Sighting,
)

DT = 0.02
CAMERA_PERIOD = 0.1
DELAY = 0.1


class Plant:
    """A base (x, y, yaw) obeying (vx, vy, ωz) in base_yaw exactly; the object at `obj`."""

    def __init__(self, x: float, y: float, yaw: float, obj: tuple[float, float] = (0.0, 0.0)):
        self.pose = np.array([x, y, yaw], dtype=float)
        self.obj = np.array(obj, dtype=float)
        self.history: list[tuple[float, Sighting]] = []

    def sense(self, t: float) -> Sighting:
        x, y, yaw = self.pose
        dx, dy = self.obj - (x, y)
        c, s = math.cos(yaw), math.sin(yaw)
        bx, by = c * dx + s * dy, -s * dx + c * dy
        return Sighting(d_obj=math.hypot(bx, by), theta_obj=math.atan2(by, bx), stamp_s=t)

    def move(self, cmd: ApproachCommand, dt: float) -> None:
        yaw = self.pose[2]
        c, s = math.cos(yaw), math.sin(yaw)
        self.pose += dt * np.array([c * cmd.vx - s * cmd.vy, s * cmd.vx + c * cmd.vy, cmd.wz])


def run(
    ctrl: ApproachController, plant: Plant, seconds: float, visible: bool = True
) -> list[ApproachCommand]:
    """Close the loop for `seconds`: frames every 100 ms, each delivered 100 ms later."""
    ctrl.reset(0.0)
    out: list[ApproachCommand] = []
    frames: list[Sighting] = []
    newest: Sighting | None = None
    for k in range(round(seconds / DT) + 1):
        t = k * DT
        if k % round(CAMERA_PERIOD / DT) == 0 and visible:
            frames.append(plant.sense(t))
        while frames and frames[0].stamp_s + DELAY <= t + 1e-9:
            newest = frames.pop(0)
        cmd = ctrl.step(t, newest)
        out.append(cmd)
        if cmd.state in ("arrived", "failed"):
            break
        plant.move(cmd, DT)
    return out


STARTS = [
    (-1.0, 0.0, 0.0),
    (-1.05, 0.2, 0.1),
    (-0.9, -0.3, -0.2),
    (-0.5, 0.5, -0.6),
    (-0.6, -0.1, 0.4),
    (-0.4, 0.0, 0.0),  # too close: backs up
    (-1.3, 0.4, -0.1),
]


@pytest.mark.parametrize("start", STARTS)
def test_the_controller_converges_to_d_opt_and_theta_opt_from_many_starts(
    start: tuple[float, float, float],
) -> None:
    gains = ApproachSettings()
    ctrl = ApproachController(gains)
    plant = Plant(*start)
    cmds = run(ctrl, plant, 30.0)
    assert cmds[-1].state == "arrived", cmds[-1]
    final = plant.sense(0.0)
    assert abs(final.d_obj - D_OPT_M) <= gains.tol_d_m + 0.005
    assert abs(final.theta_obj - THETA_OPT_RAD) <= gains.tol_theta_rad + 0.01
    assert (cmds[-1].vx, cmds[-1].vy, cmds[-1].wz) == (0.0, 0.0, 0.0)


def test_commands_respect_the_speed_and_acceleration_limits() -> None:
    gains = ApproachSettings()
    ctrl = ApproachController(gains)
    cmds = run(ctrl, Plant(-2.5, 1.0, 0.8), 30.0)
    vx = np.array([c.vx for c in cmds])
    wz = np.array([c.wz for c in cmds])
    assert np.all(np.abs(vx) <= gains.vx_max + 1e-12)
    assert np.all(np.abs(wz) <= gains.wz_max + 1e-12)
    assert np.all(np.abs(np.diff(vx[:-1])) <= gains.ax_max * DT + 1e-12)  # the last: arrived
    assert np.all(np.abs(np.diff(wz[:-1])) <= gains.az_max * DT + 1e-12)
    assert all(c.vy == 0.0 for c in cmds)


@pytest.mark.parametrize("last_d", [0.6, 1.0])
def test_a_vanished_object_is_reacquired_by_turning_toward_it_and_moving_then_fails(
    last_d: float,
) -> None:
    """Last seen nearer than d_opt: back off to get it into view; beyond: creep toward it,
    no farther than it was beyond."""
    gains = ApproachSettings()
    ctrl = ApproachController(gains)
    ctrl.reset(0.0)
    seen = Sighting(d_obj=last_d, theta_obj=0.3, stamp_s=0.0)
    states = []
    t = 0.0
    cmds = []
    while t < 20.0:
        cmd = ctrl.step(t, seen)
        cmds.append((t, cmd))
        states.append(cmd.state)
        if cmd.state == "failed":
            break
        t += DT
    assert states[0] == "tracking"
    reacq = [(t, c) for t, c in cmds if c.state == "reacquiring"]
    assert reacq, "never re-acquired"
    assert reacq[0][0] == pytest.approx(gains.lost_after_s, abs=2 * DT)
    assert any(c.wz > 0.1 for _, c in reacq)  # toward the last bearing (+0.3 rad: left)
    assert all(c.wz >= 0.0 for _, c in reacq)
    moved = sum(c.vx * DT for _, c in reacq)
    if last_d < D_OPT_M:
        assert any(c.vx < -0.05 for _, c in reacq)  # backs off
        assert -gains.back_off_max_m - 0.05 < moved < -0.1
    else:
        assert all(c.vx >= 0.0 for _, c in reacq)  # creeps toward where it was
        assert 0.1 < moved <= last_d - D_OPT_M + 0.02
    last_t, last = cmds[-1]
    assert last.state == "failed" and "lost the object" in last.reason
    assert last_t == pytest.approx(gains.lost_after_s + gains.reacquire_s, abs=2 * DT)
    # Latched: a late sighting does not revive a failed approach.
    assert ctrl.step(last_t + 1.0, Sighting(1.0, 0.0, last_t + 1.0)).state == "failed"


def test_a_sighting_during_reacquire_returns_to_tracking() -> None:
    ctrl = ApproachController()
    ctrl.reset(0.0)
    ctrl.step(0.0, Sighting(1.0, -0.2, 0.0))
    assert ctrl.step(2.0, None).state == "reacquiring"
    assert ctrl.step(2.1, Sighting(1.0, -0.2, 2.05)).state == "tracking"


def test_never_seeing_the_object_fails_with_a_reason_instead_of_freezing() -> None:
    gains = ApproachSettings()
    ctrl = ApproachController(gains)
    cmds = run(ctrl, Plant(-1.0, 0.0, 0.0), 30.0, visible=False)
    assert cmds[-1].state == "failed"
    assert "never seen" in cmds[-1].reason
    assert any(c.vx < 0.0 for c in cmds)  # it backs off to look


def test_an_approach_that_cannot_settle_times_out() -> None:
    gains = ApproachSettings(timeout_s=5.0)
    ctrl = ApproachController(gains)
    ctrl.reset(0.0)
    t, cmd = 0.0, None
    rng = np.random.default_rng(0)
    while t < 10.0:  # the object jumps around: never within tolerance for long
        cmd = ctrl.step(t, Sighting(0.7 + rng.uniform(-0.2, 0.2), rng.uniform(-0.3, 0.3), t))
        if cmd.state == "failed":
            break
        t += DT
    assert cmd is not None and cmd.state == "failed" and "not arrived" in cmd.reason
    assert t == pytest.approx(5.0, abs=2 * DT)


class Blocked(Plant):
    """A plant whose base cannot pass x = `stop_x` (a hip against the support's front)."""

    def __init__(self, x: float, stop_x: float) -> None:
        super().__init__(x, 0.0, 0.0)
        self.stop_x = stop_x
        self.moves = 0
        self.stuck_at: int | None = None  # the move at which it first met the stop

    def move(self, cmd: ApproachCommand, dt: float) -> None:
        super().move(cmd, dt)
        self.moves += 1
        if self.pose[0] >= self.stop_x and self.stuck_at is None:
            self.stuck_at = self.moves
        self.pose[0] = min(self.pose[0], self.stop_x)


def test_a_base_blocked_a_few_cm_short_arrives_there_saying_so() -> None:
    short = 0.06  # the hall's can 11 cm deep on a bench: stuck at d = d_opt + 6 cm
    plant = Blocked(-1.1, stop_x=-(D_OPT_M + short))
    gains = ApproachSettings()
    cmds = run(ApproachController(gains), plant, 30.0)
    end = cmds[-1]
    assert end.state == "arrived", end
    assert end.reason.startswith("blocked short of d_opt, no nearer in 4 s: d_obj error +6.0 cm")
    # It pushed for stall_s (and the camera's delay) after it met the stop, no longer.
    assert plant.stuck_at is not None
    pushed_s = (len(cmds) - plant.stuck_at) * DT
    assert gains.stall_s - 0.2 <= pushed_s <= gains.stall_s + 0.5, pushed_s  # progress_m: 1 cm


def test_a_base_blocked_farther_than_the_slack_does_not_arrive() -> None:
    plant = Blocked(-1.2, stop_x=-(D_OPT_M + 0.2))
    cmds = run(ApproachController(ApproachSettings(timeout_s=15.0)), plant, 30.0)
    assert cmds[-1].state == "failed" and "not arrived" in cmds[-1].reason


def test_an_unblocked_approach_still_settles_within_tolerance() -> None:
    plant = Plant(-1.1, 0.0, 0.0)
    cmds = run(ApproachController(ApproachSettings()), plant, 30.0)
    assert cmds[-1].state == "arrived" and not cmds[-1].reason.startswith("blocked")


@pytest.mark.parametrize(
    "bad",
    [
        Sighting(math.nan, 0.0, 0.0),
        Sighting(1.0, math.inf, 0.0),
        Sighting(1.0, 0.0, math.nan),
        Sighting(-1.0, 0.0, 0.0),
    ],
)
def test_bad_sightings_never_produce_nan_commands(bad: Sighting) -> None:
    ctrl = ApproachController()
    ctrl.reset(0.0)
    for k in range(400):
        cmd = ctrl.step(k * DT, bad)
        assert all(math.isfinite(x) for x in (cmd.vx, cmd.vy, cmd.wz))
    assert cmd.state == "failed"  # the bad sightings count as none


def test_noisy_sightings_still_arrive_and_never_give_nan() -> None:
    rng = np.random.default_rng(1)
    ctrl = ApproachController()
    plant = Plant(-1.0, 0.1, 0.05)
    ctrl.reset(0.0)
    newest = None
    for k in range(2000):
        t = k * DT
        if k % 5 == 0:
            s = plant.sense(t)
            newest = Sighting(s.d_obj + rng.normal(0, 0.005), s.theta_obj + rng.normal(0, 0.01), t)
        cmd = ctrl.step(t, newest)
        assert all(math.isfinite(x) for x in (cmd.vx, cmd.vy, cmd.wz))
        if cmd.state == "arrived":
            break
        plant.move(cmd, DT)
    assert cmd.state == "arrived"


def test_gains_refuse_nonsense() -> None:
    with pytest.raises(ValueError, match="positive"):
        ApproachSettings(k_d=-1.0)
    with pytest.raises(ValueError, match="lost_after_s"):
        ApproachSettings(max_age_s=2.0, lost_after_s=1.0)


def test_a_base_held_back_for_a_person_is_no_stall_and_arrives_once_let_go() -> None:
    # A person beside the object holds the base 6 cm short (navigation's caps: ahead 0)
    # for 12 s, longer than stall_s and than a 10 s timeout; then they walk off.
    gains = ApproachSettings(timeout_s=10.0)
    ctrl = ApproachController(gains)
    plant = Plant(-1.1, 0.0, 0.0)
    ctrl.reset(0.0)
    frames: list[Sighting] = []
    newest: Sighting | None = None
    cmd = None
    held_until, stop_x = 15.0, -(D_OPT_M + 0.06)
    for k in range(round(40.0 / DT)):
        t = k * DT
        if k % round(CAMERA_PERIOD / DT) == 0:
            frames.append(plant.sense(t))
        while frames and frames[0].stamp_s + DELAY <= t + 1e-9:
            newest = frames.pop(0)
        cmd = ctrl.step(t, newest)
        if cmd.state in ("arrived", "failed"):
            break
        vx = cmd.vx
        if t < held_until and plant.pose[0] >= stop_x and vx > 0.0:
            vx = 0.0  # what `within_caps` lets through
            ctrl.hold(t)
        plant.move(ApproachCommand(vx, cmd.vy, cmd.wz, cmd.state), DT)
    assert cmd is not None and cmd.state == "arrived", cmd
    assert not cmd.reason.startswith("blocked"), cmd.reason
    assert t > held_until
    e_d, _ = ctrl.errors() or (math.inf, 0.0)
    assert abs(e_d) <= gains.tol_d_m
