"""The localization service: T_map_odom from the lidar, on the map's static occupancy.

Its own process (not navigation's): perception, the mission and navigation all compose
with it (`common.map_frame.MapFrame`), and the scan matching stays off navigation's
20 Hz loop. A periodic lockstep participant at the lidar's rate
(`time.participants.localization`, 0.1 s, latency 0.1 s), running only when the robot
estimates its base (`wbc.base_state = "estimate"`: the launcher lists it then); with the
truth ablation odom is the map already, and the service idles.

At start it fetches the map's occupancy as of t = 0 (the static layer: the floor-plan
prior, a map file, or the robot's own earlier SLAM grid) and builds the likelihood field
once; the start pose is `localization.start_pose` (the user's, `dume up --start-pose`).
A map with no static layer (`static_source` none: an empty map, exploring), or
`localization.mode = "slam"`, makes it map while it localizes (`slam.Slam`): the same
`localization` samples, and the grid it builds on `slam/occupancy` whenever it changed,
at most every `slam.publish_every_s`, its stamp in the sample of that tick
(`grid_stamp_ns`) so the map adopts it at the same tick in every run. Each tick b: the scan
and `odom` stamped b (waited for), `Localizer.update`, then `localization` stamped b:
T_map_odom, T_map_base with its covariance, the status and the confidence; to rerun, the
scan over the map, the pose and its 2σ ellipse, the status (`LocalizationLogger`).
A scan or odom that does not come is said once and the last correction republished
with status `uncertain`. A restarted localization resumes from the last T_map_odom it
trusted in this run (`resume.Resume`), not from the start pose.
"""

from __future__ import annotations

import contextlib
from typing import TypeVar

import numpy as np

from common import robot
from common.bus import BusError, Latest, WaitTimeout
from common.keys import MAP_OCCUPANCY, as_of
from common.lockstep import PeriodicTicker
from common.map_frame import odom_pose
from common.messages import as_numpy, to_wire
from common.messages.base import NS_PER_S
from common.messages.localization import Localization
from common.messages.semantic_map import OccupancyGrid
from common.messages.sim import LaserScan, Odom
from common.scan import scan_points
from common.service import Service
from services.localization.localizer import Estimate, Localizer
from services.localization.matcher import LikelihoodField
from services.localization.resume import Resume
from services.localization.slam import OCCUPIED, Slam
from services.localization.telemetry import LocalizationLogger

NAME = "localization"
M = TypeVar("M", LaserScan, Odom)
#: Wall seconds a tick waits for its scan and odom.
INPUT_TIMEOUT_S = 30.0


