"""The robot's sensors: the lidar measures geometry, the IMU reads gravity and its noise
has the datasheet's size, encoders quantise, depth loses its edges; seeded noise repeats."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

import math

import mujoco
import numpy as np
import pytest

from common import robot
from common.config import (
    DepthNoiseSettings,
    ImuSettings,
    JointSensorSettings,
    LidarSettings,
    SensorSettings,
)
from services.sim import mjcf
from services.sim.core import SimCore
from services.sim.hold import StandHold
from services.sim.sensors import DepthNoise, Imu, JointSensors, Lidar, ideal_sensors, rng_for
from services.sim.world import generate_world

WALL_X = 2.0  # the wall's face in front of the robot, m
WALL_HALF_Y = 3.0


def step(core: SimCore, law: StandHold) -> None:
    """One tick of the stand-hold: state, command, step."""
    t = core.robot_state().stamp_ns
    core.command(law.tau_ff, law.q_des, law.v_des, law.kp, law.kd, t)
    core.step()


def wall_scene(side: float = 1.0) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The robot standing at the origin facing +x, a wall's face at x = WALL_X (`side`
    −1: at x = −WALL_X, behind it)."""
    spec = mjcf.robot_spec()
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[20, 20, 0.1])
    spec.worldbody.add_geom(
        name="wall", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.1, WALL_HALF_Y, 0.6],
        pos=[side * (WALL_X + 0.1), 0.0, 0.6],
    )  # fmt: skip
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[:] = mjcf.q_pin_to_mj(robot.standing_q("stand"))
    mujoco.mj_forward(model, data)
    return model, data


def test_the_ideal_lidar_measures_the_wall_and_masks_the_robot() -> None:
    model, data = wall_scene()
    lidar = Lidar(model, ideal_sensors().lidar, rng_for(0, "lidar"))
    T = lidar.T_world_lidar(data)
    mount = robot.LIDAR_MOUNT.T_parent_lidar  # the base stands level at the origin
    np.testing.assert_allclose(T[:3, 3][:2], mount[:3, 3][:2], atol=1e-9)
    r = lidar.scan(data).astype(float)
    a = lidar.angles
    x0, y0 = T[0, 3], T[1, 3]
    on_wall = np.abs(a) < math.atan2(WALL_HALF_Y - 0.05, WALL_X - x0)
    expected = (WALL_X - x0) / np.cos(a[on_wall])
    np.testing.assert_allclose(r[on_wall], expected, atol=1e-4)
    assert on_wall.sum() > 100 and y0 == pytest.approx(0.0, abs=1e-9)
    # Beams far behind meet the robot's own legs: masked, no return.
    behind = np.abs(a) > math.radians(110.0)
    assert behind.any() and np.all(r[behind] == 0.0)


def test_the_rear_lidar_measures_the_wall_behind_and_the_two_fields_cover_all_round() -> None:
    model, data = wall_scene(side=-1.0)
    rear = Lidar(model, ideal_sensors().lidar, rng_for(0, "lidar_rear"), robot.LIDAR_REAR_MOUNT)
    T = rear.T_world_lidar(data)
    assert T[0, 3] == pytest.approx(-0.46, abs=1e-6) and T[0, 0] == pytest.approx(-1.0)
    r = rear.scan(data).astype(float)
    a = rear.angles  # from the rear lidar's x: straight back
    on_wall = np.abs(a) < math.atan2(WALL_HALF_Y - 0.05, WALL_X + T[0, 3])
    np.testing.assert_allclose(r[on_wall], (WALL_X + T[0, 3]) / np.cos(a[on_wall]), atol=1e-4)
    assert np.all(r[np.abs(a) > math.radians(110.0)] == 0.0)  # its own legs, ahead: masked
    # Every heading round the base is in one field or the other, beyond the legs.
    front = Lidar(model, ideal_sensors().lidar, rng_for(0, "lidar"))
    seen = []
    for lidar in (front, rear):
        Tl = lidar.T_world_lidar(data)
        heading = math.atan2(Tl[1, 0], Tl[0, 0])
        clear = lidar.angles[~_masked(lidar, data)]  # beams past the robot's own body
        seen.append(np.unique(np.floor(np.mod(clear + heading, math.tau) / math.radians(5.0))))
    assert len(seen[0]) < 50  # the front one alone: 270° less its legs
    assert len(np.union1d(*seen)) == 72  # together: every 5° sector round the robot


def _masked(lidar: Lidar, data: mujoco.MjData) -> np.ndarray:
    """The beams that meet the robot's own body (cast against the robot alone)."""
    r = np.zeros(len(lidar.angles), dtype=np.int32)
    d = np.zeros(len(lidar.angles))
    R = data.site_xmat[lidar.site].reshape(3, 3)
    vec = np.ascontiguousarray((R @ lidar._local).T).ravel()
    mujoco.mj_multiRay(lidar.model, data, data.site_xpos[lidar.site].copy(), vec, None, 1, -1,
                       r, d, None, len(lidar.angles), lidar.s.range_max_m)  # fmt: skip
    return (r >= 0) & lidar._robot_geom[np.maximum(r, 0)]


