"""The fetch copes with a hall that changed: whole stacks, the small world, lockstep.

Each test is a fresh stack of every service (the eval's settings: the network segmenter,
dynamic locomotion, the map seeded from the world, so the map says where the bottle and
the person were), somebody moves the bottle through the sim's hook
(`dume/world/artifact_command`), or the person walks off (`dume/world/people_command`),
before the mission's first tick, or the carried bottle is knocked out of the jaws
(`dume/world/push`), and the request goes in at t = 0 (`start_gate`); or the request is
cancelled while carrying and the bottle put back. What the sim's truth sees is judged:
the bottle in the requested person's hand (or back on its table), or the typed failure
and where the robot looked.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from bench.eval.evaluate import SERVICES, world_overrides
from bench.eval.judge import MissionRecord
from bench.eval.run import watch_mission
from common.keys import (
    WORLD_ARTIFACT_COMMAND,
    WORLD_ARTIFACTS,
    WORLD_DESCRIPTION,
    WORLD_PEOPLE_COMMAND,
    WORLD_PUSH,
)
from common.messages.mission import MissionCancel, MissionRequest, MissionStatus
from common.messages.sim import (
    ArtifactCommand,
    ArtifactMoved,
    ArtifactPose,
    ArtifactsTruth,
    HandoverTaken,
    ObjectDropped,
    PersonCommand,
    Push,
)
from common.messages.world import WorldDescription
from deploy.stack import ProcessStack
from services.sim.world import new_place

pytestmark = [pytest.mark.integration, pytest.mark.slow]

#: Sim time the bottle is moved at: before the mission's first look.
MOVE_NS = 100_000_000


def coping_overrides(tmp_path: Path) -> dict[str, object]:
    """The eval's small-world stack, seed 0, its map seeded from the world (the truth
    then: what the map says before anyone moves)."""
    args = argparse.Namespace(world="small", walking_people=False, record=False, set=[])
    return world_overrides(args, 0, "coping") | {
        "semantic_map.dir": str(tmp_path / "map"),
        "recording.enabled": False,
    }


def move_bottle(s: ProcessStack, away: bool) -> str:
    """bottle_1 moved along its table (the small world has one), away from where the map
    has it, or taken away, before the mission's first look; where it went."""
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10.0)
    bottle = next(a for a in world.artifacts if a.id == "bottle_1")
    mover = s.bus.publisher(WORLD_ARTIFACT_COMMAND, ArtifactCommand, "control")
    if away:
        mover.put(ArtifactCommand(stamp_ns=MOVE_NS, artifact_id=bottle.id, away=True))
        return "away"
    spot = new_place(world, bottle.id, np.random.default_rng(3), [bottle.position[:2]])
    assert spot is not None
    position, yaw, on = spot
    mover.put(ArtifactCommand(stamp_ns=MOVE_NS, artifact_id=bottle.id, position=position, yaw=yaw))
    return f"{on} at ({position[0]:.2f}, {position[1]:.2f})"


#: Where person_1 walks off to: 2.4 m from their mapped place (-2.58, 0.58), by the
#: hall's south-west corner.
WALKED_TO = (-3.1, -1.8)
#: s after the carry began: the robot has turned from the table and sees them (they
#: stop to face it once it comes near, as a person asked for would).
WALK_AFTER_S = 5.0


class WhenCarrying:
    """Once the carry began (the status enters `bring_to_user`), `act(stamp_ns)` puts a
    hook's command for `after_s` later (sent ahead of its time)."""

    def __init__(self, after_s: float, act: Callable[[int], None]) -> None:
        self.after_ns, self.act, self.at_ns = round(after_s * 1e9), act, 0

    def on_progress(self, status: MissionStatus | None, _clock: Any, changed: bool) -> None:
        carrying = changed and status is not None and status.behaviour == "bring_to_user"
        if carrying and status is not None and not self.at_ns:
            self.at_ns = status.stamp_ns + self.after_ns
            self.act(self.at_ns)


