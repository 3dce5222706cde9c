"""What the robot's sensors measure, with their errors: the only view of the robot a
service gets (the truth travels on `…_truth` keys, for evaluation).

- `Imu`: MuJoCo's gyro and accelerometer at the trunk's `imu_link` (angular velocity and
  specific force in the IMU's frame), plus a bias that starts at a random offset and
  random-walks, plus white noise. A noise density n (unit/√Hz) sampled every dt is white
  noise of σ = n / √dt; a bias walk density w moves the bias by σ = w √dt a sample.
- `JointSensors`: absolute encoders quantise the joint angles to 2π / counts; the drives'
  velocity estimates carry white noise; the feet's force sensors carry white noise and
  report contact above a threshold.
- `Lidar`: a planar scan cast with `mujoco.mj_multiRay` from a lidar's site against
  every geom; beams that meet the robot itself, or nothing within range, read 0 (no
  return); the others get range noise; some are lost at random.
- `DepthNoise`: a stereo camera's depth: σ(z) = k z², no return across depth edges
  (stereo matching fails where a neighbour is more than `edge_jump_m` away), pixels lost
  at random.

Each model owns its random generator, seeded from the world's seed and its own name
(`rng_for`), so the same seed gives the same noise whatever else draws numbers, and it
draws in the order the sim calls it: every step for the IMU and joints, every scan; a
depth frame's noise comes from the seed, the camera and the frame's stamp.
"""

from __future__ import annotations

import math
import zlib

import mujoco
import numpy as np

from common import robot
from common.camera import stereo_depth
from common.config import (
    DepthNoiseSettings,
    ImuSettings,
    JointSensorSettings,
    LidarSettings,
    SensorSettings,
)
from common.geometry import FloatArray, make_T


def ideal_sensors() -> SensorSettings:
    """Sensors without error: positions unquantised, no noise, no bias, every beam
    returned, contact at any force (tests of the physics compare the state with it)."""
    return SensorSettings(
        imu=ImuSettings(
            gyro_noise_density=0.0, gyro_bias_walk=0.0, gyro_bias_initial=0.0,
            accel_noise_density=0.0, accel_bias_walk=0.0, accel_bias_initial=0.0,
        ),
        joints=JointSensorSettings(
            encoder_counts=0, velocity_noise=0.0, foot_force_noise=0.0, contact_force_n=0.0
        ),
        lidar=LidarSettings(range_noise_m=0.0, dropout=0.0),
        depth=DepthNoiseSettings(enabled=False),
    )  # fmt: skip


def rng_for(seed: int, name: str) -> np.random.Generator:
    """The generator of the sensor `name` in the world of `seed`."""
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


class Imu:
    """The trunk's IMU: `read(gyro, accel)` with the true values (IMU frame) gives the
    measured ones; `bias_gyro` and `bias_accel` are the biases now (truth, for tests)."""

    def __init__(self, s: ImuSettings, dt: float, rng: np.random.Generator) -> None:
        self.rng = rng
        self.bias_gyro: FloatArray = rng.normal(0.0, s.gyro_bias_initial, 3)
        self.bias_accel: FloatArray = rng.normal(0.0, s.accel_bias_initial, 3)
        self._white = np.array([s.gyro_noise_density] * 3 + [s.accel_noise_density] * 3)
        self._white /= math.sqrt(dt)
        self._walk = np.array([s.gyro_bias_walk] * 3 + [s.accel_bias_walk] * 3)
        self._walk *= math.sqrt(dt)

    def read(self, gyro: FloatArray, accel: FloatArray) -> tuple[FloatArray, FloatArray]:
        """One sample: (angular velocity rad/s, specific force m/s²), measured."""
        walk = self.rng.normal(0.0, 1.0, 6) * self._walk
        self.bias_gyro += walk[:3]
        self.bias_accel += walk[3:]
        white = self.rng.normal(0.0, 1.0, 6) * self._white
        return gyro + self.bias_gyro + white[:3], accel + self.bias_accel + white[3:]


