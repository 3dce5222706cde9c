"""Putting back an object the gripper still holds from a request that ended unfinished.

A request that ends unfinished with its object in the gripper (nobody took it, it was
cancelled while carrying) leaves it there (`Context.holding`): a request for that object
brings it on without a fetch. A request for anything else needs the gripper, so the
tree puts the held one back first, where it was picked; a request of task `put_back`
(`{"request_id", "task": "put_back"}`, `dume request --put-back`) does only that, and
succeeds saying so, or that nothing was held (`put_back_tree` in `tree`):

- `PutBackFirst`: says what goes back and where; fails `busy` when the robot does not
  know where it picked it (`Held.can_put_back`: no world-frame grasp plan or stance);
- `NavigateTo("put_back")`: walks to where the base stood for the grasp;
- mode manipulate; `ready_held`: Posture(ready), where the grasp's reach began (the jaw
  stays closed on the object); `over_the_spot`: the grasp's lift pose, via its pre-grasp
  pose (the object comes in `lift_m` above its place, as the gripper came for it; a
  reach that gives up within `OVER_THE_SPOT_M` of it is over the spot: seed 0's shift
  failed a put-back 3.2 cm from it, and the box stayed in the gripper for every request
  after);
  `set_down`: down to `put_down_clear_m` above its place (stopped short by the surface:
  it is down all the same); `let_go_held`: open; `leave_it`: back to the pre-grasp pose
  (stuck: stow anyway); `stow_put_back`: stow;
- `PutDown`: the gripper says empty: the holding is forgotten, and the map sees the
  object in its place again through the cameras;
- `FellOnTheWay`, when any of those failed: a failure `grasp_lost` (the object fell from
  the gripper on the walk back: minutes in the jaws, a box creeps out of them) is said
  with where it lies (`dropped_at`) and the holding forgotten; a fetch then goes on, its
  gripper free (the fetch's own regrasp budget is not spent on it), and a `put_back`
  request fails `object_dropped` saying where it lies. Any other failure stands.

The Reaches (`held_reach`) are stamped now, not at the grasp's capture: the place is a
pose in the map, which the robot port takes to the controller's odometry with the
localization's correction due now (`MissionRobot.send_arm_goal`); the correction of the
capture is minutes old by then.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import msgspec
from py_trees.common import Status

from common.messages.wbc import ArmGoal
from services.mission.behaviours.base import FAILURE, Context, Failure, Held, MissionBehaviour
from services.mission.targets import dropped_at

#: m: a reach to the pose above an object's place that gives up this near it is over it.
OVER_THE_SPOT_M = 0.05


def _held(leaf: MissionBehaviour) -> Held:
    held = leaf.ctx.holding
    if held is None or not held.can_put_back:
        raise RuntimeError(f"{leaf.name}: nothing held to put back (tree misbuilt)")
    return held


def held_reach(pose: Callable[[Any], Any]) -> Callable[[MissionBehaviour], ArmGoal]:
    """An `ArmAction` goal: the Reach of `pose(plan)` for the held object's grasp plan
    (`GraspPlan.over_the_spot`, `lifted`, `backed_out`), stamped now."""

    def goal(leaf: MissionBehaviour) -> ArmGoal:
        reach = pose(_held(leaf).plan).reach()
        return msgspec.structs.replace(reach, stamp_ns=leaf.port.now_ns)

    return goal


class PutBackFirst(MissionBehaviour):
    """SUCCESS, saying so, when the held object can be put back where it was picked;
    `busy` (what the gripper holds, and why it stays there) when it cannot."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("put_back_first", ctx, stage)

    def update(self) -> Status:
        held = self.ctx.holding
        if held is None:
            return Status.SUCCESS  # taken meanwhile: nothing to put back
        if not held.can_put_back:
            return self.fail(
                "busy",
                f"the robot still holds {held.map_id} from request {held.request_id} and "
                f"does not know where it picked it: ask for {held.map_id} to be brought first",
            )
        assert held.stance is not None
        x, y, _ = held.stance
        self.ctx.decide(
            f"putting {held.map_id} (held since request {held.request_id}) back where it "
            f"was picked, from ({x:.2f}, {y:.2f}), before this request"
        )
        self.feedback_message = f"putting {held.map_id} back"
        return Status.SUCCESS


class PutDown(MissionBehaviour):
    """SUCCESS once the controller says the gripper is empty: the held object is
    forgotten (`Context.holding`); FAILURE `arm_failed` when it still holds it."""

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("put_down", ctx, stage)

    def update(self) -> Status:
        held, status = self.ctx.holding, self.port.wbc_status()
        if held is None:
            return Status.SUCCESS
        if status is not None and status.held:
            return self.fail(
                "arm_failed", f"the gripper still holds {held.map_id} after letting go"
            )
        self.ctx.holding = None
        self.ctx.put_back = f"{held.map_id} put back where it was picked"
        self.ctx.decide(self.ctx.put_back)
        return Status.SUCCESS


class FellOnTheWay(MissionBehaviour):
    """After the put-back failed: the held object fell on the way (the module docstring).
    `goes_on`: SUCCESS then (a fetch goes on); else FAILURE `object_dropped`."""

    def __init__(self, ctx: Context, stage: str, goes_on: bool) -> None:
        super().__init__("fell_on_the_way", ctx, stage)
        self.goes_on = goes_on

    def update(self) -> Status:
        failure, held, status = self.get(FAILURE), self.ctx.holding, self.port.wbc_status()
        fell = isinstance(failure, Failure) and failure.reason == "grasp_lost"
        if not fell or held is None or status is None or status.held:
            return Status.FAILURE  # the failure as it was
        at = dropped_at(self.port.robot_xy(), self.port.robot_yaw())
        where = f"about ({at[0]:.2f}, {at[1]:.2f})" if at else "where the robot walked"
        said = (
            f"{held.map_id} (held since request {held.request_id}) fell from the gripper on "
            f"the way to be put back: it lies {where}"
        )
        self.ctx.holding = None
        if not self.goes_on:
            return self.fail("object_dropped", said)
        self.ctx.decide(said)
        self.set(FAILURE, None)  # dealt with: the fetch goes on with its gripper free
        return Status.SUCCESS
