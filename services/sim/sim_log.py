"""What the sim shows in rerun: the world's layout, the robot's state, cameras, events.

The world is Z-up (`world`'s view coordinates, as MuJoCo's). Cameras go to
`camera/<cam>`: the pinhole and RGB (JPEG) at the camera rate, depth (mm) and the truth
segmentation (with its label table) at every `recording.depth_every`-th logged frame, so
a recording stays near 1 MB per sim second; each logged frame also places the camera's
frustum in the 3D world (`world/cameras/<cam>`, by the base's true pose at capture).
Plots go to `plots/sim/…`, events to `log/sim/events` and, for contacts, as points in
`world/events`. The lidar's scan goes, every `SCAN_EVERY_NS`, to `world/truth/scan`: its
returns placed by the true pose of the lidar (the sim's view; a service places them by
its estimate).
"""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from common.geometry import FloatArray, quat_xyzw_to_matrix
from common.messages import as_numpy
from common.messages.sim import (
    ArtifactMoved,
    CameraFrame,
    HandoverTaken,
    MovableMoved,
    ObjectDropped,
    RobotContact,
    RobotState,
    SegmentationTruth,
    StateTruth,
    WorldEvent,
)
from common.messages.world import WorldDescription
from common.recording import FrameSelector, is_recording, stamp

#: The recording keeps one scan in this many ns of sim time (of the lidar's 10 Hz).
SCAN_EVERY_NS = 500_000_000
#: True base poses kept to place the cameras' frustums (a frame renders a few ticks late).
BASES_KEPT = 64
#: The frustums' depth in the 3D view, m.
FRUSTUM_M = 0.25


