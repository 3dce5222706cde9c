"""`BusRobot`: the `RobotPort` over Zenoh — every bus interaction the behaviours (and the
mapping patrol) need.

Inputs are kept in `Latest` buffers and read as of the tick being processed (`begin(b)`):
odom, `wbc/status`, `nav/status`, perception's detections (the wrist camera's newest
frame that takes effect by b, i.e. stamped at or before b − perception's latency).
Queries (map entries and listings, the occupancy grid, nav goals, arm goals) wait at
most `query_timeout_s` (the floor plan's supports `SUPPORTS_TIMEOUT_S`: the map may
fetch them from the sim first); a typed refusal becomes `Refused`, no answer
`Unavailable`, an unknown id None. Map queries ask for the map as of the tick
(`common.keys.as_of`); nav goals, nav cancels and arm goals carry the tick and take
effect at the tick plus the mission's latency, so the same seed gives the same run. What
the tree (or the patrol) commands during a tick is published by `end(b)` stamped b:
cmd_vel from source `mission` every tick (zero unless a behaviour set it), carrying the
mode when one was asked for (one key: the WBC gets the mode no later than the velocity).
Nav cancels go out at once. A Reach or a Posture sent while a mapped person stands within
`arm_slow_m` of the base goes at `arm_slow_speed` of the arm's speeds (`ArmSlowdown`).
The mission's own cmd_vel (the approach, the back-off, the look round) is held within
the speed and separation monitor's caps that navigation publishes on `nav/status` for
each of the base's axes (`within_caps`): navigation's people, lidar tracks included,
guard every base motion, not only its goals. It also stops short of the static world
(`within_room`): navigation's clearance along each axis less the body's extent, the front
that of the arm's last named posture (the legs' in `look`, the approach's: 0.09 m less
far forward than the stowed gripper). Stopped short of a support, the approach makes no
progress and ends as blocked, as it did with a hip against the support's front, without
the touch.
"""

from __future__ import annotations

import logging
import time
from collections import deque

import msgspec
import numpy as np

from common.bus import Bus, BusError, NoReply, RemoteError
from common.clients import ArmClient, NavClient
from common.keys import (
    MAP_ARTIFACTS,
    MAP_OCCUPANCY,
    MAP_PEOPLE,
    MAP_SUPPORTS,
    RobotKeys,
    as_of,
    map_artifact,
    map_person,
)
from common.map_frame import MapFrame, odom_pose
from common.messages import PayloadError
from common.messages.navigation import NavGoal, NavStatus, ScanBody
from common.messages.perception import Detections
from common.messages.semantic_map import MapEntity, MapListing, OccupancyGrid, SupportListing
from common.messages.sim import Odom
from common.messages.wbc import (
    ArmGoal,
    CmdVel,
    GoalStatus,
    Grasp,
    Posture,
    Reach,
    WbcMode,
    WbcModeName,
    WbcStatus,
)
from common.messages.world import SupportSurface
from common.robot import Footprint, posture_front_m
from common.sightings import pick_detection
from services.mission.ports import Unavailable, WristSighting

log = logging.getLogger("dume.mission")

Vel = tuple[float, float, float]


def within_caps(cmd: Vel, caps: tuple[float, ...] | None) -> tuple[Vel, bool]:
    """(vx, vy, ωz) with vx within (−behind, ahead) and vy within (−right, left) of
    navigation's caps (`NavStatus.caps_mps`; None: none known), and whether it was cut.
    The mission drives along one axis at a time (the approach, the back-off, the look
    round), so each axis's cap is its directed speed's. A cap of 0 is a protective stop
    for a person: no turn on the spot then either (the body's ends sweep, the trot sways
    the trunk), as navigation's own goals stand."""
    if caps is None:
        return cmd, False
    ahead, behind, left, right = caps
    vx, vy, wz = cmd
    cx = min(vx, ahead) if vx > 0.0 else max(vx, -behind)
    cy = min(vy, left) if vy > 0.0 else max(vy, -right)
    cw = 0.0 if min(caps) <= 0.0 else wz
    return (cx, cy, cw), (cx, cy, cw) != (vx, vy, wz)


