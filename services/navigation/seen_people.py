"""People seen by perception this moment: the fast half of navigation's people layer.

The semantic map's people arrive every `map_refresh_s` (a second or more behind); a
person stepping into the path must act within a camera period. `SeenPeople` keeps the
head camera's `person` detections (their visible points' centroid on the floor: a little
in front of the person's centre, so distances err on the safe side; at least
`min_height_m` of points tall, a person's size), each for `ttl_s` of sim time after it
was last seen, and `merge` puts them over the map's people: a map person with a seen
person's id (perception associated the detection with it), or within `same_m` of a
seen one, is that person, seen now: the seen position wins.

A person cannot stand inside a machine: a detection whose floor point lies within
`obstacle_margin_m` of a cell the map's grid knows to be occupied (unknown cells do
not count: a patrol starts with every cell unknown) is a fixed thing the network
took for a person (a machine's face read as a person in every frame stopped the robot
0.3 m short of its goal in two hall worlds), and is left out. A real person is a body
width from the nearest obstacle surface they face the camera across.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from common.grid import occupied_near
from common.messages.base import NS_PER_S
from common.messages.perception import Detections
from services.navigation.costmap import Person
from services.navigation.grid import Grid


@dataclass(frozen=True)
class SeenParams:
    """Which people detections count and for how long (see the module docstring). Not
    settings: tuned with the head camera and the network."""

    #: s: long enough to remember a person beside the robot, out of the head camera's view
    #: while it walks round them (the map may have lost them meanwhile).
    ttl_s: float = 30.0
    same_m: float = 1.0
    min_score: float = 0.5
    #: m, the least height of a detection's points for a person (a head camera sees a
    #: person close by from the floor up; a short blob is something else, e.g. the arm).
    min_height_m: float = 0.6
    #: m: a "person" whose floor point is this close to an occupied cell is not one.
    obstacle_margin_m: float = 0.1


class SeenPeople:
    """The people detected recently (sim time); see the module docstring."""

    def __init__(self, p: SeenParams = SeenParams()) -> None:
        self.p = p
        self._seen: list[tuple[int, Person]] = []

    def update(self, dets: Detections, grid: Grid | None = None) -> None:
        """Replace what the camera showed before with what this frame shows (people
        inside `grid`'s obstacles left out)."""
        fresh = [
            Person(d.map_id or f"seen_{k + 1}", d.centroid_in_world[0], d.centroid_in_world[1])
            for k, d in enumerate(dets.detections)
            if d.class_name == "person"
            and d.score >= self.p.min_score
            and d.extent[2] >= self.p.min_height_m
        ]
        if grid is not None and fresh:
            xy = [(f.x, f.y) for f in fresh]
            inside = occupied_near(
                grid.known_occupied, grid.resolution, grid.origin, xy, self.p.obstacle_margin_m
            )
            fresh = [f for f, bad in zip(fresh, inside, strict=True) if not bad]
        # An earlier sighting nobody in this frame matches stays until it expires (the
        # person may be out of view, not gone).
        kept = [
            (t, q) for t, q in self._seen
            if all(math.hypot(q.x - f.x, q.y - f.y) > self.p.same_m for f in fresh)
        ]  # fmt: skip
        self._seen = kept + [(dets.stamp_ns, f) for f in fresh]

    def active(self, t_ns: int) -> list[Person]:
        ttl = round(self.p.ttl_s * NS_PER_S)
        self._seen = [(t, q) for t, q in self._seen if t_ns - t <= ttl]
        return [q for _, q in self._seen]

    def merge(self, mapped: list[Person], t_ns: int) -> list[Person]:
        seen = self.active(t_ns)
        ids = {s.id for s in seen}
        out = list(seen)
        for m in mapped:
            if m.id in ids:
                continue  # seen now, wherever the map last had them
            if all(math.hypot(m.x - s.x, m.y - s.y) > self.p.same_m for s in seen):
                out.append(m)
        return out
