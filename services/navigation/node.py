"""The navigation service: a 20 Hz lockstep participant around the pure modules.

Start-up: the map source (`navigation.map_source`): the sim's truth description (tests)
is read before ready; the semantic map is fetched every `map_refresh_s` of sim time on a
thread of its own (grid and people as of that tick), adopted `MAP_ADOPT_S` later (waited
for in lockstep, so every run adopts it at the same tick), and until its grid is in,
navigation is ready but idle ("waiting for the map": zero cmd_vel); a goal sent then is
taken and queued (its status `active`, "waiting for the map") and resolved at the first
tick with a map, against the map as fetched, so no client needs to retry. Each tick b (multiples of
`time.participants.navigation.period_s`): the odom stamped b (waited for: odom is on a
known 50 Hz schedule), the head camera's depth when a frame is due at b (10 Hz; marks
and clears the short-lived layer), perception's person detections that apply by b (the
head camera's, `PerceptionFeed`, waited for in lockstep; the people layer is those seen
over the map's people, `SeenPeople`), the cancels received; the costmap is rebuilt when
a layer changed; `Navigator.tick`; then `wbc/cmd_vel` (source `navigation`, zero when
idle) and `nav/status` stamped b every tick, `nav/path` on every new plan, and the ack.
Goals arrive on the `nav/goal` queryable's thread: resolved there against the costmap
and pose as of the sender's tick (`NavGoalRequest.stamp_ns`: navigation's tick one
latency before it, which the sender waited for; the newest without a stamp) and the
map's data as of that tick (refusals with a reason), and started by the loop at its
first tick at or after `effective_ns`; cancels likewise. So goals, cancels and map
updates take effect at ticks fixed by sim time, never by when a message happened to
arrive. Speed-limit changes and recoveries are logged.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque

import numpy as np

from common.bus import RequestError, WaitTimeout
from common.camera import PinholeCamera
from common.geometry import yaw_of_quat_xyzw
from common.lockstep import PeriodicTicker
from common.messages import as_numpy, to_wire
from common.messages.base import NS_PER_S
from common.messages.navigation import (
    ArtifactStandoff,
    NavCancel,
    NavGoalReply,
    NavGoalRequest,
    NavPath,
    NavStatus,
    PersonHandover,
    PoseGoal,
)
from common.messages.sim import CameraFrame, Odom
from common.messages.wbc import CmdVel
from common.service import Service
from services.navigation import goals
from services.navigation.controller import ControllerParams
from services.navigation.costmap import Costmap, CostParams, ObstacleLayer, Person, build_costmap
from services.navigation.depth import DepthParams, obstacle_cells, seen_through
from services.navigation.goals import GoalInvalid, Queued
from services.navigation.grid import Footprint, Grid, Pose
from services.navigation.nav_log import NavLogger
from services.navigation.navigator import GoalSpec, Navigator, NavParams, TickOutput
from services.navigation.people import PeopleParams
from services.navigation.perceived import PerceptionFeed
from services.navigation.planner import PlanParams
from services.navigation.seen_people import SeenPeople
from services.navigation.sources import MapSource, Source, SourceError, WorldSource

NAME = "navigation"
INPUT_TIMEOUT_S = 30.0
#: Sim seconds from a map fetch's tick to the tick that adopts it.
MAP_ADOPT_S = 0.25
#: A goal taken before the map fails when the map has not come this long after, s.
MAP_WAIT_S = 30.0
#: Ticks of (costmap, pose) kept to resolve goals as of their sender's tick.
HISTORY = 16


def odom_pose(odom: Odom) -> Pose:
    p = odom.base_position_in_world
    return Pose(p[0], p[1], yaw_of_quat_xyzw(odom.base_orientation_xyzw))


class NavNode:
    """The loop and what it keeps between ticks; see the module docstring."""

    def __init__(self, svc: Service) -> None:
        self.svc, cfg = svc, svc.config
        n = cfg.navigation
        self.period_s = cfg.time.period_of(NAME, 0.05)
        self.fp = Footprint.stowed()
        self.cost_params = CostParams(obstacle_ttl_s=n.obstacle_ttl_s)
        self.params = NavParams(
            replan_s=n.replan_s,
            blocked_timeout_s=n.blocked_timeout_s,
            timeout_s=n.goal_timeout_s,
            controller=ControllerParams(
                v_max=(n.v_max[0], n.v_max[1], n.v_max[2]),
                a_max=(n.a_max[0], n.a_max[1], n.a_max[2]),
                lookahead_m=n.lookahead_m,
            ),
            planner=PlanParams(cost_weight=n.cost_weight, goal_tolerance_m=n.goal_search_m),
            people=PeopleParams(
                slow_radius_m=n.slow_radius_m,
                slow_speed=n.slow_speed,
                stop_distance_m=n.stop_distance_m,
                handover_speed=n.handover_speed,
                ramp_top_mps=max(n.v_max[0], n.v_max[1]),
            ),
        )
        self.depth_params = DepthParams()
        bus, keys = svc.bus, svc.keys
        self.source: Source = self._world_source() if n.map_source == "world" else MapSource(bus)
        self.ttl_ns = round(n.obstacle_ttl_s * NS_PER_S)
        self.grid: Grid | None = None
        self.layer = ObstacleLayer((1, 1), self.ttl_ns)
        self.people: list[Person] = []
        self.map_people: list[Person] = []
        self.seen = SeenPeople()
        self.costmap: Costmap | None = None
        #: The sim time the map in use is as of (goals queued before it resolve against it).
        self._map_at = 0
        self.period_ns = round(self.period_s * NS_PER_S)
        self.latency_ns = cfg.time.latency_ns_of(NAME, self.period_s)
        self.refresh_ns = round(n.map_refresh_s * NS_PER_S)
        self.lockstep = cfg.time.mode == "lockstep"
        #: The map fetch in flight: (its tick, the result once in: grid and people, or the
        #: error's sentence).
        self._fetch: tuple[int, tuple[Grid, list[Person]] | str | None] | None = None
        self._fetch_due = threading.Event()
        if isinstance(self.source, WorldSource):  # truth: there at once, and static
            self._adopt(self.source.grid(), self.source.people(), 0, 0)
        self.nav = Navigator(self.fp, self.params, self.period_s)
        self.camera = n.obstacle_camera if n.obstacle_camera in cfg.sim.cameras else ""
        self.camera_period_ns = round(NS_PER_S / cfg.sim.camera_hz)
        self.odom = bus.latest(keys.odom, Odom, history=16)
        self.frames = (
            bus.latest(keys.camera_rgbd(self.camera), CameraFrame, 2) if self.camera else None
        )
        self.cancels = bus.fifo(keys.nav_cancel, NavCancel, maxlen=64)
        # People seen by perception (the head camera), applied at their stamp + latency.
        self.perception = PerceptionFeed(bus, keys, cfg, self.camera, INPUT_TIMEOUT_S)
        self.cmd_pub = bus.publisher(keys.cmd_vel, CmdVel, "control")
        self.status_pub = bus.publisher(keys.nav_status, NavStatus, "data")
        self.path_pub = bus.publisher(keys.nav_path, NavPath, "data")
        self.ticker = PeriodicTicker(bus, keys, NAME, self.period_s, svc.stop)
        self.log = NavLogger(svc.rec, svc.log)
        self._lock = threading.Lock()
        #: Navigation's ticks done, with their costmap and pose (goals resolve against them).
        self._ticked = threading.Condition(self._lock)
        self._history: deque[tuple[int, Costmap | None, Pose | None]] = deque(maxlen=HISTORY)
        self._history.append((-1, self.costmap, None))  # before the first tick
        #: The goal to start at its effective tick (resolved, or queued before the map).
        self._pending: tuple[GoalSpec | Queued, int] | None = None
        self._cancels: list[NavCancel] = []
        self._count = 0
        self._pose: Pose | None = None
        bus.serve(keys.nav_goal, NavGoalRequest, self._on_goal)

    # -- map ------------------------------------------------------------------------------

    def _world_source(self) -> WorldSource:
        while True:
            try:
                return WorldSource(self.svc.bus, timeout_s=5.0)
            except SourceError as exc:
                self.svc.log.info("waiting for the sim: %s", exc)
                if self.svc.stop.wait(0.5):
                    raise

    def _fetch_map(self) -> None:
        """The semantic map's grid and people as of the tick the loop asks for (its own
        thread: a query may take seconds, which the lockstep loop must not)."""
        said = ""
        while not self.svc.stopping:
            if not self._fetch_due.wait(0.2):
                continue
            self._fetch_due.clear()
            with self._lock:
                if self._fetch is None:
                    continue
                b = self._fetch[0]
            try:
                got: tuple[Grid, list[Person]] | str = (
                    self.source.grid(at_ns=b),
                    self.source.people(at_ns=b),
                )
                said = ""
            except SourceError as exc:
                got = str(exc)
                if got != said:
                    self.svc.log.warning("map unavailable: %s", exc)
                    said = got
            with self._ticked:
                if self._fetch is not None and self._fetch[0] == b:
                    self._fetch = (b, got)
                    self._ticked.notify_all()

    def _map_tick(self, b: int) -> tuple[Grid, list[Person], int] | None:
        """Ask for the map at every `map_refresh_s`; the fetch to adopt at b, if any (grid,
        people and the tick they are as of)."""
        with self._ticked:
            fetch = self._fetch
            if fetch is None or b < fetch[0] + round(MAP_ADOPT_S * NS_PER_S):
                fetch = None  # none in flight, or not due yet
            elif fetch[1] is None and self.lockstep:  # every run adopts it at this tick
                self._ticked.wait_for(
                    lambda: self._fetch is None or self._fetch[1] is not None, INPUT_TIMEOUT_S
                )
                fetch = self._fetch
                if fetch is not None and fetch[1] is None:
                    self.svc.log.warning(
                        "map fetch of t=%.2f s never came: dropped", fetch[0] / 1e9
                    )
            if fetch is not None and (fetch[1] is not None or self.lockstep):
                self._fetch = None  # adopted (or failed, or given up)
            else:
                fetch = None  # realtime: adopted at the first tick after it is in
            if self._fetch is None and b % self.refresh_ns == 0:
                self._fetch = (b, None)
                self._fetch_due.set()
        got = None if fetch is None else fetch[1]
        return (*got, fetch[0]) if isinstance(got, tuple) and fetch is not None else None

    def _adopt(self, grid: Grid, people: list[Person], as_of: int, t_ns: int) -> None:
        """Take a map as of `as_of` (ns) at tick t."""
        if self.grid is None or self.grid.shape != grid.shape:
            self.svc.log.info(
                "map from %s: %s cells of %.2f m", self.source.name, grid.shape, grid.resolution
            )
            self.layer = ObstacleLayer(grid.shape, self.ttl_ns)
        self.grid, self.map_people, self._map_at = grid, people, as_of
        self.people = self.seen.merge(people, t_ns)
        self.costmap = self._build(t_ns)

    def _build(self, t_ns: int) -> Costmap:
        assert self.grid is not None  # called once a grid is in
        people = self.people if self.svc.config.navigation.people_in_costmap else []
        cm = build_costmap(self.grid, self.fp, self.cost_params, self.layer.active(t_ns), people)
        # The speed rules always see every person, whether or not the plan avoids them.
        return Costmap(cm.grid, cm.cost, cm.occupied, cm.clearance, tuple(self.people))

    # -- goals (the server's thread) ------------------------------------------------------

    def _as_of(self, stamp_ns: int | None) -> tuple[Costmap | None, Pose | None]:
        """The costmap and pose after navigation's tick one latency before `stamp_ns` (the
        sender's tick; it waited for that tick's output), or the newest without a stamp
        (or, with a warning, when that tick is not done within `INPUT_TIMEOUT_S`)."""
        if stamp_ns is None or not self.lockstep:
            return self.costmap, self._pose
        want = ((stamp_ns - self.latency_ns) // self.period_ns) * self.period_ns
        with self._ticked:
            done = self._ticked.wait_for(
                lambda: bool(self._history) and self._history[-1][0] >= want, INPUT_TIMEOUT_S
            )
            for b, cm, pose in reversed(self._history):
                if b <= want:
                    return cm, pose
        if done:  # older than the history: the oldest kept is the best guess
            self.svc.log.warning("goal stamped %d: tick %d is out of the history", stamp_ns, want)
        else:
            self.svc.log.warning("goal stamped %d: navigation has not done tick %d", stamp_ns, want)
        return self.costmap, self._pose

    def _on_goal(self, req: NavGoalRequest | None, _selector: str) -> NavGoalReply:
        if req is None:
            raise RequestError("malformed", "a NavGoalRequest is needed")
        cm, pose = self._as_of(req.stamp_ns)
        effective = -1 if req.effective_ns is None else req.effective_ns
        if cm is None:  # no map yet: taken now, resolved at the first tick that has one
            with self._lock:
                self._count += 1
                queued = Queued(f"nav_{self._count}", req)
                self._pending = (queued, effective)
            self.svc.log.info("goal %s queued until the map is in", queued.goal_id)
            return NavGoalReply(accepted=True, goal_id=queued.goal_id)
        try:
            target, tol, tol_yaw, handover = self._resolve(req, cm, pose, req.stamp_ns)
        except GoalInvalid as exc:
            return NavGoalReply(accepted=False, reason=f"invalid_goal: {exc}")
        with self._lock:
            self._count += 1
            spec = GoalSpec(f"nav_{self._count}", target, tol, tol_yaw, handover)
            self._pending = (spec, effective)
        self.svc.log.info(
            "goal %s accepted: %s -> (%.2f, %.2f, %.2f)",
            spec.goal_id,
            type(req.goal).__name__,
            *target,
        )
        return NavGoalReply(accepted=True, goal_id=spec.goal_id)

    def _resolve(
        self, req: NavGoalRequest, cm: Costmap, pose: Pose | None, at: int | None
    ) -> tuple[Pose, float, float, str]:
        """The goal's pose, tolerances and handover person against `cm` and the map's
        data as of `at`; `GoalInvalid` with the reason."""
        cfg, g = self.svc.config.navigation, req.goal
        try:
            if isinstance(g, PoseGoal):
                target = Pose(g.x, g.y, g.yaw)
                tol, tol_yaw, handover = g.position_tolerance_m, g.yaw_tolerance_rad, ""
            elif isinstance(g, ArtifactStandoff):
                x, y = self.source.artifact_xy(g.artifact_id, at_ns=at)
                target = goals.standoff_pose(cm, x, y, self.fp)
                tol, tol_yaw, handover = cfg.goal_tolerance_m, cfg.goal_tolerance_rad, ""
            else:
                assert isinstance(g, PersonHandover)
                person = self.source.person(g.person_id, at_ns=at)
                here = (pose.x, pose.y) if pose else (person.x + 1.0, person.y)
                target = goals.handover_pose(cm, person, here, self.fp)
                tol, tol_yaw, handover = cfg.goal_tolerance_m, cfg.goal_tolerance_rad, g.person_id
        except (SourceError, goals.GoalError) as exc:
            raise GoalInvalid(str(exc)) from None
        if not all(math.isfinite(v) for v in target) or cm.grid.cell(target.x, target.y) is None:
            raise GoalInvalid(f"{target} is off the map")
        return target, tol, tol_yaw, handover

    def _start(self, pending: GoalSpec | Queued, b: int) -> None:
        """Start a goal at its tick; one queued before the map is resolved now (against
        the map as fetched for the costmap in use: the same in every run)."""
        if isinstance(pending, Queued):
            assert self.costmap is not None  # the loop starts goals only with a costmap
            try:
                target, tol, tol_yaw, handover = self._resolve(
                    pending.request, self.costmap, self._pose, self._map_at
                )
            except GoalInvalid as exc:
                self.svc.log.info("goal %s refused once the map came: %s", pending.goal_id, exc)
                self.nav.refuse(pending.goal_id, str(exc))
                return
            pending = GoalSpec(pending.goal_id, target, tol, tol_yaw, handover)
            self.svc.log.info(
                "goal %s resolved: (%.2f, %.2f, %.2f)", pending.goal_id, *pending.pose
            )
        if self.nav.state == "active" and self.nav.goal is not None:
            self.svc.log.info("goal %s replaced by %s", self.nav.goal.goal_id, pending.goal_id)
        self.nav.start(pending, b)

    # -- the loop -------------------------------------------------------------------------

    def run(self) -> None:
        if isinstance(self.source, MapSource):
            threading.Thread(target=self._fetch_map, name="map", daemon=True).start()
        self.svc.ready()
        for b in self.ticker.ticks():
            try:
                self.tick(b)
            finally:
                self.ticker.ack(b)

    def _camera(self, b: int, pose: Pose) -> bool:
        if self.frames is None or self.grid is None or b % self.camera_period_ns:
            return False
        try:
            self.frames.wait_stamp(b, INPUT_TIMEOUT_S)
        except WaitTimeout:
            self.svc.log.warning("no %s frame for t=%.2f s", self.camera, b / NS_PER_S)
            return False
        f = self.frames.at(b)
        if f is None or f.stamp_ns != b:
            return False
        T = np.array(f.T_world_base).reshape(4, 4) @ np.array(f.T_base_camera).reshape(4, 4)
        cam = PinholeCamera(
            f.fx, f.fy, f.cx, f.cy, T, np.asarray(as_numpy(f.depth), dtype=np.float32)
        )
        iy, ix = np.nonzero(self.layer.active(b))
        through = seen_through(cam, self.grid, iy, ix, self.depth_params)
        self.layer.clear(iy[through], ix[through])
        my, mx = obstacle_cells(cam, self.grid, pose, self.fp, self.depth_params)
        self.layer.mark(my, mx, b)
        return bool(len(my) or through.any() or len(iy))

    def _perceive(self, b: int) -> bool:
        """The head camera's people detections due by b; whether the people seen changed."""
        due = self.perception.due(b)
        before = self.seen.active(b)
        for d in due:
            self.seen.update(d, self.grid)
        return self.seen.active(b) != before

    def tick(self, b: int) -> None:
        t0 = time.perf_counter()
        try:
            self.odom.wait_stamp(b, INPUT_TIMEOUT_S)
        except WaitTimeout:
            self.svc.log.warning("no odom for t=%.2f s: standing still", b / NS_PER_S)
        odom = self.odom.at(b)
        if odom is None:
            self._publish(b, np.zeros(3), None, "no odom")
            self._done(b)
            return
        pose = odom_pose(odom)
        self._pose = pose
        changed = self._camera(b, pose)
        fresh = self._map_tick(b) if isinstance(self.source, MapSource) else None
        seen_changed = self._perceive(b)  # every tick: lockstep waits on perception here
        if fresh is not None:
            self._adopt(*fresh, b)
        elif seen_changed and self.grid is not None:
            self.people = self.seen.merge(self.map_people, b)
            changed = True
        self._apply_cancels(b)
        if self.costmap is None:
            self._publish(b, np.zeros(3), None, "waiting for the map", self._queued(b))
            self._done(b)
            return
        with self._lock:
            pending = None
            if self._pending is not None and self._pending[1] <= b:
                pending, self._pending = self._pending[0], None
        if pending is not None:
            self._start(pending, b)
        if changed:
            self.costmap = self._build(b)
        out = self.nav.tick(b, pose, self.costmap)
        if out.recovery == "clear" and self.nav.recovery == "clear":
            self.layer.clear_all()
            self.costmap = self._build(b)
        self._publish(b, out.cmd, out)
        self._done(b)
        tick_ms = (time.perf_counter() - t0) * 1e3
        wz = odom.base_angular_velocity_in_base[2]
        self.log.tick(b, pose, self.nav, out, self.costmap, tick_ms, wz)

    def _queued(self, b: int) -> str:
        """The id of a goal waiting for the map ("" if none); one that waited
        `MAP_WAIT_S` fails (`timeout`)."""
        with self._lock:
            pending, effective = self._pending or (None, -1)
            if not isinstance(pending, Queued):
                return ""
            if pending.since_ns < 0:
                self._pending = (Queued(pending.goal_id, pending.request, b), effective)
            elif b - pending.since_ns >= MAP_WAIT_S * NS_PER_S:
                self._pending = None
                detail = f"no map from {self.source.name} within {MAP_WAIT_S:.0f} s"
                self.svc.log.warning("goal %s failed: %s", pending.goal_id, detail)
                self.nav.refuse(pending.goal_id, detail, "timeout")
                return ""
            return pending.goal_id

    def _apply_cancels(self, b: int) -> None:
        """The cancels due at b: of the active goal, or of one not started yet (an id of
        "" cancels whichever)."""
        with self._lock:
            self._cancels.extend(self.cancels.drain())
            due = [c for c in self._cancels if c.effective_ns is None or c.effective_ns <= b]
            self._cancels = [c for c in self._cancels if c not in due]
            for c in due:
                if self._pending is not None and c.goal_id in ("", self._pending[0].goal_id):
                    self.svc.log.info("goal %s cancelled before it started", c.goal_id)
                    self._pending = None
        for c in due:
            if self.nav.state == "active" and c.goal_id in ("", self.nav.goal_id):
                self.nav.cancel(c.reason or "cancelled")
                self.svc.log.info("goal %s cancelled: %s", self.nav.goal_id, c.reason)

    def _done(self, b: int) -> None:
        with self._ticked:
            self._history.append((b, self.costmap, self._pose))
            self._ticked.notify_all()

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
        if out is None:
            state = "active" if queued else self.nav.state
            self.status_pub.put(NavStatus(stamp_ns=b, goal_id=goal_id, state=state, detail=detail))
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
            )
        )


def main(svc: Service) -> None:
    NavNode(svc).run()
