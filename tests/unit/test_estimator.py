"""The leg-inertial estimator: the tilt filter finds gravity and the gyro's bias, the
Kalman filter finds the base's velocity and height from stance feet, the kinematic
terms it is fed agree with finite differences, and on the simulated robot's noisy
sensors it tracks the truth."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

import math

import numpy as np
import pinocchio as pin
import pytest

from common import robot
from common.config import EstimatorSettings, SensorSettings
from services.sim.core import SimCore
from services.sim.hold import StandHold
from services.sim.world import generate_world
from services.wbc.estimator import (
    Correction,
    G,
    LegInertialEstimator,
    LegKalman,
    TiltFilter,
    tilt_from_gravity,
)
from services.wbc.model import RobotModel

UP = np.array([0.0, 0.0, G])


def angle_between(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """The rotation angle of Raᵀ Rb, rad."""
    return float(np.linalg.norm(pin.log3(Ra.T @ Rb)))


def tilt_error(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """The angle between the up directions the two rotations see in the body (roll and
    pitch, not yaw), rad."""
    return math.acos(min(1.0, float(Ra[2] @ Rb[2])))


def test_tilt_from_gravity_recovers_roll_and_pitch() -> None:
    R = np.asarray(pin.rpy.rpyToMatrix(0.2, -0.15, 0.7))
    R0 = tilt_from_gravity(R.T @ UP, yaw=0.7)
    assert angle_between(R, R0) < 1e-9


def test_the_tilt_filter_converges_from_a_wrong_start_and_learns_the_bias() -> None:
    """At rest, tilted 5° wrongly, with a gyro bias of 0.01 rad/s on every axis: gravity
    pulls roll and pitch back, and the roll and pitch bias is learnt (gravity's pull at
    1/s, ten times the default: the stance feet do most of the work on a robot)."""
    s = EstimatorSettings(tilt_kp=1.0)
    f = TiltFilter(s)
    R_true = np.asarray(pin.rpy.rpyToMatrix(0.05, 0.03, 0.4))
    f.R = np.asarray(pin.rpy.rpyToMatrix(0.05 + math.radians(5), 0.03, 0.4))
    bias = np.full(3, 0.01)
    dt = 0.005
    for _ in range(int(10 / dt)):
        f.update(bias, R_true.T @ UP, dt)
    # The 5° are gone; what is left is the bias not yet learnt, bias / kp ≈ 0.6°.
    assert tilt_error(f.R, R_true) < math.radians(1.0)
    for _ in range(int(140 / dt)):
        f.update(bias, R_true.T @ UP, dt)
    assert tilt_error(f.R, R_true) < math.radians(0.05)
    # The bias on the axes gravity sees (orthogonal to up, in the body) is learnt.
    up_body = R_true.T @ np.array([0.0, 0.0, 1.0])
    seen = lambda b: b - (b @ up_body) * up_body  # noqa: E731
    assert np.linalg.norm(seen(f.bias) - seen(bias)) < 1e-3


def feet_of_a_tilted_stance(R_tilt: np.ndarray) -> np.ndarray:
    """(4, 3) the feet's centres in the base (pinocchio forward kinematics, as the
    controller's model has them) for joints that stand the base tilted by `R_tilt` on a
    flat floor: each leg solved (Gauss-Newton on its foot) to put its foot where the
    standing posture's foot is, seen from a base turned by `R_tilt`."""
    model = RobotModel()
    q = np.concatenate([np.zeros(3), [0.0, 0.0, 0.0, 1.0], robot.POSTURES["stand"]])
    v = np.zeros(model.nv)
    model.update(q, v, tcp=False)
    target = model.feet_p @ R_tilt  # R_tiltᵀ r, per foot
    for _ in range(30):
        model.update(q, v, tcp=False)
        err = (target - model.feet_p).ravel()
        dq = np.linalg.lstsq(model.Jc[:, 6:], err, rcond=None)[0]
        q[7:] += dq
    model.update(q, v, tcp=False)
    assert np.abs(model.feet_p - target).max() < 1e-9
    return model.feet_p.copy()


