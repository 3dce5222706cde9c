"""One pinhole camera type and its maths: depth images → 3-D points → pixels.

`PinholeCamera` holds a depth camera's intrinsics, its pose in the world and, when at hand,
its depth image. `backproject` is the paper's eq. 1, `t = K⁻¹ [u v 1]ᵀ d`, for every
pixel of a depth image (or a crop of it) with a return; `PinholeCamera.project` is its
inverse. Perception (an instance's points), navigation (the short-lived obstacle layer)
and the map (learned obstacles, the missing test) all go through these. `stereo_depth`
is the depth a stereo sensor measures of a rendered one (the sim's cameras, and the
segmenter's training, which must see what the robot's camera gives it).

Conventions (those of `common.messages.sim.CameraFrame`):

- Camera frame: the OpenCV optical frame, z forward along the optical axis, x right,
  y down. `T_world_camera` (4×4) places it in the world: `p_world = R p_camera + t`.
- Pixels: (u, v) = (column, row), u to the right, v down; pixel centres at integer
  coordinates, so `depth[v, u]` is the depth at pixel (u, v). fx, fy (focal lengths) and
  cx, cy (principal point) are in pixels.
- Depth: metres along the optical axis (a point's camera-frame z, not its distance along
  the ray); 0, a negative value or a non-finite one (NaN, ±inf) is no return.
- Points: (N, 3) float64 arrays, metres, in the frame their name says; pixels (N, 2)
  float64 (u, v).

Pure numpy: values in, values out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from common.geometry import BoolArray, FloatArray, inv_T, transform_points

#: A depth image (H, W): metres along the optical axis, 0 or non-finite = no return.
DepthImage = npt.NDArray[np.floating[Any]]


def _identity() -> FloatArray:
    return np.eye(4)


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """A pinhole depth camera (see the module doc for frames and units).

    fx, fy, cx, cy: intrinsics, px. T_world_camera: (4, 4) the optical frame in the world;
    the identity where a caller works in the camera frame alone (perception places its
    points through the frames of the capture). depth: (H, W) metres, or None when no
    image comes with the camera (perception passes its crops to `backproject`).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    T_world_camera: FloatArray = field(default_factory=_identity)
    depth: DepthImage | None = None

    def depth_image(self) -> DepthImage:
        """The depth image (H, W); ValueError when this camera carries none."""
        if self.depth is None:
            raise ValueError("this camera carries no depth image")
        return self.depth

    @property
    def T_camera_world(self) -> FloatArray:
        """The world in the camera's optical frame (the inverse of `T_world_camera`)."""
        return inv_T(self.T_world_camera)

    def unproject(self, uv: npt.ArrayLike, depth: npt.ArrayLike) -> FloatArray:
        """Eq. 1 for pixels (N, 2) (u, v) at depths (N,) m: (N, 3) points in the camera
        frame (x = (u − cx) / fx · d, y = (v − cy) / fy · d, z = d)."""
        uv = np.atleast_2d(np.asarray(uv, dtype=float))
        z = np.asarray(depth, dtype=float).reshape(-1)
        return np.column_stack(
            [(uv[:, 0] - self.cx) / self.fx * z, (uv[:, 1] - self.cy) / self.fy * z, z]
        )

    def project(self, points_camera: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Eq. 1 inverted: pixels (N, 2) (u, v), not rounded nor clipped to the image, and
        depths (N,) m (the points' z) of camera-frame points (N, 3) or one (3,). A point not
        in front of the camera (z ≤ 0) has no pixel: NaN."""
        p = np.atleast_2d(np.asarray(points_camera, dtype=float))
        z = p[:, 2].copy()
        front = z > 0.0
        uv = np.full((len(p), 2), np.nan)
        uv[front, 0] = self.fx * p[front, 0] / z[front] + self.cx
        uv[front, 1] = self.fy * p[front, 1] / z[front] + self.cy
        return uv, z

    def to_world(self, points_camera: npt.ArrayLike) -> FloatArray:
        """Camera-frame points (N, 3) or one (3,) → (N, 3) in the world."""
        return transform_points(self.T_world_camera, points_camera)

    def to_camera(self, points_world: npt.ArrayLike) -> FloatArray:
        """World points (N, 3) or one (3,) → (N, 3) in the camera frame."""
        return transform_points(self.T_camera_world, points_world)

    def project_world(self, points_world: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """`project` of world points (N, 3) or one (3,): pixels (N, 2) and depths (N,)."""
        return self.project(self.to_camera(points_world))

    def points_world(
        self,
        *,
        mask: BoolArray | None = None,
        stride: int = 1,
        min_depth_m: float = 0.0,
        max_depth_m: float = math.inf,
    ) -> FloatArray:
        """`backproject` of this camera's depth image (the same arguments), carried to the
        world: (N, 3) points, in row-major pixel order."""
        pts = backproject(
            self.depth_image(),
            self,
            mask=mask,
            stride=stride,
            min_depth_m=min_depth_m,
            max_depth_m=max_depth_m,
        )
        return self.to_world(pts)


def valid_depth(
    depth: npt.ArrayLike, min_depth_m: float = 0.0, max_depth_m: float = math.inf
) -> BoolArray:
    """Which pixels (H, W) have a return with min_depth_m < depth < max_depth_m (strict at
    both ends; NaN and ±inf never pass). The defaults keep every return (depth > 0)."""
    d = np.asarray(depth, dtype=np.float64)
    return np.asarray(np.isfinite(d) & (d > min_depth_m) & (d < max_depth_m))


def backproject(
    depth: npt.ArrayLike,
    camera: PinholeCamera,
    *,
    mask: BoolArray | None = None,
    origin: tuple[int, int] = (0, 0),
    stride: int = 1,
    min_depth_m: float = 0.0,
    max_depth_m: float = math.inf,
) -> FloatArray:
    """Eq. 1 for the pixels of `depth` with a return: (N, 3) points in the camera frame,
    in row-major pixel order (only the camera's intrinsics are used).

    depth: (H, W) m along the optical axis: the whole image, or a crop of it whose
    `depth[0, 0]` is pixel `origin` = (u0, v0) of the image. mask: (H, W) bool, the pixels
    to take (None: all). stride: every `stride`-th pixel in u and in v from `depth[0, 0]`
    (1: all). A pixel is taken where `valid_depth(depth, min_depth_m, max_depth_m)` and
    the mask hold.
    """
    d_full = np.asarray(depth, dtype=np.float64)
    if mask is not None and mask.shape != d_full.shape:
        raise ValueError(f"mask shape {mask.shape} differs from depth shape {d_full.shape}")
    if stride < 1:
        raise ValueError(f"stride {stride} is not a positive number of pixels")
    d = d_full[::stride, ::stride]
    valid = valid_depth(d, min_depth_m, max_depth_m)
    if mask is not None:
        valid &= mask[::stride, ::stride].astype(bool)
    v, u = np.nonzero(valid)
    uv = np.column_stack([u * stride + origin[0], v * stride + origin[1]])
    return camera.unproject(uv, d[v, u])


def stereo_depth(
    depth: np.ndarray,
    sigma_per_m2: float,
    edge_jump_m: float,
    dropout: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """A rendered depth image (m, 0 = no return) as a stereo sensor measures it: σ(z) =
    `sigma_per_m2` z² noise, no return on the farther side of a jump of more than
    `edge_jump_m` between neighbours (the occlusion band beside a nearer edge; the nearer
    surface keeps its depth) and a `dropout` share of pixels lost; same dtype."""
    z = depth.astype(np.float64)
    valid = z > 0.0
    far = np.where(valid, z, np.inf)  # no return: farther than anything
    edge = np.zeros_like(valid)
    with np.errstate(invalid="ignore"):  # inf − inf between two no-returns: no jump
        dx, dy = np.diff(far, axis=1), np.diff(far, axis=0)
    edge[:, 1:] |= dx > edge_jump_m  # the right one is farther
    edge[:, :-1] |= dx < -edge_jump_m
    edge[1:, :] |= dy > edge_jump_m
    edge[:-1, :] |= dy < -edge_jump_m
    noisy = z + rng.normal(0.0, 1.0, z.shape) * (sigma_per_m2 * z * z)
    lost = rng.random(z.shape) < dropout
    keep = valid & ~edge & ~lost & (noisy > 0.0)
    return np.where(keep, noisy, 0.0).astype(depth.dtype)
