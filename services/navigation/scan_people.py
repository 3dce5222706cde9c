"""People the lidar sees: the protective field of the speed and separation monitor.

The head camera looks ahead only, and the map's people arrive a second or more late: a
person walking beside or behind the robot, or standing where the camera does not look, is
unknown to the speed rules. The trunk's 270° planar lidar sweeps the plane at about 0.5 m
(people's legs; above the pallets, below the tables' tops) ten times a second, and is
what ISO/TS 15066 robots watch their protective field with. `ScanPeople.update(points,
grid, pose, t)` takes one scan's returns in the map frame:

- returns on the world the map knows are left out: within `static_margin_m` (the
  localization's and the range's error) of a cell that is occupied (walls, machines,
  shelves' uprights, the tables' legs) or in the unknown beyond what the map has seen
  (a map still being made, in exploration). An unknown island of at most
  `island_m2` inside seen floor is floor: the shadow a body standing there cast while
  the map was made (the map leaves people out; the cells under their feet are never
  seen free), where a person is likely to stand again. Returns beyond `range_m` of the
  footprint are left out too;
- the rest are cut into clusters where consecutive returns (beam order) are more than
  `gap_m` apart, and clusters whose centroids lie within `join_m` are joined (a
  person's two legs, a wall's return between them);
- a cluster of at least `min_points` returns, at most `max_extent_m` across and with no
  straight run of returns longer than `max_face_m` (a flat face: a trolley's end is as
  wide as a person, its returns a line where legs give two arcs), whose
  centroid is outside the footprint (`robot_margin_m` round it: the robot's own arm
  and what it carries), is a body that could be a person; the returns of larger ones
  (a trolley left in an aisle, a parked load: `ScanPeople.obstacles`) are obstacles the
  map lacks, which `NavMap` keeps in a layer of their own until the beams pass through
  where they stood: the lidar sees them all round, where the camera looks ahead only.
  Its floor point is the
  centroid of its returns: the near side of the legs, so a little in front of the
  person's centre (distances err on the safe side);
- each is put on a track (the nearest track's position extrapolated to now within
  `gate_m`, else a new `scan_<k>`), whose velocity is the least-squares slope of its
  positions over `velocity_window_s` (`seen_people.fitted_velocity`; None until they span
  `velocity_min_span_s`: the monitor then takes a walking pace). A track not seen for
  `ttl_s` ends (a body that left the field went out of range) unless no beam can say
  it is gone: then it coasts along its velocity for up to `coast_s`, and ends as soon
  as a beam returns from `CLEARS_BEYOND_M` beyond where it would be (`ScanView.through`,
  a beam with no return saying nothing); one standing where no lidar's open field
  reaches coasts up to `blind_hold_s`. A walker lost (a measured velocity of at least
  `standing_mps`) is not taken to walk on as they did: past `ttl_s` the track stands for
  every place they could have walked to at their pace since, unseen (`_spread`: the
  places grow from their last one through what no beam sees free, `ScanView.free`, off
  the map's world and the robot's footprint), and the speed rules take the one of those
  nearest the robot, with the velocity they had; it ends when no such place is left,
  and a body found among them (within `gate_m`) is them again, once every track has had
  its own. Hall seed 4's shift, t = 536.8 s: a worker walking at 1 m/s turned in
  through the wedge to stand before the head; their track coasted on along its old
  velocity, past the robot, the stop for them was released, and the handover's align
  stepped into them (0.305 m inside their separation). The two lidars see ±97° about their own axes
  (the trunk masks the rest): a wedge on each side of the trunk, 0.6 m long at 1.2 m
  out and closing at 3.3 m, is blind to both, and a person walking beside the robot
  crosses it in seconds (the changing hall's shift: person_1, overtaking the robot 1.1 m
  to its right, unseen for 2.2 s, was found again 0.74 m from the footprint with no
  velocity, after the robot had stepped towards them).

Every track is a person to the speed rules, as ISO 13855's protective field treats
anything that enters it: something the map lacks that is the size of a person. A
standing one costs the robot no more than its protective separation at rest. The tracks
join the people layer in `NavMap` (`merge_scan`): a track within `same_m` of a person the
layer already has is that person seen now (the lidar's 10 Hz position and its velocity
win), the rest are added under their own ids.

The scan also says where nobody stands (`ScanView.clear_at`): a person the layer has
from the map only (the camera has not seen them for `NavMap`'s `CAMERA_FRESH_S`) whose
place every beam within 0.6 m of it passes 0.3 m beyond (the floor there is seen free in
the lidar's plane, where every standing person has legs; the map places a standing
person up to a few decimetres off their legs, and 0.25 m left real people out in the
bystanders' shift) is not there any more. A beam with no return within the range passes
too where nothing of the robot masks it (within `OPEN_FIELD_RAD` of the lidar's heading:
the robot's legs meet those beyond ±97°): in a hall most beams return nothing, and hall
seed 2's shift stood 100 s by the map's entry of a worker who had walked on, 0.7 m off
the lidar, whose 0.6 m cone held beams to a wall 15 m away. A scan with hardly any
returns (`MIN_RETURNS`: a lidar covered or failing) says nothing. Such a person is not
there any more: the map's tracker holds a person who walked out of view at their last
place, or carried along their last velocity, for seconds to minutes. `NavMap` leaves
such people out of its layer (the map itself is not changed), and those the map alone
places inside the robot's own footprint.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from common.geometry import FloatArray
from common.messages.base import NS_PER_S
from services.navigation.costmap import Person
from services.navigation.grid import BoolGrid, Footprint, Grid, Pose, distance_to_footprint
from services.navigation.seen_people import WALKING_MPS, fitted_velocity

#: m: a beam returning from this far beyond a coasting track's place says it is gone.
CLEARS_BEYOND_M = 0.3
#: s a person's lidar velocity is kept for a new track of them (`VelocityMemory`): the
#: fit's own window and more; a start from rest in it is within the estimate's margin.
VELOCITY_HOLD_S = 1.0
#: m: the spacing of the places a lost walker could be (`ScanPeople._spread`).
REACH_STEP_M = 0.1
#: m/s: the fastest pace a lost walker's places grow at (beyond it, their window bounds).
MAX_WALK_MPS = 2.0
#: A cell's neighbours, diagonals too: the places grow a step each way per step walked,
#: within their reach's disc.
SQUARE = np.ones((3, 3), dtype=bool)
#: The memory forgets what it no longer holds once it keeps this many people.
MEMORY_PRUNE_AT = 256
#: m: the lidar's floor point of a person (the centroid of the returns off the near side
#: of their legs) lies about this much nearer the robot than their body's centre, where
#: the map's estimate and the handover distance are taken: a handover pose chosen from
#: the lidar's point stood the robot 0.11 m farther than the handover distance.
LEGS_NEAR_SIDE_M = 0.1
#: m: the tracks within this of the base are said to who looks for a person
#: (`nearest_tracks`, on `nav/status`), at most `TRACKS_SAID` of them.
TRACKS_SAID_M = 6.0
TRACKS_SAID = 8


@dataclass(frozen=True)
class ScanParams:
    """Which returns make a body and how bodies are tracked (see the module docstring).
    Not settings: tuned with the lidar (0.5° beams, ±15 mm) and the people's size."""

    static_margin_m: float = 0.15
    island_m2: float = 1.0
    range_m: float = 5.0
    gap_m: float = 0.12
    join_m: float = 0.45
    min_points: int = 3
    max_extent_m: float = 0.8
    #: m: a straight run of returns longer than this is a face of something, not legs (a
    #: trolley's 0.6 m end, seen square on, was a person-sized body; the shift stood 170 s
    #: before it in an aisle, its separation at a walking pace while its track was new),
    #: straight: its returns' spread across it at most `straight_m` (1-σ).
    max_face_m: float = 0.45
    straight_m: float = 0.03
    robot_margin_m: float = 0.05
    gate_m: float = 0.6
    ttl_s: float = 0.5
    velocity_window_s: float = 0.6
    velocity_min_span_s: float = 0.25
    #: s: how long a track no beam sees gone coasts (the blind wedges beside the trunk).
    coast_s: float = 3.0
    #: s: how long a standing track (slower than `standing_mps`, m/s) coasts while its
    #: place lies out of every lidar's open field (`ScanView.covers`): nobody standing
    #: beside the trunk is gone until a beam can look (hall seed 4's shift, t = 423.8 s:
    #: a worker stood 3.3 s in the wedge as the robot turned by them, their track ended
    #: at `coast_s`, and the robot walked 0.19 m/s at them when they moved, 0.72 m off).
    blind_hold_s: float = 10.0
    standing_mps: float = WALKING_MPS
    #: A track this close to a person the layer has is that person (`merge_scan`).
    same_m: float = 0.6


