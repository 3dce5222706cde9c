"""The body guard: where a command takes the footprint in the next moment must stay off
obstacles.

The planner keeps the base's centreline half a width (and a margin) from obstacles, which
is what a body walking along its path needs. But the body is longer than it is wide (front
0.52 m, back 0.62 m from the base origin) and the follower turns it to the path's heading
wherever it stands: on hall seed 0's shift a turn in place next to a pallet swept the hips
into it (50 hip and thigh contacts on pallet_3 in 45 s), the whole-body controller's
reference ran 10 cm ahead of the pinned base, and the pallet shoved the robot towards a
standing person at 0.45 m/s while navigation commanded no translation at all.

`BodyGuard(solid, grid, fp, pose)` takes one tick's obstacles known to be there (the
static layer's occupied cells and the short-lived layer's: `Costmap.solid`; people have
their own rules) and the base's pose. Unknown cells, and the world beyond the grid, are
no obstacle to it: the planner keeps the walk off them, but a body turning over floor
nobody has seen yet hits nothing the map knows of (the depth layer sees what is there).
Counted as obstacles, they held an exploring robot still at its first turn on the spot
for 57 s (the small world from nothing: 20 min of wall time, three times the walk).

`ok(cmd)` rolls a command (vx, vy, ωz in the base's yaw frame, held constant) forward
over `HORIZON_S` in `STEPS` poses and counts the footprint's points, grown by `MARGIN_M`,
on those cells at each; the command is fine when no pose along it has more than the pose
now (free stays free, and a body already touching may only move off). Given the heading
error a turn is for, the whole turn in place is checked too (`SWEEP_STEP_RAD` apart): a
turn round that can only end with a corner in a pallet is not begun. `Follower.step`
asks it of what it wants and, when refused, of the translation without the turn (walking
along the path with the heading it has: the base walks sideways and backwards too), then
of the turn without the translation, then of the turn the other way round, then of a
step straight away from where the body touches, or from the nearest obstacle within
`ROOM_M` (hall seed 5: walked 2-3 cm along a bench, every turn and the walk on refused,
it stood until the goal failed); else it stands. A robot that can do none is blocked,
and the navigator's recoveries (themselves guarded) and replans take over.

A goal pose with no room to turn in place (the body fits there at the goal's yaw, but
every turn into it sweeps a corner onto something) is turned to earlier: `turn_point`
finds the pose nearest the goal along the path where the whole turn from the heading the
body arrives with is free and from which the body at the goal's yaw walks on to the goal
free (the follower walks that part sideways or backwards).

What drives the base without a goal (the mission's visual approach, its back-off) is not
rolled out here; it gets `clearance`: how far from the base the nearest obstacle lies
along each of the base's axes, in the band the body sweeps (up to `ROOM_REACH_M` beyond
the footprint), published on `nav/status` with the people caps, so the mission slows and
stops its body short of the world
(hall seed 0's shift: the approach to a bottle deep on a bench pressed the front hip into
the bench for 2 s until its stall gave up, five contacts).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from services.navigation.grid import (
    BoolGrid,
    Footprint,
    Grid,
    Pose,
    distance_to_footprint,
    footprint_hits,
    footprint_points,
    footprints_hits,
)

#: Not settings: how far ahead (s) and in how many poses a command is rolled out, and how
#: far beyond the footprint (m) a body point counts.
HORIZON_S = 0.5
STEPS = 5
MARGIN_M = 0.02
#: rad between the headings checked along a whole turn.
SWEEP_STEP_RAD = 0.1
#: m: the room a turn in place needs beside the body (its rear corner swings 0.67 m from
#: the base, the side is 0.24 m off it): an obstacle this near is stepped away from when
#: nothing else is let through (`away`).
ROOM_M = 0.45
#: m: how far beyond the footprint `clearance` looks along each axis; farther is free (inf).
ROOM_REACH_M = 0.5
#: m: how far back from the goal along a path its turn to the goal's yaw may be moved
#: (`turn_point`).
TURN_SEARCH_M = 2.5


class BodyGuard:
    """One tick's check of commands against the obstacles; see the module docstring."""

    def __init__(self, solid: BoolGrid, grid: Grid, fp: Footprint, pose: Pose) -> None:
        self.occupied, self.grid, self.pose, self.fp = solid, grid, pose, fp
        self.local = footprint_points(fp, MARGIN_M, 0.5 * grid.resolution)
        here = np.array([pose], dtype=float)
        self.now = int(touching(self.occupied, self.grid, self.local, here)[0])

    def away(self, room_m: float = ROOM_M) -> tuple[float, float] | None:
        """The unit direction (base frame) away from the obstacle that keeps the body from
        turning: where it touches now (from the mean of its points on obstacles towards
        the base), else the nearest within `room_m` of the footprint (from the middle of
        its nearest face towards the base origin); None when there is none, or it presses
        on all sides alike."""
        if self.now:
            hits = footprint_hits(self.occupied, self.grid, self.pose, self.local, False)
            u, v = self.local[np.asarray(hits, bool)].mean(axis=0)
        else:
            near = _near_cells(self.occupied, self.grid, self.fp, self.pose, room_m)
            if near is None:
                return None
            xy, d = near
            face = xy[d <= d.min() + self.grid.resolution].mean(axis=0)  # the nearest face
            c, s = math.cos(self.pose.yaw), math.sin(self.pose.yaw)
            dx, dy = face[0] - self.pose.x, face[1] - self.pose.y
            u, v = c * dx + s * dy, -s * dx + c * dy
        norm = math.hypot(u, v)
        return None if norm < 1e-6 else (float(-u / norm), float(-v / norm))

    def rollout(self, cmd: NDArray[np.float64] | tuple[float, float, float]) -> list[Pose]:
        """The poses (`STEPS`, the last `HORIZON_S` ahead) the command takes the base to."""
        vx, vy, wz = (float(v) for v in cmd)
        dt = HORIZON_S / STEPS
        x, y, yaw = self.pose.x, self.pose.y, self.pose.yaw
        out = []
        for _ in range(STEPS):
            mid = yaw + 0.5 * wz * dt  # midpoint heading: the arc, not its chord's start
            c, s = math.cos(mid), math.sin(mid)
            x, y, yaw = x + (c * vx - s * vy) * dt, y + (s * vx + c * vy) * dt, yaw + wz * dt
            out.append(Pose(x, y, yaw))
        return out

    def ok(
        self, cmd: NDArray[np.float64] | tuple[float, float, float], turn_rad: float = 0.0
    ) -> bool:
        """Whether the command keeps the body off obstacles it is not on now; with
        `turn_rad` (the heading error the turn is for), whether the whole turn, in place
        and the command's way round, does too (one that would end stuck is not begun)."""
        if not any(abs(float(v)) > 1e-9 for v in cmd):
            return True
        poses = self.rollout(cmd)
        wz = float(cmd[2])
        at = np.array([(p.x, p.y, p.yaw) for p in poses])
        if wz and turn_rad and math.copysign(1.0, wz) == math.copysign(1.0, turn_rad):
            n = max(1, math.ceil(abs(turn_rad) / SWEEP_STEP_RAD))
            yaws = self.pose.yaw + np.linspace(turn_rad / n, turn_rad, n)
            at = np.vstack([at, np.column_stack([np.full(n, self.pose.x),
                                                 np.full(n, self.pose.y), yaws])])  # fmt: skip
        return bool(np.all(touching(self.occupied, self.grid, self.local, at) <= self.now))


