"""T_map_odom from the lidar's scans and the robot's odometry: the map correction every
consumer composes, T_map_base = T_map_odom · T_odom_base (REP 105's frames).

`Localizer.update(points, odom_pose)` per scan (points in the base's floor plane,
`common.scan.scan_points`; `odom_pose` the odometry's (x, y, yaw) at the scan's stamp):

1. predict: the base in the map is the last correction applied to the odometry;
2. seed: the prediction itself, or, before the first match and after being lost, the
   best pose of a correlative search within ± `search_m`, ± `search_rad` of it (a start
   pose off by decimetres, a robot that slipped);
3. match (`matcher.refine`); taken when at least `min_inliers` of the beams end within
   `inlier_m` of the map and, when tracking, within `gate_m` / `gate_rad` of the
   prediction (a match that jumps is a wrong one);
4. taken: T_map_odom = match ⊖ odom, the covariance the match's; refused: T_map_odom is
   kept, the covariance grows by `growth_per_m` per metre the odometry travelled, and
   after `lost_after` refusals in a row the status is `lost`.

Status: `initialising` (no match yet), `ok`, `uncertain` (the last scans were refused),
`lost`. The confidence is the last match's inlier share. All (x, y, yaw) in SE(2); pure,
no transport: a node feeds it (`tests/unit/test_localization_matcher.py`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from common.config import LocalizationSettings
from common.geometry import FloatArray
from services.localization.matcher import LikelihoodField, Match, Pose2, refine, search

Status = Literal["initialising", "ok", "uncertain", "lost"]


def compose(a: Pose2, b: Pose2) -> Pose2:
    """a ⊕ b in SE(2)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2]))


def inverse(a: Pose2) -> Pose2:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-(c * a[0] + s * a[1]), s * a[0] - c * a[1], -a[2])


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


@dataclass
class Estimate:
    """The localizer's answer after a scan: T_map_odom and T_map_base as (x, y, yaw), the
    covariance (3, 3) of T_map_base, the status, the last match's inlier share, and why
    the last scan was refused ("" when taken)."""

    map_odom: Pose2
    map_base: Pose2
    covariance: FloatArray
    status: Status
    confidence: float
    refused: str = ""
    match: Match | None = field(default=None, repr=False)


class Localizer:
    """See the module docstring. `start` is the base's pose in the map at start-up."""

    def __init__(self, s: LocalizationSettings, field_: LikelihoodField, start: Pose2) -> None:
        self.s, self.field = s, field_
        self.start = start
        self.map_odom: Pose2 | None = None
        self.covariance = np.diag([0.25, 0.25, 0.05])  # the start pose as a person gives it
        self.status: Status = "initialising"
        self.refusals = 0
        self.confidence = 0.0
        self._last_odom: Pose2 | None = None

    def update(self, points: FloatArray, odom: Pose2) -> Estimate:
        s = self.s
        if self.map_odom is None:  # the robot stands at the start pose it was given
            self.map_odom = compose(self.start, inverse(odom))
        if self._last_odom is not None:
            moved = math.hypot(odom[0] - self._last_odom[0], odom[1] - self._last_odom[1])
        else:
            moved = 0.0
        self._last_odom = odom
        predicted = compose(self.map_odom, odom)
        searching = self.status in ("initialising", "lost")
        seed = predicted
        if searching:
            seed = search(
                self.field,
                points,
                predicted,
                window_m=s.search_m,
                window_rad=s.search_rad,
                inlier_m=s.inlier_m,
            )
        m = refine(self.field, points, seed, huber_m=s.huber_m, inlier_m=s.inlier_m)
        why = self._refusal(m, predicted, searching)
        if not why:
            self.map_odom = compose(m.pose, inverse(odom))
            self.covariance = m.covariance
            self.status, self.refusals, self.confidence = "ok", 0, m.inliers
            return Estimate(self.map_odom, m.pose, m.covariance, "ok", m.inliers, "", m)
        self.refusals += 1
        self.covariance = self.covariance + np.diag([1.0, 1.0, 1.0]) * s.growth_per_m * moved
        if self.status != "initialising":
            self.status = "lost" if self.refusals >= s.lost_after else "uncertain"
        elif self.refusals >= s.lost_after:
            self.status = "lost"
        return Estimate(self.map_odom, predicted, self.covariance, self.status, m.inliers, why, m)

    def _refusal(self, m: Match, predicted: Pose2, searching: bool) -> str:
        s = self.s
        if m.inliers < s.min_inliers:
            return f"{m.inliers:.0%} of the beams on the map (< {s.min_inliers:.0%})"
        if searching:
            return ""
        dxy = math.hypot(m.pose[0] - predicted[0], m.pose[1] - predicted[1])
        dyaw = abs(_wrap(m.pose[2] - predicted[2]))
        if dxy > s.gate_m or dyaw > s.gate_rad:
            return f"the match jumped {dxy:.2f} m, {math.degrees(dyaw):.1f}° from the odometry"
        return ""
