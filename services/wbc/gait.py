"""Trot: schedule, velocity shaping, footholds and swing trajectories.

- `shape_velocity` clamps a (vx, vy, ωz) command to the limits and rate-limits it
  (`GaitSettings`, `wbc.gait`).
- `TrotGait` alternates the diagonal pairs (FL+RR, then FR+RL) with half a period each,
  swing and stance of equal length. It starts on the first nonzero command and stops at
  the end of a half-cycle once the shaped command is back near zero, so a stop always
  lands both swing feet before the robot stands.
- Footholds (Raibert + capture point): the hip's position at touchdown, plus half the
  stance's travel v_cmd T_st / 2, plus √(z/g) (v − v_cmd), which steps into a push.
  They are replanned every tick while the foot is in the air.
- Swing: xy blends from lift-off to the foothold with a quintic s(τ); z rises by
  `STEP_HEIGHT_M` as 64 τ³(1 − τ)³, zero velocity and acceleration at both ends.

Everything is in world coordinates on the plane z = 0; the gait holds only its phase,
lift-off points and the shaped command, and takes the time step from its caller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common import robot
from common.config import GaitSettings
from common.geometry import FloatArray

GRAVITY = 9.81
#: Diagonal pairs; pair 0 swings first.
PAIRS: tuple[tuple[int, ...], tuple[int, ...]] = ((0, 3), (1, 2))


#: Not settings (the command limits are `GaitSettings`, `wbc.gait`): the trot's period
#: (s), its step height (m), the shaped command below which it stops (m/s, rad/s), the
#: foothold's largest offset from the hip per axis (m) and the hips' (x, y) in the base (m).
TROT_PERIOD_S = 0.5
STEP_HEIGHT_M = 0.08
STOP_THRESHOLD = 0.02
MAX_STEP_M = 0.25
HIP_OFFSETS = np.array(
    [[0.3455, 0.19875], [0.3455, -0.19875], [-0.3455, 0.19875], [-0.3455, -0.19875]]
)
HIP_OFFSETS.flags.writeable = False


def shape_velocity(
    cmd: FloatArray, previous: FloatArray, dt: float, limits: GaitSettings
) -> FloatArray:
    """The command clamped to ±v_max, moved from `previous` by at most a_max dt per axis
    (d_max dt while it slows down)."""
    out = np.empty(3)
    for i, (c, prev, vmax, amax, dmax) in enumerate(
        zip(cmd.tolist(), previous.tolist(), limits.v_max, limits.a_max, limits.d_max, strict=True)
    ):
        target = min(max(c, -vmax), vmax)
        step = (dmax if prev * (target - prev) < 0.0 else amax) * dt
        out[i] = prev + min(max(target - prev, -step), step)
    return out


def quintic(tau: float) -> tuple[float, float, float]:
    """s, ds/dτ, d²s/dτ² of the quintic 10τ³ − 15τ⁴ + 6τ⁵ on [0, 1]."""
    t = min(max(tau, 0.0), 1.0)
    return (
        t**3 * (10 - 15 * t + 6 * t * t),
        30 * t * t * (1 - t) ** 2,
        60 * t * (1 - t) * (1 - 2 * t),
    )


def bump(tau: float) -> tuple[float, float, float]:
    """b, db/dτ, d²b/dτ² of 64 τ³ (1 − τ)³ (peak 1 at τ = ½)."""
    t = min(max(tau, 0.0), 1.0)
    u = 1.0 - t
    return (
        64 * t**3 * u**3,
        192 * t * t * u * u * (u - t),
        384 * t * u * (u * u - 3 * t * u + t * t),
    )


@dataclass
class SwingTarget:
    """A swing foot's reference: position, velocity, acceleration in world (3,) each."""

    p: FloatArray
    v: FloatArray
    a: FloatArray


