"""The seeded worlds: reproducible, feasible for the robot, and a MuJoCo scene that holds still."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

import math
import re
from collections import Counter

import msgspec
import mujoco
import numpy as np
import pytest

from common import robot
from common.messages.arrays import as_numpy
from common.messages.world import OCCUPIED, Cuboid, Cylinder, Hall, Obstacle, WorldDescription
from services.sim import feasibility as fz
from services.sim import mjcf, scene
from services.sim.visibility import (
    MIN_VISIBLE_FRACTION,
    check_visibility,
    check_world,
    visible_fractions,
)
from services.sim.world import generate_world

SEEDS = range(100)


@pytest.fixture(scope="module")
def halls() -> dict[int, WorldDescription]:
    return {seed: generate_world(seed) for seed in SEEDS}


def _encode(world: WorldDescription) -> bytes:
    return msgspec.msgpack.encode(world)


def test_the_same_seed_gives_the_same_bytes_and_another_seed_another_world() -> None:
    for name in ("hall", "small"):
        assert _encode(generate_world(7, name)) == _encode(generate_world(7, name))
        assert _encode(generate_world(7, name)) != _encode(generate_world(8, name))
    walking = generate_world(7, walking_people=True)
    assert _encode(walking) == _encode(generate_world(7, walking_people=True))


def test_walking_people_start_where_and_as_they_stand() -> None:
    """Routes come from a stream of their own: a map explored with people standing is the
    walking world's map too (it once drew them from the world's stream, so walking
    people started elsewhere, in other clothes, and the saved map's people were ghosts)."""
    for seed in range(5):
        standing, walking = generate_world(seed), generate_world(seed, walking_people=True)
        assert walking.artifacts == standing.artifacts
        still = [msgspec.structs.replace(p, waypoints=(), speed=0.0) for p in walking.people]
        assert still == list(standing.people)
        assert any(p.waypoints for p in walking.people)


def test_msgpack_and_json_round_trips_give_the_same_world(
    halls: dict[int, WorldDescription],
) -> None:
    world = halls[0]
    assert msgspec.msgpack.decode(_encode(world), type=WorldDescription) == world
    text = msgspec.json.encode(world)
    assert msgspec.json.decode(text, type=WorldDescription) == world


def test_ids_are_unique_and_numbered_per_class_from_one(halls: dict[int, WorldDescription]) -> None:
    for world in halls.values():
        for things in (world.artifacts, world.people, world.obstacles):
            ids = [t.id for t in things]
            assert len(ids) == len(set(ids))
            per_class: dict[str, list[int]] = {}
            for thing_id in ids:
                match = re.fullmatch(r"([a-z]+)_(\d+)", thing_id)
                assert match, thing_id
                per_class.setdefault(match[1], []).append(int(match[2]))
            for numbers in per_class.values():
                assert sorted(numbers) == list(range(1, len(numbers) + 1))
        assert all(a.id.startswith(a.object_class + "_") for a in world.artifacts)


def test_hall_worlds_hold_what_the_robot_is_asked_for(halls: dict[int, WorldDescription]) -> None:
    for world in halls.values():
        size = np.subtract(world.hall.max_xy, world.hall.min_xy)
        assert 18.0 <= size[0] <= 22.0 and 13.0 <= size[1] <= 17.0
        classes = Counter(a.object_class for a in world.artifacts)
        assert classes["bottle"] >= 2 and 5 <= len(world.artifacts) <= 10
        assert 2 <= len(world.people) <= 5
        assert {"wall", "rack", "table"} <= {o.kind for o in world.obstacles}


def test_artifacts_stand_near_the_front_edge_of_a_table_or_bench_within_reach(
    halls: dict[int, WorldDescription],
) -> None:
    for world in list(halls.values())[:20]:
        surfaces = {s.id: s for s in world.surfaces}
        for a in world.artifacts:
            surface = surfaces[a.surface_id]
            assert 0.7 <= surface.top_height <= 0.95
            assert a.position[2] == pytest.approx(surface.top_height)
            _, depth = fz.surface_normal_towards(surface, a.position[:2])
            assert 0.05 - 1e-9 <= depth <= 0.20 + 1e-9
            if isinstance(a.shape, Cylinder):
                assert 2 * a.shape.radius <= (0.06 if a.object_class == "bottle" else 0.07)
            if a.object_class == "bottle":
                assert isinstance(a.shape, Cylinder) and 0.15 <= a.shape.height <= 0.25
                assert 0.2 <= a.mass <= 0.5 and 2 * a.shape.radius >= 0.04
            if isinstance(a.shape, Cuboid):
                assert 2 * min(a.shape.half_size[:2]) <= 0.07