class SimLogger:
    def __init__(self, rec: rr.RecordingStream, frames: FrameSelector) -> None:
        self.rec = rec
        self.enabled = is_recording(rec)
        self.frames = frames
        self._annotated: set[str] = set()
        #: The base's true pose by stamp (the newest `BASES_KEPT`): where to draw a camera.
        self._bases: dict[int, FloatArray] = {}
        #: Each movable's half extents (m), to draw it where it is left.
        self._movables: dict[str, tuple[float, float, float]] = {}

    def world(self, world: WorldDescription) -> None:
        self._movables = {m.id: m.half_size for m in world.movables}
        if not self.enabled:
            return
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)  # MuJoCo's
        lines = [
            f"# {world.name} world, seed {world.seed}",
            "",
            "| id | class | x | y | z |",
            "|---|---|---|---|---|",
        ]
        for a in world.artifacts:
            x, y, z = a.position
            lines.append(f"| {a.id} | {a.object_class} | {x:.2f} | {y:.2f} | {z:.2f} |")
        for p in world.people:
            x, y = p.position
            lines.append(f"| {p.id} | person | {x:.2f} | {y:.2f} | 0 |")
        self.rec.log(
            "world/description",
            rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN),
            static=True,
        )
        self.rec.log(
            "world/labels",
            rr.Points3D(
                [(*a.position[:2], a.position[2] + 0.3) for a in world.artifacts]
                + [(*p.position, 2.0) for p in world.people],
                labels=[a.id for a in world.artifacts] + [p.id for p in world.people],
                radii=0.01,
            ),
            static=True,
        )

    def state(self, t_ns: int, state: RobotState, truth: StateTruth) -> None:
        """The robot's state and the base's truth (the true trajectory, under `truth/`)."""
        if not self.enabled:
            return
        stamp(self.rec, t_ns)
        x, y, z = truth.base_position_in_world
        qx, qy, qz, qw = truth.base_orientation_xyzw
        roll = math.atan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (qw * qy - qz * qx))))
        self.rec.log("plots/truth/base_height_m", rr.Scalars(z))
        self.rec.log("plots/truth/base_roll_pitch_rad", rr.Scalars([roll, pitch]))
        self.rec.log("plots/sim/gripper_effort_nm", rr.Scalars(state.gripper_effort))
        self.rec.log("plots/sim/watchdog", rr.Scalars(float(state.watchdog)))
        self.rec.log("world/truth/robot_trail", rr.Points3D([(x, y, 0.01)], radii=0.01))
        T = np.eye(4)
        T[:3, :3] = quat_xyzw_to_matrix(truth.base_orientation_xyzw)
        T[:3, 3] = (x, y, z)
        self._bases[t_ns] = T
        while len(self._bases) > BASES_KEPT:
            del self._bases[next(iter(self._bases))]

    def rtf(self, t_ns: int, rtf: float) -> None:
        if not self.enabled:
            return
        stamp(self.rec, t_ns)
        self.rec.log("plots/sim/real_time_factor", rr.Scalars(rtf))

    def keeps(self, t_ns: int) -> bool:
        """Whether the recording keeps the camera frames stamped t."""
        return self.enabled and self.frames.logged(t_ns)

    def keeps_dense(self, t_ns: int) -> bool:
        """Whether it keeps their depth and segmentation too."""
        return self.enabled and self.frames.dense_logged(t_ns)

    def scan(
        self,
        t_ns: int,
        angles: FloatArray,
        ranges: FloatArray,
        T_world_lidar: FloatArray,
        lidar: str = "lidar",
    ) -> None:
        """One scan's returns in the world, by the lidar's true pose (`SCAN_EVERY_NS`);
        the rear lidar's on `world/truth/scan_rear`."""
        if not self.enabled or t_ns % SCAN_EVERY_NS:
            return
        hit = ranges > 0.0
        r, a = ranges[hit].astype(float), angles[hit]
        local = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)], axis=1)
        points = local @ T_world_lidar[:3, :3].T + T_world_lidar[:3, 3]
        stamp(self.rec, t_ns)
        path = "world/truth/scan" + lidar.removeprefix("lidar")
        self.rec.log(path, rr.Points3D(points, radii=0.015, colors=(255, 80, 40)))

    def camera(self, t_ns: int, frame: CameraFrame, truth: SegmentationTruth | None) -> None:
        if not self.enabled:
            return
        cam = frame.camera
        if not self.frames.logged(t_ns):
            return
        stamp(self.rec, t_ns)
        path = f"camera/{cam}"
        self.rec.log(
            path,
            rr.Pinhole(
                focal_length=[frame.fx, frame.fy],
                principal_point=[frame.cx, frame.cy],
                resolution=[frame.width, frame.height],
            ),
        )
        self.rec.log(f"{path}/rgb", rr.Image(as_numpy(frame.rgb)).compress(jpeg_quality=80))
        base = self._bases.get(frame.stamp_ns)
        if base is not None:  # the camera in the 3D world: its frustum where it looked
            T = base @ np.asarray(frame.T_base_camera, dtype=float).reshape(4, 4)
            self.rec.log(
                f"world/cameras/{cam}",
                rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]),
                rr.Pinhole(
                    focal_length=[frame.fx, frame.fy],
                    principal_point=[frame.cx, frame.cy],
                    resolution=[frame.width, frame.height],
                    camera_xyz=rr.ViewCoordinates.RDF,
                    image_plane_distance=FRUSTUM_M,
                ),
            )
        if truth is not None and cam not in self._annotated:  # the same for every frame
            self.rec.log(
                f"{path}/segmentation_truth",
                rr.AnnotationContext([(int(k), v) for k, v in sorted(truth.instances.items())]),
                static=True,
            )
            self._annotated.add(cam)
        if truth is None or not self.frames.dense_logged(t_ns):
            return
        # depth in mm and labels in 8 bits where they fit: a recording stays ~1 MB/s
        depth_mm = np.round(as_numpy(frame.depth).astype(np.float32) * 1000.0).astype(np.uint16)
        self.rec.log(f"{path}/depth", rr.DepthImage(depth_mm, meter=1000.0))
        labels = np.asarray(as_numpy(truth.labels), dtype=np.int32)
        ids = labels.astype(np.uint8) if labels.max(initial=0) < 256 else labels.astype(np.uint16)
        self.rec.log(f"{path}/segmentation_truth", rr.SegmentationImage(ids))

    def _movable(self, ev: MovableMoved) -> None:
        """The movable's box where it now stands (truth); cleared when parked away."""
        path = f"world/movables/{ev.movable_id}"
        half = self._movables.get(ev.movable_id)
        if ev.away or half is None:
            self.rec.log(path, rr.Clear(recursive=False))
            return
        x, y = ev.position_in_world
        turn = rr.Quaternion(xyzw=(0.0, 0.0, math.sin(0.5 * ev.yaw), math.cos(0.5 * ev.yaw)))
        self.rec.log(
            path,
            rr.Boxes3D(
                centers=[(x, y, half[2])],
                half_sizes=[half],
                quaternions=[turn],
                labels=[ev.movable_id],
                colors=[(60, 85, 130)],
            ),
        )

    def events(self, t_ns: int, events: list[WorldEvent]) -> None:
        if not self.enabled:
            return
        stamp(self.rec, t_ns)
        for ev in events:
            if isinstance(ev, HandoverTaken):
                text = f"handover taken: {ev.person_id} took {ev.object_id}"
            elif isinstance(ev, ObjectDropped):
                text = f"object dropped: {ev.object_id} at {np.round(ev.position_in_world, 2)}"
            elif isinstance(ev, RobotContact):
                text = f"robot contact: {ev.body} touched {ev.other} ({ev.force:.0f} N)"
                self.rec.log(
                    "world/events/contacts", rr.Points3D([ev.position_in_world], radii=0.03)
                )
            elif isinstance(ev, ArtifactMoved):
                where = "away" if ev.away else f"to {np.round(ev.position_in_world, 2)}"
                text = f"artifact moved (truth): {ev.object_id} {where}"
            elif isinstance(ev, MovableMoved):
                where = "parked away" if ev.away else f"left at {np.round(ev.position_in_world, 2)}"
                text = f"movable moved (truth): {ev.movable_id} {where}"
                self._movable(ev)
            else:
                text = str(ev)
            self.rec.log("log/sim/events", rr.TextLog(text, level=rr.TextLogLevel.WARN))
