"""The sim service: the world on Zenoh, in lockstep or in real time.

Each 1 kHz tick at sim time t (ns), on the service's main thread: take liveliness joins
and leaves; in lockstep wait until every live periodic participant has acked the ticks
whose outputs take effect by t, in realtime sleep until the wall clock reaches t; publish
everything stamped t (`SimOutputs`: the state, odom at 50 Hz, the cameras at 10 Hz, then
the clock when due); take the command to step with (in lockstep the command participant's
answer to the state at t, in realtime the newest); apply it, the kinematic base's
cmd_vel, and the pushes, people and artifact commands due at t; step the physics to
t + 1 ms and publish the step's world events (an artifact moved by its hook among them);
every `ARTIFACTS_EVERY_TICKS` take the artifacts' poses for `dume/world/artifacts` (truth).
The protocol's waits (the start gate, acks, commands, stalls, liveliness) are
`common.lockstep.SimGate`'s; the physics, people, handover and events `SimCore`'s; the
cameras are rendered beside the loop, from a snapshot of tick t (`RenderWorker`); this
module wires them and keeps time.
"""

from __future__ import annotations

import time

from common import keys as K
from common.lockstep import SimGate
from common.messages.base import NS_PER_S
from common.messages.sim import Ack, ArtifactsTruth, JointCommand
from common.messages.world import WorldDescription
from common.recording import default_blueprint
from common.service import Service
from services.sim.artifact_hook import ArtifactHook, MovableHook
from services.sim.core import SimCore
from services.sim.intake import CommandIntake
from services.sim.outputs import SimOutputs, robot_description
from services.sim.people_hook import PeopleHook
from services.sim.push_hook import PushHook
from services.sim.world import generate_world

#: The artifacts' truth snapshot (`dume/world/artifacts`) is taken every this many ticks.
ARTIFACTS_EVERY_TICKS = 100


