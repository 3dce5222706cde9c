"""What the people tracker took in, frame by frame, kept for replay (`semantic_map.people_trace`).

A person's id is only as good as the tracker's rules, and those are tuned on real runs:
walkers crossing the robot's path, people seen from behind, furniture read as a person.
With `semantic_map.people_trace` set to a file, the map writes there, in msgpack records
each prefixed by its length (a killed service loses at most the last record):

- one `TraceStart` when it opens: the people it starts with (a saved map's priors, with
  their colours) and its id counters;
- one `TraceFrame` per fused camera frame: the person observations the tracker got (after
  the map's own filters: on an obstacle, on the robot, on a surface) and the camera of the
  frame (its pose, intrinsics and depth at 1/`DEPTH_STRIDE` resolution, float16), which
  the map's looks (`looks_at`) count misses with.

`replay` runs a fresh `SemanticMap` of the same settings through the trace (people only:
no artifacts, no occupancy learned) and yields the map and what each frame did to it;
`dume bench people-ids` scores that against the sim's truth. The trace is the map's own
input: no truth is in it.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import msgspec
import numpy as np

from common.camera import PinholeCamera
from common.config import SemanticMapSettings
from common.geometry import FloatArray
from common.messages.semantic_map import MapEntity
from services.semantic_map.entities import Observation, Track
from services.semantic_map.mapper import IngestReport, SemanticMap
from services.semantic_map.occupancy import Occupancy

#: The depth image is kept at every `DEPTH_STRIDE`-th pixel of each axis (the looks read a
#: 5-pixel median at the projected point: nearest-neighbour upsampling keeps it).
DEPTH_STRIDE = 4
_LEN = struct.Struct("<I")


class TracedPerson(msgspec.Struct, array_like=True):
    """One person observation as the tracker got it (`entities.Observation`)."""

    xy: tuple[float, float]
    z: float
    sigma_m: float
    score: float
    appearance: list[float] | None
    range_m: float
    whole: bool


class TracedCamera(msgspec.Struct, array_like=True):
    """The frame's camera: full-resolution intrinsics, its pose in the world (row-major
    4 × 4), and the depth image subsampled by `stride` (float16 metres, row-major)."""

    fx: float
    fy: float
    cx: float
    cy: float
    T_world_camera: list[float]
    stride: int
    height: int
    width: int
    depth: bytes


class TraceStart(msgspec.Struct, tag="start"):
    """The people the map starts with, their colours, and the id counters."""

    people: list[MapEntity]
    appearances: dict[str, list[float]]
    counters: dict[str, int]


class TraceFrame(msgspec.Struct, tag="frame"):
    """One fused camera frame: its stamp, its person observations, its camera (None when
    the frame came without an image: nothing was looked at)."""

    stamp_ns: int
    people: list[TracedPerson]
    camera: TracedCamera | None


Record = TraceStart | TraceFrame
_ENCODER = msgspec.msgpack.Encoder()
_DECODER = msgspec.msgpack.Decoder(Record)


def traced_person(o: Observation) -> TracedPerson:
    app = None if o.appearance is None else [float(v) for v in o.appearance]
    return TracedPerson(
        (float(o.xy[0]), float(o.xy[1])), o.z, o.sigma_m, o.score, app, o.range_m, o.whole
    )


def observation(p: TracedPerson) -> Observation:
    app = None if p.appearance is None else np.asarray(p.appearance, float)
    return Observation("person", np.array(p.xy, float), p.z, p.sigma_m, p.score, app,
                       p.range_m, p.whole)  # fmt: skip


def traced_camera(cam: PinholeCamera, stride: int = DEPTH_STRIDE) -> TracedCamera:
    depth = cam.depth_image()[::stride, ::stride].astype(np.float16)
    return TracedCamera(
        cam.fx, cam.fy, cam.cx, cam.cy, [float(v) for v in cam.T_world_camera.ravel()],
        stride, depth.shape[0], depth.shape[1], depth.tobytes(),
    )  # fmt: skip


def camera(c: TracedCamera) -> PinholeCamera:
    """The traced camera with its depth brought back to full resolution (nearest)."""
    small = np.frombuffer(c.depth, np.float16).reshape(c.height, c.width).astype(np.float32)
    depth = np.repeat(np.repeat(small, c.stride, axis=0), c.stride, axis=1)
    T: FloatArray = np.asarray(c.T_world_camera, float).reshape(4, 4)
    return PinholeCamera(c.fx, c.fy, c.cx, c.cy, T, depth)


class PeopleTrace:
    """The writer: `start(smap)` once, then `frame(...)` per fused frame."""

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._file: BinaryIO = path.open("wb")

    def _write(self, record: Record) -> None:
        data = _ENCODER.encode(record)
        self._file.write(_LEN.pack(len(data)) + data)
        self._file.flush()

    def start(self, smap: SemanticMap) -> None:
        people = smap.people.confirmed
        apps = {
            t.id: [float(v) for v in t.appearance]
            for t in people
            if t.id is not None and t.appearance is not None
        }
        self._write(TraceStart([t.to_message() for t in people], apps, dict(smap.ids.counters)))

    def frame(self, stamp_ns: int, people: list[Observation], cam: PinholeCamera | None) -> None:
        traced = None if cam is None else traced_camera(cam)
        self._write(TraceFrame(stamp_ns, [traced_person(o) for o in people], traced))

    def close(self) -> None:
        self._file.close()


def read_trace(path: Path) -> Iterator[Record]:
    """The records of a trace, in order; a record cut short at the end (a killed map) ends
    it."""
    with path.open("rb") as f:
        while head := f.read(_LEN.size):
            if len(head) < _LEN.size:
                return
            (n,) = _LEN.unpack(head)
            data = f.read(n)
            if len(data) < n:
                return
            yield _DECODER.decode(data)


def replay(
    path: Path, settings: SemanticMapSettings
) -> Iterator[tuple[TraceFrame, SemanticMap, IngestReport]]:
    """A fresh map of `settings` through the trace: (the frame, the map, what fusing the
    frame did) after each frame."""
    smap: SemanticMap | None = None
    for record in read_trace(path):
        if isinstance(record, TraceStart):
            smap = SemanticMap(settings, Occupancy.unknown(1.0, 0.05), record.counters)
            for e in record.people:
                app = record.appearances.get(e.id)
                smap.add(Track.from_message(e, None if app is None else np.asarray(app)))
            continue
        if smap is None:
            raise ValueError(f"{path}: a frame before the trace's start")
        people = [observation(p) for p in record.people]
        cam = None if record.camera is None else camera(record.camera)
        report = smap.fuse(record.stamp_ns, [], people, cam)
        yield record, smap, report
