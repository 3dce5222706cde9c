"""The simulator's core: joint drives, watchdog, kinematic base, people, handover, events."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

import math

import msgspec
import mujoco
import numpy as np
import pytest

from common import robot
from common.messages import Array, as_numpy
from common.messages.sim import HandoverTaken, ObjectDropped, RobotContact, RobotState
from common.messages.world import Obstacle, WorldDescription
from services.sim import handover as ho
from services.sim.core import CommandError, SimCore
from services.sim.feasibility import surface_normal_towards
from services.sim.hold import StandHold
from services.sim.people import MAX_SPEED_MPS, PAUSE_S
from services.sim.sensors import ideal_sensors
from services.sim.standing import STAND_KD, STAND_KP
from services.sim.world import generate_world

N = len(robot.JOINT_NAMES)
FAR_CORNER = (3.4, 2.3)  # in the small worlds below, more than 3 m from every person


@pytest.fixture(scope="module")
def world() -> WorldDescription:
    return generate_world(0, "small")


def f64(array: Array) -> np.ndarray:
    return np.asarray(as_numpy(array), dtype=float)


def q_of(state: RobotState) -> np.ndarray:
    return f64(state.q)


def hold(core: SimCore, law: StandHold) -> list[object]:
    """One tick of the stand-hold commander: state, command, step."""
    state = core.robot_state(core.tick)
    core.command(law.tau_ff, law.q_des, law.v_des, law.kp, law.kd, state.stamp_ns)
    return list(core.step())


# -- joint drives ------------------------------------------------------------------------------


def test_torques_follow_the_pd_law_and_are_clipped_to_the_urdf_limits(
    world: WorldDescription,
) -> None:
    core = SimCore(world, sensors=ideal_sensors())
    state = core.robot_state()
    q, v = q_of(state), f64(state.v)
    rng = np.random.default_rng(0)
    tau_ff = rng.uniform(-2.0, 2.0, N)
    q_des, v_des = q + rng.uniform(-0.01, 0.01, N), rng.uniform(-0.1, 0.1, N)
    kp, kd = np.full(N, 20.0), np.full(N, 1.0)
    core.command(tau_ff, q_des, v_des, kp, kd, core.time_ns)
    core.step()
    expected = tau_ff + kp * (q_des - q) + kd * (v_des - v)
    np.testing.assert_allclose(f64(core.robot_state().tau), expected, atol=1e-9)

    limits = robot.TORQUE_LIMITS
    for sign in (1.0, -1.0):
        core.command(sign * 10 * limits, q_des, v_des, np.full(N, 1e4), kd, core.time_ns)
        core.step()
        tau = f64(core.robot_state().tau)
        np.testing.assert_allclose(tau, sign * limits, atol=1e-9)
    assert core.robot_state().gripper_effort == pytest.approx(-limits[-1])


def test_malformed_commands_raise_and_the_previous_command_stays(
    world: WorldDescription,
) -> None:
    core = SimCore(world, sensors=ideal_sensors())
    good = dict(tau_ff=np.full(N, 1.0), q_des=np.zeros(N), v_des=np.zeros(N))
    zeros = np.zeros(N)
    core.command(good["tau_ff"], good["q_des"], good["v_des"], zeros, zeros, 0)
    nan, short, negative = zeros.copy(), np.zeros(N - 1), zeros.copy()
    nan[3] = np.nan
    negative[13] = -1.0
    bad = [
        ((short, zeros, zeros, zeros, zeros, 0), "tau_ff has shape (18,)"),
        ((zeros, nan, zeros, zeros, zeros, 0), "q_des is not finite at ['FR_hip_joint']"),
        ((zeros, zeros, np.full(N, np.inf), zeros, zeros, 0), "v_des is not finite"),
        ((zeros, zeros, zeros, negative, zeros, 0), "kp is negative at ['joint2']"),
        ((zeros, zeros, zeros, zeros, zeros, 5_000_000), "later than the sim time 0"),
    ]
    for args, message in bad:
        with pytest.raises(CommandError) as err:
            core.command(*args)
        assert message in str(err.value)
    core.step()
    np.testing.assert_allclose(f64(core.robot_state().tau), 1.0, atol=1e-9)


def test_a_plain_pd_hold_sags_more_than_2cm(world: WorldDescription) -> None:
    """Why the stand-hold carries a feed-forward: 300/10 alone gives way under 61 kg."""
    core = SimCore(world, sensors=ideal_sensors())
    law = StandHold()
    law.tau_ff[:] = 0.0
    for _ in range(1000):
        hold(core, law)
    sag = robot.STAND_BASE_HEIGHT_M - core.state_truth().base_position_in_world[2]
    assert sag > 0.02


def test_the_stand_hold_keeps_the_base_within_2cm_for_2s_without_events(
    world: WorldDescription,
) -> None:
    core = SimCore(world, sensors=ideal_sensors())
    law = StandHold()
    np.testing.assert_array_equal(law.kp, STAND_KP)
    np.testing.assert_array_equal(law.kd, STAND_KD)
    heights, events = [], []
    start = np.array(core.state_truth().base_position_in_world)
    for _ in range(2000):
        events += hold(core, law)
        heights.append(core.state_truth().base_position_in_world[2])
    assert np.max(np.abs(np.array(heights) - robot.STAND_BASE_HEIGHT_M)) < 0.02
    state = core.robot_state()
    base = core.state_truth().base_position_in_world
    assert np.linalg.norm(np.array(base)[:2] - start[:2]) < 0.01
    assert np.max(np.abs(q_of(state) - law.q_des)) < 0.02
    weight = 9.81 * core.model.body_subtreemass[core.model.body(robot.BASE_FRAME).id]
    assert all(state.foot_contacts) and sum(state.foot_forces) == pytest.approx(weight, rel=0.05)
    assert events == []  # feet on the floor are no contact events
    assert not state.watchdog and state.locomotion == "dynamic"


def test_the_robot_starts_standing_at_the_world_start_on_four_feet(
    world: WorldDescription,
) -> None:
    core = SimCore(world, sensors=ideal_sensors())
    state = core.robot_state(0)
    start = world.robot_start
    assert core.state_truth().base_position_in_world == pytest.approx(
        (start.x, start.y, robot.STAND_BASE_HEIGHT_M)
    )
    np.testing.assert_allclose(q_of(state), robot.POSTURES["stand"])
    assert all(state.foot_contacts) and sum(state.foot_forces) > 0.0
    d, m = core.data, core.model
    touching = {(m.geom(c.geom1).name, m.geom(c.geom2).name) for c in d.contact[: d.ncon]}
    assert touching == {("floor", f"{foot}_0") for foot in robot.FOOT_FRAMES}  # no self-contact


def test_state_time_is_exact_and_quaternions_are_xyzw(world: WorldDescription) -> None:
    core = SimCore(world, sensors=ideal_sensors())
    for _ in range(3):
        core.step()
    state = core.robot_state(3)
    assert state.stamp_ns == core.time_ns == 3_000_000 and state.tick == 3
    yaw = world.robot_start.yaw
    truth = core.state_truth()
    assert truth.stamp_ns == state.stamp_ns
    _, _, z, w = truth.base_orientation_xyzw
    assert (z, w) == pytest.approx((math.sin(yaw / 2), math.cos(yaw / 2)), abs=1e-3)
    np.testing.assert_allclose(core.T_world_base()[:3, 3], truth.base_position_in_world)
    with pytest.raises(ValueError, match="tick 2"):
        core.robot_state(2)


# -- watchdog ----------------------------------------------------------------------------------


def test_watchdog_holds_after_20ms_without_commands_and_the_base_stays_up_for_5s(
    world: WorldDescription,
) -> None:
    core = SimCore(world, sensors=ideal_sensors())
    flags = []
    lowest = np.inf
    for _ in range(5000):
        flags.append(core.robot_state().watchdog)
        core.step()
        lowest = min(lowest, core.state_truth().base_position_in_world[2])
    assert not any(flags[:21]) and all(flags[21:])  # engaged by the step from t = 20 ms
    state = core.robot_state()
    assert state.watchdog_reason == "no command for 20 ms"
    assert lowest > 0.35
    law = StandHold()
    hold(core, law)
    assert not core.robot_state().watchdog  # a new command releases it
    for _ in range(19):
        core.step()
    assert not core.robot_state().watchdog
    core.step()
    assert core.robot_state().watchdog  # 20 ms after the last command


# -- kinematic locomotion ----------------------------------------------------------------------


def test_kinematic_base_follows_cmd_vel_level_at_standing_height(world: WorldDescription) -> None:
    core = SimCore(world, locomotion="kinematic")
    start = np.array(core.state_truth().base_position_in_world)
    core.set_cmd_vel(0.5, 0.0, 0.0)
    for _ in range(2000):
        core.step()
    state, truth = core.robot_state(), core.state_truth()
    end = np.array(truth.base_position_in_world)
    assert np.linalg.norm(end[:2] - start[:2]) == pytest.approx(1.0, abs=0.02)
    heading = math.atan2(end[1] - start[1], end[0] - start[0])
    assert heading == pytest.approx(world.robot_start.yaw, abs=1e-6)
    assert end[2] == pytest.approx(robot.STAND_BASE_HEIGHT_M)
    assert state.locomotion == "kinematic" and core.odom().locomotion == "kinematic"
    assert truth.base_linear_velocity_in_world[:2] == pytest.approx(
        (0.5 * math.cos(heading), 0.5 * math.sin(heading)), abs=1e-6
    )
    core.set_cmd_vel(0.0, 0.0, 0.5)
    for _ in range(1000):
        core.step()
    yaw = math.atan2(*(core.T_world_base()[[1, 0], 0]))
    assert yaw == pytest.approx(world.robot_start.yaw + 0.5, abs=1e-6)
    legs = q_of(core.robot_state())[: len(robot.LEG_JOINTS)]
    assert np.max(np.abs(legs - robot.POSTURES["stand"][: len(legs)])) < 0.1


def test_cmd_vel_needs_kinematic_locomotion(world: WorldDescription) -> None:
    with pytest.raises(RuntimeError):
        SimCore(world, sensors=ideal_sensors()).set_cmd_vel(0.1, 0.0, 0.0)


# -- people ------------------------------------------------------------------------------------


def _facing(core: SimCore, person_id: str) -> float:
    """The person's heading error towards the robot's base, rad."""
    x, y, yaw = core.people.pose(person_id)
    base = core.T_world_base()[:2, 3]
    return abs(math.remainder(math.atan2(base[1] - y, base[0] - x) - yaw, math.tau))


def test_people_turn_to_face_a_robot_within_3m_and_not_one_farther(
    world: WorldDescription,
) -> None:
    person = world.people[0]
    for distance, turns in ((2.5, True), (3.5, False)):
        core = SimCore(world, locomotion="kinematic")
        side = person.yaw + math.pi / 2  # beside them, towards the hall's middle
        if person.position[1] + math.sin(side) > 0.8:
            side += math.pi
        core.reset_robot(
            person.position[0] + distance * math.cos(side),
            person.position[1] + distance * math.sin(side),
            0.0,
        )
        assert _facing(core, person.id) == pytest.approx(math.pi / 2, abs=1e-6)
        for _ in range(2000):
            core.step()
        if turns:
            assert _facing(core, person.id) < math.radians(1.0)
        else:
            assert core.people.pose(person.id)[2] == pytest.approx(person.yaw)


def test_walking_people_keep_to_their_route_at_most_1_2_mps() -> None:
    world = generate_world(0, "small", walking_people=True)
    person = world.people[0]
    assert person.waypoints and person.speed > 0
    still = SimCore(world, locomotion="kinematic", walking_people=False)
    core = SimCore(world, locomotion="kinematic", walking_people=True)
    for c in (still, core):
        c.reset_robot(*FAR_CORNER, 0.0)
    route = np.array([person.position, *person.waypoints])
    path = []
    for _ in range(8000):
        core.step()
        still.step()
        path.append(core.people.pose(person.id)[:2])
    assert still.people.pose(person.id) == pytest.approx((*person.position, person.yaw))
    path_a = np.array(path)
    speeds = np.linalg.norm(np.diff(path_a, axis=0), axis=1) / core.dt
    assert speeds.max() <= min(person.speed, MAX_SPEED_MPS) + 1e-9
    assert speeds.sum() * core.dt > 2.0  # it walks...
    at_first = np.linalg.norm(path_a - route[1], axis=1) < 1e-9
    assert np.count_nonzero(at_first) >= PAUSE_S / core.dt  # ...and pauses at a waypoint
    # Every point lies on a leg of the route.
    a, b = route[:-1], route[1:]
    for p in path_a[::50]:
        t = np.clip(np.sum((p - a) * (b - a), axis=1) / np.sum((b - a) ** 2, axis=1), 0, 1)
        assert np.min(np.linalg.norm(a + t[:, None] * (b - a) - p, axis=1)) < 1e-6


# -- handover ----------------------------------------------------------------------------------


class BottleHolder:
    """Holds the world's bottle still at a point, as a hand would: its free joint is set
    each step and its weight carried (an applied force), so MuJoCo does not put the bottle
    to sleep in mid-air — a bottle in the robot's gripper stays awake through the contact."""

    def __init__(self, core: SimCore, bottle_id: str) -> None:
        self.core = core
        self.body = core.model.body(bottle_id).id
        self.qpos = int(core.model.joint(bottle_id).qposadr[0])
        self.dof = int(core.model.joint(bottle_id).dofadr[0])
        self.com = core.data.xipos[self.body] - core.data.xpos[self.body]

    def step_at(self, centre: np.ndarray | None) -> list[object]:
        d = self.core.data
        if centre is None:
            d.xfrc_applied[self.body] = 0.0
        else:
            d.qpos[self.qpos : self.qpos + 7] = [*(centre - self.com), 1.0, 0.0, 0.0, 0.0]
            d.qvel[self.dof : self.dof + 6] = 0.0
            d.xfrc_applied[self.body, 2] = self.core.model.body_subtreemass[self.body] * 9.81
        return list(self.core.step())

    def force(self) -> np.ndarray:
        """The constraint force on the bottle in the last step (N, world): the hand's weld."""
        return np.array(self.core.data.qfrc_constraint[self.dof : self.dof + 3])


