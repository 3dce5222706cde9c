"""release_object's felt handover: does the person pull the object the robot holds out?

The robot has no force sensor: the WBC estimates the wrench on `gripper_tcp` from the
arm's joint torques (`WbcStatus.gripper_wrench`, force N in the base frame; a held
bottle reads as its weight, −z). While the arm holds still in `handover`, `reset` takes
the baseline (averaged over the first `baseline_s`); afterwards a person's pull shows
as the force rising along `toward` (from the robot to the person, base frame: ahead),
and the jaw's effort changes as the object is tugged between the pads. `update` returns
True once

    pull = (F − F₀) · toward ≥ `force_n`, or
    pull ≥ `force_n` / 2 and |effort − effort₀| ≥ `effort_nm` and the change of force
        across `toward` is no larger than the pull (within 45° of it), or
    F · toward ≥ `absolute_n` (a person who took hold before the baseline was taken:
    holding still, the load is the object's weight, across `toward`),

has held on every sample for `debounce_s` of sim time (a single spike from a footstep
or the estimator's noise does not trip it). Tripped stays tripped until `reset`.
`pulled_within(t, window_s)` says whether a pull of at least half of `force_n` was felt
in the `window_s` before t, tripped or not: a person who pulls the object out of the jaws
faster than the debounce has taken it, where an object that slips out has not been pulled
toward anyone. A force of `absolute_n` toward the person counts as such a pull on every
sample, the baseline's too (`note`, which the offer also feeds while the arm settles): a
person whose grip closed while the baseline was taken pulls against a baseline that
holds part of their pull (hall seed 5's shift: the box left the jaws 0.15 s after the
baseline, the person had it, and the mission said `grasp_lost`). So does a swing: from the
baseline on, the force toward the person rising by `force_n` or more above its lowest in
the last `SWING_S` (the hand closing on the object pushes it at the robot, then pulls:
`dume trial fetch --world hall --world-seed 5` with box_1 for person_5, F · toward from
−4.3 N to +7.7 N in 0.34 s, while against a baseline taken on the push the pull stayed
near 4 N and the box slid out). Held still, nobody pulling, the recorded swings stay
within 4 N; the reaching hand's knock was +4.1 N. The same seed's shift still says
`grasp_lost` for a box out of the jaws 0.35 s after the baseline, its rise 6.3 N: a rise
over half of `force_n` is said with it ("they may have it"); force alone cannot tell
that one from a knock.
Recorded in `bench.trial_fetch` (`dume trial fetch [--world hall --world-seed 5]`, the
samples in `tests/unit/data/`): holding still, F · toward swings by ±1-2.5 N (spikes
of 10 N across it as the robot shifts its weight); a person's pull reaches +15..17 N
within 0.4 s of their grip closing (the hand's servo limit, 15 N, and the estimate's
error); the jaw's effort stays at its cap throughout, so the force does the work. In
the hall (seed 5) the person's hand, reaching for the can at 0.8 m/s, knocked it before
its grip closed, twice in two runs: once the jaw's effort changed and the force changed
as much sideways and up as toward the person (≈ 2 N each: the effort clause's direction
test), once the force alone rose +4.1 N toward the person for 0.2 s (hence `force_n` 8
N, twice that; the real pull trips it 0.02-0.04 s later than 4 N did): either time the
jaws opened and the can fell.

Pure: statuses in (their sim-time stamps are the clock), a bool out.
"""

from __future__ import annotations

import math

import numpy as np

from common.config import PullSettings
from common.geometry import FloatArray
from common.messages.base import NS_PER_S
from common.messages.wbc import WbcStatus

#: s: a rise of the force toward the person by `force_n` within this long is a pull felt.
SWING_S = 0.5


