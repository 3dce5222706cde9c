"""Where a thing can be: the map's own geometry as evidence against false entries.

A map the robot builds from nothing has no floor plan to tell it that a "box" is a table's
edge; it has its support surfaces (the tops layer's tables and benches, `supports`) and its
occupancy. The segmenter's false positives there fall in a few places a person would
dismiss at a glance (the explored small and hall worlds: boxes flat on a table top, bottles
under one, bottles on a person, a "person" standing in a table, people beyond the walls),
so these rules hold for every detection and for every entity the map made itself:

- an artifact over a support stands on it: its visible centroid lies between
  `ABOVE_TOP_M` above the top (the smallest object's half height, less the depth's
  noise; a mask flat on the top is the top) and the tallest artifact's height above it;
  one below the top is the table's apron or legs; one off the top's rectangle but
  within `EDGE_BAND_M` of it and a little below the top is the top's edge (an
  explored top's rectangle can stop short of the edge the camera saw);
- an artifact off every support, not over an obstacle the map knows, within
  `PERSON_REACH_M` of a person the map saw lately (and often: one it would keep) is the
  person's hand or clothes (the same frame's person detections already drop them; this
  catches the frames where the person is cut off or not detected). Over an obstacle
  (`on_obstacle`: a table's footprint the depth learned, whose top the head camera,
  below it, never saw) it stands on that obstacle: the explored small world's bottle,
  0.7 m behind the only edge of its table the tops layer had, was deleted beside a
  "person" the network made of the table's underside;
- a person does not stand inside a support's top, nor inside an obstacle the map knows
  (every cell within `INSIDE_M` occupied: the people's own points are never learned as
  obstacles), nor where the map knows no floor (`KNOWN_FLOOR_M` around the place, on a
  lidar or file map: beyond the walls the depth reads through gaps).

The rules read the map's surfaces, so they apply on a map with no floor plan (the floor
plan's ablation keeps the static-obstacle checks of `mapper`). Pure functions; the
mapper applies them to each frame's observations and, when the surfaces change, to the
entities it made itself (`source` perception), which it deletes with the reason.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from common.geometry import FloatArray, on_surface
from common.messages.world import SupportSurface
from services.semantic_map.occupancy import FREE, OCCUPIED, Occupancy
from services.semantic_map.supports import SURFACE_Z_M

#: An artifact's visible centroid above the support's top, m: the flattest artifact (a
#: box 8 cm tall) shows its top face and front, 4-8 cm up; a mask on the top itself sat
#: up to 3.5 cm above the top the tops layer measured on the explored small world (the
#: "box" a table's far edge makes); the tallest artifact stands 0.25 m.
ABOVE_TOP_M = (0.04, 0.45)
#: Off every surface, an artifact's visible centroid is at most this above the floor (the
#: tallest artifact's middle, 0.125 m, and the depth's noise), m; or it stands on a top
#: within `UNDER_M` (of `TOP_FRAMES` frames, at working height, not above it).
FLOOR_CENTROID_MAX_M = 0.2
UNDER_M = 0.3
TOP_FRAMES = 3
#: A place within this of a surface's rectangle is over it, m (the rectangle is the
#: tops' minimum-area one: a little short of the edge the camera saw).
SURFACE_MARGIN_M = 0.05
#: Beyond that margin, up to this far from the rectangle, an artifact whose visible
#: centroid lies below the top, by no more than `APRON_M`, is the top's edge, m: the
#: network reads a table's front face as a "box" or "bottle" (centroids 1-2 cm below the
#: top in 516 rendered head-camera frames of seed 1's table_1, real objects' from 0.1 cm
#: above it), and an explored top's rectangle can stop short of the edge the camera saw.
#: Off the rectangle a real object stands on the top (above it) or on the floor (below
#: `FLOOR_CENTROID_MAX_M`). Below the top, not `ABOVE_TOP_M`'s least above it as over the
#: rectangle: an explored top reads 1-2 cm high, and a box there is not to be lost.
EDGE_BAND_M = 0.2
APRON_M = 0.12
#: A person stands where the map knows floor within this, m (a person's blob and its
#: shadow are unknown or occupied, the floor around them free).
KNOWN_FLOOR_M = 0.35
#: Person detections of one frame closer than this are one person, and an artifact
#: detection this close to one of them is their clothes (`mapper`), m.
PERSON_MERGE_M = 0.4
#: An artifact off every surface this close to a person the map saw within
#: `PERSON_RECENT_NS` is in their hand or on their clothes (an arm's reach from the
#: person's axis point), m.
PERSON_REACH_M = 0.6
PERSON_RECENT_NS = 10_000_000_000
#: A person whose every cell within this is an obstacle stands inside it, m.
INSIDE_M = 0.1


def surface_under(
    xy: FloatArray, surfaces: list[SupportSurface], margin_m: float = SURFACE_MARGIN_M
) -> SupportSurface | None:
    """The surface whose rectangle (grown by `margin_m`) holds `xy` (the highest one)."""
    under = [s for s in surfaces if on_surface(xy, s, margin_m)]
    return max(under, key=lambda s: s.top_height) if under else None


def artifact_doubt(
    xy: FloatArray, z: float, surfaces: list[SupportSurface], occupancy: Occupancy | None = None
) -> str:
    """Why an artifact at (xy, z) (its visible centroid) cannot be one; "" when it can.
    Without `occupancy` one off every surface is not judged."""
    s = surface_under(xy, surfaces)
    if s is None:
        edge = at_edge(xy, z, surfaces)
        if edge is not None:
            return (
                f"at the edge of {edge.id}'s top ({edge.top_height:.2f} m) at {z:.2f} m, "
                "off its rectangle: the top's edge itself"
            )
        if occupancy is None or z <= FLOOR_CENTROID_MAX_M or not floats(occupancy, xy, z):
            return ""
        return f"on no surface, {z:.2f} m over free floor with no top under it to stand on"
    above = z - s.top_height
    if above < ABOVE_TOP_M[0]:
        where = "below" if above < -ABOVE_TOP_M[0] else "flat on"
        return f"{where} the top of {s.id} ({s.top_height:.2f} m) at {z:.2f} m: the surface itself"
    if above > ABOVE_TOP_M[1]:
        return f"{above:.2f} m above the top of {s.id}: taller than any artifact"
    return ""


def at_edge(xy: FloatArray, z: float, surfaces: list[SupportSurface]) -> SupportSurface | None:
    """The surface within `EDGE_BAND_M` of xy whose top's edge a thing at height z is
    (`EDGE_BAND_M`), if any."""
    for s in surfaces:
        if -APRON_M <= z - s.top_height < 0.0 and on_surface(xy, s, EDGE_BAND_M):
            return s
    return None


def person_doubt(
    xy: FloatArray, surfaces: list[SupportSurface], occupancy: Occupancy | None = None
) -> str:
    """Why a person at xy cannot be one; "" when they can. `occupancy`: check the floor
    around them too (a map whose static layer the robot sensed)."""
    s = surface_under(xy, surfaces, 0.0)
    if s is not None:
        return f"inside the top of {s.id}"
    if occupancy is None:
        return ""
    if inside_obstacle(occupancy, xy, INSIDE_M):
        return f"inside an obstacle the map knows (every cell within {INSIDE_M:g} m)"
    if not known_floor_near(occupancy, xy, KNOWN_FLOOR_M):
        return f"no floor the map knows within {KNOWN_FLOOR_M:g} m (beyond a wall?)"
    return ""


def on_obstacle(occupancy: Occupancy, xy: FloatArray) -> bool:
    """Whether xy's cell of the merged grid is an obstacle (static or learned)."""
    return inside_obstacle(occupancy, xy, 0.0)


