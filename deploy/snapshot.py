"""A picture of a run from its recording, for a machine without a display.

`snapshot(folder, out, at_s)` reads the run's `.rrd` files back (`rerun.chunk.RrdReader`)
and draws what the viewer's layout shows first: the hall from above (the map's static
and learned occupancy, its artifacts and people with their ids, every planned path, the
robot's true trail and, dashed, where it believed it was, contacts) beside both cameras
at one moment with perception's boxes and masks over them. The moment is `at_s` (sim
seconds), else the wrist camera's last frame before the mission started `pick_object`
(the object at grasp distance; one with perception's masks kept, if any), else the
middle of the run. `dume view RUN --snapshot
FILE.png` writes it; the README's picture is one.
"""

from __future__ import annotations

import bisect
import warnings
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from rerun.chunk import RrdReader
from rerun.error_utils import RerunWarning

from services.perception.perception_log import PALETTE

#: Entities read, by prefix (a recording holds far more).
WANTED = (
    "/world/map/",
    "/world/truth/robot_trail",
    "/world/localization/base",
    "/world/nav/plan",
    "/nav/plan",  # recordings from before the plan moved into the world
    "/world/events",
    "/camera/",
    "/mission/status",
)


@dataclass
class Series:
    """One entity's rows: sim time (s) and the record batch row's columns."""

    times: list[float] = field(default_factory=list)
    rows: list[dict[str, Any]] = field(default_factory=list)

    def add(self, t: float, row: dict[str, Any]) -> None:
        i = bisect.bisect_right(self.times, t)
        self.times.insert(i, t)
        self.rows.insert(i, row)

    def last(self) -> dict[str, Any] | None:
        return self.rows[-1] if self.rows else None

    def at(self, t: float, within_s: float = float("inf")) -> dict[str, Any] | None:
        """The newest row at or before t, no older than `within_s`."""
        i = bisect.bisect_right(self.times, t) - 1
        if i < 0 or t - self.times[i] > within_s:
            return None
        return self.rows[i]


def read_run(folder: Path, wanted: Iterable[str] = WANTED) -> dict[str, Series]:
    """The wanted entities of every `.rrd` in `folder`, by entity path (timeless rows at
    t = 0)."""
    prefixes = tuple(wanted)
    out: dict[str, Series] = defaultdict(Series)
    for rrd in sorted(folder.glob("*.rrd")):
        with warnings.catch_warnings():  # a live run's files have no footer yet: read whole
            warnings.simplefilter("ignore", RerunWarning)
            reader = RrdReader(rrd)
        for chunk in reader.stream():
            path = chunk.entity_path
            if not path.startswith(prefixes):
                continue
            batch = chunk.to_record_batch()
            names = [n for n in batch.schema.names if ":" in n]
            cols = {n.split(":", 1)[1]: batch.column(batch.schema.names.index(n)) for n in names}
            times = (
                batch.column(batch.schema.names.index("sim_time")).to_pylist()
                if "sim_time" in batch.schema.names
                else [None] * batch.num_rows
            )
            for k, t in enumerate(times):
                row = {name: col[k].as_py() for name, col in cols.items()}
                out[path].add(0.0 if t is None else t.total_seconds(), row)
    return dict(out)


def _points(row: dict[str, Any] | None) -> np.ndarray:
    if row is None or not row.get("positions"):
        return np.zeros((0, 3))
    return np.asarray(row["positions"], dtype=float)


