"""No truth in the robot's loop: the whole default stack runs under the truth guard
(`common.truth`), and a service's bus refuses truth it was not granted."""

from __future__ import annotations

import time

import pytest

from common.access import identity_of
from common.bus import Bus
from common.keys import WORLD_CLOCK, WORLD_DESCRIPTION, WORLD_EVENTS
from common.messages.localization import Localization
from common.messages.sim import Clock, Odom, StateTruth, WorldEvents
from common.messages.world import WorldDescription
from common.truth import TruthGuard, TruthKeyError
from deploy.stack import MODULES
from tests.conftest import HOLD_COMMANDER, StartStack

pytestmark = pytest.mark.integration

EVERY_SERVICE = [
    "sim", "perception", "semantic_map", "navigation", "wbc", "localization", "mission"
]  # fmt: skip


@pytest.mark.parametrize("base_state", ["estimate", "truth"])
def test_the_default_stack_runs_under_the_truth_guard(stack: StartStack, base_state: str) -> None:
    """Every service starts with its bus guarded and keeps running for 2 s of sim time: a
    service that subscribed to or queried a truth key it was not granted would have
    raised `TruthKeyError` and exited."""
    assert set(EVERY_SERVICE) < set(MODULES)
    s = stack(EVERY_SERVICE, 'sim.world="small"', f'wbc.base_state="{base_state}"')
    located = s.bus.latest(s.keys.localization, Localization, history=64)
    clock = s.bus.latest(WORLD_CLOCK, Clock)
    clock.wait(lambda c: c.stamp_ns >= 2_000_000_000, 240.0)
    if base_state == "estimate":  # the robot on its own: the lidar matched to the map
        loc = located.wait(lambda m: m.stamp_ns >= 1_000_000_000, 30.0)
        assert loc.status == "ok" and loc.confidence > 0.5, loc
    else:
        assert located.get() is None  # the truth ablation: odom is the map
    for name in EVERY_SERVICE:
        assert s.procs[name].poll() is None, f"{name} exited:\n{s.log_text(name)[-3000:]}"
        assert "TruthKeyError" not in s.log_text(name), s.log_text(name)[-3000:]
    assert s.alive() >= set(EVERY_SERVICE)


def test_a_services_bus_refuses_truth_it_was_not_granted(stack: StartStack) -> None:
    """A real session with the mission's guard: odometry and the clock are the robot's,
    the base's truth, the world's description and its events are not."""
    s = stack(["sim", "hold"], 'sim.world="small"', *HOLD_COMMANDER)
    mission = Bus.open(
        s.config,
        guard=TruthGuard.of("mission", s.config),
        user=identity_of("mission", s.config.robot),
    )
    try:
        mission.latest(s.keys.odom, Odom).undeclare()
        mission.latest(WORLD_CLOCK, Clock).undeclare()
        with pytest.raises(TruthKeyError, match=r"mission may not read .*state_truth"):
            mission.latest(s.keys.state_truth, StateTruth)
        with pytest.raises(TruthKeyError, match="world/events"):
            mission.fifo(WORLD_EVENTS, WorldEvents)
        with pytest.raises(TruthKeyError, match="world/description"):
            mission.query(WORLD_DESCRIPTION, None, WorldDescription, 1.0)
    finally:
        mission.close()
    # The map's floor-plan prior is granted, and answered by the sim.
    smap = Bus.open(
        s.config,
        guard=TruthGuard.of("semantic_map", s.config),
        user=identity_of("semantic_map", s.config.robot),
    )
    try:
        t0 = time.monotonic()
        world = smap.query(WORLD_DESCRIPTION, None, WorldDescription, 10.0)
        assert world.artifacts and time.monotonic() - t0 < 10.0
        assert smap.guard is not None
        assert smap.guard.granted == {
            WORLD_DESCRIPTION: "semantic_map.floor_plan=world (the floor-plan prior)"
        }
    finally:
        smap.close()