class TrotGait:
    """The trot's state machine. `update` once per tick; read `stance` and `swing`."""

    def __init__(self, limits: GaitSettings) -> None:
        self.limits = limits
        self.cmd = np.zeros(3)  # shaped (vx, vy, ωz) in base_yaw
        self.walking = False
        self.phase = 0.0  # time into the current half-cycle, s
        self.pair = 0  # the swinging pair
        self.stance = np.ones(4)
        self.liftoff = np.zeros((4, 3))
        self.swing: dict[int, SwingTarget] = {}

    @property
    def half_period(self) -> float:
        return 0.5 * TROT_PERIOD_S

    def update(
        self,
        dt: float,
        cmd_vel: FloatArray,
        base_xy: FloatArray,
        base_yaw: float,
        com_velocity: FloatArray,
        com_height: float,
        feet: FloatArray,
    ) -> None:
        """Advance by dt. feet: (4, 3) foot positions now (world); velocities are world."""
        self.cmd = shape_velocity(cmd_vel, self.cmd, dt, self.limits)
        eps = STOP_THRESHOLD
        cx, cy, cz = cmd_vel.tolist()
        sx, sy, sz = self.cmd.tolist()
        moving = max(abs(cx), abs(cy), abs(cz), abs(sx), abs(sy), abs(sz)) > eps
        if not self.walking:
            if not moving:
                return
            self.walking, self.phase, self.pair = True, 0.0, 0
            self._lift(feet)
        else:
            self.phase += dt
            if self.phase >= self.half_period:
                self.phase -= self.half_period
                if not moving:
                    self.walking, self.stance[:], self.swing = False, 1.0, {}
                    return
                self.pair = 1 - self.pair
                self._lift(feet)
        self._plan_swing(base_xy, base_yaw, com_velocity, com_height)

    def _lift(self, feet: FloatArray) -> None:
        self.stance[:] = 1.0
        for k in PAIRS[self.pair]:
            self.stance[k] = 0.0
            self.liftoff[k] = feet[k]
            self.liftoff[k, 2] = robot.FOOT_RADIUS_M

    def foothold(
        self,
        k: int,
        base_xy: FloatArray,
        base_yaw: float,
        com_velocity: FloatArray,
        com_height: float,
    ) -> FloatArray:
        """Touchdown point (3,) of foot k for the current command (Raibert + capture point)."""
        bx, by = base_xy.tolist()
        vcx, vcy = com_velocity[0], com_velocity[1]
        return np.array(self._foothold(k, bx, by, base_yaw, float(vcx), float(vcy), com_height))

    def _foothold(
        self, k: int, bx: float, by: float, yaw: float, vcx: float, vcy: float, z: float
    ) -> tuple[float, float, float]:
        remaining = max(self.half_period - self.phase, 0.0)
        sx, sy, sz = self.cmd.tolist()
        c, s = math.cos(yaw), math.sin(yaw)
        vx = c * sx - s * sy  # the command in world
        vy = s * sx + c * sy
        yaw_td = yaw + sz * (remaining + 0.5 * self.half_period)
        c, s = math.cos(yaw_td), math.sin(yaw_td)
        hx, hy = HIP_OFFSETS[k].tolist()
        k_cp = math.sqrt(max(z, 0.0) / GRAVITY)
        half_stance = 0.5 * self.half_period
        lim = MAX_STEP_M
        ox = min(max(vx * half_stance + k_cp * (vcx - vx), -lim), lim)
        oy = min(max(vy * half_stance + k_cp * (vcy - vy), -lim), lim)
        return (
            bx + vx * remaining + c * hx - s * hy + ox,
            by + vy * remaining + s * hx + c * hy + oy,
            robot.FOOT_RADIUS_M,
        )

    def _plan_swing(
        self, base_xy: FloatArray, base_yaw: float, com_velocity: FloatArray, com_height: float
    ) -> None:
        T = self.half_period
        tau = self.phase / T
        s, ds, dds = quintic(tau)
        b, db, ddb = bump(tau)
        h = STEP_HEIGHT_M
        ds, dds, db, ddb = ds / T, dds / (T * T), db / T, ddb / (T * T)
        bx, by = base_xy.tolist()
        vcx, vcy = float(com_velocity[0]), float(com_velocity[1])
        self.swing = {}
        for k in PAIRS[self.pair]:  # in floats: this runs every tick for two feet
            tx, ty, tz = self._foothold(k, bx, by, base_yaw, vcx, vcy, com_height)
            x0, y0, z0 = self.liftoff[k].tolist()
            dx, dy, dz = tx - x0, ty - y0, tz - z0
            self.swing[k] = SwingTarget(
                p=np.array([x0 + dx * s, y0 + dy * s, z0 + dz * s + h * b]),
                v=np.array([dx * ds, dy * ds, dz * ds + h * db]),
                a=np.array([dx * dds, dy * dds, dz * dds + h * ddb]),
            )
