"""Where to look for a person who is not where the map last saw them: their usual places.

The map counts where it saw each person (`MapEntity.places`, `semantic_map.whereabouts`,
most seen first). A person not at their last place is looked for where they usually are,
as a colleague would: at their bench, along the aisle they walk. `next_place` gives the
place to walk to and look round at next: of the places seen at least `SHARE` as often as
the most seen one (where they usually are, not where they once passed), those farther
than `LOOKED_M` from every place looked round at in this request and from the robot, the
nearest. None when none is left: the walk goes to where the map last had them. A walker
on a loop comes past any place of it once a lap: standing there looking round (the turn
and the ask, `behaviours.motion.LookForPerson`) sees them come.

While it asks, the robot looks at whoever walks by where its head camera does not look
(`glance_at`), as a person waiting for a colleague turns to each footstep: the lidars
track every body near it (`NavStatus.bodies`), the camera (72° wide) says who one is. In
seed 0's shift the robot asked for person_1 for two minutes facing one way, while they
walked back and forth 0.9-3.9 m behind it and to its right, never in view. A body is
looked at once (by its track's id), when it is within `GLANCE_M`, outside the camera's
view, and no map person the camera saw within `KNOWN_S` stands there (who it is is
known; within `KNOWN_STANDING_S` for one it saw standing: seed 1's shift turned to one
bystander standing 1.5 m off three times in 40 s, each time a new track of them); again
once it came from where it was looked at (`CAME_M`) to stand within `ANSWER_M` of the
base (who answers the ask comes up to the robot, wherever it faces: seed 0's next shift
had person_4 walk up and stand 1.3 m behind it for 10 s, unseen, after the robot had
looked at them 4.4 m off, not near enough to be named). The turn aims where its velocity
takes it in `LEAD_S`. Pure: no transport.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from common.messages.base import NS_PER_S
from common.messages.navigation import ScanBody
from common.messages.semantic_map import MapEntity, SeenPlace

#: m: a place this near one looked round at (or the robot) is looked at already: the
#: head camera sees a person well beyond it while the robot turns.
LOOKED_M = 2.5
#: A usual place is seen at least this share as often as the most seen one.
SHARE = 0.25
#: m: a body the lidars track this near the base (and no nearer than `GLANCE_MIN_M`:
#: the camera, pitched down, sees no face so near) is looked at while the robot asks.
GLANCE_M = 4.5
GLANCE_MIN_M = 0.5
#: rad: a body within this of the base's heading is in the head camera's view (its half
#: field, 36°, less a body's width at 1.5 m).
IN_VIEW_RAD = math.radians(28.0)
#: A map person the camera saw within this (s), standing within `KNOWN_M` (m, and how far
#: they walk meanwhile at their speed) of a body, is who the body is.
KNOWN_S = 2.0
KNOWN_M = 0.8
#: s: ...and a map person the camera saw standing (slower than `WALKING_MPS`) this long
#: ago, within `KNOWN_M` of a body, is who that body is.
KNOWN_STANDING_S = 30.0
#: s: the turn aims where the body's velocity takes it in this long.
LEAD_S = 1.0
#: m: who comes this near the base while it asks may be answering (`LookForPerson`); a
#: body looked at once is looked at again when it has come this far from there to stand
#: that near (slower than `WALKING_MPS`).
ANSWER_M = 2.0
CAME_M = 1.0
#: m/s: a person slower than this stands (the mission's one threshold: `LookForPerson`,
#: `StandsThere` take it too).
WALKING_MPS = 0.3


def next_place(
    places: Sequence[SeenPlace],
    looked: Sequence[tuple[float, float]],
    robot_xy: tuple[float, float] | None,
) -> SeenPlace | None:
    """The usual place to look at next (module docstring); None when none is left."""
    if not places:
        return None
    most = max(p.sightings for p in places)
    done = [*looked, *([robot_xy] if robot_xy is not None else [])]
    left = [
        p
        for p in places
        if p.sightings >= SHARE * most and all(math.dist(p.xy, q) > LOOKED_M for q in done)
    ]
    if not left:
        return None
    if robot_xy is None:
        return left[0]
    return min(left, key=lambda p: (math.dist(p.xy, robot_xy), -p.sightings))


def glance_at(
    bodies: Sequence[ScanBody],
    people: Sequence[MapEntity],
    robot_xy: tuple[float, float],
    robot_yaw: float,
    now_ns: int,
    glanced: Mapping[str, tuple[float, float]] | None = None,
) -> tuple[ScanBody, float] | None:
    """The body to turn the head camera to while the robot asks, and the heading to turn
    to (rad, world); None when nobody unknown is near (module docstring). `glanced`: the
    track ids looked at already, and where they were then."""
    best: tuple[float, ScanBody, float] | None = None
    for body in bodies:
        d = math.dist(robot_xy, (body.x, body.y))
        was = (glanced or {}).get(body.id)
        if was is not None and not _came(body, was, d):
            continue
        if not GLANCE_MIN_M <= d <= GLANCE_M or _known(body, people, now_ns):
            continue
        bearing = math.atan2(body.y - robot_xy[1], body.x - robot_xy[0])
        if abs(math.remainder(bearing - robot_yaw, math.tau)) <= IN_VIEW_RAD:
            continue  # the camera sees them now: they are known, or nobody it can tell
        vx, vy = body.velocity or (0.0, 0.0)
        aim = math.atan2(body.y + vy * LEAD_S - robot_xy[1], body.x + vx * LEAD_S - robot_xy[0])
        if best is None or d < best[0]:
            best = (d, body, aim)
    return None if best is None else (best[1], best[2])


def _came(body: ScanBody, was: tuple[float, float], d: float) -> bool:
    """Whether a body looked at once came from there to stand within `ANSWER_M`."""
    standing = body.velocity is not None and math.hypot(*body.velocity) < WALKING_MPS
    return standing and d <= ANSWER_M and math.dist(was, (body.x, body.y)) >= CAME_M


def _known(body: ScanBody, people: Sequence[MapEntity], now_ns: int) -> bool:
    """Whether a map person the camera saw lately stands where the body is."""
    for q in people:
        age = (now_ns - q.last_seen_ns) / NS_PER_S
        standing = math.hypot(*q.velocity_in_world[:2]) < WALKING_MPS
        if q.last_seen_ns <= 0 or age > (KNOWN_STANDING_S if standing else KNOWN_S):
            continue
        reach = KNOWN_M + math.hypot(*q.velocity_in_world[:2]) * max(age, 0.0)
        if math.dist(q.position_in_world[:2], (body.x, body.y)) <= reach:
            return True
    return False
