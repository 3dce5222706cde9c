"""The robot description: pinocchio and MuJoCo agree, the maps are right, postures are safe."""

from __future__ import annotations

import math
import os
import subprocess
import sys

os.environ.setdefault("MUJOCO_GL", "egl")  # offscreen rendering, before mujoco is imported

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from common import robot
from common.geometry import (
    make_T,
    matrix_to_quat_xyzw,
    quat_wxyz_to_xyzw,
    quat_xyzw_to_matrix,
    quat_xyzw_to_wxyz,
    rot_x,
    rot_y,
    rot_z,
)
from common.robot_description import (
    GRIPPER_BOXES,
    MOVER_LINK,
    STATOR_LINK,
    gripper_stl_path,
    read_stl,
)
from services.mission.grasp_pose import (
    SIDE_GRASP_DEPTH,
    TOP_GRASP_OFFSET_M,
    GraspParams,
    cylinder_offset,
)
from services.sim import mjcf

PinModels = tuple[pin.Model, pin.GeometryModel]
MjRobot = tuple[mujoco.MjModel, mujoco.MjData]
MjWorld = tuple[mujoco.MjModel, mujoco.MjData, mjcf.MjRobotIndices]

N_RANDOM = 20
OPTICAL_FROM_MJ_CAMERA = np.diag([1.0, -1.0, -1.0])


@pytest.fixture(scope="module")
def pin_model() -> PinModels:
    return robot.load_pinocchio()


@pytest.fixture(scope="module")
def mj_robot() -> MjRobot:
    model = mjcf.robot_spec().compile()
    return model, mujoco.MjData(model)


@pytest.fixture(scope="module")
def mj_world() -> MjWorld:
    """The robot attached into a world with a floor and a mocap bottle, as the sim does."""
    world = mujoco.MjSpec()
    mjcf.set_sim_options(world)
    world.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1])
    bottle = world.worldbody.add_body(name="bottle", mocap=True, pos=[5, 5, 5])
    bottle.add_geom(name="bottle", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.03, 0.1])
    world.attach(mjcf.robot_spec(), prefix="b1/", frame=world.worldbody.add_frame())
    model = world.compile()
    return model, mujoco.MjData(model), mjcf.mj_indices(model, prefix="b1/")


def random_q(model: pin.Model, rng: np.random.Generator) -> np.ndarray:
    quat = rng.normal(size=4)
    joints = rng.uniform(robot.POSITION_LOWER, robot.POSITION_UPPER)
    return np.concatenate([rng.uniform(-2, 2, 3), quat / np.linalg.norm(quat), joints])


def set_mj(
    model: mujoco.MjModel, data: mujoco.MjData, q: np.ndarray, v: np.ndarray | None = None
) -> None:
    data.qpos[:] = mjcf.q_pin_to_mj(q)
    data.qvel[:] = 0.0 if v is None else mjcf.v_pin_to_mj(v, q)
    mujoco.mj_forward(model, data)


def test_joint_order_is_pinocchios_model_order(pin_model: PinModels) -> None:
    model, _ = pin_model
    assert (model.nq, model.nv) == (26, 25)
    assert tuple(model.names[2:]) == robot.JOINT_NAMES
    assert (*robot.LEG_JOINTS, *robot.ARM_JOINTS, robot.GRIPPER_JOINT) == robot.JOINT_NAMES
    assert all(
        model.existFrame(f) for f in (*robot.FOOT_FRAMES, robot.TCP_FRAME, *robot.CAMERA_MOUNTS)
    )


def test_mujoco_orders_legs_differently_and_maps_by_name(mj_robot: MjRobot) -> None:
    model, _ = mj_robot
    mj_names = mjcf.mj_joint_names()
    assert tuple(model.joint(i).name for i in range(1, model.njnt)) == mj_names
    assert mj_names[:3] == ("FR_hip_joint", "FR_thigh_joint", "FR_calf_joint")
    assert mj_names != robot.JOINT_NAMES and sorted(mj_names) == sorted(robot.JOINT_NAMES)
    q = random_q(robot.load_pinocchio()[0], np.random.default_rng(0))
    qpos = mjcf.q_pin_to_mj(q)
    for i, name in enumerate(mj_names):
        assert qpos[7 + i] == q[7 + robot.JOINT_NAMES.index(name)]
    np.testing.assert_array_equal(mjcf.q_mj_to_pin(qpos), q)
    np.testing.assert_array_equal(qpos[3:7], quat_xyzw_to_wxyz(q[3:7]))


