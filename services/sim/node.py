"""The sim service: the world on Zenoh, in lockstep or in real time.

Each 1 kHz tick at sim time t: wait until every live periodic participant has acked the
ticks whose outputs take effect by t (`AckGate`); publish the clock (when due), the
state, odom at 50 Hz and the cameras at 10 Hz, all stamped t; in lockstep, wait for the
command participant's answer to this state (stamp t), in realtime take the newest
command; then step the physics to t + 1 ms and publish the tick's world events. A
participant whose liveliness goes is no longer waited for (the sim's watchdog then holds
the joints, as a robot's would); one that stalls past `time.stall_timeout_s` is logged and
skipped until it answers again.

The physics, people, handover and events live in `SimCore`; the cameras in `CameraRig`;
this module only moves messages and keeps time. A `Push` on `dume/world/push` (tests and
evaluation) is applied at the step of its stamp, so a lockstep run with a push is as
repeatable as one without; so is a `PersonCommand` on `dume/world/people_command`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from common import keys as K
from common import robot
from common.bus import Fifo, Latest, Publisher
from common.lockstep import AckGate
from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.sim import (
    Ack,
    CameraFrame,
    CameraInfo,
    Clock,
    JointCommand,
    Odom,
    Push,
    RobotDescription,
    RobotState,
    SegmentationTruth,
    WorldEvents,
)
from common.messages.wbc import CmdVel
from common.messages.world import WorldDescription
from common.recording import default_blueprint, stamp
from common.service import Service
from services.sim.cameras import CameraRig
from services.sim.core import CommandError, PushError, SimCore
from services.sim.people_hook import PeopleHook
from services.sim.rerun_scene import SceneLogger
from services.sim.sim_log import SimLogger
from services.sim.world import generate_world

#: Publish the clock at least this often (ns) for services that only watch time.
CLOCK_EVERY_NS = 10_000_000


@dataclass
class _Io:
    clock: Publisher[Clock]
    state: Publisher[RobotState]
    odom: Publisher[Odom]
    events: Publisher[WorldEvents]
    rgbd: dict[str, Publisher[CameraFrame]]
    truth: dict[str, Publisher[SegmentationTruth]]
    commands: Fifo[JointCommand]
    acks: Fifo[Ack]
    cmd_vel: Latest[CmdVel]
    pushes: Fifo[Push]


@dataclass
class _Stats:
    ticks: int = 0
    commands: int = 0
    rejected: int = 0
    stalls: int = 0
    pushes: int = 0
    wall_start: float = field(default_factory=time.perf_counter)


def robot_description(svc: Service, core: SimCore, rig: CameraRig) -> RobotDescription:
    cams = []
    for name in svc.config.sim.cameras:
        mount = robot.CAMERA_MOUNTS[name]
        fx, fy, cx, cy = rig.intrinsics(name)
        cams.append(
            CameraInfo(
                name=name,
                parent_frame=mount.parent_frame,
                T_parent_camera=tuple(float(x) for x in np.asarray(mount.T_parent_camera).ravel()),
                width=rig.width,
                height=rig.height,
                fx=fx,
                fy=fy,
                cx=cx,
                cy=cy,
                rate_hz=svc.config.sim.camera_hz,
            )
        )
    return RobotDescription(
        robot=svc.config.robot,
        joint_names=robot.JOINT_NAMES,
        lower=tuple(float(x) for x in robot.POSITION_LOWER),
        upper=tuple(float(x) for x in robot.POSITION_UPPER),
        velocity=tuple(float(x) for x in robot.VELOCITY_LIMITS),
        effort=tuple(float(x) for x in robot.TORQUE_LIMITS),
        frames=(robot.BASE_FRAME, *robot.FOOT_FRAMES, robot.TCP_FRAME, *robot.CAMERA_MOUNTS),
        cameras=tuple(cams),
        tick_hz=svc.config.time.tick_hz,
        locomotion=core.locomotion,
        mode=svc.config.time.mode,
    )


class SimNode:
    """The sim's loop: time, messages and logging around a `SimCore`."""

    def __init__(self, svc: Service, world: WorldDescription) -> None:
        self.svc = svc
        cfg = svc.config
        self.world = world
        self.core = SimCore(
            world,
            locomotion=cfg.sim.locomotion,
            watchdog_ms=cfg.sim.watchdog_ms,
            walking_people=cfg.sim.walking_people,
        )
        self.rig = CameraRig(
            self.core.model, cfg.sim.camera_width, cfg.sim.camera_height, world=world
        )
        self.tick_ns = round(NS_PER_S / cfg.time.tick_hz)
        self.gate = AckGate(cfg.time.participants, self.tick_ns)
        commanders = [n for n, p in cfg.time.participants.items() if p.role == "command"]
        if len(commanders) > 1:
            raise ValueError(f"at most one command participant, got {commanders}")
        self.commander = commanders[0] if commanders else None
        self.command_period_ns = (
            round(cfg.time.participants[self.commander].period_s * NS_PER_S)
            if self.commander
            else self.tick_ns
        )
        self.odom_period_ns = round(NS_PER_S / cfg.sim.odom_hz)
        self.camera_period_ns = round(NS_PER_S / cfg.sim.camera_hz)
        self.stats = _Stats()
        self.duration_ns = round(cfg.sim.duration_s * NS_PER_S)
        bus, keys = svc.bus, svc.keys
        self.io = _Io(
            clock=bus.publisher(K.WORLD_CLOCK, Clock, "control"),
            state=bus.publisher(keys.state, RobotState, "control"),
            odom=bus.publisher(keys.odom, Odom, "control"),
            events=bus.publisher(K.WORLD_EVENTS, WorldEvents, "data"),
            rgbd={
                c: bus.publisher(keys.camera_rgbd(c), CameraFrame, "bulk") for c in cfg.sim.cameras
            },
            truth={
                c: bus.publisher(keys.camera_segmentation_truth(c), SegmentationTruth, "bulk")
                for c in cfg.sim.cameras
            },
            commands=bus.fifo(keys.command, JointCommand, maxlen=256),
            acks=bus.fifo(keys.ack_all, Ack, maxlen=4096),
            cmd_vel=bus.latest(keys.cmd_vel, CmdVel, history=64),
            pushes=bus.fifo(K.WORLD_PUSH, Push, maxlen=64),
        )
        self._pending_pushes: list[Push] = []
        self.people_hook = PeopleHook(bus, svc.log)
        self.alive = bus.watch_alive(keys.alive_all)
        self._alive_names: set[str] = set()
        self._alive_version = -1
        self.description = robot_description(svc, self.core, self.rig)
        bus.serve(keys.description, None, lambda _req, _sel: self.description)
        bus.serve(K.WORLD_DESCRIPTION, None, lambda _req, _sel: self.world)
        self.scene_log = SceneLogger(svc.rec, self.core.model, groups={0, 1, 2})
        self.sim_log = SimLogger(
            svc.rec, cfg.sim.cameras, cfg.recording.camera_every, cfg.recording.depth_every
        )

    # -- participants -------------------------------------------------------------------

    def _refresh_alive(self, t_ns: int) -> None:
        if self.alive.version == self._alive_version:
            return
        self._alive_version = self.alive.version
        names = {K.service_of_alive_key(k) for k in self.alive.alive()}
        for name in sorted(names - self._alive_names):
            self.svc.log.info("%s is alive at t=%.3f s", name, t_ns / NS_PER_S)
            self.gate.join(name, t_ns)
        for name in sorted(self._alive_names - names):
            self.svc.log.warning(
                "%s is gone at t=%.3f s: no longer waited for", name, t_ns / NS_PER_S
            )
            self.gate.leave(name)
        self._alive_names = names

    def _drain_acks(self, t_ns: int) -> None:
        for ack in self.io.acks.drain():
            stalled = ack.service in self.gate.schedules and ack.service not in self.gate.alive
            if stalled and ack.service in self._alive_names:  # a stalled participant is back
                self.svc.log.info("%s answers again", ack.service)
                self.gate.join(ack.service, t_ns)
            self.gate.ack(ack.service, ack.stamp_ns)

    def _wait_acks(self, t_ns: int) -> None:
        deadline = time.perf_counter() + self.svc.config.time.stall_timeout_s
        while True:
            self._drain_acks(t_ns)
            blocking = self.gate.blocking(t_ns)
            if not blocking or self.svc.stopping:
                return
            if time.perf_counter() > deadline:
                for name in blocking:
                    self.svc.log.error(
                        "%s stalled: no ack for t=%.3f s within %.1f s; stepping without it",
                        name,
                        t_ns / NS_PER_S,
                        self.svc.config.time.stall_timeout_s,
                    )
                    self.gate.leave(name)
                    self.stats.stalls += 1
                return
            self.io.acks.wait(timeout_s=0.05)  # wakes on the next ack
            self._refresh_alive(t_ns)

    def _wait_command(self, t_ns: int) -> JointCommand | None:
        """The command answering the state at t (lockstep), or None if none is due/alive."""
        if self.commander is None or t_ns % self.command_period_ns:
            return None
        deadline = time.perf_counter() + self.svc.config.time.stall_timeout_s
        while self.commander in self._alive_names and not self.svc.stopping:
            cmd = self.io.commands.pop(timeout_s=0.05)
            if cmd is not None:
                if cmd.stamp_ns == t_ns:
                    return cmd
                continue  # an answer to an older state: superseded
            if time.perf_counter() > deadline:
                self.svc.log.error("%s stalled at t=%.3f s", self.commander, t_ns / NS_PER_S)
                self.stats.stalls += 1
                return None
            self._refresh_alive(t_ns)
        return None

    def _apply(self, cmd: JointCommand | None) -> None:
        if cmd is None:
            return
        try:
            self.core.command(
                as_numpy(cmd.tau_ff),
                as_numpy(cmd.q_des),
                as_numpy(cmd.v_des),
                as_numpy(cmd.kp),
                as_numpy(cmd.kd),
                cmd.stamp_ns,
            )
            self.stats.commands += 1
        except (CommandError, ValueError) as exc:
            self.stats.rejected += 1
            self.svc.log.warning("command rejected at t=%.3f s: %s", cmd.stamp_ns / NS_PER_S, exc)

    def _apply_cmd_vel(self, t_ns: int) -> None:
        if self.core.locomotion != "kinematic":
            return
        msg = self.io.cmd_vel.at(t_ns)
        timeout_ns = round(self.svc.config.wbc.cmd_vel_timeout_s * NS_PER_S)  # as the WBC's
        fresh = msg is not None and t_ns - msg.stamp_ns <= timeout_ns
        if msg is not None and fresh:
            self.core.set_cmd_vel(msg.vx, msg.vy, msg.wz)
        else:
            self.core.set_cmd_vel(0.0, 0.0, 0.0)

    def _apply_pushes(self, t_ns: int) -> None:
        """Start the pushes stamped at or before t (a late one at once, with a warning)."""
        self._pending_pushes.extend(self.io.pushes.drain())
        if not self._pending_pushes:
            return
        due = [p for p in self._pending_pushes if p.stamp_ns <= t_ns]
        self._pending_pushes = [p for p in self._pending_pushes if p.stamp_ns > t_ns]
        for push in due:
            late_ms = (t_ns - push.stamp_ns) / 1e6
            try:
                steps = self.core.push(push.force_in_world, push.duration_s)
            except PushError as exc:
                self.svc.log.warning("push refused at t=%.3f s: %s", t_ns / NS_PER_S, exc)
                continue
            self.stats.pushes += 1
            self.svc.log.info(
                "push %s N for %d steps on the base at t=%.3f s%s",
                [round(f, 1) for f in push.force_in_world],
                steps,
                t_ns / NS_PER_S,
                f" ({late_ms:.0f} ms late: it arrived after its stamp)" if late_ms > 0 else "",
            )

    # -- the loop -------------------------------------------------------------------------

    def _publish(self, t_ns: int, tick: int, wall_rtf: float) -> None:
        """Everything stamped t: state, odom, cameras, then the clock."""
        # The state goes out when the commander answers it (every tick without one).
        state = None
        if t_ns % self.command_period_ns == 0:
            state = self.core.robot_state(tick)
            self.io.state.put(state)
        if t_ns % self.odom_period_ns == 0:
            self.io.odom.put(self.core.odom())
            if self.sim_log.enabled:
                self.sim_log.state(t_ns, state or self.core.robot_state(tick))
        if t_ns % self.camera_period_ns == 0:
            for cam in self.svc.config.sim.cameras:
                # Rendering is the sim's dearest work: only for someone who looks.
                rgbd, truth_pub = self.io.rgbd[cam], self.io.truth[cam]
                if not (
                    self.sim_log.enabled or rgbd.has_subscribers() or truth_pub.has_subscribers()
                ):
                    continue
                frame, truth = self.rig.capture(self.core.data, cam, t_ns)
                self.io.rgbd[cam].put(frame)
                if self.svc.config.sim.segmentation_truth:
                    self.io.truth[cam].put(truth)
                self.sim_log.camera(t_ns, frame, truth)
        if t_ns % 40_000_000 == 0:
            stamp(self.svc.rec, t_ns)
            self.scene_log.log_poses(self.core.data)
        # The clock goes last: a participant woken by it finds its inputs as of t in.
        if self.gate.clock_due(t_ns, CLOCK_EVERY_NS):
            self.io.clock.put(
                Clock(stamp_ns=t_ns, tick=tick, mode=self.svc.config.time.mode, rtf=wall_rtf)
            )

    def run(self) -> None:
        svc, cfg = self.svc, self.svc.config
        lockstep = cfg.time.mode == "lockstep"
        stamp(svc.rec, 0)
        self.scene_log.log_geometry(self.core.data)
        self.sim_log.world(self.world)
        svc.ready()
        if lockstep and cfg.time.participants:
            wanted = {svc.keys.alive(n) for n in cfg.time.participants}
            svc.log.info("lockstep: waiting for %s", sorted(cfg.time.participants))
            try:
                self.alive.wait_for(wanted, cfg.time.start_timeout_s)
            except Exception as exc:
                svc.log.error("starting without every participant: %s", exc)
        svc.log.info(
            "running %s world seed %d, %s, %s locomotion",
            self.world.name,
            self.world.seed,
            cfg.time.mode,
            self.core.locomotion,
        )
        wall0 = time.perf_counter()
        rtf_mark = (wall0, 0)
        rtf = 0.0
        tick = 0
        while not svc.stopping and (
            self.duration_ns == 0 or tick * self.tick_ns < self.duration_ns
        ):
            t_ns = tick * self.tick_ns
            self._refresh_alive(t_ns)
            if lockstep:
                self._wait_acks(t_ns)
            else:
                self._pace(wall0, t_ns)
                self._drain_acks(t_ns)
            self._publish(t_ns, tick, rtf)
            if lockstep:
                self._apply(self._wait_command(t_ns))
            else:
                latest = None
                for latest in self.io.commands.drain():  # noqa: B007 - newest wins
                    pass
                self._apply(latest)
            self._apply_cmd_vel(t_ns)
            self._apply_pushes(t_ns)
            self.people_hook.apply(t_ns, self.core.people)
            events = self.core.step()
            tick += 1
            if events:
                self.io.events.put(WorldEvents(stamp_ns=tick * self.tick_ns, events=events))
                self.sim_log.events(tick * self.tick_ns, events)
            if tick % 1000 == 0:
                now = time.perf_counter()
                sim_s = (tick - rtf_mark[1]) * self.tick_ns / NS_PER_S
                rtf = sim_s / max(now - rtf_mark[0], 1e-9)
                rtf_mark = (now, tick)
                self.sim_log.rtf(tick * self.tick_ns, rtf)
        self.stats.ticks = tick
        wall = time.perf_counter() - wall0
        svc.log.info(
            "stopped at t=%.3f s after %.1f s wall (rtf %.2f): %d commands, %d rejected, "
            "%d stalls, %d pushes",
            tick * self.tick_ns / NS_PER_S,
            wall,
            tick * self.tick_ns / NS_PER_S / max(wall, 1e-9),
            self.stats.commands,
            self.stats.rejected,
            self.stats.stalls,
            self.stats.pushes,
        )

    def _pace(self, wall0: float, t_ns: int) -> None:
        ahead = wall0 + t_ns / NS_PER_S - time.perf_counter()
        if ahead > 0:
            self.svc.stop.wait(ahead)


def main(svc: Service) -> None:
    cfg = svc.config.sim
    world = generate_world(cfg.world_seed, cfg.world, walking_people=cfg.walking_people)
    if svc.config.recording.enabled:
        svc.rec.send_blueprint(default_blueprint(tuple(cfg.cameras)))
    SimNode(svc, world).run()
