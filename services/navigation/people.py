"""Speed and separation monitoring around people (in the spirit of ISO/TS 15066).

Distances are from the robot's footprint (arm stowed) to a person's floor position.
`people_limit` gives the speed cap of one tick (`navigation.people`): `stop` when a person
is within `stop_distance_m` in the direction of travel (ahead of the footprint along the
commanded velocity, within ±`TRAVEL_HALF_ANGLE_RAD`); `handover_speed` within
`slow_radius_m` of the person being handed over to; `slow_speed` within `slow_radius_m`
of anyone else; otherwise no cap. The caps are met at their boundaries, not only inside
them: the command goes through acceleration limits and a period of latency, so each cap
is approached on a braking ramp `v ≤ √(v_cap² + 2 a (d − d_cap − lead))` (`BRAKE_DECEL`,
`BRAKE_LEAD_M`; no cap where that is at or above the base's top speed): the robot enters
the slow zone at the slow speed, and a person ahead brings it to rest at the stop
distance plus the lead (`stop` from there) rather than through it; a stop holds until
the person is `RESUME_MARGIN_M` further. The node logs every change of the active rule.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np

from common.config import PeopleSettings
from services.navigation.costmap import Person
from services.navigation.grid import Footprint, Pose, distance_to_footprint

Rule = Literal["", "slow", "handover", "stop"]


#: Not settings (those are `PeopleSettings`, `navigation.people`): the half angle of the
#: direction of travel (rad), the braking ramps' deceleration (m/s²) and lead (m), how much
#: further a person must be to release a stop (m).
TRAVEL_HALF_ANGLE_RAD = math.radians(60.0)
BRAKE_DECEL = 0.5
BRAKE_LEAD_M = 0.1
RESUME_MARGIN_M = 0.15
#: The caps are commanded this fraction below the limits: the trot overshoots a commanded
#: speed by up to 13 % over 0.5 s (0.306 m/s for 0.27, `dume trial person`).
TRACKING_MARGIN = 0.2


class SpeedLimit(NamedTuple):
    """speed: cap on the base's translation, m/s (inf: none). rule: which one acts.
    person_id, distance_m: the person it acts for and their distance from the footprint."""

    speed: float
    rule: Rule
    person_id: str = ""
    distance_m: float = math.inf


NO_LIMIT = SpeedLimit(math.inf, "")


def people_limit(
    pose: Pose,
    direction_world: tuple[float, float] | None,
    people: tuple[Person, ...] | list[Person],
    fp: Footprint,
    p: PeopleSettings,
    top_mps: float,
    handover_id: str = "",
    stopped: bool = False,
) -> SpeedLimit:
    """The tightest cap that people impose now; `direction_world` the intended travel
    direction (unit, world; None when not translating). `top_mps`: the base's top speed
    (a ramp's cap at or above it is no cap). `stopped`: the last cap was a stop, which
    then holds until the person is `RESUME_MARGIN_M` further away (their position
    jitters from frame to frame: no creeping on and off)."""
    if not people:
        return NO_LIMIT
    pts = np.array([[q.x, q.y] for q in people])
    dist = distance_to_footprint(pose, fp, pts)
    best = NO_LIMIT
    for person, d in zip(people, dist.tolist(), strict=True):
        handing = person.id == handover_id
        zone_speed = (p.handover_speed if handing else p.slow_speed) * (1.0 - TRACKING_MARGIN)
        speed = _ramp(zone_speed, d - p.slow_radius_m, top_mps)
        if not math.isfinite(speed):
            continue
        ahead = direction_world is not None and _ahead(
            pose, fp, (person.x, person.y), direction_world, TRAVEL_HALF_ANGLE_RAD
        )
        if ahead:
            beyond = d - p.stop_distance_m - (RESUME_MARGIN_M if stopped else 0)
            to_stop = _ramp(0.0, beyond, top_mps)
            if to_stop <= 0.0:  # within the stop distance and the lead: at rest
                return SpeedLimit(0.0, "stop", person.id, d)
            speed = min(speed, to_stop)
        cap = SpeedLimit(speed, "handover" if handing else "slow", person.id, d)
        if cap.speed < best.speed or (cap.speed == best.speed and d < best.distance_m):
            best = cap
    return best


def _ramp(v_cap: float, beyond_m: float, top_mps: float) -> float:
    """The speed from which the robot can brake to `v_cap` within `beyond_m` (less the
    lead); inf when that is at or above `top_mps`, the base's top speed."""
    room = beyond_m - BRAKE_LEAD_M
    if room <= 0.0:
        return v_cap
    v = math.sqrt(v_cap * v_cap + 2.0 * BRAKE_DECEL * room)
    return v if v < top_mps else math.inf


def _ahead(
    pose: Pose,
    fp: Footprint,
    xy: tuple[float, float],
    direction: tuple[float, float],
    half_angle: float,
) -> bool:
    """Whether the person lies in the direction of travel, seen from the footprint's
    nearest point to them."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    dx, dy = xy[0] - pose.x, xy[1] - pose.y
    u, v = c * dx + s * dy, -s * dx + c * dy
    u = min(max(u, -fp.back), fp.front)
    v = min(max(v, -fp.half_width), fp.half_width)
    nx, ny = pose.x + c * u - s * v, pose.y + s * u + c * v
    ex, ey = xy[0] - nx, xy[1] - ny
    norm = math.hypot(ex, ey)
    if norm < 1e-6:
        return True
    return (ex * direction[0] + ey * direction[1]) / norm >= math.cos(half_angle)
