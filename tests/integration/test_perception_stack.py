"""Perception as a service: sim + wbc + perception over Zenoh in lockstep, small world.

The `truth` segmenter stands in for the network where a test is about geometry and
transport, not segmentation (named so in every `Detections`). Truth for the geometry is
the sim's world description (the bottle's axis) and, for the visible centroid, the truth
mask's points.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Generator

import numpy as np
import pytest

from bench.trial_driver import Driver, trial_settings
from common.bus import Fifo, RemoteError
from common.camera import backproject
from common.geometry import transform_points, wrap_angle
from common.keys import WORLD_DESCRIPTION
from common.messages import as_numpy
from common.messages.perception import Detection, Detections, LocateReply, LocateRequest
from common.messages.sim import CameraFrame, SegmentationTruth
from common.messages.wbc import Posture
from common.messages.world import Artifact, WorldDescription
from common.robot import STANDOFF_DISTANCE_M
from deploy.stack import ProcessStack
from services.perception.pipeline import frame_geometry
from services.sim.feasibility import standoff_pose_for
from tests.conftest import StartStack

pytestmark = pytest.mark.integration

PERCEPTION = (
    'time.participants.perception.role="periodic"',
    "time.participants.perception.period_s=0.1",
    "time.participants.perception.latency_s=0.1",
    'perception.segmenter="truth"',
)
STACK = (
    'sim.world="small"',
    "sim.world_seed=0",
    "time.participants={}",
    'time.participants.wbc.role="command"',
    "time.participants.wbc.period_s=0.002",
    "time.participants.wbc.latency_s=0.0",
    *PERCEPTION,
)


def _bottle(s: ProcessStack) -> Artifact:
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 10.0)
    return next(a for a in world.artifacts if a.id == "bottle_1")


def _horizontal(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def test_every_tick_has_detections_of_each_camera_and_the_head_camera_finds_bottle_1(
    stack: StartStack,
) -> None:
    s = stack(["sim", "wbc", "perception"], *STACK, "sim.duration_s=5")
    fifo = s.bus.fifo(s.keys.detections, Detections, maxlen=1000)
    bottle = _bottle(s)
    stamps: dict[str, list[int]] = defaultdict(list)
    head: list[Detections] = []
    while min((len(v) for v in stamps.values()), default=0) < 15 or len(stamps) < 2:
        msg = fifo.pop(timeout_s=120.0)
        assert msg is not None, f"no detections after {dict(stamps)}"
        stamps[msg.camera].append(msg.stamp_ns)
        assert msg.segmenter == "truth" and msg.reason == ""
        if msg.camera == "camera_head":
            head.append(msg)
    # the stack starts before this test subscribes: from the first frame it sees, every tick
    for cam in ("camera_head", "camera_wrist"):
        first = stamps[cam][0]
        assert first % 100_000_000 == 0
        assert stamps[cam][:15] == [first + k * 100_000_000 for k in range(15)]
    found = [d for m in head for d in m.detections if d.class_name == "bottle"]
    assert len(found) == len(head)  # seen in every frame from the start pose, 3.4 m away
    r = bottle.shape.radius  # type: ignore[union-attr]
    for d in found:
        # the visible surface is about a radius in front of the axis; the axis is on it
        assert _horizontal(d.centroid_in_world, bottle.position) < r + 0.01
        assert _horizontal(d.axis_in_world, bottle.position) < 0.02
        assert bottle.position[2] < d.centroid_in_world[2] < bottle.position[2] + 0.16


def test_locate_finds_the_bottle_and_refuses_malformed_queries_with_typed_errors(
    stack: StartStack,
) -> None:
    s = stack(["sim", "wbc", "perception"], *STACK, "sim.duration_s=1.5")
    latest = s.bus.latest(s.keys.detections, Detections)
    latest.wait(lambda m: m.stamp_ns >= 1_000_000_000, 120.0)
    key = s.keys.locate
    reply = s.bus.query(key, LocateRequest(class_name="bottle", max_age_s=5.0), LocateReply)
    assert reply.found and reply.detection is not None
    assert reply.detection.class_name == "bottle" and reply.camera in (
        "camera_head",
        "camera_wrist",
    )
    none = s.bus.query(key, LocateRequest(class_name="can", max_age_s=5.0), LocateReply)
    assert not none.found and none.detection is None
    bad = [
        ({"class_name": 3}, "malformed"),
        ({"class_name": "bottle", "colour": "green"}, "malformed"),
        (LocateRequest(), "invalid"),
        (LocateRequest(class_name="bottle", map_id="bottle_1"), "invalid"),
        (LocateRequest(class_name="chair"), "invalid"),
        (LocateRequest(class_name="bottle", camera="camera_tail"), "invalid"),
        (LocateRequest(class_name="bottle", max_age_s=0.0), "invalid"),
        (LocateRequest(map_id="bottle_1"), "unavailable"),  # no semantic map in this stack
    ]
    for request, code in bad:
        with pytest.raises(RemoteError) as refused:
            s.bus.query(key, request, LocateReply)
        assert refused.value.error.code == code, (request, refused.value.error)
    again = s.bus.query(key, LocateRequest(class_name="bottle", max_age_s=5.0), LocateReply)
    assert again.found  # still serving


def test_without_its_model_the_network_segmenter_publishes_empty_detections_saying_why(
    stack: StartStack,
) -> None:
    settings = [x for x in STACK if not x.startswith("perception.segmenter")]
    s = stack(
        ["sim", "wbc", "perception"],
        *settings,
        'perception.model="services/perception/models/absent.onnx"',
        "sim.duration_s=1",
    )
    latest = s.bus.latest(s.keys.detections, Detections)
    msg = latest.wait(lambda m: m.stamp_ns >= 500_000_000, 120.0)
    assert msg.segmenter == "network" and msg.detections == []
    assert "absent.onnx not found" in msg.reason
    with pytest.raises(RemoteError) as refused:
        s.bus.query(s.keys.locate, LocateRequest(class_name="bottle"), LocateReply)
    assert refused.value.error.code == "unavailable"


def _next_of(fifo: Fifo[Detections], camera: str, stamp_ns: int) -> Detections:
    """The first `Detections` of `camera` stamped at or after `stamp_ns`."""
    while True:
        msg = fifo.pop(timeout_s=60.0)
        assert msg is not None, f"no {camera} detections stamped {stamp_ns} ns"
        if msg.camera == camera and msg.stamp_ns >= stamp_ns:
            return msg


def _approach(d: Driver, xy: np.ndarray, yaw: float, timeout_s: float) -> Generator[None]:
    """Trot to (x, y, yaw) on a free straight line: face the goal, walk, turn, settle."""
    d.mode("walk")
    yield from d.wait(0.5)
    end = d.t + timeout_s
    while d.t < end:
        p, now = d.base()
        e = xy - p
        dist = float(np.linalg.norm(e))
        heading = math.atan2(e[1], e[0]) if dist > 0.15 else yaw
        e_yaw = wrap_angle(heading - now)
        if dist < 0.03 and abs(wrap_angle(yaw - now)) < 0.03:
            break
        c, s = math.cos(now), math.sin(now)
        ex, ey = c * e[0] + s * e[1], -s * e[0] + c * e[1]
        walk = dist > 0.15 and abs(e_yaw) < 0.3
        vx = float(np.clip(0.8 * ex, -0.3, 0.3)) if walk or dist <= 0.15 else 0.0
        vy = float(np.clip(0.8 * ey, -0.1, 0.1)) if dist <= 0.15 else 0.0
        d.cmd(vx, vy, float(np.clip(1.2 * e_yaw, -0.4, 0.4)))
        yield
    d.cmd(0.0)
    yield from d.wait(1.0)


@pytest.mark.slow
def test_the_wrist_camera_in_look_at_the_standoff_measures_bottle_1_within_tolerance(
    stack: StartStack,
) -> None:
    s = stack(
        ["sim", "wbc", "perception"],
        trial_settings("small", 1, 0.002),  # seed 1: the standoff is straight ahead
        'sim.cameras=["camera_head", "camera_wrist"]',
        *PERCEPTION,
    )
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 10.0)
    bottle = next(a for a in world.artifacts if a.id == "bottle_1")
    surface = next(x for x in world.surfaces if x.id == bottle.surface_id)
    pose = standoff_pose_for(bottle, surface, STANDOFF_DISTANCE_M)
    frames = s.bus.latest(s.keys.camera_rgbd("camera_wrist"), CameraFrame, history=8)
    truths = s.bus.latest(s.keys.camera_segmentation_truth("camera_wrist"), SegmentationTruth, 8)
    detections = s.bus.fifo(s.keys.detections, Detections, maxlen=10_000)
    d = Driver(s)
    d.start()
    seen: list[tuple[Detection, np.ndarray]] = []

    def script() -> Generator[None]:
        yield from _approach(d, np.array([pose.x, pose.y]), pose.yaw, 40.0)
        d.mode("manipulate")
        yield from d.wait(0.5)
        g = yield from d.finish(d.goal(Posture(name="look")), 8.0)
        assert g is not None and g.state == "succeeded", g
        yield from d.wait(0.5)
        for _ in range(3):  # three frames, 0.1 s apart
            stamp = d.t_ns - d.t_ns % 100_000_000
            det = _next_of(detections, "camera_wrist", stamp)
            frame, truth = frames.at(det.stamp_ns), truths.at(det.stamp_ns)
            assert frame is not None and truth is not None and det.stamp_ns == frame.stamp_ns
            label = next(k for k, v in truth.instances.items() if v == "bottle_1")
            mask = np.asarray(as_numpy(truth.labels)) == label
            geo = frame_geometry(frame, np.array(det.T_world_base).reshape(4, 4))
            pts = backproject(np.asarray(as_numpy(frame.depth)), geo.camera, mask=mask)
            T_world_camera = geo.T_world_base_yaw @ geo.T_base_yaw_camera
            visible = transform_points(T_world_camera, pts).mean(axis=0)
            seen.extend((x, visible) for x in det.detections if x.class_name == "bottle")
            yield from d.wait(0.1)

    d.run(script())
    assert not d.fell and len(seen) == 3
    for det, visible in seen:
        assert np.linalg.norm(np.array(det.centroid_in_world) - visible) < 0.01
        assert _horizontal(det.axis_in_world, bottle.position) < 0.02
        assert det.d_obj < 1.5
