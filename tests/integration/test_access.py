"""Who may talk to the robot (`common.access`), on a real router: a session without the
stack's password is refused at the door; a user's session can neither watch the robot's
sensors nor move it (the rogue-client probe of the hardening issue), while a trusted one
doing the same does move it, so the test can fail."""

from __future__ import annotations

import time
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.access import TRUSTED, USER, identities, identity_of
from common.bus import Bus, NoRouter
from common.messages.sim import Odom, SimStats, StateTruth
from common.messages.wbc import CmdVel, WbcMode
from deploy.stack import ProcessStack
from tests.conftest import StartStack
from tests.integration.test_wbc_stack import WBC

pytestmark = pytest.mark.integration


def test_a_session_without_the_stacks_password_is_refused_at_the_door(
    stack: StartStack, tmp_path: Path
) -> None:
    s = stack(["sim", "wbc"], *WBC, "sim.duration_s=60")
    with pytest.raises(NoRouter, match="refused"):
        Bus.open(s.config, connect_timeout_s=2.0, user=None).close()
    forged = tmp_path / "users"
    forged.write_text("".join(f"{who}:guessed\n" for who in identities(s.config)))
    zenoh = msgspec.structs.replace(s.config.zenoh, credentials=str(forged))
    other = msgspec.structs.replace(s.config, zenoh=zenoh)
    with pytest.raises(NoRouter, match="refused"):
        Bus.open(other, connect_timeout_s=2.0, user=TRUSTED).close()


def _drive(s: ProcessStack, bus: Bus, source: str, truth_now: StateTruth) -> None:
    """What the rogue client did: the WBC's mode to walk on `source`, 1.5 s of 0.5 m/s
    forward at 20 Hz (stamped on the sim's clock), then damp."""
    mode = bus.publisher(s.keys.wbc_mode, WbcMode)
    vel = bus.publisher(s.keys.cmd_vel, CmdVel)
    t = truth_now.stamp_ns
    mode.put(WbcMode(stamp_ns=t, mode="walk", cmd_vel_source=source))
    for k in range(30):
        vel.put(CmdVel(stamp_ns=t + k * 50_000_000, vx=0.5, vy=0.0, wz=0.0, source=source))
        time.sleep(0.05)


def test_a_user_can_neither_watch_nor_move_the_robot_and_a_trusted_client_can(
    stack: StartStack,
) -> None:
    s = stack(["sim", "wbc"], *WBC, "sim.duration_s=600")
    truth = s.bus.latest(s.keys.state_truth, StateTruth)
    first = truth.wait(lambda m: m.stamp_ns >= 1_000_000_000, 120)
    with Bus.open(s.config, user=USER) as user:
        odom = user.fifo(s.keys.odom, Odom)
        seen_truth = user.fifo(s.keys.state_truth, StateTruth)
        _drive(s, user, "rogue", first)
        user.publisher(s.keys.wbc_mode, WbcMode).put(WbcMode(stamp_ns=first.stamp_ns, mode="damp"))
        later = truth.wait(lambda m: m.stamp_ns >= first.stamp_ns + 3_000_000_000, 300)
        assert len(list(odom.drain())) == 0 and len(list(seen_truth.drain())) == 0
    p0, p1 = np.array(first.base_position_in_world), np.array(later.base_position_in_world)
    assert np.linalg.norm(p1[:2] - p0[:2]) < 0.02, "the user's commands moved the robot"
    assert abs(p1[2] - p0[2]) < 0.02, "the user's damp reached the WBC"
    # The same commands from a client the stack trusts are obeyed: the check above can fail.
    _drive(s, s.bus, "trial", later)
    moved = truth.wait(lambda m: m.stamp_ns >= later.stamp_ns + 3_000_000_000, 300)
    p2 = np.array(moved.base_position_in_world)
    assert np.linalg.norm(p2[:2] - p1[:2]) > 0.1