class JointSensors:
    """Encoders, the drives' velocities and the feet's forces, measured."""

    def __init__(self, s: JointSensorSettings, rng: np.random.Generator) -> None:
        self.s, self.rng = s, rng
        self.step_rad = 2.0 * math.pi / s.encoder_counts if s.encoder_counts else 0.0

    def joints(self, q: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(positions quantised, velocities with noise), rad and rad/s."""
        q_meas = np.round(q / self.step_rad) * self.step_rad if self.step_rad else q.copy()
        v_meas = v + self.rng.normal(0.0, self.s.velocity_noise, v.shape)
        return q_meas, v_meas

    def feet(self, force: FloatArray) -> tuple[FloatArray, tuple[bool, bool, bool, bool]]:
        """(normal forces N, never below 0; in contact, above the threshold), FL FR RL RR."""
        measured = np.maximum(force + self.rng.normal(0.0, self.s.foot_force_noise, 4), 0.0)
        fl, fr, rl, rr = (bool(f > self.s.contact_force_n) for f in measured)
        return measured, (fl, fr, rl, rr)


class Lidar:
    """The planar scanner at a mount's site (`robot.LIDAR_MOUNT`, the trunk's front, or
    `LIDAR_REAR_MOUNT`): `scan(data)` → ranges (m, float32, 0 = no return), beam k at
    `angles[k]` (rad, counter-clockwise from the site's x)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        s: LidarSettings,
        rng: np.random.Generator,
        mount: robot.LidarMount | None = None,
    ):
        self.model, self.s, self.rng = model, s, rng
        self.mount = mount or robot.LIDAR_MOUNT
        self.site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, self.mount.name)
        if self.site < 0:
            raise KeyError(f"the model has no site {self.mount.name!r}")
        half = math.radians(s.fov_deg) / 2.0
        self.angles: FloatArray = np.linspace(-half, half, s.beams)
        self.angle_increment = float(self.angles[1] - self.angles[0])
        #: The beams in the site's frame (planar: z = 0).
        self._local = np.stack([np.cos(self.angles), np.sin(self.angles), np.zeros(s.beams)])
        base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, robot.BASE_FRAME)
        root = model.body_rootid[base]
        self._robot_geom = model.body_rootid[model.geom_bodyid] == root
        self._geom = np.zeros(s.beams, dtype=np.int32)
        self._dist = np.zeros(s.beams)

    def T_world_lidar(self, data: mujoco.MjData) -> FloatArray:
        """The lidar's frame in the world as `data` stands (truth)."""
        return make_T(data.site_xmat[self.site].reshape(3, 3), data.site_xpos[self.site])

    def scan(self, data: mujoco.MjData) -> FloatArray:
        s = self.s
        R = data.site_xmat[self.site].reshape(3, 3)
        vec = np.ascontiguousarray((R @ self._local).T).ravel()
        origin = data.site_xpos[self.site].copy()
        mujoco.mj_multiRay(
            self.model, data, origin, vec, None, 1, -1, self._geom, self._dist, None,
            s.beams, s.range_max_m,
        )  # fmt: skip
        r = self._dist.copy()
        hit = self._geom >= 0
        mine = hit & self._robot_geom[np.maximum(self._geom, 0)]
        r += self.rng.normal(0.0, s.range_noise_m, s.beams)
        lost = self.rng.random(s.beams) < s.dropout
        bad = ~hit | mine | lost | (r < s.range_min_m) | (r > s.range_max_m)
        r[bad] = 0.0
        return r.astype(np.float32)


class DepthNoise:
    """`apply(depth, camera, stamp_ns)`: a rendered depth image (m along the axis, 0 = no
    return) as the stereo camera would measure it. Each frame's noise is drawn from its
    own generator (the world's seed, the camera, the stamp): the same whichever frames
    were rendered before it."""

    def __init__(self, s: DepthNoiseSettings, seed: int) -> None:
        self.s, self.seed = s, seed

    def apply(self, depth: np.ndarray, camera: str, stamp_ns: int) -> np.ndarray:
        s = self.s
        rng = np.random.default_rng([self.seed, zlib.crc32(camera.encode()), stamp_ns])
        return stereo_depth(depth, s.sigma_per_m2, s.edge_jump_m, s.dropout, rng)