def turn_point(
    solid: BoolGrid,
    grid: Grid,
    fp: Footprint,
    poses: NDArray[np.float64],
    search_m: float = TURN_SEARCH_M,
) -> int:
    """Where along a path (poses (n, 3): x, y, heading; the last the goal, its yaw the
    goal's) the body turns to the goal's yaw (module docstring): the index nearest the
    goal at which the whole turn from the heading it arrives with (the pose before's),
    one way round or the other, keeps its outline off `solid`, and from which the body
    at the goal's yaw stays off it on every pose to the goal. The goal's own index when
    the turn is free there, or when no pose within `search_m` of path before it will do
    (the guard then does what it can)."""
    last = len(poses) - 1
    if last < 1:
        return last
    local = _rim(fp, MARGIN_M, 0.5 * grid.resolution)
    goal_yaw = float(poses[-1, 2])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))])
    j = last
    while j >= 1 and s[-1] - s[j] <= search_m:
        x, y = float(poses[j, 0]), float(poses[j, 1])
        if touching(solid, grid, local, np.array([[x, y, goal_yaw]])).any():
            break  # the body cannot walk on from here at the goal's yaw
        arrive = float(poses[j - 1, 2])
        d = math.remainder(goal_yaw - arrive, math.tau)
        for way in (d, d - math.copysign(math.tau, d)):
            n = max(1, math.ceil(abs(way) / SWEEP_STEP_RAD))
            yaws = arrive + np.linspace(0.0, way, n + 1)
            sweep = np.column_stack([np.full(n + 1, x), np.full(n + 1, y), yaws])
            if not touching(solid, grid, local, sweep).any():
                return j
        j -= 1
    return last


