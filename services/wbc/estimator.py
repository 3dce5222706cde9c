"""The base's pose and twist from the robot's own sensors: the trunk IMU, the joint
encoders and the feet's contact sensors (a leg-inertial estimator, where the controller
runs: it needs the estimate every tick).

Two parts, run every controller tick (dt s):

1. `TiltFilter`, a Mahony complementary filter on SO(3) for the orientation R (base in
   odom). The gyro, less its estimated bias b, is integrated: R ← R exp((ω_m − b + kp e) dt).
   The accelerometer pulls roll and pitch towards gravity: with the measured up
   direction u = f / |f| and the predicted û = Rᵀ e_z, e = u × û, the correction kp e
   turns û towards u, and ḃ = −ki e learns the gyro's bias on the axes gravity observes.
   The centripetal part of f (ω × v, v from part 2) is taken out first, and the
   accelerometer is trusted only while |f| is within `gravity_gate` of g (an impact, a
   push). Yaw is unobservable here: it drifts with the residual z bias. The bias is
   measured whenever the robot stands still on four feet (`calibrate`: the mean of the
   gyro less the base's true rate, which the legs give; the first time, the mean
   specific force also sets roll and pitch); the localization against the map corrects
   the yaw. An accelerometer's constant bias looks like a tilt at rest: 0.1 m/s² is
   0.6°. The stance feet are the second, main "up": on a flat floor their centres (base
   axes, the measured joints' kinematics) lie at one height, so every pair's difference
   d is level, ûᵀd = 0 (`correct_floor`, at `floor_kp`; a trot's diagonal pairs each
   observe one axis, in turn). Gravity's pull is slow (`tilt_kp`) and only keeps the
   long-run tilt: while trotting the specific force's direction is off up by 6°
   (median), its 1 s mean by up to 7°, the gait's own accelerations, which do not
   average out (at 1/s they made a tilt error of p95 4.4°; the feet's plane is off by
   0.06°, p95 0.4°).
2. `LegKalman`, a linear Kalman filter (as the MIT Cheetah's and Unitree's legged
   estimators) over x = [p (3), v (3), p_foot (4 × 3)] in odom, given R:
   - predict: p += v dt + ½ a dt², v += a dt with a = R f + g; the feet stay where they
     are, loosely (`q_foot_stance`), or wander freely in swing (`q_foot_swing`);
   - correct, every foot: p_foot − p = R r_foot(q) (leg kinematics, `r_kin`); a foot in
     contact rolls without slipping, so its sphere's centre moves at ω_foot × (ρ e_z)
     over the floor (ρ the radius: 6 % of a 0.5 m/s trot, if taken as standing still),
     hence v = ω_foot × ρ e_z − R (J q̇ + ω × r_foot) (`r_vel`); and its centre is ρ
     above the floor: p_foot,z = ρ (`r_height`, a flat floor). In the prediction a
     stance foot's centre moves with that rolling velocity.
   The measurement noise of a swing foot's velocity and height is made huge, so only
   the stance feet carry them. Position in x, y is unobservable: it drifts, as on a robot.

The filter is pure: the kinematic terms (r_foot and J q̇ + ω × r in odom axes) come from
the controller's model (`services.wbc.model`), updated at the predicted state, and the
contacts from the feet's force sensors. `tests/unit/test_estimator.py` checks it against
synthetic motion with known answers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from common import robot
from common.config import EstimatorSettings
from common.geometry import FloatArray

G = 9.81
E_Z = np.array([0.0, 0.0, 1.0])
N_FEET = 4
#: Every pair of feet (i, j), i < j, as two index arrays (the floor's level pairs).
FOOT_PAIRS = np.triu_indices(N_FEET, k=1)
#: The calibration's test for standing still: slower than this turn rate (rad/s; the
#: gyro's bias is far less) and an accelerometer within this of g (m/s²).
STILL_RAD_S = 0.05
STILL_ACCEL = 0.5
NX = 6 + 3 * N_FEET


def tilt_from_gravity(specific_force: FloatArray, yaw: float) -> FloatArray:
    """The rotation whose roll and pitch put `specific_force` (at rest: up, in the body)
    on +z, with the given yaw; level when the sample is not gravity (|f| off g by more
    than `STILL_ACCEL`: the robot settling onto its feet, a push)."""
    f = np.asarray(specific_force, float)
    if abs(np.linalg.norm(f) - G) > STILL_ACCEL:
        return np.asarray(pin.rpy.rpyToMatrix(0.0, 0.0, yaw))
    u = f / np.linalg.norm(f)
    roll = math.atan2(u[1], u[2])
    pitch = math.atan2(-u[0], math.hypot(u[1], u[2]))
    return np.asarray(pin.rpy.rpyToMatrix(roll, pitch, yaw))


class TiltFilter:
    """R (base in odom) and the gyro's bias from the IMU (module docstring, part 1)."""

    def __init__(self, s: EstimatorSettings) -> None:
        self.s = s
        self.R: FloatArray = np.eye(3)
        self.bias: FloatArray = np.zeros(3)
        self.omega: FloatArray = np.zeros(3)  # the last bias-corrected rate, rad/s, body
        self._calib: list[FloatArray] = []

    def reset(self, specific_force: FloatArray, yaw: float) -> None:
        self.R = tilt_from_gravity(specific_force, yaw)

    def calibrate(self, gyro: FloatArray, specific_force: FloatArray, rate: FloatArray) -> bool:
        """Collect a sample if the robot is still (its true turn `rate`, body axes, from
        the legs, is below `STILL_RAD_S`; the accelerometer reads g within `STILL_ACCEL`):
        the gyro's error `gyro − rate` and the specific force; `finish_calibration` takes
        their means. Whether it was taken."""
        f = np.asarray(specific_force, float)
        if np.linalg.norm(rate) > STILL_RAD_S or abs(np.linalg.norm(f) - G) > STILL_ACCEL:
            return False
        self._calib.append(np.concatenate([np.asarray(gyro) - rate, f]))
        return True

    def finish_calibration(self, tilt: bool = True) -> None:
        """The gyro's bias is its mean at rest; with `tilt`, roll and pitch the mean
        gravity's (yaw kept)."""
        if self._calib:
            mean = np.mean(self._calib, axis=0)
            self.bias = mean[:3]
            if tilt:
                self.reset(mean[3:], math.atan2(self.R[1, 0], self.R[0, 0]))
            self._calib = []

    def discard_calibration(self) -> None:
        self._calib = []

    def update(
        self,
        gyro: FloatArray,
        specific_force: FloatArray,
        dt: float,
        velocity: FloatArray | None = None,
    ) -> None:
        """Integrate the gyro over dt; pull towards gravity at `tilt_kp`. With the base's
        `velocity` (odom), the centripetal part of the specific force, ω × v in the body,
        is taken out first: a steady turn is not a tilt."""
        s = self.s
        w = np.asarray(gyro, float) - self.bias
        self.omega = w
        f = np.asarray(specific_force, float)
        if velocity is not None:
            f = f - np.cross(w, self.R.T @ velocity)
        norm = float(np.linalg.norm(f))
        if norm > 0.0 and abs(norm - G) < s.gravity_gate:
            e = np.cross(f / norm, self.R.T @ E_Z)
            self.bias -= s.tilt_ki * e * dt
            w = w + s.tilt_kp * e
        self.R = self.R @ np.asarray(pin.exp3(w * dt))

    def correct_floor(self, feet: FloatArray, contact: tuple[bool, ...], dt: float) -> None:
        """Pull roll and pitch towards the floor's at `floor_kp`: the centres of the feet
        in stance (`feet` (4, 3), base axes, from the measured joints) lie at one height
        on a flat floor, so each pair's difference d is level, ûᵀd = 0. The error
        e = Σ (ûᵀd̂)(û × d̂) over the pairs, over (feet down − 1), turns û off every d
        (two diagonal feet of a trot observe one axis, the next pair the other); a pair
        sloping by more than `floor_gate` (a slip, a step) is left out. The gyro's bias
        learns from it as from gravity."""
        s = self.s
        down = np.asarray(contact, dtype=bool)
        n_down = int(down.sum())
        if s.floor_kp <= 0.0 or n_down < 2:
            return
        i, j = FOOT_PAIRS
        both = down[i] & down[j]
        d = feet[i[both]] - feet[j[both]]
        norm = np.sqrt(np.einsum("ij,ij->i", d, d))
        d = d[norm >= 1e-3] / norm[norm >= 1e-3, None]
        up = self.R.T @ E_Z
        slope = d @ up
        slope[np.abs(slope) >= math.sin(s.floor_gate)] = 0.0  # a slip, a step: left out
        e = pin.skew(up) @ (slope @ d) / (n_down - 1)  # Σ slope (û × d̂), one cross
        self.bias -= s.tilt_ki * e * dt
        self.R = self.R @ np.asarray(pin.exp3(s.floor_kp * e * dt))