@dataclass(frozen=True)
class Body:
    """One cluster of returns: its centroid (m, map), extent (m, the largest distance of
    a return from the centroid, doubled) and how many returns."""

    x: float
    y: float
    extent_m: float
    points: int


def off_map(points: FloatArray, clearance: FloatArray, grid: Grid, margin_m: float) -> FloatArray:
    """The points (n, 2, map) farther than `margin_m` from the world the map knows
    (`clearance`: each cell's distance to it, `static_clearance`); points off the grid are
    left out (nothing is known there)."""
    if len(points) == 0:
        return points
    out: FloatArray = points[off_map_mask(points, clearance, grid, margin_m)]
    return out


def off_map_mask(
    points: FloatArray, clearance: FloatArray, grid: Grid, margin_m: float
) -> NDArray[np.bool_]:
    """Which points `off_map` keeps."""
    ix = np.floor((points[:, 0] - grid.origin[0]) / grid.resolution).astype(np.int64)
    iy = np.floor((points[:, 1] - grid.origin[1]) / grid.resolution).astype(np.int64)
    ny, nx = grid.shape
    inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    keep = np.zeros(len(points), dtype=bool)
    keep[inside] = clearance[iy[inside], ix[inside]] > margin_m
    return keep


def static_cells(grid: Grid, island_m2: float) -> BoolGrid:
    """The cells of the world the map knows: occupied, or unknown but for islands of at
    most `island_m2` (8-connected; one inside a machine is no matter: the lidar cannot
    see in)."""
    solid = grid.known_occupied
    unknown = grid.occupied & ~solid
    if not unknown.any():
        return solid.copy()
    labels, count = ndimage.label(unknown, structure=np.ones((3, 3), dtype=bool))
    sizes = np.bincount(labels.ravel(), minlength=count + 1) * grid.resolution**2
    small = sizes <= island_m2
    small[0] = False
    out: BoolGrid = solid | (unknown & ~small[labels])
    return out


