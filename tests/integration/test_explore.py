"""Exploration from nothing end to end: the small world mapped with no floor plan.

sim + wbc + perception (the network) + semantic_map + navigation + mission + the
localization, lockstep, dynamic locomotion, the map empty with no floor plan
(`semantic_map.floor_plan = "none"`: every cell unknown until the sensors show floor or
an obstacle), the robot on its own odometry with the localization's SLAM (it maps while
it localizes). The mission takes a request `{"task": "explore"}` and walks frontier after
frontier through navigation (`bench.trial_explore.explore_run`), then the semantic pass
over the surfaces it found (the table) with the arm raised, and a second look at what is
in doubt; it must end succeeded with no reachable frontier left, having made most of the
room's floor known, with the bottle on the map within 10 cm as a bottle and the person
found. The map is scored against the world description (truth, read by the trial only);
the figures are printed (`pytest -rP` shows them).

This is also CI's system test of the patrol's route walking (`PatrolRunner`): the
semantic pass is a patrol facing the surfaces; the floor plan's lattice patrol (`dume
trial patrol`) is not run in CI. The same on the sim's truth for the base (the ablation
that tries the exploration apart from the SLAM) is `dume trial explore`, not a test:
CI's time goes to what the robot runs.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.trial_explore import explore_run

pytestmark = [pytest.mark.integration, pytest.mark.slow]


@pytest.mark.timeout(3600)  # a whole job: minutes of wall time on 2 cores
def test_on_its_own_odometry_with_the_slam_it_explores_the_small_world_from_nothing(
    tmp_path: Path,
) -> None:
    overrides = {"wbc.base_state": "estimate", "mission.explore_semantic_pass": True}
    out = explore_run("small", 0, overrides, db_dir=str(tmp_path))
    print(json.dumps(out))
    assert (out["outcome"], out["reason"]) == ("succeeded", ""), out
    assert "no reachable frontier left" in out["detail"], out
    assert out["goals_walked"] >= 1 and out["travelled_m"] > 1.0, out  # 1 goal, 2.4 m
    assert out["semantic_pass"] and out["semantic_pass"]["viewpoints"] >= 1, out
    # The known floor grew from nothing to most of the room.
    assert out["floor_known_share"] >= 0.8, out
    assert out["occupancy_iou_5cm"] >= 0.5, out
    # The semantic pass: the one artifact and the one person, the artifact within 10 cm
    # with its class, in the map's frame as its alignment to the truth puts it (a map
    # made while localizing is in its own frame; `entities` has them as they lie).
    found = out["entities_aligned"]
    assert found["found_within_10cm"] == found["found_right_class"] == 1, found
    assert found["people_found"] == 1 and len(found["false_entries"]) <= 1, found
