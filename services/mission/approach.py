"""approach_object's visual servoing: the paper's two proportional controllers (eq. 3).

ξ = K (χ − χ_opt) on χ = (d_obj, θ_obj), the object's distance and heading in `base_yaw`
from the wrist camera, toward (`D_OPT_M`, `THETA_OPT_RAD`) of `common.robot`: vx from the
distance error (slowed while the heading is off, so the robot turns first), ωz from the
heading error, vy zero. Commands are clipped to speed limits and rate-limited to
acceleration limits. The gains, limits and times are settings (`ApproachSettings`,
`mission.approach_gains`). The states:

- tracking: a sighting no older than `max_age_s` drives the controllers; between
  `max_age_s` and `lost_after_s` without one the base slows to a stop and waits.
- arrived: both errors within tolerance on every sighting for `settle_s`; latched (zero
  command) until `reset`. Or blocked short of d_opt: the heading within tolerance, the
  distance within `blocked_slack_m` beyond d_opt, and no sighting `progress_m` nearer
  than the nearest one for `stall_s` while tracking (the legs stopped short of the
  support's front: the mission's commands keep the body off the static world, see
  `robot.within_room`; before, a hip pressed against it: a can 11 cm deep on a bench,
  seen at 0.77 m for 36 s, failed on the 40 s timeout).
  The arm's comfortable side grasps span d_opt ± 0.28 m (`common.robot`), so a base a
  few cm short still grasps comfortably; the reason says how far short it stopped.
- reacquiring: no sighting for `lost_after_s`: turn toward the last seen bearing (as
  far as it was off) and, when it was last seen beyond d_opt, creep toward it (as far
  as it was beyond), else back off slowly; a sighting returns to tracking.
- failed (latched, with a reason): reacquiring found nothing within `reacquire_s`, or no
  arrival within `timeout_s` of `reset` — the controller never freezes.

A command the caller could not give in full (`hold`: a person near the base, the speed
and separation monitor's caps) is no stall: the blocked arrival waits `stall_s` from the
hold, and the time held does not count against `timeout_s`.

Pure: sightings and sim time (seconds) in, a command out; no clock reads, no transport.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from common.config import ApproachSettings
from common.robot import D_OPT_M, THETA_OPT_RAD

ApproachState = Literal["tracking", "reacquiring", "arrived", "failed"]
#: Not a setting: holds (`hold`) at most this far apart (s) are one span of being held.
HELD_GAP_S = 0.5


@dataclass(frozen=True)
class Sighting:
    """The object seen: d_obj (m) and θ_obj (rad) in `base_yaw` at capture `stamp_s` (sim s)."""

    d_obj: float
    theta_obj: float
    stamp_s: float


@dataclass(frozen=True)
class ApproachCommand:
    """Base velocity in `base_yaw` (m/s, m/s, rad/s), the state, and why (for a person)."""

    vx: float
    vy: float
    wz: float
    state: ApproachState
    reason: str = ""


def _usable(seen: Sighting | None) -> bool:
    return (
        seen is not None
        and all(math.isfinite(x) for x in (seen.d_obj, seen.theta_obj, seen.stamp_s))
        and seen.d_obj >= 0.0
    )


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class ApproachController:
    """See the module docstring: `reset(t)` at the start, then `step(t, sighting)` each tick."""

    def __init__(self, gains: ApproachSettings | None = None) -> None:
        self.gains = gains or ApproachSettings()
        self.reset(0.0)

    def reset(self, t_s: float) -> None:
        """Start an approach at sim time `t_s` (s): nothing seen, base at rest."""
        self._t0 = t_s
        self._t_last: float | None = None
        self._v = (0.0, 0.0)  # vx, wz last commanded
        self._last: Sighting | None = None
        self._in_tol_since: float | None = None
        self._lost_since: float | None = None
        self._backed_m = 0.0
        self._latched: ApproachCommand | None = None
        self._nearest: Sighting | None = None  # the nearest sighting, by progress_m steps
        self._held_at = -math.inf  # when the base was last held back (`hold`)
        self._held_s = 0.0  # for how long in all

    def hold(self, t_s: float) -> None:
        """The command of sim time `t_s` was held back (a person near the base: the speed
        and separation monitor's caps): no progress while held is a block, and the time
        held does not count against `timeout_s`."""
        if 0.0 < t_s - self._held_at <= HELD_GAP_S:
            self._held_s += t_s - self._held_at
        self._held_at = t_s

    @property
    def held_s(self) -> float:
        """Sim seconds held back since `reset` (`hold`), in all."""
        return self._held_s

    @property
    def last_sighting(self) -> Sighting | None:
        """The newest usable sighting since `reset`."""
        return self._last

    def errors(self) -> tuple[float, float] | None:
        """(d_obj − d_opt m, θ_obj − θ_opt rad) of the newest sighting, if any."""
        if self._last is None:
            return None
        return self._last.d_obj - D_OPT_M, _wrap(self._last.theta_obj - THETA_OPT_RAD)

    def step(self, t_s: float, seen: Sighting | None) -> ApproachCommand:
        """The command at sim time `t_s` (s), given the newest sighting (None: none)."""
        if self._latched is not None:
            return self._latched
        g = self.gains
        dt = 0.0 if self._t_last is None else max(0.0, t_s - self._t_last)
        self._t_last = t_s
        if (
            _usable(seen)
            and seen is not None
            and (self._last is None or seen.stamp_s >= self._last.stamp_s)
        ):
            if self._last is None or seen.stamp_s > self._last.stamp_s:
                self._on_new_sighting(seen)
            self._last = seen
        elapsed = t_s - self._t0 - self._held_s
        if elapsed > g.timeout_s:
            return self._latch("failed", f"not arrived {elapsed:.1f} s after the start")
        age = math.inf if self._last is None else t_s - self._last.stamp_s
        settled = self._in_tol_since is not None and t_s - self._in_tol_since >= g.settle_s
        if settled and age <= g.max_age_s:
            return self._latch("arrived", self._error_text())
        if age <= g.max_age_s and self._blocked(t_s):
            return self._latch(
                "arrived", f"blocked short of d_opt, no nearer in {g.stall_s:.0f} s: "
                f"{self._error_text()}"
            )  # fmt: skip
        if age <= g.max_age_s and self._last is not None:
            self._lost_since = None
            return self._track(self._last, dt)
        if age <= g.lost_after_s:
            return self._ramp(0.0, 0.0, dt, "tracking", f"no sighting for {age:.2f} s: waiting")
        return self._reacquire(t_s, dt, age)

    # -- states -------------------------------------------------------------------------

    def _on_new_sighting(self, seen: Sighting) -> None:
        g = self.gains
        if self._nearest is None or seen.d_obj < self._nearest.d_obj - g.progress_m:
            self._nearest = seen
        e_d = seen.d_obj - D_OPT_M
        e_t = _wrap(seen.theta_obj - THETA_OPT_RAD)
        within = abs(e_d) <= g.tol_d_m and abs(e_t) <= g.tol_theta_rad
        if not within:
            self._in_tol_since = None
        elif self._in_tol_since is None:
            self._in_tol_since = seen.stamp_s

    def _track(self, seen: Sighting, dt: float) -> ApproachCommand:
        g = self.gains
        e_d = seen.d_obj - D_OPT_M
        e_t = _wrap(seen.theta_obj - THETA_OPT_RAD)
        vx = g.k_d * e_d * max(0.0, math.cos(e_t)) ** 2  # turn first when far off
        wz = g.k_theta * e_t
        return self._ramp(vx, wz, dt, "tracking", self._error_text())

    def _reacquire(self, t_s: float, dt: float, age: float) -> ApproachCommand:
        g = self.gains
        if self._lost_since is None:
            self._lost_since = t_s
            self._backed_m = 0.0
            self._in_tol_since = None
        lost_for = t_s - self._lost_since
        if lost_for > g.reacquire_s:
            what = "never seen" if self._last is None else f"last seen {age:.1f} s ago"
            return self._latch(
                "failed",
                f"lost the object: {what}; re-acquiring for {lost_for:.1f} s found nothing",
            )
        bearing = 0.0 if self._last is None else _wrap(self._last.theta_obj - THETA_OPT_RAD)
        turn_s = (abs(bearing) + g.reacquire_turn_margin_rad) / g.reacquire_wz
        wz = math.copysign(g.reacquire_wz, bearing) if abs(bearing) > g.tol_theta_rad else 0.0
        if lost_for > turn_s:
            wz = 0.0
        # Last seen beyond d_opt: creep toward it (the segmenter is surest up close: a box
        # seen at 0.95 m and lost, then backed away from, was never seen again at 1.25 m);
        # nearer, or never seen: back off to get it into view.
        ahead = 0.0 if self._last is None else self._last.d_obj - D_OPT_M - g.tol_d_m
        creep_m = min(max(ahead, 0.0), g.back_off_max_m)
        if ahead > 0.0:
            vx = g.back_off_speed if self._backed_m < creep_m else 0.0
        else:
            vx = -g.back_off_speed if self._backed_m < g.back_off_max_m else 0.0
        self._backed_m += abs(self._v[0]) * dt
        where = (
            "never seen"
            if self._last is None
            else (f"last seen at {self._last.d_obj:.2f} m, {math.degrees(bearing):+.0f} deg")
        )
        return self._ramp(vx, wz, dt, "reacquiring", f"no sighting for {age:.1f} s ({where})")

    def _blocked(self, t_s: float) -> bool:
        """Tracking made no progress for `stall_s`, short of d_opt by less than the slack
        and facing the object."""
        g, err, near = self.gains, self.errors(), self._nearest
        if err is None or near is None:
            return False
        e_d, e_t = err
        return (
            g.tol_d_m < e_d <= g.blocked_slack_m
            and abs(e_t) <= g.tol_theta_rad
            and t_s - max(near.stamp_s, self._held_at) >= g.stall_s
        )

    # -- helpers ------------------------------------------------------------------------

    def _ramp(
        self, vx: float, wz: float, dt: float, state: ApproachState, reason: str
    ) -> ApproachCommand:
        """Clip to the speed limits, then move from the last command within the accel limits."""
        g = self.gains
        vx = min(max(vx, -g.vx_max), g.vx_max)
        wz = min(max(wz, -g.wz_max), g.wz_max)
        px, pz = self._v
        vx = px + min(max(vx - px, -g.ax_max * dt), g.ax_max * dt)
        wz = pz + min(max(wz - pz, -g.az_max * dt), g.az_max * dt)
        self._v = (vx, wz)
        return ApproachCommand(vx=float(vx), vy=0.0, wz=float(wz), state=state, reason=reason)

    def _latch(self, state: ApproachState, reason: str) -> ApproachCommand:
        self._v = (0.0, 0.0)
        self._latched = ApproachCommand(vx=0.0, vy=0.0, wz=0.0, state=state, reason=reason)
        return self._latched

    def _error_text(self) -> str:
        err = self.errors()
        if err is None:
            return "nothing seen yet"
        return (
            f"d_obj error {err[0] * 100:+.1f} cm, theta_obj error {math.degrees(err[1]):+.1f} deg"
        )
