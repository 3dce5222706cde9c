"""The whole-body controller service: the lockstep command participant around the WBC.

Each state it must answer (stamps on its period, `time.participants.wbc.period_s`) gets
one `JointCommand` with the state's stamp. Per tick:

1. inputs due at t: modes (carried by a source's cmd_vel, or on `wbc/mode`) and cmd_vel
   of the obeyed source at stamp + latency (`inputs`), arm goals accepted whose
   `effective_ns` has come (`goals`). In lockstep the tick first waits
   (`UpstreamGate`, at most `UPSTREAM_WAIT_S` of wall time) for the cmd_vel due now from
   the mode's source (the mission sends one every period, with its mode changes) and
   then from the obeyed source: the sim stepped past their tick once they acked it, but
   their ack can reach the sim before their cmd_vel reaches us, and a command applied
   one period late is a different run. Nothing else is waited for;
2. the command (`commander`): damping in `damp`; otherwise `WholeBodyController.step`
   with the gait command (walk only) and the arm references; a failed QP keeps the last
   torques for one tick, then the stand hold takes over until `recover_ticks` good solves
   (`fallback`);
3. publish; then, off the critical path, `wbc/status` at `status_hz` and rerun at `log_hz`.

This module is the wiring: the parts built from the config and the bus, the loop, and
the `wbc/arm_goal` server, which hands requests to `goals.GoalIntake` on its own thread.

State estimate: with `wbc.base_state = "estimate"` the base's pose and twist are the
leg-inertial odometry's (`odometry`: the IMU, the encoders, the feet's contacts), and
the WBC publishes them on `odom` at `sim.odom_hz`, stamped with the state they answer
(after the tick's correction); with `truth` (an ablation) they are the sim's free joint,
read from `state_truth` stamped as the state (the sim sends it just before), and the sim
publishes `odom`.
Bad inputs never stop the loop: refused goals get a typed `ErrorReply`, a state with NaN
is answered with damping, a gap in the states (stale state) stops the robot.
"""

from __future__ import annotations

import contextlib
import gc
import math
import time

import numpy as np

from common.bus import WaitTimeout
from common.lockstep import UpstreamGate
from common.messages import ArrayError
from common.messages.base import NS_PER_S
from common.messages.sim import JointCommand, Odom, RobotState, StateTruth
from common.messages.wbc import ArmGoalReply, ArmGoalRequest, CmdVel, WbcMode, WbcStatus
from common.sched import make_realtime
from common.service import Service
from services.wbc.commander import WbcCommander
from services.wbc.inputs import ArbiterFeed
from services.wbc.safety import damp_command
from services.wbc.telemetry import WbcLogger
from services.wbc.wire import NAME, joint_command, wbc_state

#: How long a tick waits for an upstream cmd_vel (wall s) before it goes on without.
UPSTREAM_WAIT_S = 0.5