def static_clearance(grid: Grid, island_m2: float) -> FloatArray:
    """Each cell's distance (m) from its centre to the nearest static cell
    (`static_cells`), less half a cell (that cell's square, not its centre)."""
    dist = ndimage.distance_transform_edt(~static_cells(grid, island_m2)) * grid.resolution
    out: FloatArray = np.maximum(dist - 0.5 * grid.resolution, 0.0)
    return out


def face_m(run: FloatArray, straight_m: float) -> float:
    """How long a flat face a run of consecutive returns (k, 2) is: its length along its
    principal axis when the returns' spread across it (1-σ) is at most `straight_m` (the
    range noise; legs are two arcs), else 0."""
    if len(run) < 3:
        return 0.0
    d = run - run.mean(axis=0)
    _, sv, axes = np.linalg.svd(d, full_matrices=False)
    if sv[-1] / math.sqrt(len(run)) > straight_m:
        return 0.0
    along = d @ axes[0]
    return float(along.max() - along.min())


def clusters(points: FloatArray, p: ScanParams) -> list[tuple[FloatArray, float, float]]:
    """The clusters of `points` (n, 2, beam order), each with its extent (m) and its
    longest flat face (m, `face_m`; 0 where no run of it spans more than `max_face_m`:
    legs and stray returns skip the fit): split where consecutive points are more than
    `gap_m` apart, joined where centroids are within `join_m`; those of at least
    `min_points`."""
    if len(points) == 0:
        return []
    step = np.hypot(*np.diff(points, axis=0).T)
    cuts = np.flatnonzero(step > p.gap_m) + 1
    groups = [g for g in np.split(points, cuts) if len(g)]
    joined: list[FloatArray] = []
    faces: list[float] = []
    for g in groups:
        c = g.mean(axis=0)
        span = float(np.hypot(*np.ptp(g, axis=0)))
        face = face_m(g, p.straight_m) if span > p.max_face_m else 0.0
        for k, h in enumerate(joined):
            if float(np.hypot(*(h.mean(axis=0) - c))) <= p.join_m:
                joined[k] = np.vstack([h, g])
                faces[k] = max(faces[k], face)
                break
        else:
            joined.append(g)
            faces.append(face)
    out = []
    for g, face in zip(joined, faces, strict=True):
        if len(g) >= p.min_points:
            out.append((g, 2.0 * float(np.max(np.hypot(*(g - g.mean(axis=0)).T))), face))
    return out


