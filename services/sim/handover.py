"""The handover: a person takes an artifact that is held out to them, and pulls.

Per person, a small state machine over the hand's three servos (`services.sim.scene`):
- idle: the hand rests at `HAND_IN_PERSON`. An artifact that no person holds, touches no
  world geom (so it is held up — by the robot's gripper, in practice), moves slower than
  `STILL_MPS` and whose centre is within `RADIUS_M` of the resting hand for `DWELL_S`
  is taken: the person reaches for it.
- reaching: the hand's target moves at `REACH_SPEED_MPS` to the artifact's near side;
  once the hand is within `GRASP_M` of it the person's grip weld closes on the object
  where it is (`scene.attach_to_grip`) and `HandoverTaken` is emitted. An object that
  moves `ABORT_M` away from the resting hand first is let be.
- holding: the hand's target draws back towards the person, to `RETRACT_TO_M` ahead of
  them, over `RETRACT_S`. The servo's force limit (15 N along the person's x) is the
  pull: a robot that still grips the object feels it in its jaw and arm; once the jaws
  open, the hand brings the object to the person. The person keeps it, until somebody
  moves it elsewhere (`let_go`: the world's artifact hook puts it back on a bench).
Nothing here moves the object or the robot directly: only the hand's servo targets.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from common.messages.sim import HandoverTaken
from common.messages.world import Cuboid, WorldDescription
from services.sim import scene
from services.sim.events import StepContacts

RADIUS_M = 0.25
STILL_MPS = 0.03
DWELL_S = 0.5
REACH_SPEED_MPS = 0.8
GRASP_M = 0.02
ABORT_M = 0.40
RETRACT_TO_M = 0.30  # clear of the torso (0.16 m) with the object in hand
RETRACT_S = 1.0

_HAND = np.array(scene.HAND_IN_PERSON)
_LOW = np.array([r[0] for r in scene.HAND_RANGE_M])
_HIGH = np.array([r[1] for r in scene.HAND_RANGE_M])


@dataclass
class _Hand:
    """One person's hand: model addresses and the handover state."""

    person: str
    body: int  # the person's (mocap) body
    grip: int  # the grip body
    actuators: NDArray[np.intp]  # the x, y, z servos
    phase: str = "idle"  # idle | reaching | holding
    target: int = -1  # artifact index while reaching or holding
    dwell: dict[int, float] = field(default_factory=dict)
    ctrl: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    hold_ctrl: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    hold_s: float = 0.0


def _settled(hand: _Hand) -> bool:
    """Nothing to do for this hand until an artifact is held out near it."""
    if hand.phase == "idle":
        return not hand.dwell
    return hand.phase == "holding" and hand.hold_s >= RETRACT_S


