"""The simulator as a service: real Zenoh on loopback, real processes, lockstep time."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from common import robot
from common.config import parse_overrides
from common.geometry import T_of_pose
from common.keys import WORLD_CLOCK, WORLD_DESCRIPTION
from common.messages import as_numpy
from common.messages.sim import CameraFrame, Clock, Odom, RobotDescription, RobotState, StateTruth
from common.messages.sim import SegmentationTruth as SegTruth
from common.messages.world import WorldDescription
from deploy.stack import ProcessStack
from tests.conftest import HOLD_COMMANDER, StartStack

pytestmark = pytest.mark.integration

SMALL = ['sim.world="small"', "sim.world_seed=1"]
NO_CAMERAS = ["sim.cameras=[]"]


def wait_clock(stack: object, t_s: float, timeout_s: float = 300.0) -> Clock:
    clock = stack.bus.latest(WORLD_CLOCK, Clock)  # type: ignore[attr-defined]
    return clock.wait(lambda c: c.stamp_ns >= round(t_s * 1e9), timeout_s)


def test_a_pd_hold_in_another_process_keeps_the_robot_standing(stack: StartStack) -> None:
    s = stack(["sim", "hold"], *HOLD_COMMANDER, *SMALL, *NO_CAMERAS, "sim.duration_s=11")
    odom = s.bus.fifo(s.keys.odom, Odom, maxlen=100_000)
    wait_clock(s, 10.0)
    samples = list(odom.drain())
    heights = np.array([o.base_position_in_world[2] for o in samples])
    # The sim may run ahead of this process's subscription (a loaded machine): what
    # counts is that the samples since then are all there and span seconds of standing.
    span_s = (samples[-1].stamp_ns - samples[0].stamp_ns) / 1e9 if samples else 0.0
    assert span_s >= 5.0, span_s
    assert len(samples) == round(span_s * 50) + 1  # 50 Hz, none lost
    assert np.all(np.abs(heights - robot.STAND_BASE_HEIGHT_M) < 0.02), (
        heights.min(),
        heights.max(),
    )


def _trajectory(seconds: float, tmp: str) -> tuple[np.ndarray, np.ndarray]:
    """Every state of a lockstep run from t = 0, with an asynchronous participant in the loop."""
    participants = [
        "time.participants={}",
        'time.participants.commander.role="command"',
        "time.participants.commander.period_s=0.001",
        "time.participants.commander.latency_s=0.0",
        'time.participants.wiggle.role="periodic"',
        "time.participants.wiggle.period_s=0.02",
        "time.participants.wiggle.latency_s=0.01",
    ]
    settings = [*SMALL, *NO_CAMERAS, *participants, f"sim.duration_s={seconds + 0.5}"]
    s = ProcessStack(
        [], parse_overrides([*settings, "recording.enabled=false", f'recording.dir="{tmp}"'])
    )
    try:
        s.spawn("router")
        # subscribe before anything runs, so the trajectory starts at t = 0
        states = s.bus.fifo(s.keys.state, RobotState, maxlen=1_000_000)
        truths = s.bus.fifo(s.keys.state_truth, StateTruth, maxlen=100_000)  # 50 Hz
        s.spawn("tests.integration.wiggle_commander")
        s.spawn("tests.integration.wiggle_participant")
        s.wait_ready(["commander", "wiggle"], 60)
        s.spawn("sim")
        wait_clock(s, seconds)
        # the clock can be read before the last states reach this subscriber (a loaded
        # machine): drain until the state stamped `seconds` is in, for at most 10 s
        got: dict[int, RobotState] = {}
        end, deadline = round(seconds * 1e9), time.monotonic() + 10.0
        while (not got or max(got) < end) and time.monotonic() < deadline:
            got.update({st.stamp_ns: st for st in states.drain()})
            time.sleep(0.05)
        bases = {b.stamp_ns: b.base_position_in_world for b in truths.drain()}
    finally:
        s.stop()
    stamps = sorted(t for t in got if t <= round(seconds * 1e9))
    q = np.array([as_numpy(got[t].q) for t in stamps])
    at = sorted(bases)  # the base's truth as of each state (its newest at or before)
    base = np.array([bases[at[max(np.searchsorted(at, t, "right") - 1, 0)]] for t in stamps])
    return np.array(stamps), np.hstack([q, base])


def test_the_same_seed_gives_the_same_trajectory_with_an_async_participant(
    tmp_path: Path,
) -> None:
    t1, x1 = _trajectory(2.0, str(tmp_path))
    t2, x2 = _trajectory(2.0, str(tmp_path))
    # A loaded machine may cost the test's own subscriber a few samples; the runs are
    # compared, bit for bit, at every stamp both received.
    both, i1, i2 = np.intersect1d(t1, t2, return_indices=True)
    assert t1[0] == 0 and t2[0] == 0 and len(both) > 1900, (len(t1), len(t2), len(both))
    differ = np.flatnonzero(np.any(x1[i1] != x2[i2], axis=1))
    assert differ.size == 0, f"trajectories part at t = {both[differ[0]] / 1e9:.3f} s"
    # the participant's feedback really moves the arm (the test could fail)
    joint1 = x1[:, 12]
    assert np.ptp(joint1) > 0.1


def _ray_box_depth(
    origins: np.ndarray, dirs: np.ndarray, centre: np.ndarray, half: np.ndarray, yaw: float
) -> np.ndarray:
    """Distance along each ray to an oriented box (inf where it misses): the slab method."""
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    o = (origins - centre) @ R
    d = dirs @ R
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - o) / d
        t2 = (half - o) / d
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((tmax >= tmin) & (tmax > 0), tmin, np.inf)


def test_camera_depth_matches_the_world_geometry(stack: StartStack) -> None:
    s = stack(
        ["sim", "hold"], *HOLD_COMMANDER, *SMALL, "sim.duration_s=3", 'sim.cameras=["camera_head"]',
        "sim.sensors.depth.enabled=false",  # the renderer's geometry, not the sensor's noise
    )  # fmt: skip
    frames = s.bus.latest(s.keys.camera_rgbd("camera_head"), CameraFrame, history=8)
    truths = s.bus.latest(s.keys.camera_segmentation_truth("camera_head"), SegTruth, history=8)
    bases = s.bus.latest(s.keys.state_truth, StateTruth, history=64)  # the frame has no pose
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10)
    frame = frames.wait(lambda f: f.stamp_ns >= 1_000_000_000, 120)
    truth = truths.wait(lambda t: t.stamp_ns >= frame.stamp_ns, 30)
    assert truth.stamp_ns == frame.stamp_ns
    depth = as_numpy(frame.depth).astype(float)
    labels = as_numpy(truth.labels)
    rgb = as_numpy(frame.rgb)
    assert rgb.std() > 5  # an image, not a blank

    base = bases.wait_stamp(frame.stamp_ns, 30) and bases.at(frame.stamp_ns)
    assert base is not None and base.stamp_ns == frame.stamp_ns
    T_wb = T_of_pose(base.base_position_in_world, base.base_orientation_xyzw)
    T_wc = T_wb @ np.array(frame.T_base_camera).reshape(4, 4)
    v, u = np.mgrid[0 : frame.height, 0 : frame.width]
    rays_cam = np.stack(
        [(u - frame.cx) / frame.fx, (v - frame.cy) / frame.fy, np.ones_like(u, dtype=float)], -1
    ).reshape(-1, 3)
    dirs = rays_cam @ T_wc[:3, :3].T
    origins = np.broadcast_to(T_wc[:3, 3], dirs.shape)
    z_along = 1.0  # depth is along the optical axis: the ray scale where camera z = 1

    # the floor: pixels with no instance whose ray goes down
    floor = (labels.reshape(-1) == 0) & (dirs[:, 2] < -1e-3) & (depth.reshape(-1) > 0)
    t_floor = -origins[floor, 2] / dirs[floor, 2]
    err_floor = np.abs(depth.reshape(-1)[floor] - t_floor * z_along)
    assert floor.sum() > 1000
    assert np.percentile(err_floor, 95) < 0.01, np.percentile(err_floor, 95)

    # a known box: every wall the camera sees
    seen = 0
    for ob in world.obstacles:
        if ob.kind != "wall":
            continue
        label = next((k for k, name in truth.instances.items() if name == ob.id), None)
        if label is None:
            continue
        mask = labels.reshape(-1) == label
        if mask.sum() < 200:
            continue
        t_box = _ray_box_depth(
            origins[mask], dirs[mask], np.array(ob.centre), np.array(ob.half_size), ob.yaw
        )
        err = np.abs(depth.reshape(-1)[mask] - t_box)
        assert np.percentile(err, 95) < 0.01, (ob.id, np.percentile(err, 95))
        seen += 1
    assert seen >= 1


def test_the_watchdog_holds_the_robot_when_the_controller_dies(stack: StartStack) -> None:
    s = stack(["sim", "hold"], *HOLD_COMMANDER, *SMALL, *NO_CAMERAS, "sim.duration_s=20")
    odom = s.bus.fifo(s.keys.odom, Odom, maxlen=100_000)
    wait_clock(s, 1.0)
    s.kill("hold")
    killed = wait_clock(s, 1.0).stamp_ns
    wait_clock(s, killed / 1e9 + 6.0)
    after = [o for o in odom.drain() if o.stamp_ns > killed + 100_000_000]
    window = [o for o in after if o.stamp_ns <= killed + 5_100_000_000]
    assert len(window) > 200
    assert all(o.watchdog for o in window)
    assert min(o.base_position_in_world[2] for o in window) > 0.35


def test_the_sim_describes_the_robot_and_the_world(stack: StartStack) -> None:
    s = stack(["sim"], *SMALL, "time.participants={}", "sim.duration_s=30")
    desc = s.bus.query(s.keys.description, None, RobotDescription, timeout_s=10)
    assert desc.joint_names == robot.JOINT_NAMES
    assert {c.name for c in desc.cameras} == {"camera_head", "camera_wrist"}
    assert desc.locomotion == "dynamic"
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10)
    assert world.name == "small"
    assert [a.id for a in world.artifacts] == ["bottle_1"]


def test_with_no_participant_the_watchdog_holds_and_says_so(stack: StartStack) -> None:
    s = stack(["sim"], *SMALL, *NO_CAMERAS, "time.participants={}", "sim.duration_s=5")
    state = s.bus.latest(s.keys.state, RobotState)
    st = state.wait(lambda m: m.stamp_ns > 100_000_000, 60)
    assert st.watchdog
    assert "no command" in st.watchdog_reason
