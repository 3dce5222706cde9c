"""Mapping while localizing (SLAM) from the trunk lidar and the odometry: where the robot
is in a map it builds itself, and that map, as Cartographer's 2D pipeline splits it.

- **Local tracking**, each scan: the pose predicted by the odometry (the last correction
  applied to it), matched (`matcher.refine`, the localizer's Gauss-Newton) against a
  likelihood field of the last `local_keyframes` keyframes' returns only. A match is
  taken when `min_inliers` of its beams end on that local map and it lies within the
  gate of the prediction; otherwise the odometry carries the pose (the match is not
  trusted, the status `uncertain`). Only returns that end on cells the local map has
  seen (`KNOWN_GROW` cells about a return or a beam through them) count: turning on the
  spot, each scan sees walls farther along than the keyframes did, and those returns
  were pulled back onto the seen ends, the heading lagging the turn 0.4° and the map
  turned with it (`test_a_turn_on_the_spot_keeps_its_heading`; `dume bench slam`'s loop
  p50/p95 4.8/7.6 → 1.5/3.2 cm).
- **Keyframes**: a taken pose `keyframe_m` or `keyframe_rad` from the last keyframe
  becomes one (its pose, the odometry there, its returns in the base frame).
- **The pose graph** (gtsam, `Pose2`): a prior on the first keyframe (the start pose the
  user gives: the map's frame is the one the robot was told it starts in), a between
  factor from each keyframe to the next (the local matches' relative pose), and a loop
  closure where a new keyframe lies within `closure_radius_m` of one `closure_gap`
  keyframes or more older: its scan is registered against a submap of the older
  keyframe and its neighbours (small_gicp's GICP from the graph's pose; the correlative
  search and refine on the submap's grid, `closure_registration = "field"`, was as good
  and 30 times slower: `dume bench slam`), taken at `closure_min_inliers`, under a Huber
  loss. Each closure re-optimizes the
  graph (Levenberg-Marquardt) and moves every keyframe; the tracker follows the newest.
- **The occupancy grid** (`ScanGrid`): each keyframe's beams cast into the map at its
  pose: a cell a beam ends in counts a hit, one it crosses a miss; a cell is occupied
  when `occupied_ratio` of its counts are hits, free when it was crossed and is not
  occupied, unknown otherwise (the tracking's local grid alike, over its keyframes).
  After a closure each keyframe the optimization moved is taken out of the grid at the
  pose it was cast at and cast again at its new one, so the map never keeps a doubled
  wall; one whose returns all moved less than `RECAST_CELLS` of a cell stays as cast
  (the grid is then within that of one cast anew from every keyframe, which took 60 %
  of a core in a hall exploration, the lockstep waiting on it: closures come every few
  keyframes and most move the old ones by millimetres).

All (x, y, yaw) in SE(2), the map frame; pure (numpy, scipy, gtsam), no transport:
`services/localization/node.py` feeds it in `slam` mode, `tests/unit/test_slam.py`
drives it round ray-cast rooms with drifting odometry.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property

import gtsam
import numpy as np
import small_gicp
from numpy.typing import NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from common.config import LocalizationSettings, SlamSettings
from common.geometry import FloatArray
from services.localization.localizer import Estimate, Status, compose, inverse
from services.localization.matcher import LikelihoodField, Pose2, refine, search, transform

FREE, OCCUPIED, UNKNOWN = 0, 100, 255
#: The local map's seen cells (a return or a beam through them) grown by this many cells
#: are where the tracking takes a return at its word (`LikelihoodField.known`).
KNOWN_GROW = 4
#: After a closure a keyframe is cast again when one of its returns moved more than this
#: share of a grid cell since it was cast (the module docstring).
RECAST_CELLS = 0.25


@dataclass
class Keyframe:
    """One scan kept for the map: its pose in the map (moved by every optimization), the
    odometry's pose when it was taken, its returns (n, 2) in the base frame, and the
    lidar's origin in the base frame."""

    pose: Pose2
    odom: Pose2
    points: FloatArray
    origin: tuple[float, float]

    @cached_property
    def reach_m(self) -> float:
        """The farthest return from the base, m: a move of the pose by (d, θ) moves no
        return (nor a beam) more than d + θ × this (the returns never change)."""
        if len(self.points) == 0:
            return 0.0
        return float(np.sqrt(np.max(np.einsum("ij,ij->i", self.points, self.points))))