@pytest.mark.parametrize("gait", ["stand", "trot"])
def test_the_stance_feet_give_roll_and_pitch_on_a_flat_floor(gait: str) -> None:
    """The legs' kinematics of a base rolled 4° and pitched −3° over a flat floor: the
    floor's plane pulls a level estimate to that tilt, with four feet down or with a
    trot's two diagonal pairs in turn (each observes one axis), gravity's pull off."""
    R_tilt = np.asarray(pin.rpy.rpyToMatrix(math.radians(4), math.radians(-3), 0.0))
    feet = feet_of_a_tilted_stance(R_tilt)
    s = EstimatorSettings(tilt_kp=0.0, tilt_ki=0.0)
    f = TiltFilter(s)
    yaw = np.asarray(pin.rpy.rpyToMatrix(0.0, 0.0, 0.7))
    R_true = yaw @ R_tilt
    f.R = yaw.copy()  # level: 5° off
    assert tilt_error(f.R, R_true) > math.radians(4.9)
    dt = 0.002
    for k in range(int(4.0 / dt)):
        if gait == "stand":
            contact = (True, True, True, True)
        else:  # FL+RR, then FR+RL, 0.25 s each
            first = (k * dt) % 0.5 < 0.25
            contact = (first, not first, not first, first)
        f.correct_floor(feet, contact, dt)
    assert tilt_error(f.R, R_true) < math.radians(0.02)
    # One foot down says nothing; a pair sloping past `floor_gate` (a slip) is left out.
    R = f.R.copy()
    f.correct_floor(feet, (True, False, False, False), dt)
    assert np.allclose(f.R, R)
    slipped = feet.copy()
    slipped[0, 2] += 0.5
    f.correct_floor(slipped, (True, False, False, True), dt)
    assert np.allclose(f.R, R)


#: Four feet on the floor around the base, relative to it (m, odom axes).
FEET = np.array(
    [[0.35, 0.25, -0.5], [0.35, -0.25, -0.5], [-0.35, 0.25, -0.5], [-0.35, -0.25, -0.5]]
)


def tick(
    est: LegInertialEstimator,
    gyro: np.ndarray,
    f: np.ndarray = UP,
    dt: float = 0.002,
    standing: bool = True,
    rate: np.ndarray | None = None,
) -> None:
    """One tick of a base over fixed feet turning at `rate` (world axes; default still):
    predict with the IMU, correct with what the legs' kinematics would show."""
    est.predict(gyro, f, dt, (True,) * 4, standing)
    w_true = np.zeros(3) if rate is None else rate
    # The model's foot velocity less the base's: (ω̂ − ω) × p (the feet do not move).
    rel_v = np.cross(est._omega_used - w_true, FEET)
    est.correct(Correction(FEET, rel_v, (True,) * 4))


def test_the_tilt_filter_integrates_a_turn_and_calibration_removes_the_yaw_bias() -> None:
    s = EstimatorSettings()
    est = LegInertialEstimator(s)
    est.start(UP, np.zeros(3), 0.0, np.zeros((4, 3)))
    bias = np.array([0.0, 0.0, 0.02])
    dt = 0.002
    for _ in range(int(s.calibrate_s / dt) + 1):  # at rest: the bias is measured
        tick(est, bias, dt=dt)
    assert not est.calibrating
    assert abs(est.tilt.bias[2] - 0.02) < 1e-9
    yaw0 = math.atan2(est.R[1, 0], est.R[0, 0])
    rate, seconds = 0.5, 2.0
    for _ in range(round(seconds / dt)):  # turn at 0.5 rad/s about z (gravity unchanged)
        spin = np.array([0.0, 0.0, rate])
        tick(est, bias + spin, dt=dt, standing=False, rate=spin)
    yaw = math.atan2(est.R[1, 0], est.R[0, 0])
    assert abs(yaw - yaw0 - rate * seconds) < 1e-6


def walking_feet(p: np.ndarray) -> np.ndarray:
    """(4, 3) feet at the robot's stance corners around the base at p, on the floor."""
    corners = np.array([[0.35, 0.25], [0.35, -0.25], [-0.35, 0.25], [-0.35, -0.25]])
    feet = np.zeros((4, 3))
    feet[:, :2] = p[:2] + corners
    feet[:, 2] = robot.FOOT_RADIUS_M
    return feet


