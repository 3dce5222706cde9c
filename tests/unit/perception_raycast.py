"""An exact depth renderer for perception's tests: rays against analytic shapes.

Each pixel's ray through its centre, `[(u − cx)/fx, (v − cy)/fy, 1]` in the OpenCV optical
frame, scaled by s lands at depth s: so the renderer's depth is exactly what eq. 1 inverts,
computed without eq. 1. Shapes are in the world frame: planes, upright cylinders (with a
top cap) and upright boxes. `render` returns depth (0 = no hit), the label of the nearest
shape per pixel (0 = none) and the exact hit points in the world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.geometry import FloatArray, rot_z

INF = np.inf


@dataclass(frozen=True)
class Plane:
    point: tuple[float, float, float]
    normal: tuple[float, float, float]

    def hit(self, o: FloatArray, d: FloatArray) -> FloatArray:
        n = np.asarray(self.normal, dtype=float)
        denom = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((np.asarray(self.point) - o) @ n) / denom
        return np.where((np.abs(denom) > 1e-12) & (s > 0), s, INF)


@dataclass(frozen=True)
class UprightCylinder:
    centre_xy: tuple[float, float]
    radius: float
    z0: float
    z1: float

    def hit(self, o: FloatArray, d: FloatArray) -> FloatArray:
        oc = o[:2] - np.asarray(self.centre_xy)
        dxy = d[:, :2]
        a = np.sum(dxy * dxy, axis=1)
        b = 2.0 * dxy @ oc
        c = oc @ oc - self.radius**2
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            s_side = (-b - np.sqrt(disc)) / (2 * a)
        z = o[2] + s_side * d[:, 2]
        side_ok = (disc >= 0) & (s_side > 0) & (z >= self.z0) & (z <= self.z1)
        s_side = np.where(side_ok, s_side, INF)
        with np.errstate(divide="ignore", invalid="ignore"):
            s_top = (self.z1 - o[2]) / d[:, 2]
        p = o[:2] + s_top[:, None] * dxy
        top_ok = (s_top > 0) & (
            np.sum((p - np.asarray(self.centre_xy)) ** 2, axis=1) <= self.radius**2
        )
        return np.minimum(s_side, np.where(top_ok, s_top, INF))


@dataclass(frozen=True)
class UprightBox:
    centre: tuple[float, float, float]
    half_size: tuple[float, float, float]
    yaw: float

    def hit(self, o: FloatArray, d: FloatArray) -> FloatArray:
        R = rot_z(self.yaw)
        ol = R.T @ (o - np.asarray(self.centre))
        dl = d @ R  # rows: R.T @ d
        h = np.asarray(self.half_size)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - ol) / dl
            t2 = (h - ol) / dl
        tmin = np.nanmax(np.minimum(t1, t2), axis=1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=1)
        return np.where((tmax >= tmin) & (tmin > 0), tmin, INF)


Shape = Plane | UprightCylinder | UprightBox


def render(
    shapes: list[Shape],
    T_world_camera: FloatArray,
    K: tuple[float, float, float, float],
    width: int,
    height: int,
) -> tuple[FloatArray, np.ndarray, FloatArray]:
    """(depth (H, W), labels (H, W) int, world hit points (H, W, 3)) of the shapes."""
    fx, fy, cx, cy = K
    v, u = np.mgrid[0:height, 0:width]
    rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u, dtype=float)], axis=-1)
    rays = rays.reshape(-1, 3)
    R, o = T_world_camera[:3, :3], T_world_camera[:3, 3]
    d_world = rays @ R.T
    best = np.full(len(rays), INF)
    labels = np.zeros(len(rays), dtype=np.int32)
    for k, shape in enumerate(shapes, start=1):
        s = shape.hit(o, d_world)
        closer = s < best
        best[closer] = s[closer]
        labels[closer] = k
    hit = np.isfinite(best)
    depth = np.where(hit, best, 0.0)
    points = o + np.where(hit, best, 0.0)[:, None] * d_world
    return (
        depth.reshape(height, width),
        labels.reshape(height, width),
        points.reshape(height, width, 3),
    )
