"""`LookElsewhere`: the object was not where the map said; look where it may be now.

The fetch's first leaf. It does nothing (SUCCESS at once) unless the tree's recovery
asked for a search (`SEARCH` on the blackboard: every candidate was tried and not found
at its place). Then it plans the places (`services.mission.search.places_to_look`: its
last place, where the map saw its class lately, the supports nearest first), the route
facing them from within `patrol_recheck_see_m`, out of people's way where it can
(`search.busy_places`), rank by rank (`ranked_route`:
`coverage.facing_route`, as the second look plans, on each kind of place in turn), and
walks it as the patrol walks a route (`patrol.PatrolRunner`: the arm up
in `look`, a hold at each viewpoint; the map fuses the wrist camera meanwhile, the node
saying `arm_look`). After every tick it asks the map whether the object is there now
(`search.found`; for a request by id, an entry the map made since the request began,
`KNOWN`, or the entry of an object this mission handed over, seen since away from
everyone: another object where the robot took that one): found, the walk stops and the
found artifact becomes the only candidate (SUCCESS: the fetch goes on to it); the route
walked without it, `object_not_found` naming the places looked at. Halted, it stops the
walk.

What the search found may not be there when the fetch comes to it: a network's phantom
on a table's corner made from the head camera's views (hall seed 1's shift: the search
stopped at a "bottle_7" no wrist view ever showed, and the request failed with three
supports not looked at). So a find keeps the rest of the route (`SEARCH_LEFT`: the
viewpoints from the one being walked to on, at most `MAX_RESUMES` times a request), and
when the found one is missed at its place the tree asks for the search again: it goes on
from there, the missed one among the tried, and never found again as a handed-over
object's entry put down (hall seed 3's shift: a can stood where a bottle handed over had
stood, the head camera took it for that bottle from afar and the wrist camera for a can
from near; the search found that entry three times and the request failed after 165 s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from py_trees.common import Status

from common.messages import as_numpy
from common.messages.semantic_map import MapEntity
from common.messages.world import SupportSurface
from services.mission.behaviours.base import (
    CANDIDATE,
    CANDIDATES,
    KNOWN,
    REQUEST,
    SEARCH,
    SEARCH_LEFT,
    Context,
    MissionBehaviour,
)
from services.mission.coverage import Route, facing_route
from services.mission.patrol import VIEW_HALF_ANGLE, PatrolRunner
from services.mission.ports import PortError
from services.mission.search import Place, busy_places, found, places_to_look, re_seen
from services.mission.targets import class_of, handed_put_back, is_map_id

#: How many times a request's search goes on after what it found was not there.
MAX_RESUMES = 2


def ranked_route(
    cells: np.ndarray,
    resolution_m: float,
    origin_xy: tuple[float, float],
    start_xy: tuple[float, float],
    places: list[Place],
    clearance_m: float,
    near_m: float,
    see_m: float,
    busy: list[tuple[float, float]] | None = None,
) -> Route:
    """Viewpoints facing the places rank by rank (`Place.rank`: its last place, then
    where its class was seen lately, then the supports), each rank's (`facing_route`:
    fewest viewpoints, out of the way of the `busy` places where they can be, nearest
    first) from where the rank before ended. One route over
    them all walked nearest first: seed 0's shift looked at three supports before
    table_2, where the map had seen a bottle 104 s before and the bottle stood."""
    avoid = np.array(busy, float).reshape(-1, 2) if busy else None
    viewpoints: list[np.ndarray] = []
    paths: list[np.ndarray] = []
    facings: list[float] = []
    unseen, here = 0, start_xy
    for rank in sorted({p.rank for p in places}):
        targets = np.array([q for p in places if p.rank == rank for q in p.points])
        r = facing_route(cells, resolution_m, origin_xy, here, targets.reshape(-1, 2),
                         clearance_m, near_m, see_m, VIEW_HALF_ANGLE, avoid)  # fmt: skip
        viewpoints += r.viewpoints
        paths += r.paths
        facings += r.facings or []
        unseen += r.unseen
        if r.viewpoints:
            here = (float(r.viewpoints[-1][0]), float(r.viewpoints[-1][1]))
    return Route(viewpoints, paths, facings, unseen)


@dataclass(frozen=True)
class SearchLeft:
    """What a search that stopped at a find had left: the route from the viewpoint it was
    at, the places it planned (for the failure's text), what it looked for (the class,
    the ids known when it began: None for a request by class), the ids tried, the times
    it went on, what it found, and what it found before that the fetch missed."""

    route: Route
    places: tuple[Place, ...]
    class_name: str
    known: frozenset[str] | None
    tried: tuple[str, ...]
    resumes: int = 0
    found: str = ""
    missed: tuple[str, ...] = ()


class LookElsewhere(MissionBehaviour):
    WRITES = (CANDIDATES, CANDIDATE, SEARCH, SEARCH_LEFT)

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("look_elsewhere", ctx, stage)
        self.runner: PatrolRunner | None = None
        self.places: list[Place] = []
        self.supports: list[SupportSurface] = []
        self.known: set[str] | None = None
        self.tried: list[str] = []
        #: What this request's search found and the fetch then missed at its place.
        self.missed: set[str] = set()
        self.class_name = ""
        self.hit = ""
        self.hit_at = 0  # the viewpoint (from 1) the route was at when the hit came
        self.resumes = 0  # the times this request's search went on after a miss
        #: New entries said to be a known one seen again (`_say_re_seen`).
        self.said_re_seen: set[str] = set()
        #: Handed-over entries said to be seen again away from everyone (`_put_down`).
        self.said_put_down: set[str] = set()

    @property
    def arm_look(self) -> bool:
        """The search holds the arm up to look (the map fuses the wrist camera)."""
        return self.runner is not None and self.runner.arm_look

    def update(self) -> Status:
        if not self.get(SEARCH):
            return Status.SUCCESS
        if self.runner is None:
            return self._start()
        runner = self.runner
        runner.step()
        if runner.running and not self.hit:
            try:
                listing = self.port.artifacts_of_class(self.class_name)
                hit = found(listing, self.class_name, self.started_ns, self.tried, self.known,
                            self.port.now_ns, (self.places, self.supports),
                            self._put_down(listing))  # fmt: skip
                self._say_re_seen(listing)
            except PortError:
                hit = None
            if hit is not None:
                self.hit, self.hit_at = hit.id, runner.status(self.port.now_ns).waypoint
                x, y = hit.position_in_world[:2]
                self.ctx.decide(f"search: {hit.id} seen at ({x:.2f}, {y:.2f}), made of "
                                f"{hit.observations} detections")  # fmt: skip
                runner.stop(f"found {hit.id}")
        if runner.running:
            st = runner.status(self.port.now_ns)
            self.fraction = min(0.99, st.waypoint / max(1, st.waypoints))
            return Status.RUNNING
        return self._end()

    def _put_down(self, listing: list[MapEntity]) -> list[str]:
        """The entries of objects this mission handed over that the map saw since the
        search began, away from everyone (`targets.put_back`): another object stands
        where the robot took one (`search.found`). Asks the map for its people only when
        there is such an entry."""
        seen = [a for a in listing if a.last_seen_ns >= self.started_ns and a.id not in self.missed]
        out = [a.id for a in handed_put_back(self.port, seen, self.ctx.handed)]
        for a in out:
            if a not in self.said_put_down:
                self.said_put_down.add(a)
                whom = self.ctx.handed[a][0]
                self.ctx.decide(f"search: {a}, handed over to {whom}, seen again away "
                                "from everyone: another object where it stood")  # fmt: skip
        return out

    def _say_re_seen(self, listing: list[MapEntity]) -> None:
        """Say, once per entry, a new one the search does not take for the object asked
        for by id: a known one of its class seen again off its place (`search.re_seen`)."""
        if self.known is None:
            return
        known = self.known - set(self.tried)
        for a in listing:
            if a.id in self.known or a.id in self.said_re_seen or a.last_seen_ns < self.started_ns:
                continue
            old = re_seen(a, listing, known, self.started_ns)
            if old is not None:
                self.said_re_seen.add(a.id)
                off = math.dist(a.position_in_world[:2], old.position_in_world[:2])
                why = (
                    "not seen itself since the search began"
                    if old.last_seen_ns < self.started_ns
                    else f"{a.id} seen only from afar"
                )
                self.ctx.decide(f"search: {a.id} is {old.id} seen again {off:.2f} m from its "
                                f"place ({why}), not the one asked for")  # fmt: skip

    def _start(self) -> Status:
        request = self.get(REQUEST)
        self.tried = list(self.get(CANDIDATES) or []) + list(self.ctx.handed)
        left = self.get(SEARCH_LEFT)
        if isinstance(left, SearchLeft):
            return self._resume(left)
        self.resumes, self.missed = 0, set()
        name = request.object
        self.class_name = class_of(name) if is_map_id(name) else name
        s = self.settings
        xy = self.port.robot_xy()
        try:
            listing = self.port.artifacts_of_class(self.class_name)
            supports = self.port.floor_supports()
            grid = self.port.occupancy()
            last = self.port.artifact(name) if is_map_id(name) else None
        except PortError as exc:
            return self.fail("unavailable", f"the semantic map did not answer: {exc}")
        if xy is None:
            return self.fail("object_not_found", "no search: the robot does not know where it is")
        try:
            busy = busy_places(self.port.people())
        except PortError:
            busy = []  # the viewpoints stand wherever they see best
        # A request by id: the entries the map had when the request began are other
        # objects of the class; one made since may be the object, moved (the head camera
        # may see it at its new place on the way, before the search begins).
        known = self.get(KNOWN)
        at_start = set(known) if known is not None else {a.id for a in listing}
        self.known = at_start if is_map_id(name) else None
        self.supports = list(supports)
        last_xy = (last.position_in_world[0], last.position_in_world[1]) if last else None
        self.places = places_to_look(
            last_xy, self.class_name, listing, supports, xy, self.port.now_ns,
            s.search_recent_s, s.search_places, skip=self.tried,
        )  # fmt: skip
        route = ranked_route(
            np.asarray(as_numpy(grid.cells), np.uint8), grid.resolution_m, grid.origin_xy, xy,
            self.places, s.patrol_clearance_m, s.patrol_near_m, s.patrol_recheck_see_m, busy,
        )  # fmt: skip
        said = "; ".join(p.why for p in self.places)
        if not route.viewpoints:
            return self.fail("object_not_found", f"{name} not at its place, and no viewpoint "
                             f"sees where else to look ({said})")  # fmt: skip
        self.ctx.decide(f"search for {name}: {len(route.viewpoints)} viewpoint(s): {said}")
        self.runner = PatrolRunner(self.port, self.settings, self.ctx.decide)
        self.runner.start(route)
        return Status.RUNNING

    def _resume(self, left: SearchLeft) -> Status:
        """Go on with the route a find stopped (the module docstring)."""
        self.set(SEARCH_LEFT, None)
        self.places, self.resumes = list(left.places), left.resumes + 1
        self.missed = {*left.missed, left.found} - {""}
        self.tried = [*left.tried, *(t for t in self.tried if t not in left.tried)]
        self.class_name = left.class_name
        self.known = None if left.known is None else set(left.known)
        name = self.get(REQUEST).object
        try:
            self.supports = list(self.port.floor_supports())
        except PortError as exc:
            return self.fail("unavailable", f"the semantic map did not answer: {exc}")
        missed = (
            ", ".join(t for t in self.tried if t not in left.tried) or left.found or "what it found"
        )
        self.ctx.decide(f"search for {name} goes on: {missed} was not there; "
                        f"{len(left.route.viewpoints)} viewpoint(s) left")  # fmt: skip
        self.runner = PatrolRunner(self.port, self.settings, self.ctx.decide)
        self.runner.start(left.route)
        return Status.RUNNING

    def _left(self) -> SearchLeft | None:
        """The route from the viewpoint the find came at (None: nothing left, or the
        request went on too often)."""
        route = None if self.runner is None else self.runner.route
        if route is None or self.resumes >= MAX_RESUMES:
            return None
        k = max(0, self.hit_at - 1)
        if k >= len(route.viewpoints):
            return None
        facings = None if route.facings is None else route.facings[k:]
        rest = Route(route.viewpoints[k:], route.paths[k:], facings, route.unseen)
        known = None if self.known is None else frozenset(self.known)
        return SearchLeft(rest, tuple(self.places), self.class_name, known, tuple(self.tried),
                          self.resumes, self.hit, tuple(sorted(self.missed)))  # fmt: skip

    def _end(self) -> Status:
        request = self.get(REQUEST)
        hit, said = self.hit, "; ".join(p.why for p in self.places)
        self.set(SEARCH, False)
        if hit:
            self.set(SEARCH_LEFT, self._left())
            self.set(CANDIDATES, [hit])
            self.set(CANDIDATE, 0)
            self.ctx.decide(f"search: fetching {hit} for {request.object}")
            return Status.SUCCESS
        return self.fail("object_not_found", f"{request.object} not found; looked at: {said}")

    def terminate(self, new_status: Status) -> None:
        runner = self.runner
        if runner is not None and runner.running:
            runner.stop("the fetch stopped")
            runner.step()
        if new_status != Status.RUNNING:
            self.runner, self.hit, self.hit_at, self.places = None, "", 0, []
            self.said_re_seen, self.said_put_down = set(), set()
