"""What drives the sim's robot: the commander's joint commands and, with kinematic
locomotion, the base's `cmd_vel`.

A `JointCommand` goes to `SimCore.command` (τ = τ_ff + kp (q_des − q) + kd (v_des − v),
from the next step until replaced); one the core refuses (`CommandError`: wrong shape,
NaN/inf, negative gain, a stamp later than now) is counted and logged, and the previous
command stays in force. With kinematic locomotion the base follows the newest `CmdVel`
stamped at or before t (m/s, m/s, rad/s in `base_yaw`) while it is fresh (the WBC's
`wbc.cmd_vel_timeout_s`), else stands still. Called from the sim's loop thread.
"""

from __future__ import annotations

import logging

from common.bus import Bus
from common.keys import RobotKeys
from common.messages import as_numpy
from common.messages.base import NS_PER_S
from common.messages.sim import JointCommand
from common.messages.wbc import CmdVel
from services.sim.core import CommandError, SimCore


class CommandIntake:
    """Commands into a `SimCore`; `commands` and `rejected` count them."""

    def __init__(
        self,
        bus: Bus,
        keys: RobotKeys,
        core: SimCore,
        cmd_vel_timeout_s: float,
        log: logging.Logger,
    ) -> None:
        self.core = core
        self._cmd_vel = bus.latest(keys.cmd_vel, CmdVel, history=64)
        self._cmd_vel_timeout_s = cmd_vel_timeout_s
        self.log = log
        self.commands = 0
        self.rejected = 0

    def apply(self, cmd: JointCommand | None) -> None:
        """Drive the joints by `cmd` (None: the last command stays in force)."""
        if cmd is None:
            return
        try:
            wire = (cmd.tau_ff, cmd.q_des, cmd.v_des, cmd.kp, cmd.kd)
            tau_ff, q_des, v_des, kp, kd = (as_numpy(a) for a in wire)
            self.core.command(tau_ff, q_des, v_des, kp, kd, cmd.stamp_ns)
            self.commands += 1
        except (CommandError, ValueError) as exc:
            self.rejected += 1
            self.log.warning("command rejected at t=%.3f s: %s", cmd.stamp_ns / NS_PER_S, exc)

    def apply_cmd_vel(self, t_ns: int) -> None:
        """With kinematic locomotion: the base's twist at sim time t (zero when stale)."""
        if self.core.locomotion != "kinematic":
            return
        msg = self._cmd_vel.at(t_ns)
        timeout_ns = round(self._cmd_vel_timeout_s * NS_PER_S)  # as the WBC's
        fresh = msg is not None and t_ns - msg.stamp_ns <= timeout_ns
        if msg is not None and fresh:
            self.core.set_cmd_vel(msg.vx, msg.vy, msg.wz)
        else:
            self.core.set_cmd_vel(0.0, 0.0, 0.0)
