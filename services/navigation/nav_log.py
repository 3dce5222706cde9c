"""What navigation tells a person, in the log and in rerun, on the sim-time timeline.

Logged on change: the goal's state and reason, the speed rule acting (slow, handover,
stop — with the person and their distance), recoveries. To rerun: every new plan
(`nav/plan`), the lookahead point and the follower's command at 5 Hz, and the costmap
as an image at 1 Hz (lethal 255, costs scaled to 0–200).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import rerun as rr

from common.recording import is_recording, stamp
from services.navigation.costmap import Costmap
from services.navigation.grid import Pose

PLAN_Z = 0.05


class NavLogger:
    def __init__(self, rec: rr.RecordingStream, log: logging.Logger) -> None:
        self.rec, self.log = rec, log
        self.on = is_recording(rec)
        self.rule = ""
        self.state = ""
        self.recovery = ""
        self.last_costmap = -(10**18)

    def tick(self, b: int, pose: Pose, nav: Any, out: Any, cm: Costmap, tick_ms: float) -> None:
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
                self.log.info(
                    "t=%.2f s speed rule %s: %s at %.2f m from the footprint, cap %.2f m/s",
                    t, rule, out.limit.person_id, out.limit.distance_m, out.limit.speed,
                )  # fmt: skip
            else:
                self.log.info("t=%.2f s speed rule %s released", t, self.rule)
            self.rule = rule
        if out.recovery != self.recovery:
            if out.recovery:
                self.log.warning("t=%.2f s goal %s recovery: %s", t, goal_id, out.recovery)
            self.recovery = out.recovery
        if not self.on:
            return
        stamp(self.rec, b)
        if out.new_plan is not None:
            p = out.new_plan.poses
            pts = np.column_stack([p[:, 0], p[:, 1], np.full(len(p), PLAN_Z)])
            self.rec.log("nav/plan", rr.LineStrips3D([pts], colors=[(40, 200, 80)]))
        if b % 200_000_000 == 0:
            self.rec.log("nav/cmd/vx", rr.Scalars(float(out.cmd[0])))
            self.rec.log("nav/cmd/vy", rr.Scalars(float(out.cmd[1])))
            self.rec.log("nav/cmd/wz", rr.Scalars(float(out.cmd[2])))
            self.rec.log("nav/tick_ms", rr.Scalars(tick_ms))
        if b - self.last_costmap >= 1_000_000_000:
            self.last_costmap = b
            img = np.where(cm.cost < 0, 255, np.clip(cm.cost * 200, 0, 200)).astype(np.uint8)
            self.rec.log("nav/costmap", rr.Image(img[::-1]))