@dataclass
class Correction:
    """One tick's leg measurements, in odom axes: per foot (4, 3) the position of its
    sphere's centre relative to the base (R r_foot) and that centre's velocity relative
    to the base's origin (R (J q̇ + ω × r_foot)); the feet in contact; and `rolling`
    (4, 3), the velocity a stance foot's centre has over the floor as its sphere rolls,
    ω_foot × (radius e_z) (zero when unknown)."""

    rel_position: FloatArray
    rel_velocity: FloatArray
    contact: tuple[bool, bool, bool, bool]
    rolling: FloatArray | None = None


class LegKalman:
    """p, v and the feet in odom (module docstring, part 2). `x` (18,), `P` (18, 18)."""

    def __init__(self, s: EstimatorSettings) -> None:
        self.s = s
        self.x: FloatArray = np.zeros(NX)
        self.P: FloatArray = np.eye(NX) * 1e-4
        n = 3 * N_FEET
        # Measurement rows: relative positions (12), stance velocities (12), heights (4).
        H = np.zeros((2 * n + N_FEET, NX))
        for i in range(N_FEET):
            rows = slice(3 * i, 3 * i + 3)
            foot = slice(6 + 3 * i, 9 + 3 * i)
            H[rows, 0:3] = -np.eye(3)
            H[rows, foot] = np.eye(3)
            H[n + 3 * i : n + 3 * i + 3, 3:6] = np.eye(3)
            H[2 * n + i, 8 + 3 * i] = 1.0
        self.H = H
        self._y = np.zeros(H.shape[0])
        self._r = np.zeros(H.shape[0])
        self._rolling: FloatArray = np.zeros((N_FEET, 3))

    @property
    def position(self) -> FloatArray:
        return self.x[0:3]

    @property
    def velocity(self) -> FloatArray:
        return self.x[3:6]

    @staticmethod
    def legs_twist(c: Correction, omega_used: FloatArray) -> FloatArray | None:
        """The base's true twist (v, ω) (6,), world axes, from four feet on the floor: a
        foot's centre moves only as its sphere rolls, so R J q̇ = rolling − v − ω × p for
        each (p its position from the base), linear in (v, ω); `omega_used` is the ω
        the correction's relative velocities were computed with. None unless all four
        feet are down."""
        if not all(c.contact):
            return None
        p = c.rel_position
        rolling = np.zeros_like(p) if c.rolling is None else c.rolling
        jq = c.rel_velocity - np.cross(omega_used, p)  # R J q̇, per foot
        A = np.zeros((3 * N_FEET, 6))
        b = (jq - rolling).ravel()
        for i in range(N_FEET):
            A[3 * i : 3 * i + 3, 0:3] = -np.eye(3)
            A[3 * i : 3 * i + 3, 3:6] = pin.skew(p[i])  # p × ω
        return np.asarray(np.linalg.lstsq(A, b, rcond=None)[0])

    def reset(self, position: FloatArray, rel_position: FloatArray) -> None:
        """At rest at `position`, the feet at `position + rel_position`."""
        self.x[:] = 0.0
        self.x[0:3] = position
        self.x[6:] = (np.asarray(position) + rel_position).ravel()
        self.P = np.diag([1e-6] * 3 + [1e-4] * 3 + [1e-4] * (3 * N_FEET))

    def predict(self, accel_world: FloatArray, dt: float, contact: tuple[bool, ...]) -> None:
        """Integrate the acceleration in odom (m/s², gravity removed) over dt."""
        s, x = self.s, self.x
        x[0:3] += x[3:6] * dt + 0.5 * accel_world * dt * dt
        x[3:6] += accel_world * dt
        for i, c in enumerate(contact):  # a stance foot's centre rolls with its sphere
            if c:
                x[6 + 3 * i : 9 + 3 * i] += self._rolling[i] * dt
        P = self.P
        # F = I + dt (p ← v): P ← F P Fᵀ, written out.
        P[0:3, :] += dt * P[3:6, :]
        P[:, 0:3] += dt * P[:, 3:6]
        q = np.empty(NX)
        q[0:3] = s.q_position**2 * dt
        q[3:6] = s.q_accel**2 * dt
        for i, c in enumerate(contact):
            q[6 + 3 * i : 9 + 3 * i] = (s.q_foot_stance if c else s.q_foot_swing) ** 2 * dt
        P[np.diag_indices(NX)] += q

    def correct(self, c: Correction) -> None:
        s, n = self.s, 3 * N_FEET
        y, r = self._y, self._r
        y[:n] = c.rel_position.ravel()
        if c.rolling is None:
            self._rolling[:] = 0.0
            y[n : 2 * n] = -c.rel_velocity.ravel()
        else:
            self._rolling[:] = c.rolling
            y[n : 2 * n] = (c.rolling - c.rel_velocity).ravel()
        y[2 * n :] = robot.FOOT_RADIUS_M
        r[:n] = s.r_kin**2
        for i, contact in enumerate(c.contact):
            r[n + 3 * i : n + 3 * i + 3] = s.r_vel**2 if contact else 1e4
            r[2 * n + i] = s.r_height**2 if contact else 1e4
        H, P = self.H, self.P
        PHt = P @ H.T
        S = H @ PHt
        S[np.diag_indices_from(S)] += r
        K = np.linalg.solve(S, PHt.T).T
        self.x += K @ (y - H @ self.x)
        P -= K @ PHt.T
        self.P = 0.5 * (P + P.T)


