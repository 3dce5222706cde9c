"""Where to look for a person who is not where the map last saw them: their usual places.

The map counts where it saw each person (`MapEntity.places`, `semantic_map.whereabouts`,
most seen first). A person not at their last place is looked for where they usually are,
as a colleague would: at their bench, along the aisle they walk. `next_place` gives the
place to walk to and look round at next: of the places seen at least `SHARE` as often as
the most seen one (where they usually are, not where they once passed), those farther
than `LOOKED_M` from every place looked round at in this request and from the robot, the
nearest. None when none is left: the walk goes to where the map last had them. A walker
on a loop comes past any place of it once a lap: standing there looking round (the turn
and the ask, `behaviours.motion.LookForPerson`) sees them come. Pure: no transport.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from common.messages.semantic_map import SeenPlace

#: m: a place this near one looked round at (or the robot) is looked at already: the
#: head camera sees a person well beyond it while the robot turns.
LOOKED_M = 2.5
#: A usual place is seen at least this share as often as the most seen one.
SHARE = 0.25


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