def fetch(
    tmp_path: Path,
    before: Callable[[ProcessStack], str] = lambda _s: "",
    after_s: float = 0.0,
    act: Callable[[ProcessStack, int], None] | None = None,
) -> tuple[MissionRecord, str, int]:
    """bottle_1 to person_1 on a fresh stack: `before(stack)` done ahead of the request (it
    says what it did), `act(stack, stamp_ns)` `after_s` into the carry; the record, what
    `before` said, and when `act` was done (0: the carry never began)."""
    with ProcessStack(list(SERVICES), coping_overrides(tmp_path)) as s:
        said = before(s)
        hook = WhenCarrying(after_s, lambda at: act(s, at) if act is not None else None)
        request = MissionRequest(request_id="coping", object="bottle_1", person="person_1")
        record = watch_mission(s.bus, s.keys, request, 900.0, hook.on_progress, start_gate=True)
    return record, said, hook.at_ns


def assert_brought(record: MissionRecord) -> None:
    """The request succeeded, the sim's handover event says so: bottle_1 to person_1."""
    last = record.changes[-1]
    assert last.state == "succeeded", last
    taken = [e for e in record.events if isinstance(e, HandoverTaken)]
    assert [(e.object_id, e.person_id) for e in taken] == [("bottle_1", "person_1")]
    assert not [e for e in record.events if isinstance(e, ObjectDropped)]


def walk_off(s: ProcessStack, at_ns: int) -> None:
    walker = s.bus.publisher(WORLD_PEOPLE_COMMAND, PersonCommand, "control")
    walker.put(PersonCommand(stamp_ns=at_ns, person_id="person_1", walk_to=(WALKED_TO,),
                             speed=0.8, ignore_robot=False))  # fmt: skip


@pytest.mark.timeout(3600)  # a whole job: minutes of wall time on 2 cores
def test_a_bottle_moved_along_its_table_is_found_there_and_brought_to_its_person_who_walked_off(
    tmp_path: Path,
) -> None:
    """Two of the shift's changes in one fetch (one stack, one whole job: CI's time): the
    bottle is moved along its table before the robot first looks, and the person walks
    off 2.4 m as the robot comes with it. The search finds the bottle where it now stands,
    and the robot follows the person to where they stopped and hands it over."""
    record, where, walked_at = fetch(tmp_path, lambda s: move_bottle(s, away=False),
                                     WALK_AFTER_S, walk_off)  # fmt: skip
    assert [e for e in record.events if isinstance(e, ArtifactMoved)], where
    assert walked_at > 0, ("the carry never began", where, record.changes[-1])
    assert_brought(record)  # found where it was moved, given where they stopped


@pytest.mark.timeout(3600)
def test_a_bottle_taken_away_fails_as_not_found_naming_where_it_looked(tmp_path: Path) -> None:
    record, _, _ = fetch(tmp_path, lambda s: move_bottle(s, away=True))
    last = record.changes[-1]
    assert (last.state, last.reason) == ("failed", "object_not_found"), last
    assert "looked at:" in last.detail or "no viewpoint" in last.detail, last.detail
    assert not [e for e in record.events if isinstance(e, HandoverTaken)]


#: A slip: a knock straight down on the carried bottle, 3 s into the carry, that pulls it
#: out of the jaws (sideways knocks of 20-100 N for 0.1-0.15 s never do).
KNOCK = Push(stamp_ns=0, force_in_world=(0.0, 0.0, -150.0), duration_s=0.1, target="bottle_1")


def knock(s: ProcessStack, at_ns: int) -> None:
    pusher = s.bus.publisher(WORLD_PUSH, Push, "control")
    pusher.put(msgspec.structs.replace(KNOCK, stamp_ns=at_ns))


