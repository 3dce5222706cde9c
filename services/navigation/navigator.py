"""One goal's life: plan, follow, replan, recover, succeed or fail — pure, on sim time.

`Navigator.tick(t, pose, world, velocity)` runs once per period with the costmap and
people of the tick (and the base's measured velocity in the map) and returns the cmd_vel
and the status. Its settings are `NavigationSettings` (the
follower's `controller`, the planner's `planner`, the people rules' `people`). Per goal:
- (re)plan at start, every `replan_s`, and when the path ahead (`BLOCKED_LOOKAHEAD_M`) crosses
  a lethal cell; a periodic replan keeps the held path while it is free and the new one
  is not clearly cheaper (`SWITCH_GAIN`, `SWITCH_MIN_M`: hysteresis, so that two
  near-equal ways do not swap each second), except while the goal is blocked, after a
  recovery and after a retarget, which take the new plan; a plan that fails while a path
  is held keeps the old one until `blocked_timeout_s`; a goal in an obstacle fails
  `invalid_goal` only on its first plan: later, what covers it is the short-lived layers
  (depth, people), so it counts as blocked (the `clear` recovery may free it);
- follow with `Follower`, capped by `people_limit` (a stop for a person counts as blocked
  time, so a person who stays leads to a replan around them, then to recovery); under a
  stop the base stands, not turning on the spot either: a trot turning on the spot
  steps and sways the trunk, and the body's ends sweep at the turn rate (the changing
  hall's shift: its separation violations at 0.05-0.12 m/s came with the robot turning
  on the spot at 0.1-0.8 rad/s beside a person walking past); the goal's final turn on
  the spot (no path left to follow) is a stop within a bystander's protective
  separation at rest too; the body guard's answers that walk another way than the path
  (unturned, a step clear of a table) are held to the rules for their own way
  (`people.within_people`);
- progress is the remaining distance shrinking by 5 cm, or the heading error (to the
  follower's reference: the goal's yaw when aligning) shrinking by 0.05 rad (a turn the
  body guard sends the other way round counts from where it began);
- when blocked for `blocked_timeout_s` (no plan, or no progress; `people.wait_s` longer
  while a person is within `people.slow_radius_m` of the footprint or of the goal,
  "waiting for <person>": people move), recoveries in order:
  clear the short-lived layer, rotate in place (`ROTATE_S`), back off (`BACKOFF_S`), each
  followed by a replan, the people rules holding them as they hold a path (a rotation
  or a step back inside a bystander's protective separation is a stop: before, the
  recoveries moved whoever stood there); after them, `failed: blocked` (or `no_path`
  when no plan was ever found);
- a stop held `blocked_timeout_s` for a person standing within their S_p at rest (and
  the stop's resume margin) of the footprint (`people_limit` lets only a way clearly
  away from them move; the path rarely leads so) is a step away from them first
  (`STEP_AWAY_SPEED`, until `STEP_CLEAR_M` beyond that, at most `STEP_AWAY_S`; once
  per person and goal; a person the sensors see now, not the map's estimate alone),
  held by everybody else's rules and the body guard, before the
  wait for them to pass: seed 0's shift began a request 0.68 m from the worker it had
  just handed to, and stood 46 s and two recoveries before it moved;
- a stop held, at the recoveries' turn, for a person only the map has (not seen for
  `STALE_S`: a stale estimate; a camera's sighting kept out of view counts from when it
  was seen) where the lidar cannot clear them: beside the body's flank, in the wedge
  neither lidar sees, or within `CLEAR_RADIUS_M` of a lidar, too near for its beams to
  judge (hall seed 4's shift stood 200 s and failed for a worker's old place 0.16 m off
  the rear corner), with no wait for them to pass (`people.wait_s`: nothing would see them
  pass; hall seed 4's shift stood 23 s and 25 s for two such, nobody there), the first
  recovery is a slide instead (once per person and goal: hall seed 5's shift slid past
  one ghost, and a camera sighting of a walker gone by, kept beside the flank, then
  held the same goal 20 s and three recoveries): a
  straight walk ahead or back along the flank (`SLIDE_M` at `SLIDE_SPEED`), held by the
  people rules of everybody else, and by that person's only when it heads towards them
  (inside S_p at rest the rules let only a way 60° away from a person move: along the
  flank is not). It sweeps only floor the lidars see, never the flank's side; from
  there the lidar sees the place (and navigation drops a person it sees free). Hall seed
  0's shift: a walker's last place beside the flank held the robot 300 s (two
  requests), nobody there; turning and stepping back were stops for it, and stepping
  away from a person's estimate walked into a real person once (reverted);
- every command, the follower's and the recoveries', goes through the body guard
  (`body_guard`): it may not sweep the footprint onto obstacles;
- a handover goal held by a protective stop for somebody else (a bystander standing by
  the handover pose) within `HANDOVER_NEAR_M` of its pose, its heading within tolerance,
  has arrived: the arm reaches the rest, and the person handed to is not the one in the
  way (hall seed 10's shift stood 0.14 m from the handover pose, 0.05 rad off it, 129 s
  and every recovery while person_4 stood 0.65 m off the footprint, S_p at rest 0.61 m;
  the can it carried crept out of the jaws meanwhile);
- `goal_timeout_s` of sim time on one goal: `failed: timeout`;
- `retarget` moves the goal's pose (a handover whose person's estimate moved): replan.
`cancel` brings the command to zero at once (the WBC's own acceleration limits shape it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from common import robot
from common.config import NavigationSettings, PeopleSettings
from common.geometry import wrap_angle
from common.messages.base import NS_PER_S
from common.messages.navigation import NavFailure, NavState
from services.navigation.body_guard import HORIZON_S, BodyGuard, turn_point
from services.navigation.controller import Follower
from services.navigation.costmap import Costmap, Person
from services.navigation.grid import Footprint, Pose, distance_to_footprint
from services.navigation.people import (
    NO_LIMIT,
    RESUME_MARGIN_M,
    SpeedLimit,
    bearing,
    people_limit,
    separation_params,
    within_people,
)
from services.navigation.planner import Plan, PlanError, path_cost, plan
from services.navigation.scan_people import CLEAR_RADIUS_M
from services.navigation.separation import protective_distance

Recovery = Literal["", "clear", "rotate", "backoff", "slide", "step_away"]


#: Not settings (the navigator's are in `NavigationSettings`): how far ahead a lethal cell
#: on the path means a replan (m), how long the rotate and back-off recoveries last (s),
#: the rotation's rate (rad/s) and the back-off's speed (m/s).
BLOCKED_LOOKAHEAD_M = 1.5
ROTATE_S = 3.0
ROTATE_RATE = 0.5
BACKOFF_S = 1.5
BACKOFF_SPEED = 0.15
#: The slide (module docstring): a map person unseen this long (s) beside the flank may
#: be slid past, this far (m: their place then lies beyond the body's end, in a lidar's
#: view) at this speed (m/s).
STALE_S = 10.0
#: The body guard's answers that translate another way than the path (`Follower._guarded`):
#: held to the people rules for their own way (`people.within_people`).
GUARD_WAYS = ("unturned", "step clear")
SLIDE_M = 1.2
SLIDE_SPEED = 0.2
#: m: where the lidars stand along the base's axis (front, rear): a place within
#: `CLEAR_RADIUS_M` of one is too near for its beams to judge.
LIDARS_AHEAD_M = tuple(
    float(m.T_parent_lidar[0, 3]) for m in (robot.LIDAR_MOUNT, robot.LIDAR_REAR_MOUNT)
)
#: m the body guard looks along the slide's way before each step (its own 0.5 s at 0.2 m/s:
#: 0.3 m stood hall seed 0's slide still beside its ghost, an obstacle 0.1-0.3 m on).
SLIDE_LOOK_M = 0.1
#: A periodic replan takes the new path over the held one (free, to the same goal) only
#: when it is cheaper (`planner.path_cost`) by this fraction of the held one's cost and
#: by at least `SWITCH_MIN_M`: two near-equal ways round a table or a person otherwise
#: swap with each small change of cost, and the robot turns back and forth between them
#: (hall seed 4's shift walked 180 s to and fro at a crossroads 2 m from its viewpoint).
SWITCH_GAIN = 0.15
SWITCH_MIN_M = 0.5
#: The path pose this many ahead gives the direction of travel (the people rules).
PROBE_POSES = 10
#: m/s: a person whose estimated speed is under this stands (`_step_away`).
STANDING_MPS = 0.2
#: The step away from a person standing too near (module docstring): speed (m/s), how far
#: beyond their S_p at rest and the resume margin it ends (m), and its longest (s).
STEP_AWAY_SPEED = 0.15
STEP_CLEAR_M = 0.05
STEP_AWAY_S = 3.0
#: s: a person the sensors saw this recently is there now (a step away is from them only:
#: one only the map has, beside the flank, is slid past; `STALE_S`).
SEEN_NOW_S = 1.0
#: m/s: the base's measured velocity, when at least this, is one more direction of travel
#: for the people rules (below it, the trot's sway gives it no meaning). The trot does not
#: go quite where it is sent: turning onto a bend it stepped sideways at 0.23 m/s towards
#: a person its path ran past (the changing hall's shift, t = 19 s).
MEASURED_MIN_MPS = 0.1
#: s a stop that came early for a person coming towards the robot may hold before it no
#: longer comes early for them (`Navigator._early`).
EARLY_STOP_S = 2.0
#: m: a handover goal held by a stop for somebody else this near its pose has arrived
#: (module docstring).
HANDOVER_NEAR_M = 0.25


@dataclass(frozen=True)
class GoalSpec:
    """A resolved goal: id, pose, tolerances, and the person handed over to (if any)."""

    goal_id: str
    pose: Pose
    tol_xy: float
    tol_yaw: float
    handover_id: str = ""
    #: Where the person handed over to was when the pose was chosen (m, world).
    person_xy: tuple[float, float] | None = None
    #: The side of the person the goal asked for (`PersonHandover.bearing_rad`).
    bearing: float | None = None
    #: How far from the person the handover stands (m; `PersonHandover.extra_m` added;
    #: None: not a handover).
    distance: float | None = None


class TickOutput(NamedTuple):
    cmd: NDArray[np.float64]
    state: NavState
    reason: NavFailure
    detail: str
    progress: float
    remaining_m: float
    new_plan: Plan | None
    limit: SpeedLimit
    recovery: Recovery
    #: The body guard's answer to a refused command this tick ("": none refused).
    guarded: str = ""


class Navigator:
    """The active goal's state machine (see the module docstring)."""

    def __init__(self, fp: Footprint, n: NavigationSettings, period_s: float) -> None:
        self.fp, self.n, self.dt = fp, n, period_s
        #: The base's top speed: a people ramp's cap at or above it is no cap.
        self.top_mps = max(n.controller.v_max[0], n.controller.v_max[1])
        self.goal: GoalSpec | None = None
        #: The goal the state is about: the active or last goal's, or a refused one's.
        self.goal_id = ""
        self.state: NavState = "idle"
        self.reason: NavFailure = ""
        self.detail = ""
        self.cmd = np.zeros(3)
        self.plan: Plan | None = None
        self.follower: Follower | None = None
        self.recovery: Recovery = ""
        self.total_m = 0.0
        self.limit_rule = ""
        self.guarded = ""
        #: A stop that came early for a person coming towards the robot (`people_limit`'s
        #: `stopping_s`): since when it holds (sim ns), and who it no longer comes early
        #: for (it held `EARLY_STOP_S`: they did not come; a stale velocity, a phantom).
        self.early_since: tuple[str, int] | None = None
        self.not_early: set[str] = set()

    def _early(self, t_ns: int, limit: SpeedLimit) -> None:
        """Note a stop that came early for a person coming (their separation beyond S_p at
        rest); held `EARLY_STOP_S`, it no longer comes early for them (a person walking at
        the robot is within S_p at rest by then: seed 1's shift stood 15 s for a camera
        phantom 1.4 m off whose velocity said it came, S_p at rest 1.14 m)."""
        early = limit.rule == "stop" and limit.distance_m >= limit.protective_m
        if not early:
            self.early_since = None
            return
        if self.early_since is None or self.early_since[0] != limit.person_id:
            self.early_since = (limit.person_id, t_ns)
        elif t_ns - self.early_since[1] >= EARLY_STOP_S * NS_PER_S:
            self.not_early.add(limit.person_id)
            self.early_since = None

    def start(self, goal: GoalSpec, t_ns: int) -> None:
        self.goal, self.state, self.reason, self.detail = goal, "active", "", "planning"
        self.goal_id = goal.goal_id
        self.t0 = t_ns
        self.plan = None
        self.follower = None
        self.planned_once = False
        self.last_plan_ns = -(10**18)
        self.take_next = True  # the next plan replaces the held one, whatever it costs
        self.blocked_since: int | None = None
        self.recoveries: list[Recovery] = ["clear", "rotate", "backoff"]
        self.recovery = ""
        self.recovery_until = 0
        self.slid: set[str] = set()  # the people slid past (once per person and goal)
        self.early_since, self.not_early = None, set()
        self.stepped: set[str] = set()  # the people stepped away from (`_step_away`)
        self.step_person = ""  # the one the step away is from
        self.slide_sign = 0.0  # +1 ahead, -1 back
        self.slide_person = ""  # the stale person slid past
        self.best_remaining = math.inf
        self.best_yaw_error = math.inf
        self.progress_ns = t_ns
        self.total_m = 0.0
        self.limit_rule = ""

    def retarget(self, pose: Pose, person_xy: tuple[float, float], t_ns: int) -> None:
        """The active goal's pose moves (a handover: the person's estimate moved); the
        next tick replans to it, and progress is measured afresh."""
        if self.state != "active" or self.goal is None:
            return
        self.goal = replace(self.goal, pose=pose, person_xy=person_xy)
        self.last_plan_ns = -(10**18)
        self.take_next = True  # the next plan replaces the held one, whatever it costs
        self.best_remaining = self.best_yaw_error = math.inf
        self.progress_ns = t_ns

    def refuse(self, goal_id: str, detail: str, reason: NavFailure = "invalid_goal") -> None:
        """A goal taken before it could be resolved (no map yet) that turned out invalid,
        or whose map never came (`timeout`): it ends failed without ever starting."""
        self.goal, self.goal_id = None, goal_id
        self._finish("failed", reason, detail)
        self.plan = self.follower = None
        self.total_m = 0.0

    def cancel(self, reason: str) -> None:
        if self.state == "active":
            self.state, self.reason, self.detail = "cancelled", "cancelled", reason
        self.cmd = np.zeros(3)

    def _finish(self, state: NavState, reason: NavFailure, detail: str) -> None:
        self.state, self.reason, self.detail = state, reason, detail
        self.cmd = np.zeros(3)

    def _out(self, limit: SpeedLimit = NO_LIMIT, new_plan: Plan | None = None) -> TickOutput:
        remaining = self.follower.remaining() if self.follower else 0.0
        progress = 0.0 if self.total_m <= 0 else min(1.0, max(0.0, 1.0 - remaining / self.total_m))
        if self.state == "succeeded":
            progress, remaining = 1.0, 0.0
        return TickOutput(
            self.cmd.copy(), self.state, self.reason, self.detail, progress, remaining,
            new_plan, limit, self.recovery, self.guarded,
        )  # fmt: skip

    def _replan(self, t_ns: int, pose: Pose, cm: Costmap, hold: bool = False) -> Plan | None:
        """Plan afresh; with `hold`, the held path stays unless the new one is clearly
        better (`_switch`). None: no new plan (failed, or the held one kept)."""
        assert self.goal is not None
        self.last_plan_ns = t_ns
        first, self.planned_once = not self.planned_once, True
        try:
            new = plan(cm, pose, self.goal.pose, self.fp, self.n.planner)
        except PlanError as exc:
            self.detail = str(exc)
            if exc.reason == "invalid_goal" and first:
                self._finish("failed", "invalid_goal", str(exc))
            return None
        if hold and not self._switch(new, pose, cm):
            return None
        self.plan = new
        turn = turn_point(cm.solid, cm.grid, self.fp, new.poses)
        if self.follower is None:
            self.follower = Follower(new.poses, self.n.controller, turn)
            self.total_m = new.length_m
        else:
            self.follower.set_path(new.poses, turn)
        self.detail = f"following a {new.length_m:.1f} m path"
        if self.follower.after_turn_m > 0.0:
            self.detail += (f", turned to the goal's heading {self.follower.after_turn_m:.1f} m "
                            "before it (no room to turn there)")  # fmt: skip
        return new

    def _switch(self, new: Plan, pose: Pose, cm: Costmap) -> bool:
        """Whether `new` replaces the held plan: it goes to another goal pose, the held
        path is no longer free, or `new` is cheaper by `SWITCH_GAIN` and `SWITCH_MIN_M`."""
        held, f = self.plan, self.follower
        if held is None or f is None or new.goal != held.goal:
            return True
        rest = np.vstack([[pose.x, pose.y, pose.yaw], f.poses[f.index :]])
        w = self.n.planner.cost_weight
        held_cost, new_cost = path_cost(cm, rest, w), path_cost(cm, new.poses, w)
        return not math.isfinite(held_cost) or held_cost - new_cost > max(
            SWITCH_GAIN * held_cost, SWITCH_MIN_M
        )

    def _path_blocked(self, cm: Costmap) -> bool:
        if self.follower is None:
            return True
        f = self.follower
        end = int(np.searchsorted(f.s, f.s[f.index] + BLOCKED_LOOKAHEAD_M)) + 1
        ahead = f.poses[f.index + 1 : end, :2]
        if not len(ahead):
            return False
        iy, ix, inside = cm.grid.cells(ahead)
        return bool(np.any(cm.cost[iy, ix] < 0) | np.any(~inside))

    def tick(
        self,
        t_ns: int,
        pose: Pose,
        cm: Costmap,
        velocity: tuple[float, float] = (0.0, 0.0),
    ) -> TickOutput:
        was_guarded, self.guarded = self.guarded, ""
        if self.state != "active" or self.goal is None:
            self.cmd = np.zeros(3)
            return self._out()
        g = self.goal
        if t_ns - self.t0 > self.n.goal_timeout_s * NS_PER_S:
            self._finish("failed", "timeout", f"not there after {self.n.goal_timeout_s:.0f} s")
            return self._out()
        new_plan = None
        if self.recovery:
            return self._recover(t_ns, pose, cm)
        blocked_path = self.plan is not None and self._path_blocked(cm)
        due = t_ns - self.last_plan_ns >= self.n.replan_s * NS_PER_S
        if self.plan is None or blocked_path or due:
            hold = not (self.take_next or blocked_path) and self.blocked_since is None
            self.take_next = False
            new_plan = self._replan(t_ns, pose, cm, hold)
            if self.state != "active":
                return self._out()
            if new_plan is None and blocked_path:
                self.plan = None  # the held path runs through an obstacle: do not follow it
        if self.plan is None or self.follower is None:
            self.cmd = self.follower.stop(self.dt) if self.follower else np.zeros(3)
            return self._blocked(t_ns, pose, cm, NO_LIMIT, new_plan)
        f = self.follower
        # The people cap needs the direction of travel: the follower's, uncapped, and,
        # as the base may move along any of them in the next moment (a trot round a bend
        # lags the path), the path's nearer poses and the heading. None while the final
        # align turns on the spot (it commands no translation: the turn's own rule; seed
        # 0's shift stood 110 s 8 cm from a handover pose, 24° off, its turn stopped as a
        # step towards a bystander 0.72 m off, S_p at rest 0.62 m and the stop's margin).
        ways = []
        for k in (PROBE_POSES, 3, 6) if not f.aligning else ():
            ahead = f.poses[min(f.index + k, len(f.poses) - 1), :2] - np.array([pose.x, pose.y])
            norm = float(np.hypot(*ahead))
            if norm > 1e-3:
                ways.append((float(ahead[0] / norm), float(ahead[1] / norm)))
        direction = ways[0] if ways else None
        # The heading only where the path leads within 90° of it: walking backwards the base
        # does not go where it faces (seed 1's shift: the step back from the worker handed
        # to, who stood inside their separation at rest, stopped as a step towards them).
        heading = (math.cos(pose.yaw), math.sin(pose.yaw))
        forwards = (
            direction is not None and heading[0] * direction[0] + heading[1] * direction[1] > 0
        )
        also = (*ways[1:], *([heading] if forwards else []))
        speed = math.hypot(*velocity)
        if ways and speed >= MEASURED_MIN_MPS:
            also = (*also, (velocity[0] / speed, velocity[1] / speed))
        pp = self.n.people  # stopping from the speed now (stopped: from the one it resumes at)
        stopping = max(speed, pp.slow_speed if self.limit_rule == "stop" else 0.0)
        limit = people_limit(pose, direction, cm.people, self.fp, pp, self.top_mps,
                             g.handover_id, self.limit_rule == "stop", also,
                             turning=direction is None,
                             stopping_s=stopping / pp.brake_decel_mps2,
                             not_early=self.not_early)  # fmt: skip
        self._early(t_ns, limit)
        self.limit_rule = limit.rule
        guard = BodyGuard(cm.solid, cm.grid, self.fp, pose)
        out = f.step(pose, self.dt, max(cm.cost_at(pose.x, pose.y), 0.0), limit.speed,
                     g.tol_xy, g.tol_yaw, guard)  # fmt: skip
        self.cmd = out.cmd
        self.guarded = out.guarded
        if out.guarded in GUARD_WAYS and limit.rule != "stop":
            # the guard's way is not the path's the cap was taken along: its own rules
            self.cmd, held = within_people(self.cmd, pose, cm.people, self.fp, self.n.people,
                                           self.top_mps, g.handover_id)  # fmt: skip
            if held.speed < limit.speed:
                limit = held
                self.limit_rule = limit.rule
            f.cmd = self.cmd.copy()
        if limit.rule == "stop":  # the protective stop: at rest, no turn on the spot either
            self.cmd = np.zeros(3)
            f.cmd = self.cmd.copy()
        elif self.cmd[2] != 0.0 and self._inside_someones_separation(pose, cm, g.handover_id):
            # Walking away from a bystander inside their separation at rest: straight on, no
            # turn (its ends sweep, and the trot's turn sways the base: seed 4's shift swept
            # it 0.05 m/s towards a walker passing 0.38 m behind, S_p 0.418 m).
            self.cmd[2] = 0.0
            f.cmd = self.cmd.copy()
        if out.arrived:
            self._finish("succeeded", "", f"at ({pose.x:.2f}, {pose.y:.2f}, {pose.yaw:.2f})")
            return self._out(limit, new_plan)
        if limit.rule == "stop" and (short := self._handover_near(pose, limit)) is not None:
            self._finish("succeeded", "", f"at ({pose.x:.2f}, {pose.y:.2f}, {pose.yaw:.2f}), "
                         f"{short:.2f} m from the handover pose: {limit.person_id} stands "
                         "within their separation")  # fmt: skip
            return self._out(limit, new_plan)
        yaw_error = abs(out.yaw_error)
        if out.guarded == "the other way round" != was_guarded:
            self.best_yaw_error = yaw_error  # the long way round counts from here (no progress)
        if out.remaining_m < self.best_remaining - 0.05 or yaw_error < self.best_yaw_error - 0.05:
            self.best_remaining = min(self.best_remaining, out.remaining_m)
            self.best_yaw_error = yaw_error
            self.progress_ns = t_ns
        if limit.rule == "stop" or t_ns - self.progress_ns > self.n.blocked_timeout_s * NS_PER_S:
            return self._blocked(t_ns, pose, cm, limit, new_plan)
        self.blocked_since = None
        return self._out(limit, new_plan)

    def _handover_near(self, pose: Pose, limit: SpeedLimit) -> float | None:
        """How far (m) from its pose a handover goal stopped for somebody else is, when
        that is near enough to hand over from (`HANDOVER_NEAR_M`, the heading within
        tolerance); else None."""
        g = self.goal
        if g is None or not g.handover_id or limit.person_id in ("", g.handover_id):
            return None
        d = math.hypot(g.pose.x - pose.x, g.pose.y - pose.y)
        off = abs(wrap_angle(g.pose.yaw - pose.yaw))
        return d if d <= HANDOVER_NEAR_M and off <= g.tol_yaw else None

    def _inside_someones_separation(self, pose: Pose, cm: Costmap, handover_id: str) -> bool:
        """Whether a person other than the one handed over to stands inside their
        protective separation at rest of the footprint (a turn there is a stop:
        `people_limit(turning=True)`)."""
        rule = people_limit(pose, None, cm.people, self.fp, self.n.people, self.top_mps,
                            handover_id, turning=True)  # fmt: skip
        return rule.rule == "stop"

    def _blocked(
        self, t_ns: int, pose: Pose, cm: Costmap, limit: SpeedLimit, new_plan: Plan | None
    ) -> TickOutput:
        if self.blocked_since is None:
            self.blocked_since = t_ns
        who = limit.person_id if limit.rule == "stop" else self._person_near(pose, cm)
        # A person no sensor has seen for `STALE_S` beside the flank is not waited for to
        # pass (nothing would see them pass): slid past as soon as the block is due.
        sign = (
            self._slide_way(t_ns, pose, cm, limit)
            if limit.rule == "stop" and limit.person_id not in self.slid
            else 0.0
        )
        wait_s = self.n.blocked_timeout_s + (self.n.people.wait_s if who and not sign else 0.0)
        if t_ns - self.blocked_since < wait_s * NS_PER_S:
            if who and t_ns - self.blocked_since >= self.n.blocked_timeout_s * NS_PER_S:
                self.detail = f"waiting for {who} to pass"
                if limit.rule == "stop" and self._step_away(t_ns, cm, limit):
                    self.blocked_since = None
            return self._out(limit, new_plan)
        if not self.recoveries:
            reason: NavFailure = "blocked" if self.total_m > 0 else "no_path"
            self._finish("failed", reason, f"{reason}: {self.detail}; recoveries exhausted")
            return self._out(limit, new_plan)
        if sign:
            self.recovery, self.slide_sign = "slide", sign
            self.slid.add(self.slide_person)
        else:
            self.recovery = self.recoveries.pop(0)
        self.blocked_since = None
        span = {"clear": 0.0, "rotate": ROTATE_S, "backoff": BACKOFF_S,
                "slide": SLIDE_M / SLIDE_SPEED}  # fmt: skip
        self.recovery_until = t_ns + round(span[self.recovery] * NS_PER_S)
        self.detail = f"recovery: {self.recovery}"
        return self._out(limit, new_plan)

    def _step_away(self, t_ns: int, cm: Costmap, limit: SpeedLimit) -> bool:
        """The stop's person stands within their S_p at rest and the resume margin: the
        step away from them begins (module docstring); whether it did."""
        who = limit.person_id
        person = next((q for q in cm.people if q.id == who), None)
        if person is None or who in self.stepped or not standing(person):
            return False
        near = limit.distance_m < limit.protective_m + RESUME_MARGIN_M
        handing = self.goal is not None and who == self.goal.handover_id
        seen = person.seen_ns is None or t_ns - person.seen_ns <= SEEN_NOW_S * NS_PER_S
        if handing or not near or not seen:
            return False
        self.stepped.add(who)
        self.recovery, self.step_person = "step_away", who
        self.recovery_until = t_ns + round(STEP_AWAY_S * NS_PER_S)
        self.detail = f"recovery: step away from {who}"
        return True

    def _slide_way(self, t_ns: int, pose: Pose, cm: Costmap, limit: SpeedLimit) -> float:
        """+1 (ahead) or -1 (back): the way to slide past the person who holds the stop,
        when they qualify (module docstring) and the way neither heads towards them nor
        is held by anybody else's rules, nor by the body guard; 0 otherwise. Sets
        `slide_person` when it is not 0."""
        who = next((q for q in cm.people if q.id == limit.person_id), None)
        if who is None or who.seen_ns is None or t_ns - who.seen_ns < STALE_S * NS_PER_S:
            return 0.0
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        dx, dy = who.x - pose.x, who.y - pose.y
        u, v = c * dx + s * dy, -s * dx + c * dy
        beside = -self.fp.back <= u <= self.fp.front and abs(v) >= self.fp.half_width
        by_a_lidar = any(math.hypot(u - a, v) <= CLEAR_RADIUS_M for a in LIDARS_AHEAD_M)
        if not (beside or by_a_lidar):
            return 0.0  # ahead or behind, where a lidar sees
        guard = BodyGuard(cm.solid, cm.grid, self.fp, pose)
        for sign in (-1.0, 1.0) if u > 0.0 else (1.0, -1.0):  # away from them first
            if self._slide_limit(pose, cm, sign, who.id).rule != "stop" and _slide_free(
                guard, sign
            ):
                self.slide_person = who.id
                return sign
        return 0.0

    def _slide_limit(self, pose: Pose, cm: Costmap, sign: float, stale_id: str) -> SpeedLimit:
        """The people rules for a slide `sign` (+1 ahead, -1 back): everybody's but the
        stale person's, for whom a stop only when the slide heads towards them (it goes
        along the flank)."""
        way = (sign * math.cos(pose.yaw), sign * math.sin(pose.yaw))
        for q in cm.people:
            if q.id == stale_id:
                n = bearing(pose, self.fp, (q.x, q.y))
                if n[0] * way[0] + n[1] * way[1] > 1e-6:
                    return SpeedLimit(0.0, "stop", q.id)
        others = [q for q in cm.people if q.id != stale_id]
        handing = self.goal.handover_id if self.goal else ""
        return people_limit(pose, way, others, self.fp, self.n.people, self.top_mps,
                            handing, self.limit_rule == "stop")  # fmt: skip

    def _person_near(self, pose: Pose, cm: Costmap) -> str:
        """The nearest person within the slow radius of the footprint or of the goal
        ("" when none; not the one a handover goes to): one who may block the way."""
        if self.goal is None:
            return ""
        people = [q for q in cm.people if q.id != self.goal.handover_id]
        if not people:
            return ""
        pts = np.array([[q.x, q.y] for q in people])
        d = distance_to_footprint(pose, self.fp, pts)
        g = self.goal.pose
        d_goal = np.hypot(pts[:, 0] - g.x, pts[:, 1] - g.y)
        near = np.minimum(d, d_goal)
        k = int(np.argmin(near))
        return people[k].id if near[k] <= self.n.people.slow_radius_m else ""

    def _away(self, pose: Pose, cm: Costmap) -> tuple[float, float] | None:
        """The world direction straight away from the person stepped away from; None
        once they are `STEP_CLEAR_M` beyond their S_p at rest and the resume margin (or
        gone from the layer)."""
        who = next((q for q in cm.people if q.id == self.step_person), None)
        if who is None:
            return None
        d = float(distance_to_footprint(pose, self.fp, np.array([[who.x, who.y]]))[0])
        if d >= stand_clear_m(self.n.people) + STEP_CLEAR_M:
            return None
        n = bearing(pose, self.fp, (who.x, who.y))
        return -n[0], -n[1]

    def _recover(self, t_ns: int, pose: Pose, cm: Costmap) -> TickOutput:
        """Rotate or back off until the recovery's time is up (clear is one tick: the node
        empties the short-lived layer when it sees `recovery == "clear"`); then replan."""
        rec = self.recovery
        if t_ns >= self.recovery_until:
            self.recovery = ""
            self.cmd = np.zeros(3)
            self.last_plan_ns = -(10**18)
            self.take_next = True  # the next plan replaces the held one, whatever it costs
            self.progress_ns = t_ns
            self.best_remaining = math.inf
            self.best_yaw_error = math.inf
            return self._out()
        guard = BodyGuard(cm.solid, cm.grid, self.fp, pose)
        # The people rules hold a recovery as they hold a path: a turn on the spot or a
        # step back within a bystander's protective separation is a stop.
        behind = (-math.cos(pose.yaw), -math.sin(pose.yaw))
        away = self._away(pose, cm) if rec == "step_away" else None
        if rec == "step_away" and away is None:  # clear of them (or they went): done
            self.recovery_until = t_ns
            return self._recover(t_ns, pose, cm)
        way = behind if rec == "backoff" else away
        limit = (
            self._slide_limit(pose, cm, self.slide_sign, self.slide_person)
            if rec == "slide"
            else people_limit(
                pose, way, cm.people, self.fp, self.n.people,
                self.top_mps, self.goal.handover_id if self.goal else "",
                self.limit_rule == "stop", turning=rec == "rotate",
            )
        )  # fmt: skip
        self.limit_rule = limit.rule
        if limit.rule == "stop":
            self.cmd = np.zeros(3)
        elif away is not None:  # along `away`, in the base frame
            c, s = math.cos(pose.yaw), math.sin(pose.yaw)
            speed = min(STEP_AWAY_SPEED, limit.speed)
            step = speed * np.array([c * away[0] + s * away[1], -s * away[0] + c * away[1], 0.0])
            free = guard.ok(step)
            self.cmd = step if free else np.zeros(3)
            self.guarded = "" if free else "stand"
        elif rec == "rotate":  # either way round, whichever the body has room for
            turns = (np.array([0.0, 0.0, w]) for w in (ROTATE_RATE, -ROTATE_RATE))
            self.cmd = next((c for c in turns if guard.ok(c)), np.zeros(3))
            self.guarded = "" if self.cmd.any() else "stand"
        elif rec == "backoff":
            back = Pose(pose.x + 0.3 * behind[0], pose.y + 0.3 * behind[1], pose.yaw)
            step = np.array([-min(BACKOFF_SPEED, limit.speed), 0.0, 0.0])
            free = cm.cost_at(back.x, back.y) >= 0 and guard.ok(step)
            self.cmd = step if free else np.zeros(3)
            self.guarded = "" if free else "stand"
        elif rec == "slide":
            step = np.array([self.slide_sign * min(SLIDE_SPEED, limit.speed), 0.0, 0.0])
            free = _slide_free(guard, self.slide_sign)
            self.cmd = step if free else np.zeros(3)
            self.guarded = "" if free else "stand"
        out = self._out(limit)
        return out._replace(recovery=rec)


def _slide_free(guard: BodyGuard, sign: float) -> bool:
    """Whether the body guard lets the footprint slide `SLIDE_LOOK_M` ahead (`sign` +1) or
    back (-1) (the costmap's lethal cost is no test here: it holds the stale person's own
    disc)."""
    return guard.ok(np.array([sign * SLIDE_LOOK_M / HORIZON_S, 0.0, 0.0]))


def standing(person: Person) -> bool:
    """Whether a person's estimate says they stand (a known velocity under
    `STANDING_MPS`)."""
    return person.velocity is not None and math.hypot(*person.velocity) < STANDING_MPS


def stand_clear_m(p: PeopleSettings) -> float:
    """How far (m) from the footprint a person standing must be for a stop for them to
    release: S_p at rest for them and the stop's resume margin."""
    sep = separation_params(p)
    return protective_distance(0.0, sep.speed_margin_mps, sep) + RESUME_MARGIN_M