def test_actuators_are_motors_in_joint_order_clipped_at_urdf_effort(mj_robot: MjRobot) -> None:
    model, _ = mj_robot
    ctrl = mjcf.mj_indices(model).ctrl
    for k, name in enumerate(robot.JOINT_NAMES):
        act = model.actuator(int(ctrl[k]))
        assert act.name == name and model.joint(int(act.trnid[0])).name == name
        np.testing.assert_allclose(act.ctrlrange, [-robot.TORQUE_LIMITS[k], robot.TORQUE_LIMITS[k]])
    assert robot.TORQUE_LIMITS[robot.JOINT_NAMES.index("FL_calf_joint")] == 140.0
    # A torque vector in JOINT_NAMES order lands on the right joints, clipped at the limits.
    data = mujoco.MjData(model)
    tau = np.linspace(-1.5, 1.5, 19) * robot.TORQUE_LIMITS
    data.ctrl[ctrl] = tau
    mujoco.mj_forward(model, data)
    applied = mjcf.joints_mj_to_pin(data.qfrc_actuator[6:])
    np.testing.assert_allclose(applied, np.clip(tau, -robot.TORQUE_LIMITS, robot.TORQUE_LIMITS))


def test_total_mass_agrees(pin_model: PinModels, mj_robot: MjRobot) -> None:
    model, _ = mj_robot
    total_pin = pin.computeTotalMass(pin_model[0])
    assert total_pin == pytest.approx(60.91, abs=0.01)
    assert model.body_subtreemass[1] == pytest.approx(total_pin, abs=1e-9)


def test_mass_matrix_and_bias_forces_agree_through_the_maps(
    pin_model: PinModels, mj_robot: MjRobot
) -> None:
    """Per-body masses, COMs, inertias and armature agree: M and h match, not just the sum."""
    pmodel, _ = pin_model
    pdata = pmodel.createData()
    model, data = mj_robot
    rng = np.random.default_rng(1)
    perm = np.array([robot.JOINT_NAMES.index(n) for n in mjcf.mj_joint_names()])
    for _ in range(5):
        q, v = random_q(pmodel, rng), rng.normal(size=25)
        set_mj(model, data, q, v)
        # qvel_mj = T v_pin: world linear velocity = R v_local; joints permuted.
        T = np.zeros((25, 25))
        T[:3, :3] = quat_xyzw_to_matrix(q[3:7])
        T[3:6, 3:6] = np.eye(3)
        T[6 + np.arange(19), 6 + perm] = 1.0
        M_mj = np.zeros((25, 25))
        mujoco.mj_fullM(model, data, M_mj)
        np.testing.assert_allclose(T.T @ M_mj @ T, pin.crba(pmodel, pdata, q), atol=1e-9)
        # d/dt(R v_local) = R (dv_local + omega x v_local): that term moves into the bias.
        extra = np.zeros(25)
        extra[:3] = T[:3, :3] @ np.cross(v[3:6], v[:3])
        bias_pin = pin.rnea(pmodel, pdata, q, v, np.zeros(25))
        np.testing.assert_allclose(T.T @ (M_mj @ extra + data.qfrc_bias), bias_pin, atol=1e-8)


def test_forward_kinematics_agree_for_feet_tcp_and_cameras(
    pin_model: PinModels, mj_robot: MjRobot
) -> None:
    pmodel, _ = pin_model
    pdata = pmodel.createData()
    model, data = mj_robot
    rng = np.random.default_rng(2)
    for _ in range(N_RANDOM):
        q = random_q(pmodel, rng)
        set_mj(model, data, q)
        pin.framesForwardKinematics(pmodel, pdata, q)
        for name in (*robot.FOOT_FRAMES, robot.TCP_FRAME):
            oMf = pdata.oMf[pmodel.getFrameId(name)]
            np.testing.assert_allclose(data.site(name).xpos, oMf.translation, atol=1e-6)
            np.testing.assert_allclose(data.site(name).xmat.reshape(3, 3), oMf.rotation, atol=1e-6)
        for name in robot.CAMERA_MOUNTS:
            oMf = pdata.oMf[pmodel.getFrameId(name)]
            np.testing.assert_allclose(data.cam(name).xpos, oMf.translation, atol=1e-6)
            R_optical = data.cam(name).xmat.reshape(3, 3) @ OPTICAL_FROM_MJ_CAMERA
            np.testing.assert_allclose(R_optical, oMf.rotation, atol=1e-6)