def bodies_and_larger(points: FloatArray, p: ScanParams) -> tuple[list[Body], FloatArray]:
    """The `clusters` of `points` at most `max_extent_m` across and with no flat face
    longer than `max_face_m`, as bodies, and the returns (k, 2) of the others."""
    found, big = [], []
    for g, extent, face in clusters(points, p):
        if extent <= p.max_extent_m and face <= p.max_face_m:
            c = g.mean(axis=0)
            found.append(Body(float(c[0]), float(c[1]), extent, len(g)))
        else:
            big.append(g)
    larger: FloatArray = np.vstack(big) if big else np.zeros((0, 2))
    return found, larger


def bodies(points: FloatArray, p: ScanParams) -> list[Body]:
    """The `clusters` of `points` at most `max_extent_m` across, as bodies."""
    return bodies_and_larger(points, p)[0]


#: rad: the lidar's beams within this of its heading meet nothing of the robot (its legs
#: mask those beyond ±97° standing, in every posture): no return there is free floor.
OPEN_FIELD_RAD = math.radians(90.0)
#: The least share of a scan's beams with a return for it to say where nobody stands.
MIN_RETURNS = 0.1
#: m: the body round a place whose beams must all pass for it to be free (`clear_at`): a
#: place this near a lidar the scan cannot judge.
CLEAR_RADIUS_M = 0.6


