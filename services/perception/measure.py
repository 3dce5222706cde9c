"""One instance's measurement: masked depth → points → frames → centroid, d_obj, θ_obj, axis.

`measure(frame_geometry, depth, mask, origin, class_name)` chains `geometry`: eq. 1 in the
camera frame, the outlier gate there (depth bleed shows along the optical axis), then the
inliers through `T_base_camera` to `base`, `base_yaw` (eq. 2: d_obj, θ_obj) and the world
(`T_world_base`), and the class's upright fit in `base_yaw` (z up), carried to the world.
`FrameGeometry` holds what a `CameraFrame` says about its geometry, as numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.geometry import FloatArray, wrap_angle, yaw_only
from services.perception.fits import UprightFit, fit_upright
from services.perception.geometry import (
    CLASS_SHAPES,
    BoolArray,
    Intrinsics,
    T_base_yaw_base,
    backproject,
    heading,
    robust_centroid,
    transform,
)

#: Fewer valid points than this: no measurement (a sliver of mask or no depth).
MIN_POINTS = 8


@dataclass(frozen=True)
class FrameGeometry:
    """A camera frame's geometry: intrinsics and the frames at capture (4×4 arrays)."""

    K: Intrinsics
    T_base_camera: FloatArray
    T_world_base: FloatArray

    @property
    def T_base_yaw_camera(self) -> FloatArray:
        return np.asarray(T_base_yaw_base(self.T_world_base) @ self.T_base_camera)

    @property
    def T_world_base_yaw(self) -> FloatArray:
        return yaw_only(self.T_world_base)


@dataclass(frozen=True)
class Measurement:
    """What the geometry says about one instance.

    centroid_camera, centroid_base_yaw, centroid_world: (3,) m, robust visible centroid.
    d_obj, theta_obj: eq. 2 in base_yaw (m, rad). fit_base_yaw: the upright fit in
    base_yaw; axis_world: (3,) its axis point in the world; yaw_world: its yaw there.
    points_world: (N, 3) the inlier points (for logging). n_points, n_outliers: counts.
    """

    centroid_camera: FloatArray
    centroid_base_yaw: FloatArray
    centroid_world: FloatArray
    d_obj: float
    theta_obj: float
    fit_base_yaw: UprightFit
    axis_base_yaw: FloatArray
    axis_world: FloatArray
    yaw_world: float
    points_world: FloatArray
    n_points: int
    n_outliers: int


def measure(
    geo: FrameGeometry,
    depth: npt.NDArray[np.floating],
    mask: BoolArray,
    origin: tuple[int, int],
    class_name: str,
) -> Measurement | None:
    """The instance's geometry from its mask over `depth` (a crop at `origin`), or None
    when fewer than `MIN_POINTS` pixels have depth."""
    pts_cam = backproject(depth, mask, geo.K, origin)
    if len(pts_cam) < MIN_POINTS:
        return None
    centroid_cam, keep = robust_centroid(pts_cam)
    inliers = pts_cam[keep]
    T_by_c = geo.T_base_yaw_camera
    T_w_by = geo.T_world_base_yaw
    pts_by = transform(T_by_c, inliers)
    centroid_by = pts_by.mean(axis=0)
    d_obj, theta_obj = heading(centroid_by)
    eye_by = T_by_c[:3, 3]
    fit = fit_upright(pts_by, eye_by, CLASS_SHAPES.get(class_name, "centroid"))
    base_yaw_in_world = float(np.arctan2(T_w_by[1, 0], T_w_by[0, 0]))
    return Measurement(
        centroid_camera=centroid_cam,
        centroid_base_yaw=centroid_by,
        centroid_world=transform(T_w_by, centroid_by)[0],
        d_obj=d_obj,
        theta_obj=theta_obj,
        fit_base_yaw=fit,
        axis_base_yaw=fit.axis,
        axis_world=transform(T_w_by, fit.axis)[0],
        yaw_world=wrap_angle(fit.yaw + base_yaw_in_world),
        points_world=transform(T_w_by, pts_by),
        n_points=int(keep.sum()),
        n_outliers=int((~keep).sum()),
    )