def test_the_lidar_noise_and_dropouts_have_their_settings_size() -> None:
    model, data = wall_scene()
    s = LidarSettings(range_noise_m=0.02, dropout=0.05)
    lidar = Lidar(model, s, rng_for(3, "lidar"))
    ideal = Lidar(model, ideal_sensors().lidar, rng_for(3, "lidar")).scan(data).astype(float)
    hit = ideal > 0
    scans = np.array([lidar.scan(data) for _ in range(40)], dtype=float)[:, hit]
    returned = scans > 0
    assert 1.0 - returned.mean() == pytest.approx(0.05, abs=0.01)
    residual = (scans - ideal[hit])[returned]
    assert residual.std() == pytest.approx(0.02, rel=0.05)
    assert abs(residual.mean()) < 0.002


def test_white_noise_and_bias_walk_follow_their_densities() -> None:
    s = ImuSettings(
        gyro_noise_density=2e-4, gyro_bias_walk=1e-3, gyro_bias_initial=0.0,
        accel_noise_density=2e-3, accel_bias_walk=0.0, accel_bias_initial=0.0,
    )  # fmt: skip
    dt = 1e-3
    # White noise: σ = density / √dt, about the (walking) bias.
    imu = Imu(s, dt, rng_for(1, "imu"))
    zero = np.zeros(3)
    samples = np.array([np.concatenate(imu.read(zero, zero)) for _ in range(4000)])
    assert samples[:, 3:].std(axis=0) == pytest.approx([2e-3 / math.sqrt(dt)] * 3, rel=0.05)
    # Bias walk: after n steps the bias's spread is walk √(n dt), over many IMUs.
    n = 1000
    biases = []
    for k in range(300):
        imu = Imu(s, dt, rng_for(k, "imu"))
        for _ in range(n):
            imu.read(zero, zero)
        biases.append(imu.bias_gyro.copy())
    assert np.std(biases) == pytest.approx(1e-3 * math.sqrt(n * dt), rel=0.1)


def test_a_standing_robot_s_imu_reads_gravity_and_no_rotation() -> None:
    core = SimCore(generate_world(0, "small"), sensors=ideal_sensors())
    hold = StandHold()
    forces, rates = [], []
    for _ in range(1500):
        step(core, hold)
        forces.append(core.robot_state().imu_specific_force)
        rates.append(core.robot_state().imu_angular_velocity)
    f, w = np.mean(forces[-500:], axis=0), np.mean(rates[-500:], axis=0)
    np.testing.assert_allclose(f, [0.0, 0.0, 9.81], atol=0.15)
    np.testing.assert_allclose(w, 0.0, atol=0.01)


def test_encoders_quantise_and_feet_report_contact_above_the_threshold() -> None:
    s = JointSensorSettings(
        encoder_counts=4096, velocity_noise=0.0, foot_force_noise=0.0, contact_force_n=20.0
    )
    sensors = JointSensors(s, rng_for(0, "joints"))
    q = np.linspace(-2.0, 2.0, 19)
    q_meas, v_meas = sensors.joints(q, np.ones(19))
    step = 2 * math.pi / 4096
    np.testing.assert_allclose(q_meas / step, np.round(q_meas / step), atol=1e-9)
    assert np.max(np.abs(q_meas - q)) <= step / 2 + 1e-12
    np.testing.assert_array_equal(v_meas, 1.0)
    forces, contacts = sensors.feet(np.array([0.0, 10.0, 25.0, 150.0]))
    assert contacts == (False, False, True, True)
    np.testing.assert_array_equal(forces, [0.0, 10.0, 25.0, 150.0])


def test_depth_loses_its_edges_and_grows_noisy_with_range() -> None:
    depth = np.full((60, 80), 1.0, dtype=np.float32)
    depth[:, 40:] = 4.0  # an edge: a near board against a far wall
    depth[:5, :] = 0.0  # no return
    noise = DepthNoise(DepthNoiseSettings(sigma_per_m2=0.004, dropout=0.0), seed=0)
    out = noise.apply(depth, "camera_head", 100)
    assert out.dtype == np.float32
    assert np.all(out[:5] == 0.0)
    assert np.all(out[10:, 40] == 0.0)  # the far side of the edge is lost …
    assert np.all(out[10:, 39] > 0.0)  # … the near one keeps its depth
    assert np.all(out[5, :40] > 0.0)  # beside no return: kept
    near, far = out[10:, :30] - 1.0, out[10:, 50:] - 4.0
    assert near.std() == pytest.approx(0.004, rel=0.1)
    assert far.std() == pytest.approx(0.004 * 16, rel=0.1)
    # The same frame gets the same noise; another stamp, other noise.
    np.testing.assert_array_equal(out, noise.apply(depth, "camera_head", 100))
    assert not np.array_equal(out, noise.apply(depth, "camera_head", 200))


def test_the_same_seed_gives_the_same_measurements() -> None:
    world = generate_world(2, "small")

    def run() -> list[tuple[float, ...]]:
        core = SimCore(world, sensors=SensorSettings())
        hold = StandHold()
        out = []
        for _ in range(50):
            step(core, hold)
            s = core.robot_state()
            out.append((*s.imu_angular_velocity, *s.imu_specific_force, *s.foot_forces))
        return out

    assert run() == run()
