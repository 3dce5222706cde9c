"""Where the base is in the map, from one lidar scan: scan-to-map matching on a likelihood
field (as AMCL's and Hector's sensor models; the matcher is Gauss-Newton with a robust
loss, seeded by a correlative search when the pose is in doubt).

- `LikelihoodField.of_grid`: each cell's signed distance to the map's obstacles'
  boundary, taken through the centres of their outermost occupied cells (a cell is
  occupied when an obstacle overlaps it, so the face lies anywhere in that cell, on
  average at its centre): + in free space, − inside an obstacle (exact Euclidean
  distance transforms of both sides, capped at ± `max_dist_m`), bilinear with its
  gradient at any point. A beam's end costs its distance to the boundary on either
  side: an unsigned field (nothing inside) let the range noise pull the scan into the
  walls, by up to a wall's depth where one wall alone holds an axis.
- the scan's returns come as points in the base's floor plane (`common.scan.scan_points`;
  the trunk's roll and pitch, up to 4–5° while walking, shorten a horizontal range by
  under 4 mm per metre and are left out: levelling the scan with the odometry's
  attitude measured no better).
- `refine(field, points, pose)`: the pose (x, y, yaw) minimising Σ ρ(d(T·p)), ρ Huber at
  `huber_m`, and no pull at all beyond 3 `huber_m` in front of the map's obstacles or
  `huber_m` inside them: a beam on a person or on clutter the map does not have, or one
  that went where the map is solid but the lidar's plane is not (under a table's top
  to a leg, a tilted beam onto the top), does not drag the pose.
  Gauss-Newton on the three pose parameters, the Jacobian from the field's gradient.
  Returns the pose, the inlier share (beams within `inlier_m` of an obstacle, the
  match's confidence) and the covariance σ² H⁻¹ of the last step.
- `search(field, points, pose, …)`: the best pose on a grid of offsets (x, y, yaw)
  around `pose`, scored by the inlier-weighted field (what seeds `refine` when the start
  pose is off by decimetres, or after the robot was lost).

Pure numpy; `tests/unit/test_localization_matcher.py` checks it on ray-cast scans.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from common.geometry import FloatArray

Pose2 = tuple[float, float, float]


@dataclass(frozen=True)
class LikelihoodField:
    """Signed distance (m) to the obstacles' boundary (+ free, − inside; see the module
    docstring), on the map's grid: cell [iy, ix] is centred at origin + (i + 0.5) ×
    resolution (the occupancy grids' convention)."""

    dist: FloatArray  # (ny, nx)
    grad_x: FloatArray
    grad_y: FloatArray
    resolution: float
    origin: tuple[float, float]
    max_dist_m: float
    #: The gradient of the bilinear interpolant itself rather than the interpolated
    #: central differences (`grad_x`, `grad_y` unused): on a map of one scan's thin lines
    #: of cells the differences vanish on the lines, where the scan's returns lie.
    exact_gradient: bool = False
    #: Cells the map has seen (a return or a beam through them); None: all. A point in an
    #: unseen cell is "off the map" (the cap, no gradient): a wall's unseen part is no
    #: wall's end to pull the points toward.
    known: npt.NDArray[np.bool_] | None = None

    @classmethod
    def of_grid(
        cls,
        occupied: npt.NDArray[np.bool_],
        resolution: float,
        origin: tuple[float, float],
        max_dist_m: float = 1.0,
        exact_gradient: bool = False,
        known: npt.NDArray[np.bool_] | None = None,
    ) -> LikelihoodField:
        # Zero on the outermost occupied cells' centres: a cell is occupied when an
        # obstacle overlaps it at all, so a face lies anywhere in its boundary cell, on
        # average at the centre (the cells' edges instead measured worse). Outside: to
        # the nearest occupied centre; inside: to the nearest free centre, less a cell.
        outside = ndimage.distance_transform_edt(~occupied)
        inside = ndimage.distance_transform_edt(occupied) - 1.0
        dist = np.where(occupied, -inside, outside) * resolution
        dist = np.clip(dist, -max_dist_m, max_dist_m)
        gy, gx = np.gradient(dist, resolution)
        return cls(dist, gx, gy, resolution, origin, max_dist_m, exact_gradient, known)

    def at(self, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Signed distance (n,) and its gradient (n, 2) at points (n, 2); off the map: the
        cap, no gradient."""
        u = (xy[:, 0] - self.origin[0]) / self.resolution - 0.5
        v = (xy[:, 1] - self.origin[1]) / self.resolution - 0.5
        ny, nx = self.dist.shape
        inside = (u >= 0.0) & (v >= 0.0) & (u < nx - 1) & (v < ny - 1)
        d = np.full(len(xy), self.max_dist_m)
        g = np.zeros((len(xy), 2))
        if self.known is not None and inside.any():
            idx = np.flatnonzero(inside)
            seen = self.known[(v[idx] + 0.5).astype(int), (u[idx] + 0.5).astype(int)]
            inside[idx[~seen]] = False
        if not inside.any():
            return d, g
        u, v = u[inside], v[inside]
        i0, j0 = v.astype(int), u.astype(int)
        fv, fu = v - i0, u - j0
        w00, w01 = (1 - fv) * (1 - fu), (1 - fv) * fu
        w10, w11 = fv * (1 - fu), fv * fu

        def bilinear(a: FloatArray) -> FloatArray:
            return (
                w00 * a[i0, j0]
                + w01 * a[i0, j0 + 1]
                + w10 * a[i0 + 1, j0]
                + w11 * a[i0 + 1, j0 + 1]
            )

        d[inside] = bilinear(self.dist)
        if self.exact_gradient:
            a00, a01 = self.dist[i0, j0], self.dist[i0, j0 + 1]
            a10, a11 = self.dist[i0 + 1, j0], self.dist[i0 + 1, j0 + 1]
            g[inside, 0] = ((1 - fv) * (a01 - a00) + fv * (a11 - a10)) / self.resolution
            g[inside, 1] = ((1 - fu) * (a10 - a00) + fu * (a11 - a01)) / self.resolution
        else:
            g[inside, 0] = bilinear(self.grad_x)
            g[inside, 1] = bilinear(self.grad_y)
        return d, g


def transform(points: FloatArray, pose: Pose2) -> FloatArray:
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack(
        [c * points[:, 0] - s * points[:, 1] + x, s * points[:, 0] + c * points[:, 1] + y], axis=1
    )


@dataclass(frozen=True)
class Match:
    """A matched pose (x, y, yaw in the map), the share of beams within `inlier_m` of an
    obstacle, the mean robust cost per beam (m²), and the pose's covariance (3, 3)."""

    pose: Pose2
    inliers: float
    cost: float
    covariance: FloatArray


def refine(
    field: LikelihoodField,
    points: FloatArray,
    pose: Pose2,
    *,
    huber_m: float = 0.1,
    inlier_m: float = 0.1,
    sigma_m: float = 0.03,
    iterations: int = 15,
    prior: FloatArray | None = None,
) -> Match:
    """Gauss-Newton on (x, y, yaw) with a Huber loss (see the module docstring).

    `prior`: an information matrix (3, 3) on the offset from `pose`, in units of the
    beams' (a beam weighs 1): the odometry's word where the scan says little (a hall's
    long axis with its far wall out of range), as Cartographer's scan matcher weighs its
    initial pose."""
    x = np.array(pose, dtype=float)
    x0 = x.copy()
    H = np.eye(3)
    n = max(len(points), 1)
    for _ in range(iterations):
        c, s = math.cos(x[2]), math.sin(x[2])
        world = transform(points, (x[0], x[1], x[2]))
        d, g = field.at(world)
        a = np.abs(d)
        # IRLS weights: Huber's, and none beyond 3 huber_m in front (a person, clutter, a
        # beam through a door the map shuts: their pull, however weak, adds up) or
        # huber_m inside (a table's leg under its mapped top, a tilted beam onto it).
        w = np.where(a <= huber_m, 1.0, huber_m / np.maximum(a, 1e-9))
        w[(d > 3.0 * huber_m) | (d < -huber_m)] = 0.0
        # ∂(Rp + t)/∂yaw = (−s px − c py, c px − s py)
        dyaw = np.stack(
            [-s * points[:, 0] - c * points[:, 1], c * points[:, 0] - s * points[:, 1]], axis=1
        )
        J = np.column_stack([g[:, 0], g[:, 1], np.sum(g * dyaw, axis=1)])
        JW = J * w[:, None]
        H = JW.T @ J + 1e-6 * np.eye(3)
        g_ = JW.T @ d
        if prior is not None:
            off = x - x0
            off[2] = math.atan2(math.sin(off[2]), math.cos(off[2]))
            H = H + prior
            g_ = g_ + prior @ off
        step = -np.linalg.solve(H, g_)
        step[:2] = np.clip(step[:2], -0.1, 0.1)  # the field is only locally linear
        step[2] = float(np.clip(step[2], -0.05, 0.05))
        x += step
        if abs(step[0]) + abs(step[1]) < 1e-4 and abs(step[2]) < 1e-4:
            break
    d, _ = field.at(transform(points, (x[0], x[1], x[2])))
    d = np.abs(d)
    rho = np.where(d <= huber_m, 0.5 * d * d, huber_m * (d - 0.5 * huber_m))
    cov: FloatArray = np.asarray(sigma_m**2 * np.linalg.inv(H), dtype=float)
    return Match(
        (float(x[0]), float(x[1]), float(math.atan2(math.sin(x[2]), math.cos(x[2])))),
        float(np.mean(d <= inlier_m)) if len(points) else 0.0,
        float(np.sum(rho) / n),
        cov,
    )


def search(
    field: LikelihoodField,
    points: FloatArray,
    pose: Pose2,
    *,
    window_m: float = 0.6,
    step_m: float = 0.05,
    window_rad: float = math.radians(15.0),
    step_rad: float = math.radians(1.0),
    inlier_m: float = 0.1,
) -> Pose2:
    """The offset on the grid around `pose` under which most beams end on an obstacle
    (ties: the nearer to the field's obstacles on average)."""
    offsets = np.arange(-window_m, window_m + 1e-9, step_m)
    yaws = pose[2] + np.arange(-window_rad, window_rad + 1e-9, step_rad)
    best, best_score = pose, -math.inf
    for yaw in yaws:
        rotated = transform(points, (0.0, 0.0, float(yaw)))
        # every (dx, dy) at once: (k, n, 2) endpoints
        dx, dy = np.meshgrid(offsets, offsets, indexing="ij")
        shift = np.stack([dx.ravel() + pose[0], dy.ravel() + pose[1]], axis=1)
        ends = rotated[None, :, :] + shift[:, None, :]
        d, _ = field.at(ends.reshape(-1, 2))
        d = d.reshape(len(shift), len(points))
        score = np.sum(np.exp(-0.5 * (d / inlier_m) ** 2), axis=1)
        k = int(np.argmax(score))
        if score[k] > best_score:
            best_score = float(score[k])
            best = (float(shift[k, 0]), float(shift[k, 1]), float(yaw))
    return best