@dataclass(frozen=True)
class ScanView:
    """One scan as rays in the map: the lidar's origin (m) and heading (rad), its beams'
    angles (from the heading) and ranges (m, 0: no return within `range_max`)."""

    origin: tuple[float, float]
    heading: float
    angle_min: float
    angle_increment: float
    ranges: FloatArray
    range_max: float

    @cached_property
    def returns_enough(self) -> bool:
        """Whether at least `MIN_RETURNS` of the beams returned (once per scan: every
        person asked after reads it)."""
        return bool(np.count_nonzero(self.ranges > 0.0) >= MIN_RETURNS * len(self.ranges))

    def clear_at(
        self, x: float, y: float, radius_m: float = CLEAR_RADIUS_M, beyond_m: float = 0.3
    ) -> bool:
        """Whether the beams at a body of `radius_m` at (x, y) all return from at least
        `beyond_m` beyond it, or return nothing within the range in the open field
        (`OPEN_FIELD_RAD`); False where the scan cannot say: out of its field or range, a
        beam without a return beyond the open field (masked where it meets the robot's
        own legs: a person behind the lidar's ±97° is not seen gone), or a scan with
        hardly any returns (`MIN_RETURNS`)."""
        if not self.returns_enough:
            return False
        dx, dy = x - self.origin[0], y - self.origin[1]
        dist = math.hypot(dx, dy)
        if dist <= radius_m or dist + beyond_m >= self.range_max:
            return False
        bearing = math.remainder(math.atan2(dy, dx) - self.heading, math.tau)
        half = math.asin(min(1.0, radius_m / dist))
        k0 = math.ceil((bearing - half - self.angle_min) / self.angle_increment)
        k1 = math.floor((bearing + half - self.angle_min) / self.angle_increment)
        if k0 < 0 or k1 >= len(self.ranges) or k1 < k0:
            return False
        r = self.ranges[k0 : k1 + 1]
        angles = self.angle_min + self.angle_increment * np.arange(k0, k1 + 1)
        open_field = (r <= 0.0) & (np.abs(angles) <= OPEN_FIELD_RAD)
        return bool(np.all((r >= dist + beyond_m) | open_field))

    def _polar(self, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Points (n, 2, map) as the lidar sees them: range (m) and bearing from its
        heading (rad, in [-π, π))."""
        dx, dy = xy[:, 0] - self.origin[0], xy[:, 1] - self.origin[1]
        bearing = np.remainder(np.arctan2(dy, dx) - self.heading + np.pi, 2 * np.pi) - np.pi
        return np.hypot(dx, dy), bearing

    def covers(self, xy: FloatArray) -> NDArray[np.bool_]:
        """Which points (n, 2, map) lie in the scan's open field (`OPEN_FIELD_RAD` of its
        heading, where no part of the robot masks a beam) and within its range."""
        dist, bearing = self._polar(xy)
        out: NDArray[np.bool_] = (np.abs(bearing) <= OPEN_FIELD_RAD) & (dist < self.range_max)
        return out

    def free(self, xy: FloatArray, beyond_m: float) -> NDArray[np.bool_]:
        """Which points (n, 2, map) the scan sees free: a beam returns from at least
        `beyond_m` beyond, or none returns within the range in the open field (as
        `clear_at` judges a place, by the nearest beam; a scan with hardly any returns
        sees only the first)."""
        inside, r, dist, bearing = self._beams(xy, beyond_m)
        none = (r <= 0.0) & (np.abs(bearing) <= OPEN_FIELD_RAD) & self.returns_enough
        out: NDArray[np.bool_] = inside & ((r >= dist + beyond_m) | none)
        return out

    def _beams(
        self, xy: FloatArray, beyond_m: float
    ) -> tuple[NDArray[np.bool_], FloatArray, FloatArray, FloatArray]:
        """For points (n, 2, map): whether the nearest beam and `beyond_m` beyond lie in
        the scan, that beam's range, and the points' range and bearing."""
        dist, bearing = self._polar(xy)
        k = np.rint((bearing - self.angle_min) / self.angle_increment).astype(np.int64)
        inside = (k >= 0) & (k < len(self.ranges)) & (dist + beyond_m < self.range_max)
        return inside, self.ranges[np.clip(k, 0, len(self.ranges) - 1)], dist, bearing

    def through(
        self, xy: FloatArray, beyond_m: float = 0.15, none_passes: bool = True
    ) -> NDArray[np.bool_]:
        """Which points (n, 2, map) its beam passes: a return from at least `beyond_m`
        beyond the point, or none at all (nothing within the range: in the middle of a
        hall most beams return nothing; a beam lost, or masked by the robot's own legs,
        reads so too, which costs a mark the other lidar or the next scan makes again),
        the point in the scan's field and range. `none_passes` False: a beam with no
        return says nothing (where a person may be hidden: the trunk masks it)."""
        if len(xy) == 0:
            return np.zeros(0, dtype=bool)
        inside, r, dist, _ = self._beams(xy, beyond_m)
        out: NDArray[np.bool_] = inside & ((r >= dist + beyond_m) | (none_passes & (r <= 0.0)))
        return out


@lru_cache(maxsize=64)
def _disc(n: int) -> FloatArray:
    """Each cell's squared distance (m²) from the centre of a (2n + 1)² window of cells
    `REACH_STEP_M` on a side (read-only: cached)."""
    axis = np.arange(-n, n + 1) * REACH_STEP_M
    out: FloatArray = axis[None, :] ** 2 + axis[:, None] ** 2
    out.flags.writeable = False
    return out


@dataclass
class _Track:
    id: str
    points: list[tuple[int, float, float]]
    velocity: tuple[float, float] | None = None
    #: A beam returned from beyond where it would be: it is gone.
    cleared: bool = False
    #: Unseen, where no lidar's open field reaches (`ScanView.covers`).
    blind: bool = False
    #: A walker unseen: the place nearest the robot they could be now (`ScanPeople._spread`),
    #: the cells round their last place they could be in (`REACH_STEP_M` apart), how many
    #: steps those have grown, and the places themselves (k, 2, map).
    hidden: tuple[float, float] | None = None
    places: NDArray[np.bool_] | None = None
    grown: int = 0
    place_xy: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def last(self) -> tuple[int, float, float]:
        return self.points[-1]

    def walking(self, standing_mps: float) -> bool:
        return self.velocity is not None and math.hypot(*self.velocity) >= standing_mps

    def reach_m(self, t_ns: int) -> float:
        """How far from its last place it could be at `t_ns`, at its pace."""
        speed = 0.0 if self.velocity is None else math.hypot(*self.velocity)
        return speed * max(t_ns - self.last[0], 0) / NS_PER_S

    def predicted(self, t_ns: int) -> tuple[float, float]:
        t, x, y = self.last
        if self.velocity is None:
            return x, y
        dt = (t_ns - t) / NS_PER_S
        return x + self.velocity[0] * dt, y + self.velocity[1] * dt


class ScanPeople:
    """The lidar's tracks of bodies the map lacks (sim time); see the module docstring."""

    def __init__(self, fp: Footprint, p: ScanParams = ScanParams()) -> None:
        self.fp, self.p = fp, p
        self.tracks: list[_Track] = []
        self._count = 0
        self._grid: Grid | None = None
        self._clearance: FloatArray = np.zeros((0, 0))
        #: The last scan's bodies (for the log).
        self.bodies: list[Body] = []
        #: The last scan's returns (k, 2, map) of clusters larger than a person: obstacles.
        self.obstacles: FloatArray = np.zeros((0, 2))

    def update(
        self,
        points: FloatArray,
        grid: Grid,
        pose: Pose,
        t_ns: int,
        views: tuple[ScanView, ...] | list[ScanView] = (),
    ) -> None:
        """One scan's returns (n, 2, map frame, beam order) at `t_ns`, the robot at `pose`;
        `views`: the scans' rays, which end the tracks they see gone (none: a track lives
        `ttl_s` unseen)."""
        p = self.p
        if grid is not self._grid:
            self._grid, self._clearance = grid, static_clearance(grid, p.island_m2)
        pts = off_map(points, self._clearance, grid, p.static_margin_m)
        if len(pts):
            d = distance_to_footprint(pose, self.fp, pts)
            pts = pts[d <= p.range_m]
        found, big = bodies_and_larger(pts, p)
        if found:
            xy = np.array([(b.x, b.y) for b in found])
            mine = distance_to_footprint(pose, self.fp, xy) <= p.robot_margin_m
            found = [b for b, m in zip(found, mine.tolist(), strict=True) if not m]
        self.bodies = found
        if len(big):
            big = big[distance_to_footprint(pose, self.fp, big) > p.robot_margin_m]
        self.obstacles = big
        self._associate(found, t_ns, views, pose)

    def _alive(self, tr: _Track, t_ns: int) -> bool:
        """Seen within `ttl_s`, or coasting: within `coast_s` and not seen gone, or
        `blind_hold_s` standing where no lidar looks."""
        p, age = self.p, t_ns - tr.last[0]
        if age <= round(p.ttl_s * NS_PER_S):
            return True
        standing = tr.velocity is not None and not tr.walking(p.standing_mps)
        coast = p.blind_hold_s if tr.blind and standing else p.coast_s
        return age <= round(coast * NS_PER_S) and not tr.cleared

    def _spread(
        self, tr: _Track, t_ns: int, views: Sequence[ScanView], pose: Pose
    ) -> tuple[float, float] | None:
        """Where a lost walker could be now, kept on `tr.places`, and the one nearest the
        footprint (None: nowhere; they are gone). The places grow from their last one at
        their pace (a cell's neighbours each `REACH_STEP_M` they could walk, never beyond
        `reach_m`), through what no beam sees free: a place seen free is dropped (a
        walker out of sight behind a shelf is not taken to be beside the trunk until they
        could have walked there unseen), as are those on the world the map knows
        (`static_margin_m`) and on the robot (`robot_margin_m`)."""
        p, grid = self.p, self._grid
        assert grid is not None
        speed = math.hypot(*tr.velocity) if tr.velocity else 0.0
        if tr.places is None:
            n = math.ceil(p.coast_s * min(speed, MAX_WALK_MPS) / REACH_STEP_M) + 1
            tr.places = np.zeros((2 * n + 1, 2 * n + 1), dtype=bool)
            tr.places[n, n] = True
            tr.grown = 0
        n = tr.places.shape[0] // 2
        r = tr.reach_m(t_ns)
        steps = min(math.ceil(r / REACH_STEP_M), n) - tr.grown
        if steps > 0:
            tr.places = ndimage.binary_dilation(tr.places, SQUARE, iterations=steps)
            tr.places &= _disc(n) <= max(r, REACH_STEP_M) ** 2 + 1e-9
            tr.grown += steps
        cells = np.argwhere(tr.places)
        xy = (cells[:, ::-1] - n) * REACH_STEP_M + np.array(tr.last[1:])
        keep = off_map_mask(xy, self._clearance, grid, p.static_margin_m)
        d = distance_to_footprint(pose, self.fp, xy)
        keep &= d > p.robot_margin_m
        for v in views:
            keep[keep] &= ~v.free(xy[keep], p.static_margin_m)
        gone = cells[~keep]
        tr.places[gone[:, 0], gone[:, 1]] = False
        if not keep.any():
            return None
        tr.place_xy = xy[keep]
        k = int(np.argmin(np.where(keep, d, np.inf)))
        return float(xy[k, 0]), float(xy[k, 1])

    def _associate(
        self,
        found: list[Body],
        t_ns: int,
        views: Sequence[ScanView] = (),
        pose: Pose | None = None,
    ) -> None:
        p = self.p
        ttl = round(p.ttl_s * NS_PER_S)
        unseen = [tr for tr in self.tracks if t_ns - tr.last[0] > ttl and not tr.cleared]
        # A walker lost: where could they be that no beam sees free?
        lost = bool(views) and pose is not None
        for tr in unseen:
            if lost and tr.walking(p.standing_mps):
                assert pose is not None
                tr.hidden = self._spread(tr, t_ns, views, pose)
                tr.cleared = tr.hidden is None
        unseen = [tr for tr in unseen if tr.hidden is None and not tr.cleared]
        # The rest: does a beam return from beyond where it would be?
        if unseen:
            where = np.array([tr.predicted(t_ns) for tr in unseen])
            gone = np.full(len(unseen), not views)
            covered = np.zeros(len(unseen), dtype=bool)
            for v in views:
                gone |= v.through(where, CLEARS_BEYOND_M, none_passes=False)
                covered |= v.covers(where)
            for tr, g, c in zip(unseen, gone.tolist(), covered.tolist(), strict=True):
                tr.cleared, tr.blind = g, bool(views) and not c
        live = [tr for tr in self.tracks if self._alive(tr, t_ns)]
        pairs = (
            (math.hypot(b.x - px, b.y - py), i, k)
            for i, b in enumerate(found)
            for k, tr in enumerate(live)
            for px, py in [tr.predicted(t_ns)]
        )
        body_track: dict[int, int] = {}
        _pair(pairs, p.gate_m, body_track)
        # Then a lost walker is any body left near a place they could be, nearest first.
        again = (
            (float(np.min(np.hypot(*(tr.place_xy - (b.x, b.y)).T))), i, k)
            for i, b in enumerate(found)
            if i not in body_track
            for k, tr in enumerate(live)
            if tr.hidden is not None and k not in body_track.values()
        )
        _pair(again, p.gate_m, body_track)
        window = round(p.velocity_window_s * NS_PER_S)
        for i, b in enumerate(found):
            if i in body_track:
                tr = live[body_track[i]]
            else:
                self._count += 1
                tr = _Track(f"scan_{self._count}", [])
                live.append(tr)
            tr.points = [q for q in tr.points if t_ns - q[0] <= window and q[0] < t_ns]
            tr.points.append((t_ns, b.x, b.y))
            tr.velocity = fitted_velocity(tr.points, p.velocity_min_span_s)
            tr.cleared = tr.blind = False
            tr.hidden, tr.places = None, None
        self.tracks = live

    def people(self, t_ns: int) -> list[Person]:
        """The tracks alive at `t_ns`, as people: where their velocity has carried them
        since they were last seen (at rest: where they were); a walker lost, at the place
        nearest the robot they could be (`_spread`)."""
        return [
            Person(tr.id, *(tr.hidden or tr.predicted(t_ns)), None, tr.velocity)
            for tr in self.tracks
            if self._alive(tr, t_ns)
        ]


