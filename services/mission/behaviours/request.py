"""The leaves about what was asked: wait for a request, pick the object, name the person.

- `WaitForRequest`: RUNNING until the node put an accepted request on the blackboard.
- `NoteKnown`: for a request by id, the map's entries of its class as the fetch begins
  (`KNOWN`: other objects of the class, for the search; one made since, or made after
  the map last saw the object, may be the object, moved: `targets.other_objects`).
  Before anything else: a fetch that first puts back what it holds
  walks past tables, and the entry its head camera makes of the moved object on the way
  is not one the map had (hall seed 0's shift: bottle_2 moved onto table_2 at 305 s, the
  request came at 306 s, the walk to put box_1 back made bottle_5 of it at 308 s, and
  the search that began at 390 s took bottle_5 for another bottle and fetched bottle_1).
- `SelectTarget`: the object's candidates from the map on first use (a map id: itself; a
  class: every mapped instance, nearest first, at most `max_candidates`), then the one at
  the blackboard's `candidate` index becomes the `target`. The `next_instance` recovery
  moves the index on; past the last one the object was not found.
- `ResolvePerson`: the person's map id, checked against the map now (the request was
  checked when it came; the map may have changed since); their colours noted if the
  fetch's start had none (`identity.note_look`).
"""

from __future__ import annotations

from py_trees.common import Status

from common.messages.mission import MissionRequest
from services.mission import targets
from services.mission.behaviours.base import (
    CANDIDATE,
    CANDIDATES,
    FACING,
    KNOWN,
    PERSON,
    PERSON_LOOK,
    REQUEST,
    TARGET,
    Context,
    Held,
    MissionBehaviour,
    Target,
)
from services.mission.behaviours.identity import note_look
from services.mission.ports import Unavailable


class WaitForRequest(MissionBehaviour):
    def __init__(self, ctx: Context) -> None:
        super().__init__("wait_for_request", ctx, stage="")

    def update(self) -> Status:
        if isinstance(self.get(REQUEST), MissionRequest):
            return Status.SUCCESS
        self.feedback_message = "waiting for a request"
        return Status.RUNNING


class IsTask(MissionBehaviour):
    """SUCCESS when the request is of `task` (`fetch`, `put_back`); FAILURE otherwise (a
    condition: the tree's branch for the other task runs)."""

    def __init__(self, ctx: Context, task: str) -> None:
        super().__init__(f"is_{task}", ctx, stage="")
        self.task = task

    def update(self) -> Status:
        request = self.get(REQUEST)
        return Status.SUCCESS if request.task == self.task else Status.FAILURE


class NoteKnown(MissionBehaviour):
    """Always SUCCESS: `KNOWN` noted for a request by id (`targets.other_objects`; the map
    down: `SelectTarget` notes it later)."""

    WRITES = (KNOWN,)

    def __init__(self, ctx: Context) -> None:
        super().__init__("note_known", ctx, stage="")

    def update(self) -> Status:
        request: MissionRequest = self.get(REQUEST)
        if targets.is_map_id(request.object):
            try:
                like = self.port.artifacts_of_class(targets.class_of(request.object))
            except Unavailable:
                return Status.SUCCESS
            self.set(KNOWN, targets.other_objects(like, request.object))
        return Status.SUCCESS


