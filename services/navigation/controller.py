"""Omnidirectional regulated pure pursuit: a path and the base pose in, cmd_vel out.

Each tick (`Follower.step`; `navigation.controller` holds the limits and the lookahead):
the closest path pose ahead of the last one (the progress never goes back), a lookahead
point `lookahead_m` further along it, and a velocity in the world towards that point
whose speed is regulated down by (the minimum of) the limit `v_max[0]`, the costmap
cost at the robot (`COST_SLOWDOWN`: near obstacles it walks slower), the path's turn
within the lookahead, the remaining distance (it can stop: v ≤ √(2 a d)) and the
caller's cap (people). The heading follows the path's direction (the B1 walks forward
faster than sideways) and turns to the goal's yaw over the last `HEADING_BLEND_M`; a
large heading error holds translation back until the robot has turned. The velocity
goes to `base_yaw` (vx, vy scaled together to their limits, so the direction is kept)
and through per-axis acceleration limits. With a `guard` (`body_guard.BodyGuard`), a
command that would sweep the body onto an obstacle becomes the translation without the
turn (and without the turn-first hold), else the turn alone, else the turn the other way
round, else a stand; a refused axis stops at once, and a fallback is kept a moment
(`GUARD_HOLD_S`) before the full command is asked again.

Where the goal has no room for the body to turn in place (a standoff beside a table: the
rear corners swing 0.67 m from the base), the turn to the goal's yaw is done earlier,
at the path's turn point (`body_guard.turn_point`, given with the path): the heading
blend ends there, a heading error beyond `TURN_FIRST_RAD` past it holds the walk until
turned, and the body walks the rest at the goal's yaw, sideways or backwards as need be
(hall seed 4's shift: at a standoff by a table the guard refused the turn either way
round, and the robot stood 20 s aligning, 2.1 rad off, before the goal failed).

The final align: once inside the position tolerance the follower latches `aligning`
(released if the base drifts `ALIGN_RELEASE_M` beyond the tolerance, or out of it with
the heading already aligned, so that it walks back in): translation
stops and the heading goes to the goal's yaw itself — not the blend, whose path
direction is meaningless a few cm from the goal (it held the robot at a fixed 0.15 rad
off the goal's yaw, a stall only the recoveries broke) — at a rate of at least
`MIN_TURN_RATE` while the error exceeds half the tolerance (a trot turns poorly at
tiny rates, and a proportional command fades as the error shrinks). `arrived` once both
tolerances hold and the base is slow.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from common.config import ControllerSettings
from services.navigation.body_guard import BodyGuard
from services.navigation.grid import Pose

Vec3 = NDArray[np.float64]


#: Not settings: the follower's gains and thresholds, tuned with the trot (the settings,
#: limits and lookahead, are `ControllerSettings`, `navigation.controller`).
K_HEADING = 1.5  # 1/s, heading error → ωz
HEADING_BLEND_M = 0.8  # m before the goal over which the heading turns to its yaw
TURN_FIRST_RAD = 1.0  # heading error beyond which translation is held back
COST_SLOWDOWN = 0.5  # the speed's fraction lost at cost 1
MIN_SPEED = 0.05  # m/s, the least speed commanded while following
K_POSITION = 1.2  # 1/s, distance to the goal → speed on the last poses
MIN_TURN_RATE = 0.25  # rad/s, the least ωz while aligning
ALIGN_RELEASE_M = 0.05  # m beyond the tolerance that releases the align
CRAB_MPS = 0.2  # m/s, the most while walking on unturned (sideways, backwards: the guard)
CRAB_AHEAD_RAD = 0.3  # rad off the heading within which unturned is not "crab"
GUARD_HOLD_S = 0.5  # s a body guard's answer other than the full command is kept
CENTRE_M = 0.03  # m from the goal's point beyond which an align the guard refuses walks in
STEP_CLEAR_MPS = 0.1  # m/s, the guard's last way out: a step away from the obstacle in the way
TURN_HERE_M = 0.05  # m before a turn point (`set_path`) from which the turn holds the walk


class FollowOutput(NamedTuple):
    """cmd: (vx, vy, ωz) in base_yaw. arrived: within both tolerances and slow.
    at_index: progress along the path (pose index). remaining_m: along the path from it."""

    cmd: Vec3
    arrived: bool
    at_index: int
    remaining_m: float
    lookahead: tuple[float, float]
    direction: tuple[float, float] | None
    aligning: bool = False
    #: rad, the turn still to do to the heading reference (the goal's yaw when
    #: aligning), signed the way it turns (the long way when the guard turned it so).
    yaw_error: float = 0.0
    #: What the body guard made of a refused command: "" (none refused), "unturned"
    #: (the translation without the turn), "turn only", "the other way round", "step
    #: clear" (away from the obstacle the body touches or has no room to turn by) or "stand".
    guarded: str = ""


def limit_accel(prev: Vec3, want: Vec3, a_max: Sequence[float], dt: float) -> Vec3:
    """`want` moved no further from `prev` than a_max · dt per axis."""
    step = np.asarray(a_max) * dt
    out: Vec3 = prev + np.clip(want - prev, -step, step)
    return out


def to_base(v_world: tuple[float, float], yaw: float) -> tuple[float, float]:
    c, s = math.cos(yaw), math.sin(yaw)
    return c * v_world[0] + s * v_world[1], -s * v_world[0] + c * v_world[1]


def scale_to_limits(vx: float, vy: float, vx_max: float, vy_max: float) -> tuple[float, float]:
    """(vx, vy) scaled down together so each is within its limit."""
    k = max(abs(vx) / vx_max, abs(vy) / vy_max, 1.0)
    return vx / k, vy / k


class Follower:
    """Follows one path; `step` once per tick (see the module docstring)."""

    def __init__(
        self, poses: NDArray[np.float64], p: ControllerSettings, turn_index: int | None = None
    ) -> None:
        self.p = p
        self.set_path(poses, turn_index)
        self.cmd: Vec3 = np.zeros(3)
        self.aligning = False
        self.held, self.hold_s = "", 0.0  # the body guard's last answer, kept a moment

    def set_path(self, poses: NDArray[np.float64], turn_index: int | None = None) -> None:
        """Follow `poses`, turned to the goal's yaw by the pose `turn_index` (None: the
        goal's own; `body_guard.turn_point`)."""
        self.poses = poses
        seg = np.hypot(*np.diff(poses[:, :2], axis=0).T) if len(poses) > 1 else np.zeros(0)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])
        turn = len(poses) - 1 if turn_index is None else min(turn_index, len(poses) - 1)
        #: m of path from the turn point to the goal (0: it turns at the goal).
        self.after_turn_m = float(self.s[-1] - self.s[turn])
        self.index = 0
        self.held, self.hold_s = "", 0.0

    def remaining(self) -> float:
        return float(self.s[-1] - self.s[self.index])

    def _progress(self, x: float, y: float) -> int:
        # Search a window ahead (the robot cannot have skipped far) for the closest pose.
        end = int(np.searchsorted(self.s, self.s[self.index] + 2.0)) + 1
        window = self.poses[self.index : end, :2]
        d = np.hypot(window[:, 0] - x, window[:, 1] - y)
        return self.index + int(np.argmin(d))

    def step(
        self,
        pose: Pose,
        dt: float,
        cost_here: float,
        speed_cap: float,
        tol_xy: float,
        tol_yaw: float,
        guard: BodyGuard | None = None,
    ) -> FollowOutput:
        p = self.p
        self.index = self._progress(pose.x, pose.y)
        goal = self.poses[-1]
        to_goal = math.hypot(goal[0] - pose.x, goal[1] - pose.y)
        remaining = max(self.remaining(), to_goal if self.index == len(self.poses) - 1 else 0.0)
        la_s = self.s[self.index] + p.lookahead_m
        k = min(int(np.searchsorted(self.s, la_s)), len(self.poses) - 1)
        target = self.poses[k]
        # The heading: along the path, blending to the goal's yaw near the end.
        yaw_goal = float(goal[2])
        path_yaw = float(self.poses[min(self.index + 1, len(self.poses) - 1), 2])
        if len(self.poses) > 1 and self.index < len(self.poses) - 1:
            d = self.poses[k, :2] - np.array([pose.x, pose.y])
            if np.hypot(*d) > 0.1:
                path_yaw = math.atan2(d[1], d[0])
        goal_err = math.remainder(yaw_goal - pose.yaw, math.tau)
        if to_goal <= tol_xy:
            self.aligning = True
        elif to_goal > tol_xy + ALIGN_RELEASE_M or abs(goal_err) <= 0.5 * tol_yaw:
            self.aligning = False  # drifted out while turning: walk back in
        inside = self.aligning
        # turned by the turn point: past it the body walks on at the goal's yaw
        to_turn = remaining - self.after_turn_m
        blend = min(1.0, max(to_turn, 0.0) / HEADING_BLEND_M)
        if inside:
            blend = 0.0
        yaw_ref = yaw_goal + blend * math.remainder(path_yaw - yaw_goal, math.tau)
        yaw_err = math.remainder(yaw_ref - pose.yaw, math.tau)
        wz = float(np.clip(K_HEADING * yaw_err, -p.v_max[2], p.v_max[2]))
        if inside and abs(yaw_err) > 0.5 * tol_yaw:  # a gait turns poorly at tiny rates
            wz = math.copysign(max(abs(wz), MIN_TURN_RATE), yaw_err)
        direction: tuple[float, float] | None = None
        vx = vy = 0.0
        crab = (0.0, 0.0)  # the translation without the turn-first hold (the guard's)
        if inside and to_goal > CENTRE_M:  # the guard's: to the goal's own point, unturned
            d = ((goal[0] - pose.x) / to_goal, (goal[1] - pose.y) / to_goal)
            crab = self._translation(d, min(CRAB_MPS, K_POSITION * to_goal), pose.yaw)
        if not inside:
            ex, ey = float(target[0] - pose.x), float(target[1] - pose.y)
            norm = math.hypot(ex, ey)
            if norm > 1e-6:
                direction = (ex / norm, ey / norm)
                turn = abs(math.remainder(float(target[2]) - path_yaw, math.tau))
                speed = min(
                    p.v_max[0],
                    p.v_max[0] * (1.0 - COST_SLOWDOWN * max(cost_here, 0.0)),
                    p.v_max[0] / (1.0 + 1.5 * turn),
                    math.sqrt(2.0 * p.a_max[0] * 0.7 * remaining),
                    K_POSITION * to_goal if self.index >= len(self.poses) - 2 else math.inf,
                    speed_cap,
                )
                least = min(MIN_SPEED, speed_cap) if speed_cap > 0 else 0.0
                # Sideways or backwards the trot is slow; nearly ahead, the speed stands.
                crab_mps = CRAB_MPS if abs(yaw_err) > CRAB_AHEAD_RAD else math.inf
                crab = self._translation(direction, min(max(speed, least), crab_mps), pose.yaw)
                turned_by_now = self.after_turn_m > 0.0 and to_turn <= TURN_HERE_M
                if abs(yaw_err) > TURN_FIRST_RAD and (blend > 0.5 or turned_by_now):
                    speed *= max(0.0, 1.0 - (abs(yaw_err) - TURN_FIRST_RAD) / 0.5)
                vx, vy = self._translation(direction, max(speed, least), pose.yaw)
        want = np.array([vx, vy, wz])
        guarded = ""
        if guard is not None:
            guarded, want, yaw_err = self._guarded(guard, want, crab, yaw_err, dt)
        self.cmd = limit_accel(self.cmd, want, p.a_max, dt)
        slow = float(np.hypot(self.cmd[0], self.cmd[1])) < 0.05
        arrived = to_goal <= tol_xy and abs(goal_err) <= tol_yaw and slow
        return FollowOutput(
            self.cmd.copy(),
            arrived,
            self.index,
            remaining,
            (float(target[0]), float(target[1])),
            direction,
            inside,
            yaw_err,
            guarded,
        )

    def _guarded(
        self, guard: BodyGuard, want: Vec3, crab: tuple[float, float], yaw_err: float, dt: float
    ) -> tuple[str, Vec3, float]:
        """What the body guard lets through of `want`: (its answer, the command, the turn
        still to do the way it turns). Refused, in order: the translation along the path
        without the turn (aligning, inside a loose tolerance: to the goal's own point,
        where its sender made room: a patrol's viewpoint 0.36 m off could not turn), the
        turn alone, the turn the other way round (the body is longer behind than ahead:
        one way round may sweep a corner into a pallet where the other does not), a step
        away from where the body touches or from the nearest obstacle in the way of a turn
        (`body_guard.ROOM_M`), else stand. An answer other than the full command is kept
        `GUARD_HOLD_S` before the full command is asked again (it flipped at the tick's
        rate along a pallet's edge); one the guard refuses is dropped at once. Stepping
        clear, it steps on until a turn is let through before it walks on unturned (hall
        seed 2's shift: the walk to the goal's point took it back to where the turn was
        refused, 5 cm back and forth for 34 s)."""
        wz = float(want[2])
        other = -math.copysign(max(abs(wz), MIN_TURN_RATE), yaw_err)
        ways: dict[str, tuple[Vec3, float] | None] = {
            "": (want, yaw_err),
            "unturned": (np.array([*crab, 0.0]), yaw_err),
            "turn only": (np.array([0.0, 0.0, wz]), yaw_err),
            "the other way round": (
                np.array([0.0, 0.0, other if abs(yaw_err) > 1e-3 else 0.0]),
                yaw_err - math.copysign(math.tau, yaw_err),
            ),
            "step clear": None,  # looked for only when asked (`_step_clear`): seldom
        }
        self.hold_s = max(0.0, self.hold_s - dt)
        order = list(ways)
        if self.held in ways and self.hold_s > 0.0:
            order.remove(self.held)
            order.insert(0, self.held)
        if self.held == "step clear":  # the walk on would only take it back: a turn first
            order.remove("unturned")
            order.append("unturned")
        label, cmd, turn = "stand", np.zeros(3), yaw_err
        for k in order:
            c, t = ways[k] or (self._step_clear(guard), yaw_err)
            if (k == "" or c.any()) and guard.ok(c, t):
                label, cmd, turn = k, c, t
                break
        if label != self.held:
            self.held, self.hold_s = label, GUARD_HOLD_S if label else 0.0
        if label:
            self.cmd = np.where(cmd * self.cmd > 0.0, self.cmd, 0.0)  # a refused axis stops now
        return label, cmd, turn

    @staticmethod
    def _step_clear(guard: BodyGuard) -> Vec3:
        """The guard's last way out: `STEP_CLEAR_MPS` away from where the body touches or
        from the nearest obstacle in the way of a turn (`BodyGuard.away`); none without."""
        away = guard.away()
        if away is None:
            return np.zeros(3)
        return np.array([STEP_CLEAR_MPS * away[0], STEP_CLEAR_MPS * away[1], 0.0])

    def _translation(
        self, direction: tuple[float, float], speed: float, yaw: float
    ) -> tuple[float, float]:
        """(vx, vy) in the base's yaw frame for `speed` along the world `direction`."""
        vx, vy = to_base((speed * direction[0], speed * direction[1]), yaw)
        return scale_to_limits(vx, vy, self.p.v_max[0], self.p.v_max[1])

    def stop(self, dt: float) -> Vec3:
        """Brake to rest within the acceleration limits."""
        self.cmd = limit_accel(self.cmd, np.zeros(3), self.p.a_max, dt)
        return self.cmd.copy()