def _pair(
    pairs: Iterable[tuple[float, int, int]], gate_m: float, body_track: dict[int, int]
) -> None:
    """Pairs (distance, body, track) into `body_track`, nearest first, each body and
    track once, none farther than `gate_m`."""
    taken = set(body_track.values())
    for dist, i, k in sorted(pairs):
        if dist > gate_m:
            break
        if i in body_track or k in taken:
            continue
        body_track[i] = k
        taken.add(k)


def nearest_tracks(
    tracks: Sequence[Person],
    x: float,
    y: float,
    within_m: float = TRACKS_SAID_M,
    most: int = TRACKS_SAID,
) -> list[Person]:
    """The lidar's tracks within `within_m` of (x, y), nearest first, at most `most`:
    who walks by near the robot, where its head camera may not look."""
    near = sorted((math.hypot(q.x - x, q.y - y), k) for k, q in enumerate(tracks))
    return [tracks[k] for d, k in near if d <= within_m][:most]


def handover_person(
    pid: str,
    map_people: Sequence[Person],
    layer: Sequence[Person],
    scanned: Sequence[Person],
    robot_xy: tuple[float, float],
) -> Person | None:
    """Where a handover goal's person is to be taken: the lidar's track of them when one
    is theirs in the people layer (`merge_scan`: its position is the track's), moved
    `LEGS_NEAR_SIDE_M` away from the robot to their body's centre; else the map's
    estimate, unless the layer left it out (the lidar sees free floor there: the map
    carried a walker along a stale velocity, or took someone else's detection for them);
    None when neither has them where they can be."""
    mapped = next((q for q in map_people if q.id == pid), None)
    layered = next((q for q in layer if q.id == pid), None)
    if mapped is None or layered is None:
        return None
    if not any(s.x == layered.x and s.y == layered.y for s in scanned):
        return mapped
    dx, dy = layered.x - robot_xy[0], layered.y - robot_xy[1]
    far = math.hypot(dx, dy)
    k = LEGS_NEAR_SIDE_M / far if far > 1e-6 else 0.0
    return replace(mapped, x=layered.x + k * dx, y=layered.y + k * dy)


