"""The map node's side of `dume/<r>/map/patrol`: starting and stopping the mapping patrol,
and stepping it in the map's tick (the walking itself is `patrol_driver`'s).

- `support_targets()`: with `floor_plan = "world"`, the world description's tables and
  benches as points (m, world) the patrol must see, fetched once through `world(wait_s)`
  (None without them). It may wait up to 5 wall s: the node calls it on the queryable's
  thread *before* taking the map's lock.
- `request(req, targets, smap)`: `start` plans a coverage route over the map's occupancy
  grid from the odometry's pose and starts the patrol (refused `busy` while one runs,
  `unavailable` without odometry or free space); `stop` stops it; either way the
  `PatrolStatus`. Called with the map's lock held.
- `step(b)`: at the tick b (sim ns), with a patrol running, waits (1 wall s at most) for
  the odometry of b and steps the patrol on it; the route to log, or None when no patrol
  runs. Called by the tick thread with the map's lock held.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

from common.bus import RequestError, WaitTimeout
from common.config import SemanticMapSettings
from common.geometry import FloatArray, yaw_of_quat_xyzw
from common.messages.base import NS_PER_S
from common.messages.semantic_map import PatrolRequest, PatrolStatus
from common.messages.sim import Odom
from common.messages.world import WorldDescription
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.patrol import Route, coverage_route, support_targets
from services.semantic_map.patrol_driver import PatrolDriver

log = logging.getLogger("dume.semantic_map")


class OdomSource(Protocol):
    """The robot's recent odometry (`common.bus.Latest`)."""

    def get(self) -> Odom | None: ...
    def at(self, stamp_ns: int) -> Odom | None: ...
    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> Odom: ...


class PatrolControl:
    """One `PatrolDriver` and what starts, stops and steps it; see the module docstring."""

    def __init__(
        self,
        driver: PatrolDriver,
        odom: OdomSource,
        cfg: SemanticMapSettings,
        world: Callable[[float], WorldDescription | None],
    ) -> None:
        self.driver, self.odom, self.cfg, self.world = driver, odom, cfg, world
        self._supports: FloatArray | None = None

    def support_targets(self) -> FloatArray | None:
        """The floor plan's tables and benches as places the patrol must see (only with
        `floor_plan = "world"`: the world description's surfaces, fetched once)."""
        if self.cfg.floor_plan != "world":
            return None
        if self._supports is None:
            w = self.world(5.0)
            if w is None:
                log.warning("patrol: no world description: no floor plan's supports to look at")
                return None
            self._supports = support_targets(w.surfaces)
        return self._supports

    def request(
        self, req: PatrolRequest, targets: FloatArray | None, smap: SemanticMap
    ) -> PatrolStatus:
        patrol = self.driver
        if req.action == "start":
            if patrol.running:
                raise RequestError("busy", "a patrol is running; stop it first")
            odom = self.odom.get()
            if odom is None:
                raise RequestError("unavailable", "no odometry: is the sim running?")
            occ = smap.occupancy
            x, y, _z = odom.base_position_in_world
            route = coverage_route(
                occ.cells(),
                occ.resolution_m,
                occ.origin_xy,
                (x, y),
                req.spacing_m or self.cfg.patrol_spacing_m,
                self.cfg.patrol_clearance_m,
                targets,
                self.cfg.patrol_see_m,
            )
            if not route.viewpoints:
                raise RequestError("unavailable", "no free space to patrol in the grid")
            patrol.start(route, yaw_of_quat_xyzw(odom.base_orientation_xyzw))
            log.info("patrol: %d viewpoints via %s", len(route.viewpoints), self.cfg.patrol_via)
        elif req.action == "stop":
            patrol.stop()
        return self.status(smap)

    def status(self, smap: SemanticMap) -> PatrolStatus:
        at, n, travelled, _skipped = self.driver.progress()
        return PatrolStatus(
            stamp_ns=smap.stamp_ns,
            state=self.driver.state,
            waypoint=at,
            waypoints=n,
            travelled_m=travelled,
            artifacts=len(smap.artifacts.confirmed),
            people=len(smap.people.confirmed),
            reason=self.driver.reason,
        )

    def step(self, b: int) -> Route | None:
        if not self.driver.running:
            return None
        try:
            self.odom.wait_stamp(b, 1.0)
        except WaitTimeout:
            log.warning("patrol: no odom at %.1f s", b / NS_PER_S)
        self.driver.step(b, self.odom.at(b))
        return self.driver.route