def test_small_world_is_one_table_one_bottle_one_person_a_few_metres_away() -> None:
    for seed in range(10):
        world = generate_world(seed, "small")
        size = np.subtract(world.hall.max_xy, world.hall.min_xy)
        assert 7.0 <= size[0] <= 9.0 and 5.0 <= size[1] <= 7.0
        assert [o.kind for o in world.obstacles if o.kind != "wall"] == ["table"]
        assert [a.id for a in world.artifacts] == ["bottle_1"]
        assert [p.id for p in world.people] == ["person_1"]
        table = world.surfaces[0].centre_xy
        start = (world.robot_start.x, world.robot_start.y)
        assert 2.0 <= math.dist(start, table) <= 4.0
    assert _encode(generate_world(0, "small")) != _encode(generate_world(1, "small"))


def test_every_goal_is_free_and_reachable_for_100_seeds(halls: dict[int, WorldDescription]) -> None:
    for seed, world in halls.items():
        assert fz.check_paths(world) == [], seed


def test_people_stand_clear_of_obstacles_and_walk_at_most_1_2_m_per_s() -> None:
    for seed in range(10):
        world = generate_world(seed, walking_people=True)
        clearance = fz.clearance(world.occupancy)
        assert any(p.waypoints for p in world.people)
        for p in world.people:
            cell = fz.cell_of(world.occupancy, *p.position)
            assert cell is not None and clearance[cell] >= 1.0
            assert 0.0 < p.speed <= 1.2 if p.waypoints else p.speed == 0.0


def test_standoff_and_pick_poses_face_the_artifact_at_their_distances(
    halls: dict[int, WorldDescription],
) -> None:
    world = halls[1]
    for a in world.artifacts:
        for pose, distance in (
            (fz.standoff_pose(world, a.id), robot.STANDOFF_DISTANCE_M),
            (fz.pick_pose(world, a.id), robot.D_OPT_M),
        ):
            dx, dy = a.position[0] - pose.x, a.position[1] - pose.y
            assert math.hypot(dx, dy) == pytest.approx(distance)
            bearing = math.remainder(math.atan2(dy, dx) - pose.yaw, math.tau)
            assert bearing == pytest.approx(robot.THETA_OPT_RAD, abs=1e-9)


def test_occupancy_grid_marks_obstacles_and_leaves_the_aisles_free(
    halls: dict[int, WorldDescription],
) -> None:
    for world in list(halls.values())[:10]:
        grid = world.occupancy
        cells = as_numpy(grid.cells)
        assert cells.dtype == np.uint8 and set(np.unique(cells)) <= {0, OCCUPIED}
        for ob in world.obstacles:
            assert cells[fz.cell_of(grid, ob.centre[0], ob.centre[1])] == OCCUPIED, ob.id
        for p in world.people:
            assert cells[fz.cell_of(grid, *p.position)] == 0
        start = world.robot_start
        assert cells[fz.cell_of(grid, start.x, start.y)] == 0
        # Across the middle of each work surface's front (local +y; both sides of a table):
        # 3 cm inside the edge is occupied, 10 cm outside is free floor.
        obstacles = {o.id: o for o in world.obstacles}
        for s in world.surfaces:
            sides = (1.0, -1.0) if obstacles[s.id].kind == "table" else (1.0,)
            for side, off, value in (
                (sd, d, v) for sd in sides for d, v in ((-0.03, OCCUPIED), (0.10, 0))
            ):
                v_local = side * (s.half_extents[1] + off)
                x = s.centre_xy[0] - math.sin(s.yaw) * v_local
                y = s.centre_xy[1] + math.cos(s.yaw) * v_local
                assert cells[fz.cell_of(grid, x, y)] == value, (s.id, side, off)


def test_rasterized_box_covers_the_cells_it_overlaps_and_no_more() -> None:
    hall = Hall((0.0, 0.0), (2.0, 1.0), 3.0)
    box = Obstacle("machine_1", "machine", (1.0, 0.5, 0.5), (0.19, 0.09, 0.5), 0.0, (1, 1, 1, 1))
    grid = fz.rasterize(hall, (box,))
    cells = as_numpy(grid.cells)
    xs, ys = fz.cell_centres(grid)
    assert grid.resolution == 0.05 and grid.origin == pytest.approx((-0.5, -0.5))
    occupied_x = xs[np.any(cells == OCCUPIED, axis=0)]
    occupied_y = ys[np.any(cells == OCCUPIED, axis=1)]
    # The box spans [0.81, 1.19] x [0.41, 0.59]: it overlaps the 8 x 4 cells of [0.8, 1.2] x
    # [0.4, 0.6] and no other.
    assert occupied_x.min() == pytest.approx(0.825) and occupied_x.max() == pytest.approx(1.175)
    assert occupied_y.min() == pytest.approx(0.425) and occupied_y.max() == pytest.approx(0.575)
    assert int(np.count_nonzero(cells)) == 8 * 4


