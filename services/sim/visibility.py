"""Can the wrist camera see each artifact from its standoff pose? And `check_world`.

The robot is put, kinematically, at an artifact's standoff pose in the `look` posture and
the wrist camera renders instance segmentation of the full scene. The visible fraction is
that artifact's pixel count over its pixel count when drawn alone (every other geom, the
robot's included, hidden) by the same camera with twice the image size and the same focal
length: the wide image contains the camera's image at its centre pixel for pixel, so the
parts of the artifact that fall outside the camera's frame count as hidden too. An
artifact passes at `MIN_VISIBLE_FRACTION`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import mujoco
import numpy as np

from common import robot
from common.messages.world import WorldDescription
from services.sim import mjcf, scene
from services.sim.feasibility import check_paths, standoff_pose

MIN_VISIBLE_FRACTION = 0.5
CAMERA = "camera_wrist"
POSTURE = "look"
_HIDDEN_GROUP = 5


def place_robot(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    x: float,
    y: float,
    yaw: float,
    posture: str = POSTURE,
) -> None:
    """Put the robot standing at (x, y, yaw) in a named posture and run the kinematics."""
    q_pin = robot.standing_q(posture, x, y, yaw)
    data.qpos[mjcf.mj_indices(model).qpos] = mjcf.q_pin_to_mj(q_pin)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)


@contextmanager
def _isolated(model: mujoco.MjModel, geoms: np.ndarray, camera: int) -> Iterator[mujoco.MjvOption]:
    """Only `geoms` drawn, the camera's tan(fovy/2) doubled; the model restored after."""
    groups, fovy = model.geom_group.copy(), float(model.cam_fovy[camera])
    option = mujoco.MjvOption()
    option.geomgroup[:] = 1
    option.geomgroup[_HIDDEN_GROUP] = 0
    try:
        model.geom_group[:] = _HIDDEN_GROUP
        model.geom_group[geoms] = 0
        half = math.radians(0.5 * fovy)
        model.cam_fovy[camera] = math.degrees(2.0 * math.atan(2.0 * math.tan(half)))
        yield option
    finally:
        model.geom_group[:] = groups
        model.cam_fovy[camera] = fovy


def visible_fractions(
    world: WorldDescription, model: mujoco.MjModel | None = None
) -> dict[str, float]:
    """Each artifact's visible fraction in the wrist camera from its standoff pose."""
    model = model if model is not None else scene.compile_scene(world, with_robot=True)
    data = mujoco.MjData(model)
    camera = model.camera(CAMERA).id
    width, height = (int(v) for v in model.cam_resolution[camera])
    table = scene.segmentation_ids(model, world)
    label_of = {name: label for label, name in table.labels.items()}
    fractions: dict[str, float] = {}
    with (
        mujoco.Renderer(model, height, width) as view,
        mujoco.Renderer(model, 2 * height, 2 * width) as wide,
    ):
        view.enable_segmentation_rendering()
        wide.enable_segmentation_rendering()
        for artifact in world.artifacts:
            label = label_of[artifact.id]
            place_robot(model, data, *standoff_pose(world, artifact.id))
            view.update_scene(data, camera=camera)
            seen = int(np.count_nonzero(scene.label_image(view.render(), table) == label))
            with _isolated(model, np.flatnonzero(table.geom_label == label), camera) as option:
                wide.update_scene(data, camera=camera, scene_option=option)
                alone = int(np.count_nonzero(scene.label_image(wide.render(), table) == label))
            fractions[artifact.id] = seen / alone if alone else 0.0
    return fractions


def check_visibility(world: WorldDescription, model: mujoco.MjModel | None = None) -> list[str]:
    """Artifacts less than `MIN_VISIBLE_FRACTION` visible from their standoff pose."""
    return [
        f"{aid} is {fraction:.0%} visible to {CAMERA} from its standoff pose in {POSTURE!r}"
        for aid, fraction in visible_fractions(world, model).items()
        if fraction < MIN_VISIBLE_FRACTION
    ]


def check_world(world: WorldDescription) -> list[str]:
    """Every problem that makes a world infeasible: paths and goal poses, then visibility."""
    return check_paths(world) + check_visibility(world)
