"""The MuJoCo scene of a `WorldDescription`, built as an `MjSpec`.

Every named thing in the world is one MuJoCo body named by its id: obstacles are static
bodies (tables drawn as a top on four legs, the rest as solid boxes), artifacts are free
bodies, people and the movables (a trolley, parked beyond the walls) are mocap bodies,
and the world is built into `mjcf.robot_spec()`, so the robot keeps its unprefixed
names, its root at the start pose. A geom's instance is
its root body's name, which is how `segmentation_ids` labels pixels.

Physics: timestep 1 ms with `implicitfast` (stable with the actuators' damping at no extra
cost), elliptic friction cones with `impratio` 100 (the accurate cone for grasping: a
pyramidal or soft cone lets objects creep out of a grip; `mjcf` says why 100,
and sets them all in `set_sim_options`); artifacts have condim 4 (torsional friction, so a
pinched object does not spin about the jaw axis) and friction 1.0.
Sleeping islands are on (`SLEEP`): artifacts resting on tables drop out of the solver and
wake on any contact, weld or qpos write, which halves a hall's step (about 100 to 50 us
with the robot standing); the actuated robot never sleeps.

Handover: each person carries a `<id>_grip` body at their hand (site `<id>_hand`, 0.35 m in
front at 1.0 m height) and one inactive weld per artifact (`grip_weld_name`); the sim
activates one with `attach_to_grip` when the person takes the object. The hand moves on
three slide joints (`hand_joint_name`, the person's x, y, z) driven by force-limited
position servos of the same names: the sim reaches with them and pulls with at most
`HAND_FORCE_N`, so a robot that still grips the object feels a modest pull, not a weld.

Rendering: shadows and multisampling are off (the robot cameras' settings) and the
offscreen buffer holds 1280 x 960, twice the largest camera image, for the visibility
check's wider view.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from common import robot
from common.messages.world import Artifact, Cuboid, Light, Obstacle, Person, Rgba, WorldDescription
from services.sim import mjcf

#: Let resting artifacts sleep (MuJoCo's island sleeping).
SLEEP = True
#: Offscreen framebuffer, pixels: room for a 640 x 480 camera at twice its size.
OFFSCREEN_SIZE = (1280, 960)
#: Friction of artifacts: sliding, torsional, rolling.
ARTIFACT_FRICTION = (1.0, 0.01, 0.0001)
TABLE_TOP_M = 0.04
TABLE_LEG_M = 0.05
#: A person's hand (and grip body) at rest in the person frame, m: ahead, left, up. The
#: robot presents the object from `HANDOVER_DISTANCE_M`, i.e. `PERSON_REACH_M` (0.50 m)
#: ahead of the person: 0.15 m before the resting hand, well within the handover's reach.
HAND_IN_PERSON = (0.35, 0.0, 1.0)
#: The hand's slide joints, each about the rest position along the person's axis: range
#: (m), and the servo's stiffness (N/m), damping (N s/m) and force limit (N). The force
#: limit is the most a person pulls with; z carries the heaviest artifact (0.5 kg) easily.
HAND_AXES = ("x", "y", "z")
HAND_RANGE_M = ((-0.25, 0.30), (-0.35, 0.35), (-0.45, 0.45))
HAND_KP = 600.0
HAND_KV = 25.0
HAND_FORCE_N = (15.0, 15.0, 25.0)
HAND_MASS_KG = 0.3
#: The hand's weld: a 5 ms time constant, so a walking person's object lags 1 cm per m/s
#: (MuJoCo's default 20 ms lets it trail by 4 cm per m/s).
GRIP_SOLREF = (0.005, 1.0)
#: Instance name of every robot geom in segmentation tables.
ROBOT_INSTANCE = "robot"
#: Label of pixels that show no instance (the floor, the sky).
BACKGROUND_LABEL = 0


class SegmentationTable(NamedTuple):
    """Geom ids to instance labels: `geom_label[geom_id]`, and `labels[label]` -> instance id."""

    geom_label: NDArray[np.int32]
    labels: dict[int, str]


def _quat_yaw(yaw: float) -> list[float]:
    return [math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)]


def grip_weld_name(person_id: str, artifact_id: str) -> str:
    """The name of the weld that holds `artifact_id` in `person_id`'s hand."""
    return f"{person_id}_grip_{artifact_id}"


def hand_joint_name(person_id: str, axis: str) -> str:
    """The slide joint (and its servo) moving `person_id`'s hand along their `axis`."""
    return f"{person_id}_hand_{axis}"


