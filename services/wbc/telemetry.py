"""What the controller tells the others and the recording: `wbc/status` and rerun.

`tracking_errors` reads the base and gripper tracking errors off the controller's tasks;
`WbcLogger` logs time series (tracking errors, QP and tick time, joint torques), the
footstep plan (swing targets and the feet in stance) and the gripper target to rerun,
under `plots/wbc/…` and `world/wbc/…`, stamped on sim time.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import rerun as rr

from common import robot
from common.geometry import FloatArray
from common.recording import stamp
from services.wbc.controller import WholeBodyController


def tracking_errors(ctrl: WholeBodyController, tcp_on: bool) -> tuple[float, float, float]:
    """Base (CoM xy and base height) error m, gripper_tcp error m and rad (0 when off)."""
    m = ctrl.model
    base = m.frames[robot.BASE_FRAME]
    dxy = ctrl.com_task.p_ref[:2] - m.com[:2]
    dz = ctrl.base_task.p_ref[2] - base.p[2]
    base_err = float(np.sqrt(dxy @ dxy + dz * dz))
    if not tcp_on:
        return base_err, 0.0, 0.0
    tcp, task = m.frames[robot.TCP_FRAME], ctrl.tcp_task
    dp = float(np.linalg.norm(task.p_ref - tcp.p))
    return base_err, dp, float(np.linalg.norm(pin.log3(task.R_ref @ tcp.R.T)))


class WbcLogger:
    """rerun output of the controller."""

    def __init__(self, rec: rr.RecordingStream) -> None:
        self.rec = rec
        rec.log(
            "plots/wbc/tau",
            rr.SeriesLines(names=list(robot.JOINT_NAMES)),
            static=True,
        )

    def log(
        self,
        t_ns: int,
        ctrl: WholeBodyController,
        tau: FloatArray,
        errors: tuple[float, float, float],
        qp_us: float,
        tick_us: float,
        T_target: FloatArray | None,
    ) -> None:
        rec = self.rec
        stamp(rec, t_ns)
        rec.log("plots/wbc/base_error_m", rr.Scalars(errors[0]))
        rec.log("plots/wbc/gripper_error_m", rr.Scalars(errors[1]))
        rec.log("plots/wbc/gripper_error_rad", rr.Scalars(errors[2]))
        rec.log("plots/wbc/qp_us", rr.Scalars(qp_us))
        rec.log("plots/wbc/tick_us", rr.Scalars(tick_us))
        rec.log("plots/wbc/tau", rr.Scalars(np.asarray(tau, dtype=float)))
        gait = ctrl.gait
        stance = [f.p for f, s in zip(ctrl.model.feet, gait.stance, strict=True) if s > 0.5]
        swing = [target.p for target in gait.swing.values()]
        m = ctrl.model
        base_xy, height = m.frames[robot.BASE_FRAME].p[:2], float(m.com[2] - robot.FOOT_RADIUS_M)
        footholds = [gait.foothold(k, base_xy, ctrl.ref_yaw, m.vcom, height) for k in gait.swing]
        rec.log(
            "world/wbc/footsteps",
            rr.Points3D(
                [*stance, *swing, *footholds],
                colors=[(40, 200, 40)] * len(stance)
                + [(240, 160, 0)] * len(swing)
                + [(220, 40, 40)] * len(footholds),
                radii=0.02,
            ),
        )
        if T_target is None:
            rec.log("world/wbc/gripper_target", rr.Clear(recursive=False))
        else:
            rec.log(
                "world/wbc/gripper_target",
                rr.Transform3D(translation=T_target[:3, 3], mat3x3=T_target[:3, :3]),
                rr.TransformAxes3D(0.1),
            )