def _handover_setup(world: WorldDescription) -> tuple[SimCore, BottleHolder, np.ndarray]:
    core = SimCore(world, locomotion="kinematic")
    core.reset_robot(*FAR_CORNER, 0.0)
    person = world.people[0]
    rest = core.handover.rest_position(core.data, person.id)
    ahead = np.array([math.cos(person.yaw), math.sin(person.yaw), 0.0])
    return core, BottleHolder(core, world.artifacts[0].id), rest + 0.1 * ahead


def test_a_bottle_held_still_near_a_hand_is_taken_after_half_a_second_and_pulled(
    world: WorldDescription,
) -> None:
    core, bottle, presented = _handover_setup(world)
    person = world.people[0]
    events: list[object] = []
    for _ in range(500):
        events += bottle.step_at(presented)
    assert events == []  # not before 0.5 s
    for _ in range(500):
        events += bottle.step_at(presented)
    taken = [e for e in events if isinstance(e, HandoverTaken)]
    assert taken == [
        HandoverTaken(stamp_ns=taken[0].stamp_ns, person_id=person.id, object_id="bottle_1")
    ]
    assert 0.5e9 < taken[0].stamp_ns < 1.0e9
    assert core.handover.holder("bottle_1") == person.id
    for _ in range(1200):  # the hand draws back over 1 s: the pull builds up
        events += bottle.step_at(presented)
    pull = bottle.force()
    towards = np.array([*person.position, 0.0]) - presented
    towards[2] = 0.0
    assert 10.0 <= np.linalg.norm(pull) <= 20.0
    assert pull @ towards / (np.linalg.norm(pull) * np.linalg.norm(towards)) > 0.95
    np.testing.assert_allclose(core.handover.pull_force(core.data, person.id), pull, atol=0.5)
    assert len([e for e in events if isinstance(e, HandoverTaken)]) == 1
    # Let go: the person keeps the bottle and draws it in; nothing drops.
    for _ in range(1500):
        events += bottle.step_at(None)
    position = np.array(core.truth_positions()["bottle_1"])
    assert position[2] > 0.8
    assert math.dist(position[:2], person.position) < math.dist(presented[:2], person.position)
    assert not [e for e in events if isinstance(e, ObjectDropped)]