class SelectTarget(MissionBehaviour):
    WRITES = (CANDIDATES, TARGET, KNOWN)

    def __init__(self, ctx: Context) -> None:
        super().__init__("select_target", ctx, stage="navigate_to_object")

    def update(self) -> Status:
        request: MissionRequest = self.get(REQUEST)
        candidates: list[str] | None = self.get(CANDIDATES)
        if candidates is None:
            try:
                found = targets.object_candidates(self.port, request.object)
            except Unavailable as exc:
                return self.fail("unavailable", f"the semantic map did not answer: {exc}")
            handed = self.ctx.handed
            if back := targets.handed_put_back(self.port, found, handed):
                for e in back:
                    person, at = handed.pop(e.id)
                    x, y = e.position_in_world[:2]
                    self.ctx.decide(
                        f"{e.id}, handed over to {person} at t={at / 1e9:.1f} s, was put down "
                        f"at ({x:.2f}, {y:.2f}): a candidate again"
                    )
            gone = [e.id for e in found if e.id in handed]
            found = [e for e in found if e.id not in handed]
            if not found and gone:
                person, at = handed[gone[0]]
                return self.fail("unknown_object", f"{gone[0]} was handed over to {person} at "
                                 f"t={at / 1e9:.1f} s")  # fmt: skip
            if not found:
                return self.fail("unknown_object", f"no mapped artifact is {request.object!r}")
            if gone:
                self.ctx.decide(f"object {request.object!r}: {', '.join(gone)} handed over "
                                "already, not a candidate")  # fmt: skip
            candidates = [e.id for e in found[: max(1, self.settings.max_candidates)]]
            self.set(CANDIDATES, candidates)
            if targets.is_map_id(request.object) and self.get(KNOWN) is None:
                # What the map had of the class (`NoteKnown`, when the map did not answer
                # it): an entry made since may be the object, moved (the search's
                # `found`; a request by class takes any).
                try:
                    like = self.port.artifacts_of_class(targets.class_of(request.object))
                except Unavailable:
                    like = list(found)
                self.set(KNOWN, targets.other_objects(like, request.object))
            self.ctx.decide(f"object {request.object!r}: candidates {candidates}")
        index = int(self.get(CANDIDATE, 0))
        if index >= len(candidates):
            return self.fail(
                "object_not_found", f"none of {candidates} was found where the map has it"
            )
        map_id = candidates[index]
        previous = self.get(TARGET)
        if isinstance(previous, Target) and previous.map_id == map_id:
            target = previous  # a re-pick: the place as it was, or where it fell
        else:
            try:
                entity = self.port.artifact(map_id)
            except Unavailable as exc:
                return self.fail("unavailable", f"the semantic map did not answer: {exc}")
            xy = None
            if entity is not None:
                xy = (entity.position_in_world[0], entity.position_in_world[1])
            target = Target(map_id, targets.class_of(map_id), xy)
        self.set(TARGET, target)
        if not isinstance(previous, Target) or previous.map_id != map_id:
            self.ctx.decide(f"target {map_id} ({index + 1} of {len(candidates)})")
        self.feedback_message = f"target {map_id}"
        return Status.SUCCESS


def held_from_before(leaf: MissionBehaviour) -> Held | None:
    """The object the gripper still holds from a request that ended unfinished
    (`Context.holding`), None when none; forgotten once the controller says the gripper
    holds nothing (somebody took it meanwhile)."""
    wbc = leaf.port.wbc_status()
    if leaf.ctx.holding is not None and wbc is not None and not wbc.held:
        leaf.ctx.holding = None
    return leaf.ctx.holding


class StillHolding(MissionBehaviour):
    """SUCCESS when the robot still holds, from a request that ended unfinished
    (`Context.holding`), the object this request asks for (that id, or one of that
    class): the fetch is skipped and the bring goes on with it. FAILURE otherwise."""

    WRITES = (TARGET, CANDIDATES)

    def __init__(self, ctx: Context) -> None:
        super().__init__("still_holding", ctx, stage="navigate_to_object")

    def update(self) -> Status:
        held = held_from_before(self)
        if held is None:
            return Status.FAILURE
        request: MissionRequest = self.get(REQUEST)
        name, map_id = request.object, held.map_id
        if name != map_id and (targets.is_map_id(name) or targets.class_of(map_id) != name):
            return Status.FAILURE
        self.set(TARGET, Target(map_id, targets.class_of(map_id), None))
        self.set(CANDIDATES, [map_id])
        self.ctx.decide(
            f"still holding {map_id} from request {held.request_id}: bringing it, no fetch"
        )
        return Status.SUCCESS


class HandsFree(MissionBehaviour):
    """SUCCESS when the gripper holds nothing from an earlier request; FAILURE (a
    condition, no mission failure) when it still holds one this request does not ask for
    (`StillHolding` did not take it): the tree puts that one back first."""

    def __init__(self, ctx: Context, name: str = "hands_free") -> None:
        super().__init__(name, ctx, stage="navigate_to_object")

    def update(self) -> Status:
        return Status.SUCCESS if held_from_before(self) is None else Status.FAILURE


class ResolvePerson(MissionBehaviour):
    WRITES = (PERSON, FACING, PERSON_LOOK)

    def __init__(self, ctx: Context) -> None:
        super().__init__("resolve_person", ctx, stage="bring_to_user")

    def update(self) -> Status:
        request: MissionRequest = self.get(REQUEST)
        try:
            person = targets.person_named(self.port, request.person)
        except Unavailable as exc:
            return self.fail("unavailable", f"the semantic map did not answer: {exc}")
        if person is None:
            return self.fail("unknown_person", f"no mapped person is {request.person!r}")
        self.set(PERSON, person.id)
        note_look(self, person)
        if person.id != request.person and targets.is_map_id(request.person):
            self.ctx.decide(f"{request.person} is {person.id} now: the map found them one person")
        # 0.0 is also the yaw of an entity without one (`navigation.sources._person`)
        self.set(FACING, person.yaw != 0.0)
        self.feedback_message = f"person {person.id}"
        return Status.SUCCESS
