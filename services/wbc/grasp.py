"""The grasp detector: is something held between the jaws?

A single revolute jaw closing under a torque limit stops where it meets the object.
Held means: the gripper is closing with effort, the jaw has stopped (|velocity| below
`still_rad_s` for `still_s`), it stopped short of closed by more than
`short_of_closed_rad`, and the measured effort is at least `effort_min_nm` in the closing
direction. Once held, it stays held while the jaw stays short of closed under that effort
(the jaw's velocity jitters on a held object as the arm moves). A jaw that reaches closed
has nothing in it (`empty`): an object that slips out is no longer held. No force
sensing, no vision: what a real gripper's driver knows.
"""

from __future__ import annotations

from dataclasses import dataclass

from common import robot


@dataclass(frozen=True)
class GraspParams:
    """Thresholds of the detector (rad, rad/s, N·m, s). Not settings: tuned with the jaw."""

    short_of_closed_rad: float = 0.05
    still_rad_s: float = 0.05
    effort_min_nm: float = 1.0
    still_s: float = 0.1


class GraspDetector:
    """Feed it every tick's jaw state; `held` and `empty` say what it concluded."""

    def __init__(self, params: GraspParams | None = None) -> None:
        self.params = params or GraspParams()
        self.held = False
        self.empty = False
        self._still_for = 0.0

    def reset(self) -> None:
        self.held = self.empty = False
        self._still_for = 0.0

    def update(
        self, closing: bool, angle: float, velocity: float, effort: float, dt: float
    ) -> bool:
        """Advance by dt seconds; returns `held`.

        closing: the controller is closing the jaw under a torque limit. angle: rad (0
        closed, negative open). velocity: rad/s. effort: applied jaw torque, N·m,
        positive closing.
        """
        p = self.params
        if not closing:
            self.reset()
            return False
        self._still_for = self._still_for + dt if abs(velocity) < p.still_rad_s else 0.0
        still = self._still_for >= p.still_s
        short = angle < robot.GRIPPER_CLOSED - p.short_of_closed_rad
        if self.held and short and effort >= p.effort_min_nm:
            return True  # latched: a jaw that jitters on a held object still holds it
        self.held = still and short and effort >= p.effort_min_nm
        self.empty = still and not short
        return self.held
