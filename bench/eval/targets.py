"""Which object and which person to ask for, chosen from the semantic map's listings.

A request names **map** ids, so both choices read the map (`dume/map/artifacts`,
`dume/map/people`), never the sim's truth. `demo_pair` is `dume demo`'s default: the
bottle and the person that are farthest apart (the longest walk, the whole job), or the
user's `--object` / `--person` with the other side chosen to be far from it.
`seeded_pair` is `dume eval`'s: a uniformly random mapped artifact and person, from a
`random.Random(seed)` over the entities sorted by id, so the same map and seed give the
same request. Entities the map marks missing are never chosen. Pure: no transport.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from typing import NamedTuple

from common.messages.semantic_map import MapEntity

#: The class `dume demo` asks for by default.
DEMO_CLASS = "bottle"


class TargetError(ValueError):
    """No request can be made: what was asked for and what the map holds."""


class Pair(NamedTuple):
    """A request's two targets (map ids, or a class for the object) and their distance.

    distance_m: horizontal distance between them, m (nan when the object is a class).
    """

    object: str
    person: str
    distance_m: float


def _present(entities: Sequence[MapEntity]) -> list[MapEntity]:
    return sorted((e for e in entities if e.missing_since_ns is None), key=lambda e: e.id)


def _xy_distance(a: MapEntity, b: MapEntity) -> float:
    (ax, ay, _), (bx, by, _) = a.position_in_world, b.position_in_world
    return math.hypot(ax - bx, ay - by)


def _ids(entities: Sequence[MapEntity]) -> str:
    return ", ".join(e.id for e in entities) or "nothing"


def demo_pair(
    artifacts: Sequence[MapEntity],
    people: Sequence[MapEntity],
    object_: str | None = None,
    person: str | None = None,
    default_class: str = DEMO_CLASS,
) -> Pair:
    """The demo's request: the farthest-apart object and person, honouring either choice.

    `object_` is a map id or a class; `person` a map id. The side not given is chosen to
    maximise the distance (for a class, to the class's nearest instance).
    Raises `TargetError` when a named entity or class is not in the map.
    """
    arts, folks = _present(artifacts), _present(people)
    if object_ is None:
        objects = [a for a in arts if a.class_name == default_class]
        if not objects:
            raise TargetError(f"no {default_class} in the map; it holds {_ids(arts)}")
    else:
        objects = [a for a in arts if object_ in (a.id, a.class_name)]
        if not objects:
            raise TargetError(f"{object_!r} is no mapped artifact id or class: {_ids(arts)}")
    if person is None:
        persons = folks
        if not persons:
            raise TargetError("no person in the map")
    else:
        persons = [p for p in folks if p.id == person]
        if not persons:
            raise TargetError(f"{person!r} is no mapped person: {_ids(folks)}")
    if object_ is not None and all(o.id != object_ for o in objects):
        # A class: the mission takes its nearest instance, so keep the person far from all.
        far = max(persons, key=lambda p: min(_xy_distance(o, p) for o in objects))
        return Pair(object_, far.id, math.nan)
    best = max(
        ((o, p) for o in objects for p in persons),
        key=lambda op: (_xy_distance(*op), op[0].id, op[1].id),
    )
    return Pair(best[0].id, best[1].id, _xy_distance(*best))


def seeded_pair(artifacts: Sequence[MapEntity], people: Sequence[MapEntity], seed: int) -> Pair:
    """A random mapped artifact and person: the same listings and seed give the same pair."""
    arts, folks = _present(artifacts), _present(people)
    if not arts or not folks:
        raise TargetError(f"the map holds artifacts {_ids(arts)} and people {_ids(folks)}")
    rng = random.Random(seed)
    o = rng.choice(arts)
    p = rng.choice(folks)
    return Pair(o.id, p.id, _xy_distance(o, p))
