"""A command participant for the determinism test: the stand-hold, with joint1 following
the wiggle participant's offset from the tick at which it takes effect (its stamp plus
its configured latency)."""

from __future__ import annotations

import sys

import numpy as np

from common.bus import WaitTimeout
from common.lockstep import UpstreamGate
from common.messages import to_wire
from common.messages.sim import JointCommand, RobotState
from common.messages.wbc import CmdVel
from common.service import Service, run
from services.sim.hold import StandHold
from tests.integration.wiggle_participant import NAME as WIGGLE
from tests.integration.wiggle_participant import key

NAME = "commander"
JOINT1 = 12


def main(svc: Service) -> None:
    law = StandHold()
    states = svc.bus.latest(svc.keys.state, RobotState, history=4)
    wiggle = svc.bus.latest(key(svc), CmdVel, history=64)
    upstream = UpstreamGate(svc.bus, svc.keys, svc.config)
    upstream.watch(WIGGLE, wiggle)
    latency_ns = upstream.latency_ns(WIGGLE)
    commands = svc.bus.publisher(svc.keys.command, JointCommand, "control")
    svc.ready()
    last = -1
    while not svc.stopping:
        try:
            state = states.wait(lambda s, last=last: s.stamp_ns != last, 0.1)
        except WaitTimeout:
            continue
        last = state.stamp_ns
        missing = upstream.wait(state.stamp_ns, svc.config.time.stall_timeout_s)
        if missing:
            svc.log.warning("no ack from %s for t=%d ns", missing, state.stamp_ns)
        w = wiggle.at(state.stamp_ns - latency_ns)
        due = ((state.stamp_ns - latency_ns) // 20_000_000) * 20_000_000
        if state.stamp_ns >= latency_ns and (w is None or w.stamp_ns != due):
            svc.log.warning("wiggle at %d is %s", state.stamp_ns, None if w is None else w.stamp_ns)
        q_des = law.q_des.copy()
        q_des[JOINT1] += 0.0 if w is None else float(np.clip(w.vx, -1.0, 1.0))
        cmd = law.command(state.stamp_ns, NAME)
        commands.put(
            JointCommand(
                stamp_ns=cmd.stamp_ns,
                tau_ff=cmd.tau_ff,
                q_des=to_wire(q_des),
                v_des=cmd.v_des,
                kp=cmd.kp,
                kd=cmd.kd,
                source=NAME,
            )
        )


if __name__ == "__main__":
    sys.exit(run(NAME, main))