@pytest.mark.timeout(3600)
def test_a_bottle_knocked_from_the_gripper_to_the_floor_is_reported_where_it_lies(
    tmp_path: Path,
) -> None:
    """The bottle falls at the robot's feet, out of every camera's view and below any
    grasp: the robot steps back to look at the floor there and ends the request
    `object_dropped` saying where it lies (no walk back to its table, no search).

    Where: as seen ("lies at": whatever class the network gives it there, where the
    gripper lost it), else as the gripper's place at the loss said ("fell at ... not found
    where it fell"). The network never saw a bottle lying on a floor in training:
    rendered from the look pose (1.3-2.0 m, three orientations) it found it only at about
    1.4 m, as a bottle or a box, and from nearer, looking down, called it a person (0.9:
    no longer taken for one, `self_filter.is_flat`). This run sees a box there."""
    record, _, knocked_at = fetch(tmp_path, after_s=3.0, act=knock)
    assert knocked_at > 0, "the carry began and the bottle was knocked"
    dropped = [e for e in record.events if isinstance(e, ObjectDropped)]
    # one fall, or a fall onto the robot's foot and off it to the floor: two landings
    assert dropped and {e.object_id for e in dropped} == {"bottle_1"}
    last = record.changes[-1]
    assert (last.state, last.reason) == ("failed", "object_dropped"), last
    said = "lies at (" if "lies at (" in last.detail else "fell at ("
    x, y = (float(v) for v in last.detail.split(said)[1].split(")")[0].split(", "))
    fell = [e.position_in_world for e in dropped]
    assert any(np.hypot(x - f[0], y - f[1]) < 0.5 for f in fell), (last.detail, fell)  # where
    assert last.stamp_ns - dropped[0].stamp_ns < 30e9  # told at once, not after a search
    assert not [e for e in record.events if isinstance(e, HandoverTaken)]


@pytest.mark.timeout(3600)
def test_a_bottle_still_held_after_a_cancel_is_put_back_on_its_table_when_asked(
    tmp_path: Path,
) -> None:
    """The request is cancelled as the carry begins: the robot holds the bottle (and says
    so). A `put_back` request then walks it back to where it stood for the grasp, sets it
    down where it was picked and lets go: the sim's truth has it upright within 5 cm of
    where it stood before the fetch, and nothing fell."""
    with ProcessStack(list(SERVICES), coping_overrides(tmp_path)) as s:
        before = _bottle(s)
        canceller = s.bus.publisher(s.keys.mission_cancel, MissionCancel, "control")
        hook = WhenCarrying(
            0.0,
            lambda _at: canceller.put(
                MissionCancel(request_id="carried", reason="changed my mind")
            ),
        )
        request = MissionRequest(request_id="carried", object="bottle_1", person="person_1")
        carried = watch_mission(s.bus, s.keys, request, 900.0, hook.on_progress, start_gate=True)
        back = watch_mission(
            s.bus, s.keys, MissionRequest(request_id="back", task="put_back"), 600.0
        )
        after = _bottle(s)
    cancelled = carried.changes[-1]
    assert cancelled.state == "cancelled", cancelled
    assert "the robot was holding bottle_1" in cancelled.detail, cancelled.detail
    last = back.changes[-1]
    assert (last.state, last.detail) == ("succeeded", "bottle_1 put back where it was picked")
    moved = np.subtract(after.position_in_world, before.position_in_world)
    print(f"bottle_1 moved {np.hypot(moved[0], moved[1]) * 100:.1f} cm across, "
          f"{moved[2] * 100:+.1f} cm up; upright {after.upright:.4f}")  # fmt: skip
    assert float(np.hypot(moved[0], moved[1])) < 0.05 and abs(moved[2]) < 0.02, (before, after)
    assert after.upright > 0.95, after
    assert not [e for e in (*carried.events, *back.events) if isinstance(e, ObjectDropped)]


def _bottle(s: ProcessStack) -> ArtifactPose:
    """bottle_1 as the sim has it now (truth)."""
    truth = s.bus.query(WORLD_ARTIFACTS, None, ArtifactsTruth, timeout_s=10.0)
    return next(a for a in truth.artifacts if a.id == "bottle_1")
