"""What the sim gives out: the robot's description, and everything stamped with sim time.

`SimOutputs.publish(t)` puts out, in this order, all stamped t (ns): the state (when the
commander answers it; every tick without one; with the WBC's truth ablation the base's
truth just before it), the base's truth (`state_truth`) at `sim.odom_hz` and `odom` with
it unless the WBC estimates the base (`Config.odom_from_estimate`), the lidar's scan at
its rate (`sim.sensors.lidar`), each camera's RGB-D frame at `sim.camera_hz` and its
truth segmentation (`sim.segmentation_truth`) (each rendered only for someone who looks:
a subscriber or the recording's kept frames), the people's truth (`world/people`) with
the scan for whoever listens, the recording's poses every 40 ms, and last the clock
(when due), so a participant woken by the clock finds its inputs as of t in (the WBC's
`odom`, when it estimates, comes after its tick: its consumers wait for the stamp).
`events` puts out a step's world events. The recording (rerun) is logged alongside.
Called from the sim's loop thread only.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from common import robot
from common.bus import Bus, Publisher
from common.config import Config
from common.keys import WORLD_CLOCK, WORLD_EVENTS, WORLD_PEOPLE, RobotKeys
from common.messages import to_wire
from common.messages.base import NS_PER_S
from common.messages.sim import (
    CameraFrame,
    CameraInfo,
    Clock,
    LaserScan,
    Odom,
    PeopleTruth,
    PersonTruth,
    RobotDescription,
    RobotState,
    SegmentationTruth,
    SimStats,
    StateTruth,
    WorldEvent,
    WorldEvents,
)
from common.messages.world import WorldDescription
from common.recording import FrameSelector, stamp
from common.sched import CpuLayout
from services.sim.cameras import CameraRig
from services.sim.core import SimCore
from services.sim.render_worker import RenderWorker, Shot
from services.sim.rerun_scene import SceneLogger
from services.sim.sensors import DepthNoise, Lidar
from services.sim.sim_log import SimLogger

#: The recording's body poses are logged this often, ns of sim time.
POSES_EVERY_NS = 40_000_000


def robot_description(config: Config, core: SimCore) -> RobotDescription:
    """`dume/<r>/description`: joints, limits, frames, cameras, tick rate and time mode."""
    cams = []
    w, h = config.sim.camera_width, config.sim.camera_height
    for name in config.sim.cameras:
        mount = CameraRig.mount(name, w, h)
        fx, fy, cx, cy = robot.intrinsics(mount)
        cams.append(
            CameraInfo(
                name=name,
                parent_frame=mount.parent_frame,
                T_parent_camera=tuple(float(x) for x in np.asarray(mount.T_parent_camera).ravel()),
                width=w,
                height=h,
                fx=fx,
                fy=fy,
                cx=cx,
                cy=cy,
                rate_hz=config.sim.camera_hz,
            )
        )
    return RobotDescription(
        robot=config.robot,
        joint_names=robot.JOINT_NAMES,
        lower=tuple(float(x) for x in robot.POSITION_LOWER),
        upper=tuple(float(x) for x in robot.POSITION_UPPER),
        velocity=tuple(float(x) for x in robot.VELOCITY_LIMITS),
        effort=tuple(float(x) for x in robot.TORQUE_LIMITS),
        frames=(robot.BASE_FRAME, *robot.FOOT_FRAMES, robot.TCP_FRAME, *robot.CAMERA_MOUNTS),
        cameras=tuple(cams),
        tick_hz=config.time.tick_hz,
        locomotion=core.locomotion,
        mode=config.time.mode,
    )


class SimOutputs:
    """The sim's publishers and recording, reading a `SimCore`; its cameras rendered by a
    `RenderWorker` (frames published from the render thread). `close()` when done."""

    def __init__(
        self,
        bus: Bus,
        keys: RobotKeys,
        config: Config,
        core: SimCore,
        world: WorldDescription,
        rec: rr.RecordingStream,
        cpus: CpuLayout | None = None,
    ) -> None:
        """`cpus`: the machine's layout; the cameras render on its `rest`."""
        cpus = cpus or CpuLayout()
        self.config = config
        self.core = core
        self.rec = rec
        cameras = config.sim.cameras
        self.clock = bus.publisher(WORLD_CLOCK, Clock, "control")
        #: Each robot-facing publisher's last sample, by key (`send_again`).
        self._sent: dict[str, tuple[Publisher[Any], Any]] = {}
        self.state = bus.publisher(keys.state, RobotState, "control")
        #: The free joint on `odom` only when nothing estimates it (the truth ablation,
        #: kinematic locomotion); otherwise the WBC publishes its estimate there.
        self.odom = (
            None if config.odom_from_estimate() else bus.publisher(keys.odom, Odom, "control")
        )
        self.state_truth = bus.publisher(keys.state_truth, StateTruth, "control")
        #: The WBC's truth ablation reads the base's truth beside every state it answers.
        self.truth_with_state = (
            config.wbc.base_state == "truth"
            and config.sim.locomotion == "dynamic"
            and "wbc" in config.time.participants
        )
        self.scan = bus.publisher(keys.scan, LaserScan, "data")
        self.scan_rear = bus.publisher(keys.scan_rear, LaserScan, "data")
        self.world_events = bus.publisher(WORLD_EVENTS, WorldEvents, "data")
        self.people_truth = bus.publisher(WORLD_PEOPLE, PeopleTruth, "data")
        self.sim_stats = bus.publisher(keys.sim_stats, SimStats, "data")
        self.rgbd = {c: bus.publisher(keys.camera_rgbd(c), CameraFrame, "bulk") for c in cameras}
        self.truth = {
            c: bus.publisher(keys.camera_segmentation_truth(c), SegmentationTruth, "bulk")
            for c in cameras
        }
        self.odom_period_ns = round(NS_PER_S / config.sim.odom_hz)
        self.camera_period_ns = round(NS_PER_S / config.sim.camera_hz)
        self.scene_log = SceneLogger(rec, core.model, groups={0, 1, 2})
        self.sim_log = SimLogger(rec, FrameSelector.of(config))
        s = config.sim
        noise = s.sensors.depth
        self.render = RenderWorker(
            core.model, s.camera_width, s.camera_height, world, self._put, cpus.rest,
            DepthNoise(noise, world.seed) if noise.enabled else None,
        )  # fmt: skip
        self.lidar_period_ns = round(NS_PER_S / s.sensors.lidar.rate_hz)
        self.T_base_lidar = {
            m.name: tuple(m.T_parent_lidar.ravel().tolist())
            for m in (robot.LIDAR_MOUNT, robot.LIDAR_REAR_MOUNT)
        }

    def begin(self, world: WorldDescription) -> None:
        """The recording at t = 0: the scene's geometry and the world's layout."""
        stamp(self.rec, 0)
        self.scene_log.log_geometry(self.core.data)
        self.sim_log.world(world)

    def publish(
        self, t_ns: int, tick: int, wall_rtf: float, *, state_due: bool, clock_due: bool
    ) -> None:
        """Everything stamped t: state (`state_due`), odom, cameras, then the clock
        (`clock_due`, with the wall real-time factor `wall_rtf`)."""
        # The state goes out when the commander answers it (every tick without one).
        state = truth = None
        if state_due:
            if self.truth_with_state:  # first: the WBC finds it in when the state comes
                truth = self.core.state_truth()
                self.state_truth.put(truth)
            state = self.core.robot_state(tick)
            self._send(self.state, state)
        if t_ns % self.odom_period_ns == 0:
            if self.odom is not None:
                self._send(self.odom, self.core.odom())
            if truth is None:
                truth = self.core.state_truth()
                self.state_truth.put(truth)
        if t_ns % self.lidar_period_ns == 0:
            self._send(self.scan, self._scan(t_ns, self.core.lidar))
            if self.core.lidar_rear is not None:
                self._send(self.scan_rear, self._scan(t_ns, self.core.lidar_rear))
            if self.people_truth.has_subscribers():
                self.people_truth.put(self._people(t_ns))
            if self.sim_log.enabled:
                state = state or self.core.robot_state(tick)
                self.sim_log.state(t_ns, state, truth or self.core.state_truth())
        if t_ns % self.camera_period_ns == 0:
            self.render.submit(t_ns, self.core.data, self._shots(t_ns))
        if t_ns % POSES_EVERY_NS == 0:
            stamp(self.rec, t_ns)
            self.scene_log.log_poses(self.core.data)
        # The clock goes last: a participant woken by it finds its inputs as of t in.
        if clock_due:
            self._send(
                self.clock,
                Clock(stamp_ns=t_ns, tick=tick, mode=self.config.time.mode, rtf=wall_rtf),
            )

    def _send(self, publisher: Publisher[Any], msg: Any) -> None:
        """Put `msg`, kept as the publisher's last sample (`send_again`)."""
        publisher.put(msg)
        self._sent[publisher.key] = (publisher, msg)

    def send_again(self) -> None:
        """What the participants wait for, once more: the last state, odometry, scans and
        camera frames, then the last clock (the link was down when they went;
        `common.lockstep.SimGate`)."""
        sent = dict(self._sent)  # the render thread adds frames meanwhile
        clock = sent.pop(self.clock.key, None)
        for publisher, msg in [*sent.values(), *([clock] if clock else [])]:
            publisher.put(msg)

    def _people(self, t_ns: int) -> PeopleTruth:
        people = self.core.people
        out = []
        for pid in people.ids:
            x, y, yaw = people.pose(pid)
            out.append(PersonTruth(id=pid, position=(x, y), yaw=yaw,
                                   velocity=people.velocity(pid)))  # fmt: skip
        return PeopleTruth(stamp_ns=t_ns, people=out)

    def _scan(self, t_ns: int, lidar: Lidar) -> LaserScan:
        ranges = lidar.scan(self.core.data)
        if self.sim_log.enabled:
            T_world_lidar = lidar.T_world_lidar(self.core.data)
            self.sim_log.scan(t_ns, lidar.angles, ranges, T_world_lidar, lidar.mount.name)
        return LaserScan(
            stamp_ns=t_ns,
            angle_min=float(lidar.angles[0]),
            angle_increment=lidar.angle_increment,
            range_min=lidar.s.range_min_m,
            range_max=lidar.s.range_max_m,
            ranges=to_wire(ranges),
            T_base_lidar=self.T_base_lidar[lidar.mount.name],
        )

    def _shots(self, t_ns: int) -> list[Shot]:
        """The cameras to render at t: only for someone who looks (a subscriber, the
        recording's kept frames); with labels for a subscriber to them or a dense frame."""
        shots = []
        for cam in self.config.sim.cameras:
            truth_pub = self.truth[cam]
            labels = (
                self.config.sim.segmentation_truth and truth_pub.has_subscribers()
            ) or self.sim_log.keeps_dense(t_ns)
            if labels or self.sim_log.keeps(t_ns) or self.rgbd[cam].has_subscribers():
                shots.append(Shot(cam, labels))
        return shots

    def _put(self, frame: CameraFrame, truth: SegmentationTruth | None) -> None:
        """A rendered frame out (on the render thread)."""
        self._send(self.rgbd[frame.camera], frame)
        if truth is not None and self.config.sim.segmentation_truth:
            self.truth[frame.camera].put(truth)
        self.sim_log.camera(frame.stamp_ns, frame, truth)

    def close(self) -> None:
        """Render and publish what is waiting; stop the render thread."""
        self.render.close()

    def stats(
        self, t_ns: int, ticks: int, wall_s: float, step_s: float, publish_s: float,
        waited_s: dict[str, float], stalls: int,
    ) -> None:  # fmt: skip
        """Where the wall time went so far (`SimStats`; rendering on its own thread)."""
        self.sim_stats.put(
            SimStats(
                stamp_ns=t_ns, ticks=ticks, wall_s=wall_s, step_s=step_s,
                render_s=self.render.render_s, captures=self.render.captures,
                publish_s=publish_s, waited_s=dict(waited_s), stalls=stalls,
            )
        )  # fmt: skip

    def events(self, stamp_ns: int, events: list[WorldEvent]) -> None:
        """A step's world events (none: nothing goes out), stamped at the new time."""
        if events:
            self.world_events.put(WorldEvents(stamp_ns=stamp_ns, events=events))
            self.sim_log.events(stamp_ns, events)
