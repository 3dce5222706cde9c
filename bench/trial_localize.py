"""`dume trial localize`: the localizer (`services.localization`) on the robot's own
scans and odometry, while it walks the `random` trial, against the sim's truth.

The stack is the trials' (router + sim + wbc, lockstep) with the robot on its own
odometry (`wbc.base_state = "estimate"`) and people walking their routes
(`sim.walking_people`). The trial plays the map's part: the floor plan's occupancy (the
prior `dume/map/occupancy` serves; read here from the world's description, truth-side
set-up) becomes the likelihood field. The localizer is told the start pose off by
`start_off` (x m, y m, yaw rad in the robot's frame; the issue's 0.5 m and 10° with
`--set`-free option `off`), and every `scan` is matched with `odom` at its stamp.

`dume trial slam` walks the same with no map at all: SLAM (`services.localization.slam`)
maps while it localizes, told the start pose exactly (the map's frame), and the figures
add its grid's agreement with the floor plan over what it saw (`map_agreement`), its
keyframes and loop closures.

Figures: the map-frame position and heading errors of T_map_base against the truth
(p50, p95, max; the first second, while the start is sought, apart), the statuses, the
refusals, the match's wall time per scan, and the odometry's own drift for comparison.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from bench import map_agreement
from bench.trial_driver import Driver, Script
from bench.trial_random import random_walk
from common import robot
from common.config import LocalizationSettings
from common.geometry import wrap_angle
from common.keys import WORLD_DESCRIPTION
from common.map_frame import odom_pose
from common.messages import as_numpy
from common.messages.sim import LaserScan, Odom, StateTruth
from common.messages.world import WorldDescription
from common.scan import scan_points
from services.localization.localizer import Localizer, compose
from services.localization.matcher import LikelihoodField
from services.localization.slam import Slam

Figures = dict[str, Any]
SEEKING_S = 1.0  # the first scans, while an off start pose is sought, are counted apart


def localize(
    d: Driver,
    out: Figures,
    seconds: float = 120.0,
    start_off: tuple[float, float, float] = (0.0, 0.0, 0.0),
    slam: bool = False,
) -> Script:
    world = d.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10.0)
    grid = world.occupancy
    occupied = np.asarray(as_numpy(grid.cells)) > 0
    origin = (float(grid.origin[0]), float(grid.origin[1]))
    field = LikelihoodField.of_grid(occupied, grid.resolution, origin)
    s = LocalizationSettings()
    start = world.robot_start
    given = compose((start.x, start.y, start.yaw), start_off)
    loc: Localizer | Slam = Localizer(s, field, given)
    if slam:
        T = robot.LIDAR_MOUNT.T_parent_lidar
        loc = Slam(s, s.slam, given, (float(T[0, 3]), float(T[1, 3])))
    scans = d.bus.fifo(d.keys.scan, LaserScan, maxlen=10_000)
    odoms = d.bus.latest(d.keys.odom, Odom, history=256)
    truths = d.bus.latest(d.keys.state_truth, StateTruth, history=2048)
    errors: list[tuple[float, float, float]] = []  # (t, m, rad)
    statuses: dict[str, int] = {}
    refusals: dict[str, int] = {}
    wall: list[float] = []
    walk = random_walk(d, out, seconds)
    try:
        for _ in walk:
            for scan in scans.drain():
                odom, truth = odoms.at(scan.stamp_ns), truths.at(scan.stamp_ns)
                if odom is None or truth is None or odom.stamp_ns != scan.stamp_ns:
                    refusals["no odom at the scan's stamp"] = (
                        refusals.get("no odom at the scan's stamp", 0) + 1
                    )
                    continue
                ranges = np.asarray(as_numpy(scan.ranges), dtype=float)
                pts = scan_points(
                    ranges,
                    scan.angle_min,
                    scan.angle_increment,
                    np.asarray(scan.T_base_lidar).reshape(4, 4),
                    1 if slam else s.beam_stride,
                )
                t0 = time.perf_counter()
                if isinstance(loc, Slam):
                    est = loc.update(pts, odom_pose(odom), s.beam_stride)
                else:
                    est = loc.update(pts, odom_pose(odom))
                wall.append(time.perf_counter() - t0)
                statuses[est.status] = statuses.get(est.status, 0) + 1
                if est.refused:
                    key = est.refused.split(" (")[0].split(" of the beams")[0]
                    key = "too few beams on the map" if "%" in key else "jumped from the odometry"
                    refusals[key] = refusals.get(key, 0) + 1
                tx, ty, tyaw = odom_pose(truth)
                e_m = math.hypot(est.map_base[0] - tx, est.map_base[1] - ty)
                e_rad = abs(wrap_angle(est.map_base[2] - tyaw))
                errors.append((scan.stamp_ns / 1e9, e_m, e_rad))
            yield
    finally:
        scans.undeclare()
        odoms.undeclare()
        truths.undeclare()
    out.update(_figures(errors, statuses, refusals, wall, start_off))
    if isinstance(loc, Slam):
        g = loc.grid
        plan = map_agreement.truth_on(world, g.shape, g.resolution_m, g.origin_xy)
        out["slam"] = {
            "keyframes": len(loc.keyframes),
            "closures": len(loc.closures),
            "closure_corrections_m": [round(c.correction_m, 3) for c in loc.closures],
            "agreement": map_agreement.agreement(g.cells(), plan),
            "agreement_at_lidar_height": map_agreement.agreement(
                g.cells(), map_agreement.truth_on(world, g.shape, g.resolution_m, g.origin_xy, 0.5)
            ),
        }


def _figures(
    errors: list[tuple[float, float, float]],
    statuses: dict[str, int],
    refusals: dict[str, int],
    wall: list[float],
    start_off: tuple[float, float, float],
) -> Figures:
    if not errors:
        return {"localization": {"scans": 0}}
    t0 = errors[0][0]
    settled = [e for e in errors if e[0] - t0 >= SEEKING_S]
    m = np.array([e[1] for e in settled]) if settled else np.zeros(1)
    a = np.degrees([e[2] for e in settled]) if settled else np.zeros(1)
    first = errors[0]
    return {
        "localization": {
            "scans": len(errors),
            "start_off": [round(x, 3) for x in start_off],
            "first_scan_error_m": round(first[1], 3),
            "first_scan_error_deg": round(math.degrees(first[2]), 2),
            "position_error_m": {
                "p50": round(float(np.percentile(m, 50)), 4),
                "p95": round(float(np.percentile(m, 95)), 4),
                "max": round(float(m.max()), 4),
            },
            "heading_error_deg": {
                "p50": round(float(np.percentile(a, 50)), 3),
                "p95": round(float(np.percentile(a, 95)), 3),
                "max": round(float(a.max()), 3),
            },
            "statuses": dict(sorted(statuses.items())),
            "refusals": dict(sorted(refusals.items())),
            "match_ms": {
                "p50": round(1e3 * float(np.percentile(wall, 50)), 2),
                "p95": round(1e3 * float(np.percentile(wall, 95)), 2),
            },
        }
    }
