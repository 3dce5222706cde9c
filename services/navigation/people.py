"""Speed and separation monitoring around people (ISO/TS 15066's, `separation`).

Distances are from the robot's footprint (arm stowed) to a person's floor position.
`people_limit` gives the speed cap of one tick (`navigation.people`), the tightest of two
rules per person:

- **the protective separation** (`separation.allowed_speed`): the robot's speed towards
  the person (its travel direction's component along the line from the footprint's
  nearest point to them) is at most the speed from which it can react and brake before
  the separation falls below the standard's S_p, with the person's own speed towards the
  robot (their estimated velocity plus a margin; a walking pace while unknown). Where
  even a robot at rest is too close (S_p(0) ≥ the separation, or the allowed speed below
  `CREEP_MPS`) and it is not moving away: `stop`. A walking robot is not at rest at
  once: for a person coming towards it, the stop comes earlier by how far they walk
  (their measured speed towards it) while the base comes to rest from its speed now
  (`stopping_s`): the trot's stop sways the base 0.1-0.2 m/s any way for 0.3 s (hall
  seed 0's shift, t = 46.6 s: a walker at 1.1 m/s from behind, the stop issued at S_p at
  rest, and the base's sway took it 0.15 m/s towards them 0.11 m inside S_p). A stop
  holds until the person is `RESUME_MARGIN_M` further than that (their position jitters
  from frame to frame: no creeping on and off), then the robot goes on by itself; not
  for the person handed over to, whom the robot comes up to at `handover_speed` by
  design (the handover pose lies 0.83 m from them, 0.07 m beyond the margin: the
  changing hall's shifts stood 53 and 77 s stopped 0.67-0.73 m from them). Within S_p at
  rest of anyone but the person handed over to, the robot is at rest unless its path
  leads clearly away from them (`AWAY_COS`; not once stopped for someone still coming at
  it, `HOLD_COMING_MPS`): moving along or beside a person that close,
  the trot's sway and drift step towards them (a bystander passing 0.3 m behind the
  robot, the shift: 0.06-0.1 m/s towards them while the path ran along them); nor does
  it turn on the spot (hall seed 1's shift: the handover's final turn went on with a
  bystander 0.45 m off the footprint, the base swaying 0.06 m/s towards them);
- **the slow zone**: `handover_speed` within `slow_radius_m` of the person being handed
  over to, `slow_speed` within it of anyone else, entered on a braking ramp
  `v ≤ √(v_cap² + 2 a (d − d_cap − lead))` (the command goes through acceleration limits
  and a period of latency; no cap where that is at or above the base's top speed).

The caps are commanded `TRACKING_MARGIN` below the limits. The node logs every change of
the active rule, with the person, the separation and S_p at rest.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from typing import Literal, NamedTuple

import numpy as np

from common.config import PeopleSettings
from common.geometry import FloatArray
from services.navigation.costmap import Person
from services.navigation.grid import Footprint, Pose, distance_to_footprint
from services.navigation.separation import (
    SeparationParams,
    allowed_speed,
    directed_speed,
    protective_distance,
)

Rule = Literal["", "slow", "handover", "stop"]


#: Not settings (those are `PeopleSettings`, `navigation.people`): the slow zone's ramp
#: lead (m), how much further a person must be to release a stop (m), the least speed
#: worth commanding towards a person (m/s: below it, a stop).
BRAKE_LEAD_M = 0.1
RESUME_MARGIN_M = 0.15
CREEP_MPS = 0.03
#: Within S_p at rest of a bystander, the path's direction must point at least this
#: much away from them (the cosine with the line to them) for the robot to move.
AWAY_COS = -0.5
#: A stop inside S_p of a person coming at the robot at least this fast (their measured
#: speed towards it, m/s) holds even where the path leads away: walking away at the slow
#: zone's 0.24 m/s outruns no walker, and each resume and stop sways the base towards them
#: (hall seed 4's shift, t = 277.8 s: stop and slow flapped every 0.1-0.2 s as a walker
#: at 1.13 m/s came from behind, and the sway took the base 0.087 m/s at them 0.135 m
#: inside S_p). Someone standing or slowing below it may still be walked away from.
HOLD_COMING_MPS = 0.3
#: The caps are commanded this fraction below the limits: the trot overshoots a commanded
#: speed by up to 13 % over 0.5 s (0.306 m/s for 0.27, `dume trial person`).
TRACKING_MARGIN = 0.2


class SpeedLimit(NamedTuple):
    """speed: cap on the base's translation, m/s (inf: none). rule: which one acts.
    person_id, distance_m: the person it acts for and their distance from the footprint;
    protective_m: S_p at rest for them (the separation below which the robot stops)."""

    speed: float
    rule: Rule
    person_id: str = ""
    distance_m: float = math.inf
    protective_m: float = 0.0


NO_LIMIT = SpeedLimit(math.inf, "")


def separation_params(p: PeopleSettings) -> SeparationParams:
    """The monitor's protective separation terms from the settings (its lead too)."""
    return SeparationParams(
        reaction_s=p.reaction_s,
        decel_mps2=p.brake_decel_mps2,
        intrusion_m=p.intrusion_m,
        detection_uncertainty_m=p.detection_uncertainty_m,
        robot_uncertainty_m=p.robot_uncertainty_m,
        speed_margin_mps=p.person_speed_margin_mps,
        unknown_speed_mps=p.unknown_person_speed_mps,
        lead_s=p.monitor_lead_s,
    )