def test_the_kalman_filter_finds_the_velocity_from_stance_feet() -> None:
    """The base moves at 0.5 m/s in x over feet that stand still (all in stance); the
    filter starts believing it is at rest and is fed a biased, noisy accelerometer."""
    s = EstimatorSettings()
    kf = LegKalman(s)
    rng = np.random.default_rng(0)
    v = np.array([0.5, 0.0, 0.0])
    p = np.array([0.0, 0.0, 0.5])
    feet = walking_feet(p)
    kf.reset(p, feet - p)
    dt = 0.002
    for _ in range(int(2.0 / dt)):
        p = p + v * dt
        a = np.array([0.0, 0.0, 0.05]) + rng.normal(0.0, 0.05, 3)  # a bias on z
        kf.predict(a, dt, (True,) * 4)
        kf.correct(
            Correction(
                rel_position=feet - p + rng.normal(0.0, 0.002, (4, 3)),
                rel_velocity=np.tile(-v, (4, 1)) + rng.normal(0.0, 0.02, (4, 3)),
                contact=(True,) * 4,
            )
        )
    assert np.linalg.norm(kf.velocity - v) < 0.01
    assert abs(kf.position[2] - p[2]) < 0.003  # the height, from the feet on the floor
    # x, y drift: the velocity was found within the first moments; the rest is small.
    assert np.linalg.norm(kf.position[:2] - p[:2]) < 0.02
    cov = kf.P[0:6, 0:6]
    assert np.all(np.linalg.eigvalsh(cov) > 0.0)


def test_a_swing_foot_does_not_pull_the_velocity() -> None:
    """Two feet in swing report a velocity that is not the base's (they move forward): the
    filter follows the two in stance."""
    s = EstimatorSettings()
    kf = LegKalman(s)
    v = np.array([0.3, 0.1, 0.0])
    p = np.array([0.0, 0.0, 0.5])
    feet = walking_feet(p)
    kf.reset(p, feet - p)
    contact = (True, False, False, True)
    dt = 0.002
    for _ in range(int(1.0 / dt)):
        p = p + v * dt
        feet[1:3] += 2 * v * dt  # the swing feet move at twice the base's speed
        rel_v = np.tile(-v, (4, 1))
        rel_v[1:3] += 2 * v
        kf.predict(np.zeros(3), dt, contact)
        kf.correct(Correction(feet - p, rel_v, contact))
    assert np.linalg.norm(kf.velocity - v) < 0.005


def test_the_model_gives_the_feet_velocity_its_positions_change_by() -> None:
    """What `correct` is fed: the model's feet velocities (LWA) agree with finite
    differences of their positions under the same (q, v)."""
    m = RobotModel()
    rng = np.random.default_rng(1)
    q = robot.standing_q()
    q[7:] += rng.uniform(-0.2, 0.2, 19)
    q[3:7] = np.array([0.05, -0.04, 0.3, 1.0]) / np.linalg.norm([0.05, -0.04, 0.3, 1.0])
    v = rng.normal(0.0, 0.5, m.nv)
    m.update(q, v, tcp=False)
    p0, vel = m.feet_p.copy(), m.v_feet.reshape(4, 3).copy()
    h = 1e-6
    m.update(pin.integrate(m.model, q, v * h), v, tcp=False)
    fd = (m.feet_p - p0) / h
    assert np.allclose(fd, vel, atol=1e-4)


