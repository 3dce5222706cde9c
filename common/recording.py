"""rerun: one recording per run, shared by every service.

Each service opens a `RecordingStream` with the run's id (`recording.run_id`, set by
`dume up` for all of them) and saves its own `var/run/<run>/<service>.rrd` (the run's
folder, beside its logs; `recording.dir`); `dume view <run>` opens them as one
recording. With `recording.viewer` set, the data is also streamed to a live viewer.
Everything is stamped on the `sim_time` timeline (seconds of sim time), never on wall
time.

Entity paths are shared: `world/…` (3D, world frame), `robot/…`, `camera/<cam>/…`,
`plots/<service>/…` (time series), `log/<service>` (text). The blueprint that lays them
out is sent by the sim (`default_blueprint`).
"""

from __future__ import annotations

import logging
import os
import time
import uuid
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from common.config import Config, RecordingSettings, resolve

APP_ID = "dume"
#: A batch is written when it reaches this many bytes or rows, or `flush_s` passed.
BATCH_BYTES = 16 << 20
BATCH_ROWS = 1 << 20
log = logging.getLogger(__name__)


def new_run_id() -> str:
    """A fresh, sortable, human-readable run id: `20261121-101500-1a2b3c`."""
    return time.strftime("%Y%m%d-%H%M%S") + "-" + uuid.uuid4().hex[:6]


def run_dir(settings: RecordingSettings, run_id: str) -> Path:
    return resolve(settings.dir) / run_id


def open_recording(
    service: str, settings: RecordingSettings, blueprint: rrb.Blueprint | None = None
) -> rr.RecordingStream:
    """The service's stream of the run's recording (disabled when recording is off).

    The rerun recording id is derived from the run id, so every service of one run writes
    to the same recording.
    """
    run_id = settings.run_id or os.environ.get("DUME_RECORDING_RUN_ID") or new_run_id()
    rec_id = uuid.uuid5(uuid.NAMESPACE_URL, f"dume/{run_id}")
    batching = rr.ChunkBatcherConfig(
        flush_tick=settings.flush_s, flush_num_bytes=BATCH_BYTES, flush_num_rows=BATCH_ROWS
    )
    rec = rr.RecordingStream(
        APP_ID, recording_id=rec_id, default_enabled=settings.enabled, batcher_config=batching
    )
    if not settings.enabled:
        return rec
    folder = run_dir(settings, run_id)
    folder.mkdir(parents=True, exist_ok=True)
    sinks: list[rr.FileSink | rr.GrpcSink] = [rr.FileSink(str(folder / f"{service}.rrd"))]
    if settings.viewer:
        sinks.append(rr.GrpcSink(settings.viewer))
    rec.set_sinks(*sinks, default_blueprint=blueprint)
    rec.send_recording_name(f"dume {run_id}")
    log.info("recording %s to %s", run_id, folder)
    return rec


def is_recording(rec: rr.RecordingStream) -> bool:
    """Whether `rec` keeps what is logged (recording off: every log call is skipped)."""
    return bool(rr.is_enabled(recording=rec))


class FrameSelector:
    """Which camera frames the recording keeps, by their stamps, so that every service
    logs the same ones (the sim's image, perception's boxes over it): every
    `camera_every`-th frame of the camera's period, and of those every `dense_every`-th
    with the dense layers (depth, segmentation, masks)."""

    def __init__(self, camera_hz: float, camera_every: int, dense_every: int) -> None:
        self.period_ns = max(1, round(1e9 / camera_hz))
        self.every = max(1, camera_every)
        self.dense = self.every * max(1, dense_every)

    @classmethod
    def of(cls, config: Config) -> FrameSelector:
        """The selector of a stack's settings (`sim.camera_hz`, `recording.*_every`)."""
        r = config.recording
        return cls(config.sim.camera_hz, r.camera_every, r.depth_every)

    def logged(self, stamp_ns: int) -> bool:
        return (stamp_ns // self.period_ns) % self.every == 0

    def dense_logged(self, stamp_ns: int) -> bool:
        return (stamp_ns // self.period_ns) % self.dense == 0


def stamp(rec: rr.RecordingStream, stamp_ns: int) -> None:
    """Put what follows on the sim-time timeline."""
    if is_recording(rec):
        rec.set_time("sim_time", duration=stamp_ns * 1e-9)


class RerunHandler(logging.Handler):
    """Forwards a service's log records to `log/<service>` in its recording."""

    def __init__(self, rec: rr.RecordingStream, service: str) -> None:
        super().__init__(level=logging.INFO)
        self._rec = rec
        self._path = f"log/{service}"

    def emit(self, record: logging.LogRecord) -> None:
        try:
            level = {
                logging.DEBUG: rr.TextLogLevel.DEBUG,
                logging.INFO: rr.TextLogLevel.INFO,
                logging.WARNING: rr.TextLogLevel.WARN,
                logging.ERROR: rr.TextLogLevel.ERROR,
            }.get(record.levelno, rr.TextLogLevel.CRITICAL)
            self._rec.log(self._path, rr.TextLog(self.format(record), level=level))
        except Exception:  # logging must never take a service down
            self.handleError(record)


#: The plots' tabs: (name, origin), the controller's first.
PLOT_TABS = (
    ("controller", "plots/wbc"),
    ("navigation", "plots/nav"),
    ("localization", "plots/localization"),
    ("perception", "plots/perception"),
    ("sim", "plots/sim"),
    ("truth", "plots/truth"),
)


def view_origins(blueprint: rrb.Blueprint) -> list[tuple[str, str]]:
    """(view name, origin) of every view in `blueprint`, depth first."""
    out: list[tuple[str, str]] = []

    def walk(part: object) -> None:
        if isinstance(part, rrb.View):
            out.append((str(part.name), str(part.origin)))
        for child in getattr(part, "contents", None) or []:
            if isinstance(child, (rrb.View, rrb.Container)):
                walk(child)

    walk(blueprint.root_container)
    return out


def shown_by(entity: str, origins: list[tuple[str, str]]) -> list[str]:
    """The names of the views whose origin holds `entity` (an entity path)."""
    path = "/" + entity.strip("/")
    return [
        n
        for n, o in origins
        if path == "/" + o.strip("/") or path.startswith("/" + o.strip("/") + "/")
    ]


def default_blueprint(cameras: tuple[str, ...] = ("camera_head", "camera_wrist")) -> rrb.Blueprint:
    """The layout of a run, what a person watching the robot wants in view: the 3D world
    (the map's occupancy and entities, the costmap and the planned path, the cameras'
    frustums, the robot's true trail, perception's points), both cameras with
    perception's boxes and masks, the mission's behaviour tree and decisions, and the
    plots (the controller's first) beside the services' logs. The side panels start
    open: the entity tree and the timeline are how one finds the rest."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(name="world", origin="world"),
                rrb.Tabs(
                    *[rrb.TimeSeriesView(name=n, origin=o) for n, o in PLOT_TABS],
                    rrb.TimeSeriesView(name="mission progress", origin="mission/progress"),
                ),
                row_shares=[3, 2],
            ),
            rrb.Vertical(
                *[rrb.Spatial2DView(name=cam, origin=f"camera/{cam}") for cam in cameras],
                rrb.Tabs(
                    rrb.TextDocumentView(name="behaviour tree", origin="mission/tree"),
                    rrb.TextLogView(name="mission", origin="mission"),
                    rrb.TextLogView(name="logs", origin="log"),
                    rrb.TextDocumentView(name="world", origin="world/description"),
                ),
                row_shares=[2, 2, 3],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )
