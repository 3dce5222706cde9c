"""The changing hall's hooks on artifacts: moved by somebody, taken away, knocked."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

import logging
import math

import numpy as np
import pytest

from common.messages.sim import ArtifactCommand, ObjectDropped, WorldEvent
from common.messages.world import WorldDescription
from services.sim.artifact_hook import ArtifactHook
from services.sim.core import PushError, SimCore
from services.sim.sensors import ideal_sensors
from services.sim.world import ARTIFACT_SPACING_M, generate_world, new_place


@pytest.fixture(scope="module")
def world() -> WorldDescription:
    return generate_world(0, "small")  # bottle_1 on table_1 (top 0.826 m)


def _run(core: SimCore, seconds: float) -> list[WorldEvent]:
    events: list[WorldEvent] = []
    for _ in range(round(seconds * 1000)):
        events += core.step()
    return events


def test_an_artifact_moved_to_another_place_rests_there_and_is_no_drop(
    world: WorldDescription,
) -> None:
    """From the table top to the floor by hand: 83 cm lower, yet no ObjectDropped (it was
    put there, it did not fall), upright where it was put."""
    core = SimCore(world, locomotion="kinematic", sensors=ideal_sensors())
    _run(core, 0.2)
    where = core.place_artifact("bottle_1", (-2.0, 1.5, 0.0), math.pi / 2)
    assert where == (-2.0, 1.5, 0.0)
    events = _run(core, 1.0)
    assert not [e for e in events if isinstance(e, ObjectDropped)]
    x, y, z = core.truth_positions()["bottle_1"]
    assert math.dist((x, y), (-2.0, 1.5)) < 0.01 and abs(z) < 0.005


def test_the_artifacts_truth_has_each_one_where_it_is_and_how_upright(
    world: WorldDescription,
) -> None:
    core = SimCore(world, locomotion="kinematic", sensors=ideal_sensors())
    _run(core, 0.2)
    (pose,) = core.artifact_poses()
    assert pose.id == "bottle_1" and pose.upright > 0.999
    assert pose.position_in_world == pytest.approx(core.truth_positions()["bottle_1"])
    core.place_artifact("bottle_1", (-2.0, 1.5, 0.0), 0.0)
    adr = core._artifact_q[0]
    core.data.qpos[adr + 3 : adr + 7] = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0)
    (lying,) = core.artifact_poses()  # turned 90° about x: on its side
    assert lying.upright == pytest.approx(0.0, abs=1e-9)


def test_an_artifact_taken_away_is_parked_beyond_the_walls(world: WorldDescription) -> None:
    core = SimCore(world, locomotion="kinematic", sensors=ideal_sensors())
    x = core.place_artifact("bottle_1", None, 0.0)[0]
    assert x > world.hall.max_xy[0] + 10.0
    events = _run(core, 0.5)
    assert not [e for e in events if isinstance(e, ObjectDropped)]
    assert core.truth_positions()["bottle_1"][0] == pytest.approx(x, abs=0.01)


def test_a_knock_on_an_artifact_can_make_it_fall_and_that_is_a_drop(
    world: WorldDescription,
) -> None:
    """A sideways knock off the table top: it lands on the floor, an ObjectDropped."""
    core = SimCore(world, locomotion="kinematic", sensors=ideal_sensors())
    _run(core, 0.5)  # resting on the table, its support recorded
    assert core.push((0.0, 30.0, 0.0), 0.1, target="bottle_1") == 100
    events = _run(core, 2.0)
    dropped = [e for e in events if isinstance(e, ObjectDropped)]
    assert [e.object_id for e in dropped] == ["bottle_1"]
    assert core.truth_positions()["bottle_1"][2] < 0.1


def test_a_bad_move_or_knock_is_refused_and_changes_nothing(world: WorldDescription) -> None:
    core = SimCore(world, locomotion="kinematic", sensors=ideal_sensors())
    before = core.truth_positions()["bottle_1"]
    with pytest.raises(KeyError, match="bottle_9"):
        core.place_artifact("bottle_9", (0.0, 0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="finite"):
        core.place_artifact("bottle_1", (math.nan, 0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="hall's floor"):  # a huge value would blow MuJoCo up
        core.place_artifact("bottle_1", (1e300, 0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="hall's floor"):
        core.place_artifact("bottle_1", (0.0, 0.0, -2.0), 0.0)
    with pytest.raises(PushError, match="bottle_9"):
        core.push((1.0, 0.0, 0.0), 0.1, target="bottle_9")
    assert core.truth_positions()["bottle_1"] == before


class _Fifo:
    def __init__(self, items: list[ArtifactCommand]) -> None:
        self.items = items

    def drain(self) -> list[ArtifactCommand]:
        out, self.items = self.items, []
        return out


def test_the_hook_moves_at_the_stamp_reports_the_move_and_refuses_a_bad_command(
    world: WorldDescription,
) -> None:
    core = SimCore(world, locomotion="kinematic", sensors=ideal_sensors())
    hook = ArtifactHook.__new__(ArtifactHook)
    hook._fifo = _Fifo([  # type: ignore[assignment]
        ArtifactCommand(stamp_ns=2_000_000, artifact_id="bottle_1", position=(1.0, -1.0, 0.0)),
        ArtifactCommand(stamp_ns=1_000_000, artifact_id="bottle_9", away=True),
        ArtifactCommand(stamp_ns=1_000_000, artifact_id="bottle_1"),  # neither place nor away
    ])  # fmt: skip
    hook._pending, hook.log, hook.applied = [], logging.getLogger("test"), 0
    assert hook.apply(0, core) == []  # nothing due yet
    assert hook.apply(1_000_000, core) == [] and hook.applied == 0  # both refused
    moved = hook.apply(2_000_000, core)
    assert [(m.object_id, m.position_in_world, m.away) for m in moved] == [
        ("bottle_1", (1.0, -1.0, 0.0), False)
    ]
    assert hook.applied == 1


def test_a_new_place_is_on_another_support_clear_of_the_others_and_pickable() -> None:
    """Where somebody puts a hall artifact down instead: on another surface's top, near a
    long edge, 0.3 m clear of every other artifact; the same seed, the same place."""
    hall = generate_world(0)
    art = hall.artifacts[0]
    taken = [a.position[:2] for a in hall.artifacts]
    got = new_place(hall, art.id, np.random.default_rng(1), taken, art.surface_id)
    assert got is not None
    (x, y, z), _yaw, surface_id = got
    assert surface_id != art.surface_id
    top = next(s for s in hall.surfaces if s.id == surface_id)
    assert z == pytest.approx(top.top_height)
    assert all(math.dist((x, y), q) >= ARTIFACT_SPACING_M for q in taken)
    assert new_place(hall, art.id, np.random.default_rng(1), taken, art.surface_id) == got


def test_bystanders_see_the_robot_carrying_only_what_is_held_up_off_every_surface() -> None:
    """The sim tells people the robot carries something when an artifact is off every
    surface and in no hand (in the gripper, in practice): here, one let fall through the
    air; the bottle on its table is not carried."""
    walking = generate_world(0, "small", walking_people=True)
    core = SimCore(walking, locomotion="kinematic", walking_people=True, bystanders=True,
                   sensors=ideal_sensors())  # fmt: skip
    _run(core, 0.3)
    near = core._robot_near()
    assert not near.carrying
    assert (near.x, near.y) == pytest.approx(
        (walking.robot_start.x, walking.robot_start.y), abs=0.05
    )
    core.place_artifact("bottle_1", (-2.0, 1.5, 1.5), 0.0)
    _run(core, 0.05)
    assert core._robot_near().carrying