def test_velocity_maps_give_the_same_frame_velocities(
    pin_model: PinModels, mj_robot: MjRobot
) -> None:
    pmodel, _ = pin_model
    pdata = pmodel.createData()
    model, data = mj_robot
    rng = np.random.default_rng(3)
    vel = np.zeros(6)
    for _ in range(N_RANDOM):
        q, v = random_q(pmodel, rng), rng.normal(size=25)
        set_mj(model, data, q, v)
        np.testing.assert_allclose(mjcf.v_mj_to_pin(data.qvel, data.qpos), v, atol=1e-12)
        pin.forwardKinematics(pmodel, pdata, q, v)
        pin.updateFramePlacements(pmodel, pdata)
        for name in (robot.TCP_FRAME, *robot.FOOT_FRAMES):
            site = model.site(name).id
            mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, site, vel, 0)
            twist = pin.getFrameVelocity(
                pmodel, pdata, pmodel.getFrameId(name), pin.LOCAL_WORLD_ALIGNED
            )
            np.testing.assert_allclose(vel[3:], twist.linear, atol=1e-6)
            np.testing.assert_allclose(vel[:3], twist.angular, atol=1e-6)
        # The free joint: MuJoCo's qvel is [linear in world, angular in base].
        mujoco.mj_objectVelocity(
            model, data, mujoco.mjtObj.mjOBJ_BODY, model.body("base").id, vel, 1
        )
        np.testing.assert_allclose(np.r_[vel[3:], vel[:3]], v[:6], atol=1e-9)


def test_attached_into_a_world_the_indices_find_the_robot(
    mj_world: MjWorld, pin_model: PinModels
) -> None:
    model, data, idx = mj_world
    pmodel, _ = pin_model
    pdata = pmodel.createData()
    q = robot.standing_q("look", x=1.0, y=-2.0, yaw=0.7)
    data.qpos[idx.qpos] = mjcf.q_pin_to_mj(q)
    mujoco.mj_forward(model, data)
    np.testing.assert_array_equal(mjcf.q_mj_to_pin(data.qpos[idx.qpos]), q)
    pin.framesForwardKinematics(pmodel, pdata, q)
    np.testing.assert_allclose(
        data.site("b1/gripper_tcp").xpos,
        pdata.oMf[pmodel.getFrameId(robot.TCP_FRAME)].translation,
        atol=1e-9,
    )
    assert [model.actuator(int(i)).name for i in idx.ctrl] == [f"b1/{n}" for n in robot.JOINT_NAMES]


def non_foot_contacts(model: mujoco.MjModel, data: mujoco.MjData) -> list[tuple[str, str]]:
    feet = {f"b1/{f}_0" for f in robot.FOOT_FRAMES}
    pairs = [
        (model.geom(c.geom1).name, model.geom(c.geom2).name) for c in data.contact[: data.ncon]
    ]
    return [p for p in pairs if not (set(p) & feet and "floor" in p)]


@pytest.mark.parametrize("posture", sorted(robot.POSTURES))
def test_posture_has_no_self_contact_and_stands_on_its_feet(
    posture: str, mj_world: MjWorld, pin_model: PinModels
) -> None:
    model, data, idx = mj_world
    q = robot.standing_q(posture)
    data.qpos[idx.qpos] = mjcf.q_pin_to_mj(q)
    mujoco.mj_forward(model, data)
    assert non_foot_contacts(model, data) == []
    feet = [c for c in data.contact[: data.ncon] if "floor" in model.geom(c.geom1).name]
    assert len(feet) == 4 and all(abs(c.dist) < 1e-9 for c in feet)
    # pinocchio's collision model (same boxes, same pairs) agrees.
    pmodel, geom = pin_model
    gdata = geom.createData()
    assert not pin.computeCollisions(pmodel, pmodel.createData(), geom, gdata, q, False)


