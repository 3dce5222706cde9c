"""Goal intake: goals and cancels, taken on the queryable's thread, started by the loop.

Times are ns of sim time (a tick b, a request's `stamp_ns` and `effective_ns`); poses
are the base's in the world frame (m, rad; `grid.Pose`).

On the `nav/goal` queryable's thread, `on_goal` resolves a request against the costmap
and pose as of the sender's tick (`as_of`: navigation's tick one latency before
`stamp_ns`, which the sender waited for, looked up in the last `HISTORY` ticks and, in
lockstep, waited for up to `timeout_s` wall seconds, else the newest tick done; the
newest, `now()`, without a stamp or in realtime) and the map's data as of that tick:
accepted with an id, or refused with the reason (`invalid_goal: …`). With no costmap yet
it is taken and queued (`Queued`) to be resolved once the map is in. Either way it is
pending until its `effective_ns`; a newer goal replaces a pending one.

On the loop's thread, each tick b: `apply_cancels(b)` (the cancels due at b: of the
pending goal or of the active one; an id of "" cancels whichever); then, while there is
no costmap, `queued(b)` (the id of the goal waiting for the map, reported `active`; it
fails `timeout` after `MAP_WAIT_S` of sim time), else `start_due(b, …)` (the pending goal
whose tick has come is started; a queued one is resolved now, against the map as fetched,
so the same in every run); at each map adopted, `follow_person` (a handover goal's pose
is chosen again once its person, the lidar's track of them or the map's estimate, is
`RETARGET_M` from where it was chosen); last,
`done(b, …)` records the tick's costmap and pose and wakes `as_of`.

Locks: `cond` (the node's one condition, shared with `map_feed.MapFeed`) guards the
pending goal, the cancels, the goal count and the history; the navigator is touched by the
loop's thread only; `now()` and the map's data (`Source`) are read without it.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import replace

from common import robot
from common.bus import RequestError
from common.messages.base import NS_PER_S
from common.messages.navigation import (
    ArtifactStandoff,
    NavCancel,
    NavGoalReply,
    NavGoalRequest,
    PersonHandover,
    PoseGoal,
)
from services.navigation import goals
from services.navigation.costmap import Costmap, Person
from services.navigation.goals import GoalInvalid, Queued
from services.navigation.grid import Footprint, Pose
from services.navigation.navigator import GoalSpec, Navigator
from services.navigation.scan_people import handover_person
from services.navigation.sources import Source, SourceError

#: A goal taken before the map fails when the map has not come this long after, s.
MAP_WAIT_S = 30.0
#: A handover goal's person this far (m) from where its pose was chosen: chosen again.
RETARGET_M = 0.05
#: Ticks of (costmap, pose) kept to resolve goals as of their sender's tick.
HISTORY = 16
#: m: a handover goal's heading is kept within this of their person, sideways, at the
#: handover distance (its yaw tolerance: `handover_yaw_tolerance`). The navigation's
#: 0.1 rad put hall seed 7's person 0.13 m to the side, past the mission's 0.12 m check
#: (`mission.handover_tol_m`), and the goal once more was already there: the bottle was
#: held out 60 s beyond the person's reach.
HANDOVER_SIDEWAYS_M = 0.06


def handover_yaw_tolerance(default_rad: float) -> float:
    """A handover goal's yaw tolerance: `default_rad`, or less, so that its person stands
    within `HANDOVER_SIDEWAYS_M` of the line ahead."""
    return min(default_rad, math.atan2(HANDOVER_SIDEWAYS_M, robot.HANDOVER_DISTANCE_M))


class GoalIntake:
    """The pending goal, the cancels and the tick history; see the module docstring.

    `tolerance`: (m, rad) of the standoff and handover goals (a `PoseGoal` carries its
    own); `now`: the newest costmap and pose; `cancels`: the cancels received since.
    """

    def __init__(
        self,
        nav: Navigator,
        source: Source,
        cond: threading.Condition,
        now: Callable[[], tuple[Costmap | None, Pose | None]],
        cancels: Callable[[], Iterable[NavCancel]],
        log: logging.Logger,
        *,
        fp: Footprint,
        tolerance: tuple[float, float],
        lockstep: bool,
        period_ns: int,
        latency_ns: int,
        timeout_s: float,
        costmap: Costmap | None,
    ) -> None:
        self.nav, self.source, self.fp, self.tolerance = nav, source, fp, tolerance
        self.now, self.cancels, self.log = now, cancels, log
        self.lockstep, self.period_ns, self.latency_ns = lockstep, period_ns, latency_ns
        self.timeout_s = timeout_s
        #: Navigation's ticks done, with their costmap and pose (goals resolve against them).
        self._ticked = cond
        self._history: deque[tuple[int, Costmap | None, Pose | None]] = deque(maxlen=HISTORY)
        self._history.append((-1, costmap, None))  # before the first tick
        #: The goal to start at its effective tick (resolved, or queued before the map).
        self._pending: tuple[GoalSpec | Queued, int] | None = None
        self._cancels: list[NavCancel] = []
        self._count = 0

    # -- the queryable's thread -----------------------------------------------------------

    def as_of(self, stamp_ns: int | None) -> tuple[Costmap | None, Pose | None]:
        """The costmap and pose after navigation's tick one latency before `stamp_ns` (the
        sender's tick; it waited for that tick's output), or the newest (`now()`) without a
        stamp or in realtime. When that tick is not done within `timeout_s`, the newest
        tick done (the history always holds one, so the second warning below is not
        reached); for a tick older than the history, `now()` with a warning."""
        if stamp_ns is None or not self.lockstep:
            return self.now()
        want = ((stamp_ns - self.latency_ns) // self.period_ns) * self.period_ns
        with self._ticked:
            done = self._ticked.wait_for(
                lambda: bool(self._history) and self._history[-1][0] >= want, self.timeout_s
            )
            for b, cm, pose in reversed(self._history):
                if b <= want:
                    return cm, pose
        if done:  # older than the history: the oldest kept is the best guess
            self.log.warning("goal stamped %d: tick %d is out of the history", stamp_ns, want)
        else:
            self.log.warning("goal stamped %d: navigation has not done tick %d", stamp_ns, want)
        return self.now()

    def on_goal(self, req: NavGoalRequest | None, _selector: str) -> NavGoalReply:
        if req is None:
            raise RequestError("malformed", "a NavGoalRequest is needed")
        cm, pose = self.as_of(req.stamp_ns)
        effective = -1 if req.effective_ns is None else req.effective_ns
        if cm is None:  # no map yet: taken now, resolved at the first tick that has one
            with self._ticked:
                self._count += 1
                queued = Queued(f"nav_{self._count}", req)
                self._pending = (queued, effective)
            self.log.info("goal %s queued until the map is in", queued.goal_id)
            return NavGoalReply(accepted=True, goal_id=queued.goal_id)
        try:
            resolved = self.resolve(req, cm, pose, req.stamp_ns)
        except GoalInvalid as exc:
            self.log.info("goal %s refused: %s", type(req.goal).__name__, exc)
            return NavGoalReply(accepted=False, reason=f"invalid_goal: {exc}")
        with self._ticked:
            self._count += 1
            spec = replace(resolved, goal_id=f"nav_{self._count}")
            target = spec.pose
            self._pending = (spec, effective)
        self.log.info(
            "goal %s accepted: %s -> (%.2f, %.2f, %.2f)",
            spec.goal_id,
            type(req.goal).__name__,
            *target,
        )
        return NavGoalReply(accepted=True, goal_id=spec.goal_id)

    def resolve(
        self, req: NavGoalRequest, cm: Costmap, pose: Pose | None, at: int | None, goal_id: str = ""
    ) -> GoalSpec:
        """The goal's pose, tolerances and handover person against `cm` and the map's
        data as of `at`; `GoalInvalid` with the reason."""
        g = req.goal
        person_xy, bearing, distance = None, None, None
        try:
            if isinstance(g, PoseGoal):
                target = Pose(g.x, g.y, g.yaw)
                tol, tol_yaw, handover = g.position_tolerance_m, g.yaw_tolerance_rad, ""
            elif isinstance(g, ArtifactStandoff):
                x, y = self.source.artifact_xy(g.artifact_id, at_ns=at)
                target = goals.standoff_pose(
                    cm, x, y, self.fp, bearings=g.bearings_rad, tolerance=g.bearing_tolerance_rad
                )
                tol, tol_yaw, handover = *self.tolerance, ""
            else:
                assert isinstance(g, PersonHandover)
                person = self.source.person(g.person_id, at_ns=at)
                here = (pose.x, pose.y) if pose else (person.x + 1.0, person.y)
                bearing = g.bearing_rad
                distance = robot.HANDOVER_DISTANCE_M + g.extra_m
                target = goals.handover_pose(cm, person, here, self.fp, bearing=bearing,
                                             distance=distance)  # fmt: skip
                tol, handover = self.tolerance[0], g.person_id
                tol_yaw = handover_yaw_tolerance(self.tolerance[1])
                person_xy = (person.x, person.y)
        except (SourceError, goals.GoalError) as exc:
            raise GoalInvalid(str(exc)) from None
        if not all(math.isfinite(v) for v in target) or cm.grid.cell(target.x, target.y) is None:
            raise GoalInvalid(f"{target} is off the map")
        return GoalSpec(goal_id, target, tol, tol_yaw, handover, person_xy, bearing, distance)

    def follow_person(
        self,
        b: int,
        cm: Costmap,
        pose: Pose,
        people: list[Person],
        layer: list[Person] | None = None,
        scanned: list[Person] | None = None,
    ) -> None:
        """A handover goal follows its person: once they are `RETARGET_M` from where the
        pose was chosen, the pose is chosen again from there (the estimate of a person
        far away firms up as the robot comes near; a person may step aside). Where they
        are (`scan_people.handover_person`): the lidar's track of them in the people
        `layer` (its floor point moved to their body's centre: from the near side of the
        legs, the pose stood the robot 0.11 m farther than the handover distance and
        nobody took the bottle, `tests/integration/test_coping.py`), else the map's
        estimate in `people`, not followed where the lidar sees free floor (seed 0's
        shift: the map carried person_4 0.8 m off, where nobody stood, while they waited
        1.2 m from the robot; the goal followed, and the robot stood 70 s aligning to
        it, stopped by the rules 0.62 m from the real person). Without a `layer`, the
        map's estimate."""
        g = self.nav.goal
        if self.nav.state != "active" or g is None or not g.handover_id or g.person_xy is None:
            return
        if layer is None:
            person = next((q for q in people if q.id == g.handover_id), None)
        else:
            person = handover_person(g.handover_id, people, layer, scanned or [], (pose.x, pose.y))
        if person is None or math.hypot(person.x - g.person_xy[0],
                                        person.y - g.person_xy[1]) < RETARGET_M:  # fmt: skip
            return
        try:
            here = (pose.x, pose.y)
            target = goals.handover_pose(
                cm, person, here, self.fp, bearing=g.bearing, distance=g.distance
            )
        except goals.GoalError as exc:
            self.log.info("goal %s keeps its pose: %s", g.goal_id, exc)
            return
        self.log.info(
            "goal %s follows %s to (%.2f, %.2f): (%.2f, %.2f, %.2f)",
            g.goal_id, person.id, person.x, person.y, *target,
        )  # fmt: skip
        self.nav.retarget(target, (person.x, person.y), b)

    # -- the loop's thread ----------------------------------------------------------------

    def apply_cancels(self, b: int) -> None:
        """The cancels due at b: of the active goal, or of one not started yet (an id of
        "" cancels whichever)."""
        with self._ticked:
            self._cancels.extend(self.cancels())
            due = [c for c in self._cancels if c.effective_ns is None or c.effective_ns <= b]
            self._cancels = [c for c in self._cancels if c not in due]
            for c in due:
                if self._pending is not None and c.goal_id in ("", self._pending[0].goal_id):
                    self.log.info("goal %s cancelled before it started", c.goal_id)
                    self._pending = None
        for c in due:
            if self.nav.state == "active" and c.goal_id in ("", self.nav.goal_id):
                self.nav.cancel(c.reason or "cancelled")
                self.log.info("goal %s cancelled: %s", self.nav.goal_id, c.reason)

    def queued(self, b: int) -> str:
        """The id of a goal waiting for the map ("" if none); one that waited
        `MAP_WAIT_S` fails (`timeout`)."""
        with self._ticked:
            pending, effective = self._pending or (None, -1)
            if not isinstance(pending, Queued):
                return ""
            if pending.since_ns < 0:
                self._pending = (Queued(pending.goal_id, pending.request, b), effective)
            elif b - pending.since_ns >= MAP_WAIT_S * NS_PER_S:
                self._pending = None
                detail = f"no map from {self.source.name} within {MAP_WAIT_S:.0f} s"
                self.log.warning("goal %s failed: %s", pending.goal_id, detail)
                self.nav.refuse(pending.goal_id, detail, "timeout")
                return ""
            return pending.goal_id

    def start_due(self, b: int, costmap: Costmap, pose: Pose | None, map_at: int) -> None:
        """Start the pending goal whose tick has come; one queued before the map is
        resolved now against `costmap` and the map's data as of `map_at` (the map as
        fetched for the costmap in use: the same in every run)."""
        with self._ticked:
            pending = None
            if self._pending is not None and self._pending[1] <= b:
                pending, self._pending = self._pending[0], None
        if pending is None:
            return
        if isinstance(pending, Queued):
            try:
                pending = self.resolve(pending.request, costmap, pose, map_at, pending.goal_id)
            except GoalInvalid as exc:
                self.log.info("goal %s refused once the map came: %s", pending.goal_id, exc)
                self.nav.refuse(pending.goal_id, str(exc))
                return
            self.log.info("goal %s resolved: (%.2f, %.2f, %.2f)", pending.goal_id, *pending.pose)
        if self.nav.state == "active" and self.nav.goal is not None:
            self.log.info("goal %s replaced by %s", self.nav.goal.goal_id, pending.goal_id)
        self.nav.start(pending, b)

    def done(self, b: int, costmap: Costmap | None, pose: Pose | None) -> None:
        """Tick b is done with this costmap and pose (wakes `as_of`)."""
        with self._ticked:
            self._history.append((b, costmap, pose))
            self._ticked.notify_all()