class VelocityMemory:
    """The lidar's last measured velocity of each person of the layer (by id), kept
    `hold_s` of sim time: a person whose track broke up and began again (a new track has
    no velocity until its positions span `velocity_min_span_s`) keeps it meanwhile. The
    person handed over to, standing at 0.5-1.5 m, was a new track every second or two in
    the changing hall's shift: each time "unknown" (a walking pace: S_p at rest 1.52 m),
    a stop, and the walk to them took 152 s."""

    def __init__(self, hold_s: float = VELOCITY_HOLD_S) -> None:
        self.hold_ns = round(hold_s * NS_PER_S)
        self._last: dict[str, tuple[int, tuple[float, float]]] = {}

    def note(self, pid: str, velocity: tuple[float, float], t_ns: int) -> None:
        self._last[pid] = (t_ns, velocity)
        if len(self._last) > MEMORY_PRUNE_AT:  # ids come and go over a shift: no growth
            self._last = {k: v for k, v in self._last.items() if t_ns - v[0] <= self.hold_ns}

    def get(self, pid: str, t_ns: int) -> tuple[float, float] | None:
        """The velocity measured last for `pid` within `hold_s` before `t_ns`, else None."""
        last = self._last.get(pid)
        if last is None or t_ns - last[0] > self.hold_ns:
            return None
        return last[1]


