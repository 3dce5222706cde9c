"""The robot's separation from people judged from the simulator's truth, as the speed and
separation monitor's own rule has it (`services.navigation.separation`).

`SeparationWatch.add(base, people)` takes one moment: the base's truth (`state_truth`)
and every person's (`world/people`: floor point and velocity). Per person: the
separation d (the stowed footprint's distance to their floor point), the robot's speed
towards them and theirs towards it, both true (so no margin on a person's estimated
speed: `truth_separation`); a violation is a moment when the robot moved towards them
(faster than `AT_REST_MPS`) with d below the protective separation S_p of both speeds. A
person walking into a robot at rest is none (the standard's protective stop). Kept: the
violations, the least margin d − S_p while moving towards someone, the least separation,
who it was and the robot's speed then, and at every moment the tightest person's d and
S_p (`series`, the shift's plots). `dume trial person|crossing` and `dume eval --shift`
use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.config import Overrides, load_config
from common.messages.sim import PeopleTruth, StateTruth
from common.robot import Footprint
from services.navigation.grid import Pose, distance_to_footprint
from services.navigation.people import bearing, separation_params
from services.navigation.separation import SeparationParams, directed_speed, protective_distance

#: m/s: a robot slower than this towards a person is at rest (the trot's sway).
AT_REST_MPS = 0.05
#: Violations kept whole for the report (the count goes on).
KEEP = 20


@dataclass
class SeparationWatch:
    """The robot's separation from every person over a shift (truth samples: the base,
    `state_truth`; the people, `world/people`)."""

    sep: SeparationParams
    fp: Footprint = field(default_factory=Footprint.stowed)
    samples: int = 0
    violations: int = 0
    least_margin_m: float = math.inf
    closest_m: float = math.inf
    speed_at_closest_mps: float = math.nan
    closest_person: str = ""
    #: The first `KEEP` violations, each as it was: when, who, d, S_p, the two speeds,
    #: where the robot (x, y, yaw) and the person stood and the person's velocity.
    kept: list[dict[str, Any]] = field(default_factory=list)
    #: Every moment's tightest person (least d − S_p): (t s, d m, S_p m, base speed m/s),
    #: S_p of the robot's speed towards them (0 moving away) and theirs (the plots).
    series: list[tuple[float, float, float, float]] = field(default_factory=list)

    def add(self, base: StateTruth, people: PeopleTruth) -> None:
        """One moment: the base and every person, as of one stamp."""
        pose = Pose.of_odom(base)
        v = base.base_linear_velocity_in_world[:2]
        self.samples += 1
        tightest: tuple[float, float, float] | None = None  # (d − S_p, d, S_p)
        for p in people.people:
            xy = (p.position[0], p.position[1])
            d = float(distance_to_footprint(pose, self.fp, np.array([xy]))[0])
            n = bearing(pose, self.fp, xy)
            v_r = v[0] * n[0] + v[1] * n[1]
            v_h = directed_speed(p.velocity, (-n[0], -n[1]), self.sep)
            if d < self.closest_m:
                self.closest_m, self.closest_person = d, p.id
                self.speed_at_closest_mps = math.hypot(*v)
            s_now = protective_distance(v_r if v_r > AT_REST_MPS else 0.0, v_h, self.sep)
            if tightest is None or d - s_now < tightest[0]:
                tightest = (d - s_now, d, s_now)
            if v_r > AT_REST_MPS:
                s_p = protective_distance(v_r, v_h, self.sep)
                margin = d - s_p
                self.least_margin_m = min(self.least_margin_m, margin)
                if margin < 0.0:
                    self.violations += 1
                    if len(self.kept) < KEEP:
                        self.kept.append({
                            "t_s": round(base.stamp_ns / 1e9, 2), "person": p.id,
                            "d_m": round(d, 3), "s_p_m": round(s_p, 3),
                            "v_robot_mps": round(v_r, 3), "v_person_mps": round(v_h, 3),
                            "robot_xy_yaw": [round(pose.x, 2), round(pose.y, 2),
                                             round(pose.yaw, 2)],
                            "person_xy": [round(xy[0], 2), round(xy[1], 2)],
                            "person_velocity": [round(c, 2) for c in p.velocity],
                        })  # fmt: skip
        if tightest is not None:
            self.series.append((base.stamp_ns / 1e9, tightest[1], tightest[2], math.hypot(*v)))

    def figures(self) -> dict[str, Any]:
        return {
            "samples": self.samples,
            "violations": self.violations,
            "least_margin_m": round(self.least_margin_m, 3),
            "closest_m": round(self.closest_m, 3),
            "closest_person": self.closest_person,
            "speed_at_closest_mps": round(self.speed_at_closest_mps, 3),
            "violations_kept": list(self.kept),
        }


def truth_separation(overrides: Overrides | None = None) -> SeparationParams:
    """The monitor's own rule, for the truth: its terms, no margin on a known speed and
    no lead (the standard's S_p of the moment)."""
    sep = separation_params(load_config(overrides or {}).navigation.people)
    return SeparationParams(**{**sep.__dict__, "speed_margin_mps": 0.0, "lead_s": 0.0})