class SimNode:
    """The sim's loop: a `SimCore` stepped through the `SimGate`, between its inputs and
    its `SimOutputs`. `run()` blocks until the service stops or `sim.duration_s` (sim
    time; 0: forever) is reached."""

    def __init__(self, svc: Service, world: WorldDescription) -> None:
        self.svc = svc
        cfg = svc.config
        self.world = world
        self.core = SimCore(
            world,
            locomotion=cfg.sim.locomotion,
            watchdog_ms=cfg.sim.watchdog_ms,
            walking_people=cfg.sim.walking_people,
            bystanders=cfg.sim.bystanders,
            sensors=cfg.sim.sensors,
        )
        self.duration_ns = round(cfg.sim.duration_s * NS_PER_S)
        bus, keys = svc.bus, svc.keys
        # Declared in this order: the publishers, then the commands, acks, cmd_vel, pushes,
        # people commands and liveliness.
        self.out = SimOutputs(bus, keys, cfg, self.core, world, svc.rec, svc.cpus)
        commands = bus.fifo(keys.command, JointCommand, maxlen=256)
        # A subscriber on each participant's own ack key, not one on `ack/*`: under the
        # router's ACL a participant hears only of subscribers on keys it may put, and a
        # Zenoh publisher that hears of none sends nothing (lockstep was lost so).
        periodic = sorted(n for n, p in cfg.time.participants.items() if p.role == "periodic")
        acks = bus.fifo(tuple(keys.ack(n) for n in periodic), Ack, maxlen=4096)
        self.intake = CommandIntake(bus, keys, self.core, cfg.wbc.cmd_vel_timeout_s, svc.log)
        self.push_hook = PushHook(bus, svc.log)
        self.people_hook = PeopleHook(bus, svc.log)
        self.artifact_hook = ArtifactHook(bus, svc.log)
        self.movable_hook = MovableHook(bus, svc.log)
        self.gate = SimGate(
            cfg.time,
            alive=bus.watch_alive(keys.alive_all),
            acks=acks,
            commands=commands,
            alive_key=keys.alive,
            stop=svc.stop,
            log=svc.log,
            on_back=lambda: self.out.send_again(),
        )
        self.tick_ns = self.gate.tick_ns
        self.description = robot_description(cfg, self.core)
        bus.serve(keys.description, None, lambda _req, _sel: self.description)
        bus.serve(K.WORLD_DESCRIPTION, None, lambda _req, _sel: self.world)
        #: The artifacts where they are (truth), snapshot on the loop's thread: a query
        #: answers from Zenoh's while the physics steps.
        self.artifacts = ArtifactsTruth(stamp_ns=0, artifacts=self.core.artifact_poses())
        bus.serve(K.WORLD_ARTIFACTS, None, lambda _req, _sel: self.artifacts)

    def run(self) -> None:
        svc, cfg, gate = self.svc, self.svc.config, self.gate
        self.out.begin(self.world)
        svc.ready()
        gate.start()
        svc.log.info(
            "running %s world seed %d, %s, %s locomotion",
            self.world.name,
            self.world.seed,
            cfg.time.mode,
            self.core.locomotion,
        )
        wall0 = time.perf_counter()
        rtf_mark = (wall0, 0)
        rtf = step_s = publish_s = 0.0
        tick = 0
        while not svc.stopping and (
            self.duration_ns == 0 or tick * self.tick_ns < self.duration_ns
        ):
            t_ns = tick * self.tick_ns
            gate.refresh(t_ns)
            if gate.lockstep:
                gate.wait_acks(t_ns)
            else:
                self._pace(wall0, t_ns)
                gate.drain_acks(t_ns)
            t0 = time.perf_counter()
            self.out.publish(
                t_ns, tick, rtf, state_due=gate.state_due(t_ns), clock_due=gate.clock_due(t_ns)
            )
            t1 = time.perf_counter()
            self.intake.apply(gate.command(t_ns))
            self.intake.apply_cmd_vel(t_ns)
            self.push_hook.apply(t_ns, self.core)
            self.people_hook.apply(t_ns, self.core.people)
            moved = self.artifact_hook.apply(t_ns, self.core)
            left = self.movable_hook.apply(t_ns, self.core)
            t2 = time.perf_counter()
            events = self.core.step()
            if moved or left:
                events = [*moved, *left, *events]
            now = time.perf_counter()
            publish_s += t1 - t0
            step_s += now - t2
            tick += 1
            self.out.events(tick * self.tick_ns, events)
            if tick % ARTIFACTS_EVERY_TICKS == 0:
                self.artifacts = ArtifactsTruth(
                    stamp_ns=tick * self.tick_ns, artifacts=self.core.artifact_poses()
                )
            if tick % 1000 == 0:
                sim_s = (tick - rtf_mark[1]) * self.tick_ns / NS_PER_S
                rtf = sim_s / max(now - rtf_mark[0], 1e-9)
                rtf_mark = (now, tick)
                self.out.sim_log.rtf(tick * self.tick_ns, rtf)
                self.out.stats(
                    tick * self.tick_ns, tick, now - wall0, step_s, publish_s, gate.waited_s,
                    gate.stalls,
                )  # fmt: skip
        self.out.close()
        wall = time.perf_counter() - wall0
        svc.log.info(
            "stopped at t=%.3f s after %.1f s wall (rtf %.2f): %d commands, %d rejected, "
            "%d stalls, %d pushes",
            tick * self.tick_ns / NS_PER_S,
            wall,
            tick * self.tick_ns / NS_PER_S / max(wall, 1e-9),
            self.intake.commands,
            self.intake.rejected,
            gate.stalls,
            self.push_hook.applied,
        )

    def _pace(self, wall0: float, t_ns: int) -> None:
        """Realtime: sleep until the wall clock reaches sim time t (or the service stops)."""
        ahead = wall0 + t_ns / NS_PER_S - time.perf_counter()
        if ahead > 0:
            self.svc.stop.wait(ahead)


def main(svc: Service) -> None:
    cfg = svc.config.sim
    world = generate_world(cfg.world_seed, cfg.world, walking_people=cfg.walking_people)
    if svc.config.recording.enabled:
        svc.rec.send_blueprint(default_blueprint(tuple(cfg.cameras)))
    SimNode(svc, world).run()