class LegInertialEstimator:
    """The base in odom from the IMU, the legs and the contacts (module docstring).

    `start(specific_force, gyro, position, yaw, rel_position)` at rest, then every tick
    `predict(gyro, specific_force, dt, contact)` → the predicted state to run the
    controller's model at, and `correct(Correction)` with the model's kinematics there.
    While `calibrating` (until it has stood still `calibrate_s`, or is asked to move) the
    gyro's bias is learnt and gravity sets roll and pitch; afterwards, every unbroken
    `calibrate_s` the robot stands still (`standing`, the gait not stepping) measures
    the bias again: the z bias, which nothing else observes, stops wandering into yaw.
    `recalibrations` counts those.
    """

    def __init__(self, s: EstimatorSettings) -> None:
        self.s = s
        self.tilt = TiltFilter(s)
        self.kf = LegKalman(s)
        self.calibrating = False
        self._calib_left = 0.0
        self.started = False
        self.recalibrations = 0
        self._sample: tuple[FloatArray, FloatArray, float, bool] | None = None
        self._omega_used: FloatArray = np.zeros(3)

    def start(
        self,
        specific_force: FloatArray,
        position: FloatArray,
        yaw: float,
        rel_position: FloatArray,
    ) -> None:
        self.tilt.reset(specific_force, yaw)
        self.kf.reset(position, rel_position)
        self.calibrating = self.s.calibrate_s > 0.0
        self._calib_left = self.s.calibrate_s
        self.started = True

    def predict(
        self,
        gyro: FloatArray,
        specific_force: FloatArray,
        dt: float,
        contact: tuple[bool, ...],
        standing: bool = False,
    ) -> None:
        self._sample = (np.array(gyro, float), np.array(specific_force, float), dt, standing)
        if not (self.calibrating or standing) and self._calib_left != self.s.calibrate_s:
            self.tilt.discard_calibration()  # walking: a window left open is void
            self._calib_left = self.s.calibrate_s
        self.tilt.update(gyro, specific_force, dt, self.kf.velocity)
        self._omega_used = self.tilt.R @ self.tilt.omega  # what the model's twist will use
        a = self.tilt.R @ np.asarray(specific_force, float) - G * E_Z
        self.kf.predict(a, dt, contact)

    def correct(self, c: Correction) -> None:
        self.kf.correct(c)
        if self._sample is not None:
            feet = c.rel_position @ self.tilt.R  # Rᵀ r, per foot: base axes
            dt = self._sample[2]
            self._calibrate(c, *self._sample)
            self.tilt.correct_floor(feet, c.contact, dt)
            self._sample = None

    def _calibrate(
        self, c: Correction, gyro: FloatArray, f: FloatArray, dt: float, standing: bool
    ) -> None:
        """A still sample of the gyro's error: the gyro less the base's true rate, which
        the four feet on the floor give (`LegKalman.legs_twist`). Not the gyro alone: the
        controller holds the estimated heading, so a standing robot turns at minus the
        gyro's bias and the gyro's mean reads nothing (a 0.0026 rad/s bias, 0.15°/s of
        yaw drift, was calibrated as 0.00007). No faster pull towards gravity meanwhile
        either: the controller stands on this estimate (a tilt following every jolt, kp
        10 1/s, shook the standing robot at 0.1 rad/s)."""
        if not (self.calibrating or standing):
            return
        twist = self.kf.legs_twist(c, self._omega_used)
        rate = None if twist is None else self.tilt.R.T @ twist[3:]
        if rate is not None and self.tilt.calibrate(gyro, f, rate):
            self._calib_left -= dt  # only the time it stood still counts
            if self._calib_left <= 0.0:
                self.tilt.finish_calibration(tilt=self.calibrating)
                self.recalibrations += not self.calibrating
                self.calibrating = False
                self._calib_left = self.s.calibrate_s
        elif not self.calibrating:  # a rest's window must be unbroken
            self.tilt.discard_calibration()
            self._calib_left = self.s.calibrate_s

    @property
    def R(self) -> FloatArray:
        return self.tilt.R

    @property
    def position(self) -> FloatArray:
        return self.kf.position

    @property
    def velocity(self) -> FloatArray:
        return self.kf.velocity

    @property
    def angular_velocity(self) -> FloatArray:
        """Body rate, rad/s in the base: the gyro less its estimated bias."""
        return self.tilt.omega

    @property
    def covariance(self) -> FloatArray:
        """(6, 6) of [p, v], m² and (m/s)²."""
        return self.kf.P[0:6, 0:6]
