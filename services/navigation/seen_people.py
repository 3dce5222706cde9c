"""People seen by perception this moment: the fast half of navigation's people layer.

The semantic map's people arrive every `map_refresh_s` (a second or more behind); a
person stepping into the path must act within a camera period. `SeenPeople` keeps the
head camera's `person` detections (their visible points' centroid on the floor: a little
in front of the person's centre, so distances err on the safe side; at least
`min_height_m` of points tall, a person's size), each for `ttl_s` of sim time after it
was last seen, and `merge` puts them over the map's people: a map person with a seen
person's id (perception associated the detection with it), or within `same_m` of a
seen one, is that person, seen now: the seen position wins. A sighting perception gave
no id takes the map person's within `named_m` (hall seed 5: the camera's `seen_5`
replaced person_3, the handover's own person, in the layer, and the handover stood
14 s under the bystanders' stop rule 0.99 m from them, then failed blocked).

A person cannot stand inside a machine: a detection whose floor point lies within
`obstacle_margin_m` of a cell the map's grid knows to be occupied (unknown cells do
not count: a patrol starts with every cell unknown) is a fixed thing the network
took for a person (a machine's face read as a person in every frame stopped the robot
0.3 m short of its goal in two hall worlds), and is left out. A real person is a body
width from the nearest obstacle surface they face the camera across.

Each person seen is a short track (by perception's map id, else the nearest sighting
within `same_m`): their velocity is the least-squares slope of their positions over the
last `velocity_window_s`, once those span `velocity_min_span_s` (None before: the speed
and separation monitor then assumes a walking pace, `separation`). A sighting too brief
for a velocity that is not seen again for `unknown_still_s` is taken as standing (velocity
zero) for the rest of its `ttl_s`: one that walked on at the robot would be seen again by
then, by the head camera or the lidars all round; as a walker at 1.6 m/s (S_p at rest
1.52 m) one glimpse of a worker standing beside the trunk held the robot 23 s in hall seed
1's shift, the lidars' own track of them lost in the blind wedge beside it. A sighting
walking (`walking_mps`) not seen again for `walker_ttl_s` has walked on and is dropped,
as the lidar's coasting tracks end: kept at its last place for the whole `ttl_s`, a
walker gone by beside the flank, where neither lidar sees, held the robot 20 s under the
stop rule with nobody there (hall seed 5's shift).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from common.grid import occupied_near
from common.messages.base import NS_PER_S
from common.messages.perception import Detections
from services.navigation.costmap import Person
from services.navigation.grid import Grid

#: m/s: a person measured at least this fast walks; slower, they stand (the camera's
#: sightings here, the lidar's tracks in `scan_people`: one threshold for both).
WALKING_MPS = 0.3


@dataclass(frozen=True)
class SeenParams:
    """Which people detections count and for how long (see the module docstring). Not
    settings: tuned with the head camera and the network."""

    #: s: long enough to remember a person beside the robot, out of the head camera's view
    #: while it walks round them (the map may have lost them meanwhile).
    ttl_s: float = 30.0
    same_m: float = 1.0
    #: m: a sighting without a map id this close to a map person takes their id (`merge`).
    named_m: float = 0.6
    min_score: float = 0.5
    #: m, the least height of a detection's points for a person (a head camera sees a
    #: person close by from the floor up; a short blob is something else, e.g. the arm).
    min_height_m: float = 0.6
    #: m: a "person" whose floor point is this close to an occupied cell is not one.
    obstacle_margin_m: float = 0.1
    #: s: the positions a velocity is fitted to, and the least time they must span.
    velocity_window_s: float = 0.6
    velocity_min_span_s: float = 0.25
    #: s: a sighting without a velocity not seen again this long is taken as standing.
    unknown_still_s: float = 2.0
    #: A sighting walking (at least `walking_mps`, m/s) not seen again for `walker_ttl_s`
    #: (s: the lidar's tracks coast as long) has walked on: it is dropped.
    walking_mps: float = WALKING_MPS
    walker_ttl_s: float = 3.0


class SeenPeople:
    """The people detected recently (sim time); see the module docstring."""

    def __init__(self, p: SeenParams = SeenParams()) -> None:
        self.p = p
        self._seen: list[tuple[int, Person]] = []
        self._tracks: dict[str, list[tuple[int, float, float]]] = {}
        self._count = 0
        #: The map ids the last `merge` gave sightings without one (`_named`).
        self._names: dict[str, str] = {}

    def update(self, dets: Detections, grid: Grid | None = None) -> None:
        """Replace what the camera showed before with what this frame shows (people
        inside `grid`'s obstacles left out)."""
        fresh = [
            (d.map_id, d.centroid_in_world[0], d.centroid_in_world[1])
            for d in dets.detections
            if d.class_name == "person"
            and d.score >= self.p.min_score
            and d.extent[2] >= self.p.min_height_m
        ]
        if grid is not None and fresh:
            inside = occupied_near(
                grid.known_occupied, grid.resolution, grid.origin,
                [(x, y) for _, x, y in fresh], self.p.obstacle_margin_m,
            )  # fmt: skip
            fresh = [f for f, bad in zip(fresh, inside, strict=True) if not bad]
        people: list[Person] = []
        for map_id, x, y in fresh:
            people.append(self._track(map_id, x, y, dets.stamp_ns, {q.id for q in people}))
        # An earlier sighting nobody in this frame matches stays until it expires (the
        # person may be out of view, not gone).
        kept = [
            (t, q) for t, q in self._seen
            if all(math.hypot(q.x - f.x, q.y - f.y) > self.p.same_m for f in people)
            and all(q.id != f.id for f in people)
        ]  # fmt: skip
        self._seen = kept + [(dets.stamp_ns, f) for f in people]
        live = {q.id for _, q in self._seen}
        self._tracks = {k: v for k, v in self._tracks.items() if k in live}

    def _track(self, map_id: str | None, x: float, y: float, t_ns: int, taken: set[str]) -> Person:
        """This sighting on its track (the map's id, else the nearest earlier sighting
        within `same_m` not `taken` by this frame, else a new one), with its velocity."""
        pid = map_id
        if pid is None:
            near = [
                (d, q.id) for _, q in self._seen
                if q.id not in taken and (d := math.hypot(q.x - x, q.y - y)) <= self.p.same_m
            ]  # fmt: skip
            if near:
                pid = min(near)[1]
            else:
                self._count += 1
                pid = f"seen_{self._count}"
        window = round(self.p.velocity_window_s * NS_PER_S)
        points = [q for q in self._tracks.get(pid, []) if t_ns - q[0] <= window and q[0] < t_ns]
        points.append((t_ns, x, y))
        self._tracks[pid] = points
        return Person(pid, x, y, None, fitted_velocity(points, self.p.velocity_min_span_s))

    def seen_since(self, t_ns: int) -> set[str]:
        """The ids of the people detected at or after `t_ns` (as the last `merge` named
        them)."""
        return {self._names.get(q.id, q.id) for t, q in self._seen if t >= t_ns}

    def active(self, t_ns: int) -> list[Person]:
        """The sightings within their `ttl_s` at `t_ns`, each stamped when it was seen
        (`seen_ns`: a sighting kept for seconds out of view is no person seen now), one
        without a velocity not seen for `unknown_still_s` standing (the module docstring)."""
        ttl = round(self.p.ttl_s * NS_PER_S)
        walker_ttl = round(self.p.walker_ttl_s * NS_PER_S)
        self._seen = [
            (t, q) for t, q in self._seen
            if t_ns - t <= (walker_ttl if self._walking(q) else ttl)
        ]  # fmt: skip
        still = round(self.p.unknown_still_s * NS_PER_S)
        return [
            replace(q, seen_ns=t, velocity=(0.0, 0.0))
            if q.velocity is None and t_ns - t > still
            else replace(q, seen_ns=t)
            for t, q in self._seen
        ]

    def _walking(self, q: Person) -> bool:
        v = q.velocity
        return v is not None and math.hypot(*v) >= self.p.walking_mps

    def merge(self, mapped: list[Person], t_ns: int) -> list[Person]:
        seen = self._named(self.active(t_ns), mapped)
        by_id = {m.id: m for m in mapped}
        # A person seen too briefly for a velocity of their own keeps the map's (its
        # tracker's, over their earlier sightings).
        out = [
            replace(s, velocity=by_id[s.id].velocity)
            if s.velocity is None and s.id in by_id else s
            for s in seen
        ]  # fmt: skip
        ids = {s.id for s in seen}
        for m in mapped:
            if m.id in ids:
                continue  # seen now, wherever the map last had them
            if all(math.hypot(m.x - s.x, m.y - s.y) > self.p.same_m for s in seen):
                out.append(m)
        return out

    def _named(self, seen: list[Person], mapped: list[Person]) -> list[Person]:
        """A sighting perception gave no map id (`seen_<k>`) within `named_m` of a map
        person no sighting names is that person, under their id (nearest pairs first,
        each once): the id is who they are to the rules (a handover's person is kept
        apart from the bystanders by it); the map's position is dropped either way."""
        named = {q.id for q in seen}
        pairs = sorted(
            (d, i, m.id)
            for i, q in enumerate(seen) if q.id.startswith("seen_")
            for m in mapped if m.id not in named
            if (d := math.hypot(m.x - q.x, m.y - q.y)) <= self.p.named_m
        )  # fmt: skip
        out, taken = list(seen), set()
        self._names = {}
        for _d, i, mid in pairs:
            if out[i].id.startswith("seen_") and mid not in taken:
                self._names[out[i].id] = mid
                out[i] = replace(out[i], id=mid)
                taken.add(mid)
        return out


def fitted_velocity(
    points: list[tuple[int, float, float]], min_span_s: float
) -> tuple[float, float] | None:
    """The least-squares floor velocity (m/s) of (t ns, x, y) points; None when they span
    less than `min_span_s` or are fewer than 3."""
    if len(points) < 3 or (points[-1][0] - points[0][0]) / NS_PER_S < min_span_s:
        return None
    t = np.array([q[0] for q in points], dtype=float) / NS_PER_S
    xy = np.array([(q[1], q[2]) for q in points])
    dt = t - t.mean()
    slope = dt @ (xy - xy.mean(axis=0)) / float(dt @ dt)
    return float(slope[0]), float(slope[1])
