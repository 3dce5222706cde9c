"""Labelled RGB-D frames for training a segmenter: seeded worlds, both cameras, `.npz` shards.

`render_seed(seed)` builds the hall world of a seed, puts the robot kinematically at poses
drawn from its own generator (seeded by the world seed, so a seed always gives the same
frames) and captures `CameraRig` frames; `write_dataset(seeds, folder)` writes one
compressed shard per seed. Domain randomization: the world seed varies furniture, object
colours, sizes, poses and the lights (`services.sim.appearance`); here the robot's pose
varies across the hall and its posture is jittered (base height, pitch and roll, arm
joints), which moves the cameras' height and tilt. Frames per seed:
- wrist camera in `look` from near the artifacts' standoff poses (distance between `D_OPT_M`
  and a little beyond `STANDOFF_DISTANCE_M`, heading jittered): tables with objects close up;
- head camera from free poses facing a person (1.2-7 m away), an artifact, or anywhere;
- wrist camera in a random posture facing a person (what a handover sees);
- artifacts from 1.5-3 m, the wrist camera held up as the mapping patrol holds it or the
  head camera, those on benches twice as often, and furniture edges with no artifact near
  as negatives (`services.sim.dataset_shots`: drawn from a generator of their own, so the
  frames above are the same as before they were added).

`render_seed(seed, plan="heldout")` renders the confusion report's views instead
(`dataset_shots.plan_heldout_shots`), from another stream of the seed. A shard records its
plan and version (`PLANS`): `write_dataset` renders again a shard of another one.

A shard holds `rgb` (N, H, W, 3) uint8, `depth_mm` (N, H, W) uint16 (0 = no return),
`labels` (N, H, W) uint16 instance labels, `label_ids`/`label_names` (the world's label →
truth id, `bottle_1`, `person_2`, `table_1`, `robot`), `camera` (N,), `intrinsics` (N, 4)
fx fy cx cy, `T_base_camera` and `T_world_base` (N, 4, 4), `seed`, `world` and `plan`. It
knows nothing of classes: a trainer maps ids to its classes.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from common import robot
from common.geometry import matrix_to_quat_xyzw, rot_x, rot_y, rot_z
from common.messages.arrays import as_numpy
from common.messages.world import WorldDescription
from services.sim import dataset_shots as shots_
from services.sim import feasibility as fz
from services.sim import mjcf, scene
from services.sim.cameras import CameraRig
from services.sim.dataset_shots import Floor, Shot, facing
from services.sim.world import generate_world

log = logging.getLogger(__name__)

WIDTH, HEIGHT = 320, 240
#: Frames of each kind per seed (artifacts repeat when a world has fewer).
WRIST_ARTIFACT_FRAMES = 8
HEAD_FRAMES = 9
WRIST_PERSON_FRAMES = 3
#: Posture jitter: base height (m), pitch and roll (rad), arm joints (rad).
HEIGHT_JITTER_M = 0.04
PITCH_JITTER_RAD = 0.08
ROLL_JITTER_RAD = 0.04
ARM_JITTER_RAD = 0.08
_ARM = slice(7 + 12, 7 + 18)  # the arm's joints in pinocchio's q


class Frame(NamedTuple):
    """One capture: images, labels and the camera's geometry."""

    camera: str
    rgb: NDArray[np.uint8]
    depth_mm: NDArray[np.uint16]
    labels: NDArray[np.uint16]
    intrinsics: tuple[float, float, float, float]
    T_base_camera: NDArray[np.float64]
    T_world_base: NDArray[np.float64]


def _jittered_q(shot: Shot, rng: np.random.Generator) -> NDArray[np.float64]:
    """Pinocchio q of the shot's pose and posture, with height, tilt and arm jitter."""
    q = np.array(robot.standing_q(shot.posture, shot.x, shot.y, shot.yaw), dtype=float)
    q[2] += rng.uniform(-HEIGHT_JITTER_M, HEIGHT_JITTER_M)
    pitch = rng.uniform(-PITCH_JITTER_RAD, PITCH_JITTER_RAD)
    roll = rng.uniform(-ROLL_JITTER_RAD, ROLL_JITTER_RAD)
    q[3:7] = matrix_to_quat_xyzw(rot_z(shot.yaw) @ rot_y(pitch) @ rot_x(roll))
    q[_ARM] += rng.uniform(-ARM_JITTER_RAD, ARM_JITTER_RAD, 6)
    q[_ARM] = np.clip(q[_ARM], robot.POSITION_LOWER[12:18], robot.POSITION_UPPER[12:18])
    return q


