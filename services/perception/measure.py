"""One instance's measurement: masked depth → points → frames → centroid, d_obj, θ_obj, axis.

`measure(frame_geometry, depth, mask, origin, class_name)` chains `geometry`: eq. 1 in the
camera frame (`common.camera.backproject`), the outlier gate there (depth bleed shows
along the optical axis), then the inliers through `T_base_camera` to `base` and
`base_yaw`, where, for upright objects (bottles, cans, boxes), the mask's bleed onto their
support is dropped (`support`), and a mask that is all support (flat: no upright
object) is no measurement; the centroid of what is left gives eq. 2 (d_obj, θ_obj)
and, through `T_world_base`, the world position, and the class's upright fit in
`base_yaw` (z up) is carried to the world. `FrameGeometry` holds what a `CameraFrame`
says about its geometry, as numpy.

The shape check (`ShapeCheck`): near the camera, whether a can or a box is a cylinder is
told better by its depth than by its look. The network reads a small box seen square-on
as a can (hall seed 0's 9 x 6 x 13 cm box from 0.78 m: can 0.62-0.73 in every frame)
and a can as a box at times; a can's points fit a cylinder to the depth noise, a box's
do not. So a can or box within `range_m` of the camera whose cylinder fit (not a
fallback: enough arc to fit) lies within `rms_per_m2` × depth² of its points is a can,
and beyond it a box, whatever the network said; the measurement keeps the network's
class beside it (`network_class`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.camera import PinholeCamera, backproject
from common.geometry import BoolArray, FloatArray, transform_points, wrap_angle, yaw_of, yaw_only
from services.perception.fits import UprightFit, body_axis, fit_upright
from services.perception.geometry import (
    CLASS_SHAPES,
    T_base_yaw_base,
    depth_inliers,
    heading,
    robust_inliers,
)
from services.perception.support import support_inliers

#: Fewer valid points than this: no measurement (a sliver of mask or no depth).
MIN_POINTS = 8
#: Rounds of the depth-gap and support gates (`object_inliers`).
GATE_ROUNDS = 3
#: An upright object's points span at least this in height, m; less is a flat patch
#: (a strip of table top the network called a bottle beside the real one: its centroid
#: 0.25 m behind it along the line of sight made a second bottle in the map, hall seed
#: 1's shift). Every real artifact the bench's renders show spans 3.3 cm or more.
MIN_UPRIGHT_HEIGHT_M = 0.02


@dataclass(frozen=True)
class ShapeCheck:
    """The can/box shape check (see the module docstring; `perception.shape_check_*`).

    range_m: checked only this near the camera (the centroid's depth, m); rms_per_m2:
    the cylinder fit's rms bound at 1 m depth, m (it grows as the depth squared, as a
    stereo sensor's noise does)."""

    range_m: float
    rms_per_m2: float
    classes: tuple[str, str] = ("can", "box")

    def judge(self, cylinder: UprightFit, depth_m: float) -> str | None:
        """`can` or `box` by the cylinder fit of points at `depth_m`; None when it cannot
        tell (too far, or no circle fitted)."""
        if not 0.0 < depth_m <= self.range_m or cylinder.fallback:
            return None
        if not math.isfinite(cylinder.rms_m):
            return None
        can, box = self.classes
        return can if cylinder.rms_m <= self.rms_per_m2 * depth_m**2 else box


@dataclass(frozen=True)
class FrameGeometry:
    """A camera frame's geometry: intrinsics and the frames at capture (4×4 arrays).

    camera: the intrinsics (its pose is not read: the two frames below place the camera).
    """

    camera: PinholeCamera
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
    class_name: the instance's class after the shape check; network_class: the
    segmenter's, when the check changed it ("" otherwise).
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
    class_name: str = ""
    network_class: str = ""


def object_inliers(pts_cam: FloatArray, T_base_yaw_camera: FloatArray, upright: bool) -> BoolArray:
    """The points (camera frame) that are the object: depth-connected to its median depth
    (`geometry.robust_inliers`) and, for an upright object, not its support
    (`support.support_inliers`, in `base_yaw`). The two alternate until neither removes
    anything (at most `GATE_ROUNDS` rounds): once the table around a foot is gone, what
    it bridged in depth to the object (something behind) shows its gap."""
    if not upright:  # people and unknown classes: the depth-gap gate alone
        return robust_inliers(pts_cam)
    keep = np.ones(len(pts_cam), dtype=bool)
    for _ in range(GATE_ROUNDS):
        idx = np.flatnonzero(keep)
        ok = depth_inliers(pts_cam[idx, 2])
        kept = pts_cam[idx[ok]]
        on_object = support_inliers(transform_points(T_base_yaw_camera, kept), kept[:, 2])
        if on_object.sum() >= MIN_POINTS:  # else too little is left to judge: gap only
            ok[ok] = on_object
        keep[idx[~ok]] = False
        if ok.all():
            break
    return keep


def measure(
    geo: FrameGeometry,
    depth: npt.NDArray[np.floating],
    mask: BoolArray,
    origin: tuple[int, int],
    class_name: str,
    shape_check: ShapeCheck | None = None,
) -> Measurement | None:
    """The instance's geometry from its mask over `depth` (a crop at `origin`), or None
    when fewer than `MIN_POINTS` pixels have depth, or an upright object's points are flat
    (under `MIN_UPRIGHT_HEIGHT_M` tall: a patch of its support, all the gates left);
    with `shape_check`, a can's or a box's class by its shape near the camera (see the
    module docstring)."""
    pts_cam = backproject(depth, geo.camera, mask=mask, origin=origin)
    if len(pts_cam) < MIN_POINTS:
        return None
    T_by_c = geo.T_base_yaw_camera
    T_w_by = geo.T_world_base_yaw
    shape = CLASS_SHAPES.get(class_name, "centroid")
    keep = object_inliers(pts_cam, T_by_c, shape != "centroid")
    pts_by = transform_points(T_by_c, pts_cam[keep])
    if shape != "centroid" and float(np.ptp(pts_by[:, 2])) < MIN_UPRIGHT_HEIGHT_M:
        return None
    centroid_cam = pts_cam[keep].mean(axis=0)
    centroid_by = pts_by.mean(axis=0)
    d_obj, theta_obj = heading(centroid_by)
    eye_by = T_by_c[:3, 3]
    fit = fit_upright(pts_by, eye_by, shape)
    network_class = ""
    if shape_check is not None and class_name in shape_check.classes:
        cylinder = fit if shape == "cylinder" else fit_upright(pts_by, eye_by, "cylinder")
        by_shape = shape_check.judge(cylinder, float(centroid_cam[2]))
        if by_shape is not None and by_shape != class_name:
            network_class, class_name = class_name, by_shape
            shape = CLASS_SHAPES[class_name]
            fit = cylinder if shape == "cylinder" else fit_upright(pts_by, eye_by, shape)
    if class_name == "person":
        fit = body_axis(fit, eye_by)
    base_yaw_in_world = yaw_of(T_w_by[:3, :3])
    return Measurement(
        centroid_camera=centroid_cam,
        centroid_base_yaw=centroid_by,
        centroid_world=transform_points(T_w_by, centroid_by)[0],
        d_obj=d_obj,
        theta_obj=theta_obj,
        fit_base_yaw=fit,
        axis_base_yaw=fit.axis,
        axis_world=transform_points(T_w_by, fit.axis)[0],
        yaw_world=wrap_angle(fit.yaw + base_yaw_in_world),
        points_world=transform_points(T_w_by, pts_by),
        n_points=int(keep.sum()),
        n_outliers=int((~keep).sum()),
        class_name=class_name,
        network_class=network_class,
    )
