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

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from common.geometry import FloatArray, inv_T


@dataclass(frozen=True)
class View:
    """One camera frame's geometry: T_world_camera (4×4), intrinsics, size, depth (m, 0 = no
    return) or None when the depth image is not at hand."""

    T_world_camera: FloatArray
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    depth: NDArray[np.float32] | None = None


def looks_at(
    view: View,
    p_world: FloatArray,
    max_range_m: float,
    margin_px: int = 8,
    occluder_m: float = 0.15,
) -> bool:
    """Whether this frame would have seen an object at `p_world` (see the module doc)."""
    p = inv_T(view.T_world_camera) @ np.append(np.asarray(p_world, float), 1.0)
    z = float(p[2])
    if z < 0.2 or float(np.linalg.norm(p[:3])) > max_range_m:
        return False
    u = view.fx * p[0] / z + view.cx
    v = view.fy * p[1] / z + view.cy
    if not (margin_px <= u < view.width - margin_px and margin_px <= v < view.height - margin_px):
        return False
    if view.depth is None:
        return True
    iu, iv = round(u), round(v)
    patch = view.depth[max(iv - 2, 0) : iv + 3, max(iu - 2, 0) : iu + 3]
    valid = patch[patch > 0]
    if valid.size == 0:
        return True  # no return at all: nothing in front, and nothing there either
    return float(np.median(valid)) >= z - occluder_m
