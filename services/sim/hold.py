"""`python -m services.sim.hold`: the joint commander until the whole-body controller exists.

A PD stand-hold: every state it gets is answered with one command stamped with the
state's stamp (what the lockstep sim waits for), holding the `stand` posture with the
gains and static feed-forward of `services.sim.standing`. `StandHold` is the law alone,
for in-process loops (benchmarks, tests) and for commanders built on it.
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

import msgspec
import numpy as np

from common import robot
from common.bus import WaitTimeout
from common.geometry import FloatArray
from common.messages import to_wire
from common.messages.sim import JointCommand, RobotState
from common.service import Service, run
from services.sim.standing import STAND_KD, STAND_KP, standing_feedforward

NAME = "hold"


class StandHold:
    """τ = τ_ff + kp (q_des − q) + kd (0 − v) about a posture (19-vectors, `JOINT_NAMES`)."""

    def __init__(self, posture: str = "stand") -> None:
        self.q_des: FloatArray = np.array(robot.POSTURES[posture], dtype=float)
        self.v_des: FloatArray = np.zeros(len(robot.JOINT_NAMES))
        self.tau_ff: FloatArray = standing_feedforward(robot.standing_q(posture))
        self.kp: FloatArray = np.array(STAND_KP, dtype=float)
        self.kd: FloatArray = np.array(STAND_KD, dtype=float)
        # The law is constant: pack its arrays once, not on every 1 kHz answer.
        self._wire = JointCommand(
            stamp_ns=0,
            tau_ff=to_wire(self.tau_ff),
            q_des=to_wire(self.q_des),
            v_des=to_wire(self.v_des),
            kp=to_wire(self.kp),
            kd=to_wire(self.kd),
            source=NAME,
        )

    def command(self, stamp_ns: int, source: str = NAME) -> JointCommand:
        """The command answering the state stamped `stamp_ns`."""
        return msgspec.structs.replace(self._wire, stamp_ns=stamp_ns, source=source)


def main(svc: Service) -> None:
    law = StandHold()
    states = svc.bus.latest(svc.keys.state, RobotState, history=4)
    commands = svc.bus.publisher(svc.keys.command, JointCommand, "control")
    svc.ready()
    last = -1

    def is_new(state: RobotState) -> bool:
        return state.stamp_ns != last

    while not svc.stopping:
        try:
            state = states.wait(is_new, 0.1)
        except WaitTimeout:
            continue
        last = state.stamp_ns
        commands.put(law.command(state.stamp_ns))


if __name__ == "__main__":
    sys.exit(run(NAME, main))
