"""Which detection is a mapped thing: the one rule every consumer of detections uses.

A detection is the map entity of class C at `near_xy` (world, horizontal, m) when it is
of class C and its point-cloud centroid (`Detection.centroid_in_world`) is the nearest
of that class to `near_xy`, within `gate_m`. The gate keeps a consumer off another
thing in view (a table edge the network read as a box, 0.6 m behind the box it missed
for a frame, drew the hall's box approaches back and forth). With `any_class`, when no
detection of C is within the gate, any artifact there will do (the network reads a box
1.5 m away as a can: where it is is all an approach needs). Without a mapped place, the
nearest of the class to the camera (`d_obj`). Pure: used by the mission's approach,
perception's `locate` and the trials.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from common.messages.perception import Detection


def pick_detection(
    detections: Sequence[Detection],
    class_name: str,
    near_xy: tuple[float, float] | None,
    gate_m: float,
    any_class: bool = False,
) -> Detection | None:
    """The detection that is the mapped thing (see the module docstring), or None."""
    same = [d for d in detections if d.class_name == class_name]
    if near_xy is None:
        return min(same, key=lambda d: d.d_obj, default=None)
    x, y = near_xy

    def off(d: Detection) -> float:
        return math.hypot(d.centroid_in_world[0] - x, d.centroid_in_world[1] - y)

    others = [d for d in detections if d.class_name not in (class_name, "person")]
    for pool in (same, others if any_class else []):
        best = min(pool, key=off, default=None)
        if best is not None and off(best) <= gate_m:
            return best
    return None