def _rim(fp: Footprint, margin: float, spacing: float) -> NDArray[np.float64]:
    """The outline's points (n, 2, base frame) of the footprint grown by `margin`: what
    meets an obstacle first wherever the body turns or walks from a free pose (a sixth
    of the guard's points: a turn point in a tight spot in 18 ms, not 57)."""
    pts = footprint_points(fp, margin, spacing)
    u, v = pts[:, 0], pts[:, 1]
    edge = (
        np.isclose(u, u.min()) | np.isclose(u, u.max())
        | np.isclose(v, v.min()) | np.isclose(v, v.max())
    )  # fmt: skip
    return pts[edge]


def touching(
    solid: BoolGrid, grid: Grid, local: NDArray[np.float64], poses: NDArray[np.float64]
) -> NDArray[np.int64]:
    """Per pose (k, 3: x, y, yaw): how many of `local`'s points (base frame) placed there
    lie on `solid` (off the grid is no obstacle to the guard); all poses in one lookup
    (`grid.footprints_hits`)."""
    return np.count_nonzero(footprints_hits(solid, grid, poses, local, False), axis=1)


def clearance(
    solid: BoolGrid, grid: Grid, fp: Footprint, pose: Pose, reach_m: float = ROOM_REACH_M
) -> tuple[float, float, float, float]:
    """How far (m) from the base origin the nearest cell of `solid` lies ahead, behind,
    left and right within the band the footprint sweeps moving that way (its width, or
    its length, grown by `MARGIN_M` and half a cell: a cell is its centre here), less
    that growth; inf where none lies within `reach_m` of the footprint. What drives the
    base subtracts the body's own extent along the axis (the arm's posture changes the
    front): the room it has. A cell under the body counts where it lies, so the body
    may move only off it."""
    grow = MARGIN_M + 0.5 * grid.resolution
    near = _near_cells(solid, grid, fp, pose, reach_m + grow)
    if near is None:
        return (math.inf,) * 4
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    dx, dy = near[0][:, 0] - pose.x, near[0][:, 1] - pose.y
    u, v = c * dx + s * dy, -s * dx + c * dy
    along = np.abs(v) < fp.half_width + grow
    across = (u > -fp.back - grow) & (u < fp.front + grow)
    gaps = (
        u[along & (u > 0.0)],
        -u[along & (u < 0.0)],
        v[across & (v > 0.0)],
        -v[across & (v < 0.0)],
    )
    out = [float(g.min()) - grow if g.size else math.inf for g in gaps]
    return out[0], out[1], out[2], out[3]


def _near_cells(
    solid: BoolGrid, grid: Grid, fp: Footprint, pose: Pose, within_m: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The centres (n, 2, m) of `solid`'s cells within `within_m` of the footprint at
    `pose` and their distances to it; None when there are none (a window of the grid
    round the base, not the whole of it)."""
    reach = max(fp.front, fp.back, fp.half_width) + within_m + grid.resolution
    centre = grid.cell(pose.x, pose.y)
    if centre is None:
        return None
    n = math.ceil(reach / grid.resolution)
    iy0, ix0 = max(0, centre[0] - n), max(0, centre[1] - n)
    iy, ix = np.nonzero(solid[iy0 : centre[0] + n + 1, ix0 : centre[1] + n + 1])
    if not len(iy):
        return None
    xy = np.column_stack([grid.origin[0] + (ix + ix0 + 0.5) * grid.resolution,
                          grid.origin[1] + (iy + iy0 + 0.5) * grid.resolution])  # fmt: skip
    d = distance_to_footprint(pose, fp, xy)
    near = d <= within_m
    return (xy[near], d[near]) if near.any() else None


def what_is_near(
    solid: BoolGrid, static: BoolGrid, grid: Grid, fp: Footprint, pose: Pose, within_m: float = 0.1
) -> str:
    """The guard's obstacles within `within_m` of the footprint at `pose`, for a person
    reading why it refused: how many cells, of which layer (`static`: the map's; the
    rest of `solid` the short-lived depth layer's), and where the nearest lies in the
    base's frame. Only when the guard's answer changes."""
    if grid.cell(pose.x, pose.y) is None:
        return "the base is off the map"
    found = _near_cells(solid, grid, fp, pose, within_m)
    if found is None:
        return f"nothing within {within_m:.2f} m"
    xy, d = found
    iy, ix, _inside = grid.cells(xy)
    mapped = int(np.count_nonzero(static[iy, ix]))
    k = int(np.argmin(d))
    c, sn = math.cos(pose.yaw), math.sin(pose.yaw)
    dx, dy = xy[k, 0] - pose.x, xy[k, 1] - pose.y
    ahead, left = c * dx + sn * dy, -sn * dx + c * dy
    return (
        f"{len(d)} cells within {within_m:.2f} m ({mapped} the map's, "
        f"{len(d) - mapped} the depth's), the nearest {d[k]:.2f} m off at "
        f"{ahead:+.2f} m ahead, {left:+.2f} m left"
    )