def test_a_bottle_a_person_holds_can_be_put_back_on_the_table_and_taken_again(
    world: WorldDescription,
) -> None:
    """Somebody takes it from the person's hand and puts it on the table (the world's
    artifact hook): the grip lets go, it rests there, and a second handover works."""
    core, bottle, presented = _handover_setup(world)
    for _ in range(1000):
        bottle.step_at(presented)
    assert core.handover.holder("bottle_1") == world.people[0].id
    bottle.step_at(None)
    table = world.artifacts[0].position
    core.place_artifact("bottle_1", table, 0.0)
    for _ in range(1000):
        core.step()
    assert core.handover.holder("bottle_1") is None
    x, y, z = core.truth_positions()["bottle_1"]
    assert math.dist((x, y), table[:2]) < 0.01 and abs(z - table[2]) < 0.005
    events: list[object] = []
    for _ in range(1000):
        events += bottle.step_at(presented)
    assert [e for e in events if isinstance(e, HandoverTaken)]
    assert core.handover.holder("bottle_1") == world.people[0].id


def test_a_bottle_moved_away_before_half_a_second_is_not_taken(world: WorldDescription) -> None:
    core, bottle, presented = _handover_setup(world)
    away = presented + np.array([0.0, 0.0, ho.RADIUS_M + 0.05])
    events: list[object] = []
    for _ in range(400):
        events += bottle.step_at(presented)
    for _ in range(1000):
        events += bottle.step_at(away)
    for _ in range(450):  # back near the hand: the half second starts again
        events += bottle.step_at(presented)
    assert events == []
    assert core.handover.holder("bottle_1") is None