def test_on_the_simulated_robots_sensors_standing_it_tracks_the_truth() -> None:
    """The robot stands 3 s in the sim under its stand-hold, with the configured sensor
    noise: the estimate's height, tilt and velocity follow MuJoCo's free joint."""
    world = generate_world(0, "small")
    core = SimCore(world, sensors=SensorSettings())
    law = StandHold()
    s = EstimatorSettings()
    est = LegInertialEstimator(s)
    model = RobotModel()
    dt = core.dt
    heights, tilts, speeds = [], [], []
    for k in range(int(3.0 / dt)):
        state = core.robot_state()
        truth = core.state_truth()
        joints = np.frombuffer(state.q.data)
        q = np.concatenate([est.position, pin.Quaternion(est.R).coeffs(), joints])
        contact = tuple(state.foot_contacts)
        if not est.started:
            t_xyzw = np.array(truth.base_orientation_xyzw)
            yaw = robot_yaw(t_xyzw)
            f0 = np.array(state.imu_specific_force)
            q[3:7] = pin.Quaternion(tilt_from_gravity(f0, yaw)).coeffs()
            model.update(q, np.zeros(model.nv), tcp=False)
            rel = model.feet_p - model.q[:3]
            p0 = np.array(truth.base_position_in_world)
            est.start(np.array(state.imu_specific_force), p0, yaw, rel)
        else:
            est.predict(
                np.array(state.imu_angular_velocity),
                np.array(state.imu_specific_force),
                dt,
                contact,
            )
            q[:3] = est.position
            q[3:7] = pin.Quaternion(est.R).coeffs()
            v = np.concatenate(
                [est.R.T @ est.velocity, est.angular_velocity, np.frombuffer(state.v.data)]
            )
            model.update(q, v, tcp=False)
            rel_v = model.v_feet.reshape(4, 3) - est.velocity
            est.correct(Correction(model.feet_p - model.q[:3], rel_v, contact))
        core.command(law.tau_ff, law.q_des, law.v_des, law.kp, law.kd, state.stamp_ns)
        core.step()
        if k * dt > 1.5:
            xyzw = np.array(truth.base_orientation_xyzw)
            R_true = np.asarray(pin.Quaternion(xyzw).toRotationMatrix())
            heights.append(abs(est.position[2] - truth.base_position_in_world[2]))
            tilts.append(tilt_error(est.R, R_true))
            speeds.append(np.linalg.norm(est.velocity - truth.base_linear_velocity_in_world))
    assert max(heights) < 0.01
    assert max(tilts) < math.radians(1.0)  # the accelerometer's bias: ~0.6° (module doc)
    assert float(np.sqrt(np.mean(np.square(speeds)))) < 0.03


def robot_yaw(xyzw: np.ndarray) -> float:
    R = np.asarray(pin.Quaternion(xyzw).toRotationMatrix())
    return math.atan2(R[1, 0], R[0, 0])


def test_every_unbroken_standstill_measures_the_gyros_bias_again() -> None:
    s = EstimatorSettings()
    est = LegInertialEstimator(s)
    est.start(UP, np.zeros(3), 0.0, np.zeros((4, 3)))
    dt = 0.002
    b1, b2 = np.array([0.0, 0.0, 0.002]), np.array([0.0, 0.0, -0.004])
    for _ in range(int(s.calibrate_s / dt) + 1):
        tick(est, b1)
    assert not est.calibrating and est.tilt.bias[2] == pytest.approx(0.002)
    for _ in range(500):  # walking: the bias wanders to b2, nothing measures it
        tick(est, b2, standing=False)
    half = int(0.5 * s.calibrate_s / dt)
    for _ in range(half):  # half a window, then a jolt: the window starts again
        tick(est, b2)
    tick(est, b2, UP + np.array([0.0, 0.0, 1.0]))
    for _ in range(half + 10):
        tick(est, b2)
    assert est.recalibrations == 0 and est.tilt.bias[2] == pytest.approx(0.002)
    for _ in range(half):
        tick(est, b2)
    assert est.recalibrations == 1 and est.tilt.bias[2] == pytest.approx(-0.004)


def test_the_bias_is_found_when_the_controller_turns_the_robot_against_it() -> None:
    """Standing, the controller holds the estimated heading: the base turns at minus the
    gyro's bias and the gyro reads nothing. The legs show the turn: the bias is found."""
    s = EstimatorSettings()
    est = LegInertialEstimator(s)
    est.start(UP, np.zeros(3), 0.0, np.zeros((4, 3)))
    bias = np.array([0.001, -0.002, -0.0026])
    for _ in range(int(s.calibrate_s / 0.002) + 1):
        tick(est, np.zeros(3), rate=-bias)  # gyro = bias + true rate = 0
    assert not est.calibrating
    np.testing.assert_allclose(est.tilt.bias, bias, atol=1e-6)