def inside_obstacle(occupancy: Occupancy, xy: FloatArray, radius_m: float) -> bool:
    """Whether every cell of the merged grid within `radius_m` of xy is an obstacle."""
    window = _disc(occupancy, xy, radius_m)
    if window is None:
        return False
    (y0, y1, x0, x1), disc = window
    return bool(np.all(occupancy.cells((slice(y0, y1), slice(x0, x1)))[disc] == OCCUPIED))


def floats(occupancy: Occupancy, xy: FloatArray, z: float) -> bool:
    """Whether a thing at xy, z would float: its cell of the merged grid free, and no
    top at working height (not above z + 5 cm, seen in `TOP_FRAMES` frames) within
    `UNDER_M`."""
    window = _disc(occupancy, xy, 0.0)
    if window is None:
        return False
    (y0, y1, x0, x1), _ = window
    if not np.all(occupancy.cells((slice(y0, y1), slice(x0, x1))) == FREE):
        return False
    window = _disc(occupancy, xy, UNDER_M)
    assert window is not None
    (y0, y1, x0, x1), disc = window
    tz, tn = occupancy.top_z[y0:y1, x0:x1], occupancy.top_n[y0:y1, x0:x1]
    top = (tn >= TOP_FRAMES) & (tz >= SURFACE_Z_M[0] - 0.1) & (tz <= z + 0.05)
    return not np.any(top & disc)


def _disc(
    occupancy: Occupancy, xy: FloatArray, radius_m: float
) -> tuple[tuple[int, int, int, int], NDArray[np.bool_]] | None:
    """The grid's window round xy (y0, y1, x0, x1) and the disc of `radius_m` in it."""
    res = occupancy.resolution_m
    ix = int(np.floor((float(xy[0]) - occupancy.origin_xy[0]) / res))
    iy = int(np.floor((float(xy[1]) - occupancy.origin_xy[1]) / res))
    r = int(np.ceil(radius_m / res))
    h, w = occupancy.static.shape
    y0, y1, x0, x1 = max(0, iy - r), min(h, iy + r + 1), max(0, ix - r), min(w, ix + r + 1)
    if y0 >= y1 or x0 >= x1:
        return None
    yy, xx = np.mgrid[y0:y1, x0:x1]
    return (y0, y1, x0, x1), (yy - iy) ** 2 + (xx - ix) ** 2 <= r * r


def known_floor_near(occupancy: Occupancy, xy: FloatArray, radius_m: float) -> bool:
    """Whether a cell within `radius_m` of xy is known floor: free in the static layer,
    or seen as floor by the depth (the merged grid's free cells, but for learned
    obstacles: a person's own cells are not floor anyway)."""
    window = _disc(occupancy, xy, radius_m)
    if window is None:
        return False
    (y0, y1, x0, x1), disc = window
    floor = (occupancy.static[y0:y1, x0:x1] == FREE) | occupancy.seen_free[y0:y1, x0:x1]
    return bool(np.any(floor & disc))
