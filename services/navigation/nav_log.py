"""What navigation tells a person, in the log and in rerun, on the sim-time timeline.

Logged on change: the goal's state and reason, the speed rule acting (slow, handover,
stop — with the person and their distance), the body guard's answer to a refused command
(walking on unturned, turning only, standing), recoveries; at 2 Hz while the robot aligns
its final heading (within 0.3 m of the goal): the yaw error, the commanded and the
measured ωz. To rerun: every new plan (`world/nav/plan`), the follower's command and the
tick's time at 5 Hz (`plots/nav/…`), with the speed rule's person: their separation, the
protective separation at rest and the cap (`plots/nav/separation/…`), the lidar's bodies
the map lacks and its tracks (`world/nav/scan_people`, at every scan), and the costmap at
1 Hz as a textured quad on the floor of the 3D world (`world/nav/costmap`: lethal red,
costs orange).
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np
import rerun as rr

from common.geometry import FloatArray
from common.recording import is_recording, stamp
from services.navigation.body_guard import what_is_near
from services.navigation.costmap import Costmap, Person
from services.navigation.grid import Pose
from services.navigation.scan_people import Body

PLAN_Z = 0.05
#: The costmap's height in the 3D view, m: just above the floor, under the map's cells.
COSTMAP_Z = 0.005
#: The lidar's plane, m (about: the trunk's height varies with the gait).
SCAN_Z = 0.5


def costmap_mesh(cm: Costmap) -> rr.Mesh3D:
    """The costmap as a textured quad on the floor: lethal red, costs orange by their
    value, free cells clear (one RGBA texel per cell, row iy at y = origin + iy·res)."""
    cost = np.asarray(cm.cost, dtype=np.float32)
    rgba = np.zeros((*cost.shape, 4), dtype=np.uint8)
    lethal = cost < 0
    rgba[lethal] = (220, 40, 40, 170)
    costly = ~lethal & (cost > 0)
    rgba[costly, 0], rgba[costly, 1] = 255, 160
    rgba[costly, 3] = np.clip(40 + 120 * cost[costly], 0, 160).astype(np.uint8)
    g = cm.grid
    (x0, y0), ny, nx = g.origin, *cost.shape
    x1, y1 = x0 + nx * g.resolution, y0 + ny * g.resolution
    return rr.Mesh3D(
        vertex_positions=[[x0, y0, COSTMAP_Z], [x1, y0, COSTMAP_Z], [x1, y1, COSTMAP_Z],
                          [x0, y1, COSTMAP_Z]],
        triangle_indices=[[0, 1, 2], [0, 2, 3]],
        vertex_texcoords=[[0, 0], [1, 0], [1, 1], [0, 1]],
        albedo_texture=rgba,
    )  # fmt: skip


class NavLogger:
    def __init__(self, rec: rr.RecordingStream, log: logging.Logger) -> None:
        self.rec, self.log = rec, log
        self.on = is_recording(rec)
        self.rule = ""
        self.state = ""
        self.recovery = ""
        self.guarded = ""
        self.last_costmap = -(10**18)
        self.last_align = -(10**18)
        self.tracks: set[str] = set()
        #: Whether the last scan held obstacles larger than a person (said on a change).
        self.scan_obstacles = False

    def tick(
        self,
        b: int,
        pose: Pose,
        nav: Any,
        out: Any,
        cm: Costmap,
        tick_ms: float,
        wz_measured: float = 0.0,
    ) -> None:
        t = b / 1e9
        goal_id = nav.goal.goal_id if nav.goal else ""
        if out.state != self.state:
            self.state = out.state
            level = logging.WARNING if out.state == "failed" else logging.INFO
            self.log.log(
                level, "t=%.2f s goal %s %s %s %s", t, goal_id, out.state, out.reason, out.detail
            )
        rule = out.limit.rule
        if rule != self.rule:
            if rule:
                who = next((q for q in cm.people if q.id == out.limit.person_id), None)
                self.log.info(
                    "t=%.2f s speed rule %s: %s%s at %.2f m from the footprint (protective "
                    "separation at rest %.2f m), cap %.2f m/s",
                    t, rule, out.limit.person_id,
                    f" at ({who.x:.2f}, {who.y:.2f})" if who is not None else "",
                    out.limit.distance_m, out.limit.protective_m, out.limit.speed,
                )  # fmt: skip
            else:
                self.log.info("t=%.2f s speed rule %s released", t, self.rule)
            self.rule = rule
        if out.guarded != self.guarded:
            if out.guarded:
                near = what_is_near(cm.solid, cm.grid.known_occupied, cm.grid, nav.fp, pose)
                self.log.info("t=%.2f s body guard: %s (the command would sweep the body onto "
                              "an obstacle; %s)", t, out.guarded, near)  # fmt: skip
            else:
                self.log.info("t=%.2f s body guard released", t)
            self.guarded = out.guarded
        if out.recovery != self.recovery:
            if out.recovery:
                self.log.warning("t=%.2f s goal %s recovery: %s", t, goal_id, out.recovery)
            self.recovery = out.recovery
        self._align(b, pose, nav, out, wz_measured)
        if not self.on:
            return
        stamp(self.rec, b)
        if out.new_plan is not None:
            p = out.new_plan.poses
            pts = np.column_stack([p[:, 0], p[:, 1], np.full(len(p), PLAN_Z)])
            self.rec.log("world/nav/plan", rr.LineStrips3D([pts], colors=[(40, 200, 80)]))
        if b % 200_000_000 == 0:
            self.rec.log("plots/nav/cmd/vx", rr.Scalars(float(out.cmd[0])))
            self.rec.log("plots/nav/cmd/vy", rr.Scalars(float(out.cmd[1])))
            self.rec.log("plots/nav/cmd/wz", rr.Scalars(float(out.cmd[2])))
            self.rec.log("plots/nav/tick_ms", rr.Scalars(tick_ms))
            lim = out.limit
            if lim.person_id:  # the person the speed rule acts for: separation and S_p
                self.rec.log("plots/nav/separation/distance_m", rr.Scalars(lim.distance_m))
                self.rec.log("plots/nav/separation/protective_m", rr.Scalars(lim.protective_m))
                if math.isfinite(lim.speed):
                    self.rec.log("plots/nav/separation/cap_mps", rr.Scalars(lim.speed))
        if b - self.last_costmap >= 1_000_000_000:
            self.last_costmap = b
            self.rec.log("world/nav/costmap", costmap_mesh(cm))

    def scan(self, b: int, bodies: list[Body], tracks: list[Person], obstacles: FloatArray) -> None:
        """The lidar's bodies (their extent as a ring), its tracks (id, velocity) and the
        returns of obstacles larger than a person (`obstacles`, (k, 2) map); a new track
        is said once, and when larger obstacles come into or leave the scan."""
        if bool(len(obstacles)) != self.scan_obstacles:
            self.scan_obstacles = bool(len(obstacles))
            if self.scan_obstacles:
                lo, hi = obstacles.min(axis=0), obstacles.max(axis=0)
                self.log.info(
                    "t=%.2f s lidar: an obstacle the map lacks, larger than a person, %d "
                    "returns in x %.2f..%.2f, y %.2f..%.2f: kept until the beams pass through",
                    b / 1e9, len(obstacles), lo[0], hi[0], lo[1], hi[1],
                )  # fmt: skip
            else:
                self.log.info("t=%.2f s lidar: no obstacle larger than a person now", b / 1e9)
        ids = {q.id for q in tracks}
        for q in tracks:
            if q.id not in self.tracks:
                self.log.info(
                    "t=%.2f s lidar: %s at (%.2f, %.2f), a body the map lacks", b / 1e9, q.id,
                    q.x, q.y,
                )  # fmt: skip
        self.tracks = ids
        if not self.on:
            return
        stamp(self.rec, b)
        self.rec.log(
            "world/nav/scan_people/bodies",
            rr.Points3D(
                [[q.x, q.y, SCAN_Z] for q in bodies],
                radii=[q.extent_m / 2 for q in bodies],
                colors=[(250, 200, 40)],
            ),
        )
        self.rec.log(
            "world/nav/scan_people/obstacles",
            rr.Points3D(
                [[x, y, SCAN_Z] for x, y in obstacles.tolist()], radii=0.02, colors=[(200, 60, 200)]
            ),
        )
        self.rec.log(
            "world/nav/scan_people/tracks",
            rr.Arrows3D(
                origins=[[q.x, q.y, SCAN_Z] for q in tracks],
                vectors=[[*(q.velocity or (0.0, 0.0)), 0.0] for q in tracks],
                labels=[q.id for q in tracks],
                colors=[(250, 120, 40)],
            ),
        )

    def _align(self, b: int, pose: Pose, nav: Any, out: Any, wz_measured: float) -> None:
        if out.state != "active" or nav.goal is None or out.remaining_m > 0.3:
            return
        if b - self.last_align < 500_000_000:
            return
        self.last_align = b
        g = nav.goal.pose
        yaw_err = math.remainder(g.yaw - pose.yaw, math.tau)
        self.log.info(
            "t=%.2f s aligning: %.3f m, yaw error %+.3f rad; cmd (%+.2f, %+.2f, %+.3f), "
            "measured wz %+.3f rad/s",
            b / 1e9, math.hypot(g.x - pose.x, g.y - pose.y), yaw_err, *out.cmd, wz_measured,
        )  # fmt: skip