class Handover:
    """Every person's hand; `update` after each step, `held` marks taken artifacts."""

    def __init__(self, model: mujoco.MjModel, world: WorldDescription) -> None:
        self.artifact_ids = tuple(a.id for a in world.artifacts)
        self.bodies = np.array([model.body(a).id for a in self.artifact_ids], dtype=np.intp)
        self.dofs = np.array([model.joint(a).dofadr[0] for a in self.artifact_ids], dtype=np.intp)
        # How far the near side of each artifact is from its axis, m.
        self.radius = np.array(
            [
                min(a.shape.half_size[:2]) if isinstance(a.shape, Cuboid) else a.shape.radius
                for a in world.artifacts
            ]
        )
        self.hands = [
            _Hand(
                person=p.id,
                body=model.body(p.id).id,
                grip=model.body(f"{p.id}_grip").id,
                actuators=np.array(
                    [model.actuator(scene.hand_joint_name(p.id, ax)).id for ax in scene.HAND_AXES]
                ),
            )
            for p in world.people
        ]
        self.held = np.zeros(len(self.artifact_ids), dtype=bool)

    def rest_position(self, data: mujoco.MjData, person_id: str) -> NDArray[np.float64]:
        """Where `person_id`'s hand rests now, in the world (m)."""
        hand = self._hand(person_id)
        return self._rest(data, hand)

    def pull_force(self, data: mujoco.MjData, person_id: str) -> NDArray[np.float64]:
        """The force (N, world) `person_id`'s hand servos apply: the pull on what it holds."""
        hand = self._hand(person_id)
        R = data.xmat[hand.body].reshape(3, 3)
        return np.asarray(R @ data.actuator_force[hand.actuators], dtype=float)

    def holder(self, artifact_id: str) -> str | None:
        """The person holding `artifact_id`, if any."""
        k = self.artifact_ids.index(artifact_id)
        return next((h.person for h in self.hands if h.phase == "holding" and h.target == k), None)

    def update(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        contacts: StepContacts,
        dt: float,
        stamp_ns: int,
    ) -> list[HandoverTaken]:
        """Advance every hand by dt after a step; the handovers whose grip closed."""
        events: list[HandoverTaken] = []
        taken = contacts.artifact_on_world | contacts.artifact_asleep | self.held
        free = [] if taken.all() else np.flatnonzero(~taken).tolist()
        if not free and all(_settled(hand) for hand in self.hands):
            return events  # nothing held out, every hand at rest or done
        for hand in self.hands:
            if hand.phase == "idle":
                self._idle(data, hand, free, dt)
            elif hand.phase == "reaching":
                if self._reach(model, data, hand, dt):
                    events.append(
                        HandoverTaken(
                            stamp_ns=stamp_ns,
                            person_id=hand.person,
                            object_id=self.artifact_ids[hand.target],
                        )
                    )
            else:
                self._retract(data, hand, dt)
        return events

    # -- phases ---------------------------------------------------------------------------

    def _idle(self, data: mujoco.MjData, hand: _Hand, free: list[int], dt: float) -> None:
        if not free:
            hand.dwell.clear()
            return
        rest = self._rest(data, hand)
        dwell: dict[int, float] = {}
        for k in free:
            centre = data.xipos[self.bodies[k]]
            speed = float(np.linalg.norm(data.qvel[self.dofs[k] : self.dofs[k] + 3]))
            if speed < STILL_MPS and float(np.linalg.norm(centre - rest)) < RADIUS_M:
                dwell[k] = hand.dwell.get(k, 0.0) + dt
        hand.dwell = dwell
        ready = [k for k, s in dwell.items() if s >= DWELL_S - 1e-9]
        if ready:
            hand.phase, hand.target = "reaching", ready[0]
            hand.dwell.clear()

    def _reach(self, model: mujoco.MjModel, data: mujoco.MjData, hand: _Hand, dt: float) -> bool:
        rest = self._rest(data, hand)
        R = data.xmat[hand.body].reshape(3, 3)
        centre = data.xipos[self.bodies[hand.target]]
        if float(np.linalg.norm(centre - rest)) > ABORT_M or self.held[hand.target]:
            self._reset(data, hand)
            return False
        towards = rest - centre
        towards[2] = 0.0
        norm = float(np.linalg.norm(towards))
        grab = centre + (self.radius[hand.target] / norm) * towards if norm > 1e-6 else centre
        goal = np.clip(R.T @ (grab - rest), _LOW, _HIGH)
        step = goal - hand.ctrl
        length = float(np.linalg.norm(step))
        limit = REACH_SPEED_MPS * dt
        hand.ctrl += step if length <= limit else step * (limit / length)
        data.ctrl[hand.actuators] = hand.ctrl
        if float(np.linalg.norm(data.xpos[hand.grip] - grab)) > GRASP_M:
            return False
        scene.attach_to_grip(model, data, hand.person, self.artifact_ids[hand.target])
        self.held[hand.target] = True
        hand.phase, hand.hold_ctrl, hand.hold_s = "holding", hand.ctrl.copy(), 0.0
        return True

    def _retract(self, data: mujoco.MjData, hand: _Hand, dt: float) -> None:
        if hand.hold_s >= RETRACT_S:
            return
        hand.hold_s = min(RETRACT_S, hand.hold_s + dt)
        hand.ctrl[:] = hand.hold_ctrl
        back = min(hand.hold_ctrl[0], max(_LOW[0], RETRACT_TO_M - _HAND[0]))  # never push
        hand.ctrl[0] += (back - hand.hold_ctrl[0]) * hand.hold_s / RETRACT_S
        data.ctrl[hand.actuators] = hand.ctrl

    def let_go(self, model: mujoco.MjModel, data: mujoco.MjData, artifact_id: str) -> None:
        """Whoever holds or reaches for `artifact_id` lets it go (the grip weld opens, the
        hand back at rest): somebody is about to put it elsewhere."""
        k = self.artifact_ids.index(artifact_id)
        for hand in self.hands:
            if hand.target == k:
                weld = model.equality(scene.grip_weld_name(hand.person, artifact_id)).id
                data.eq_active[weld] = 0
                self._reset(data, hand)
        self.held[k] = False

    def _reset(self, data: mujoco.MjData, hand: _Hand) -> None:
        hand.phase, hand.target = "idle", -1
        hand.ctrl[:] = 0.0
        data.ctrl[hand.actuators] = 0.0

    # -- helpers --------------------------------------------------------------------------

    def _hand(self, person_id: str) -> _Hand:
        for hand in self.hands:
            if hand.person == person_id:
                return hand
        raise KeyError(f"no person {person_id!r}; people are {[h.person for h in self.hands]}")

    @staticmethod
    def _rest(data: mujoco.MjData, hand: _Hand) -> NDArray[np.float64]:
        R = data.xmat[hand.body].reshape(3, 3)
        return np.asarray(data.xpos[hand.body] + R @ _HAND, dtype=float)