class ScanGrid:
    """Hit and miss counts per cell of a fixed grid (cell [iy, ix] spans origin + (i, i+1)
    × res), from keyframes' beams; see the module docstring."""

    def __init__(
        self, shape: tuple[int, int], resolution_m: float, origin_xy: tuple[float, float],
        occupied_ratio: float,
    ) -> None:  # fmt: skip
        self.shape, self.resolution_m = shape, float(resolution_m)
        self.origin_xy = (float(origin_xy[0]), float(origin_xy[1]))
        self.occupied_ratio = occupied_ratio
        self.hits = np.zeros(shape, np.float32)
        self.misses = np.zeros(shape, np.float32)
        #: The keyframes in the counts and the pose each was cast at, by id().
        self._cast: dict[int, tuple[Keyframe, Pose2]] = {}
        #: Counts every change of the counts (a reader can tell its copy is old).
        self.version = 0

    @classmethod
    def centred(cls, half_extent_m: float, resolution_m: float, occupied_ratio: float) -> ScanGrid:
        n = round(2 * half_extent_m / resolution_m)
        return cls((n, n), resolution_m, (-half_extent_m, -half_extent_m), occupied_ratio)

    def _flat(self, xy: FloatArray) -> NDArray[np.intp]:
        """Flat indices of the cells holding the points (those off the grid left out)."""
        ix = np.floor((xy[:, 0] - self.origin_xy[0]) / self.resolution_m).astype(np.intp)
        iy = np.floor((xy[:, 1] - self.origin_xy[1]) / self.resolution_m).astype(np.intp)
        ny, nx = self.shape
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        return np.unique(iy[ok] * nx + ix[ok])

    def add(self, kf: Keyframe) -> None:
        """Cast one keyframe's beams at its pose: each cell counted once per keyframe."""
        pose = self._cast.setdefault(id(kf), (kf, kf.pose))[1]
        self._count(kf, pose, 1.0)

    def remove(self, kf: Keyframe) -> None:
        """Take a keyframe out of the counts, at the pose it was cast at (none: a no-op)."""
        was = self._cast.pop(id(kf), None)
        if was is not None:
            self._count(kf, was[1], -1.0)

    def recast(self, keyframes: list[Keyframe], tol_m: float) -> int:
        """Every keyframe in the counts at its pose now: one not cast yet is cast, one
        cast at a pose from which a return moved more than `tol_m` is taken out there
        and cast again; the others stay. Returns how many were cast."""
        cast = 0
        for kf in keyframes:
            was = self._cast.get(id(kf))
            if was is not None:
                d, turned = _moved(kf.pose, was[1])
                if d + turned * kf.reach_m <= tol_m:
                    continue
                self.remove(kf)
            self.add(kf)
            cast += 1
        return cast

    def _count(self, kf: Keyframe, pose: Pose2, weight: float) -> None:
        if len(kf.points) == 0:
            return
        ends = transform(kf.points, pose)
        o = np.array(transform(np.array([kf.origin]), pose)[0])
        d = ends - o
        length = np.hypot(d[:, 0], d[:, 1])
        step = 0.5 * self.resolution_m
        # samples every half cell from the origin to a cell short of the end
        n = np.maximum(np.floor((length - self.resolution_m) / step).astype(np.intp), 0)
        beam = np.repeat(np.arange(len(n)), n)
        first = np.cumsum(n) - n
        k = np.arange(int(n.sum())) - np.repeat(first, n)
        t = (k * step / np.maximum(length[beam], 1e-9))[:, None]
        crossed = self._flat(o + t * d[beam])
        hit = self._flat(ends)
        self.misses.reshape(-1)[np.setdiff1d(crossed, hit, assume_unique=True)] += weight
        self.hits.reshape(-1)[hit] += weight
        self.version += 1

    def rebuild(self, keyframes: list[Keyframe]) -> None:
        self.hits[:] = 0.0
        self.misses[:] = 0.0
        self._cast.clear()
        for kf in keyframes:
            self.add(kf)

    def occupied(self) -> NDArray[np.bool_]:
        total = self.hits + self.misses
        return (self.hits > 0.5) & (self.hits >= self.occupied_ratio * total)

    def field(self, margin_m: float = 1.0) -> LikelihoodField | None:
        """The likelihood field of the occupied cells, on their extent grown by
        `margin_m` (None: nothing occupied)."""
        occ = self.occupied()
        rows, cols = np.flatnonzero(occ.any(axis=1)), np.flatnonzero(occ.any(axis=0))
        if len(rows) == 0:
            return None
        m = round(margin_m / self.resolution_m)
        i0, i1 = max(0, rows[0] - m), min(self.shape[0], rows[-1] + m + 1)
        j0, j1 = max(0, cols[0] - m), min(self.shape[1], cols[-1] + m + 1)
        origin = (
            self.origin_xy[0] + j0 * self.resolution_m,
            self.origin_xy[1] + i0 * self.resolution_m,
        )
        # the seen cells grown on the field's extent only (padded by the growth, so the
        # cells at its edge grow as on the whole grid): the grid is 1200² cells
        k = KNOWN_GROW
        a0, a1 = max(0, i0 - k), min(self.shape[0], i1 + k)
        b0, b1 = max(0, j0 - k), min(self.shape[1], j1 + k)
        seen = (self.hits[a0:a1, b0:b1] > 0) | (self.misses[a0:a1, b0:b1] > 0)
        known = ndimage.binary_dilation(seen, np.ones((3, 3), bool), iterations=k)
        return LikelihoodField.of_grid(
            occ[i0:i1, j0:j1], self.resolution_m, origin, exact_gradient=True,
            known=known[i0 - a0 : i1 - a0, j0 - b0 : j1 - b0],
        )  # fmt: skip

    def cells(self) -> NDArray[np.uint8]:
        """FREE, OCCUPIED or UNKNOWN per cell (the map's codes)."""
        out = np.full(self.shape, UNKNOWN, np.uint8)
        out[self.misses > 0.5] = FREE
        out[self.occupied()] = OCCUPIED
        return out