def _material(spec: mujoco.MjSpec, name: str, rgba: Rgba, shininess: float = 0.2) -> str:
    spec.add_material(name=name, rgba=list(rgba), specular=0.2, shininess=shininess)
    return name


def _floor(spec: mujoco.MjSpec, world: WorldDescription) -> None:
    spec.add_texture(
        name="floor_tex",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.42, 0.43, 0.44],
        rgb2=[0.38, 0.39, 0.40],
        width=512,
        height=512,
    )
    mat = spec.add_material(name="floor_mat", texrepeat=[0.5, 0.5], texuniform=True)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor_tex"
    (x0, y0), (x1, y1) = world.hall.min_xy, world.hall.max_xy
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        pos=[0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0],
        size=[0.5 * (x1 - x0) + 2.0, 0.5 * (y1 - y0) + 2.0, 0.1],
        material="floor_mat",
    )


def _obstacle(spec: mujoco.MjSpec, ob: Obstacle, movable: bool = False) -> None:
    """A static obstacle's body; a movable's (a trolley) is a mocap body: the sim's hook
    sets it down elsewhere (`SimCore.place_movable`), and nothing pushes it."""
    body = spec.worldbody.add_body(
        name=ob.id, pos=list(ob.centre), quat=_quat_yaw(ob.yaw), mocap=movable
    )
    mat = _material(spec, f"{ob.id}_mat", ob.rgba)
    hx, hy, hz = ob.half_size
    if ob.kind != "table":
        body.add_geom(name=ob.id, type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, hz], material=mat)
        return
    # A table: its top flush with the obstacle box, legs inset at the corners.
    top = 0.5 * TABLE_TOP_M
    body.add_geom(
        name=f"{ob.id}_top",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[hx, hy, top],
        pos=[0.0, 0.0, hz - top],
        material=mat,
    )
    leg_half = 0.5 * (2 * hz - TABLE_TOP_M)
    inset = 0.5 * TABLE_LEG_M + 0.03
    for k, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1)), start=1):
        body.add_geom(
            name=f"{ob.id}_leg{k}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.5 * TABLE_LEG_M, 0.5 * TABLE_LEG_M, leg_half],
            pos=[sx * (hx - inset), sy * (hy - inset), leg_half - hz],
            material=mat,
        )


def _artifact(spec: mujoco.MjSpec, art: Artifact) -> None:
    body = spec.worldbody.add_body(name=art.id, pos=list(art.position), quat=_quat_yaw(art.yaw))
    body.add_freejoint(name=art.id)
    mat = _material(spec, f"{art.id}_mat", art.rgba, shininess=0.5)
    common = dict(material=mat, condim=4, friction=list(ARTIFACT_FRICTION))
    if isinstance(art.shape, Cuboid):
        hx, hy, hz = art.shape.half_size
        body.add_geom(
            name=art.id,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[hx, hy, hz],
            pos=[0, 0, hz],
            mass=art.mass,
            **common,
        )
        return
    r, h = art.shape.radius, art.shape.height
    if art.object_class != "bottle":
        body.add_geom(
            name=art.id,
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[r, 0.5 * h],
            pos=[0, 0, 0.5 * h],
            mass=art.mass,
            **common,
        )
        return
    # A bottle: a body of 3/4 of the height, a neck of 0.4 r above it; mass by volume.
    hb, hn, rn = 0.75 * h, 0.25 * h, 0.4 * r
    vb, vn = r * r * hb, rn * rn * hn
    body.add_geom(
        name=art.id,
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[r, 0.5 * hb],
        pos=[0, 0, 0.5 * hb],
        mass=art.mass * vb / (vb + vn),
        **common,
    )
    body.add_geom(
        name=f"{art.id}_neck",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[rn, 0.5 * hn],
        pos=[0, 0, hb + 0.5 * hn],
        mass=art.mass * vn / (vb + vn),
        **common,
    )


