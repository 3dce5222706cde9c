"""Which mapped things a request names: a map id (`bottle_1`) or a class (`bottle`).

A map id names one entity (or none: unknown). A class names every mapped, not missing
artifact of that class, nearest to the robot first: the first is fetched, the rest are
the candidates a recovery tries when the first is not where the map says. A person may
be named by id, or as `person` (the nearest mapped person). Which wrist detection is the
target is `common.sightings.pick_detection`'s rule. Pure apart from the port's map
queries, which raise `Unavailable` when the map does not answer.
"""

from __future__ import annotations

import math
import re

from common.messages.semantic_map import MapEntity
from common.robot import posture_tcp
from services.mission.ports import RobotPort

_MAP_ID = re.compile(r"^[a-z][a-z0-9]*_[1-9][0-9]*$")


def is_map_id(name: str) -> bool:
    """`bottle_1` is a map id; `bottle` is a class."""
    return bool(_MAP_ID.match(name))


def class_of(map_id: str) -> str:
    """The class part of a map id (`bottle_1` → `bottle`)."""
    return map_id.rsplit("_", 1)[0]


def nearest_first(entities: list[MapEntity], xy: tuple[float, float] | None) -> list[MapEntity]:
    """Sorted by horizontal distance to `xy` (by id when the robot's place is unknown)."""
    if xy is None:
        return sorted(entities, key=lambda e: e.id)
    x, y = xy
    return sorted(
        entities,
        key=lambda e: (math.hypot(e.position_in_world[0] - x, e.position_in_world[1] - y), e.id),
    )


def object_candidates(port: RobotPort, name: str) -> list[MapEntity]:
    """The artifacts a request's `object` names, nearest first (empty: none known)."""
    if is_map_id(name):
        entity = port.artifact(name)
        return [] if entity is None else [entity]
    present = [e for e in port.artifacts_of_class(name) if e.missing_since_ns is None]
    return nearest_first(present, port.robot_xy())


def dropped_at(xy: tuple[float, float] | None, yaw: float | None) -> tuple[float, float] | None:
    """About where an object that fell from the gripper while carried lies (world x, y):
    below the carry posture's TCP (`stow`), from the robot's place and heading at the
    loss; None when those are unknown."""
    if xy is None or yaw is None:
        return None
    tx, ty, _ = posture_tcp("stow")
    c, s = math.cos(yaw), math.sin(yaw)
    return (xy[0] + c * tx - s * ty, xy[1] + s * tx + c * ty)


def person_named(port: RobotPort, name: str) -> MapEntity | None:
    """The person a request's `person` names (by id, or `person`: the nearest)."""
    if is_map_id(name):
        return port.person(name)
    if name != "person":
        return None
    people = nearest_first(port.people(), port.robot_xy())
    return people[0] if people else None
