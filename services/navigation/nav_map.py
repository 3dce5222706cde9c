"""The map navigation plans on: the grid in use, its layers, and the costmap built from them.

Times are ns of sim time; positions m in the world frame. `adopt` takes a grid and the
map's people as of a sim time (a new grid shape starts an empty short-lived layer); the
short-lived depth layer (`layer`, marked and cleared by `depth.DepthFeed`), the lidar's
layer of bodies larger than a person (`scan_layer`: a trolley the map lacks, marked at
each scan, cleared where its beams pass through, else kept `SCAN_TTL_S`) and the people
layer (`people`: the map's people with those perception sees over them, `SeenPeople`,
and the lidar's tracks over those, `scan_people`; in the costmap when
`people_in_costmap`, always in `Costmap.people` for the speed rules) are combined by
`build` (`costmap.build_costmap`); the map's walkers are carried along their velocity
from when it last saw them to the tick (`ahead`); a person the map alone has (the
camera has not seen them for `CAMERA_FRESH_S`) whose place the lidar sees free
(`ScanView.clear_at`), or saw
free since the map last saw them there (`cleared`: out of the lidar's field now, in the
blind wedge beside the trunk), or who is inside the robot's footprint, is left out of
the layer and said once. A person the layer had within `NEAR_HOLD_M` of the footprint
does not vanish at once: lost by every sensor (no person of the layer within the lidar's
`same_m` of them now), they are held where the layer last had them for `NEAR_HOLD_S`
(said once): nobody walks off from beside a robot in a blink, where a track can drop out
(hall seed 3's shift: the lidar's track of a worker standing 0.6 m off ended, the map's
place of them lay 0.2 m off their legs and the lidar saw it free, and for 0.8 s the
layer had nobody; the robot walked on at 0.3 m/s and came to 0.45 m of them, inside
their separation, before the lidar found them again). The lidar's
tracks move a little at every scan: the costmap is rebuilt when a person came or went
or moved `REBUILD_MOVE_M` since the last build, and otherwise only its people (what the
speed rules read) are the newest.
`costmap` is None until a grid is in; `map_at` is the sim time the map in use is as of
(goals queued before it resolve against it).

Threads: the loop's only; the goal queryable's thread reads `costmap` (a new object on
every rebuild, never changed in place) without a lock.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from common.geometry import FloatArray
from common.messages.base import NS_PER_S
from common.messages.perception import Detections
from services.navigation.costmap import Costmap, CostParams, ObstacleLayer, Person, build_costmap
from services.navigation.grid import Footprint, Grid, Pose, distance_to_footprint
from services.navigation.scan_people import ScanPeople, ScanView, VelocityMemory, merge_scan
from services.navigation.seen_people import SeenPeople

#: m: a person this far from where the costmap last had them (or one come or gone) has
#: the costmap rebuilt; the speed rules always read the newest positions.
REBUILD_MOVE_M = 0.1
#: s: a person the camera saw this recently is there, whatever the map's tracker says.
CAMERA_FRESH_S = 2.0
#: s: the lidar's obstacles larger than a person are kept this long unseen (its beams
#: passing through where one stood clear it sooner): a trolley behind the robot stays on
#: the plan's map while the robot goes round by another aisle (the depth layer's 3 s
#: would let the plan lead back to it every few seconds).
SCAN_TTL_S = 120.0
#: m: a map person still this near where the lidar saw their place free, and not seen
#: by the map since, is not there (the robot turned that place into the blind wedge
#: beside its trunk, or behind it: hall seed 0's shift held a goal 20 s for a ghost
#: 0.76 m off the flank, and failed it blocked).
CLEARED_SAME_M = 0.3
#: A person the layer had within `NEAR_HOLD_M` (m) of the footprint, lost by every sensor,
#: is held where it last had them this long (s).
NEAR_HOLD_M = 1.0
NEAR_HOLD_S = 1.0
#: Why a map person is left out for the lidar: it sees their place free now, or it saw
#: it free since the map last saw them.
LIDAR_FREE = "the lidar sees free floor there"
LIDAR_FREED = "the lidar saw free floor there after the map last saw them"


#: s: a person the map has walking is carried along their velocity from when it last saw
#: them to the tick, for at most this long (`ahead`).
AHEAD_MAX_S = 1.0


def ahead(q: Person, t_ns: int) -> Person:
    """A map person walking (a velocity, last seen at `seen_ns`) where they are by `t_ns`
    at that velocity, for at most `AHEAD_MAX_S`: the map's place of a walker is that of
    its newest fused frame, late by the camera's and the map's latency (the changing
    hall's shift: 0.7 m behind a walker coming head-on at 1 m/s, who was then taken for
    0.8 m further off than they were, and the robot kept 0.35 m/s towards them). Anyone
    else as they are."""
    v = q.velocity
    if q.seen_ns is None or v is None or not any(v):
        return q
    dt = min(max(t_ns - q.seen_ns, 0) / NS_PER_S, AHEAD_MAX_S)
    return replace(q, x=q.x + v[0] * dt, y=q.y + v[1] * dt)


class NavMap:
    """The map in use and its layers; see the module docstring."""

    def __init__(
        self,
        fp: Footprint,
        cost_params: CostParams,
        ttl_ns: int,
        people_in_costmap: bool,
        source_name: str,
        log: logging.Logger,
    ) -> None:
        self.fp, self.cost_params, self.ttl_ns = fp, cost_params, ttl_ns
        self.people_in_costmap, self.source_name, self.log = people_in_costmap, source_name, log
        self.grid: Grid | None = None
        self.layer = ObstacleLayer((1, 1), self.ttl_ns)
        #: The lidar's obstacles larger than a person (`_mark_obstacles`): kept until its
        #: beams pass through them, or `SCAN_TTL_S` unseen.
        self.scan_layer = ObstacleLayer((1, 1), round(SCAN_TTL_S * NS_PER_S))
        self.people: list[Person] = []
        self.map_people: list[Person] = []
        self.seen = SeenPeople()
        self.scan = ScanPeople(fp)
        #: The map's people with the camera's over them (the lidar's go over these).
        self.known: list[Person] = []
        self.scanned: list[Person] = []
        #: The lidar's last velocity of each person, for a new track of them (`merge_scan`).
        self.velocities = VelocityMemory()
        #: The people the costmap was last built with.
        self.built: list[Person] = []
        #: The tick being handled (what "recently seen" counts from).
        self.now = 0
        #: The newest scans' rays (front, rear) and pose (what says where nobody stands),
        #: and the people left out for it (id → why, said once).
        self.views: tuple[ScanView, ...] = ()
        self.pose: Pose | None = None
        self.left_out: dict[str, str] = {}
        #: Where and when (ns, x, y) the lidar last saw each map person's place free.
        self.cleared: dict[str, tuple[int, float, float]] = {}
        #: The people last in the layer within `NEAR_HOLD_M` of the footprint: id → (when,
        #: as what), and those held since every sensor lost them (said once).
        self.near: dict[str, tuple[int, Person]] = {}
        self.held: set[str] = set()
        self.costmap: Costmap | None = None
        #: The sim time the map in use is as of (goals queued before it resolve against it).
        self.map_at = 0

    def adopt(self, grid: Grid, people: list[Person], as_of: int, t_ns: int) -> None:
        """Take a map as of `as_of` (ns) at tick t."""
        if self.grid is None or self.grid.shape != grid.shape:
            self.log.info(
                "map from %s: %s cells of %.2f m", self.source_name, grid.shape, grid.resolution
            )
            self.layer = ObstacleLayer(grid.shape, self.ttl_ns)
            self.scan_layer = ObstacleLayer(grid.shape, self.scan_layer.ttl_ns)
        self.grid, self.map_people, self.map_at = grid, people, as_of
        self.now = t_ns
        self.known = self.seen.merge(people, t_ns)
        self._layer()
        self.costmap = self.build(t_ns)

    def _layer(self) -> bool:
        """The people layer from the known people and the lidar's tracks; whether it
        changed enough for a rebuild (`REBUILD_MOVE_M`). Without one, the costmap's
        people are the new ones all the same."""
        known = [ahead(q, self.now) for q in self.known]
        people = merge_scan(known, self.scanned, self.scan.p.same_m, self.velocities, self.now)
        fresh = self.seen.seen_since(self.now - round(CAMERA_FRESH_S * 1e9))
        self.people = self._hold_near([
            q for q in people
            if q.id.startswith("scan_") or q.id in fresh or not self._absent(q)
        ])  # fmt: skip
        before = {q.id: q for q in self.built}
        material = len(before) != len(self.people) or any(
            (b := before.get(q.id)) is None or math.hypot(q.x - b.x, q.y - b.y) >= REBUILD_MOVE_M
            for q in self.people
        )
        if not material and self.costmap is not None:
            self.costmap = replace(self.costmap, people=tuple(self.people))
        return material

    def _hold_near(self, people: list[Person]) -> list[Person]:
        """`people` with those the layer had near the footprint lately and every sensor
        lost since (module docstring), where it last had them; notes who is near now."""
        hold_ns = round(NEAR_HOLD_S * NS_PER_S)
        same_m = self.scan.p.same_m
        here = {q.id for q in people}
        lost = [
            q for pid, (t, q) in self.near.items()
            if pid not in here and self.now - t <= hold_ns
            and all(math.hypot(p.x - q.x, p.y - q.y) > same_m for p in people)
        ]  # fmt: skip
        for q, dq in zip(people, self._off_footprint(people), strict=True):
            if 0.0 < dq <= NEAR_HOLD_M:
                self.near[q.id] = (self.now, q)
                self.held.discard(q.id)
        self.near = {k: v for k, v in self.near.items() if self.now - v[0] <= hold_ns}
        # not one the body now stands on
        lost = [q for q, dq in zip(lost, self._off_footprint(lost), strict=True) if dq > 0.0]
        for q in lost:
            if q.id not in self.held:
                self.held.add(q.id)
                self.log.info("%s at (%.2f, %.2f), near the robot, lost by every sensor: "
                              "held there %.1f s", q.id, q.x, q.y, NEAR_HOLD_S)  # fmt: skip
        return people + lost

    def _off_footprint(self, people: list[Person]) -> list[float]:
        """Each person's distance (m) from the footprint (inf without a pose)."""
        if self.pose is None or not people:
            return [math.inf] * len(people)
        pts = np.array([[q.x, q.y] for q in people])
        return [float(d) for d in distance_to_footprint(self.pose, self.fp, pts)]

    def _absent(self, q: Person) -> bool:
        """Whether the newest scan, an earlier one since the map last saw `q`, or the
        robot's own body says `q` is not there (said once per person and reason)."""
        why = ""
        at = np.array([[q.x, q.y]])
        cleared = self.cleared.get(q.id)
        if self.pose is not None and distance_to_footprint(self.pose, self.fp, at)[0] <= 0.0:
            why = "inside the robot's footprint"
        elif any(v.clear_at(q.x, q.y) for v in self.views):
            why = LIDAR_FREE
            self.cleared[q.id] = (self.now, q.x, q.y)
        elif (
            cleared is not None and q.seen_ns is not None and q.seen_ns < cleared[0]
            and math.hypot(q.x - cleared[1], q.y - cleared[2]) <= CLEARED_SAME_M
        ):  # fmt: skip
            why = LIDAR_FREED
        said = self.left_out.get(q.id, "")
        # said once per person and reason (the lidar's now and since are one: the trot's
        # sway takes a place in and out of the field from scan to scan)
        if why and said != why and {said, why} != {LIDAR_FREE, LIDAR_FREED}:
            self.log.info("%s at (%.2f, %.2f) left out of the people layer: %s", q.id, q.x, q.y,
                          why)  # fmt: skip
            self.left_out[q.id] = why
        return bool(why)

    def build(self, t_ns: int) -> Costmap:
        assert self.grid is not None  # called once a grid is in
        self.built = list(self.people)
        people = self.people if self.people_in_costmap else []
        seen = self.layer.active(t_ns) | self.scan_layer.active(t_ns)
        cm = build_costmap(self.grid, self.fp, self.cost_params, seen, people)
        # The speed rules always see every person, whether or not the plan avoids them.
        return replace(cm, people=tuple(self.people))

    def see(self, due: list[Detections], b: int) -> bool:
        """The head camera's people detections due by b; whether the people seen changed."""
        before = self.seen.active(b)
        for d in due:
            self.seen.update(d, self.grid)
        return self.seen.active(b) != before

    def see_scan(
        self,
        points: FloatArray,
        pose: Pose,
        b: int,
        views: Sequence[ScanView] = (),
    ) -> bool:
        """The lidars' returns (n, 2, map frame, each scan's in beam order) taken at b with
        the robot at `pose` (`views`: their rays, for where nobody stands: a place any
        one of them sees free); whether the costmap is to be rebuilt."""
        self.views = tuple(views)
        self.pose, self.now = pose, b
        if self.grid is None:
            return False
        self.scan.update(points, self.grid, pose, b, self.views)
        self.scanned = self.scan.people(b)
        marked = self._mark_obstacles(b)
        return self._layer() or marked

    def _mark_obstacles(self, b: int) -> bool:
        """The lidar's returns of bodies larger than a person (a trolley the map lacks) into
        its layer at b, and that layer's cells its beams now pass through cleared (the
        trolley taken away, or a group of people gone); whether the layer's cells changed
        (a mark refreshed where one was is no change: no costmap rebuild at the scan's
        rate while a trolley stands in view)."""
        if self.grid is None:
            return False
        before = self.scan_layer.active(b)
        iy, ix = np.nonzero(before)
        if len(iy):
            through = np.zeros(len(iy), dtype=bool)
            xy = self.grid.centres(np.stack([iy, ix], axis=1))
            for view in self.views:
                through |= view.through(xy)
            self.scan_layer.clear(iy[through], ix[through])
        pts = self.scan.obstacles
        if len(pts):
            iy, ix, inside = self.grid.cells(pts)
            self.scan_layer.mark(iy[inside], ix[inside], b)
        return not np.array_equal(before, self.scan_layer.active(b))

    def take(
        self, fresh: tuple[Grid, list[Person], int] | None, seen_changed: bool, b: int
    ) -> bool:
        """Adopt the map `fresh` (grid, people, as of) at tick b if one came, else put the
        people seen over the map's when they changed; whether the people layer changed
        without a rebuild (the costmap is to be rebuilt)."""
        if fresh is not None:
            self.adopt(*fresh, b)
        elif seen_changed and self.grid is not None:
            self.now = b
            self.known = self.seen.merge(self.map_people, b)
            self._layer()
            return True
        return False

    def rebuild(self, t_ns: int) -> None:
        self.costmap = self.build(t_ns)

    def clear(self, t_ns: int) -> None:
        """The `clear` recovery: forget the short-lived layer and rebuild."""
        self.layer.clear_all()
        self.scan_layer.clear_all()
        self.costmap = self.build(t_ns)