def merge_scan(
    people: list[Person],
    scanned: list[Person],
    same_m: float,
    memory: VelocityMemory | None = None,
    t_ns: int = 0,
) -> list[Person]:
    """The people layer with the lidar's tracks: a person with a track within `same_m` (the
    nearest, each track once) is seen there now, with the track's velocity once it has
    one (noted in `memory`); until then with the one `memory` measured for them lately,
    else with the person's own only when it is a motion (a zero velocity is
    no evidence of standing: the map's for a person it made a second ago, or could not
    be sure of, is zero; the changing hall's shift: a walker coming head-on at 1 m/s,
    found again by the lidar 1.4 m off and claimed by the map's new track of them, was
    taken for standing, and the robot walked on at 0.35 m/s towards them); the tracks no
    person claims are added under their own ids."""
    out = list(people)
    free = list(range(len(scanned)))
    pairs = sorted(
        (math.hypot(q.x - s.x, q.y - s.y), i, k)
        for i, q in enumerate(people)
        for k, s in enumerate(scanned)
    )
    claimed: set[int] = set()
    for dist, i, k in pairs:
        if dist > same_m:
            break
        if i in claimed or k not in free:
            continue
        s, pid = scanned[k], people[i].id
        mapped = people[i].velocity
        moving = mapped is not None and any(mapped)
        held = memory.get(pid, t_ns) if memory is not None else None
        if s.velocity is not None and memory is not None:
            memory.note(pid, s.velocity, t_ns)
        velocity = s.velocity or held or (mapped if moving else None)
        out[i] = replace(people[i], x=s.x, y=s.y, velocity=velocity, seen_ns=None)
        claimed.add(i)
        free.remove(k)
    return out + [scanned[k] for k in free]