# -- events ------------------------------------------------------------------------------------


def test_object_dropped_when_an_artifact_falls_from_its_table(world: WorldDescription) -> None:
    core = SimCore(world, locomotion="kinematic")
    bottle = world.artifacts[0]
    surface = next(s for s in world.surfaces if s.id == bottle.surface_id)
    events: list[object] = []
    for _ in range(300):  # resting: nothing happens
        events += core.step()
    assert events == []
    # Nudge it over the table's edge: off the top by its radius, at the top's height.
    qpos = int(core.model.joint(bottle.id).qposadr[0])
    normal, depth = surface_normal_towards(surface, bottle.position[:2])
    core.data.qpos[qpos : qpos + 2] += (depth + 0.04) * normal
    core.data.qpos[qpos + 2] += 0.002
    for _ in range(1500):
        events += core.step()
    dropped = [e for e in events if isinstance(e, ObjectDropped)]
    assert len(dropped) == 1 and dropped[0].object_id == bottle.id
    assert dropped[0].position_in_world[2] < 0.1  # on the floor
    assert not [e for e in events if isinstance(e, RobotContact)]


def test_robot_contact_when_the_trunk_is_driven_into_a_bar_once_not_for_feet(
    world: WorldDescription,
) -> None:
    """A bar at trunk height, narrower than the hips: only the trunk's front can reach it."""
    x0, y0 = 2.8, -1.8
    bar = Obstacle(
        id="machine_1",
        kind="machine",
        centre=(x0 + 0.55, y0, 0.53),
        half_size=(0.05, 0.04, 0.05),
        yaw=0.0,
        rgba=(0.5, 0.5, 0.5, 1.0),
    )
    core = SimCore(
        msgspec.structs.replace(world, obstacles=(*world.obstacles, bar)), locomotion="kinematic"
    )
    core.reset_robot(x0, y0, 0.0)
    core.set_cmd_vel(0.2, 0.0, 0.0)
    events: list[object] = []
    for _ in range(2000):
        events += core.step()
        if events:
            core.set_cmd_vel(0.0, 0.0, 0.0)  # stop against the bar: the contact stays
    contacts = [e for e in events if isinstance(e, RobotContact)]
    assert len(contacts) == 1, contacts  # edge-triggered: once while it stays in touch
    contact = contacts[0]
    assert (contact.body, contact.other) == ("trunk", "machine_1") and contact.force > 0.0
    assert contact.position_in_world[0] == pytest.approx(x0 + 0.5, abs=0.01)
    assert core.contacts.contacts.foot_force.sum() >= 0.0  # feet on the floor: no events


def test_truth_positions_name_every_artifact_and_person(world: WorldDescription) -> None:
    core = SimCore(world, sensors=ideal_sensors())
    truth = core.truth_positions()
    assert set(truth) == {a.id for a in world.artifacts} | {p.id for p in world.people}
    assert truth["bottle_1"] == pytest.approx(world.artifacts[0].position, abs=1e-6)
    assert truth[world.people[0].id][:2] == pytest.approx(world.people[0].position)
    assert mujoco.mj_name2id(core.model, mujoco.mjtObj.mjOBJ_BODY, "base") >= 0
