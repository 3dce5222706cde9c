"""The navigation service: a 20 Hz lockstep participant, wired from its parts.

The node builds the parts from the config and the bus, runs the loop and publishes:
- the map (`navigation.map_source`, `sources`): the sim's truth (tests), read before ready
  and adopted at once; or the semantic map, fetched on sim time by `map_feed.MapFeed` (its
  own thread) and adopted `MAP_ADOPT_S` after the tick it is as of;
- `nav_map.NavMap`: the map in use, its short-lived depth layer (`depth.DepthFeed`, the
  head camera at 10 Hz), its people layer (the map's, with those perception sees:
  `perceived.PerceptionFeed`, `seen_people.SeenPeople`; the lidar's bodies the map lacks,
  `scan_people.ScanPeople`, the speed monitor's protective field) and the costmap;
- `intake.GoalIntake`: goals (on the `nav/goal` queryable's thread, resolved as of the
  sender's tick, or queued until the map is in: `timeout` after `MAP_WAIT_S`) and
  cancels, started by the loop at their effective tick;
- `navigator.Navigator`, the goal's life; `nav_log.NavLogger`, what it tells a person.

Each tick b (multiples of `time.participants.navigation.period_s`): the odom stamped b
(waited for: 50 Hz), put in the map with the localization due at b
(`common.map_frame.MapFrame`; standing still while it is `lost`), the depth layer, the
lidars' scans stamped b at the scan rate (the trunk's front one and its rear twin:
waited for, the sim puts them just after the odom), the map to adopt, perception's
people due by b, the cancels; until the map is in, idle ("waiting for the map": zero
cmd_vel, a queued goal `active`); else the goal due, a
handover goal following its person on a new map, the costmap rebuilt when a layer
changed, `Navigator.tick` (its `clear` recovery empties the depth layer); then
`wbc/cmd_vel` (source `navigation`) and `nav/status` stamped b, `nav/path` on a new
plan, the ack. So goals, cancels and map updates take effect at ticks fixed by sim time,
never by when a message happened to arrive.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from common.bus import WaitTimeout
from common.geometry import yaw_of, yaw_of_quat_xyzw
from common.lockstep import PeriodicTicker
from common.map_frame import MapFrame
from common.messages import as_numpy, to_wire
from common.messages.base import NS_PER_S
from common.messages.navigation import NavCancel, NavGoalRequest, NavPath, NavStatus, ScanBody
from common.messages.sim import CameraFrame, LaserScan, Odom
from common.messages.wbc import CmdVel
from common.scan import scan_points
from common.service import Service
from services.navigation.body_guard import clearance
from services.navigation.costmap import CostParams
from services.navigation.depth import DepthFeed
from services.navigation.grid import Footprint, Pose
from services.navigation.intake import GoalIntake
from services.navigation.map_feed import MapFeed
from services.navigation.nav_log import NavLogger
from services.navigation.nav_map import NavMap
from services.navigation.navigator import Navigator, TickOutput
from services.navigation.people import base_caps
from services.navigation.perceived import PerceptionFeed
from services.navigation.scan_people import ScanView, nearest_tracks
from services.navigation.sources import MapSource, Source, WorldSource, wait_for_world

NAME = "navigation"
Caps = tuple[float, float, float, float]
#: Wall seconds to wait for a tick's input (odom, a depth frame, perception, the map
#: fetch, the tick a goal is stamped at); NavigationSettings has no setting for it.
INPUT_TIMEOUT_S = 30.0
#: Wall seconds a tick waits for its scan, and how many scan periods old the newest may be
#: for scans to count as flowing (else none is waited for: the lidar is gone).
SCAN_WAIT_S = 2.0
SCAN_FLOWING = 3


class NavNode:
    """The loop and its parts; see the module docstring."""

    def __init__(self, svc: Service) -> None:
        self.svc, cfg = svc, svc.config
        n = cfg.navigation
        self.period_s = cfg.time.period_of(NAME, 0.05)
        self.fp = Footprint.stowed()
        bus, keys, log = svc.bus, svc.keys, svc.log
        self.source: Source = (
            wait_for_world(bus, svc.stop, log) if n.map_source == "world" else MapSource(bus)
        )
        ttl_ns = round(n.obstacle_ttl_s * NS_PER_S)
        self.map = NavMap(self.fp, CostParams(), ttl_ns, n.people_in_costmap, self.source.name, log)
        period_ns = round(self.period_s * NS_PER_S)
        lockstep = cfg.time.mode == "lockstep"
        #: One lock for the goal intake and the map feed (the queryable's, the fetch's and
        #: the loop's threads).
        ticked = threading.Condition(threading.Lock())
        self.feed: MapFeed | None = None
        if isinstance(self.source, MapSource):
            refresh_ns = round(n.map_refresh_s * NS_PER_S)
            self.feed = MapFeed(
                self.source, ticked, log,
                lockstep=lockstep, refresh_ns=refresh_ns, timeout_s=INPUT_TIMEOUT_S,
            )  # fmt: skip
        if isinstance(self.source, WorldSource):  # truth: there at once, and static
            self.map.adopt(self.source.grid(), self.source.people(), 0, 0)
        self.nav = Navigator(self.fp, n, self.period_s)
        #: The caps on the base's axes for other drivers (`people.base_caps`), as published.
        self.caps: Caps = (math.inf,) * 4
        #: The static world's clearance along the base's axes (`body_guard.clearance`).
        self.clear: Caps = (math.inf,) * 4
        self.cap_person = ""
        #: The lidar's tracks near the base (`scan_people.nearest_tracks`), as published.
        self.bodies: tuple[ScanBody, ...] = ()
        self.camera = n.obstacle_camera if n.obstacle_camera in cfg.sim.cameras else ""
        self.odom = bus.latest(keys.odom, Odom, history=16)
        self.map_frame = MapFrame(bus, keys, cfg)
        self.depth: DepthFeed | None = None
        if self.camera:
            frames = bus.latest(keys.camera_rgbd(self.camera), CameraFrame, 2)
            camera_period_ns = round(NS_PER_S / cfg.sim.camera_hz)
            self.depth = DepthFeed(
                frames, self.camera, camera_period_ns, self.fp, log, INPUT_TIMEOUT_S
            )
        #: The lidars' scans: the trunk's front one, and its rear twin when the robot has it.
        self.scans = [bus.latest(keys.scan, LaserScan, history=4)]
        if cfg.sim.sensors.lidar.rear:
            self.scans.append(bus.latest(keys.scan_rear, LaserScan, history=4))
        #: The scans none of which has come, after one wait for the first: not waited for.
        self.scans_absent: set[int] = set()
        self.scan_period_ns = round(NS_PER_S / cfg.sim.sensors.lidar.rate_hz)
        cancels = bus.fifo(keys.nav_cancel, NavCancel, maxlen=64)
        # People seen by perception (the head camera), applied at their stamp + latency.
        self.perception = PerceptionFeed(bus, keys, cfg, self.camera, INPUT_TIMEOUT_S)
        self.cmd_pub = bus.publisher(keys.cmd_vel, CmdVel, "control", again=True)
        self.status_pub = bus.publisher(keys.nav_status, NavStatus, "data")
        self.path_pub = bus.publisher(keys.nav_path, NavPath, "data")
        self.ticker = PeriodicTicker(bus, keys, NAME, self.period_s, svc.stop)
        self.log = NavLogger(svc.rec, log)
        self.pose: Pose | None = None
        self.intake = GoalIntake(
            self.nav, self.source, ticked, lambda: (self.map.costmap, self.pose), cancels.drain,
            log, fp=self.fp, tolerance=(n.goal_tolerance_m, n.goal_tolerance_rad),
            lockstep=lockstep, period_ns=period_ns, timeout_s=INPUT_TIMEOUT_S,
            latency_ns=cfg.time.latency_ns_of(NAME, self.period_s), costmap=self.map.costmap,
        )  # fmt: skip
        bus.serve(keys.nav_goal, NavGoalRequest, self.intake.on_goal)

    def run(self) -> None:
        if self.feed is not None:
            self.feed.start(self.svc.stop)
        self.svc.ready()
        self.ticker.run(self.tick)

    def tick(self, b: int) -> None:
        t0 = time.perf_counter()
        try:
            self.odom.wait_stamp(b, INPUT_TIMEOUT_S)
        except WaitTimeout:
            self.svc.log.warning("no odom for t=%.2f s: standing still", b / NS_PER_S)
        odom = self.odom.at(b)
        m = self.map
        if odom is None:
            self._publish(b, np.zeros(3), None, "no odom")
            self.intake.done(b, m.costmap, self.pose)
            return
        if not self.map_frame.wait(b, INPUT_TIMEOUT_S):
            self.svc.log.warning("no localization due at t=%.2f s", b / NS_PER_S)
        T_map_base = self.map_frame.base(odom, b)  # odom, corrected into the map
        pose = Pose(float(T_map_base[0, 3]), float(T_map_base[1, 3]), yaw_of(T_map_base[:3, :3]))
        self.pose = pose
        changed = self.depth is not None and self.depth.update(b, pose, T_map_base, m.grid, m.layer)
        changed = self._scan(b, pose, T_map_base) or changed
        fresh = self.feed.tick(b) if self.feed is not None else None
        seen_changed = m.see(self.perception.due(b), b)  # every tick: lockstep waits here
        changed = m.take(fresh, seen_changed, b) or changed
        self.intake.apply_cancels(b)
        if m.costmap is None:
            self._publish(b, np.zeros(3), None, "waiting for the map", self.intake.queued(b))
            self.intake.done(b, m.costmap, pose)
            return
        if self.map_frame.status(b) == "lost":  # it does not know where it is: stand
            self.caps, self.cap_person = (0.0,) * 4, ""  # nor where people are from it
            self.bodies = ()
            self._publish(b, np.zeros(3), None, "localization lost", self.intake.queued(b))
            self.intake.done(b, m.costmap, pose)
            return
        self.intake.start_due(b, m.costmap, pose, m.map_at)
        if fresh is not None:
            self.intake.follow_person(b, m.costmap, pose, m.map_people, m.people, m.scanned)
        if changed:
            m.rebuild(b)
        out = self.nav.tick(b, pose, m.costmap, map_velocity(odom, pose.yaw))
        self._caps(b, pose)
        if out.recovery == "clear" and self.nav.recovery == "clear":
            m.clear(b)
        self._publish(b, out.cmd, out)
        self.intake.done(b, m.costmap, pose)
        tick_ms = (time.perf_counter() - t0) * 1e3
        wz = odom.base_angular_velocity_in_base[2]
        self.log.tick(b, pose, self.nav, out, m.costmap, tick_ms, wz)

    def _caps(self, b: int, pose: Pose) -> None:
        """The speed and separation monitor's caps on the base's axes for what drives it
        without a goal (`people.base_caps`, on `nav/status`); an axis stopped or released
        is logged (with who and how near)."""
        cm, n = self.map.costmap, self.svc.config.navigation
        if cm is None:
            return
        stopped = tuple(c == 0.0 for c in self.caps)
        limits = base_caps(pose, cm.people, self.fp, n.people, n.controller.v_max[0], stopped)
        ahead, behind, left, right = (lim.speed for lim in limits)
        caps = (ahead, behind, left, right)
        tight = min(limits, key=lambda lim: lim.speed)
        person = tight.person_id if math.isfinite(tight.speed) else ""
        if tuple(c == 0.0 for c in caps) != stopped:  # an axis stopped or released
            said = ", ".join(
                f"{w} {c:.2f}"
                for w, c in zip(("ahead", "behind", "left", "right"), caps, strict=True)
                if math.isfinite(c)
            )
            self.svc.log.info("t=%.2f s base caps for other drivers: %s", b / NS_PER_S,
                              f"{said} m/s ({person}, {tight.distance_m:.2f} m)" if person
                              else "none")  # fmt: skip
        self.caps, self.cap_person = caps, person
        self.clear = clearance(cm.solid, cm.grid, self.fp, pose)
        self.bodies = tuple(
            ScanBody(id=q.id, x=q.x, y=q.y, velocity=q.velocity)
            for q in nearest_tracks(self.map.scanned, pose.x, pose.y)
        )

    def _scan(self, b: int, pose: Pose, T_map_base: np.ndarray) -> bool:
        """The lidars' scans stamped b (at their rate) into the people layer, the front's
        returns then the rear's; whether the costmap is to be rebuilt. Each is waited for
        (lockstep: the same scans in every run) while its scans flow (one stamped within
        `SCAN_FLOWING` periods before b came); one that does not come in `SCAN_WAIT_S` is
        said and skipped, and the tracks go stale. A lidar none of whose scans ever came
        is waited for once, then not until one comes."""
        if b % self.scan_period_ns:
            return False
        worlds, views = [], []
        for k, scans in enumerate(self.scans):
            newest = scans.get()
            if newest is None and k in self.scans_absent:
                continue  # never came, nor since its wait timed out: a lidar that is not there
            if newest is None or newest.stamp_ns >= b - SCAN_FLOWING * self.scan_period_ns:
                try:
                    scans.wait_stamp(b, SCAN_WAIT_S)
                except WaitTimeout:
                    self.svc.log.warning("no %s for t=%.2f s: its people go stale",
                                         scans.key.rsplit("/", 1)[-1], b / 1e9)  # fmt: skip
                    if newest is None:
                        self.scans_absent.add(k)
            scan = scans.at(b)
            if scan is None or scan.stamp_ns != b:
                continue
            T = np.asarray(scan.T_base_lidar).reshape(4, 4)
            ranges = np.asarray(as_numpy(scan.ranges), dtype=float)
            pts = scan_points(ranges, scan.angle_min, scan.angle_increment, T)
            worlds.append(pts @ T_map_base[:2, :2].T + T_map_base[:2, 3])
            T_map_lidar = T_map_base @ T
            views.append(ScanView(
                (float(T_map_lidar[0, 3]), float(T_map_lidar[1, 3])),
                math.atan2(T_map_lidar[1, 0], T_map_lidar[0, 0]),
                scan.angle_min, scan.angle_increment, ranges, scan.range_max,
            ))  # fmt: skip
        if not worlds:
            return False
        changed = self.map.see_scan(np.vstack(worlds), pose, b, views)
        self.log.scan(b, self.map.scan.bodies, self.map.scanned, self.map.scan.obstacles)
        return changed

    def _publish(
        self,
        b: int,
        cmd: np.ndarray,
        out: TickOutput | None,
        detail: str = "",
        queued: str = "",
    ) -> None:
        """cmd_vel and the status; `queued`: a goal taken before the map (active, waiting)."""
        self.cmd_pub.put(
            CmdVel(stamp_ns=b, vx=float(cmd[0]), vy=float(cmd[1]), wz=float(cmd[2]), source=NAME)
        )
        goal_id = queued or self.nav.goal_id
        caps, person = self.caps, self.cap_person
        if out is None:
            state = "active" if queued else self.nav.state
            status = NavStatus(
                stamp_ns=b, goal_id=goal_id, state=state, detail=detail,
                caps_mps=caps, cap_person=person, clear_m=self.clear, bodies=self.bodies,
            )  # fmt: skip
            self.status_pub.put(status)
            return
        if out.new_plan is not None:
            self.path_pub.put(
                NavPath(
                    stamp_ns=b,
                    goal_id=goal_id,
                    poses=to_wire(np.ascontiguousarray(out.new_plan.poses)),
                )
            )
        self.status_pub.put(
            NavStatus(
                stamp_ns=b,
                goal_id=goal_id,
                state=out.state,
                reason=out.reason,
                detail=out.detail,
                progress=out.progress,
                remaining_m=out.remaining_m,
                caps_mps=caps,
                cap_person=person,
                clear_m=self.clear,
                bodies=self.bodies,
            )
        )


def map_velocity(odom: Odom, map_yaw: float) -> tuple[float, float]:
    """The base's measured floor velocity (the odometry's, in its own world frame) in the
    map frame, the base's heading there being `map_yaw`: the map's correction of the
    odometry is a rotation about the vertical."""
    turn = map_yaw - yaw_of_quat_xyzw(odom.base_orientation_xyzw)
    c, s = math.cos(turn), math.sin(turn)
    vx, vy = odom.base_linear_velocity_in_world[:2]
    return c * vx - s * vy, s * vx + c * vy


def main(svc: Service) -> None:
    NavNode(svc).run()
