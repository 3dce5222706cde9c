"""Which mapped things a request names: a map id (`bottle_1`) or a class (`bottle`).

A map id names one entity (or none: unknown). A class names every mapped, not missing
artifact of that class, nearest to the robot first: the first is fetched, the rest are
the candidates a recovery tries when the first is not where the map says. Entries the
map made from a few far views (not `firm`) come after every firm one, nearest first too:
the map deletes such ones when a look at their place misses them, and hall seed 1's
shift walked 51 s to a "box_6" of 6 head-camera detections on a pallet's edge, with
a box the map had seen often on a table 5 m further. A person may
be named by id, or as `person` (the nearest mapped person). An object handed over is
no candidate until somebody puts it down again (`put_back`: the map saw it since, away
from everyone). Which wrist detection is the target is `common.sightings.pick_detection`'s
rule. Pure apart from the port's map queries, which raise `Unavailable` when the map
does not answer.
"""

from __future__ import annotations

import math
import re

from common.messages.semantic_map import MapEntity
from common.robot import posture_tcp
from services.mission.ports import RobotPort, Unavailable
from services.mission.search import NEAR_VIEW_M

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


#: m: an object handed over and seen since this far from every mapped person was put
#: down again (a held one is seen within an arm's length of its holder).
PUT_BACK_M = 1.0


def put_back(entity: MapEntity, handed_ns: int, people: list[MapEntity]) -> bool:
    """Whether an artifact handed over at `handed_ns` (sim ns) was put down again: the
    map saw it since, `PUT_BACK_M` or more from every person it has. A person the map
    holds stale, walked off with it, would read as a put-down: the fetch then finds it
    in a hand, or not at all, and says so."""
    if entity.last_seen_ns <= handed_ns:
        return False
    x, y = entity.position_in_world[:2]
    return all(
        math.hypot(p.position_in_world[0] - x, p.position_in_world[1] - y) >= PUT_BACK_M
        for p in people
    )


#: An entry the map made itself from fewer detections than this, never seen from within
#: `search.NEAR_VIEW_M` (the map's `class_near_m`), is not firm (the map's
#: `drop_below_observations`).
FIRM_ENTRY_OBSERVATIONS = 10


def firm(e: MapEntity) -> bool:
    """Whether the map's entry is more than a few far views (seeded and imported ones are)."""
    near = e.nearest_view_m is not None and e.nearest_view_m <= NEAR_VIEW_M
    return e.source != "perception" or e.observations >= FIRM_ENTRY_OBSERVATIONS or near


def handed_put_back(
    port: RobotPort, entries: list[MapEntity], handed: dict[str, tuple[str, int]]
) -> list[MapEntity]:
    """Those of `entries` handed over (`handed`: map id → to whom, when) and put down
    again (`put_back`), the map's people asked once; none when the map does not answer."""
    mine = [e for e in entries if e.id in handed]
    if not mine:
        return []
    try:
        people = port.people()
    except Unavailable:
        return []
    return [e for e in mine if put_back(e, handed[e.id][1], people)]


def other_objects(like: list[MapEntity], asked_id: str) -> list[str]:
    """The ids of `like` (the map's entries of a class) that are other objects than the
    one asked for, for the search (`search.found`'s `known`): not those the map made from
    its own sightings after it last saw `asked_id`, which may be it, moved (hall seed 0's
    shift moved bottle_2 onto table_2 in view of the head camera, 0.9 s before the request
    for it; the map made bottle_4 there, and the search looked at it and passed it over
    as another bottle). `asked_id` not among them: all of them."""
    asked = next((e for e in like if e.id == asked_id), None)

    def made_since(e: MapEntity) -> bool:
        return (
            asked is not None and e.id != asked.id and e.source == "perception"
            and e.first_seen_ns > asked.last_seen_ns
        )  # fmt: skip

    return sorted(e.id for e in like if not made_since(e))


def object_candidates(port: RobotPort, name: str) -> list[MapEntity]:
    """The artifacts a request's `object` names, firm ones first, each nearest first
    (empty: none known)."""
    if is_map_id(name):
        entity = port.artifact(name)
        return [] if entity is None else [entity]
    present = [e for e in port.artifacts_of_class(name) if e.missing_since_ns is None]
    ordered = nearest_first(present, port.robot_xy())
    return [e for e in ordered if firm(e)] + [e for e in ordered if not firm(e)]


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
