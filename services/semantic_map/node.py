"""The semantic map service: a lockstep participant that fuses detections into the map,
persists every tick's changes before acknowledging it and serves the map; it drives
nothing (the mapping patrol is the mission's). This module only wires the parts to the
bus and runs the tick.

Per tick b (period and latency from `time.participants.semantic_map`): wait for
perception's detections and the mission's patrol status due by b (`UpstreamGate`); under
the map's lock, fuse the frames `intake` releases (each fused camera's stamped at or
before b − perception's latency; `fusion_log`): the head camera, and `patrol_cameras`
too while the mission's patrol status due by b says it holds the arm in `look`
(`intake.patrol_holds_look`); while the map has no static layer but the robot's own,
adopt the SLAM grid the localization's sample due by b names (`grid_stamp_ns`, waited
for on `slam/occupancy`: every run adopts it at the same tick); commit the tick in one
SQLite transaction (`commit`), keep the map's view after b (`views`); then ack b.
Queryables run on their own threads: one with `at=<t>` (a lockstep consumer's tick) is
answered from the view of the map's last tick that takes effect by t, so every run of a
seed answers it alike; one without, from the map now (`queries`; export and import:
`exchange`; the floor plan's supports: `supports`).
"""

from __future__ import annotations

import logging
import threading
from functools import partial

import numpy as np

from common.bus import RequestError, WaitTimeout
from common.config import resolve
from common.keys import (
    MAP_ARTIFACTS,
    MAP_ARTIFACTS_ONE,
    MAP_EXPORT,
    MAP_IMPORT,
    MAP_OCCUPANCY,
    MAP_PEOPLE,
    MAP_PEOPLE_ONE,
    MAP_SUPPORTS,
)
from common.lockstep import PeriodicTicker, UpstreamGate
from common.messages import PayloadError, as_numpy
from common.messages.base import NS_PER_S
from common.messages.localization import Localization
from common.messages.mission import PatrolStatus
from common.messages.perception import Detections
from common.messages.semantic_map import MapFile, MapSummary, OccupancyGrid, SupportListing
from common.messages.sim import CameraFrame
from common.recording import stamp
from common.service import Service
from services.semantic_map import queries
from services.semantic_map.commit import TickCommitter
from services.semantic_map.exchange import check_import, export_map, import_map
from services.semantic_map.fusion_log import FusionLog
from services.semantic_map.intake import (
    DetectionIntake,
    fused_cameras,
    patrol_holds_look,
    perception_due,
)
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.people_trace import PeopleTrace
from services.semantic_map.rerun_log import MapLogger
from services.semantic_map.startup import MapSiteError, open_map, world_description
from services.semantic_map.store import MapStore, database_path, remove_database
from services.semantic_map.supports import FloorPlanSupports
from services.semantic_map.views import ViewHistory

NAME = "semantic_map"
log = logging.getLogger(f"dume.{NAME}")


