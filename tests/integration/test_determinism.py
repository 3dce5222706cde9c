"""The whole job through `dume eval`, twice: the small world's bring-me succeeds as the
report says, and the same seed gives the same run.

Each run is `dume eval --worlds 1 --world small --seed 0 --map saved`, as a user types
it: a fresh stack of every service in lockstep (the network segmenter, dynamic
locomotion) on the world's saved map (explored from nothing, shipped in `deploy/maps/`:
no floor plan, the pose estimated on the map's own grid), the request handed to the
mission before the sim starts. The first, recorded, must succeed as the sim's truth
judges it (bottle_1 in person_1's hand, nothing dropped) through the paper's stages in
order, with its report, plots, recording and logs. The two runs' digests (`run_digest`:
every status change as published and the base's trajectory at 10 Hz, bit for bit) must
be the same.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from common.config import REPO_ROOT
from common.messages.mission import STAGES
from tests.conftest import dume

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def eval_small_world(out: Path, *extra: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """One `dume eval` of the small world into `out`: its summary line and its world."""
    run = dume("eval", "--worlds", "1", "--world", "small", "--seed", "0", "--map", "saved",
               "--out", str(out), *extra, timeout=3000)  # fmt: skip
    assert run.returncode == 0, run.stderr[-4000:]
    assert run.stdout.strip(), run.stderr[-3000:]
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    (world,) = json.loads((out / "results.json").read_text())["worlds"]
    return summary, world


@pytest.mark.timeout(3600)  # two whole jobs: minutes of wall time each on 2 cores
def test_the_bring_me_succeeds_as_the_report_says_and_the_same_seed_gives_the_same_run(
    tmp_path: Path,
) -> None:
    summary, first = eval_small_world(tmp_path / "first", "--record")
    doc = json.loads((tmp_path / "first" / "results.json").read_text())
    assert doc["settings"]["segmenter"] == "network"
    assert doc["settings"]["locomotion"] == "dynamic"
    assert doc["settings"]["map start"].startswith("each world's saved map in var/saved-maps/")
    assert first["outcome"] == "succeeded", first  # the whole record: CI keeps no logs
    assert summary["worlds"] == 1 and summary["succeeded"] == 1
    assert first["object"] == "bottle_1"  # the map's ids: the robot's own map's
    assert (first["truth_object"], first["truth_person"]) == ("bottle_1", "person_1")
    assert first["agree"] and first["stages_passed"] == list(STAGES)
    assert first["drops"] == 0
    report = (tmp_path / "first" / "report.md").read_text()
    assert "**Success: 1/1 (100 %; 95 % interval 21-100 %, Wilson)**" in report
    for plot in ("stage_times.png", "outcomes.png", "worlds/seed-0.png"):
        assert (tmp_path / "first" / plot).exists(), plot
    assert first["logs"].startswith("var/run/") and (REPO_ROOT / first["logs"] / "sim.log").exists()
    assert list((REPO_ROOT / first["recording"]).glob("mission.rrd")), first["recording"]

    _, second = eval_small_world(tmp_path / "second", "--record")  # as like as can be
    assert second["outcome"] == "succeeded", second
    assert second["digest"] == first["digest"], [
        (run["stage_times_s"], run["watch_lapses"]) for run in (first, second)
    ]  # a lapse of this client's own link loses what it would have heard meanwhile
