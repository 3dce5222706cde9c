"""The dataset's added views: artifacts from afar and furniture edges after the first
kinds of frames (which stay as they were), the held-out plan, and shards that say their
plan."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from common.messages.world import Obstacle, WorldDescription
from services.sim import dataset, dataset_shots
from services.sim.world import generate_world

SEED = 5


@pytest.fixture(scope="module")
def world() -> WorldDescription:
    return generate_world(SEED, "hall")


def _plan(
    world: WorldDescription, far: int, edges: int, monkeypatch: pytest.MonkeyPatch
) -> list[dataset_shots.Shot]:
    monkeypatch.setattr(dataset_shots, "FAR_FRAMES", far)
    monkeypatch.setattr(dataset_shots, "EDGE_FRAMES", edges)
    return dataset.plan_shots(world, np.random.default_rng([SEED, 0xD05E]))


def test_the_added_views_leave_the_first_ones_as_they_were(
    world: WorldDescription, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = _plan(world, 0, 0, monkeypatch)
    full = _plan(world, 6, 4, monkeypatch)
    assert len(full) == len(first) + 10
    assert full[: len(first)] == first


def test_far_views_face_an_artifact_from_one_and_a_half_to_three_metres(
    world: WorldDescription, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = _plan(world, 0, 0, monkeypatch)
    far = _plan(world, 40, 0, monkeypatch)[len(first) :]
    lo, hi = dataset_shots.FAR_RING_M
    for shot in far:
        seen = [
            a
            for a in world.artifacts
            if lo - 0.1 <= math.dist((shot.x, shot.y), a.position[:2]) <= hi + 0.1
            and abs(_bearing(shot, a.position[:2])) <= 0.36
        ]
        assert seen, shot
    assert {s.camera for s in far} == {"camera_wrist", "camera_head"}
    assert all(s.posture == "look" for s in far if s.camera == "camera_wrist")


def test_edge_points_lie_on_furniture_edges_away_from_every_artifact(
    world: WorldDescription,
) -> None:
    rng = np.random.default_rng(0)
    furniture = [o for o in world.obstacles if o.kind in dataset_shots.EDGE_KINDS]
    for _ in range(30):
        point = dataset_shots.edge_point(world, rng)
        assert point is not None
        assert all(
            math.dist(point, a.position[:2]) >= dataset_shots.EDGE_CLEAR_M for a in world.artifacts
        )
        assert any(_on_boundary(point, o) for o in furniture), point


def test_the_held_out_plan_sees_each_artifact_near_middle_and_far(
    world: WorldDescription,
) -> None:
    shots = dataset_shots.plan_heldout_shots(world, np.random.default_rng([SEED, 1]))
    again = dataset_shots.plan_heldout_shots(world, np.random.default_rng([SEED, 1]))
    assert shots == again
    per_artifact = 1 + 2 * len(dataset_shots.HELDOUT_RINGS_M)
    people = 2 * len(world.people)
    assert len(world.artifacts) * per_artifact + people <= len(shots)
    assert len(shots) <= len(world.artifacts) * per_artifact + people + 6


def test_a_shard_of_another_plan_is_rendered_again(tmp_path: Path) -> None:
    path = dataset.shard_path(tmp_path, 3)
    np.savez(path, seed=np.int64(3))  # a shard from before shards said their plan
    assert dataset.shard_plan(path) == "train-1"
    [written] = dataset.write_dataset([3], tmp_path, "small")
    assert dataset.shard_plan(written) == dataset.plan_tag("train") == "train-2"
    stamp = written.stat().st_mtime_ns
    list(dataset.write_dataset([3], tmp_path, "small"))
    assert written.stat().st_mtime_ns == stamp  # kept
    [heldout] = dataset.write_dataset([3], tmp_path / "heldout", "small", plan="heldout")
    assert dataset.shard_plan(heldout) == "heldout-1"


def _bearing(shot: dataset_shots.Shot, xy: tuple[float, ...]) -> float:
    d = math.atan2(xy[1] - shot.y, xy[0] - shot.x) - shot.yaw
    return math.atan2(math.sin(d), math.cos(d))


def _on_boundary(point: tuple[float, float], o: Obstacle) -> bool:
    c, s = math.cos(o.yaw), math.sin(o.yaw)
    dx, dy = point[0] - o.centre[0], point[1] - o.centre[1]
    u, v = c * dx + s * dy, -s * dx + c * dy
    hx, hy = o.half_size[0], o.half_size[1]
    inside = abs(u) <= hx + 1e-9 and abs(v) <= hy + 1e-9
    return inside and (
        math.isclose(abs(u), hx, abs_tol=1e-9) or math.isclose(abs(v), hy, abs_tol=1e-9)
    )