def _gpose(p: Pose2) -> gtsam.Pose2:
    return gtsam.Pose2(p[0], p[1], p[2])


def _pose(g: gtsam.Pose2) -> Pose2:
    return (float(g.x()), float(g.y()), float(g.theta()))


def _moved(a: Pose2, b: Pose2) -> tuple[float, float]:
    dyaw = math.atan2(math.sin(a[2] - b[2]), math.cos(a[2] - b[2]))
    return math.hypot(a[0] - b[0], a[1] - b[1]), abs(dyaw)


@dataclass(frozen=True)
class Closure:
    """A loop closure taken: the older keyframe, the newer, the registration's inlier
    share, and how far the optimization moved the newest keyframe (m)."""

    older: int
    newer: int
    inliers: float
    correction_m: float


class Slam:
    """See the module docstring. `start` is the base's pose in the map at start-up;
    `origin` the lidar's position in the base frame (x, y)."""

    def __init__(
        self,
        s: LocalizationSettings,
        slam: SlamSettings,
        start: Pose2,
        origin: tuple[float, float],
    ) -> None:
        self.s, self.c = s, slam
        self.start, self.origin = start, origin
        self.grid = ScanGrid.centred(slam.half_extent_m, slam.resolution_m, slam.occupied_ratio)
        #: The last `local_keyframes` keyframes alone: what each scan is tracked on.
        self.local = ScanGrid.centred(
            slam.half_extent_m, slam.track_resolution_m, slam.occupied_ratio
        )
        beam = 0.03  # a beam's residual scale, m (the matcher's sigma_m)
        self.prior = np.diag(
            [(beam / slam.prior_sigma_m) ** 2] * 2 + [(beam / slam.prior_sigma_rad) ** 2]
        )
        self.keyframes: list[Keyframe] = []
        self.closures: list[Closure] = []
        self.graph = gtsam.NonlinearFactorGraph()
        self.values = gtsam.Values()
        self.map_odom: Pose2 | None = None
        self.status: Status = "initialising"
        self.covariance = np.diag([1e-4, 1e-4, 1e-5])
        self.refusals = 0
        self._local: LikelihoodField | None = None
        #: Wall ms of each loop closure's registration (`dume bench slam`).
        self.closure_ms: list[float] = []
        #: Keyframes cast again after closures (`dume bench slam`).
        self.recast = 0
        self._since_closure = 0

    # -- each scan -----------------------------------------------------------------------

    def update(self, points: FloatArray, odom: Pose2, stride: int = 1) -> Estimate:
        """One scan's returns (n, 2) in the base frame and the odometry at its stamp; the
        matching uses every `stride`-th return, the map every one."""
        s = self.s
        if self.map_odom is None:  # the robot stands at the start pose it was given
            self.map_odom = compose(self.start, inverse(odom))
        predicted = compose(self.map_odom, odom)
        if not self.keyframes:
            self._keyframe(predicted, odom, points)
            self.status = "ok"
            return Estimate(self.map_odom, predicted, self.covariance, "ok", 1.0)
        assert self._local is not None
        sparse = points[::stride]
        m = refine(
            self._local, sparse, predicted, huber_m=s.huber_m, inlier_m=s.inlier_m,
            prior=self.prior,
        )  # fmt: skip
        dxy, dyaw = _moved(m.pose, predicted)
        why = ""
        if m.inliers < self.c.min_inliers:
            why = f"{m.inliers:.0%} of the beams on the local map (< {self.c.min_inliers:.0%})"
        elif dxy > s.gate_m or dyaw > s.gate_rad:
            why = f"the match jumped {dxy:.2f} m, {math.degrees(dyaw):.1f}° from the odometry"
        pose = predicted if why else m.pose
        if why:
            self.refusals += 1
            self.status = "lost" if self.refusals >= s.lost_after else "uncertain"
        else:
            self.refusals, self.status = 0, "ok"
            self.map_odom = compose(pose, inverse(odom))
            self.covariance = m.covariance
        last = self.keyframes[-1].pose
        far, turned = _moved(pose, last)
        if not why and (far >= self.c.keyframe_m or turned >= self.c.keyframe_rad):
            before = pose
            self._keyframe(pose, odom, points)
            after = self.keyframes[-1].pose
            if after != before:  # a closure moved the graph: the tracker follows
                self.map_odom = compose(after, inverse(odom))
                pose = after
        return Estimate(self.map_odom, pose, self.covariance, self.status, m.inliers, why, m)

    # -- keyframes, the graph ------------------------------------------------------------

    def _keyframe(self, pose: Pose2, odom: Pose2, points: FloatArray) -> None:
        k = len(self.keyframes)
        kf = Keyframe(pose, odom, np.asarray(points, float), self.origin)
        self.keyframes.append(kf)
        self.values.insert(k, _gpose(pose))
        if k == 0:
            sigmas = np.array([1e-3, 1e-3, 1e-4])
            self.graph.add(gtsam.PriorFactorPose2(0, _gpose(pose), _sigmas(sigmas)))
        else:
            prev = self.keyframes[k - 1].pose
            rel = compose(inverse(prev), pose)
            d = math.hypot(rel[0], rel[1])
            c = self.c
            sigmas = np.array(
                [c.odom_sigma_m + c.odom_sigma_per_m * d] * 2
                + [c.odom_sigma_rad + c.odom_sigma_rad_per_m * d]
            )
            self.graph.add(gtsam.BetweenFactorPose2(k - 1, k, _gpose(rel), _sigmas(sigmas)))
        self._since_closure += 1
        closure = self._close_loop(k) if k > 0 else None
        n = self.c.local_keyframes
        if closure is not None:
            self.closures.append(closure)
            self.recast += self.grid.recast(self.keyframes, RECAST_CELLS * self.grid.resolution_m)
        else:
            self.grid.add(kf)
        self.local.recast(self.keyframes[-n:], RECAST_CELLS * self.local.resolution_m)
        if len(self.keyframes) > n:
            self.local.remove(self.keyframes[-n - 1])
        self._local = self.local.field() or self._local

    def _close_loop(self, k: int) -> Closure | None:
        c = self.c
        if self._since_closure < c.closure_every:
            return None
        new = self.keyframes[k]
        old = [
            (math.hypot(kf.pose[0] - new.pose[0], kf.pose[1] - new.pose[1]), j)
            for j, kf in enumerate(self.keyframes[: max(0, k - c.closure_gap + 1)])
        ]
        near = [(d, j) for d, j in old if d <= c.closure_radius_m]
        if not near:
            return None
        _, j = min(near)
        lo, hi = max(0, j - c.closure_submap), min(k - c.closure_gap + 1, j + c.closure_submap + 1)
        t0 = time.perf_counter()
        if c.closure_registration == "gicp":
            pose, inliers = self._register_gicp(new, self.keyframes[lo:hi])
        else:
            pose, inliers = self._register_field(new, self.keyframes[lo:hi])
        self.closure_ms.append(1e3 * (time.perf_counter() - t0))
        if inliers < c.closure_min_inliers:
            return None
        rel = compose(inverse(self.keyframes[j].pose), pose)
        noise = gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Huber.Create(1.0),
            _sigmas(np.array([c.closure_sigma_m, c.closure_sigma_m, c.closure_sigma_rad])),
        )
        self.graph.add(gtsam.BetweenFactorPose2(j, k, _gpose(rel), noise))
        result = gtsam.LevenbergMarquardtOptimizer(self.graph, self.values).optimize()
        before = new.pose
        for i, kf in enumerate(self.keyframes):
            kf.pose = _pose(result.atPose2(i))
        self.values = result
        self._since_closure = 0
        return Closure(j, k, inliers, math.hypot(new.pose[0] - before[0], new.pose[1] - before[1]))

    def _register_field(self, new: Keyframe, submap: list[Keyframe]) -> tuple[Pose2, float]:
        """The new keyframe's pose on the submap's grid: a correlative search around the
        graph's pose, then the Gauss-Newton refine; (pose, inlier share)."""
        c, s = self.c, self.s
        grid = ScanGrid.centred(c.half_extent_m, c.track_resolution_m, c.occupied_ratio)
        grid.rebuild(submap)
        field = grid.field()
        if field is None:
            return new.pose, 0.0
        pts = new.points[:: max(1, s.beam_stride)]
        seed = search(
            field, pts, new.pose, window_m=c.closure_search_m, window_rad=c.closure_search_rad,
            inlier_m=s.inlier_m,
        )  # fmt: skip
        m = refine(field, pts, seed, huber_m=s.huber_m, inlier_m=s.inlier_m, iterations=30)
        return m.pose, m.inliers

    def _register_gicp(self, new: Keyframe, submap: list[Keyframe]) -> tuple[Pose2, float]:
        """The new keyframe's pose on the submap's returns by small_gicp's GICP from the
        graph's pose (points lifted to z = 0), projected back to SE(2)."""
        c, s = self.c, self.s
        target = np.concatenate([transform(kf.points, kf.pose) for kf in submap if len(kf.points)])
        x, y, yaw = new.pose
        init = np.eye(4)
        init[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
        init[:2, 3] = (x, y)
        r = small_gicp.align(
            _lift(target), _lift(new.points), init, registration_type="GICP",
            downsampling_resolution=c.track_resolution_m,
            max_correspondence_distance=c.closure_search_m, num_threads=1,
        )  # fmt: skip
        T = r.T_target_source
        pose = (float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0]))
        d, _ = cKDTree(target).query(transform(new.points, pose))
        return pose, float(np.mean(d <= s.inlier_m))


def _lift(points: FloatArray) -> FloatArray:
    return np.column_stack([points, np.zeros(len(points))])


def _sigmas(sigmas: FloatArray) -> gtsam.noiseModel.Base:
    return gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, float))
