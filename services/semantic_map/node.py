"""The semantic map service: a lockstep participant that fuses detections into the map,
persists every tick's changes before acknowledging it, serves the map and walks the
mapping patrol.

Per tick b (period and latency from `time.participants.semantic_map`): wait for
perception's detections due by b (`UpstreamGate`, and each fused camera's), fuse every
frame's detections stamped at or before b − perception's latency, step the patrol on
the odom at b (`patrol_driver`: pose goals to navigation),
commit the changes in one SQLite transaction, keep the map's view after b (`views`),
then ack b. Queryables run on their own threads; one with `at=<t>` (a lockstep
consumer's tick) is answered from the view of the map's last tick that takes effect by
t, so every run of a seed answers it alike; one without, from the map now.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import defaultdict

from common.bus import NoReply, RemoteError, RequestError, WaitTimeout
from common.geometry import FloatArray, yaw_of_quat_xyzw
from common.keys import (
    MAP_ARTIFACTS,
    MAP_ARTIFACTS_ONE,
    MAP_EXPORT,
    MAP_IMPORT,
    MAP_OCCUPANCY,
    MAP_PEOPLE,
    MAP_PEOPLE_ONE,
    WORLD_DESCRIPTION,
)
from common.lockstep import PeriodicTicker, UpstreamGate
from common.messages import PayloadError
from common.messages.base import NS_PER_S
from common.messages.perception import Detections
from common.messages.semantic_map import (
    MapFile,
    MapSummary,
    OccupancyGrid,
    PatrolRequest,
    PatrolStatus,
)
from common.messages.sim import CameraFrame, Odom
from common.messages.world import WorldDescription
from common.recording import stamp
from common.service import Service
from services.semantic_map import queries
from services.semantic_map.mapfile import occupancy_from_grid, tracks_from_file
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.patrol import coverage_route, support_targets
from services.semantic_map.patrol_driver import PatrolDriver
from services.semantic_map.rerun_log import MapLogger
from services.semantic_map.startup import open_map, save_all
from services.semantic_map.store import Grid, MapStore, database_path, remove_database
from services.semantic_map.views import ViewHistory, view_of

NAME = "semantic_map"
#: Wall seconds a tick waits for a due camera's detections (the other camera's are in),
#: or for the frame behind detections it fuses.
FRAME_WAIT_S = 2.0
#: Sim seconds between the per-camera summaries of what was fused.
SUMMARY_EVERY_S = 10.0
log = logging.getLogger(f"dume.{NAME}")


class MapNode:
    def __init__(self, svc: Service) -> None:
        self.svc = svc
        self.cfg = svc.config.semantic_map
        self.period_ns = svc.config.time.period_ns_of(NAME, 0.1)
        path = database_path(self.cfg)
        if self.cfg.reset:
            remove_database(path)
        self.store = MapStore(path)
        self.lock = threading.RLock()
        self.smap: SemanticMap
        self.smap, how = open_map(self.cfg, self.store, self._world)
        log.info("%s", how)
        latency_ns = svc.config.time.latency_ns_of(NAME, self.period_ns / NS_PER_S)
        lockstep = svc.config.time.mode == "lockstep"
        self.views = ViewHistory(self.period_ns, latency_ns, wait=lockstep)
        self.views.add(view_of(self.smap, -1, None))
        bus, keys = svc.bus, svc.keys
        self.det_fifo = bus.fifo(keys.detections, Detections, maxlen=512)
        self.det_latest = bus.latest(keys.detections, Detections, history=2)
        self.frames = {
            cam: bus.latest(keys.camera_rgbd(cam), CameraFrame, history=6)
            for cam in self.cfg.cameras
        }
        self.odom = bus.latest(keys.odom, Odom, history=16)
        self.pending: dict[int, dict[str, Detections]] = defaultdict(dict)
        self.patrol = PatrolDriver(
            bus,
            keys,
            self.cfg,
            NAME,
            svc.config.wbc.cmd_vel_source,
            svc.config.time.latencies_ns(),
        )
        self._supports: FloatArray | None = None
        self.logger = MapLogger(svc.rec, self.cfg.log_every_s, self.cfg.grid_log_every_s)
        self.last_grid_save = 0
        #: Per camera since the last summary: frames, detections fused, ignored (logged
        #: every `SUMMARY_EVERY_S` of sim time: what each camera adds to the map).
        self.counts: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0])
        self.last_summary_ns = 0
        bus.serve(MAP_ARTIFACTS, None, lambda _r, sel: self._q(queries.listing, "artifact", sel))
        bus.serve(MAP_PEOPLE, None, lambda _r, sel: self._q(queries.listing, "person", sel))
        bus.serve(MAP_ARTIFACTS_ONE, None, lambda _r, sel: self._q(queries.one, "artifact", sel))
        bus.serve(MAP_PEOPLE_ONE, None, lambda _r, sel: self._q(queries.one, "person", sel))
        bus.serve(MAP_OCCUPANCY, None, self._on_occupancy)
        bus.serve(MAP_EXPORT, None, self._on_export)
        bus.serve(MAP_IMPORT, MapFile, self._on_import)
        bus.serve(keys.map_patrol, PatrolRequest, self._on_patrol)

    # -- start-up ------------------------------------------------------------------------

    def _world(self, wait_s: float = 30.0) -> WorldDescription | None:
        deadline = time.monotonic() + wait_s
        while not self.svc.stopping and time.monotonic() < deadline:
            try:
                return self.svc.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 5.0)
            except (NoReply, RemoteError, PayloadError) as exc:
                log.info("waiting for the world description: %s", exc)
                time.sleep(0.5)
        return None

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
            s = self.smap
            entities = s.entities("artifact") + s.entities("person")
            return MapFile(
                stamp_ns=s.stamp_ns,
                entities=entities,
                counters=dict(s.ids.counters),
                occupancy=s.grid(),
            )

    def _on_import(self, mf: MapFile | None, _selector: str) -> MapSummary:
        assert mf is not None
        ids = [e.id for e in mf.entities]
        if len(set(ids)) != len(ids):
            raise RequestError("invalid", "the map file names an id twice")
        bad = [e.id for e in mf.entities if (e.kind == "person") != (e.class_name == "person")]
        if bad:
            raise RequestError("invalid", f"kind and class disagree for {bad}")
        with self.lock:
            s = self.smap
            s.clear()
            s.ids.counters.update(mf.counters)
            if mf.occupancy is not None:
                occ = s.occupancy
                s.occupancy = occupancy_from_grid(
                    mf.occupancy, hits_needed=occ.hits_needed, z_range=occ.z_range
                )
                s.static_source = "file"
            for tr in tracks_from_file(mf, "import"):
                s.add(tr)
            save_all(s, self.store, {"static_source": s.static_source})
            newest = self.views.newest
            self.views.reset(view_of(s, newest.tick_ns if newest else -1, None))
            log.info("imported a map: %d entities", len(mf.entities))
            return self._summary()

    def _summary(self) -> MapSummary:
        arts = self.smap.entities("artifact")
        return MapSummary(
            stamp_ns=self.smap.stamp_ns,
            artifacts=len(arts),
            people=len(self.smap.people.confirmed),
            missing=sum(e.missing_since_ns is not None for e in arts),
        )

    def _support_targets(self) -> FloatArray | None:
        """The floor plan's tables and benches as places the patrol must see (only with
        `floor_plan = "world"`: the world description's surfaces, fetched once)."""
        if self.cfg.floor_plan != "world":
            return None
        if self._supports is None:
            w = self._world(wait_s=5.0)
            if w is None:
                log.warning("patrol: no world description: no floor plan's supports to look at")
                return None
            self._supports = support_targets(w.surfaces)
        return self._supports

    def _on_patrol(self, req: PatrolRequest | None, _selector: str) -> PatrolStatus:
        assert req is not None
        targets = self._support_targets() if req.action == "start" else None
        with self.lock:
            if req.action == "start":
                if self.patrol.running:
                    raise RequestError("busy", "a patrol is running; stop it first")
                odom = self.odom.get()
                if odom is None:
                    raise RequestError("unavailable", "no odometry: is the sim running?")
                occ = self.smap.occupancy
                x, y, _z = odom.base_position_in_world
                route = coverage_route(
                    occ.cells(),
                    occ.resolution_m,
                    occ.origin_xy,
                    (x, y),
                    req.spacing_m or self.cfg.patrol_spacing_m,
                    self.cfg.patrol_clearance_m,
                    targets,
                    self.cfg.patrol_see_m,
                )
                if not route.viewpoints:
                    raise RequestError("unavailable", "no free space to patrol in the grid")
                self.patrol.start(route, yaw_of_quat_xyzw(odom.base_orientation_xyzw))
                log.info("patrol: %d viewpoints via %s", len(route.viewpoints), self.cfg.patrol_via)
            elif req.action == "stop":
                self.patrol.stop()
            return self._patrol_status()

    def _patrol_status(self) -> PatrolStatus:
        at, n, travelled, _skipped = self.patrol.progress()
        return PatrolStatus(
            stamp_ns=self.smap.stamp_ns,
            state=self.patrol.state,
            waypoint=at,
            waypoints=n,
            travelled_m=travelled,
            artifacts=len(self.smap.artifacts.confirmed),
            people=len(self.smap.people.confirmed),
            reason=self.patrol.reason,
        )

    # -- the tick --------------------------------------------------------------------------

    def run(self) -> None:
        svc = self.svc
        ticker = PeriodicTicker(svc.bus, svc.keys, NAME, self.period_ns / NS_PER_S, svc.stop)
        gate = UpstreamGate(svc.bus, svc.keys, svc.config)
        gate.watch("perception", self.det_latest)
        stall = svc.config.time.stall_timeout_s
        svc.ready()
        for b in ticker.ticks():
            stamp(svc.rec, b)
            late = gate.wait(b, stall)
            if late:
                log.warning("tick %.1f s: no detections from %s in time", b / NS_PER_S, late)
            with self.lock:
                self._fuse_due(b, gate)
                self._step_patrol(b)
                self._commit(b)
                self.logger.log(b, self.smap)
                self.views.add(view_of(self.smap, b, self.views.newest))
            ticker.ack(b)

    def _cameras(self) -> list[str]:
        """The cameras fused now: `cameras`, and `patrol_cameras` while a patrol holds the
        arm in `look` (the wrist camera then sees bench tops; stowed, it sees the legs)."""
        extra = self.cfg.patrol_cameras if self.patrol.arm_up else []
        return [*self.cfg.cameras, *(c for c in extra if c not in self.cfg.cameras)]

    def _collect(self, cameras: list[str]) -> None:
        for dets in self.det_fifo.drain():
            if dets.camera in cameras:
                self.pending[dets.stamp_ns][dets.camera] = dets

    def _fuse_due(self, b: int, gate: UpstreamGate) -> None:
        """Fuse every frame whose detections take effect by b (stamp ≤ b − perception's
        latency), each camera's: one detections key carries both cameras, so the gate may
        have been met by the other camera's message; the one due is waited for (bounded),
        as every camera publishes at every tick (older stamps are complete: one key keeps
        its order)."""
        cameras = self._cameras()
        self._collect(cameras)
        schedule = gate.gate.schedules.get("perception")
        due = b - gate.latency_ns("perception")
        wait = schedule is not None and "perception" in gate.gate.alive and gate.lockstep
        if wait and schedule is not None and due >= 0 and due % schedule.period_ns == 0:
            deadline = time.monotonic() + FRAME_WAIT_S
            while not set(cameras) <= set(self.pending.get(due, {})):
                left = deadline - time.monotonic()
                dets = self.det_fifo.pop(timeout_s=left) if left > 0 else None
                if dets is None:
                    log.warning("tick %.1f s: detections at %d missing", b / NS_PER_S, due)
                    break
                if dets.camera in cameras:
                    self.pending[dets.stamp_ns][dets.camera] = dets
        for s in sorted(self.pending):
            if s > due:
                break
            cams = self.pending.pop(s)
            for cam in cameras:
                if cam in cams:
                    self._fuse(cams[cam])

    def _frame(self, cam: str, s: int) -> CameraFrame | None:
        sub = self.frames.get(cam)
        if sub is None or sub.received == 0:
            return None
        frame = sub.at(s)
        if frame is None or frame.stamp_ns != s:
            try:
                sub.wait_stamp(s, FRAME_WAIT_S)
            except WaitTimeout:
                log.warning("no %s frame stamped %.3f s: detections fused without it", cam, s / 1e9)
                return None
            frame = sub.at(s)
        return frame if frame is not None and frame.stamp_ns == s else None

    def _fuse(self, dets: Detections) -> None:
        frame = self._frame(dets.camera, dets.stamp_ns)
        try:
            report = self.smap.ingest(dets, frame)
        except (ValueError, PayloadError) as exc:
            log.warning("detections of %s at %d rejected: %s", dets.camera, dets.stamp_ns, exc)
            return
        c = self.counts[dets.camera]
        c[0], c[1], c[2] = c[0] + 1, c[1] + report.fused, c[2] + report.ignored
        if dets.stamp_ns - self.last_summary_ns >= SUMMARY_EVERY_S * NS_PER_S:
            self.last_summary_ns = dets.stamp_ns
            log.info(
                "fused in the last %.0f s: %s",
                SUMMARY_EVERY_S,
                ", ".join(f"{cam} {f} frames {n} detections ({i} ignored)"
                          for cam, (f, n, i) in sorted(self.counts.items())),
            )  # fmt: skip
            self.counts.clear()
        for entity_id in report.new_ids:
            tr = self.smap.artifacts.by_id(entity_id) or self.smap.people.by_id(entity_id)
            if tr is not None:
                log.info(
                    "t=%.2f s: new %s at (%.2f, %.2f) from %s",
                    dets.stamp_ns / NS_PER_S,
                    entity_id,
                    tr.xy[0],
                    tr.xy[1],
                    dets.camera,
                )
        for entity_id in report.missing:
            log.info(
                "t=%.2f s: %s missing: looked at its place from %s, not seen",
                dets.stamp_ns / NS_PER_S,
                entity_id,
                dets.camera,
            )
        for entity_id, reason in report.dropped:
            t = dets.stamp_ns / NS_PER_S
            log.info("t=%.2f s: %s deleted from %s: %s", t, entity_id, dets.camera, reason)

    def _step_patrol(self, b: int) -> None:
        if not self.patrol.running:
            return
        try:
            self.odom.wait_stamp(b, 1.0)
        except WaitTimeout:
            log.warning("patrol: no odom at %.1f s", b / NS_PER_S)
        self.patrol.step(b, self.odom.at(b))
        route = self.patrol.route
        if route is not None:
            self.logger.patrol(b, route)

    def _commit(self, b: int) -> None:
        self.smap.stamp_ns = max(self.smap.stamp_ns, b)
        changed, counters = self.smap.take_changes()
        deleted = self.smap.take_deletions()
        grids = None
        occ = self.smap.occupancy
        if self.smap.grid_dirty and b - self.last_grid_save >= 2 * NS_PER_S:
            grids = {"learned": Grid(occ.hits, occ.resolution_m, occ.origin_xy)}
            self.smap.grid_dirty = False
            self.last_grid_save = b
        if not changed and not deleted and counters is None and grids is None:
            return
        self.store.commit(
            entities=[(t.to_message(), t.appearance) for t in changed],
            counters=counters,
            grids=grids,
            meta={"stamp_ns": str(b)},
            deleted=deleted,
        )

    def close(self) -> None:
        with self.lock:
            occ = self.smap.occupancy
            self.store.commit(grids={"learned": Grid(occ.hits, occ.resolution_m, occ.origin_xy)})
            self.store.close()


def main(svc: Service) -> None:
    node = MapNode(svc)
    try:
        node.run()
    finally:
        node.close()
