"""The WBC's odometry: the leg-inertial estimator (`estimator`) wired to the controller.

With `wbc.base_state = "estimate"` the controller runs on this, not on the sim's free
joint. Per tick, on the WBC's thread:

1. `predict(msg, state, dt, model)`: the IMU's rate and specific force carry the
   estimate over dt; the controller's state gets the predicted base (pose and twist in
   odom) in place of the message's;
2. the controller runs at that state, its model updated there (`damp` too: the
   commander updates the model when it does not step the controller);
3. `correct(model, contacts)`, after the command went out: each foot's position
   relative to the base and its velocity less the base's, from the model at the
   predicted base, with the feet's contact sensors, correct the estimate.

The odom frame starts at the start pose the user gives (`localization.start_pose`: x, y,
yaw in the map; the height from the stance feet), so odom and map coincide at start-up
and part only by the estimator's drift, which localization's T_map_odom takes up. The
estimate starts again at every state until the four feet first stand on the floor
together (a stack starts with the robot settling onto its feet: integrating that drop
moved the odometry 0.2 m): roll and pitch from gravity (level while the accelerometer is
not reading it), the feet where the legs put them; for the first `calibrate_s` standing
still the gyro's bias is learnt, cut short when the gait starts stepping (`moving`), and
again at every later standstill as long.
"""

from __future__ import annotations

import numpy as np

from common import robot
from common.config import EstimatorSettings
from common.geometry import FloatArray
from common.messages.sim import Odom, RobotState
from services.wbc.estimator import E_Z, Correction, LegInertialEstimator, tilt_from_gravity
from services.wbc.model import RobotModel
from services.wbc.values import WbcState

Pose2 = tuple[float, float, float]


class LegOdometry:
    """The base in odom, every tick, from the robot's sensors (module docstring)."""

    def __init__(self, s: EstimatorSettings, start: Pose2) -> None:
        self.est = LegInertialEstimator(s)
        self.start_pose = start
        self._v_pred: FloatArray = np.zeros(3)
        #: The four feet have been down together: the robot stands, the estimate runs.
        self._grounded = False

        self._zero_v: FloatArray | None = None

    @property
    def started(self) -> bool:
        return self.est.started

    @property
    def calibrating(self) -> bool:
        """Learning the IMU's bias at start-up (until it has stood still long enough)."""
        return self.est.calibrating

    def _start(self, msg: RobotState, joints: FloatArray, model: RobotModel) -> None:
        """At rest: the tilt from gravity, the feet from the legs, the height from them."""
        x, y, yaw = self.start_pose
        f = np.array(msg.imu_specific_force, dtype=float)
        R = tilt_from_gravity(f, yaw)
        q = np.concatenate([np.zeros(3), robot.quat_xyzw_of(R), joints])
        if self._zero_v is None:
            self._zero_v = np.zeros(model.nv)
        model.update(q, self._zero_v, tcp=False)
        rel = model.feet_p.copy()  # the base at the origin: the feet relative to it
        down = [rel[k, 2] for k, c in enumerate(msg.foot_contacts) if c] or list(rel[:, 2])
        z = robot.FOOT_RADIUS_M - float(np.mean(down))
        self.est.start(f, np.array([x, y, z]), yaw, rel)

    def predict(
        self, msg: RobotState, state: WbcState, dt: float, model: RobotModel, standing: bool
    ) -> WbcState:
        """The state with the base predicted at the message's stamp (dt s since the last;
        `standing`: the gait is not stepping, so a still IMU measures its own bias)."""
        est = self.est
        if not self._grounded:  # started again each tick until the four feet are down
            self._start(msg, np.asarray(state.q), model)
            self._grounded = all(msg.foot_contacts)
        else:
            est.predict(
                np.array(msg.imu_angular_velocity, dtype=float),
                np.array(msg.imu_specific_force, dtype=float),
                dt,
                msg.foot_contacts,
                standing,
            )
        self._v_pred = est.velocity.copy()
        return WbcState(
            q=state.q,
            v=state.v,
            base_position_in_world=est.position.copy(),
            base_orientation_xyzw=self.quaternion(),
            base_linear_velocity_in_world=self._v_pred,
            base_angular_velocity_in_base=est.angular_velocity.copy(),
        )

    def moving(self) -> None:
        """The robot is asked to move: the calibration at rest ends now."""
        if self.est.calibrating:
            self.est.tilt.finish_calibration()
            self.est.calibrating = False

    def correct(self, model: RobotModel, contacts: tuple[bool, bool, bool, bool]) -> None:
        """The legs' measurements from the model, as updated at the predicted state."""
        rel_p = model.feet_p - model.q[:3]
        rel_v = model.v_feet.reshape(4, 3) - self._v_pred
        omega = np.array([f.twist[3:6] for f in model.feet])  # each calf's, in world axes
        rolling = robot.FOOT_RADIUS_M * np.cross(omega, E_Z)
        self.est.correct(Correction(rel_p, rel_v, contacts, rolling))

    def odom(self, msg: RobotState) -> Odom:
        """`odom` at the message's stamp: the estimate, the gripper as the state has it."""
        est = self.est
        return Odom(
            stamp_ns=msg.stamp_ns,
            base_position_in_world=tuple(est.position.tolist()),
            base_orientation_xyzw=tuple(self.quaternion().tolist()),
            base_linear_velocity_in_world=tuple(est.velocity.tolist()),
            base_angular_velocity_in_base=tuple(est.angular_velocity.tolist()),
            gripper_angle=msg.gripper_angle,
            gripper_effort=msg.gripper_effort,
            watchdog=msg.watchdog,
            locomotion=msg.locomotion,
        )

    def quaternion(self) -> FloatArray:
        """The estimated orientation, a unit quaternion x y z w."""
        return robot.quat_xyzw_of(self.est.R)