class MapNode:
    def __init__(self, svc: Service) -> None:
        self.svc = svc
        self.cfg = svc.config.semantic_map
        self.period_ns = svc.config.time.period_ns_of(NAME, 0.1)
        self.site = svc.config.map_site()
        path = database_path(self.cfg, site=self.site)
        if self.cfg.reset:
            remove_database(path)
        self.store = MapStore(path)
        self.lock = threading.RLock()
        self.smap: SemanticMap
        world = partial(world_description, svc.bus, svc.stop)
        self.smap, how = open_map(self.cfg, self.store, world, self.site)
        log.info("%s", how)
        self.trace: PeopleTrace | None = None
        if self.cfg.people_trace:
            self.trace = PeopleTrace(resolve(self.cfg.people_trace))
            self.trace.start(self.smap)
            self.smap.people_trace = self.trace
        latency_ns = svc.config.time.latency_ns_of(NAME, self.period_ns / NS_PER_S)
        lockstep = svc.config.time.mode == "lockstep"
        self.views = ViewHistory(self.period_ns, latency_ns, wait=lockstep)
        self.views.record(self.smap, -1)
        bus, keys = svc.bus, svc.keys
        det_fifo = bus.fifo(keys.detections, Detections, maxlen=512)
        self.det_latest = bus.latest(keys.detections, Detections, history=2)
        frames = {
            cam: bus.latest(keys.camera_rgbd(cam), CameraFrame, history=6)
            for cam in self.cfg.cameras
        }
        self.intake = DetectionIntake(det_fifo, frames)
        #: The mission's patrol, as it says (published every mission tick).
        self.patrol = bus.latest(keys.mission_patrol_status, PatrolStatus, history=8)
        #: The localization's samples (their `grid_stamp_ns`) and the SLAM grids they name.
        self.loc = bus.latest(keys.localization, Localization, history=16)
        self.slam_grids = bus.latest(keys.slam_occupancy, OccupancyGrid, history=2)
        self._slam_stamp = 0
        self.supports = FloorPlanSupports(self.cfg.floor_plan, world)
        self.logger = MapLogger(svc.rec, self.cfg.log_every_s, self.cfg.grid_log_every_s)
        self.committer = TickCommitter(self.store)
        self.fusion_log = FusionLog()
        bus.serve(MAP_ARTIFACTS, None, lambda _r, sel: self._q(queries.listing, "artifact", sel))
        bus.serve(MAP_PEOPLE, None, lambda _r, sel: self._q(queries.listing, "person", sel))
        bus.serve(MAP_ARTIFACTS_ONE, None, lambda _r, sel: self._q(queries.one, "artifact", sel))
        bus.serve(MAP_PEOPLE_ONE, None, lambda _r, sel: self._q(queries.one, "person", sel))
        bus.serve(MAP_OCCUPANCY, None, self._on_occupancy)
        bus.serve(MAP_EXPORT, None, self._on_export)
        bus.serve(MAP_IMPORT, MapFile, self._on_import)
        bus.serve(MAP_SUPPORTS, None, self._on_supports)

    # -- queries (server threads) -----------------------------------------------------------

    def _q(self, fn, kind, selector):  # type: ignore[no-untyped-def]
        selector, at = queries.split_at(selector)
        view = self.views.at(at)
        if view is not None:
            return fn(view, kind, selector)
        with self.lock:
            return fn(self.smap, kind, selector)

    def _on_occupancy(self, _req: None, selector: str) -> OccupancyGrid:
        selector, at = queries.split_at(selector)
        _key, params = queries.parse_selector(selector)
        if params:
            raise RequestError("invalid", f"dume/map/occupancy takes no parameters: {params}")
        view = self.views.at(at)
        if view is not None:
            return view.grid()
        with self.lock:
            return self.smap.grid()

    def _on_export(self, _req: None, _selector: str) -> MapFile:
        with self.lock:
            return export_map(self.smap)

    def _on_import(self, mf: MapFile | None, _selector: str) -> MapSummary:
        assert mf is not None
        check_import(mf, self.site)
        with self.lock:
            return import_map(mf, self.smap, self.store, self.views)

    def _on_supports(self, _req: None, selector: str) -> SupportListing:
        if self.cfg.floor_plan == "world":
            surfaces = self.supports.surfaces()  # may wait for the sim: not under the lock
            with self.lock:
                stamp_ns = self.smap.stamp_ns
            return SupportListing(stamp_ns=stamp_ns, surfaces=surfaces)
        _selector, at = queries.split_at(selector)
        view = self.views.at(at)
        if view is not None:
            return SupportListing(stamp_ns=view.stamp_ns, surfaces=list(view.surfaces))
        with self.lock:
            return SupportListing(stamp_ns=self.smap.stamp_ns, surfaces=list(self.smap.surfaces))

    # -- the tick --------------------------------------------------------------------------

    def run(self) -> None:
        svc = self.svc
        ticker = PeriodicTicker(svc.bus, svc.keys, NAME, self.period_ns / NS_PER_S, svc.stop)
        gate = UpstreamGate(svc.bus, svc.keys, svc.config)
        gate.watch("perception", self.det_latest)
        gate.watch("mission", self.patrol)
        gate.watch("localization", self.loc)
        stall = svc.config.time.stall_timeout_s
        svc.ready()
        for b in ticker.ticks():
            stamp(svc.rec, b)
            late = gate.wait(b, stall)
            if late:
                log.warning("tick %.1f s: no output of %s in time", b / NS_PER_S, late)
            with self.lock:
                self._adopt_slam(b, gate)
                self._fuse_due(b, gate)
                if self.cfg.floor_plan != "world" and b % NS_PER_S == 0:
                    self.smap.find_surfaces()
                    for entity_id, why in self.smap.drop_doubtful():
                        log.info("t=%.2f s: %s deleted: %s", b / NS_PER_S, entity_id, why)
                self.committer.commit(self.smap, b)
                self.logger.log(b, self.smap)
                self.views.record(self.smap, b)
            ticker.ack(b)

    def _adopt_slam(self, b: int, gate: UpstreamGate) -> None:
        """The SLAM grid named by the localization's sample due at b, as the static layer
        of a map that has none but the robot's own."""
        if self.smap.static_source not in ("none", "slam"):
            return
        loc = self.loc.at(b - gate.latency_ns("localization"))
        want = 0 if loc is None else loc.grid_stamp_ns
        if want <= self._slam_stamp:
            return
        try:
            self.slam_grids.wait_stamp(want, self.svc.config.time.stall_timeout_s)
        except WaitTimeout:
            log.warning(
                "tick %.1f s: the SLAM grid of %.1f s never came", b / NS_PER_S, want / NS_PER_S
            )
            return
        grid = self.slam_grids.at(want)
        if grid is None or grid.stamp_ns != want:
            return
        try:
            people = [tr.xy for tr in self.smap.people.confirmed]
            self.smap.occupancy.adopt_static(
                np.asarray(as_numpy(grid.cells), np.uint8), people=np.array(people).reshape(-1, 2)
            )
        except ValueError as exc:
            log.error("the SLAM grid is not the map's: %s", exc)
            self._slam_stamp = want
            return
        if self.smap.static_source != "slam":
            log.info("t=%.1f s: the static layer is the robot's own SLAM grid", b / NS_PER_S)
        self.smap.static_source = "slam"
        self.smap.static_dirty = True
        self._slam_stamp = want

    def _fuse_due(self, b: int, gate: UpstreamGate) -> None:
        """Fuse every frame `intake` releases at b: perception's due then (b − its
        latency), waited for when perception is a live lockstep producer; the patrol's
        cameras too while the mission's patrol status due at b holds the arm up. First,
        what that status says the robot took is marked missing (`SemanticMap.taken`)."""
        cfg = self.cfg
        patrol = self.patrol.at(b - gate.latency_ns("mission"))
        for entity_id, take in self.smap.taken(() if patrol is None else patrol.taken):
            log.info("t=%.2f s: %s missing: taken by the robot at %.2f s (as %s, the jaw at "
                     "(%.2f, %.2f))", b / NS_PER_S, entity_id, take.stamp_ns / NS_PER_S,
                     take.map_id, *take.xy)  # fmt: skip
        arm_up = patrol_holds_look(patrol)
        cameras = fused_cameras(cfg.cameras, cfg.patrol_cameras, arm_up)
        for dets in self.intake.release(b, cameras, *perception_due(b, gate)):
            frame = self.intake.frame(dets.camera, dets.stamp_ns)
            try:
                report = self.smap.ingest(dets, frame)
            except (ValueError, PayloadError) as exc:
                log.warning("detections of %s at %d rejected: %s", dets.camera, dets.stamp_ns, exc)
                continue
            self.fusion_log.fused(dets, report, self.smap)

    def close(self) -> None:
        with self.lock:
            self.committer.close(self.smap)
            if self.trace is not None:
                self.trace.close()


def main(svc: Service) -> None:
    try:
        node = MapNode(svc)
    except MapSiteError as exc:  # never serve a map of another place: say so and stop
        log.error("refused: %s", exc)
        raise SystemExit(2) from None
    try:
        node.run()
    finally:
        node.close()
