"""The same seed gives the same run: the small world's bring-me twice, compared.

Each run is a fresh stack of every service in lockstep (the eval's settings: the network
segmenter, dynamic locomotion, the map seeded from the world), the request handed to the
mission before the sim starts (`watch_mission(start_gate=True)`). The mission's status
timeline (every change, as published) and the base's trajectory at 10 Hz must be the
same bit for bit, and so the runs' digests.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import msgspec
import pytest

from common.eval_judge import MissionRecord, run_digest
from common.eval_run import read_map, watch_mission
from common.eval_targets import seeded_pair
from common.evaluate import SERVICES, world_overrides
from common.messages.mission import MissionRequest
from common.stack import ProcessStack

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def bring_me(tmp_path: Path, run: int) -> MissionRecord:
    args = argparse.Namespace(world="small", walking_people=False, record=False, set=[])
    overrides = [
        *world_overrides(args, 0, f"determinism-{run}"),
        f'semantic_map.dir="{tmp_path / f"map-{run}"}"',
    ]
    with ProcessStack(list(SERVICES), overrides) as s:
        arts, people = read_map(s.bus)
        pair = seeded_pair(arts, people, 0)
        request = MissionRequest(request_id="same-seed", object=pair.object, person=pair.person)
        return watch_mission(s.bus, s.keys, request, 300.0, start_gate=True)


@pytest.mark.timeout(2400)  # two whole jobs: minutes of wall time each on 2 cores
def test_the_same_seed_gives_the_same_status_timeline_and_trajectory(tmp_path: Path) -> None:
    first, second = bring_me(tmp_path, 1), bring_me(tmp_path, 2)
    assert first.changes and first.changes[-1].state == "succeeded", first.changes[-1:]
    timeline = [[msgspec.to_builtins(c) for c in r.changes] for r in (first, second)]
    assert timeline[0] == timeline[1]
    assert len(first.trajectory) > 100
    n = min(len(first.trajectory), len(second.trajectory))
    diverged = next((i for i in range(n) if first.trajectory[i] != second.trajectory[i]), None)
    assert diverged is None, (first.trajectory[diverged], second.trajectory[diverged])
    assert run_digest(first) == run_digest(second)