def within_room(
    cmd: Vel, clear: tuple[float, ...] | None, body: tuple[float, float, float, float]
) -> tuple[Vel, bool]:
    """(vx, vy, ωz) with the translation slowed to stop `ROOM_KEEP_M` short of the static
    world, and whether it was cut: along the axis it moves on, at most the room left
    (navigation's clearance, `NavStatus.clear_m`, less the body's extent `body` that way:
    ahead, behind, left, right; None: none known) less the keep, over `ROOM_TIME_S`.
    Turns are not cut: the mission turns at a support only to face what stands on it."""
    if clear is None:
        return cmd, False
    ahead, behind, left, right = (c - e for c, e in zip(clear, body, strict=True))
    vx, vy, wz = cmd

    def most(room_m: float) -> float:
        return max(0.0, room_m - ROOM_KEEP_M) / ROOM_TIME_S

    cx = min(vx, most(ahead)) if vx > 0.0 else max(vx, -most(behind))
    cy = min(vy, most(left)) if vy > 0.0 else max(vy, -most(right))
    return (cx, cy, wz), (cx, cy) != (vx, vy)


def _metres(values: tuple[float, ...] | None) -> str:
    return "none" if values is None else "(" + ", ".join(f"{v:.2f}" for v in values) + ")"


NAME = "mission"
WRIST = "camera_wrist"
#: Refusals that mean "no such thing" rather than "cannot answer now".
_NOT_FOUND = ("unknown_id", "invalid")
#: Wall seconds the floor plan's supports may take (the map's first answer asks the sim).
SUPPORTS_TIMEOUT_S = 10.0
#: m the body stops short of the static world, and s to close the rest at most (the
#: speed cap is the room left over this time): 0.1 m/s at 0.12 m of room.
ROOM_KEEP_M = 0.02
ROOM_TIME_S = 1.0