class PullDetector:
    """See the module docstring."""

    def __init__(
        self,
        settings: PullSettings | None = None,
        toward: tuple[float, float, float] = (1.0, 0.0, 0.0),
    ) -> None:
        """Thresholds from `settings` (`mission.pull_detector`). Not settings: `toward`,
        the direction from the robot to the person in the base frame."""
        s = settings or PullSettings()
        force_n, effort_nm, debounce_s = s.force_n, s.effort_nm, s.debounce_s
        baseline_s, absolute_n = s.baseline_s, s.absolute_n
        thresholds = (force_n, effort_nm, debounce_s, absolute_n)
        if not all(math.isfinite(x) and x > 0 for x in thresholds):
            raise ValueError(
                f"thresholds must be finite and positive: force_n={force_n}, "
                f"effort_nm={effort_nm}, debounce_s={debounce_s}, absolute_n={absolute_n}"
            )
        direction = np.asarray(toward, dtype=float)
        if not (np.all(np.isfinite(direction)) and np.linalg.norm(direction) > 1e-6):
            raise ValueError(f"toward {toward} is not a direction")
        self.force_n, self.effort_nm, self.absolute_n = force_n, effort_nm, absolute_n
        self.debounce_s, self.baseline_s = debounce_s, max(0.0, baseline_s)
        self.toward: FloatArray = direction / np.linalg.norm(direction)
        self._t0_ns = 0
        self._forces: list[FloatArray] = []
        self._efforts: list[float] = []
        self._F0: FloatArray = np.zeros(3)
        self._e0 = 0.0
        self._since_ns: int | None = None
        self.tripped = False
        self.pull_n = 0.0  # the last sample's pull, N (for logging)
        self.effort_change_nm = 0.0  # the last sample's |effort − effort₀|, N·m
        self.across_n = 0.0  # the last sample's change of force across `toward`, N
        self.tripped_at_ns: int | None = None
        self.last_pull_ns: int | None = None  # the last sample pulling ≥ force_n / 2
        #: Since when the pull has stayed above a quarter of `force_n` (None: below now):
        #: a person's pull rises within a few tenths of a second, a drift over seconds.
        self.rising_since_ns: int | None = None
        #: (stamp ns, F · toward N) since the baseline, the last `SWING_S`; the largest
        #: rise above the lowest of them so far (N, for logging).
        self._along: list[tuple[int, float]] = []
        self.swing_n = 0.0

    def reset(self, status: WbcStatus) -> None:
        """Start feeling from this status (the arm still in `handover`): a new baseline."""
        self._t0_ns = status.stamp_ns
        self._forces, self._efforts = [], []
        self._since_ns, self.tripped, self.tripped_at_ns = None, False, None
        self.rising_since_ns = None  # `last_pull_ns` kept: a pull `note`d while settling
        self.pull_n = self.effort_change_nm = self.swing_n = 0.0
        self._along = []
        self._add_baseline(status)
        self._swing(np.asarray(status.gripper_wrench[:3], dtype=float), status.stamp_ns)

    @property
    def baseline(self) -> tuple[FloatArray, float]:
        """(F₀ (3,) N in base, effort₀ N·m)."""
        return self._F0.copy(), self._e0

    def _add_baseline(self, status: WbcStatus) -> None:
        self._forces.append(np.asarray(status.gripper_wrench[:3], dtype=float))
        self._efforts.append(float(status.gripper_effort))
        self._F0 = np.mean(self._forces, axis=0)
        self._e0 = float(np.mean(self._efforts))

    def note(self, status: WbcStatus) -> None:
        """Remember a force of `absolute_n` toward the person (`pulled_within`), whatever
        the baseline: statuses before `reset` too."""
        self._note(np.asarray(status.gripper_wrench[:3], dtype=float), status.stamp_ns)

    def _note(self, F: FloatArray, stamp_ns: int) -> None:
        if np.all(np.isfinite(F)) and float(F @ self.toward) >= self.absolute_n:
            self.last_pull_ns = stamp_ns

    def _swing(self, F: FloatArray, stamp_ns: int) -> None:
        """Remember a rise of `force_n` toward the person within `SWING_S` as a pull."""
        if not np.all(np.isfinite(F)):
            return
        along = float(F @ self.toward)
        since = stamp_ns - SWING_S * NS_PER_S
        self._along = [(t, f) for t, f in self._along if t >= since] + [(stamp_ns, along)]
        rise = along - min(f for _, f in self._along)
        self.swing_n = max(self.swing_n, rise)
        if rise >= self.force_n:
            self.last_pull_ns = stamp_ns

    def update(self, status: WbcStatus) -> bool:
        """Feed the next status; True once a pull has been felt (see the module docstring)."""
        if self.tripped:
            return True
        F = np.asarray(status.gripper_wrench[:3], dtype=float)
        self._note(F, status.stamp_ns)
        self._swing(F, status.stamp_ns)
        if (status.stamp_ns - self._t0_ns) / NS_PER_S < self.baseline_s:
            self._add_baseline(status)
            return False
        effort = float(status.gripper_effort)
        if not (np.all(np.isfinite(F)) and math.isfinite(effort)):
            self._since_ns = None
            return False
        change = F - self._F0
        self.pull_n = float(change @ self.toward)
        self.across_n = float(np.linalg.norm(change - self.pull_n * self.toward))
        self.effort_change_nm = abs(effort - self._e0)
        if self.pull_n >= 0.5 * self.force_n:
            self.last_pull_ns = status.stamp_ns  # (`note` may have set it already)
        if self.pull_n < 0.25 * self.force_n:
            self.rising_since_ns = None
        elif self.rising_since_ns is None:
            self.rising_since_ns = status.stamp_ns
        tugged = self.effort_change_nm >= self.effort_nm and self.across_n <= self.pull_n
        pulling = (
            self.pull_n >= self.force_n
            or (self.pull_n >= 0.5 * self.force_n and tugged)
            or float(F @ self.toward) >= self.absolute_n
        )
        if not pulling:
            self._since_ns = None
            return False
        if self._since_ns is None:
            self._since_ns = status.stamp_ns
        if (status.stamp_ns - self._since_ns) / NS_PER_S >= self.debounce_s:
            self.tripped, self.tripped_at_ns = True, status.stamp_ns
        return self.tripped

    def pulled_within(self, t_ns: int, window_s: float) -> bool:
        """Whether a pull of at least half `force_n` was felt in the `window_s` before t."""
        last = self.last_pull_ns
        return last is not None and 0 <= t_ns - last <= window_s * NS_PER_S
