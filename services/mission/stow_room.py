"""Whether the arm can fold a held object to `stow` where the robot stands, and how far
the base backs off first when it cannot.

`stow` holds the TCP `posture_tcp("stow")` ahead of and above the base (0.50 m, 0.29 m:
0.82 m over the floor standing). An object picked with the TCP higher than that hangs
below its support's top once stowed, by the difference; and where the support's edge is
nearer the base than the stowed object's far end (`GraspPlan.beyond_m` past the TCP)
and `MARGIN_M`, the fold pushes it into the support. Hall seed 11's shift: box_1 on
bench_1 (top 0.87 m), side-grasped with the TCP at 0.94 m, the base 0.55 m from the
bench's end and the box reaching 8 cm past the TCP: `Posture(stow)` stopped 0.42 rad
short after 5.7 s, twice, and the request failed `arm_failed` with the box held.

So, before the stow, the arm pulls the lifted object straight back toward the robot by
the distance the base then backs off (`stow_back_off_m`; the object stays where the arm
holds it in the world while the base walks back under it, the arm's reach as after the
lift), and the stow folds it down `MARGIN_M` clear of the edge. The edge is the map's
first occupied cell ahead of the base in a corridor as wide as the held object
(`support_ahead_m`). An object that does not dip below its support's top (a bottle off a
0.72 m table grasped at 0.82 m) stows where it was picked. Pure numpy.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from common.robot import STAND_BASE_HEIGHT_M, posture_tcp
from services.mission.room_behind import occupied_rows

#: Kept between the stowed object's far end and the support's edge, m.
MARGIN_M = 0.04
#: The stowed object must hang more than this below its support's top (m) for the edge to
#: matter: a bottle off a table stows level with the top and passes over its edge.
DIP_M = 0.02
#: Half the width of the corridor ahead of the TCP searched for the edge, m (a held box's
#: half length across, and the gripper's).
HALF_WIDTH_M = 0.08
#: How far ahead of the base the edge is looked for, m (one farther than the stowed
#: object's far end by more than the largest back-off never matters).
LOOK_AHEAD_M = 1.0
#: The most the base backs off for a stow, m: more would walk it far from where it
#: stood, out of what the map showed round the pick.
BACK_OFF_MAX_M = 0.3


def support_ahead_m(
    cells: NDArray[np.uint8],
    resolution_m: float,
    origin_xy: tuple[float, float],
    xy: tuple[float, float],
    yaw: float,
    lateral_m: float,
    reach_m: float = LOOK_AHEAD_M,
    half_width_m: float = HALF_WIDTH_M,
) -> float:
    """Metres from the base at (xy, yaw) straight ahead to the first occupied cell of the
    grid in the corridor `half_width_m` either side of the line `lateral_m` to its left,
    looked at up to `reach_m`; inf when there is none (or the corridor leaves the grid)."""
    step = resolution_m / 2.0
    ahead = np.arange(0.0, reach_m + step / 2, step)
    across = np.arange(lateral_m - half_width_m, lateral_m + half_width_m + step / 2, step)
    rows = np.nonzero(occupied_rows(cells, resolution_m, origin_xy, xy, yaw, ahead, across))[0]
    return math.inf if len(rows) == 0 else float(ahead[rows[0]])


def stow_back_off_m(grasp_tcp_z: float, edge_m: float, beyond_m: float) -> float:
    """How far (m) the base backs off before the stow: 0 when the stowed object does not
    hang `DIP_M` below its support's top (the TCP's height at the grasp, world z, against
    the stow's standing) or its far end (`beyond_m` past the TCP) stays `MARGIN_M` short
    of the support's edge `edge_m` ahead of the base; at most `BACK_OFF_MAX_M`."""
    ahead, _, up = posture_tcp("stow")
    if STAND_BASE_HEIGHT_M + up > grasp_tcp_z - DIP_M:
        return 0.0
    need = ahead + beyond_m + MARGIN_M - edge_m
    return float(min(max(need, 0.0), BACK_OFF_MAX_M))