def _person(spec: mujoco.MjSpec, person: Person, artifacts: tuple[Artifact, ...]) -> None:
    """Capsule legs, torso and arms, a sphere head; the right arm reaches to the hand."""
    x, y = person.position
    body = spec.worldbody.add_body(name=person.id, pos=[x, y, 0.0], quat=_quat_yaw(person.yaw))
    body.mocap = True
    h = person.height
    shirt = _material(spec, f"{person.id}_shirt", person.shirt_rgba)
    trousers = _material(spec, f"{person.id}_trousers", person.trousers_rgba)
    skin = _material(spec, f"{person.id}_skin", person.skin_rgba)
    capsule = mujoco.mjtGeom.mjGEOM_CAPSULE
    for side, sy in (("l", 0.1), ("r", -0.1)):
        body.add_geom(
            name=f"{person.id}_leg_{side}",
            type=capsule,
            size=[0.07, 0, 0],
            fromto=[0, sy, 0.07, 0, sy, 0.47 * h],
            material=trousers,
        )
    body.add_geom(
        name=f"{person.id}_torso",
        type=capsule,
        size=[0.16, 0, 0],
        fromto=[0, 0, 0.56 * h, 0, 0, 0.74 * h],
        material=shirt,
    )
    body.add_geom(
        name=f"{person.id}_head",
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[0.11, 0, 0],
        pos=[0, 0, h - 0.11],
        material=skin,
    )
    hand = HAND_IN_PERSON
    # Arms and hands do not collide: the robot's gripper and the object come right up to them.
    limb = dict(type=capsule, size=[0.045, 0, 0], material=shirt, contype=0, conaffinity=0)
    body.add_geom(
        name=f"{person.id}_arm_l", fromto=[0, 0.22, 0.81 * h, 0.02, 0.25, 0.5 * h], **limb
    )
    body.add_geom(
        name=f"{person.id}_arm_r",
        fromto=[0, -0.22, 0.81 * h, hand[0] - 0.04, hand[1] - 0.02, hand[2]],
        **limb,
    )
    grip = body.add_body(name=f"{person.id}_grip", pos=list(hand), gravcomp=1.0)
    grip.add_geom(
        name=f"{person.id}_hand_geom",
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[0.045, 0, 0],
        material=skin,
        contype=0,
        conaffinity=0,
        mass=HAND_MASS_KG,
    )
    grip.add_site(name=f"{person.id}_hand", size=[0.01, 0, 0])
    _hand_servos(spec, grip, person.id)
    for art in artifacts:
        spec.add_equality(
            name=grip_weld_name(person.id, art.id),
            type=mujoco.mjtEq.mjEQ_WELD,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            name1=f"{person.id}_grip",
            name2=art.id,
            active=False,
            data=[0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0],
            solref=list(GRIP_SOLREF),
        )


def _hand_servos(spec: mujoco.MjSpec, grip: mujoco.MjsBody, person_id: str) -> None:
    """Three slide joints under the grip body and a force-limited position servo on each."""
    for k, (axis, span, force) in enumerate(
        zip(HAND_AXES, HAND_RANGE_M, HAND_FORCE_N, strict=True)
    ):
        name = hand_joint_name(person_id, axis)
        direction = [0.0, 0.0, 0.0]
        direction[k] = 1.0
        grip.add_joint(
            name=name,
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=direction,
            range=list(span),
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        )
        spec.add_actuator(
            name=name,
            target=name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            gaintype=mujoco.mjtGain.mjGAIN_FIXED,
            gainprm=[HAND_KP] + [0.0] * 9,
            biastype=mujoco.mjtBias.mjBIAS_AFFINE,
            biasprm=[0.0, -HAND_KP, -HAND_KV] + [0.0] * 7,
            ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE,
            ctrlrange=list(span),
            forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE,
            forcerange=[-force, force],
        )


def _light(spec: mujoco.MjSpec, k: int, light: Light) -> None:
    kind = mujoco.mjtLightType
    spec.worldbody.add_light(
        name=f"light_{k}",
        pos=list(light.position),
        dir=list(light.direction),
        diffuse=list(light.diffuse),
        specular=list(light.specular),
        type=kind.mjLIGHT_DIRECTIONAL if light.directional else kind.mjLIGHT_SPOT,
        castshadow=False,
        cutoff=70.0,
        exponent=2.0,
    )


def _options(spec: mujoco.MjSpec, world: WorldDescription) -> None:
    spec.modelname = f"dume_{world.name}_{world.seed}"
    mjcf.set_sim_options(spec)
    if SLEEP:
        spec.option.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    spec.visual.global_.offwidth, spec.visual.global_.offheight = OFFSCREEN_SIZE
    spec.visual.quality.shadowsize = 0
    spec.visual.quality.offsamples = 0
    spec.visual.headlight.ambient = list(world.lighting.ambient)
    spec.visual.headlight.diffuse = list(world.lighting.headlight_diffuse)
    spec.visual.headlight.specular = [0.0, 0.0, 0.0]
    (x0, y0), (x1, y1) = world.hall.min_xy, world.hall.max_xy
    extent = 0.5 * math.hypot(x1 - x0, y1 - y0)
    spec.stat.extent = extent
    spec.stat.center = [0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * world.hall.wall_height]
    spec.visual.map.znear = 0.01 / extent  # 1 cm: the wrist camera sees the jaws up close
    spec.visual.map.zfar = 4.0  # times the extent: the far corner of the hall


