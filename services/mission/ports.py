"""What the mission's behaviours may ask of the robot: one small interface, no transport.

Every bus interaction a behaviour (or the mapping patrol, `patrol`) needs goes through
a `RobotPort`: the Zenoh client (`services.mission.robot.BusRobot`) in the service, a
scripted fake in the unit tests. Reads are of the inputs as of the current tick (the
node refreshes them before it ticks the tree); commands are either short queries with a
timeout (a goal sent, a map entry read) or values the node publishes after the tick
(cmd_vel, the wbc mode). Nothing here blocks for longer than one query: goals are sent,
then watched over later ticks.

Failures the behaviours must handle are typed: `Refused` (the service answered no, with
its reason) and `Unavailable` (nobody answered in time).
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

from common.clients import ClientError, Refused, Unavailable
from common.messages.base import Mat4
from common.messages.navigation import NavGoal, NavStatus, ScanBody
from common.messages.perception import Detection
from common.messages.semantic_map import MapEntity, OccupancyGrid
from common.messages.wbc import ArmGoal, GoalStatus, WbcModeName, WbcStatus
from common.messages.world import SupportSurface


class WristSighting(NamedTuple):
    """A wrist-camera detection of the target: its frame's stamp (ns), the detection and
    the base pose at capture (`T_world_base`, row-major 4×4) that places it in the world."""

    stamp_ns: int
    detection: Detection
    T_world_base: Mat4


__all__ = ["PortError", "Refused", "RobotPort", "Unavailable", "WristSighting"]

#: A request the robot's services did not serve (the goal clients' errors, `Refused`
#: and `Unavailable`, are the port's).
PortError = ClientError


class RobotPort(Protocol):
    """The robot as the mission's behaviours see it (see the module docstring)."""

    @property
    def now_ns(self) -> int:
        """The tick being processed: sim time, ns."""
        ...

    # -- the semantic map (queries) -----------------------------------------------------

    def artifact(self, map_id: str) -> MapEntity | None:
        """A mapped artifact by id (None: no such id); `Unavailable` if the map is down."""
        ...

    def artifacts_of_class(self, class_name: str) -> list[MapEntity]:
        """Every mapped, not missing artifact of a class, in any order."""
        ...

    def mapped_artifacts(self) -> list[MapEntity]:
        """Every mapped, not missing artifact, in any order."""
        ...

    def person(self, person_id: str) -> MapEntity | None:
        """A mapped person by id (None: no such id)."""
        ...

    def people(self) -> list[MapEntity]:
        """Every mapped person."""
        ...

    def occupancy(self) -> OccupancyGrid:
        """The map's occupancy grid as of this tick (what the patrol plans its route on);
        `Unavailable` if the map does not answer."""
        ...

    def floor_supports(self) -> list[SupportSurface]:
        """The floor plan's tables and benches (empty without a floor plan), which the
        patrol must see from near; `Unavailable` if the map does not answer."""
        ...

    def robot_xy(self) -> tuple[float, float] | None:
        """The base's position in the world as of this tick (None before the first odom)."""
        ...

    def robot_yaw(self) -> float | None:
        """The base's heading in the world, rad, as of this tick (None before the first odom)."""
        ...

    # -- navigation ---------------------------------------------------------------------

    def send_nav_goal(self, goal: NavGoal) -> str:
        """Send a goal; its id. `Refused` with navigation's reason, or `Unavailable`."""
        ...

    def nav_status(self, goal_id: str) -> NavStatus | None:
        """Navigation's newest status of that goal (None: none about it yet)."""
        ...

    def cancel_nav(self, goal_id: str, reason: str) -> None:
        """Cancel a goal ("" for whatever is active)."""
        ...

    def bodies(self) -> list[ScanBody]:
        """The bodies the lidars track near the robot as of this tick (`NavStatus.bodies`:
        people, whoever they are), nearest first; empty without a status."""
        ...

    # -- the whole-body controller ------------------------------------------------------

    def set_mode(self, mode: WbcModeName, cmd_vel_source: str) -> None:
        """Ask for a mode and a cmd_vel source (published after the tick, stamped with it)."""
        ...

    def command_velocity(self, vx: float, vy: float, wz: float) -> str:
        """This tick's cmd_vel from source `mission` (zero unless set again next tick),
        within navigation's people caps (`NavStatus.caps_mps`); who held it back ("" when
        nobody did: "localization" while navigation does not know where the robot is)."""
        ...

    def send_arm_goal(self, goal: ArmGoal) -> str:
        """Send an arm goal; its id. `Refused` with the controller's reason, or `Unavailable`."""
        ...

    def hold_arm(self, reason: str) -> None:
        """Stop the arm where it is (the controller leaves `manipulate`: joints frozen)."""
        ...

    def arm_goal(self, goal_id: str) -> GoalStatus | None:
        """The goal's state on the newest `wbc/status` (None: not listed yet)."""
        ...

    def wbc_status(self) -> WbcStatus | None:
        """The newest `wbc/status` as of this tick."""
        ...

    # -- perception ---------------------------------------------------------------------

    def wrist_detection(
        self,
        map_id: str,
        class_name: str,
        near_xy: tuple[float, float] | None = None,
        any_class: bool = False,
    ) -> WristSighting | None:
        """The wrist camera's newest detection of the target, with its frame's stamp and base pose.

        The detection associated with `map_id` when perception associated one, else the
        one of `class_name` (with `any_class`, else any artifact) at the target's mapped
        place `near_xy` (world; gated, `targets.pick_detection`), or without it the
        nearest of the class to the base; None when the newest wrist frame due by now
        shows none.
        """
        ...