def people_limit(
    pose: Pose,
    direction_world: tuple[float, float] | None,
    people: tuple[Person, ...] | list[Person],
    fp: Footprint,
    p: PeopleSettings,
    top_mps: float,
    handover_id: str = "",
    stopped: bool = False,
    also: tuple[tuple[float, float], ...] = (),
    turning: bool = False,
    stopping_s: float = 0.0,
    not_early: Collection[str] = (),
) -> SpeedLimit:
    """The tightest cap that people impose now; `direction_world` the intended travel
    direction (unit, world; None when not translating), `also` other directions the base
    may move in over the next moment (unit: the path's next poses, the heading), the one
    most towards each person counting. `top_mps`: the base's top speed
    (a cap at or above it is no cap). `stopped`: the last cap was a stop (it holds until
    the person is `RESUME_MARGIN_M` further than S_p at rest). `turning`: not
    translating but turning on the spot (the goal's final turn): the footprint's ends
    sweep and the trot sways, so within S_p at rest of a bystander it is a stop too.
    `stopping_s`: how long the base takes to come to rest from its speed now (the stop
    is that much earlier for a person coming towards it, not for those in `not_early`)."""
    if not people:
        return NO_LIMIT
    sep = separation_params(p)
    pts = np.array([[q.x, q.y] for q in people])
    dist = distance_to_footprint(pose, fp, pts)
    best = NO_LIMIT
    for person, d in zip(people, dist.tolist(), strict=True):
        handing = person.id == handover_id
        n = bearing(pose, fp, (person.x, person.y))
        v_h = directed_speed(person.velocity, (-n[0], -n[1]), sep)
        at_rest = protective_distance(0.0, v_h, sep)
        measured = person.velocity is not None and person.id not in not_early
        coming = v_h - sep.speed_margin_mps if measured else 0.0  # their own, no margin
        halt = at_rest + coming * stopping_s
        zone_speed = (p.handover_speed if handing else p.slow_speed) * (1.0 - TRACKING_MARGIN)
        speed = _ramp(zone_speed, d - p.slow_radius_m, top_mps, p.brake_decel_mps2)
        ways = (direction_world, *also) if direction_world else ()
        cos = max((n[0] * u[0] + n[1] * u[1] for u in ways), default=0.0)
        if (direction_world or turning) and not handing and d < halt:
            away = direction_world is not None and (
                n[0] * direction_world[0] + n[1] * direction_world[1] <= AWAY_COS
            )
            held = stopped and coming >= HOLD_COMING_MPS  # a walker still coming: stay
            if held or not away:  # too close to move but away from them: the protective stop
                return SpeedLimit(0.0, "stop", person.id, d, at_rest)
        if cos > 1e-6:  # moving towards them (not along or away): the protective separation
            room = d - (RESUME_MARGIN_M if stopped and not handing else 0.0)
            v_a = allowed_speed(room, v_h, sep)
            if v_a < CREEP_MPS:
                return SpeedLimit(0.0, "stop", person.id, d, at_rest)
            cap = v_a * (1.0 - TRACKING_MARGIN) / cos
            speed = min(speed, cap if cap < top_mps else math.inf)
        if not math.isfinite(speed):
            continue
        limit = SpeedLimit(speed, "handover" if handing else "slow", person.id, d, at_rest)
        if limit.speed < best.speed or (limit.speed == best.speed and d < best.distance_m):
            best = limit
    return best