def _place_robot(spec: mujoco.MjSpec, world: WorldDescription) -> None:
    """Stand the robot's root body at the start pose (its free joint starts there)."""
    start = world.robot_start
    base = spec.worldbody.first_body()
    base.pos = [start.x, start.y, robot.STAND_BASE_HEIGHT_M]
    base.quat = _quat_yaw(start.yaw)


def build_scene(world: WorldDescription, *, with_robot: bool = True) -> mujoco.MjSpec:
    """The scene of a world: floor, obstacles, artifacts, people, lights and the robot.

    With the robot, the world is built into `mjcf.robot_spec()` rather than the
    robot attached to it, so every robot name stays unprefixed and the robot's bodies come
    first; its root stands at the start pose.
    """
    spec = mjcf.robot_spec() if with_robot else mujoco.MjSpec()
    if with_robot:
        _place_robot(spec, world)
    _options(spec, world)
    _floor(spec, world)
    for ob in world.obstacles:
        _obstacle(spec, ob)
    for ob in world.movables:
        _obstacle(spec, ob, movable=True)
    for art in world.artifacts:
        _artifact(spec, art)
    for person in world.people:
        _person(spec, person, world.artifacts)
    for k, light in enumerate(world.lighting.lights, start=1):
        _light(spec, k, light)
    return spec


def compile_scene(world: WorldDescription, *, with_robot: bool = True) -> mujoco.MjModel:
    """The compiled model of `build_scene`."""
    return build_scene(world, with_robot=with_robot).compile()


def segmentation_ids(
    model: mujoco.MjModel, world: WorldDescription | None = None
) -> SegmentationTable:
    """Instance labels of every geom: artifacts, people, obstacles, movables, then the robot;
    0 for none.

    A geom's instance is its root body's name; the robot's bodies are `ROBOT_INSTANCE`.
    With `world`, labels follow its order (artifacts first, from 1), the same for every
    model of that world; without, the model's order of root bodies.
    """
    robot_root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, robot.BASE_FRAME)
    if world is not None:
        ids = [a.id for a in world.artifacts] + [p.id for p in world.people]
        ids += [o.id for o in world.obstacles] + [m.id for m in world.movables]
    else:
        roots = sorted({int(r) for r in model.body_rootid[1:]} - {robot_root})
        ids = [model.body(r).name for r in roots]
    label_of = {name: k for k, name in enumerate([*ids, ROBOT_INSTANCE], start=1)}
    geom_label = np.full(model.ngeom, BACKGROUND_LABEL, dtype=np.int32)
    for g in range(model.ngeom):
        root = int(model.body_rootid[model.geom_bodyid[g]])
        if root == robot_root:
            geom_label[g] = label_of[ROBOT_INSTANCE]
        elif root != 0:  # world-body geoms (the floor) stay background
            geom_label[g] = label_of[model.body(root).name]
    return SegmentationTable(geom_label, {k: name for name, k in label_of.items()})


def label_image(segmentation: NDArray[np.int32], table: SegmentationTable) -> NDArray[np.int32]:
    """Per-pixel instance labels (H, W) from a MuJoCo segmentation render (H, W, 2)."""
    objid, objtype = segmentation[..., 0], segmentation[..., 1]
    is_geom = (objtype == int(mujoco.mjtObj.mjOBJ_GEOM)) & (objid >= 0)
    labels = np.full(objid.shape, BACKGROUND_LABEL, dtype=np.int32)
    labels[is_geom] = table.geom_label[objid[is_geom]]
    return labels


def attach_to_grip(
    model: mujoco.MjModel, data: mujoco.MjData, person_id: str, artifact_id: str
) -> None:
    """Activate the weld holding the artifact in the person's hand, at their current poses."""
    eq = model.equality(grip_weld_name(person_id, artifact_id)).id
    hand, obj = data.body(f"{person_id}_grip"), data.body(artifact_id)
    # Relative pose of the object in the hand frame, as MuJoCo's weld expects.
    rel_pos = np.empty(3)
    rel_quat = np.empty(4)
    hand_inv_pos, hand_inv_quat = np.empty(3), np.empty(4)
    mujoco.mju_negPose(hand_inv_pos, hand_inv_quat, hand.xpos, hand.xquat)
    mujoco.mju_mulPose(rel_pos, rel_quat, hand_inv_pos, hand_inv_quat, obj.xpos, obj.xquat)
    model.eq_data[eq, 3:6] = rel_pos
    model.eq_data[eq, 6:10] = rel_quat
    data.eq_active[eq] = 1