class BusRobot:
    """The robot over the bus (see the module docstring)."""

    def __init__(
        self,
        bus: Bus,
        keys: RobotKeys,
        query_timeout_s: float,
        latency_ns: dict[str, int],
        sighting_gate_m: float = 0.35,
        map_frame: MapFrame | None = None,
        arm_slow: tuple[float, float] = (0.0, 1.0),
    ) -> None:
        self.bus, self.keys = bus, keys
        #: (m, share): a person this near the base slows Reach and Posture to the share.
        self.arm_slow_m, self.arm_slow_speed = arm_slow
        self.timeout_s = query_timeout_s
        self.sighting_gate_m = sighting_gate_m
        self.perception_latency_ns = latency_ns.get("perception", 0)
        self.nav_latency_ns = latency_ns.get("navigation", 0)
        #: What the mission sends at its tick b takes effect at b + its own latency.
        self.latency_ns = latency_ns.get(NAME, 0)
        self.odom = bus.latest(keys.odom, Odom, history=16)
        #: The map frame (the localization's correction of odom); None: odom is the map.
        self.map_frame = map_frame
        self.wbc = bus.latest(keys.wbc_status, WbcStatus, history=16)
        self.nav = bus.latest(keys.nav_status, NavStatus, history=32)
        #: The newest detections of either camera (what the lockstep gate waits on) …
        self.detections = bus.latest(keys.detections, Detections, history=1)
        # … and every frame, of which the wrist camera's are kept.
        self._frames_in = bus.fifo(keys.detections, Detections, maxlen=256)
        self._wrist: deque[Detections] = deque(maxlen=8)
        self._nav = NavClient(bus, keys, query_timeout_s)
        self._arm = ArmClient(bus, keys, query_timeout_s)
        self._cmd_pub = bus.publisher(keys.cmd_vel, CmdVel, "control", again=True)
        self._t = 0
        self._cmd = (0.0, 0.0, 0.0)
        self._held = ""  # who the last command was held back for
        self._mode: tuple[WbcModeName, str] | None = None
        #: The arm's last named posture (None: a reach since, or none yet) and the body's
        #: extent in it (ahead, behind, left, right: the stowed footprint's, the front
        #: the posture's): what `within_room` keeps off the static world.
        self._posture: str | None = None
        self._stowed = Footprint.stowed()
        fp = self._stowed
        self._body = (fp.front, fp.back, fp.half_width, fp.half_width)
        self._roomed = False  # whether the last command was cut short of the world

    # -- the tick -------------------------------------------------------------------------

    def begin(self, b: int) -> None:
        self._t, self._cmd, self._mode = b, (0.0, 0.0, 0.0), None
        if self.map_frame is not None:
            self.map_frame.wait(b, self.timeout_s)
        for frame in self._frames_in.drain():
            if frame.camera == WRIST:
                self._wrist.append(frame)

    def end(self, b: int) -> None:
        change = None
        if self._mode is not None:
            mode, source = self._mode
            change = WbcMode(stamp_ns=b, mode=mode, cmd_vel_source=source)
        vx, vy, wz = self._cmd
        self._cmd_pub.put(CmdVel(stamp_ns=b, vx=vx, vy=vy, wz=wz, source=NAME, mode=change))

    @property
    def now_ns(self) -> int:
        return self._t

    @property
    def _effective(self) -> int:
        """When what this tick sends takes effect (the tick plus the mission's latency)."""
        return self._t + self.latency_ns

    def wait_wrist(self, timeout_s: float) -> bool:
        """Wait (bounded) for the wrist camera's detections due at this tick: the gate was
        met by either camera's, and both share one key. False when they did not come."""
        due = self._t - self.perception_latency_ns
        deadline = time.monotonic() + timeout_s
        while not self._wrist or self._wrist[-1].stamp_ns < due:
            left = deadline - time.monotonic()
            frame = self._frames_in.pop(timeout_s=left) if left > 0 else None
            if frame is None:
                return False
            if frame.camera == WRIST:
                self._wrist.append(frame)
        return True

    # -- the semantic map -----------------------------------------------------------------

    def _query_map(
        self,
        key: str,
        type_: type[MapEntity] | type[MapListing] | type[OccupancyGrid] | type[SupportListing],
        timeout_s: float | None = None,
    ) -> object | None:
        timeout = self.timeout_s if timeout_s is None else timeout_s
        try:  # the map as of this tick: the same answer in every run
            return self.bus.query(as_of(key, self._t), None, type_, timeout)
        except RemoteError as exc:
            if exc.error.code in _NOT_FOUND:
                return None
            raise Unavailable(f"{key}: {exc.error.code}: {exc.error.message}") from None
        except (NoReply, PayloadError, BusError) as exc:
            raise Unavailable(str(exc)) from None

    def artifact(self, map_id: str) -> MapEntity | None:
        found = self._query_map(map_artifact(map_id), MapEntity)
        return found if isinstance(found, MapEntity) else None

    def artifacts_of_class(self, class_name: str) -> list[MapEntity]:
        found = self._query_map(f"{MAP_ARTIFACTS}?class={class_name}", MapListing)
        return list(found.entities) if isinstance(found, MapListing) else []

    def mapped_artifacts(self) -> list[MapEntity]:
        found = self._query_map(f"{MAP_ARTIFACTS}?missing=false", MapListing)
        return list(found.entities) if isinstance(found, MapListing) else []

    def person(self, person_id: str) -> MapEntity | None:
        found = self._query_map(map_person(person_id), MapEntity)
        return found if isinstance(found, MapEntity) else None

    def people(self) -> list[MapEntity]:
        found = self._query_map(MAP_PEOPLE, MapListing)
        return list(found.entities) if isinstance(found, MapListing) else []

    def occupancy(self) -> OccupancyGrid:
        found = self._query_map(MAP_OCCUPANCY, OccupancyGrid)
        if not isinstance(found, OccupancyGrid):
            raise Unavailable(f"{MAP_OCCUPANCY}: no grid")
        return found

    def floor_supports(self) -> list[SupportSurface]:
        found = self._query_map(MAP_SUPPORTS, SupportListing, SUPPORTS_TIMEOUT_S)
        if not isinstance(found, SupportListing):
            raise Unavailable(f"{MAP_SUPPORTS}: no listing")
        return list(found.surfaces)

    def robot_xy(self) -> tuple[float, float] | None:
        """The base in the map: odom with the localization's correction due now."""
        odom = self.odom.at(self._t)
        if odom is None:
            return None
        x, y, _ = self.map_frame.pose(odom, self._t) if self.map_frame else odom_pose(odom)
        return x, y

    def robot_yaw(self) -> float | None:
        odom = self.odom.at(self._t)
        if odom is None:
            return None
        return (self.map_frame.pose(odom, self._t) if self.map_frame else odom_pose(odom))[2]

    # -- navigation -----------------------------------------------------------------------

    def send_nav_goal(self, goal: NavGoal) -> str:
        return self._nav.send(goal, stamp_ns=self._t, effective_ns=self._effective)

    def nav_status(self, goal_id: str) -> NavStatus | None:
        status = self.nav.at(self._t - self.nav_latency_ns)
        return status if status is not None and status.goal_id == goal_id else None

    def cancel_nav(self, goal_id: str, reason: str) -> None:
        self._nav.cancel(goal_id, reason, effective_ns=self._effective)

    def bodies(self) -> list[ScanBody]:
        status = self.nav.at(self._t - self.nav_latency_ns)
        return list(status.bodies) if status is not None else []

    # -- the whole-body controller --------------------------------------------------------

    def set_mode(self, mode: WbcModeName, cmd_vel_source: str) -> None:
        self._mode = (mode, cmd_vel_source)

    def command_velocity(self, vx: float, vy: float, wz: float) -> str:
        status = self.nav.at(self._t - self.nav_latency_ns)
        caps = status.caps_mps if status is not None else None
        capped, held = within_caps((float(vx), float(vy), float(wz)), caps)
        clear = status.clear_m if status is not None else None
        self._cmd, roomed = within_room(capped, clear, self._body)
        if roomed != self._roomed:
            log.info("t=%.2f s the base %s: (%.2f, %.2f) m/s asked, clearance %s m, body %s m "
                     "(arm in %s)", self._t / 1e9,
                     "stops short of the world" if roomed else "has room again", vx, vy,
                     _metres(clear), _metres(self._body), self._posture or "a reach")  # fmt: skip
            self._roomed = roomed
        if not held:
            self._held = ""
            return ""
        who = (status.cap_person if status is not None else "") or "localization"
        if who != self._held:
            log.info("t=%.2f s the base held back for %s: (%.2f, %.2f) m/s asked, caps %s",
                     self._t / 1e9, who, vx, vy, caps)  # fmt: skip
        self._held = who
        return who

    def hold_arm(self, reason: str) -> None:
        """Leaving `manipulate` freezes the arm's joints where they are (the controller
        has no goal cancel); a posture already under way in walk or stand ends at its
        named, collision-checked posture."""
        status = self.wbc_status()
        if status is not None and status.mode == "manipulate":
            log.info("holding the arm: %s", reason)
            self._mode = ("stand", "navigation")

    def send_arm_goal(self, goal: ArmGoal) -> str:
        """Send an arm goal; a world-frame reach, planned in the map, goes in the WBC's
        world, the odometry's frame, with the correction that placed what it was planned
        from: T_odom_map due at the goal's stamp (the capture). What the camera saw was
        seen from the base, so odom at the capture holds it exactly; a correction the
        localization made since (a few cm) would move the grasp off the object."""
        if isinstance(goal, Reach) and goal.frame == "world" and self.map_frame is not None:
            H_map = np.asarray(goal.H, dtype=float).reshape(4, 4)
            H = self.map_frame.to_odom(H_map, goal.stamp_ns, self._t)
            goal = msgspec.structs.replace(goal, H=tuple(H.ravel().tolist()))
        if isinstance(goal, (Posture, Reach, Grasp)):
            fp = self._stowed  # after a reach: the stowed front (the next is stow)
            self._posture = goal.name if isinstance(goal, Posture) else None
            front = posture_front_m(goal.name) if isinstance(goal, Posture) else fp.front
            self._body = (front, fp.back, fp.half_width, fp.half_width)
        if isinstance(goal, (Reach, Posture)) and self.arm_slow_speed < goal.speed:
            near = self.person_near(self.arm_slow_m)
            if near:
                log.info(
                    "t=%.2f s %s near (%s): the arm at %.0f %% of its speeds", self._t / 1e9,
                    near, type(goal).__name__, 100 * self.arm_slow_speed,
                )  # fmt: skip
                goal = msgspec.structs.replace(goal, speed=self.arm_slow_speed)
        return self._arm.send(goal, effective_ns=self._effective)

    def person_near(self, radius_m: float) -> str:
        """The id of a mapped person within `radius_m` of the base (the nearest), or ""."""
        xy = self.robot_xy()
        if xy is None or radius_m <= 0.0:
            return ""
        near = []
        for e in self.people():
            d = float(np.hypot(e.position_in_world[0] - xy[0], e.position_in_world[1] - xy[1]))
            if d <= radius_m:
                near.append((d, e.id))
        return min(near)[1] if near else ""

    def wbc_status(self) -> WbcStatus | None:
        # Stamped before the tick: the controller surely published it (lockstep) and the
        # node waited for it; one stamped at the tick may or may not be in yet.
        return self.wbc.at(self._t - 1)

    def arm_goal(self, goal_id: str) -> GoalStatus | None:
        status = self.wbc_status()
        if status is None:
            return None
        return next((g for g in status.goals if g.goal_id == goal_id), None)

    # -- perception -----------------------------------------------------------------------

    def wrist_detection(
        self,
        map_id: str,
        class_name: str,
        near_xy: tuple[float, float] | None = None,
        any_class: bool = False,
    ) -> WristSighting | None:
        due = self._t - self.perception_latency_ns
        frame = self._wrist_frame(due)
        if frame is None:
            return None
        mine = pick_detection(
            frame.detections, class_name, near_xy, self.sighting_gate_m, any_class
        )
        return WristSighting(frame.stamp_ns, mine, frame.T_world_base) if mine else None

    def _wrist_frame(self, due_ns: int) -> Detections | None:
        for frame in reversed(self._wrist):
            if frame.stamp_ns <= due_ns:
                return frame
        return None
