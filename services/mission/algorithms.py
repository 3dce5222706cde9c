"""The algorithms the behaviours call, behind small protocols so the tree is testable alone.

- the visual approach (`approach.ApproachController`: eq. 3's two P-controllers and the
  re-acquire), fed `Sighting`s of the wrist camera;
- the grasp pose (`grasp_pose.grasp_from_detection` → a `GraspPlan` whose `reach()` is
  the whole-body controller's `Reach`; `GraspPoseError` when none is possible);
- the felt handover (`handover_feel.PullDetector` on `wbc/status`).

`default_algorithms(settings)` binds the real ones (imported when the service starts,
with the config's overrides of their defaults); unit tests pass scripted stand-ins.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from common.config import MissionSettings
from common.geometry import FloatArray
from common.messages.perception import Detection
from common.messages.wbc import Reach, WbcStatus


class ApproachStep(Protocol):
    """One approach command: base velocity in base_yaw and the controller's state."""

    vx: float
    vy: float
    wz: float
    state: str  # tracking | reacquiring | arrived | failed
    reason: str


class Approacher(Protocol):
    def reset(self, t_s: float) -> None: ...

    def step(self, t_s: float, seen: Any | None) -> ApproachStep: ...


class GraspPlanLike(Protocol):
    kind: str

    def reach(self) -> Reach: ...

    def lifted(self, dz_m: float) -> GraspPlanLike: ...


class PullFeeler(Protocol):
    def reset(self, status: WbcStatus) -> None: ...

    def update(self, status: WbcStatus) -> bool: ...


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
    approach: Any = importlib.import_module("services.mission.approach")
    grasp: Any = importlib.import_module("services.mission.grasp_pose")
    feel: Any = importlib.import_module("services.mission.handover_feel")
    gains = dict(settings.approach_gains)
    pull = dict(settings.pull_detector)

    def approacher() -> Approacher:
        if gains:
            return approach.ApproachController(approach.ApproachGains(**gains))
        return approach.ApproachController()

    def sighting(d_obj: float, theta_obj: float, stamp_s: float) -> Any:
        return approach.Sighting(d_obj=d_obj, theta_obj=theta_obj, stamp_s=stamp_s)

    return Algorithms(
        approacher=approacher,
        sighting=sighting,
        grasp_from_detection=grasp.grasp_from_detection,
        grasp_error=grasp.GraspPoseError,
        pull_detector=lambda: feel.PullDetector(**pull),
    )


def missing_algorithms(why: str) -> Algorithms:
    """Stand-ins that raise when used: the service still validates requests and reports
    a mission that reaches them as failed (`internal`), instead of not starting."""

    def unavailable(*_args: object) -> Any:
        raise RuntimeError(f"the mission's algorithms are not installed: {why}")

    return Algorithms(
        approacher=unavailable,
        sighting=unavailable,
        grasp_from_detection=unavailable,
        grasp_error=RuntimeError,
        pull_detector=unavailable,
    )
