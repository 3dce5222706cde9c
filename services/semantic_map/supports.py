"""`dume/map/supports`: the tables, benches and loaded pallets artifacts stand on, served
to the mapping patrol's semantic pass.

With `floor_plan = "world"` they are the floor plan's (the sim's world description, the
building's plan, as the static occupancy layer is): fetched once, through
`world(wait_s)`, on the first query that needs them, and kept (`FloorPlanSupports`). A
world description that does not come is `unavailable` (asked again by the next query);
the node asks on the queryable's thread, without the map's lock: the fetch may wait up
to `WORLD_WAIT_S` wall seconds.

Without a floor plan they are what the map saw (`surfaces_from_tops`, on the occupancy's
tops layer): cells whose top lies at working height (`SURFACE_Z_M`), confirmed by
`min_frames` frames, joined into patches (8-connected, gaps of a cell closed); a patch
whose tops agree within `FLAT_M` of its median and covers `min_area_m2` is a surface:
its minimum-area rectangle (OpenCV) with half a cell each side, the median top as its
height, ids `surface_<n>` in order of position. The head camera sees a bench top from
below its edge: such a surface is the strip of its front edge, which is where the
patrol must look from anyway; with the arm up (`look`) the wrist camera fills the top.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from common.bus import RequestError
from common.geometry import on_surface
from common.messages.world import SupportSurface, WorldDescription

#: Wall seconds a query waits for the world description.
WORLD_WAIT_S = 5.0
log = logging.getLogger("dume.semantic_map")
#: Working height: the tops of tables, benches and loaded pallets, m.
SURFACE_Z_M = (0.45, 1.3)
FLAT_M = 0.04


def surfaces_from_tops(
    top_z: NDArray[np.float32],
    top_n: NDArray[np.uint16],
    resolution_m: float,
    origin_xy: tuple[float, float],
    *,
    min_frames: int = 3,
    min_area_m2: float = 0.05,
) -> list[SupportSurface]:
    """The surfaces at working height in a tops layer (see the module docstring)."""
    z0, z1 = SURFACE_Z_M
    top = (top_n >= min_frames) & (top_z >= z0) & (top_z <= z1)
    joined = ndimage.binary_closing(top, structure=np.ones((3, 3), bool)) | top
    labels, n = ndimage.label(joined, structure=np.ones((3, 3), bool))
    out: list[SupportSurface] = []
    for k in range(1, n + 1):
        patch = (labels == k) & top
        heights = top_z[patch]
        if len(heights) == 0:
            continue
        height = float(np.median(heights))
        patch &= np.abs(top_z - height) <= FLAT_M
        if patch.sum() * resolution_m**2 < min_area_m2:
            continue
        iy, ix = np.nonzero(patch)
        xy = np.column_stack(
            [origin_xy[0] + (ix + 0.5) * resolution_m, origin_xy[1] + (iy + 0.5) * resolution_m]
        ).astype(np.float32)
        (cx, cy), (w, h), angle = cv2.minAreaRect(xy)
        out.append(
            SupportSurface(
                id="",
                centre_xy=(float(cx), float(cy)),
                half_extents=(0.5 * (w + resolution_m), 0.5 * (h + resolution_m)),
                yaw=float(np.radians(angle)),
                top_height=height,
            )
        )
    return _numbered(out)


def _numbered(surfaces: Iterable[SupportSurface]) -> list[SupportSurface]:
    """`surface_1`, `surface_2`, ... in order of their centres (to 0.1 m, x then y)."""
    ordered = sorted(surfaces, key=lambda s: (round(s.centre_xy[0], 1), round(s.centre_xy[1], 1)))
    return [
        SupportSurface(f"surface_{i}", s.centre_xy, s.half_extents, s.yaw, s.top_height)
        for i, s in enumerate(ordered, start=1)
    ]


def with_kept(found: list[SupportSurface], kept: list[SupportSurface]) -> list[SupportSurface]:
    """`found` (this run's tops) and those of `kept` (a saved map's) it shows nothing of:
    no centre of either inside the other."""
    if not kept:
        return found
    extra = [
        k
        for k in kept
        if not any(on_surface(k.centre_xy, f) or on_surface(f.centre_xy, k) for f in found)
    ]
    return _numbered([*found, *extra]) if extra else found


class FloorPlanSupports:
    """The floor plan's support surfaces, fetched once (see the module docstring)."""

    def __init__(self, floor_plan: str, world: Callable[[float], WorldDescription | None]) -> None:
        self.floor_plan, self.world = floor_plan, world
        self._surfaces: list[SupportSurface] | None = None
        self._lock = threading.Lock()

    def surfaces(self) -> list[SupportSurface]:
        if self.floor_plan != "world":
            return []
        with self._lock:
            if self._surfaces is None:
                w = self.world(WORLD_WAIT_S)
                if w is None:
                    raise RequestError(
                        "unavailable", "no world description: the floor plan's supports are unknown"
                    )
                self._surfaces = list(w.surfaces)
                log.info("floor plan: %d tables and benches", len(self._surfaces))
            return self._surfaces
