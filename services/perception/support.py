"""Mask pixels that bled onto the surface an object stands on, found in 3D.

A mask's boundary pixels often land on the table top around the object's foot: they are
depth-continuous with the object (so the depth-gap gate of `geometry.robust_inliers`
keeps them) but lie at the support's height, outside the object's footprint. An upright
object (bottle, can, box) has vertical walls: every point of its own near its foot has
points of the object above it, within the footprint of its upper part. So, in a z-up
frame: the points higher than `band_m` above the low end of the points (the 2nd
percentile of their heights: the support's height, or the object's foot when no table
pixel is in the mask) draw the footprint (their convex hull, grown by `margin_m`), and a
point in the low band outside it is the support (table top, or a table's front face
below it), rejected. The upper points are gated on depth first, so that a background the
table top bridged to the object in depth does not widen the footprint. Clean data loses
nothing: its low points are under its own walls (sparse far objects may lose a point or
two of their foot, a fraction of a millimetre on the centroid).

Pure numpy + OpenCV's convex hull; `measure` calls it in `base_yaw`.
"""

from __future__ import annotations

import cv2
import numpy as np

from common.geometry import BoolArray, FloatArray
from services.perception.geometry import depth_inliers

#: Points within this height of the low end are the band tested against the footprint, m.
SUPPORT_BAND_M = 0.01
#: A band point this close outside the upper part's footprint is still the object's, m.
FOOTPRINT_MARGIN_M = 0.003
#: The footprint needs this many upper points (fewer: nothing is rejected).
MIN_UPPER_POINTS = 12


def outside_hull_m(xy: FloatArray, hull_xy: FloatArray) -> FloatArray:
    """How far each point (N, 2) lies outside the convex polygon `hull_xy` (M, 2), m.

    The largest signed distance to the lines of the polygon's edges: ≤ 0 inside, and for
    a point outside a lower bound of its distance to the polygon (exact off an edge's
    middle). A polygon of fewer than 3 vertices contains nothing: +inf everywhere.
    """
    if len(hull_xy) < 3:
        return np.full(len(xy), np.inf)
    a, b = hull_xy, np.roll(hull_xy, -1, axis=0)
    edge = b - a
    length = np.linalg.norm(edge, axis=1)
    ok = length > 1e-12
    a, edge, length = a[ok], edge[ok], length[ok]
    normal = np.column_stack([edge[:, 1], -edge[:, 0]]) / length[:, None]
    # orient every normal outwards (away from the polygon's mean)
    inward = np.sum((hull_xy.mean(axis=0) - a) * normal, axis=1)
    normal = np.where((inward > 0)[:, None], -normal, normal)
    offset = np.sum(a * normal, axis=1)
    return np.asarray((xy @ normal.T - offset).max(axis=1))


def footprint_hull(xy: FloatArray) -> FloatArray:
    """The convex hull (M, 2) of points (N, 2), its vertices in order."""
    hull = cv2.convexHull(np.ascontiguousarray(xy, dtype=np.float32), clockwise=False)
    return np.asarray(hull, dtype=float).reshape(-1, 2)


def support_inliers(
    points: FloatArray,
    depth: FloatArray,
    band_m: float = SUPPORT_BAND_M,
    margin_m: float = FOOTPRINT_MARGIN_M,
) -> BoolArray:
    """The points (N, 3, z up) that are not the support under an upright object.

    depth: (N,) m, the points' depth along the camera's optical axis. The upper points are
    first gated on their own depth (`geometry.robust_inliers`): with the support's band
    set aside, a background the table top bridged to the object in depth (a wall behind
    the table) is split off, so the footprint is the object's alone; those background
    points are rejected too.
    """
    keep = np.ones(len(points), dtype=bool)
    if len(points) == 0:
        return keep
    z = points[:, 2]
    low = z < float(np.percentile(z, 2)) + band_m
    upper = np.flatnonzero(~low)
    if len(upper) < MIN_UPPER_POINTS or not low.any():
        return keep
    upper_ok = depth_inliers(depth[upper])
    if upper_ok.sum() < MIN_UPPER_POINTS:
        return keep
    keep[upper[~upper_ok]] = False
    hull = footprint_hull(points[upper[upper_ok], :2])
    keep[low] = outside_hull_m(points[low, :2], hull) <= margin_m
    return keep