class LocalizationNode:
    def __init__(self, svc: Service) -> None:
        self.svc, cfg = svc, svc.config
        self.s = cfg.localization
        self.active = NAME in cfg.time.participants
        period_s = cfg.time.period_of(NAME, 1.0 / cfg.sim.sensors.lidar.rate_hz)
        bus, keys = svc.bus, svc.keys
        self.scans = bus.latest(keys.scan, LaserScan, history=8)
        self.odom = bus.latest(keys.odom, Odom, history=32)
        self.pub = bus.publisher(keys.localization, Localization, "control", again=True)
        self.ticker = PeriodicTicker(bus, keys, NAME, period_s, svc.stop)
        self.logger = LocalizationLogger(svc.rec)
        self.loc: Localizer | Slam | None = None
        self.grid_pub = bus.publisher(keys.slam_occupancy, OccupancyGrid, "data", again=True)
        self._grid_version = -1
        self._grid_stamp = 0
        self._grid_every_ns = round(self.s.slam.publish_every_s * NS_PER_S)
        self._closures_said = 0
        self.last: Estimate | None = None
        self.resume = Resume.of_run()
        self._said = ""
        self._status = ""

    def _grid(self) -> OccupancyGrid:
        """The map's occupancy as of t = 0, asked for until the map answers."""
        while True:
            try:
                grid = self.svc.bus.query(as_of(MAP_OCCUPANCY, 0), None, OccupancyGrid, 5.0)
                break
            except BusError as exc:
                self.svc.log.info("waiting for the map's occupancy: %s", exc)
                if self.svc.stop.wait(0.5):
                    raise
        return grid

    def _field(self, grid: OccupancyGrid) -> LikelihoodField:
        occupied = np.asarray(as_numpy(grid.cells)) == 100
        self.logger.map(occupied, grid.resolution_m, grid.origin_xy)
        self.svc.log.info(
            "matching on the map's %s occupancy: %d occupied cells of %.2f m",
            grid.static_source, int(occupied.sum()), grid.resolution_m,
        )  # fmt: skip
        origin = (float(grid.origin_xy[0]), float(grid.origin_xy[1]))
        return LikelihoodField.of_grid(occupied, grid.resolution_m, origin)

    def run(self) -> None:
        svc = self.svc
        if not self.active:
            svc.log.info("not a lockstep participant (the truth ablation: odom is the map)")
            svc.ready()
            svc.stop.wait()
            return
        start = self.s.start_pose
        if start is None:
            svc.log.warning("no localization.start_pose: the robot is taken to start at 0 0 0")
            start = (0.0, 0.0, 0.0)
        grid = self._grid()
        if self.s.mode == "slam" or (self.s.mode == "auto" and grid.static_source == "none"):
            svc.log.info("mapping while localizing (SLAM): the map has no static layer")
            T = robot.LIDAR_MOUNT.T_parent_lidar  # the lidar in the base (no scan yet at t = 0)
            self.loc = Slam(self.s, self.s.slam, start, (float(T[0, 3]), float(T[1, 3])))
        else:
            self.loc = Localizer(self.s, self._field(grid), start)
        if (held := self.resume.load()) is not None:
            self.loc.map_odom = held.map_odom  # odom lived on: it is still in the map there
            svc.log.warning(
                "restarted: resuming from the T_map_odom trusted at t=%.2f s, not the start "
                "pose", held.stamp_ns / NS_PER_S,
            )  # fmt: skip
        svc.ready()
        self.ticker.run(self.tick)

    def tick(self, b: int) -> None:
        assert self.loc is not None
        scan, odom = self._input(self.scans, b, "scan"), self._input(self.odom, b, "odom")
        if scan is None or odom is None:
            status = "uncertain" if self.loc.status == "ok" else self.loc.status
            self._publish(b, self.last, status, f"no {'scan' if scan is None else 'odom'}")
            return
        pts = scan_points(
            np.asarray(as_numpy(scan.ranges), dtype=float),
            scan.angle_min,
            scan.angle_increment,
            np.asarray(scan.T_base_lidar).reshape(4, 4),
            self.s.beam_stride,
        )
        if isinstance(self.loc, Slam):
            full = scan_points(
                np.asarray(as_numpy(scan.ranges), dtype=float), scan.angle_min,
                scan.angle_increment, np.asarray(scan.T_base_lidar).reshape(4, 4),
            )  # fmt: skip
            est = self.loc.update(full, odom_pose(odom), self.s.beam_stride)
            self._publish_grid(b, self.loc)
        else:
            est = self.loc.update(pts, odom_pose(odom))
        self.last = est
        if est.status == "ok":
            self.resume.save(b, (est.map_odom[0], est.map_odom[1], est.map_odom[2]))
        self._publish(b, est, est.status, est.refused)
        self.logger.log(b, est, pts)

    def _publish_grid(self, b: int, slam: Slam) -> None:
        """The SLAM grid on `slam/occupancy` when it changed and `publish_every_s` passed."""
        g = slam.grid
        if g.version == self._grid_version or b - self._grid_stamp < self._grid_every_ns:
            return
        cells = g.cells()
        self.grid_pub.put(
            OccupancyGrid(
                stamp_ns=b, resolution_m=g.resolution_m, origin_xy=g.origin_xy,
                cells=to_wire(cells), static_source="slam",
            )
        )  # fmt: skip
        self._grid_version, self._grid_stamp = g.version, b
        self.logger.map(cells == OCCUPIED, g.resolution_m, g.origin_xy)
        self.logger.slam(
            b,
            np.array([kf.pose for kf in slam.keyframes], float).reshape(-1, 3),
            [(c.older, c.newer) for c in slam.closures],
        )
        if len(slam.closures) > self._closures_said:
            for c in slam.closures[self._closures_said :]:
                self.svc.log.info(
                    "t=%.1f s: loop closed, keyframe %d on %d (%.0f%% inliers), moved %.3f m",
                    b / NS_PER_S, c.newer, c.older, 100 * c.inliers, c.correction_m,
                )  # fmt: skip
            self._closures_said = len(slam.closures)

    def _input(self, latest: Latest[M], b: int, what: str) -> M | None:
        with contextlib.suppress(WaitTimeout):
            latest.wait_stamp(b, INPUT_TIMEOUT_S)
        msg = latest.at(b)
        if msg is None or msg.stamp_ns != b:
            why = f"no {what} stamped {b / NS_PER_S:.2f} s"
            if why != self._said:
                self.svc.log.warning("%s", why)
                self._said = why
            return None
        return msg

    def _publish(self, b: int, est: Estimate | None, status: str, reason: str) -> None:
        if est is None:  # no scan matched yet: odom starts at the start pose, in the map
            assert self.loc is not None
            cov = tuple(float(x) for x in self.loc.covariance.ravel())
            mo, mb = (0.0, 0.0, 0.0), self.loc.start
        else:
            cov = tuple(float(x) for x in est.covariance.ravel())
            mo, mb = est.map_odom, est.map_base
        self.pub.put(
            Localization(
                stamp_ns=b,
                map_odom=(mo[0], mo[1], mo[2]),
                map_base=(mb[0], mb[1], mb[2]),
                covariance=cov,
                status=status,  # type: ignore[arg-type]
                confidence=min(1.0, max(0.0, est.confidence if est is not None else 0.0)),
                reason=reason,
                grid_stamp_ns=self._grid_stamp,
            )
        )
        if status != self._status:
            self.svc.log.info("t=%.2f s: %s %s", b / NS_PER_S, status, reason)
            self._status = status


def main(svc: Service) -> None:
    LocalizationNode(svc).run()
