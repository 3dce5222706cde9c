"""Where to look for an object that is not where the map says, and when it is found.

A person who does not find a part where it usually lies looks round that place first,
then where they last saw such parts, then on the benches nearby, then everywhere else.
`places_to_look` orders the places so, at most `max_places` of them:

1. the object's last place (the map's, where the approach did not find it): the whole
   support it stood on is looked at again, from a viewpoint of its own;
2. the other places the map saw an artifact of its class within `recent_s`, nearest
   first (someone may have put it beside its like);
3. the supports (tables, benches, pallets: `dume/map/supports`) not yet among the places,
   nearest first: those nearby, then the rest of the hall (the semantic pass's surfaces).

The viewpoints stand out of people's way where they can (`busy_places`: where the map's
people are usually seen, and where they are now; `coverage.facing_route`).

A place is a point on the floor to look at with why it is looked at, and, for a place on
a support, the points along that support's top `STRETCH_M` apart (`along`: a viewpoint
facing one point sees a stretch of a top; an object moved along its table by 0.6 m was
not in view of its old place, and the search ended there); the mission walks viewpoints
facing them all (`coverage.facing_route`, as the second look does) with the arm up.
`found` says, after each look, whether the map now has the object: an artifact of the
class, not missing, seen since the search began over a support or at a place looked at,
fused from at least `FIRM_OBSERVATIONS` detections (the map deletes an entry of a few
stray detections as soon as a look misses it: hall seed 0's shift stopped its search for
a "bottle" made from two head-camera detections, deleted 1.2 s later, and the fetch
walked to nothing), not one the fetch already tried; for a
request by id, also not one the map already knew when the search began (the object
moved makes a new entry where it now stands; an old one is another object of its
class), nor a new one standing where the map has a known one of its class that was
not seen itself since the search began, or that stands there seen only from afar
(`re_seen`: that one, seen again a little off its mapped place). An object this
mission handed over is tried, unless the map saw its entry since the search began, away
from everyone (`put_down`, `targets.put_back`): the robot took it from its place, and
whatever the map sees there now is another one (hall seed 2's shift put bottle_1 where
the handed-over bottle_8 had stood; every view of it went to bottle_8's stale entry,
which the search passed over as tried and known, and the request failed
`object_not_found` with the bottle in view). Pure: no transport.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import NamedTuple

from common.geometry import on_surface
from common.messages.semantic_map import MapEntity
from common.messages.world import SupportSurface

#: m: a point this near a support's top counts as on it.
ON_MARGIN_M = 0.2
#: m: a support's top is looked at every this far along it.
STRETCH_M = 0.6
#: An entry fused from fewer detections than this is not found yet (0.5 s of a camera).
FIRM_OBSERVATIONS = 5
#: m: a new entry this near a known one of its class not seen since the search began is
#: that one seen again (`re_seen`): twice the map's least association gate.
RE_SEEN_M = 0.5
#: m: a new entry seen from no nearer than this beside a known one of its class may be
#: that one, even when it was seen too (`re_seen`): the map's `class_near_m`, the range
#: within which the network and the depth are trusted.
NEAR_VIEW_M = 2.0


class Place(NamedTuple):
    """A point on the floor to look at (m, world), and why; `also`: the other points of
    the place (along its support's top); `rank`: which of the module docstring's three
    kinds it is (1 its last place, 2 a recent sighting of its class, 3 a support): the
    route looks at them rank by rank (`behaviours.search`)."""

    xy: tuple[float, float]
    why: str
    also: tuple[tuple[float, float], ...] = ()
    rank: int = 3

    @property
    def points(self) -> list[tuple[float, float]]:
        return [self.xy, *self.also]


def along(s: SupportSurface) -> list[tuple[float, float]]:
    """Points on the top's long axis, `STRETCH_M` apart, centred on it (the centre alone
    for a top shorter than that)."""
    long_x = s.half_extents[0] >= s.half_extents[1]
    half = max(s.half_extents)
    n = max(1, math.ceil(2 * half / STRETCH_M))
    step = 2 * half / n
    c, si = math.cos(s.yaw), math.sin(s.yaw)
    ux, uy = (c, si) if long_x else (-si, c)
    return [
        (s.centre_xy[0] + ux * u, s.centre_xy[1] + uy * u)
        for u in (-half + step * (k + 0.5) for k in range(n))
    ]


def places_to_look(
    last_xy: tuple[float, float] | None,
    class_name: str,
    artifacts: Iterable[MapEntity],
    supports: Sequence[SupportSurface],
    robot_xy: tuple[float, float],
    now_ns: int,
    recent_s: float,
    max_places: int,
    skip: Iterable[str] = (),
) -> list[Place]:
    """The places of the module docstring, in order, `max_places` at most; `skip`: map ids
    whose places are not worth a look (the candidates already tried there)."""
    out: list[Place] = []
    covered: set[str] = set()

    def add(xy: tuple[float, float], why: str, rank: int) -> None:
        if len(out) >= max_places:
            return
        under = next((s.id for s in supports if on_surface(xy, s, ON_MARGIN_M)), "")
        if under and under in covered:
            return  # that support is looked at already
        if any(math.dist(xy, p.xy) < 0.5 for p in out):
            return
        also: tuple[tuple[float, float], ...] = ()
        if under:
            covered.add(under)
            top = next(s for s in supports if s.id == under)
            also = tuple(q for q in along(top) if math.dist(q, xy) > STRETCH_M / 2)
        on = f" (on {under})" if under and under not in why else ""
        out.append(Place(xy, why + on, also, rank))

    if last_xy is not None:
        add(last_xy, "where the map had it", 1)
    skipped = set(skip)
    recent_ns = round(recent_s * 1e9)
    seen = [
        a for a in artifacts
        if a.class_name == class_name and a.missing_since_ns is None and a.id not in skipped
        and 0 <= now_ns - a.last_seen_ns <= recent_ns and a.last_seen_ns > 0
    ]  # fmt: skip
    for a in sorted(seen, key=lambda a: math.dist(a.position_in_world[:2], robot_xy)):
        ago = (now_ns - a.last_seen_ns) / 1e9
        x, y = a.position_in_world[:2]
        add((x, y), f"a {class_name} seen there {ago:.0f} s ago ({a.id} at ({x:.2f}, {y:.2f}))", 2)
    for s in sorted(supports, key=lambda s: math.dist(s.centre_xy, robot_xy)):
        if s.id not in covered:
            add((s.centre_xy[0], s.centre_xy[1]), f"{s.id}, a support", 3)
    return out


def busy_places(people: Iterable[MapEntity]) -> list[tuple[float, float]]:
    """Where people walk and stand, as the map knows it: each person's usual places
    (`MapEntity.places`: every cell they were seen in, a walker's aisle as a worker's
    bench) and where they are now."""
    out: list[tuple[float, float]] = []
    for p in people:
        out.append((p.position_in_world[0], p.position_in_world[1]))
        out += [(q.xy[0], q.xy[1]) for q in p.places]
    return out


#: m: a sighting this near a place looked at counts even off every known support.
NEAR_PLACE_M = 0.75


def _near(a: MapEntity, places: Sequence[Place], supports: Sequence[SupportSurface]) -> bool:
    xy = (a.position_in_world[0], a.position_in_world[1])
    return any(on_surface(xy, s, ON_MARGIN_M) for s in supports) or any(
        math.dist(xy, q) <= NEAR_PLACE_M for p in places for q in p.points
    )


def found(
    artifacts: Iterable[MapEntity],
    class_name: str,
    since_ns: int,
    tried: Iterable[str],
    known: Iterable[str] | None,
    now_ns: int | None = None,
    where: tuple[Sequence[Place], Sequence[SupportSurface]] | None = None,
    put_down: Iterable[str] = (),
) -> MapEntity | None:
    """The artifact the search found (module docstring), nearest to nothing in
    particular: the most recently seen; None while there is none. `known`: the ids the
    map had when the search began (a request by id), None for a request by class; a
    sighting stamped after `now_ns` is no sighting (a clock other than this run's).
    `where`: the places looked at and the supports: a sighting counts only over a
    support or within `NEAR_PLACE_M` of a place (a "bottle" the network saw in the
    aisle while the robot walked is not where anyone puts one: hall seed 0's shift
    fetched such a one, and it was not there). `put_down`: tried or known ids that count
    as new sightings all the same (objects handed over, seen since away from everyone)."""
    artifacts = list(artifacts)
    skip = (set(tried) | set(known or ())) - set(put_down)
    fresh = [
        a for a in artifacts
        if a.class_name == class_name and a.missing_since_ns is None and a.id not in skip
        and a.observations >= FIRM_OBSERVATIONS
        and since_ns <= a.last_seen_ns and (now_ns is None or a.last_seen_ns <= now_ns)
        and (where is None or _near(a, *where))
        and (known is None or re_seen(a, artifacts, set(known) - set(tried), since_ns) is None)
    ]  # fmt: skip
    return max(fresh, key=lambda a: (a.last_seen_ns, a.id)) if fresh else None


def re_seen(
    new: MapEntity, artifacts: Iterable[MapEntity], known: set[str], since_ns: int
) -> MapEntity | None:
    """The known entry of `new`'s class that `new` is most likely that one seen again off
    its mapped place: within `RE_SEEN_M` of it, not missing, and either not seen itself
    since the search began (its detections went to the new entry) or `new` seen only
    from afar (never within `NEAR_VIEW_M`). None: `new` is another object.
    The map's estimate of an artifact seen from afar, or seeded, can lie a little beyond
    its association gate, and one far view can come apart in two: hall seed 1's shift
    looked for a moved bottle_1 from table_1, 5 m from table_2, where the map had
    bottle_2; the head camera's views of it went to bottle_2, the raised wrist camera's,
    0.26 m nearer, made bottle_8, and the fetch brought bottle_2 for bottle_1. An
    object put down beside its like and seen from near, the like seen too, is still
    found; from afar the two cannot be told apart, and a near look decides."""
    x, y = new.position_in_world[:2]
    far = new.nearest_view_m is None or new.nearest_view_m > NEAR_VIEW_M
    near = [
        a for a in artifacts
        if a.id in known and a.id != new.id and a.class_name == new.class_name
        and a.missing_since_ns is None and (far or a.last_seen_ns < since_ns)
        and math.hypot(a.position_in_world[0] - x, a.position_in_world[1] - y) <= RE_SEEN_M
    ]  # fmt: skip
    return min(near, key=lambda a: math.dist(a.position_in_world[:2], (x, y)), default=None)