def test_pinocchio_checks_every_pair_mujoco_checks(pin_model: PinModels) -> None:
    model = mjcf.robot_spec().compile()
    data = mujoco.MjData(model)
    model.geom_margin[:] = 5.0  # every pair MuJoCo does not filter out reports a contact
    data.qpos[:] = mjcf.q_pin_to_mj(robot.standing_q("stand"))
    mujoco.mj_forward(model, data)
    names = [
        tuple(sorted((model.geom(c.geom1).name, model.geom(c.geom2).name)))
        for c in data.contact[: data.ncon]
    ]
    _, geom = pin_model
    pin_pairs = {
        tuple(sorted((geom.geometryObjects[p.first].name, geom.geometryObjects[p.second].name)))
        for p in geom.collisionPairs
    }
    assert len(set(names)) > 100
    assert set(names) <= pin_pairs
    # ...and neither checks the SRDF's disabled pairs nor parent-child bodies.
    assert ("FL_hip_0", "trunk_0") not in pin_pairs and ("FL_calf_0", "FL_foot_0") not in pin_pairs


def test_postures_are_within_joint_limits() -> None:
    for name, joints in robot.POSTURES.items():
        assert joints.shape == (19,), name
        assert np.all(joints >= robot.POSITION_LOWER) and np.all(joints <= robot.POSITION_UPPER)
    assert pytest.approx(0.5277, abs=1e-3) == robot.STAND_BASE_HEIGHT_M


def jaw_clearance(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    name: str,
    jaw: float,
    at_tcp: tuple[float, float, float],
    R_rel: np.ndarray,
    prefix: str = "",
) -> dict[str, float]:
    """Distance (m) from the mocap object `name`, at `at_tcp` in the TCP's frame turned by
    `R_rel` from it, to each gripper geom and the wrist, the arm in `ready`, the jaw at
    `jaw` (`prefix`: the robot's names in a world that has one)."""
    q = robot.standing_q("ready")
    q[7 + robot.JOINT_NAMES.index(robot.GRIPPER_JOINT)] = jaw
    data.qpos[mjcf.mj_indices(model, prefix).qpos] = mjcf.q_pin_to_mj(q)
    mujoco.mj_forward(model, data)
    tcp = data.site(prefix + robot.TCP_FRAME)
    R = tcp.xmat.reshape(3, 3)
    data.mocap_pos[0] = tcp.xpos + R @ np.array(at_tcp)
    data.mocap_quat[0] = quat_xyzw_to_wxyz(matrix_to_quat_xyzw(R @ R_rel))
    mujoco.mj_forward(model, data)
    g = model.geom(name).id
    names = [b.name for b in GRIPPER_BOXES] + ["link06_0"]
    return {
        n: mujoco.mj_geomDistance(model, data, g, model.geom(prefix + n).id, 0.2, None)
        for n in names
    }


def jaw_distances(
    model: mujoco.MjModel, data: mujoco.MjData, gripper: float, depth_m: float = 0.0
) -> dict[str, float]:
    """Distance from a 6 cm bottle, centred on gripper_tcp along its y (`depth_m` deeper
    along its x), to each gripper geom."""
    up = rot_x(-math.pi / 2)  # the bottle's z along the TCP's y
    return jaw_clearance(model, data, "bottle", gripper, (-depth_m, 0.0, 0.0), up, "b1/")


def test_a_6cm_bottle_fits_between_the_open_jaws_and_the_closed_jaws_hit_it(
    mj_world: MjWorld,
) -> None:
    model, data, _ = mj_world
    opened = jaw_distances(model, data, robot.GRIPPER_OPEN)
    assert min(opened.values()) > 0.003, opened
    assert opened["gripper_jaw_fixed"] < 0.01  # it sits right on the fixed pad
    # held as deep as a side grasp holds a bottle, it still passes the open jaw
    deeper = jaw_distances(model, data, robot.GRIPPER_OPEN, SIDE_GRASP_DEPTH["bottle"])
    assert min(deeper.values()) > 0.003, deeper
    closed = jaw_distances(model, data, robot.GRIPPER_CLOSED)
    assert closed["gripper_jaw_moving"] < 0.0, closed


