"""What perception shows in rerun, on the sim-time timeline.

Per camera, on the frames the sim keeps the image of (`common.recording.FrameSelector`):
boxes with `class score` labels over the image (`camera/<cam>/perception/boxes`), and
with the dense ones the instance masks (`camera/<cam>/perception/masks`, label k = the
k-th detection). In the world: each instance's inlier points (thinned), its centroid with
`class d θ`, and its axis as a vertical segment over the fitted height
(`world/perception/<cam>/…`).
Plots, every frame: detections and processing time (`plots/perception/…`).
"""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from common.messages.perception import Detection, Detections
from common.recording import FrameSelector, is_recording, stamp
from services.perception.pipeline import Detected, class_text, mask_of

#: Points logged per instance at most.
MAX_LOG_POINTS = 120
#: Instance colours (boxes, masks), also `dume view --snapshot`'s.
PALETTE = np.array(
    [[230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48], [145, 30, 180]],
    dtype=np.uint8,
)


def _axis_segment(d: Detection) -> list[tuple[float, float, float]]:
    """The axis as a vertical segment over the fitted height."""
    x, y, z = d.axis_in_world
    half = 0.5 * d.extent[2]
    return [(x, y, z - half), (x, y, z + half)]


class PerceptionLogger:
    def __init__(self, rec: rr.RecordingStream, frames: FrameSelector) -> None:
        self.rec = rec
        self.enabled = is_recording(rec)
        self.frames = frames

    def frame(
        self, msg: Detections, detected: list[Detected], image_shape: tuple[int, int]
    ) -> None:
        if not self.enabled:
            return
        cam = msg.camera
        stamp(self.rec, msg.stamp_ns)
        self.rec.log(f"plots/perception/{cam}/detections", rr.Scalars(len(detected)))
        self.rec.log(f"plots/perception/{cam}/process_ms", rr.Scalars(msg.process_ms))
        if not self.frames.logged(msg.stamp_ns):  # the sim keeps no image of it
            return
        dets = [d.detection for d in detected]
        colours = PALETTE[np.arange(len(dets)) % len(PALETTE)]
        labels = [f"{class_text(d)} {d.score:.2f}" for d in dets]
        self.rec.log(
            f"camera/{cam}/perception/boxes",
            rr.Boxes2D(
                array=[d.bbox for d in dets],
                array_format=rr.Box2DFormat.XYXY,
                labels=labels,
                colors=colours,
            ),
        )
        if self.frames.dense_logged(msg.stamp_ns):
            ids = np.zeros(image_shape, dtype=np.uint8)
            for i, d in enumerate(dets[:255]):
                ids[mask_of(d, image_shape)] = i + 1
            self.rec.log(f"camera/{cam}/perception/masks", rr.SegmentationImage(ids))
        world = f"world/perception/{cam}"
        points, point_colours = [], []
        for item, c in zip(detected, colours, strict=True):
            stride = -(-len(item.points_world) // MAX_LOG_POINTS)
            pts = item.points_world[:: max(stride, 1)]
            points.append(pts)
            point_colours.append(np.repeat(c[None], len(pts), axis=0))
        self.rec.log(
            f"{world}/points",
            rr.Points3D(
                np.vstack(points) if points else np.zeros((0, 3)),
                colors=np.vstack(point_colours) if point_colours else None,
                radii=0.004,
            ),
        )
        self.rec.log(
            f"{world}/centroids",
            rr.Points3D(
                [d.centroid_in_world for d in dets],
                labels=[
                    f"{class_text(d)} d={d.d_obj:.2f} m θ={math.degrees(d.theta_obj):.0f}°"
                    for d in dets
                ],
                colors=colours,
                radii=0.012,
            ),
        )
        self.rec.log(
            f"{world}/axes",
            rr.LineStrips3D(
                [_axis_segment(d) for d in dets],
                colors=colours,
                radii=0.003,
            ),
        )
