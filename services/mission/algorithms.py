"""The algorithms the behaviours call, behind small protocols so the tree is testable alone.

- the visual approach (`approach.ApproachController`: eq. 3's two P-controllers and the
  re-acquire), fed `Sighting`s of the wrist camera;
- the grasp pose (`grasp_pose.grasp_from_detection` → a `GraspPlan` whose `reach()` is
  the whole-body controller's `Reach`; `GraspPoseError` when none is possible);
- the felt handover (`handover_feel.PullDetector` on `wbc/status`).

`default_algorithms(settings)` binds the real ones (with the settings' approach gains and
pull thresholds); unit tests pass scripted stand-ins.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from common.config import MissionSettings
from common.geometry import FloatArray
from common.messages.perception import Detection
from common.messages.wbc import Reach, WbcStatus
from services.mission import approach, grasp_pose, handover_feel


class ApproachStep(Protocol):
    """One approach command: base velocity in base_yaw and the controller's state."""

    @property
    def vx(self) -> float: ...
    @property
    def vy(self) -> float: ...
    @property
    def wz(self) -> float: ...
    @property
    def state(self) -> str: ...  # tracking | reacquiring | arrived | failed
    @property
    def reason(self) -> str: ...


class Approacher(Protocol):
    def reset(self, t_s: float) -> None: ...

    def hold(self, t_s: float) -> None: ...

    @property
    def held_s(self) -> float: ...

    def step(self, t_s: float, seen: Any | None) -> ApproachStep: ...


class GraspPlanLike(Protocol):
    @property
    def kind(self) -> str: ...

    def reach(self) -> Reach: ...

    def lifted(self, dz_m: float) -> GraspPlanLike: ...


class PullFeeler(Protocol):
    pull_n: float  # the last sample's pull toward the person, N (logged)
    across_n: float  # its change of force across that direction, N (logged)
    effort_change_nm: float  # its jaw effort change, N·m (logged)
    rising_since_ns: int | None  # since when the pull has been rising (logged)
    swing_n: float  # the largest rise toward the person since the baseline, N (logged)

    def note(self, status: WbcStatus) -> None: ...

    def reset(self, status: WbcStatus) -> None: ...

    def update(self, status: WbcStatus) -> bool: ...

    def pulled_within(self, t_ns: int, window_s: float) -> bool: ...


@dataclass(frozen=True)
class Algorithms:
    """Factories of the mission's algorithms (see the module docstring)."""

    approacher: Callable[[], Approacher]
    #: (d_obj m, θ_obj rad, stamp s) → the approach controller's `Sighting`.
    sighting: Callable[[float, float, float], Any]
    #: (detection, its frame's stamp ns, T_world_base at capture 4×4) → a world-frame plan.
    grasp_from_detection: Callable[[Detection, int, FloatArray], GraspPlanLike]
    #: The exception `grasp_from_detection` raises when no grasp is possible.
    grasp_error: type[Exception]
    pull_detector: Callable[[], PullFeeler]


def default_algorithms(settings: MissionSettings) -> Algorithms:
    """The real algorithms, with `approach_gains` and `pull_detector` from the config."""

    def approacher() -> Approacher:
        return approach.ApproachController(settings.approach_gains)

    def sighting(d_obj: float, theta_obj: float, stamp_s: float) -> Any:
        return approach.Sighting(d_obj=d_obj, theta_obj=theta_obj, stamp_s=stamp_s)

    return Algorithms(
        approacher=approacher,
        sighting=sighting,
        grasp_from_detection=grasp_pose.grasp_from_detection,
        grasp_error=grasp_pose.GraspPoseError,
        pull_detector=lambda: handover_feel.PullDetector(settings.pull_detector),
    )
