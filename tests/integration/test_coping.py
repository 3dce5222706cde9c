"""The fetch copes with a hall that changed: whole stacks, the small world, lockstep.

Each test is a fresh stack of every service (the eval's settings: the network segmenter,
dynamic locomotion, the map seeded from the world, so the map says where the bottle was),
somebody moves the bottle through the sim's hook (`dume/world/artifact_command`) before
the mission's first tick, and the request goes in at t = 0 (`start_gate`). What the sim's
truth sees is judged: the bottle in the person's hand, or the typed failure and where the
robot looked.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from bench.eval.evaluate import SERVICES, world_overrides
from bench.eval.judge import MissionRecord
from bench.eval.run import watch_mission
from common.keys import WORLD_ARTIFACT_COMMAND, WORLD_DESCRIPTION
from common.messages.mission import MissionRequest
from common.messages.sim import ArtifactCommand, ArtifactMoved, HandoverTaken, ObjectDropped
from common.messages.world import WorldDescription
from deploy.stack import ProcessStack
from services.sim.world import new_place

pytestmark = [pytest.mark.integration, pytest.mark.slow]

#: Sim time the bottle is moved at: before the mission's first look.
MOVE_NS = 100_000_000


def fetch_after_a_move(tmp_path: Path, away: bool) -> tuple[MissionRecord, str]:
    """The bottle moved along its table (or taken away), then asked for; the record and
    where it went."""
    args = argparse.Namespace(world="small", walking_people=False, record=False, set=[])
    overrides = world_overrides(args, 0, "coping") | {
        "semantic_map.dir": str(tmp_path / "map"),
        "recording.enabled": False,
    }
    with ProcessStack(list(SERVICES), overrides) as s:
        world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=10.0)
        bottle = next(a for a in world.artifacts if a.id == "bottle_1")
        mover = s.bus.publisher(WORLD_ARTIFACT_COMMAND, ArtifactCommand, "control")
        if away:
            mover.put(ArtifactCommand(stamp_ns=MOVE_NS, artifact_id=bottle.id, away=True))
            said = "away"
        else:  # the same table (the small world has one), away from where the map has it
            spot = new_place(world, bottle.id, np.random.default_rng(3), [bottle.position[:2]])
            assert spot is not None
            position, yaw, on = spot
            mover.put(
                ArtifactCommand(stamp_ns=MOVE_NS, artifact_id=bottle.id, position=position, yaw=yaw)
            )
            said = f"{on} at ({position[0]:.2f}, {position[1]:.2f})"
        request = MissionRequest(request_id="coping", object=bottle.id, person="person_1")
        return watch_mission(s.bus, s.keys, request, 600.0, start_gate=True), said


@pytest.mark.timeout(3600)  # a whole job: minutes of wall time on 2 cores
def test_a_bottle_moved_along_its_table_is_found_there_and_brought(tmp_path: Path) -> None:
    record, where = fetch_after_a_move(tmp_path, away=False)
    last = record.changes[-1]
    assert [e for e in record.events if isinstance(e, ArtifactMoved)], where
    assert last.state == "succeeded", (where, last)
    taken = [e for e in record.events if isinstance(e, HandoverTaken)]
    assert [(e.object_id, e.person_id) for e in taken] == [("bottle_1", "person_1")]
    assert not [e for e in record.events if isinstance(e, ObjectDropped)]


@pytest.mark.timeout(3600)
def test_a_bottle_taken_away_fails_as_not_found_naming_where_it_looked(tmp_path: Path) -> None:
    record, _ = fetch_after_a_move(tmp_path, away=True)
    last = record.changes[-1]
    assert (last.state, last.reason) == ("failed", "object_not_found"), last
    assert "looked at:" in last.detail or "no viewpoint" in last.detail, last.detail
    assert not [e for e in record.events if isinstance(e, HandoverTaken)]
