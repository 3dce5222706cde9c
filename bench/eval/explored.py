"""How good a map the robot made of a world it explored, judged from the truth
(evaluation only): what `dume eval --map explored` and `dume trial explore` report.

`score_entities(world, artifacts, people)`:
- artifacts: each of the world's artifacts is *found* when a mapped artifact lies within
  `FOUND_M` (10 cm, horizontally) of it, and *right* when that one has its class; each
  mapped artifact is matched to at most one (the nearest pairs first). A mapped artifact
  matched to none within `FALSE_M` is a *false entry*; one within `FALSE_M` but not
  `FOUND_M` (a real object placed too far off) is *misplaced*.
- people: each of the world's people is found when a mapped person lies within
  `PERSON_M` of where they stand (people are mapped at their feet and may have moved
  a step); mapped people matched to none are false.
Lists name the truth ids, so a report says which ones were missed. A map made from
nothing is in its own frame (`map_agreement.align_to_truth`): `moved` puts its entities
where its alignment to the truth moves them, for the figures "as aligned".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import msgspec
import numpy as np

from bench.map_agreement import Alignment
from common.messages.semantic_map import MapEntity
from common.messages.world import WorldDescription

FOUND_M = 0.10
FALSE_M = 0.30
PERSON_M = 0.5


def _pairs(
    truth: Sequence[tuple[str, float, float]], mapped: Sequence[MapEntity], within_m: float
) -> list[tuple[str, MapEntity, float]]:
    """Nearest-first one-to-one pairs (truth id, mapped entity, distance) within `within_m`."""
    cand = sorted(
        (math.hypot(m.position_in_world[0] - x, m.position_in_world[1] - y), tid, i)
        for tid, x, y in truth
        for i, m in enumerate(mapped)
    )
    used_t: set[str] = set()
    used_m: set[int] = set()
    out = []
    for d, tid, i in cand:
        if d > within_m:
            break
        if tid in used_t or i in used_m:
            continue
        used_t.add(tid)
        used_m.add(i)
        out.append((tid, mapped[i], d))
    return out


def moved(entities: Sequence[MapEntity], aligned: Alignment) -> list[MapEntity]:
    """The entities as the map's alignment to the truth moves them (`map_agreement`)."""
    out = []
    for e in entities:
        x, y, z = e.position_in_world
        ((nx, ny),) = aligned.apply(np.array([[x, y]]))
        out.append(msgspec.structs.replace(e, position_in_world=(float(nx), float(ny), z)))
    return out


def score_entities(
    world: WorldDescription, artifacts: Sequence[MapEntity], people: Sequence[MapEntity]
) -> dict[str, Any]:
    truth_arts = [(a.id, a.position[0], a.position[1]) for a in world.artifacts]
    classes = {a.id: a.object_class for a in world.artifacts}
    near = _pairs(truth_arts, artifacts, FALSE_M)
    found = [(t, m, d) for t, m, d in near if d <= FOUND_M]
    right = [t for t, m, _ in found if m.class_name == classes[t]]
    matched = {id(m) for _, m, _ in near}
    false = [m.id for m in artifacts if id(m) not in matched]
    truth_people = [(p.id, p.position[0], p.position[1]) for p in world.people]
    seen = _pairs(truth_people, people, PERSON_M)
    seen_ids = {id(m) for _, m, _ in seen}
    return {
        "artifacts": len(truth_arts),
        "found_within_10cm": len(found),
        "found_right_class": len(right),
        "missed": sorted({t for t, _, _ in truth_arts} - {t for t, _, _ in found}),
        "wrong_class": sorted(f"{t} as {m.class_name}" for t, m, _ in found if t not in right),
        "misplaced": sorted(f"{t} {d * 100:.0f} cm" for t, _, d in near if d > FOUND_M),
        "false_entries": sorted(false),
        "placement_cm_max": round(max((d for _, _, d in found), default=0.0) * 100, 1),
        "people": len(truth_people),
        "people_found": len(seen),
        "people_missed": sorted({t for t, _, _ in truth_people} - {t for t, _, _ in seen}),
        "false_people": sorted(m.id for m in people if id(m) not in seen_ids),
    }