def plan_shots(world: WorldDescription, rng: np.random.Generator) -> list[Shot]:
    """The seed's camera placements (see the module docstring)."""
    shots: list[Shot] = []
    surfaces = {s.id: s for s in world.surfaces}
    floor = Floor(world, rng)
    order = np.resize(rng.permutation(len(world.artifacts)), WRIST_ARTIFACT_FRAMES)
    for index in order.tolist():
        artifact = world.artifacts[index]
        distance = float(rng.uniform(robot.D_OPT_M, robot.STANDOFF_DISTANCE_M + 0.15))
        heading = robot.THETA_OPT_RAD + float(rng.uniform(-0.3, 0.3))
        pose = fz.standoff_pose_for(artifact, surfaces[artifact.surface_id], distance, heading)
        shots.append(Shot("camera_wrist", pose.x, pose.y, pose.yaw, "look"))
    for k in range(HEAD_FRAMES):
        target: tuple[float, float] | None = None
        if k % 3 != 2 and world.people:
            target = world.people[int(rng.integers(len(world.people)))].position
            x, y = floor.point(0.5, target, (1.2, 7.0))
        elif k % 2 == 0:
            a = world.artifacts[int(rng.integers(len(world.artifacts)))]
            target = (a.position[0], a.position[1])
            x, y = floor.point(0.5, target, (1.0, 4.0))
        else:
            x, y = floor.point(0.5)
        yaw = facing(x, y, target, rng) if target else float(rng.uniform(-math.pi, math.pi))
        posture = ("stand", "stow", "look")[int(rng.integers(3))]
        shots.append(Shot("camera_head", x, y, yaw, posture))
    for _ in range(WRIST_PERSON_FRAMES if world.people else 0):
        person = world.people[int(rng.integers(len(world.people)))]
        x, y = floor.point(0.4, person.position, (1.0, 4.0))
        posture = ("look", "ready", "handover")[int(rng.integers(3))]
        shots.append(Shot("camera_wrist", x, y, facing(x, y, person.position, rng), posture))
    more = np.random.default_rng([world.seed, 0xD05E, 2])  # the frames above stay as they were
    shots += shots_.far_shots(world, more, shots_.FAR_FRAMES)
    return shots + shots_.edge_shots(world, more, shots_.EDGE_FRAMES)


#: The plans a shard can be rendered with: (plan, its generator's stream of the seed,
#: its version, stored in the shard; a shard of another version is rendered again).
PLANS: dict[str, tuple[Callable[[WorldDescription, np.random.Generator], list[Shot]], int, int]] = {
    "train": (plan_shots, 0xD05E, 2),
    "heldout": (shots_.plan_heldout_shots, 0xC0F5, 1),
}


def plan_tag(plan: str) -> str:
    """What a shard of `plan` records: `train-2`."""
    return f"{plan}-{PLANS[plan][2]}"


def render_seed(
    seed: int, world_name: str = "hall", plan: str = "train"
) -> tuple[dict[int, str], list[Frame]]:
    """Label → truth id of the world of `seed`, and its frames of `plan` (`PLANS`;
    deterministic per seed)."""
    world = generate_world(seed, world_name)
    planner, stream, _ = PLANS[plan]
    rng = np.random.default_rng([seed, stream])
    model = scene.compile_scene(world, with_robot=True)
    data = mujoco.MjData(model)
    qpos = mjcf.mj_indices(model).qpos
    rig = CameraRig(model, WIDTH, HEIGHT, world)
    instances = dict(rig.instances)
    frames: list[Frame] = []
    try:
        for shot in planner(world, rng):
            data.qpos[qpos] = mjcf.q_pin_to_mj(_jittered_q(shot, rng))
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            frame, truth = rig.capture(data, shot.camera, 0)
            depth = np.asarray(as_numpy(frame.depth), dtype=np.float64)
            frames.append(
                Frame(
                    camera=shot.camera,
                    rgb=np.array(as_numpy(frame.rgb), dtype=np.uint8),
                    depth_mm=np.clip(np.round(depth * 1e3), 0, 65535).astype(np.uint16),
                    labels=np.asarray(as_numpy(truth.labels)).astype(np.uint16),
                    intrinsics=(frame.fx, frame.fy, frame.cx, frame.cy),
                    T_base_camera=np.array(frame.T_base_camera, dtype=float).reshape(4, 4),
                    T_world_base=rig.base_pose(data),
                )
            )
    finally:
        rig.close()
    return instances, frames


def shard_path(folder: Path, seed: int) -> Path:
    """Where the shard of `seed` lives in `folder`."""
    return folder / f"seed_{seed:05d}.npz"


def save_shard(
    path: Path,
    seed: int,
    world: str,
    instances: dict[int, str],
    frames: list[Frame],
    plan: str = "train",
) -> None:
    """Write `frames` as one compressed shard (atomically: a partial file never remains)."""
    if not frames:
        raise ValueError(f"seed {seed}: no frames to write")
    ids = sorted(instances)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(
        tmp,
        rgb=np.stack([f.rgb for f in frames]),
        depth_mm=np.stack([f.depth_mm for f in frames]),
        labels=np.stack([f.labels for f in frames]),
        label_ids=np.array(ids, dtype=np.int32),
        label_names=np.array([instances[k] for k in ids]),
        camera=np.array([f.camera for f in frames]),
        intrinsics=np.array([f.intrinsics for f in frames], dtype=np.float64),
        T_base_camera=np.stack([f.T_base_camera for f in frames]),
        T_world_base=np.stack([f.T_world_base for f in frames]),
        seed=np.int64(seed),
        world=np.array(world),
        plan=np.array(plan_tag(plan)),
    )
    tmp.replace(path)


def shard_plan(path: Path) -> str:
    """The plan and version a shard was rendered with (`train-1`: before shards said)."""
    with np.load(path) as shard:
        return str(shard["plan"]) if "plan" in shard.files else "train-1"


def write_dataset(
    seeds: Iterable[int],
    folder: Path,
    world_name: str = "hall",
    overwrite: bool = False,
    plan: str = "train",
) -> Iterator[Path]:
    """Render and save each seed's shard of `plan` into `folder`; yields the paths
    (existing shards of the plan's version are kept unless `overwrite`, so an interrupted
    run resumes)."""
    folder.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        path = shard_path(folder, seed)
        if path.exists() and not overwrite and shard_plan(path) == plan_tag(plan):
            yield path
            continue
        instances, frames = render_seed(seed, world_name, plan)
        save_shard(path, seed, world_name, instances, frames, plan)
        log.info("seed %d: %d frames of %s -> %s", seed, len(frames), plan, path.name)
        yield path