class WbcNode:
    """The service's parts and its loop; the domain work is `WbcCommander`'s."""

    def __init__(self, svc: Service) -> None:
        self.svc, cfg = svc, svc.config
        w = cfg.wbc
        self.period_ns = cfg.time.period_ns_of(NAME, 1.0 / cfg.time.tick_hz)
        latency = cfg.time.latencies_ns()
        start = cfg.localization.start_pose
        if w.base_state == "estimate" and start is None:
            svc.log.warning("no localization.start_pose: odometry starts at the origin")
        self.core = core = WbcCommander(w, latency, self.period_ns, svc.log, start)
        self.tick_us = 0.0
        #: Wall seconds this tick waited for upstream inputs (not compute).
        self._waited_s = 0.0
        self.status_every = round(NS_PER_S / w.status_hz)
        self.log_every = round(NS_PER_S / w.log_hz)
        bus, keys = svc.bus, svc.keys
        self.states = bus.latest(keys.state, RobotState, history=4)
        #: The truth ablation's base (`wbc.base_state = "truth"`), beside each state.
        self.truths = (
            bus.latest(keys.state_truth, StateTruth, history=8) if w.base_state == "truth" else None
        )
        self.cmd_vel = bus.fifo(keys.cmd_vel, CmdVel, maxlen=4096)
        #: cmd_vel into the arbiter, the modes they carry into the queue.
        self.intake = ArbiterFeed(self.cmd_vel, core.arbiter, "", core.modes)
        self.upstream = UpstreamGate(bus, keys, cfg)
        self.mode_source = w.mode_source
        for name in sorted(cfg.time.participants):  # any periodic one may send cmd_vel
            self.upstream.watch(name, ArbiterFeed(self.cmd_vel, core.arbiter, name, core.modes))
        self.late_inputs = 0
        self.mode_in = bus.fifo(keys.wbc_mode, WbcMode, maxlen=256)
        self.commands = bus.publisher(keys.command, JointCommand, "control")
        #: The last command sent, answered again to a state sent again.
        self._answer: JointCommand | None = None
        self.status = bus.publisher(keys.wbc_status, WbcStatus, "data")
        self.odom = bus.publisher(keys.odom, Odom, "control") if cfg.odom_from_estimate() else None
        self.odom_every = round(NS_PER_S / cfg.sim.odom_hz)
        bus.serve(keys.arm_goal, ArmGoalRequest, self._on_goal)
        self.logger = WbcLogger(svc.rec)

    def _on_goal(self, req: ArmGoalRequest | None, _selector: str) -> ArmGoalReply:
        """The server's thread: accept (queue) or refuse the goal."""
        return self.core.goals.accept(req)

    # -- the loop --------------------------------------------------------------------------

    def run(self) -> None:
        svc = self.svc
        # Everything set up so far (pinocchio, MuJoCo, OSQP, Zenoh) lives as long as the
        # service: out of the collector's reach, a collection costs microseconds, not
        # milliseconds in the middle of a tick.
        gc.collect()
        gc.freeze()
        prio = svc.config.wbc.realtime_priority
        if prio and (why := make_realtime(prio)):
            svc.log.warning("%s: the controller runs under the normal scheduler", why)
        elif prio:
            svc.log.info("the controller runs SCHED_FIFO %d", prio)
        svc.ready()
        last, seen = -1, None

        def is_new(state: RobotState) -> bool:
            # a later state, or the last one arrived again (another sample: the sim sends
            # it once more when its link was down, `common.lockstep.SimGate`)
            return state.stamp_ns > last or (state.stamp_ns == last and state is not seen)

        while not svc.stopping:
            try:
                msg = self.states.wait(is_new, 0.1)
            except WaitTimeout:
                continue
            again, seen = msg.stamp_ns == last, msg
            if again:  # its answer was lost the same way: the same answer once more
                if self._answer is not None and self._answer.stamp_ns == last:
                    self.commands.put(self._answer)
                continue
            last = msg.stamp_ns
            if msg.stamp_ns % self.period_ns:
                continue  # the sim waits for us only on our period
            t0 = time.perf_counter()
            self.tick(msg, t0)

    def tick(self, msg: RobotState, t0: float) -> None:
        t, core = msg.stamp_ns, self.core
        base = None
        if self.truths is not None:  # the truth ablation: the sim's base beside the state
            base = self._truth_at(t)
            if base is None:  # no command: the sim's watchdog holds the joints
                core.say(f"no state_truth at t={t / NS_PER_S:.3f} s (truth ablation): not answered")
                return
        try:
            state = wbc_state(msg, base)
        except ArrayError as exc:  # no command: the sim's watchdog holds the joints
            core.say(f"state at t={t / NS_PER_S:.3f} s is malformed ({exc}): not answered")
            return
        if not math.isfinite(float(state.q.sum()) + float(state.v.sum())):  # any NaN or inf
            self.commands.put(joint_command(t, damp_command(np.nan_to_num(state.q))))
            core.say(f"state at t={t / NS_PER_S:.3f} s has NaN: damping")
            return
        state, dt = core.begin(t, state, msg)
        self._waited_s = 0.0
        # The inputs due at t: the mode source's, its modes, then the obeyed source's.
        self._upstream(t, self.mode_source)
        self.intake.get()  # whatever came (realtime: nothing was waited for)
        for mode_msg in self.mode_in.drain():
            core.modes.push(mode_msg)
        core.apply_modes(t, state)
        self._upstream(t, core.arbiter.source)
        self.intake.get()
        core.start_goals(t)
        cmd = core.command(t, state, dt)
        self._answer = joint_command(t, cmd)
        self.commands.put(self._answer)
        self.tick_us = (time.perf_counter() - t0 - self._waited_s) * 1e6
        # Off the critical path: the sim is stepping now.
        core.end(t, msg)
        if self.odom is not None and core.odometry is not None and t % self.odom_every == 0:
            self.odom.put(core.odometry.odom(msg))
        if t % self.status_every == 0:
            self.status.put(core.status(t, msg, self.tick_us))
        if t % self.log_every == 0:
            T_goal = core.actions.T_goal
            self.logger.log(
                t, core.ctrl, cmd.tau_ff, core.errors(), core.qp_us, self.tick_us, T_goal
            )

    def _truth_at(self, t: int) -> StateTruth | None:
        assert self.truths is not None
        with contextlib.suppress(WaitTimeout):
            self.truths.wait_stamp(t, UPSTREAM_WAIT_S)
        truth = self.truths.at(t)
        return truth if truth is not None and truth.stamp_ns == t else None

    def _upstream(self, t: int, producer: str) -> None:
        """Wait for `producer`'s cmd_vel due at t (lockstep; see the module's docstring)."""
        t0 = time.perf_counter()
        late = self.upstream.wait(t, UPSTREAM_WAIT_S, (producer,))
        self._waited_s += time.perf_counter() - t0
        if not late:
            return
        self.late_inputs += 1
        if self.late_inputs in (1, 10, 100) or self.late_inputs % 1000 == 0:
            self.core.say(
                f"t={t / NS_PER_S:.3f} s: no cmd_vel from {producer} for its tick due now "
                f"within {UPSTREAM_WAIT_S} s ({self.late_inputs} times): went on without it"
            )


def main(svc: Service) -> None:
    WbcNode(svc).run()