def object_in_jaws(
    name: str, type_: mujoco.mjtGeom, size: list[float]
) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The robot standing and a mocap body holding one geom `name`, to place in its jaws
    (`jaw_clearance`)."""
    spec = mjcf.robot_spec()
    spec.body("base").pos = [0.0, 0.0, robot.STAND_BASE_HEIGHT_M]
    spec.worldbody.add_body(name=name, mocap=True).add_geom(name=name, type=type_, size=size)
    model = spec.compile()
    return model, mujoco.MjData(model)


def test_a_box_taken_from_above_clears_both_wide_open_jaws() -> None:
    """`grasp_pose.TOP_GRASP_OFFSET_M`: hall seed 0's 6.3 cm box, 3 cm into the jaws, had
    3.5 mm to the fixed jaw and 2.8 mm to the open moving one; opened wide, its middle
    moved toward the moving jaw, `top_depth_m` (4.5 cm) into the jaws, it clears the
    fixed jaw by 15.5 mm and the moving one by 7 mm."""
    # its height along the TCP's x, 6.3 cm across its z
    model, data = object_in_jaws("box", mujoco.mjtGeom.mjGEOM_BOX, [0.0665, 0.0455, 0.0315])
    down = 0.0665 - GraspParams().top_depth_m

    def clearance(jaw: float, offset_m: float) -> dict[str, float]:
        return jaw_clearance(model, data, "box", jaw, (down, 0.0, offset_m), np.eye(3))

    before = clearance(robot.GRIPPER_OPEN, 0.0)
    assert before["gripper_jaw_fixed"] < 0.004 and before["gripper_jaw_moving"] < 0.004
    after = clearance(robot.GRIPPER_WIDE, TOP_GRASP_OFFSET_M)
    assert after["gripper_jaw_fixed"] > 0.015 and after["gripper_jaw_moving"] > 0.007, after
    assert min(after.values()) > 0.007, after


@pytest.mark.parametrize("radius", [0.026, 0.0325])
def test_a_wide_can_comes_in_clear_of_both_wide_open_jaws(radius: float) -> None:
    """`grasp_pose.cylinder_offset`: a can 5.2-6.5 cm across, 1 cm deeper in the jaws than
    the TCP (`SIDE_GRASP_DEPTH`), its axis toward the moving jaw, clears every gripper
    geom with the jaws opened wide; once closed in it sits on the fixed pad."""
    model, data = object_in_jaws("can", mujoco.mjtGeom.mjGEOM_CYLINDER, [radius, 0.06, 0.0])
    depth, up = SIDE_GRASP_DEPTH["can"], rot_x(-math.pi / 2)  # its axis along the TCP's y

    def clearance(across_m: float) -> dict[str, float]:
        return jaw_clearance(model, data, "can", robot.GRIPPER_WIDE, (-depth, 0.0, across_m), up)

    coming = clearance(cylinder_offset(2 * radius))
    assert min(coming.values()) > 0.012, coming  # 12.9 mm to the palm at 6.5 cm
    closed_in = clearance(0.0)
    assert 0.0 <= closed_in["gripper_jaw_fixed"] < 0.01, closed_in


def hold_bottle(
    seconds: float, shake_rad: float = 0.0, depth_m: float = 0.0
) -> tuple[float, float]:
    """Base welded in place, arm held in `ready` by PD, 3 N m on the jaw, gravity on: a
    6 cm, 400 g bottle, its axis `depth_m` deeper in the jaws than the TCP, closed on for
    0.5 s, then left to gravity for `seconds` while the arm's first joint swings
    ±`shake_rad` at 1.5 Hz (a walk's sway, harder). Returns the bottle's slip from the
    TCP (m) and the jaw angle (rad) at the end."""
    spec = mjcf.robot_spec()
    spec.body("base").pos = [0.0, 0.0, robot.STAND_BASE_HEIGHT_M]
    spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, name1="base", objtype=mujoco.mjtObj.mjOBJ_BODY)
    body = spec.worldbody.add_body(name="bottle", gravcomp=1.0)  # floats until gripped
    body.add_freejoint(name="bottle")
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.03, 0.1], mass=0.4)
    model = spec.compile()
    data = mujoco.MjData(model)
    idx = mjcf.mj_indices(model)
    data.qpos[idx.qpos] = mjcf.q_pin_to_mj(robot.standing_q("ready"))
    mujoco.mj_forward(model, data)
    tcp = data.site(robot.TCP_FRAME)
    R_tcp = tcp.xmat.reshape(3, 3)
    adr = model.joint("bottle").qposadr[0]
    # 1 mm off the fixed pad
    data.qpos[adr : adr + 3] = tcp.xpos - 0.004 * R_tcp[:, 2] - depth_m * R_tcp[:, 0]
    data.qpos[adr + 3 : adr + 7] = quat_xyzw_to_wxyz(
        matrix_to_quat_xyzw(R_tcp @ rot_x(-math.pi / 2))
    )
    kp = np.r_[[300.0] * 12, [200.0, 200.0, 200.0, 100.0, 50.0, 50.0], 0.0]
    kd = np.r_[[8.0] * 12, [5.0, 5.0, 5.0, 2.0, 1.0, 1.0], 0.0]
    held = None
    grip_steps = 500
    for step in range(grip_steps + round(seconds / model.opt.timestep)):
        target = robot.POSTURES["ready"].copy()
        if step > grip_steps:
            target[0] += shake_rad * math.sin(2 * math.pi * 1.5 * (step - grip_steps) * 1e-3)
        q = mjcf.q_mj_to_pin(data.qpos[idx.qpos])
        v = mjcf.v_mj_to_pin(data.qvel[idx.qvel], data.qpos[idx.qpos])
        tau = kp * (target - q[7:]) - kd * v[6:]
        tau[-1] = 3.0  # positive closes the jaw
        data.ctrl[idx.ctrl] = tau
        if step == grip_steps:  # closed on the bottle: let gravity have it
            model.body_gravcomp[model.body("bottle").id] = 0.0
            held = (data.body("bottle").xpos - tcp.xpos) @ tcp.xmat.reshape(3, 3)
        mujoco.mj_step(model, data)
    assert held is not None
    now = (data.body("bottle").xpos - tcp.xpos) @ tcp.xmat.reshape(3, 3)  # in the TCP frame
    jaw = float(mjcf.q_mj_to_pin(data.qpos[idx.qpos])[-1])
    return float(np.linalg.norm(now - held)), jaw


def test_the_closed_jaws_hold_a_400g_bottle_without_slipping() -> None:
    slip, jaw = hold_bottle(1.5)
    assert slip < 0.003, slip
    assert robot.GRIPPER_OPEN < jaw < -0.5  # stopped by the 6 cm bottle, not closed


def test_a_swung_bottle_does_not_creep_out_of_the_jaws() -> None:
    """The jaws meet at an angle, so the squeeze pushes a bottle toward their tips; with a
    softer friction cone (impratio 10) it crept 1.0 mm in these 4 s (0.1 mm at 100) and
    slipped out of carried bottles."""
    slip, jaw = hold_bottle(4.0, shake_rad=0.3)
    assert slip < 0.0005, slip
    assert robot.GRIPPER_OPEN < jaw < -0.5


def test_a_bottle_held_deeper_in_the_jaws_creeps_no_faster() -> None:
    """`grasp_pose.SIDE_GRASP_DEPTH`: a bottle 1 cm deeper opens the jaws a few degrees
    more (a wider wedge) and still holds as well, with 1 cm more of the moving pad
    before its end."""
    slip, jaw = hold_bottle(4.0, shake_rad=0.3, depth_m=SIDE_GRASP_DEPTH["bottle"])
    assert slip < 0.0005, slip
    assert robot.GRIPPER_OPEN < jaw < -0.5


def test_gripper_boxes_follow_the_stl_meshes() -> None:
    for link in (STATOR_LINK, MOVER_LINK):
        vertices = read_stl(gripper_stl_path(link))
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        for box in (b for b in GRIPPER_BOXES if b.link == link):
            c, h = np.array(box.center), np.array(box.half_size)
            assert np.all(c - h >= lo - 1e-3) and np.all(c + h <= hi + 1e-3), box.name
    # The pads meet where the meshes' jaws do: stator z = -9 mm with the jaw closed.
    pads = {b.name: b for b in GRIPPER_BOXES if b.is_jaw_pad}
    assert pads["gripper_jaw_fixed"].center[2] + pads["gripper_jaw_fixed"].half_size[2] == (
        pytest.approx(-0.009, abs=2e-4)
    )
    assert pads["gripper_jaw_moving"].center[2] - pads["gripper_jaw_moving"].half_size[2] == (
        pytest.approx(-0.009, abs=2e-4)
    )
    assert set(robot.JAW_GEOMS) == set(pads)


def test_gripper_opens_with_negative_angles(pin_model: PinModels) -> None:
    pmodel, _ = pin_model
    pdata = pmodel.createData()
    tip = pin.SE3(np.eye(3), np.array([0.1, 0.0, -0.009]))  # the moving pad's tip
    heights = []
    for angle in (robot.GRIPPER_CLOSED, robot.GRIPPER_OPEN):
        q = robot.standing_q("stand")
        q[7 + robot.JOINT_NAMES.index(robot.GRIPPER_JOINT)] = angle
        pin.framesForwardKinematics(pmodel, pdata, q)
        stator = pdata.oMf[pmodel.getFrameId(STATOR_LINK, pin.FrameType.BODY)]
        mover = pdata.oMf[pmodel.getFrameId(MOVER_LINK, pin.FrameType.BODY)]
        heights.append((stator.inverse() * mover * tip).translation[2])
    assert heights[0] == pytest.approx(-0.009, abs=1e-9) and heights[1] > 0.05


def project(mount: robot.CameraMount, T_world_camera: pin.SE3, p: np.ndarray) -> np.ndarray:
    fx, fy, cx, cy = robot.intrinsics(mount)
    x, y, z = T_world_camera.actInv(p)
    return np.array([fx * x / z + cx, fy * y / z + cy, z])


def camera_pose(posture: str, name: str) -> pin.SE3:
    pmodel, _ = robot.load_pinocchio()
    pdata = pmodel.createData()
    pin.framesForwardKinematics(pmodel, pdata, robot.standing_q(posture))
    return pdata.oMf[pmodel.getFrameId(name)]


def test_look_posture_shows_the_table_top_to_the_wrist_camera() -> None:
    mount = robot.CAMERA_MOUNTS["camera_wrist"]
    T = camera_pose("look", mount.name)
    for x in (robot.D_OPT_M, robot.STANDOFF_DISTANCE_M + 0.25):
        for y in (-0.15, 0.0, 0.15):
            for z in robot.GRASP_HEIGHTS_M:
                u, v, depth = project(mount, T, np.array([x, y, z]))
                assert depth > 0.2
                assert 0.05 * mount.width < u < 0.95 * mount.width, (x, y, z, u)
                assert 0.1 * mount.height < v < 0.95 * mount.height, (x, y, z, v)


def test_head_camera_looks_down_ahead_from_the_trunk_front() -> None:
    T = camera_pose("stow", "camera_head")
    forward = T.rotation[:, 2]
    assert math.degrees(math.asin(-forward[2])) == pytest.approx(20.0)  # pitched down
    assert 0.3 < T.translation[0] < 0.45
    # The ground 1.5 m ahead is in view.
    u, v, _ = project(robot.CAMERA_MOUNTS["camera_head"], T, np.array([1.5, 0.0, 0.0]))
    assert 0 < u < 320 and 0 < v < 240


def test_reach_and_standoff_come_from_the_kinematics(pin_model: PinModels) -> None:
    pmodel, _ = pin_model
    pdata = pmodel.createData()
    plane = robot.arm_plane()
    rng = np.random.default_rng(4)
    k = [robot.JOINT_NAMES.index(n) for n in ("joint2", "joint3", "joint4")]
    for _ in range(N_RANDOM):  # the planar model is pinocchio's FK at joint1 = joint5 = 0
        q = robot.standing_q("ready")
        q[3:7] = [0, 0, 0, 1]
        q[2] = 0.0
        a = rng.uniform(robot.POSITION_LOWER[k], robot.POSITION_UPPER[k])
        q[7 + np.array(k)] = a
        pin.framesForwardKinematics(pmodel, pdata, q)
        tcp = pdata.oMf[pmodel.getFrameId(robot.TCP_FRAME)].translation
        angles = np.array([a[0], a[0] + a[1], a.sum()])
        predicted = (
            plane["shoulder"]
            + robot._planar(angles[:1], plane["upper"])[0]
            + robot._planar(angles[1:2], plane["fore"])[0]
            + robot._planar(angles[2:], plane["tool"])[0]
        )
        np.testing.assert_allclose(tcp[[0, 2]], predicted, atol=1e-9)
    assert 0.8 < robot.ARM_REACH_M < 0.9
    front = robot.FOOTPRINT_BOUNDS[1]
    assert robot.D_OPT_M - 0.1 > 0.45  # a table edge 10 cm short of the object clears the hips
    assert plane["shoulder"][0] + robot.ARM_REACH_M - 0.1 > robot.D_OPT_M  # not stretched
    assert robot.THETA_OPT_RAD == 0.0
    assert robot.STANDOFF_DISTANCE_M > robot.D_OPT_M
    assert front < robot.HANDOVER_DISTANCE_M
    assert robot.FOOTPRINT[0] >= max(-robot.FOOTPRINT_BOUNDS[0], front)


def test_importing_the_robot_loads_no_model_and_every_name_resolves() -> None:
    """`import common.robot` is cheap (no pinocchio, coal or MuJoCo); the computed names
    come on first access and then stay put as plain attributes."""
    code = (
        "import sys, common.robot as r\n"
        "heavy = {'pinocchio', 'coal', 'mujoco'} & set(sys.modules)\n"
        "assert not heavy, heavy\n"
        "for name in r.__all__:\n"
        "    getattr(r, name)\n"
        "assert r.D_OPT_M is vars(r)['D_OPT_M'] and 'mujoco' not in sys.modules\n"
        "assert set(r.__all__) <= set(dir(r))\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
    with pytest.raises(AttributeError):
        _ = robot.NO_SUCH_NAME  # type: ignore[attr-defined]


def test_intrinsics_match_mujocos_rendering(mj_world: MjWorld) -> None:
    """Render a small sphere off the optical axis and find its centre in the image."""
    spec = mjcf.robot_spec()
    mount = robot.CAMERA_MOUNTS["camera_head"]
    T = camera_pose("stand", mount.name)
    p = T.act(np.array([0.12, -0.05, 1.0]))
    spec.worldbody.add_geom(name="dot", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02], pos=p)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[:] = mjcf.q_pin_to_mj(robot.standing_q("stand"))
    mujoco.mj_forward(model, data)
    renderer = mujoco.Renderer(model, mount.height, mount.width)
    renderer.enable_segmentation_rendering()
    renderer.update_scene(data, camera=mount.name)
    seg = renderer.render()[..., 0]
    renderer.close()
    vs, us = np.nonzero(seg == model.geom("dot").id)
    u, v, _ = project(mount, T, p)
    assert us.size > 20
    assert us.mean() == pytest.approx(u, abs=0.15) and vs.mean() == pytest.approx(v, abs=0.15)


def test_geometry_helpers_round_trip() -> None:
    rng = np.random.default_rng(5)
    for _ in range(10):
        R = rot_z(rng.uniform(-3, 3)) @ rot_y(rng.uniform(-3, 3)) @ rot_x(rng.uniform(-3, 3))
        q = matrix_to_quat_xyzw(R)
        np.testing.assert_allclose(quat_xyzw_to_matrix(q), R, atol=1e-12)
        np.testing.assert_allclose(quat_wxyz_to_xyzw(quat_xyzw_to_wxyz(q)), q)
        np.testing.assert_allclose(pin.Quaternion(R).matrix(), R, atol=1e-12)
    np.testing.assert_allclose(make_T(np.eye(3), [1, 2, 3])[:3, 3], [1, 2, 3])


def test_quat_xyzw_of_a_rotation_agrees_with_scipy_up_to_sign() -> None:
    from scipy.spatial.transform import Rotation

    for R in Rotation.random(50, random_state=3).as_matrix():
        q = robot.quat_xyzw_of(R)
        ref = Rotation.from_matrix(R).as_quat()
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12
        assert min(np.abs(q - ref).max(), np.abs(q + ref).max()) < 1e-9