def moment(run: dict[str, Series], at_s: float | None) -> float:
    """The sim time to show the cameras at (see the module docstring)."""
    if at_s is not None:
        return at_s
    status = run.get("/mission/status")
    wrist = run.get("/camera/camera_wrist/rgb")
    masks = run.get("/camera/camera_wrist/perception/masks")
    if status is not None:
        for t, row in zip(status.times, status.rows, strict=True):
            if any("pick_object" in str(x) for x in row.get("text") or []):
                if wrist is not None and wrist.times:
                    before = [s for s in wrist.times if s <= t]
                    masked = [s for s in before if masks is not None and masks.at(s, 0.05)]
                    return (masked or before or [t])[-1]
                return t
    frames = (wrist or Series()).times
    return frames[len(frames) // 2] if frames else 0.0


def camera_image(run: dict[str, Series], cam: str, t: float) -> np.ndarray | None:
    """The camera's RGB at t (its newest frame before), with perception's masks and
    boxes drawn over it."""
    rgb = run.get(f"/camera/{cam}/rgb")
    row = None if rgb is None else rgb.at(t)
    if row is None or not row.get("blob"):
        return None
    img = cv2.imdecode(np.frombuffer(bytes(row["blob"][0]), np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        return None
    img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    masks = run.get(f"/camera/{cam}/perception/masks")
    m = None if masks is None else masks.at(t, within_s=0.5)
    if m is not None and m.get("buffer") and m.get("format"):
        fmt = m["format"][0]
        dtype = _CHANNEL_DTYPES.get(int(fmt["channel_datatype"] or 0), np.uint8)
        flat: np.ndarray = np.frombuffer(bytes(m["buffer"][0]), dtype=dtype)
        ids = flat.reshape(int(fmt["height"]), int(fmt["width"]))
        if ids.shape == img.shape[:2]:
            tint = np.zeros_like(img)
            for k in np.unique(ids[ids > 0]):
                tint[ids == k] = PALETTE[int(k) % len(PALETTE)]
            on = ids > 0
            img[on] = (0.55 * img[on] + 0.45 * tint[on]).astype(np.uint8)
    boxes = run.get(f"/camera/{cam}/perception/boxes")
    b = None if boxes is None else boxes.at(t, within_s=0.5)
    if b is not None:
        labels = b.get("labels") or []
        for k, (c, h) in enumerate(zip(b.get("centers") or [], b.get("half_sizes") or [],
                                       strict=False)):  # fmt: skip
            p0 = (int(c[0] - h[0]), int(c[1] - h[1]))
            p1 = (int(c[0] + h[0]), int(c[1] + h[1]))
            cv2.rectangle(img, p0, p1, (255, 255, 0), 1)
            if k < len(labels):
                cv2.putText(img, str(labels[k]), (p0[0], max(8, p0[1] - 3)),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.33, (255, 255, 0), 1)  # fmt: skip
    return img


#: rerun's `ChannelDatatype` codes of the label images perception logs (8 or 16 bits).
_CHANNEL_DTYPES: dict[int, type] = {6: np.uint8, 8: np.uint16}


def top_down(ax: Any, run: dict[str, Series], t: float | None = None) -> None:
    """The hall from above on matplotlib axes `ax` (the map, plans, trail, entities)."""
    for name, colour, size in (("static", "0.45", 4), ("learned", "tab:orange", 4)):
        occ = _points((run.get(f"/world/map/occupancy/{name}") or Series()).last())
        if len(occ):
            ax.scatter(occ[:, 0], occ[:, 1], s=size, marker="s", c=colour, linewidths=0,
                       label=f"map: {name} occupancy")  # fmt: skip
    plans = run.get("/world/nav/plan") or run.get("/nav/plan")
    if plans is not None:
        for k, row in enumerate(plans.rows):
            for strip in row.get("strips") or []:
                xy = np.asarray(strip, dtype=float)
                last = k == len(plans.rows) - 1
                ax.plot(xy[:, 0], xy[:, 1], color="tab:green", lw=1.2, alpha=0.9 if last else 0.35,
                        label="planned path" if last else None)  # fmt: skip
    trail = run.get("/world/truth/robot_trail")
    if trail is not None and trail.rows:
        xy = np.concatenate([_points(r) for r in trail.rows])
        ax.plot(xy[:, 0], xy[:, 1], color="tab:blue", lw=1.8, label="the robot (truth)")
        ax.plot(*xy[-1, :2], marker="o", color="tab:blue", ms=6)
    est = run.get("/world/localization/base")
    if est is not None and est.rows:
        xy = np.concatenate([_points(r) for r in est.rows])
        if len(xy):
            ax.plot(xy[:, 0], xy[:, 1], color="tab:purple", lw=1, ls="--",
                    label="where it believed it was")  # fmt: skip
    for kind, colour, marker in (("artifacts", "tab:red", "o"), ("people", "k", "^")):
        series = run.get(f"/world/map/{kind}")
        entity: dict[str, Any] | None = None
        if series is not None:
            entity = series.last() if t is None else series.at(t)
        pts = _points(entity)
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], c=colour, marker=marker, s=30, zorder=5,
                       label=f"map: {kind}")  # fmt: skip
            for p, label in zip(pts, (entity or {}).get("labels") or [], strict=False):
                ax.annotate(str(label), p[:2], fontsize=7, xytext=(3, 3),
                            textcoords="offset points")  # fmt: skip
    events = run.get("/world/events")
    if events is not None and events.rows:
        pts = np.concatenate([_points(r) for r in events.rows])
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], c="red", marker="x", s=40, label="contact")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, map)")
    ax.set_ylabel("y (m, map)")
    ax.legend(loc="upper right", fontsize=7, framealpha=0.8)
    ax.grid(alpha=0.2)


def snapshot(folder: Path, out: Path, at_s: float | None = None, title: str = "") -> float:
    """Write the run's picture (see the module docstring) to `out`; the moment shown."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = read_run(folder)
    if not run:
        raise ValueError(f"no recording in {folder}")
    t = moment(run, at_s)
    fig = plt.figure(figsize=(16, 9), dpi=100)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.6, 1.0])
    top_down(fig.add_subplot(grid[:, 0]), run)
    for k, cam in enumerate(("camera_head", "camera_wrist")):
        ax = fig.add_subplot(grid[k, 1])
        img = camera_image(run, cam, t)
        if img is not None:
            ax.imshow(img)
        ax.set_title(f"{cam} at t = {t:.1f} s (perception's boxes and masks)", fontsize=9)
        ax.axis("off")
    fig.suptitle(title or f"run {folder.name}", fontsize=11)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return t
