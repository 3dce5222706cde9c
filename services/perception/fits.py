"""An upright object's axis and extent from its points in a z-up frame (`base_yaw`).

- Cylinders (bottles, cans) are surfaces of revolution: per 1 cm height slab a circle, all
  with one centre, solved linearly (x² + y² = 2ax + 2by + c_k) then refined on the
  geometric residual, with trimming — a bottle's neck is just a smaller ring about the
  same axis. When the visible arc is too short to fit (or the fit is implausible: in
  front of the surface, or much wider or narrower than what shows), the axis is put one
  radius (half the visible width) behind the centroid along the line of sight.
- Boxes: the rectangle whose edges the points' footprint lies on (exact when two faces
  show; with one face the centre is on that face).
- Anything else: the centroid and the points' extent. A person's axis is that centroid
  moved `BODY_DEPTH_M` away from the eye along the line of sight (`body_axis`): a camera
  sees the near half of a body, whose centroid lies in front of the body's centre.

Pure numpy, used by `measure`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from common.geometry import BoolArray, FloatArray
from services.perception.geometry import MAD_TO_SIGMA, Shape, thin

#: Height of the slabs of a surface-of-revolution fit, m.
SLAB_M = 0.01
#: A ring needs this many points; fewer are merged into no ring (dropped from the fit).
MIN_RING_POINTS = 4
#: How far a person's centre lies behind the centroid of what a camera sees of them, m:
#: the sim's people seen by the head camera from 1.3, 2 and 3 m all round (hall seeds
#: 9001-9002, truth masks, 167 views): the centroid lay 6.4, 6.0 and 6.8 cm in front of
#: the person's axis (median; 10th percentile 12-14 cm), 1 cm across. Left uncorrected,
#: the robot stood that much too far for the handover, and the object held out ended
#: 16-23 cm from the hand that takes it within 25 cm: the first try failed one fetch in
#: four on the small world's soak.
BODY_DEPTH_M = 0.06


@dataclass(frozen=True)
class UprightFit:
    """An object's vertical axis and size in a z-up frame.

    axis: (3,) m, the axis at the middle of the points' height (x, y on the axis).
    extent: (3,) m, size along the fit's own x, y and z (cylinders: 2r, 2r, height).
    yaw: rad, the fit's x axis about z (boxes; 0 otherwise). radius: m (cylinders; 0
    otherwise). shape: which fit. rms_m: geometric residual of the points, m.
    fallback: the arc was too short for a circle fit (axis from the line of sight).
    """

    axis: FloatArray
    extent: FloatArray
    yaw: float
    radius: float
    shape: Shape
    rms_m: float
    fallback: bool = False


def _z_range(z: FloatArray) -> tuple[float, float]:
    return float(np.min(z)), float(np.max(z))


class _Arrow(NamedTuple):
    """Normal equations M x = v whose M = [[A, B], [Bᵀ, diag(d)]] is an arrow matrix
    (A 2×2, B 2×n, d (n,) > 0): those of a concentric-rings Jacobian (`_ring_normal`)."""

    A: FloatArray
    B: FloatArray
    d: FloatArray
    v: FloatArray

    def dense(self) -> FloatArray:
        n = len(self.d)
        M = np.zeros((2 + n, 2 + n))
        M[:2, :2] = self.A
        M[:2, 2:] = self.B
        M[2:, :2] = self.B.T
        M[np.arange(2, 2 + n), np.arange(2, 2 + n)] = self.d
        return M

    def lstsq(self) -> FloatArray:
        """The least-squares solution, by the Schur complement of the diagonal block
        (O(n), where the dense SVD is O(n³) and most of a cylinder fit's time); the dense
        least squares itself when that 2×2 complement is near singular."""
        Bd = self.B / self.d
        S = self.A - Bd @ self.B.T
        r = self.v[:2] - Bd @ self.v[2:]
        a, b, c = float(S[0, 0]), 0.5 * float(S[0, 1] + S[1, 0]), float(S[1, 1])
        hi = 0.5 * (a + c) + math.hypot(0.5 * (a - c), b)  # its eigenvalues: hi, det / hi
        det = a * c - b * b
        # S is A less nearly all of it when the rings' arcs are short: its small eigenvalue
        # is then round-off of A's size, and M nearly singular (the dense SVD truncates)
        scale = max(float(self.A[0, 0] + self.A[1, 1]), float(self.d.max()))
        if not (hi > 0.0 and det > 1e-8 * scale * hi):
            return np.asarray(np.linalg.lstsq(self.dense(), self.v, rcond=None)[0])
        x = np.array([(c * r[0] - b * r[1]) / det, (a * r[1] - b * r[0]) / det])
        return np.concatenate([x, (self.v[2:] - self.B.T @ x) / self.d])


def _ring_normal(
    u: FloatArray,
    s: float,
    rings: npt.NDArray[np.int_],
    counts: npt.NDArray[np.int_],
    rhs: FloatArray,
) -> _Arrow:
    """JᵀJ and Jᵀ·rhs of a concentric-rings Jacobian whose row i is [uᵢ (2), s·e_ring(i)]
    (`counts`: points per ring), summed per ring with `bincount` (O(points))."""
    n = len(counts)
    B = np.stack([s * np.bincount(rings, weights=u[:, j], minlength=n) for j in (0, 1)])
    v = np.concatenate([u.T @ rhs, s * np.bincount(rings, weights=rhs, minlength=n)])
    return _Arrow(u.T @ u, B, np.asarray(s * s * counts, dtype=float), v)


def _fit_rings(
    xy: FloatArray, rings: npt.NDArray[np.int_], n: int
) -> tuple[FloatArray, FloatArray] | None:
    """Common centre (2,) and per-ring radii (n,): algebraic, then Gauss-Newton geometric.

    Algebraic: [2x 2y e_k] [a b c_k]ᵀ = x² + y² (concentric circles, linear)."""
    counts = np.bincount(rings, minlength=n)
    algebraic = _ring_normal(2.0 * xy, 1.0, rings, counts, np.sum(xy * xy, axis=1))
    normal = algebraic.dense()
    if np.linalg.cond(normal) > 1e14:  # the arc is too short to locate a centre
        return None
    sol = np.linalg.solve(normal, algebraic.v)
    centre = sol[:2]
    r2 = sol[2:] + centre @ centre
    if np.any(r2 <= 0.0):
        return None
    radii = np.sqrt(r2)
    for _ in range(10):  # geometric refinement: residual |p - c| - r_k
        diff = xy - centre
        dist = np.maximum(np.linalg.norm(diff, axis=1), 1e-9)
        res = dist - radii[rings]
        step = _ring_normal(diff / dist[:, None], 1.0, rings, counts, res).lstsq()
        centre = centre + step[:2]
        radii = radii + step[2:]
        if np.linalg.norm(step) < 1e-7:
            break
    if np.any(radii <= 0.0):
        return None
    return np.asarray(centre, dtype=float), np.asarray(radii, dtype=float)


def _trimmed_rings(
    xy: FloatArray, ring_of: npt.NDArray[np.int_], keep: BoolArray, rounds: int
) -> tuple[FloatArray, FloatArray, float] | None:
    """Concentric rings fitted to the kept points, refitted without the points farther
    than max(3 σ_MAD, 2 mm) from their ring, up to `rounds` times: centre, radii, rms."""
    best: tuple[FloatArray, FloatArray, float] | None = None
    idx = np.flatnonzero(keep)
    for _ in range(rounds + 1):
        if len(idx) < 6:
            break
        # the kept points' rings renumbered 0.. in order (np.unique's inverse, by counting)
        present = np.bincount(ring_of[idx]) > 0
        rings = (np.cumsum(present) - 1)[ring_of[idx]]
        xy_kept = xy[idx]
        fit = _fit_rings(xy_kept, rings, int(np.count_nonzero(present)))
        if fit is None:
            break
        centre, radii = fit
        res = np.linalg.norm(xy_kept - centre, axis=1) - radii[rings]
        best = (centre, radii, float(np.sqrt(np.mean(res * res))))
        gate = max(3.0 * MAD_TO_SIGMA * float(np.median(np.abs(res))), 0.002)
        out = np.abs(res) > gate
        if not out.any():
            break
        idx = idx[~out]
    return best


def _line_of_sight_axis(
    xy: FloatArray, centroid_xy: FloatArray, eye_xy: FloatArray
) -> tuple[FloatArray, float]:
    """The axis one radius behind the centroid, the radius half the visible width."""
    sight = centroid_xy - eye_xy
    sight = sight / max(float(np.linalg.norm(sight)), 1e-9)
    across = np.array([-sight[1], sight[0]])
    s = (xy - centroid_xy) @ across
    if len(s) < 2:
        return centroid_xy, 0.0
    hi, lo = np.percentile(s, [98, 2])
    radius = 0.5 * float(hi - lo)
    return centroid_xy + radius * sight, radius


def fit_cylinder(points: FloatArray, eye: npt.ArrayLike, trim_rounds: int = 2) -> UprightFit:
    """Upright surface of revolution through the points (z up); `eye` is the camera."""
    points = thin(points)
    xy_all, z = points[:, :2], points[:, 2]
    z0, z1 = _z_range(z)
    ref = xy_all.mean(axis=0)  # conditioning: fit about the points' mean
    xy = xy_all - ref
    eye_xy = np.asarray(eye, dtype=float)[:2] - ref
    slab = np.floor((z - z0) / SLAB_M).astype(int)
    _, ring_of, counts = np.unique(slab, return_inverse=True, return_counts=True)
    fit = _trimmed_rings(xy, ring_of, counts[ring_of] >= MIN_RING_POINTS, trim_rounds)
    mid_z = 0.5 * (z0 + z1)
    fallback_centre, width_radius = _line_of_sight_axis(xy, xy.mean(axis=0), eye_xy)
    if fit is not None:
        centre, radii, rms = fit
        radius = float(np.percentile(radii, 90))  # the body's rings, not a bottle's neck
        # the axis lies behind the visible surface, and the ring is about as wide as it shows
        behind = np.dot(centre - xy.mean(axis=0), xy.mean(axis=0) - eye_xy) > 0.0
        plausible = 0.5 * width_radius <= radius <= 2.0 * max(width_radius, 1e-3)
        if behind and plausible:
            return UprightFit(
                axis=np.array([*(centre + ref), mid_z]),
                extent=np.array([2 * radius, 2 * radius, z1 - z0]),
                yaw=0.0,
                radius=radius,
                shape="cylinder",
                rms_m=rms,
            )
    return UprightFit(
        axis=np.array([*(fallback_centre + ref), mid_z]),
        extent=np.array([2 * width_radius, 2 * width_radius, z1 - z0]),
        yaw=0.0,
        radius=width_radius,
        shape="cylinder",
        rms_m=float("nan"),
        fallback=True,
    )


def fit_box(points: FloatArray) -> UprightFit:
    """Upright box: the rectangle whose edges the points' footprint lies on (z up).

    The visible side faces lie on the footprint's edges, so the yaw minimises the points'
    distance to the nearest edge of their bounding rectangle at that yaw (the minimal
    area alone is ambiguous for an L: a rectangle along the hypotenuse has the same area).
    Points of the top face (within 1 cm of the highest) are left out of that residual.
    """
    points = thin(points, 800)
    xy, z = points[:, :2], points[:, 2]
    z0, z1 = _z_range(z)
    centre0 = xy.mean(axis=0)
    d = xy - centre0
    sides = z < z1 - 0.01
    d_sides = d[sides] if sides.sum() >= 6 else d

    def edge_rms(angles: FloatArray) -> FloatArray:
        """Per angle: rms distance of the side points to their bounding rectangle's edges."""
        c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
        lx, ly = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c  # (angles, points)
        sx, sy = d_sides[:, 0] * c + d_sides[:, 1] * s, -d_sides[:, 0] * s + d_sides[:, 1] * c
        edge = np.minimum.reduce(
            [
                sx - lx.min(axis=1, keepdims=True),
                lx.max(axis=1, keepdims=True) - sx,
                sy - ly.min(axis=1, keepdims=True),
                ly.max(axis=1, keepdims=True) - sy,
            ]
        )
        return np.asarray(np.sqrt(np.mean(edge * edge, axis=1)))

    coarse = np.deg2rad(np.arange(0.0, 90.0, 2.0))
    best = coarse[int(np.argmin(edge_rms(coarse)))]
    fine = best + np.deg2rad(np.arange(-2.0, 2.01, 0.1))
    rms = edge_rms(fine)
    yaw = float(fine[int(np.argmin(rms))])
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    local = d @ rot  # coordinates along the rectangle's axes
    lo, hi = np.percentile(local, [1, 99], axis=0)
    centre = centre0 + rot @ (0.5 * (lo + hi))
    return UprightFit(
        axis=np.array([*centre, 0.5 * (z0 + z1)]),
        extent=np.array([hi[0] - lo[0], hi[1] - lo[1], z1 - z0]),
        yaw=float((yaw + math.pi / 2) % math.pi - math.pi / 2),
        radius=0.0,
        shape="box",
        rms_m=float(rms.min()),
    )


def fit_centroid(points: FloatArray) -> UprightFit:
    """No shape model: the centroid with the points' extent (2nd to 98th percentile)."""
    lo, hi = np.percentile(points, [2, 98], axis=0)
    return UprightFit(
        axis=points.mean(axis=0),
        extent=hi - lo,
        yaw=0.0,
        radius=0.0,
        shape="centroid",
        rms_m=0.0,
    )


def body_axis(fit: UprightFit, eye: npt.ArrayLike) -> UprightFit:
    """A person's fit (`fit_centroid`) with its axis moved `BODY_DEPTH_M` away from `eye`
    (horizontally, along the line of sight; unchanged when the eye is above it)."""
    away = fit.axis[:2] - np.asarray(eye, dtype=float)[:2]
    norm = float(np.hypot(*away))
    if norm < 1e-6:
        return fit
    axis = fit.axis.copy()
    axis[:2] += BODY_DEPTH_M * away / norm
    return replace(fit, axis=axis)


def fit_upright(points: FloatArray, eye: npt.ArrayLike, shape: Shape) -> UprightFit:
    """The fit for `shape` of points in a z-up frame seen from `eye`."""
    if shape == "cylinder":
        return fit_cylinder(points, eye)
    if shape == "box":
        return fit_box(points)
    return fit_centroid(points)