def within_people(
    cmd: FloatArray,
    pose: Pose,
    people: tuple[Person, ...] | list[Person],
    fp: Footprint,
    p: PeopleSettings,
    top_mps: float,
    handover_id: str = "",
) -> tuple[FloatArray, SpeedLimit]:
    """A command's translation (`cmd` = vx, vy in the base's frame, wz) held to the people
    rules for the way it goes itself, with the rule that acted: for the body guard's
    answers (a walk on unturned, a step clear of a table), which go another way than the
    path the tick's cap was taken along (the changing hall's shift: a step clear of a
    table took the base 0.15 m/s towards a bystander 0.36 m from the footprint, their
    S_p at rest 0.44 m, while the path led away from them). A stop keeps the turn."""
    vx, vy = float(cmd[0]), float(cmd[1])
    speed = math.hypot(vx, vy)
    if speed < 1e-6:
        return cmd, NO_LIMIT
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    way = ((c * vx - s * vy) / speed, (s * vx + c * vy) / speed)
    limit = people_limit(pose, way, people, fp, p, top_mps, handover_id)
    if limit.speed >= speed:
        return cmd, limit
    k = limit.speed / speed
    return np.array([vx * k, vy * k, float(cmd[2])]), limit


#: The base's axes in its own frame, as `base_caps` orders them: ahead, behind, left, right.
AXES = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))


def base_caps(
    pose: Pose,
    people: tuple[Person, ...] | list[Person],
    fp: Footprint,
    p: PeopleSettings,
    top_mps: float,
    stopped: tuple[bool, ...] = (False,) * 4,
) -> tuple[SpeedLimit, ...]:
    """`people_limit` for a translation along each of the base's axes (`AXES`): the caps
    on whatever drives the base other than a goal (the mission's visual approach, its
    back-off, the exploration's steps), which navigation publishes on `nav/status`.
    `stopped`: per axis, whether its last cap was a stop (the same hysteresis)."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    return tuple(
        people_limit(pose, (c * u - s * v, s * u + c * v), people, fp, p, top_mps, "", st)
        for (u, v), st in zip(AXES, stopped, strict=True)
    )


def _ramp(v_cap: float, beyond_m: float, top_mps: float, decel: float) -> float:
    """The speed from which the robot can brake to `v_cap` within `beyond_m` (less the
    lead) at `decel`; inf when that is at or above `top_mps`, the base's top speed."""
    room = beyond_m - BRAKE_LEAD_M
    if room <= 0.0:
        return v_cap
    v = math.sqrt(v_cap * v_cap + 2.0 * decel * room)
    return v if v < top_mps else math.inf


def bearing(pose: Pose, fp: Footprint, xy: tuple[float, float]) -> tuple[float, float]:
    """The unit vector (world) from the footprint's nearest point to a person (the
    robot's heading when they stand on it)."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    dx, dy = xy[0] - pose.x, xy[1] - pose.y
    u, v = c * dx + s * dy, -s * dx + c * dy
    u = min(max(u, -fp.back), fp.front)
    v = min(max(v, -fp.half_width), fp.half_width)
    nx, ny = pose.x + c * u - s * v, pose.y + s * u + c * v
    ex, ey = xy[0] - nx, xy[1] - ny
    norm = math.hypot(ex, ey)
    if norm < 1e-6:
        return c, s
    return ex / norm, ey / norm
