"""What the localization shows in the recording, stamped on sim time: the map it matches
against (once), each scan over it where the match put it, the base's estimated pose
with its 2σ ellipse, and the status, confidence and covariance as time series."""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from common.geometry import FloatArray
from common.recording import stamp
from services.localization.localizer import Estimate
from services.localization.matcher import transform

COLOURS = {"ok": (40, 200, 80), "uncertain": (240, 170, 0), "lost": (230, 40, 40)}


class LocalizationLogger:
    def __init__(self, rec: rr.RecordingStream) -> None:
        self.rec = rec

    def map(self, occupied: np.ndarray, resolution: float, origin: tuple[float, float]) -> None:
        iy, ix = np.nonzero(occupied)
        pts = np.stack(
            [origin[0] + (ix + 0.5) * resolution, origin[1] + (iy + 0.5) * resolution], axis=1
        )
        self.rec.log(
            "world/localization/map",
            rr.Points3D(np.column_stack([pts, np.full(len(pts), 0.02)]), radii=0.02,
                        colors=(120, 120, 140)),
            static=True,
        )  # fmt: skip

    def slam(self, t_ns: int, keyframes: FloatArray, closures: list[tuple[int, int]]) -> None:
        """The SLAM's keyframes (n, 3: x, y, yaw) as its path, and its loop closures as
        lines between the two keyframes each ties."""
        stamp(self.rec, t_ns)
        z = np.full(len(keyframes), 0.06)
        self.rec.log(
            "world/localization/keyframes",
            rr.LineStrips3D([np.column_stack([keyframes[:, :2], z])], colors=(90, 160, 255),
                            radii=0.015),
        )  # fmt: skip
        if closures:
            ties = [[[*keyframes[i, :2], 0.08], [*keyframes[j, :2], 0.08]] for i, j in closures]
            self.rec.log(
                "world/localization/closures",
                rr.LineStrips3D(ties, colors=(255, 120, 0), radii=0.02),
            )

    def log(self, t_ns: int, est: Estimate, points_base: FloatArray) -> None:
        rec = self.rec
        stamp(rec, t_ns)
        colour = COLOURS.get(est.status, (150, 150, 150))
        ends = transform(points_base, est.map_base)
        rec.log(
            "world/localization/scan",
            rr.Points3D(np.column_stack([ends, np.full(len(ends), 0.45)]), radii=0.02,
                        colors=colour),
        )  # fmt: skip
        x, y, yaw = est.map_base
        cov = est.covariance[:2, :2]
        w, v = np.linalg.eigh(0.5 * (cov + cov.T))
        a = np.linspace(0.0, 2.0 * math.pi, 33)
        ring = v @ (2.0 * np.sqrt(np.maximum(w, 0.0))[:, None] * np.stack([np.cos(a), np.sin(a)]))
        rec.log(
            "world/localization/base",
            rr.LineStrips3D(
                [
                    np.column_stack([x + ring[0], y + ring[1], np.full(len(a), 0.05)]),
                    [[x, y, 0.05], [x + 0.4 * math.cos(yaw), y + 0.4 * math.sin(yaw), 0.05]],
                ],
                colors=colour,
                radii=0.01,
            ),
        )
        rec.log("plots/localization/confidence", rr.Scalars(est.confidence))
        rec.log("plots/localization/sigma_xy_m", rr.Scalars(float(np.sqrt(max(w.max(), 0.0)))))
        rec.log(
            "plots/localization/sigma_yaw_deg",
            rr.Scalars(math.degrees(math.sqrt(max(float(est.covariance[2, 2]), 0.0)))),
        )
        if est.refused:
            rec.log("log/localization", rr.TextLog(f"{est.status}: {est.refused}"))
