"""The robot's kinematics and dynamics at one tick, computed once and shared by every task.

`RobotModel.update(q, v)` runs pinocchio's batched pass once (`computeAllTerms`: M, the
nonlinear effects h, all joint Jacobians, the CoM and its Jacobian, and the joints'
accelerations at v̇ = 0, which make the frames' classical accelerations the drifts J̇v),
then reads the frames the controller uses (feet, base, `gripper_tcp`) into preallocated
arrays, and the feet's rows into the contact Jacobian `Jc` (12, nv); `update(..., tcp=False)`
skips the `gripper_tcp` Jacobian and drift when no task needs them (its placement is always
read; `frame_jacobian` gives its Jacobian on demand). Everything is in pinocchio's
conventions: q (26,) with the base quaternion xyzw, v (25,) with the base twist in the
base frame; frame Jacobians are LOCAL_WORLD_ALIGNED (origin velocity and angular velocity
in world axes), so frame tasks and contact rows are all in world coordinates.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from common import robot
from common.geometry import FloatArray

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
#: Frames whose placement, Jacobian and drift every tick provides.
TRACKED_FRAMES: tuple[str, ...] = (*robot.FOOT_FRAMES, robot.BASE_FRAME, robot.TCP_FRAME)


class FrameState:
    """One frame at this tick: placement in world (p, R), 6×nv LWA Jacobian J, J̇v (6,) and
    twist (6,) [linear, angular]. The arrays are views into the model's stacked buffers."""

    __slots__ = ("H", "J", "R", "dJv", "frame_id", "name", "p", "twist")

    def __init__(
        self,
        name: str,
        frame_id: int,
        H: FloatArray,
        J: FloatArray,
        dJv: FloatArray,
        twist: FloatArray,
    ) -> None:
        self.name, self.frame_id = name, frame_id
        self.H: FloatArray = H
        self.p: FloatArray = self.H[:3, 3]
        self.R: FloatArray = self.H[:3, :3]
        self.J, self.dJv, self.twist = J, dJv, twist