def _rest_model(world: WorldDescription) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = scene.compile_scene(world, with_robot=False)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def test_artifacts_rest_on_their_surfaces_after_half_a_second() -> None:
    for seed in range(5):
        world = generate_world(seed)
        model, data = _rest_model(world)
        start = {a.id: data.body(a.id).xpos.copy() for a in world.artifacts}
        for _ in range(round(0.5 / model.opt.timestep)):
            mujoco.mj_step(model, data)
        for a in world.artifacts:
            body = data.body(a.id)
            assert np.linalg.norm(body.xpos - start[a.id]) < 0.005, (seed, a.id)
            tilt = math.degrees(math.acos(min(1.0, body.xmat.reshape(3, 3)[2, 2])))
            assert tilt < 2.0, (seed, a.id)
            assert np.linalg.norm(data.qvel[model.joint(a.id).dofadr[0] :][:6]) < 0.01


def test_scene_with_the_robot_keeps_robot_names_and_a_640x480_buffer() -> None:
    world = generate_world(0, "small")
    model = scene.compile_scene(world)
    assert model.opt.timestep == 0.001
    assert model.vis.global_.offwidth >= 640 and model.vis.global_.offheight >= 480
    for name in ("camera_head", "camera_wrist"):
        assert model.camera(name).id >= 0
    assert model.site("gripper_tcp").id >= 0 and model.site("person_1_hand").id >= 0
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    root = data.qpos[mjcf.mj_indices(model).qpos[:2]]
    assert root == pytest.approx([world.robot_start.x, world.robot_start.y])


def test_segmentation_labels_map_geoms_to_instance_ids() -> None:
    world = generate_world(2)
    model = scene.compile_scene(world)
    table = scene.segmentation_ids(model, world)
    named = {name for name in table.labels.values()}
    assert {a.id for a in world.artifacts} <= named and {p.id for p in world.people} <= named
    assert table.geom_label[model.geom("floor").id] == scene.BACKGROUND_LABEL
    for a in world.artifacts:
        assert table.labels[int(table.geom_label[model.geom(a.id).id])] == a.id
    assert table.labels[int(table.geom_label[model.geom("gripper_jaw_fixed").id])] == "robot"
    from_model = scene.segmentation_ids(model)  # without the world: the model's own order
    assert set(from_model.labels.values()) == named
    by_name = {name: label for label, name in table.labels.items()}
    assert all(
        by_name[from_model.labels[int(k)]] == int(j)
        for k, j in zip(from_model.geom_label, table.geom_label, strict=True)
        if k
    )


def test_a_person_holds_an_object_once_the_grip_weld_is_active() -> None:
    world = generate_world(0, "small")
    model, data = _rest_model(world)
    person, bottle = world.people[0], world.artifacts[0]
    qpos = model.joint(bottle.id).qposadr[0]
    data.qpos[qpos : qpos + 3] = data.body(f"{person.id}_grip").xpos + np.array([0.03, 0.0, -0.05])
    mujoco.mj_forward(model, data)
    offset = data.body(bottle.id).xpos - data.body(f"{person.id}_grip").xpos
    scene.attach_to_grip(model, data, person.id, bottle.id)
    mocap = model.body(person.id).mocapid[0]
    for _ in range(1000):
        data.mocap_pos[mocap, 0] += 0.5 * model.opt.timestep  # walks at 0.5 m/s
        mujoco.mj_step(model, data)
    moved = data.body(bottle.id).xpos - data.body(f"{person.id}_grip").xpos
    assert np.linalg.norm(moved - offset) < 0.01


def test_every_artifact_is_half_visible_from_its_standoff_pose_5_seeds() -> None:
    for seed in range(5):
        world = generate_world(seed)
        fractions = visible_fractions(world)
        assert min(fractions.values()) >= MIN_VISIBLE_FRACTION, (seed, fractions)


def test_an_artifact_behind_a_screen_counts_as_hidden() -> None:
    world = generate_world(0, "small")
    bottle, surface = world.artifacts[0], world.surfaces[0]
    normal, _ = fz.surface_normal_towards(surface, bottle.position[:2])
    x, y = np.add(bottle.position[:2], 0.25 * normal)  # between the table's edge and the robot
    screen = Obstacle(
        "wall_99",
        "wall",
        (x, y, 0.8),
        (0.02, 0.4, 0.8),
        math.atan2(normal[1], normal[0]),
        (0.5, 0.5, 0.5, 1.0),
    )
    screened = msgspec.structs.replace(world, obstacles=(*world.obstacles, screen))
    assert visible_fractions(world)[bottle.id] >= MIN_VISIBLE_FRACTION
    assert visible_fractions(screened)[bottle.id] < 0.05
    assert check_visibility(screened) != []


@pytest.mark.slow
def test_every_world_is_feasible_with_rendering_for_100_seeds(
    halls: dict[int, WorldDescription],
) -> None:
    for seed, world in halls.items():
        assert check_world(world) == [], seed
