"""The robot's cameras: depth is geometry along the optical axis, frames agree with pinocchio,
segmentation names what it shows."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

from collections.abc import Iterator

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from common import robot
from common.geometry import inv_T, matrix_to_quat_xyzw, quat_xyzw_to_wxyz
from common.messages import as_numpy
from common.messages.sim import CameraFrame, SegmentationTruth
from services.sim import mjcf
from services.sim.cameras import CameraRig
from services.sim.core import SimCore
from services.sim.feasibility import standoff_pose
from services.sim.visibility import place_robot
from services.sim.world import generate_world

BOX_DISTANCE_M = 1.0  # from camera_head to the box's near face, along the optical axis
BOX_HALF_M = 0.25  # its face spans +-54 px about the image centre, its bottom clears the floor
BOX_RGBA = (0.9, 0.1, 0.1, 1.0)


def camera_pose(q: np.ndarray, frame: str) -> np.ndarray:
    """pinocchio's frame in the world (4x4) at configuration q."""
    model, _ = robot.load_pinocchio()
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return np.asarray(data.oMf[model.getFrameId(frame)].homogeneous)


@pytest.fixture(scope="module")
def box_scene() -> Iterator[tuple[mujoco.MjModel, mujoco.MjData, CameraRig]]:
    """The robot standing on a floor, a box square to camera_head's axis in front of it."""
    q = robot.standing_q("stand")
    T = camera_pose(q, "camera_head")
    spec = mjcf.robot_spec()
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[20, 20, 0.1])
    centre = T[:3, :3] @ [0.0, 0.0, BOX_DISTANCE_M + BOX_HALF_M] + T[:3, 3]
    body = spec.worldbody.add_body(
        name="box_1", pos=centre, quat=quat_xyzw_to_wxyz(matrix_to_quat_xyzw(T[:3, :3]))
    )
    body.add_geom(
        name="box_1", type=mujoco.mjtGeom.mjGEOM_BOX, size=[BOX_HALF_M] * 3, rgba=BOX_RGBA
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[:] = mjcf.q_pin_to_mj(q)
    mujoco.mj_forward(model, data)
    rig = CameraRig(model, 320, 240)
    yield model, data, rig
    rig.close()


def test_depth_is_the_distance_along_the_optical_axis_within_1cm(box_scene: tuple) -> None:
    _, data, rig = box_scene
    frame, _ = rig.capture(data, "camera_head", 0)
    depth = as_numpy(frame.depth)
    assert depth.dtype == np.float32 and depth.shape == (240, 320)
    v, u = int(frame.cy), int(frame.cx)  # cx, cy fall between pixels: the 2 x 2 around them
    assert depth[v : v + 2, u : u + 2].mean() == pytest.approx(BOX_DISTANCE_M, abs=0.01)
    # 48 px off-centre on the face the ray is 2.4 cm longer; the depth is not.
    off = depth[v, u + 48]
    ray = BOX_DISTANCE_M * np.hypot(1.0, (u + 48 - frame.cx) / frame.fx)
    assert off == pytest.approx(BOX_DISTANCE_M, abs=0.01) and ray - BOX_DISTANCE_M > 0.02
    # The top rows look above the horizon at the empty sky: no return is 0.
    assert np.all(depth[0] == 0.0)


def test_intrinsics_and_camera_frames_agree_with_pinocchio(box_scene: tuple) -> None:
    _, data, rig = box_scene
    q = robot.standing_q("stand")
    T_world_base = camera_pose(q, robot.BASE_FRAME)
    for camera in ("camera_head", "camera_wrist"):
        frame, _ = rig.capture(data, camera, 7)
        assert (frame.fx, frame.fy, frame.cx, frame.cy) == pytest.approx(
            robot.intrinsics(robot.CAMERA_MOUNTS[camera])
        )
        expected = inv_T(T_world_base) @ camera_pose(q, camera)
        T_base_camera = np.array(frame.T_base_camera).reshape(4, 4)
        np.testing.assert_allclose(T_base_camera, expected, atol=1e-6)
        np.testing.assert_allclose(rig.base_pose(data), T_world_base, atol=1e-6)
        assert frame.stamp_ns == 7 and frame.camera == camera
        assert rig.render_ms[camera] > 0.0


def test_segmentation_labels_the_box_and_rgb_shows_it(box_scene: tuple) -> None:
    _, data, rig = box_scene
    frame, truth = rig.capture(data, "camera_head", 0)
    labels = as_numpy(truth.labels)
    box = {name: label for label, name in truth.instances.items()}["box_1"]
    v, u = int(frame.cy), int(frame.cx)
    assert labels[v, u] == box and labels[0, 0] == 0
    # The near face projects to a square of side 2 f h / d pixels.
    side = 2 * frame.fx * BOX_HALF_M / BOX_DISTANCE_M
    assert np.count_nonzero(labels == box) == pytest.approx(side * side, rel=0.05)
    rgb = as_numpy(frame.rgb)
    assert rgb.dtype == np.uint8 and rgb.shape == (240, 320, 3) and rgb.std() > 10
    red = rgb[labels == box].astype(float).mean(axis=0)
    assert red[0] > 2 * red[1] and red[0] > 2 * red[2]


def test_the_wrist_camera_labels_the_bottle_at_its_standoff_pose() -> None:
    world = generate_world(0, "small")
    core = SimCore(world)
    model, data = core.model, core.data
    place_robot(model, data, *standoff_pose(world, "bottle_1"))
    rig = CameraRig(model, 320, 240, world=world)
    try:
        frame, truth = rig.capture(data, "camera_wrist", 0)
    finally:
        rig.close()
    assert isinstance(frame, CameraFrame) and isinstance(truth, SegmentationTruth)
    labels, depth = as_numpy(truth.labels), as_numpy(frame.depth)
    bottle = {name: label for label, name in truth.instances.items()}["bottle_1"]
    pixels = labels == bottle
    assert np.count_nonzero(pixels) > 100
    # Its nearest pixel is the nearest point of its surface along the optical axis.
    T_world_camera = rig.base_pose(data) @ np.array(frame.T_base_camera).reshape(4, 4)
    assert depth[pixels].min() == pytest.approx(
        nearest_depth(model, data, "bottle_1", inv_T(T_world_camera)), abs=0.01
    )


def nearest_depth(
    model: mujoco.MjModel, data: mujoco.MjData, body: str, T_camera_world: np.ndarray
) -> float:
    """The least optical-axis depth over a body's cylinders (sampled surfaces)."""
    best = np.inf
    angles = np.linspace(0.0, 2 * np.pi, 721)
    for g in np.flatnonzero(model.geom_bodyid == model.body(body).id):
        r, half = model.geom_size[g][:2]
        local = np.array(
            [
                [rho * np.cos(a), rho * np.sin(a), z]
                for z in np.linspace(-half, half, 41)
                for rho in ((r,) if abs(z) < half else np.linspace(0.0, r, 11))
                for a in angles
            ]
        )
        world = local @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
        best = min(best, float(np.min(world @ T_camera_world[2, :3] + T_camera_world[2, 3])))
    return best
