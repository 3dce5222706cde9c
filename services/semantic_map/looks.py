"""Was an artifact looked for at its mapped place? The frustum and depth test behind
`missing`.

A camera frame that carried detections *looked at* a mapped position when the point
projects inside the image (a margin in from the border), lies in front of the camera
within `max_range_m`, and the depth image around its pixel does not show something
nearer in front of it (an occluder: then the frame says nothing about the artifact). A
look that does not find the artifact counts a miss; `missing_after` misses in a row mark
it missing since that frame's stamp; a detection clears it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from common.camera import PinholeCamera
from common.geometry import FloatArray


def looks_at(
    camera: PinholeCamera,
    p_world: FloatArray,
    max_range_m: float,
    margin_px: int = 8,
    occluder_m: float = 0.15,
) -> bool:
    """Whether this frame (the camera with its depth image) would have seen an object at
    `p_world` (see the module doc)."""
    depth = camera.depth_image()
    p = camera.to_camera(p_world)[0]
    z = float(p[2])
    if z < 0.2 or float(np.linalg.norm(p)) > max_range_m:
        return False
    uv, _ = camera.project(p)
    u, v = float(uv[0, 0]), float(uv[0, 1])
    h, w = depth.shape
    if not (margin_px <= u < w - margin_px and margin_px <= v < h - margin_px):
        return False
    iu, iv = round(u), round(v)
    patch = depth[max(iv - 2, 0) : iv + 3, max(iu - 2, 0) : iu + 3]
    valid = patch[patch > 0]
    if valid.size == 0:
        return True  # no return at all: nothing in front, and nothing there either
    return float(np.median(valid)) >= z - occluder_m


def sees_over(
    camera: PinholeCamera, points_world: FloatArray, margin_px: int = 2, beyond_m: float = 0.1
) -> NDArray[np.bool_]:
    """Which points (N, 3; world) this frame sees past: in front of the camera, inside the
    picture (`margin_px` in from its border), and its depth there at least `beyond_m`
    farther than the point (no return: nothing there). A point just above a table's edge
    is seen past (the ray goes on to the floor or a wall behind); one just above the
    highest point a frame saw of a wall is not (out of the picture, or on the wall
    itself). The tops layer's test (`Occupancy.integrate`)."""
    depth = camera.depth_image()
    h, w = depth.shape
    uv, z = camera.project_world(points_world)
    u, v = uv[:, 0], uv[:, 1]
    inside = (z > 0.0) & (u >= margin_px) & (u < w - margin_px) & (v >= margin_px)
    inside &= v < h - margin_px  # NaN (behind the camera) compares False
    out = np.zeros(len(z), bool)
    k = np.flatnonzero(inside)
    d = depth[np.round(v[k]).astype(np.intp), np.round(u[k]).astype(np.intp)]
    out[k] = (d <= 0.0) | (d >= z[k] + beyond_m)
    return out