class RobotModel:
    """pinocchio model + data and the per-tick quantities the WBC needs.

    After `update(q, v)`: `M` (nv, nv, symmetric), `h` (nv,) = C v + g, `com` (3,),
    `vcom` (3,), `Jcom` (3, nv), `dJcom_v` (3,), `frames[name]` for `TRACKED_FRAMES`, and
    the feet's positions `feet_p` (4, 3).
    """

    def __init__(self, model: pin.Model | None = None) -> None:
        self.model: pin.Model = model if model is not None else robot.load_pinocchio()[0]
        self.data = self.model.createData()
        nv = self.model.nv
        self.nv, self.nq = nv, self.model.nq
        self.mass = float(pin.computeTotalMass(self.model))
        self.q: FloatArray = pin.neutral(self.model)
        self.v: FloatArray = np.zeros(nv)
        # Views into pinocchio's data (its Eigen buffers keep their addresses), so each
        # tick reads them without a copy; `update` refreshes them in place.
        pin.computeAllTerms(self.model, self.data, self.q, self.v)
        pin.centerOfMass(self.model, self.data, pin.KinematicLevel.ACCELERATION, False)
        self.M: FloatArray = self.data.M
        self.h: FloatArray = self.data.nle
        self.com: FloatArray = self.data.com[0]
        self.vcom: FloatArray = self.data.vcom[0]
        self.Jcom: FloatArray = self.data.Jcom
        self.dJcom_v: FloatArray = self.data.acom[0]
        n = len(TRACKED_FRAMES)
        self._J_all: FloatArray = np.zeros((6 * n, nv))  # every frame's J, stacked
        self._dJv_all: FloatArray = np.zeros(6 * n)
        self._twist_all: FloatArray = np.zeros(6 * n)
        self._H_all: FloatArray = np.tile(np.eye(4), (n, 1, 1))
        self.frames: dict[str, FrameState] = {}
        for k, name in enumerate(TRACKED_FRAMES):
            if not self.model.existFrame(name):
                known = [f.name for f in self.model.frames]
                raise KeyError(f"frame {name!r} is not in the model; frames are {known}")
            rows = slice(6 * k, 6 * k + 6)
            self.frames[name] = FrameState(
                name,
                self.model.getFrameId(name),
                self._H_all[k],
                self._J_all[rows],
                self._dJv_all[rows],
                self._twist_all[rows],
            )
        self.feet: tuple[FrameState, ...] = tuple(self.frames[f] for f in robot.FOOT_FRAMES)
        #: (4, 3) the feet's positions in world, a view that each update refreshes.
        self.feet_p: FloatArray = self._H_all[: len(self.feet), :3, 3]
        if TRACKED_FRAMES[: len(self.feet)] != robot.FOOT_FRAMES:  # feet_p is their rows
            raise ValueError(f"the feet must be the first tracked frames: {TRACKED_FRAMES}")
        self._foot_rows = np.concatenate(
            [6 * TRACKED_FRAMES.index(f) + np.arange(3) for f in robot.FOOT_FRAMES]
        )
        self.Jc: FloatArray = np.zeros((3 * len(self.feet), nv))
        self.dJc_v: FloatArray = np.zeros(3 * len(self.feet))
        self.v_feet: FloatArray = np.zeros(3 * len(self.feet))
        self._tcp = self.frames[robot.TCP_FRAME]
        self._derived = tuple(fs for fs in self.frames.values() if fs is not self._tcp)
        self._tcp_fresh = True

    def update(self, q: FloatArray, v: FloatArray, tcp: bool = True) -> None:
        """Compute everything for the state (q, v) in pinocchio's layout.

        tcp=False leaves `gripper_tcp`'s J, J̇v and twist at zero (its placement is read).
        """
        model, data = self.model, self.data
        self.q[:] = q
        self.v[:] = v
        pin.computeAllTerms(model, data, self.q, self.v)  # M is filled whole (pinocchio 4)
        pin.updateFramePlacements(model, data)
        pin.centerOfMass(model, data, pin.KinematicLevel.ACCELERATION, False)
        oMf = data.oMf
        for fs in self._derived:
            fid = fs.frame_id
            fs.H[:] = oMf[fid].homogeneous
            fs.J[:] = pin.getFrameJacobian(model, data, fid, LWA)
            fs.dJv[:] = pin.getFrameClassicalAcceleration(model, data, fid, LWA).vector
        tcp_state = self._tcp
        tcp_state.H[:] = oMf[tcp_state.frame_id].homogeneous
        if tcp:
            tcp_state.J[:] = pin.getFrameJacobian(model, data, tcp_state.frame_id, LWA)
            tcp_state.dJv[:] = pin.getFrameClassicalAcceleration(
                model, data, tcp_state.frame_id, LWA
            ).vector
        elif self._tcp_fresh:
            tcp_state.J[:] = 0.0
            tcp_state.dJv[:] = 0.0
        self._tcp_fresh = tcp
        np.dot(self._J_all, self.v, out=self._twist_all)
        np.take(self._J_all, self._foot_rows, axis=0, out=self.Jc)
        np.take(self._dJv_all, self._foot_rows, out=self.dJc_v)
        np.take(self._twist_all, self._foot_rows, out=self.v_feet)

    def frame_jacobian(self, name: str) -> FloatArray:
        """A tracked frame's LWA Jacobian (6, nv) at the last update, computed if skipped."""
        fs = self.frames[name]
        if fs is self._tcp and not self._tcp_fresh:
            return np.asarray(pin.getFrameJacobian(self.model, self.data, fs.frame_id, LWA))
        return fs.J


def q_from_state(
    base_position_in_world: FloatArray,
    base_orientation_xyzw: FloatArray,
    joints: FloatArray,
) -> FloatArray:
    """Pinocchio q (26,) from the base pose and the 19 joint positions."""
    return np.concatenate([base_position_in_world, base_orientation_xyzw, joints])


def v_from_state(
    R_world_base: FloatArray,
    base_linear_velocity_in_world: FloatArray,
    base_angular_velocity_in_base: FloatArray,
    joint_velocities: FloatArray,
) -> FloatArray:
    """Pinocchio v (25,): the base twist in the base frame, then the joint velocities."""
    return np.concatenate(
        [
            R_world_base.T @ base_linear_velocity_in_world,
            base_angular_velocity_in_base,
            joint_velocities,
        ]
    )
