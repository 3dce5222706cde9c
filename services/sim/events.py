"""World events from the contacts of each step: robot contacts, dropped objects, and the
per-artifact contact flags the handover needs.

`ContactMonitor.update` reads the step's contacts once, vectorised over per-geom tables
built at start-up: which robot body (if any) a geom belongs to, which foot, which world
thing (`floor`, an obstacle, artifact or person id). It sums the feet's normal forces, flags
each artifact touching the world (anything but the robot) or the robot, and emits a
`RobotContact` when a robot body other than a foot begins touching a world thing — the
gripper on an artifact is a grasp, not a contact. "Begins" means the pair was not in
contact during the last `REARM_NS`, so a contact that chatters is reported once.

`DropMonitor` tracks each artifact's height where it was last supported (resting, touching
the robot or held by a person) and emits `ObjectDropped` when it lands on the world more
than `DROP_M` below it while no person holds it: knocked off a table, or let go mid-air.
Normal forces are the first row of each contact's constraint (elliptic cones, as set by
`services.sim.scene`).
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from common import robot
from common.messages.sim import ObjectDropped, RobotContact
from common.messages.world import WorldDescription

FLOOR = "floor"
#: A robot-world pair must have been apart this long to be reported again, ns.
REARM_NS = 50_000_000
#: An artifact landing this far below where it was last supported has dropped, m.
DROP_M = 0.10
GRIPPER_BODIES = ("gripperStator", "gripperMover")
_ASLEEP = int(mujoco.mjtSleepState.mjS_ASLEEP)

IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


def _vec3(v: NDArray[np.float64]) -> tuple[float, float, float]:
    x, y, z = v.tolist()
    return x, y, z


class StepContacts:
    """What the last step's contacts say, in reusable arrays (read, do not keep).

    foot_force: (4,) N normal force on FL, FR, RL, RR. artifact_on_world, artifact_on_robot:
    (n_artifacts,) whether each artifact touches a world geom / a robot geom.
    artifact_asleep: (n_artifacts,) resting in MuJoCo's sleep, where contacts are skipped.
    """

    def __init__(self, n_artifacts: int) -> None:
        self.foot_force = np.zeros(len(robot.FOOT_FRAMES))
        self.artifact_on_world = np.zeros(n_artifacts, dtype=bool)
        self.artifact_on_robot = np.zeros(n_artifacts, dtype=bool)
        self.artifact_asleep = np.zeros(n_artifacts, dtype=bool)


class ContactMonitor:
    """Per-step contact bookkeeping and the edge-triggered `RobotContact` events."""

    def __init__(self, model: mujoco.MjModel, world: WorldDescription) -> None:
        base = model.body(robot.BASE_FRAME).id
        root = model.body_rootid[model.geom_bodyid]
        body = model.geom_bodyid
        self.robot_body: IntArray = np.where(root == base, body, -1)
        feet = [model.body(f).id for f in robot.FOOT_FRAMES]
        self.foot: IntArray = np.array([feet.index(b) if b in feet else -1 for b in body])
        grippers = [model.body(name).id for name in GRIPPER_BODIES]
        self.gripper: BoolArray = np.isin(body, grippers)
        self.artifact_ids = tuple(a.id for a in world.artifacts)
        art_bodies = [model.body(a).id for a in self.artifact_ids]
        self.artifact: IntArray = np.array(
            [art_bodies.index(r) if r in art_bodies else -1 for r in root], dtype=np.intp
        )
        self.artifact_bodies: IntArray = np.array(art_bodies, dtype=np.intp)
        self.others: list[str] = [FLOOR]
        other = np.full(model.ngeom, -1, dtype=np.intp)
        for g in range(model.ngeom):
            if root[g] == base:
                continue
            name = FLOOR if root[g] == 0 else model.body(int(root[g])).name
            if name not in self.others:
                self.others.append(name)
            other[g] = self.others.index(name)
        self.other: IntArray = other
        self.body_names = [model.body(b).name for b in range(model.nbody)]
        # The same tables as Python lists, for the per-step loop.
        self._robot_body: list[int] = self.robot_body.tolist()
        self._foot: list[int] = self.foot.tolist()
        self._gripper: list[bool] = self.gripper.tolist()
        self._artifact: list[int] = self.artifact.tolist()
        self._other: list[int] = self.other.tolist()
        self.contacts = StepContacts(len(self.artifact_ids))
        self._last_seen: dict[int, int] = {}

    def update(self, data: mujoco.MjData, stamp_ns: int) -> list[RobotContact]:
        """Read the last step's contacts into `self.contacts`; the contacts that began.

        A plain loop over the few contacts of a step (feet, a grasp, a bump) costs less
        than numpy's per-call overhead on such small arrays.
        """
        c = self.contacts
        c.artifact_on_world[:] = False
        c.artifact_on_robot[:] = False
        c.artifact_asleep[:] = data.body_awake[self.artifact_bodies] == _ASLEEP
        feet = [0.0, 0.0, 0.0, 0.0]
        pairs: dict[int, list[int]] = {}
        if data.ncon:
            contact = data.contact
            robot_body, artifact, efc = self._robot_body, self._artifact, data.efc_force
            rows = zip(contact.geom.tolist(), contact.efc_address.tolist(), strict=True)
            for row, ((g1, g2), address) in enumerate(rows):
                b1, b2 = robot_body[g1], robot_body[g2]
                if b1 < 0 and b2 < 0:  # world and world: an artifact resting on something
                    for art in (artifact[g1], artifact[g2]):
                        if art >= 0:
                            c.artifact_on_world[art] = True
                    continue
                if b1 >= 0 and b2 >= 0:  # the robot's own parts
                    continue
                mine, theirs, body = (g1, g2, b1) if b1 >= 0 else (g2, g1, b2)
                art = artifact[theirs]
                if art >= 0:
                    c.artifact_on_robot[art] = True
                foot = self._foot[mine]
                if foot >= 0:
                    feet[foot] += float(efc[address]) if address >= 0 else 0.0
                elif not (art >= 0 and self._gripper[mine]):
                    key = body * len(self.others) + self._other[theirs]
                    pairs.setdefault(key, []).append(row)
        c.foot_force[:] = feet
        return self._began(data, stamp_ns, pairs) if pairs else []

    def _began(
        self, data: mujoco.MjData, stamp_ns: int, pairs: dict[int, list[int]]
    ) -> list[RobotContact]:
        """Events for the robot-world pairs in touch now that were apart for `REARM_NS`."""
        events = []
        contact = data.contact
        for key, rows in pairs.items():
            last = self._last_seen.get(key)
            self._last_seen[key] = stamp_ns
            if last is not None and stamp_ns - last <= REARM_NS:
                continue
            address = contact.efc_address[rows]
            forces = np.where(address >= 0, data.efc_force[address], 0.0)
            body, other = divmod(key, len(self.others))
            events.append(
                RobotContact(
                    stamp_ns=stamp_ns,
                    body=self.body_names[body],
                    other=self.others[other],
                    position_in_world=_vec3(contact.pos[rows[int(np.argmax(forces))]]),
                    force=float(max(forces.sum(), 0.0)),
                )
            )
        return events


class DropMonitor:
    """`ObjectDropped` when an artifact lands more than `DROP_M` below its last support."""

    def __init__(self, model: mujoco.MjModel, artifact_ids: tuple[str, ...]) -> None:
        self.ids = artifact_ids
        self.bodies: IntArray = np.array([model.body(a).id for a in artifact_ids], dtype=np.intp)
        self.z_ref: NDArray[np.float64] = np.zeros(len(artifact_ids))
        self._started = False

    def forget(self, k: int) -> None:
        """Artifact k was moved by hand: its last support is unknown until it rests again
        (landing on its new one is no drop)."""
        self.z_ref[k] = -np.inf

    def update(
        self, data: mujoco.MjData, contacts: StepContacts, held: BoolArray, stamp_ns: int
    ) -> list[ObjectDropped]:
        """Check after each step; `held` (n_artifacts,) marks artifacts a person holds."""
        if not len(self.ids) or (contacts.artifact_asleep.all() and not held.any()):
            return []  # all resting in MuJoCo's sleep: their heights were recorded awake
        z = data.xpos[self.bodies, 2]
        if not self._started:
            self.z_ref[:] = z
            self._started = True
        asleep = contacts.artifact_asleep
        supported = contacts.artifact_on_world | contacts.artifact_on_robot | asleep | held
        landed = contacts.artifact_on_world & ~held & ~asleep & (z < self.z_ref - DROP_M)
        events = [
            ObjectDropped(
                stamp_ns=stamp_ns,
                object_id=self.ids[k],
                position_in_world=_vec3(data.xpos[self.bodies[k]]),
            )
            for k in np.flatnonzero(landed).tolist()
        ]
        self.z_ref[supported] = z[supported]
        return events
