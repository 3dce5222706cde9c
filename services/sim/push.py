"""External pushes on the robot's base: the test and evaluation hook behind `dume/world/push`.

A push is a constant force in world axes on the base body's centre of mass for a whole
number of physics steps (`round(duration / dt)`, at least one), applied through MuJoCo's
`xfrc_applied` from the next step on: 200 N for 0.1 s is a 20 N·s impulse. Pushes that
overlap add up. `PushQueue` holds the active ones and writes their sum before each step;
the base body's `xfrc_applied` row belongs to it alone (nothing else in the sim uses it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from common.geometry import FloatArray

#: The longest push accepted, s (a push is an impulse, not a steady load), and the
#: strongest along each axis, N (a disturbance, not a catapult: a huge force blows the
#: physics up).
MAX_DURATION_S = 10.0
MAX_FORCE_N = 5000.0


class PushError(ValueError):
    """A push that cannot be applied (non-finite force, bad duration); says what was given."""


@dataclass
class _Active:
    force: FloatArray  # (3,) N in world
    steps_left: int


class PushQueue:
    """The active pushes on one body; `add` one, `apply` before every step."""

    def __init__(self, body_id: int, dt: float) -> None:
        self.body_id = body_id
        self.dt = dt
        self._active: list[_Active] = []
        self._written = False

    @property
    def active(self) -> bool:
        return bool(self._active)

    def add(self, force_in_world: ArrayLike, duration_s: float) -> int:
        """Push with `force_in_world` (3,) N for `duration_s` from the next step; the steps."""
        force = np.asarray(force_in_world, dtype=float)
        if force.shape != (3,) or not np.all(np.isfinite(force)):
            raise PushError(f"a push needs a finite force (3,) in N, got {force.tolist()}")
        if float(np.max(np.abs(force))) > MAX_FORCE_N:
            raise PushError(f"a push is at most {MAX_FORCE_N:g} N a side, got {force.tolist()}")
        if not (math.isfinite(duration_s) and 0.0 < duration_s <= MAX_DURATION_S):
            raise PushError(f"a push lasts (0, {MAX_DURATION_S}] s, got {duration_s}")
        steps = max(1, round(duration_s / self.dt))
        self._active.append(_Active(force.copy(), steps))
        return steps

    def apply(self, data: mujoco.MjData) -> None:
        """Write this step's force on the body (zero once every push has ended)."""
        if not self._active and not self._written:
            return
        total = np.zeros(3)
        for push in self._active:
            total += push.force
            push.steps_left -= 1
        self._active = [p for p in self._active if p.steps_left > 0]
        data.xfrc_applied[self.body_id, :3] = total
        data.xfrc_applied[self.body_id, 3:] = 0.0
        self._written = bool(total.any())
