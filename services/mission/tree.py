"""The bring-me behaviour tree (the paper's, with abort and recovery) and its lifecycle.

    bring_me (sequence)
      wait_for_request
      mission_or_abort (selector)
        the_task (selector): fetch_task (below), else put_back_task: is_put_back, then
                             nothing_held, else put_back_asked (`put_back_tree`)
        fetch_task (sequence): is_fetch, note_look (the requested person's colours),
          note_known (the map's entries of the class asked for by id), then
          regrasp (Recover: grasp_lost | grasp_failed, budget repick_budget)
            fetch_and_carry (sequence)
              have_it: still_holding (the object asked for, held since an unfinished
                       request: no fetch), else find_and_pick: hands_free, else put_back
                       (the object held since an unfinished request, not asked for: put
                       back where it was picked, `behaviours.put_back`; fallen from the
                       gripper on the way: where it lies said, and on), then:
              next_instance (Recover: object_not_found | navigation_failed |
                             blocked_by_person,
                             budget max_candidates - 1, while candidates remain; then,
                             once, object_not_found: a search, when search_places; what
                             it found missed, the search goes on, up to twice)
                find_object (sequence)
                  navigate_to_object: look_elsewhere (only when a search is asked: the
                                      places the object may be now, walked with the
                                      arm up until the map sees it: the only candidate),
                                      select_target, mode walk/navigation, ArtifactStandoff
                  restance (Recover: grasp_pose_failed, budget 1, when a stance was
                            asked for: a box too tall for a top grasp, its long faces
                            off the line of sight)
                    at_the_object (sequence)
                      stance: no_stance_asked, else Posture(stow), mode walk/navigation,
                              ArtifactStandoff at an end of the line along its long faces
                      approach_object: mode walk/mission, Posture(look), approach (eq. 3)
                      pose_estimation: mode manipulate, estimate_grasp
              pick_object: Release (open), Posture(ready), then grasp_it: Reach(plan)
                           (stopped more than reach_miss_max_m short: grasp_pose_failed),
                           Grasp, check_held, seated_or_again (a cylinder held
                           shallower than planned, by the jaw's angle: open, Reach deeper,
                           close in, Grasp, held_again), lift (Reach up lift_m; short is
                           enough), still_held; any of these failing, back_out: open on the spot,
                           Reach back to the pre-grasp pose, Posture(stow), fail with its
                           reason; then room_to_stow: stows_here, else (the stowed
                           object would meet its support's edge, `stow_room`) pull_back
                           (Reach, level), mode walk/mission, back_off_to_stow, mode
                           manipulate; then Posture(stow), mode walk/navigation
              bring_to_user (while_held: fails grasp_lost the tick the gripper lets go,
                             whatever runs): resolve_person, PersonHandover
                             (navigation_failed: walked_short, find_person takes over),
                             find_person (Recover: person_not_found | navigation_failed
                                          | wrong_person while another wears their
                                          colours, budget person_rounds - 1)
                               at_the_person: person_ahead, else: when unseen, look round
                                 and ask (then the next of their usual places, or their
                                 last), PersonHandover (or a walk to that place) once
                                 more, stands_there (seen, not walking: present)
                               right_person: wears the colours noted at the start
                                 (note_look, `identity`), else wrong_person
              (a grasp lost: the object fell where the gripper was (`dropped_at`): no
              walk to its map place, the nearest of its class looked for and picked;
              not seen there, or out of the arm's reach (the floor): `object_dropped`)
          other_side (Recover: handover_timeout, budget handover_sides - 1, while the
                      person's facing is unknown: the next side round them)
            hand_over (sequence)
              at_a_side: first_side, else go_round: Posture(stow), mode walk/navigation,
                         PersonHandover at the side
              release_object: mode stand, Posture(handover), feel_pull (its first
                              handover_lean_after_s; nobody pulling: mode walk/mission,
                              lean_in, mode stand, feel_pull_again), Release,
                              mode walk/mission, back_off, mode stand, Posture(stow)
        abort: halt everything, FAILURE with the blackboard's reason

Every sequence has memory (a running child resumes). `MissionTree` runs it: `start`
puts an accepted request on the blackboard, `tick` ticks once and returns the outcome
when the root finished, `cancel` stops every running leaf (each `terminate` cancels
what it started) and halts like abort. After an outcome the blackboard is cleared and
the root waits for the next request. Pure: the robot is the context's port.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import py_trees
from py_trees.common import Status
from py_trees.composites import Selector, Sequence

from common.messages.base import NS_PER_S
from common.messages.mission import STAGES, MissionReason, MissionRequest
from common.messages.wbc import Grasp, Posture, Release
from services.mission.behaviours.abort import Abort, halt
from services.mission.behaviours.arm import (
    ArmAction,
    CheckHeld,
    GraspReach,
    NoCloseIn,
    Seated,
    StowsHere,
)
from services.mission.behaviours.base import (
    CANDIDATE,
    CANDIDATES,
    DETECTION,
    FAILURE,
    GRASP_PLAN,
    PERSON,
    REQUEST,
    SEARCH,
    SEARCH_LEFT,
    SEARCHED,
    SIDE,
    STANCE,
    STOW_BACK,
    TARGET,
    Context,
    Failure,
    Held,
    MissionBehaviour,
    Target,
    blackboard,
    read,
    reset_blackboard,
)
from services.mission.behaviours.handover import (
    FeelPull,
    FirstSide,
    LeanIn,
    NotTakenYet,
    next_side,
)
from services.mission.behaviours.identity import NoteLook, RightPerson, another_to_try
from services.mission.behaviours.motion import (
    BackOff,
    LookForPerson,
    NavigateTo,
    PersonAhead,
    SeenThere,
    SetMode,
    StandsThere,
    WalkedShort,
)
from services.mission.behaviours.perceive import Approach, EstimateGrasp, NoStance
from services.mission.behaviours.put_back import (
    OVER_THE_SPOT_M,
    FellOnTheWay,
    PutBackFirst,
    PutDown,
    held_reach,
)
from services.mission.behaviours.request import (
    HandsFree,
    IsTask,
    NoteKnown,
    ResolvePerson,
    SelectTarget,
    StillHolding,
    WaitForRequest,
)
from services.mission.behaviours.search import MAX_RESUMES, LookElsewhere
from services.mission.carrying import WhileHeld
from services.mission.recovery import Recover
from services.mission.targets import dropped_at

REPICK_REASONS = frozenset({"grasp_lost", "grasp_failed"})
NEXT_INSTANCE_REASONS = frozenset({"object_not_found", "navigation_failed", "blocked_by_person"})
#: One more round of looking for the person and walking to them (they walk on, were not
#: seen, or their place could not be walked to).
FIND_PERSON_REASONS = frozenset({"person_not_found", "navigation_failed", "wrong_person"})


def _seq(name: str, *children: py_trees.behaviour.Behaviour) -> Sequence:
    return Sequence(name, memory=True, children=list(children))


def put_back_tree(ctx: Context, name: str, goes_on: bool) -> Selector:
    """Put what the gripper still holds from an unfinished request back where it was
    picked (`behaviours.put_back`): walk to the grasp's stance, carry it in over its
    place, set it down, let go, leave, stow; the object fallen on the way, say where it
    lies (`goes_on`: and go on with the request)."""
    s, st = ctx.settings, STAGES
    steps = _seq(
        f"{name}_steps",
        PutBackFirst(ctx, st[0]),
        SetMode(ctx, "walk", "navigation", st[0], name="mode_walk_put_back"),
        WhileHeld(ctx, NavigateTo(ctx, "put_back", st[0])),
        SetMode(ctx, "manipulate", "navigation", st[0], name="mode_manipulate_put_back"),
        ArmAction(ctx, "ready_held", lambda _b: Posture(name="ready"), "arm_failed",
                  s.posture_timeout_s, st[0]),  # out of the stow as the grasp's reach began
        ArmAction(ctx, "over_the_spot", held_reach(lambda p: p.over_the_spot(s.lift_m)),
                  "arm_failed", s.reach_timeout_s, st[0], near_enough_m=OVER_THE_SPOT_M),
        # stopped short by the surface: it is down all the same
        ArmAction(ctx, "set_down", held_reach(lambda p: p.lifted(s.put_down_clear_m)),
                  "arm_failed", s.reach_timeout_s, st[0], must_succeed=False),
        ArmAction(ctx, "let_go_held", lambda _b: Release(), "arm_failed",
                  s.release_timeout_s, st[0]),
        ArmAction(ctx, "leave_it", held_reach(lambda p: p.backed_out()), "arm_failed",
                  s.reach_timeout_s, st[0], must_succeed=False),  # stuck short: stow anyway
        ArmAction(ctx, "stow_put_back", lambda _b: Posture(name="stow"), "arm_failed",
                  s.posture_timeout_s, st[0]),
        PutDown(ctx, st[0]),
        SetMode(ctx, "walk", "navigation", st[0], name="mode_walk_put_down"),
    )  # fmt: skip
    return Selector(name, memory=True, children=[steps, FellOnTheWay(ctx, st[0], goes_on)])


def build_tree(ctx: Context) -> Sequence:
    """The tree of the module docstring, its leaves bound to `ctx`."""
    s = ctx.settings
    bb = blackboard(
        "recovery",
        (CANDIDATE, GRASP_PLAN, DETECTION, TARGET, SEARCH, SEARCHED, SEARCH_LEFT, STANCE),
    )

    def next_candidate(failure: Failure) -> bool:
        bb.set(STANCE, None)  # a stance is one object's
        candidates = read(bb, CANDIDATES) or []
        index = int(read(bb, CANDIDATE, 0)) + 1
        if index < len(candidates):
            bb.set(CANDIDATE, index)
            return True
        # Every candidate missed at its place: look elsewhere, once per request; what
        # the search found missed too, the search goes on where it stopped (at most
        # `MAX_RESUMES` times: `behaviours.search`).
        if failure.reason != "object_not_found" or not s.search_places:
            return False
        if read(bb, SEARCHED) and read(bb, SEARCH_LEFT) is None:
            return False
        bb.set(SEARCH, True)
        bb.set(SEARCHED, True)
        return True

    def forget_grasp(failure: Failure) -> bool:
        bb.set(GRASP_PLAN, None)
        bb.set(DETECTION, None)
        bb.set(STANCE, None)
        target = read(bb, TARGET)
        if failure.reason == "grasp_lost" and isinstance(target, Target):
            # It fell from the gripper: look where the gripper was, not at its old place.
            at = dropped_at(ctx.port.robot_xy(), ctx.port.robot_yaw())
            bb.set(TARGET, replace(target, xy=at, dropped=True))
            ctx.decide(f"{target.map_id} fell {replace(target, xy=at).where_dropped()}")
        return True

    st = STAGES
    navigate = _seq(
        st[0],
        LookElsewhere(ctx, st[0]),
        SelectTarget(ctx),
        SetMode(ctx, "walk", "navigation", st[0]),
        NavigateTo(ctx, "artifact", st[0]),
    )
    approach = _seq(
        st[1],
        SetMode(ctx, "walk", "mission", st[1]),
        ArmAction(ctx, "look", lambda _b: Posture(name="look"), "arm_failed",
                  s.posture_timeout_s, st[1]),
        Approach(ctx, st[1]),
    )  # fmt: skip
    pose = _seq(st[2], SetMode(ctx, "manipulate", "navigation", st[2]), EstimateGrasp(ctx, st[2]))
    pick = _seq(
        st[3],
        ArmAction(ctx, "open_jaw", lambda _b: Release(), "arm_failed", s.release_timeout_s, st[3]),
        ArmAction(ctx, "ready", lambda _b: Posture(name="ready"), "arm_failed",
                  s.posture_timeout_s, st[3]),
        Selector(
            "picked_or_back_out",
            memory=True,
            children=[
                _seq(
                    "grasp_it",
                    GraspReach(ctx, lambda b: b.get(GRASP_PLAN).reach(), st[3]),
                    # a box or a wide cylinder comes in with room, then brings the fixed
                    # jaw to it (stopped short by it: close anyway)
                    Selector("closed_in", memory=True, children=[
                        NoCloseIn(ctx, st[3]),
                        ArmAction(ctx, "close_in", lambda b: b.get(GRASP_PLAN).closed_in().reach(),
                                  "grasp_failed", s.reach_timeout_s, st[3], must_succeed=False),
                    ]),
                    ArmAction(ctx, "grasp", lambda _b: Grasp(), "grasp_failed",
                              s.grasp_timeout_s, st[3]),
                    CheckHeld(ctx, st[3]),
                    # a cylinder held near the jaws' tips creeps out on the carry: the
                    # jaw's angle says where it sits; too shallow, it is taken again deeper
                    Selector("seated_or_again", memory=True, children=[
                        Seated(ctx, st[3]),
                        _seq(
                            "reseat",
                            ArmAction(ctx, "open_to_reseat", lambda _b: Release(),
                                      "grasp_failed", s.release_timeout_s, st[3]),
                            ArmAction(ctx, "reseat", lambda b: b.get(GRASP_PLAN).reach(),
                                      "grasp_failed", s.reach_timeout_s, st[3],
                                      must_succeed=False),
                            ArmAction(ctx, "reseat_close_in",
                                      lambda b: b.get(GRASP_PLAN).closed_in().reach(),
                                      "grasp_failed", s.reach_timeout_s, st[3],
                                      must_succeed=False),
                            ArmAction(ctx, "regrasp", lambda _b: Grasp(), "grasp_failed",
                                      s.grasp_timeout_s, st[3]),
                            CheckHeld(ctx, st[3], name="held_again", take=False),
                            Seated(ctx, st[3], again=True),
                        ),
                    ]),
                    # a lift short of its goal with the object still held is lift enough
                    # (hall seed 16: a box held, lifted 5.8 cm short; letting go drops it)
                    ArmAction(ctx, "lift", lambda b: b.get(GRASP_PLAN).lifted(s.lift_m).reach(),
                              "grasp_failed", s.reach_timeout_s, st[3], must_succeed=False),
                    CheckHeld(ctx, st[3], name="still_held", take=False),
                ),
                _seq(
                    # open on the spot (the object stays for a re-pick), leave along the
                    # approach and stow before the base moves: an arm left out over the
                    # table sweeps it when the robot walks (hall seed 11)
                    "back_out",
                    ArmAction(ctx, "let_go", lambda _b: Release(), "arm_failed",
                              s.release_timeout_s, st[3]),
                    ArmAction(ctx, "leave", lambda b: b.get(GRASP_PLAN).backed_out().reach(),
                              "grasp_failed", s.reach_timeout_s, st[3],
                              must_succeed=False),  # stuck short of it: stow anyway
                    ArmAction(ctx, "stow_empty", lambda _b: Posture(name="stow"), "arm_failed",
                              s.posture_timeout_s, st[3]),
                    py_trees.behaviours.Failure(name="not_picked"),
                ),
            ],
        ),
        # an object that would meet its support's edge folded to stow where the base
        # stands is drawn back over the floor while the base backs off (`stow_room`)
        Selector("room_to_stow", memory=True, children=[
            StowsHere(ctx, st[3]),
            _seq(
                "make_room",
                ArmAction(ctx, "pull_back", lambda b: b.get(GRASP_PLAN).pulled_back(
                              s.lift_m, b.get(STOW_BACK), b.port.robot_yaw() or 0.0).reach(),
                          "grasp_failed", s.reach_timeout_s, st[3], must_succeed=False),
                SetMode(ctx, "walk", "mission", st[3], name="mode_walk_make_room"),
                BackOff(ctx, st[3], name="back_off_to_stow", distance=lambda b: b.get(STOW_BACK)),
                SetMode(ctx, "manipulate", "navigation", st[3], name="mode_manipulate_stow"),
            ),
        ]),
        ArmAction(ctx, "stow", lambda _b: Posture(name="stow"), "arm_failed",
                  s.posture_timeout_s, st[3]),
        SetMode(ctx, "walk", "navigation", st[3]),
    )  # fmt: skip
    bring = WhileHeld(ctx, _seq(
        st[4],
        ResolvePerson(ctx),
        SetMode(ctx, "walk", "navigation", st[4]),
        Selector("walk_to_them", memory=True, children=[
            NavigateTo(ctx, "person", st[4]),
            WalkedShort(ctx, st[4]),
        ]),
        Recover(
            "find_person",
            _seq(
                "at_the_right_person",
                Selector(
                    "at_the_person",
                    memory=True,
                    children=[
                        PersonAhead(ctx, st[4]),
                        _seq(
                            "to_them_again",
                            Selector("look_if_unseen", memory=True, children=[
                                SeenThere(ctx, st[4]),
                                LookForPerson(ctx, st[4]),
                            ]),
                            NavigateTo(ctx, "person", st[4], name="navigate_again"),
                            StandsThere(ctx, st[4]),
                        ),
                    ],
                ),
                RightPerson(ctx, st[4]),
            ),
            FIND_PERSON_REASONS,
            max(0, s.person_rounds - 1),
            ctx.decide,
            another_to_try(blackboard("find_person")),
        ),
    ))  # fmt: skip
    release = _seq(
        st[5],
        SetMode(ctx, "stand", "navigation", st[5]),
        ArmAction(ctx, "present", lambda _b: Posture(name="handover"), "arm_failed",
                  s.posture_timeout_s, st[5]),
        Selector("feel_or_lean", memory=True, children=[
            FeelPull(ctx, st[5], "before_lean"),
            _seq(
                "lean_in_and_feel",
                NotTakenYet(ctx, st[5]),
                SetMode(ctx, "walk", "mission", st[5], name="mode_walk_lean"),
                LeanIn(ctx, st[5]),
                SetMode(ctx, "stand", "navigation", st[5], name="mode_stand_lean"),
                FeelPull(ctx, st[5], "after_lean"),
            ),
        ]),
        ArmAction(ctx, "release", lambda _b: Release(), "arm_failed", s.release_timeout_s, st[5]),
        SetMode(ctx, "walk", "mission", st[5]),
        BackOff(ctx, st[5]),
        SetMode(ctx, "stand", "navigation", st[5], name="mode_stand_at_rest"),
        ArmAction(ctx, "stow_empty", lambda _b: Posture(name="stow"), "arm_failed",
                  s.posture_timeout_s, st[5]),
    )  # fmt: skip

    def to_stance(failure: Failure) -> bool:
        return read(bb, STANCE) is not None

    # A grasp that needs another stance (`STANCE`): stow, walk to it, approach again.
    at_the_object = Recover(
        "restance",
        _seq(
            "at_the_object",
            Selector("stance", memory=True, children=[
                NoStance(ctx, st[1]),
                _seq(
                    "to_a_stance",
                    ArmAction(ctx, "stow_for_stance", lambda _b: Posture(name="stow"),
                              "arm_failed", s.posture_timeout_s, st[0]),
                    SetMode(ctx, "walk", "navigation", st[0], name="mode_walk_stance"),
                    NavigateTo(ctx, "artifact", st[0], name="navigate_to_stance",
                               fails_as=("grasp_pose_failed",
                                         "no stance along its long faces: ")),
                ),
            ]),
            approach,
            pose,
        ),
        frozenset({"grasp_pose_failed"}),
        1,
        ctx.decide,
        to_stance,
    )  # fmt: skip
    find = Recover(
        "next_instance",
        _seq("find_object", navigate, at_the_object),
        NEXT_INSTANCE_REASONS,
        max(0, s.max_candidates - 1) + (1 + MAX_RESUMES if s.search_places else 0),
        ctx.decide,
        next_candidate,
    )
    fetch = Recover(
        "regrasp",
        _seq(
            "fetch_and_carry",
            Selector(
                "have_it",
                memory=True,
                children=[
                    StillHolding(ctx),
                    _seq(
                        "find_and_pick",
                        Selector(
                            "hands_free_or_put_back",
                            memory=True,
                            children=[HandsFree(ctx), put_back_tree(ctx, "put_back", True)],
                        ),
                        find,
                        pick,
                    ),
                ],
            ),
            bring,
        ),
        REPICK_REASONS,
        s.repick_budget,
        ctx.decide,
        forget_grasp,
    )
    go_round = WhileHeld(ctx, _seq(
        "go_round",
        ArmAction(ctx, "carry", lambda _b: Posture(name="stow"), "arm_failed",
                  s.posture_timeout_s, st[5]),
        SetMode(ctx, "walk", "navigation", st[5], name="mode_walk_round"),
        NavigateTo(ctx, "person", st[5], name="navigate_round"),
    ))  # fmt: skip
    offer = Recover(
        "other_side",
        _seq("hand_over", Selector("at_a_side", memory=True,
                                   children=[FirstSide(ctx, st[5]), go_round]), release),
        frozenset({"handover_timeout"}),
        max(0, s.handover_sides - 1),
        ctx.decide,
        next_side(ctx, blackboard("other_side", (SIDE,))),
    )  # fmt: skip
    mission = Selector(
        "the_task",
        memory=True,
        children=[
            _seq("fetch_task", IsTask(ctx, "fetch"), NoteLook(ctx), NoteKnown(ctx), fetch, offer),
            _seq(
                "put_back_task",
                IsTask(ctx, "put_back"),
                Selector(
                    "nothing_held_or_put_back",
                    memory=True,
                    children=[
                        HandsFree(ctx, "nothing_held"),
                        put_back_tree(ctx, "put_back_asked", False),
                    ],
                ),
            ),
        ],
    )
    return _seq(
        "bring_me",
        WaitForRequest(ctx),
        Selector("mission_or_abort", memory=True, children=[mission, Abort(ctx)]),
    )


@dataclass(frozen=True)
class Outcome:
    """How a mission ended: its state, the typed reason and a sentence."""

    state: Literal["succeeded", "failed", "cancelled"]
    reason: MissionReason = ""
    detail: str = ""


class MissionTree:
    """The tree and one mission's lifecycle (see the module docstring)."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        reset_blackboard()
        self.root = build_tree(ctx)
        #: The search leaves, found once (the node asks `arm_look` at every tick).
        self._searches = [b for b in self.root.iterate() if isinstance(b, LookElsewhere)]
        self.bb = blackboard("mission_tree", (REQUEST,))
        self.request: MissionRequest | None = None

    @property
    def busy(self) -> bool:
        return self.request is not None

    @property
    def arm_look(self) -> bool:
        """A search holds the arm up to look (the map fuses the wrist camera meanwhile)."""
        return any(b.arm_look for b in self._searches)

    def start(self, request: MissionRequest) -> None:
        if self.request is not None:
            raise RuntimeError(f"mission {self.request.request_id} is still running")
        reset_blackboard()
        self.request = request
        self.bb.set(REQUEST, request)
        self.ctx.put_back = ""
        said = (
            "put back what it holds"
            if request.task == "put_back"
            else (f"bring {request.object} to {request.person}")
        )
        self.ctx.decide(f"mission {request.request_id}: {said}")

    def tick(self) -> Outcome | None:
        """Tick once; the outcome when the mission ended this tick."""
        self.root.tick_once()
        if self.request is None or self.root.status == Status.RUNNING:
            return None
        if self.root.status == Status.SUCCESS and self.request.task == "put_back":
            outcome = Outcome("succeeded", "", self.ctx.put_back or "nothing held to put back")
        elif self.root.status == Status.SUCCESS:
            outcome = Outcome("succeeded", "", f"{self.request.object} handed over")
            target, person = read(self.bb, TARGET), read(self.bb, PERSON)
            if isinstance(target, Target):
                self.ctx.handed[target.map_id] = (str(person), self.ctx.port.now_ns)
            self.ctx.holding = None
        else:
            failure = read(self.bb, FAILURE)
            if isinstance(failure, Failure):
                outcome = Outcome("failed", failure.reason, failure.detail)
            else:
                outcome = Outcome("failed", "internal", "the tree failed without a reason")
            outcome = self._with_holding(outcome)
        self._clear()
        return outcome

    def _with_holding(self, outcome: Outcome) -> Outcome:
        """An unfinished request whose object is in the gripper says so (the controller's
        last status): a person must know where the object is, and a controller that
        died holding it may drop it after the status went out."""
        status = self.ctx.port.wbc_status()
        if status is None or not status.held:
            return outcome
        target = read(self.bb, TARGET)
        plan, stance, before = read(self.bb, GRASP_PLAN), self.ctx.picked_from, self.ctx.holding
        if isinstance(target, Target) and self.request is not None:
            rid = self.request.request_id
            if plan is not None or before is None:  # picked by this request
                self.ctx.holding = Held(target.map_id, rid, plan, stance)
            elif before.map_id == target.map_id:  # brought on, not picked again
                self.ctx.holding = Held(target.map_id, rid, before.plan, before.stance)
            # else what an earlier request left, whose put-back failed, is still held (seed
            # 0's shift said "holding bottle_2", the request's object, for box_1)
        held = self.ctx.holding
        what = (
            held.map_id if held is not None
            else target.map_id if isinstance(target, Target)
            else self.request.object if self.request is not None else "the object"
        )  # fmt: skip
        said = (
            f"the robot was holding {what} "
            f"(the controller's status at t={status.stamp_ns / NS_PER_S:.2f} s)"
        )
        return Outcome(outcome.state, outcome.reason, f"{outcome.detail}; {said}")

    def cancel(self, reason: str) -> Outcome | None:
        """Stop every running leaf and halt; None when no mission runs."""
        return self._end(Outcome("cancelled", "cancelled", reason or "cancelled by the user"))

    def fail(self, reason: MissionReason, detail: str) -> Outcome | None:
        """Stop every running leaf and halt, failed for `reason`; None when idle."""
        return self._end(Outcome("failed", reason, detail))

    def _end(self, outcome: Outcome) -> Outcome | None:
        if self.request is None:
            return None
        outcome = self._with_holding(outcome)
        self.root.stop(Status.INVALID)
        said = (
            outcome.detail
            if outcome.state == "cancelled"
            else f"{outcome.reason}: {outcome.detail}"
        )
        halt(self.ctx.port, f"{outcome.state}: {said}")
        self.ctx.decide(f"mission {self.request.request_id} {outcome.state}: {said}")
        self._clear()
        return outcome

    def _clear(self) -> None:
        self.request = None
        reset_blackboard()

    def where(self) -> tuple[str, str, float]:
        """(stage, running leaf, progress in [0, 1]) of the mission now."""
        tip = self.root.tip()
        if self.request is None or not isinstance(tip, MissionBehaviour) or not tip.stage:
            return "", "" if tip is None else tip.name, 0.0
        index = STAGES.index(tip.stage)
        return tip.stage, tip.say or tip.name, min(1.0, (index + tip.fraction) / len(STAGES))

    def text(self) -> str:
        """The tree with every node's status, as text (for the log and rerun)."""
        return py_trees.display.unicode_tree(self.root, show_status=True)

    def statuses(self) -> tuple[tuple[str, str], ...]:
        """Every node's (name, status): what changes when the tree's state changes."""
        return tuple((b.name, b.status.value) for b in self.root.iterate())