def test_another_robots_navigation_on_the_same_router_cannot_move_this_one(
    stack: StartStack,
) -> None:
    """Robot b1's stack on a router that also serves b2 (`zenoh.robots`): b2's navigation,
    logged in as itself, drives b1's base and damps it; b1 neither moves nor sags, and
    b2's navigation does not see b1's odometry. (The trusted drive in the user test above
    moves the same robot, so the check can fail.)"""
    s = stack(["sim", "wbc"], *WBC, "sim.duration_s=600", 'zenoh.robots=["b2"]')
    truth = s.bus.latest(s.keys.state_truth, StateTruth)
    first = truth.wait(lambda m: m.stamp_ns >= 1_000_000_000, 120)
    with Bus.open(s.config, user=identity_of("navigation", "b2")) as other:
        odom = other.fifo(s.keys.odom, Odom)
        _drive(s, other, "navigation", first)
        other.publisher(s.keys.wbc_mode, WbcMode).put(WbcMode(stamp_ns=first.stamp_ns, mode="damp"))
        later = truth.wait(lambda m: m.stamp_ns >= first.stamp_ns + 3_000_000_000, 300)
        assert len(list(odom.drain())) == 0, "b2's navigation read b1's odometry"
    p0, p1 = np.array(first.base_position_in_world), np.array(later.base_position_in_world)
    assert np.linalg.norm(p1[:2] - p0[:2]) < 0.02, "b2's navigation moved b1"
    assert abs(p1[2] - p0[2]) < 0.02, "b2's damp reached b1's WBC"


def test_lockstep_holds_under_the_acl_the_sim_hears_every_participants_ack(
    stack: StartStack,
) -> None:
    """The mission, logged in as itself, is a periodic participant: the sim hears its
    acks and waits for it, and never steps on without it. (A subscriber on `ack/*` was
    never announced to a participant under the ACL, so a Zenoh publisher that heard of no
    subscriber sent no ack: every real service stalled 10 s at start and ran free after.)"""
    mission = [
        'time.participants.mission.role="periodic"',
        "time.participants.mission.period_s=0.05",
        "time.participants.mission.latency_s=0.05",
    ]
    s = stack(["sim", "wbc", "mission"], *WBC, *mission, "sim.duration_s=60")
    stats = s.bus.latest(s.keys.sim_stats, SimStats)
    at = stats.wait(lambda m: m.stamp_ns >= 2_000_000_000, 120)
    assert at.stalls == 0, f"the sim stepped on without a participant: {at}"


def test_a_service_identity_reaches_only_its_own_keys(stack: StartStack) -> None:
    """A process logged in as perception (a compromised or buggy one) reads no truth and
    cannot move the robot; as navigation, it can drive the base (its job) but not the
    joints. Measured on the sim's truth, with the trusted session's drive as the check
    that the drive works."""
    s = stack(["sim", "wbc"], *WBC, "sim.duration_s=600", 'semantic_map.floor_plan="none"')
    truth = s.bus.latest(s.keys.state_truth, StateTruth)
    first = truth.wait(lambda m: m.stamp_ns >= 1_000_000_000, 120)
    with Bus.open(s.config, user=identity_of("perception", s.config.robot)) as perception:
        seen_truth = perception.fifo(s.keys.state_truth, StateTruth)
        odom = perception.fifo(s.keys.odom, Odom)  # its own input: delivered
        _drive(s, perception, "rogue", first)
        later = truth.wait(lambda m: m.stamp_ns >= first.stamp_ns + 3_000_000_000, 300)
        assert len(list(seen_truth.drain())) == 0, "perception read the sim's truth"
        assert len(list(odom.drain())) > 0, "perception's own input did not arrive"
    p0, p1 = np.array(first.base_position_in_world), np.array(later.base_position_in_world)
    assert np.linalg.norm(p1[:2] - p0[:2]) < 0.02, "perception's commands moved the robot"
    with Bus.open(s.config, user=identity_of("navigation", s.config.robot)) as navigation:
        joints = navigation.publisher(s.keys.wbc_mode, WbcMode)  # the mode: not navigation's
        joints.put(WbcMode(stamp_ns=later.stamp_ns, mode="damp"))
        after = truth.wait(lambda m: m.stamp_ns >= later.stamp_ns + 2_000_000_000, 300)
    assert abs(after.base_position_in_world[2] - p1[2]) < 0.02, "navigation's damp reached the WBC"
