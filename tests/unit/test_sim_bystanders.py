"""Bystanders in the changing hall: people who walk their routes past the robot."""

from __future__ import annotations

import math

import mujoco
import pytest

from common.messages.world import Person
from services.sim.people import ACCEL_MPS2, COME_M, FACE_RADIUS_M, WAIT_S, People, RobotNear

XML = """<mujoco><worldbody>
<body name="person_1" mocap="true"><geom type="box" size=".2 .2 .9"/></body>
</worldbody></mujoco>"""
DT = 0.001


def _walker(bystanders: bool) -> tuple[People, mujoco.MjData]:
    """person_1 walks from (0, 0) to (6, 0) and back at 1 m/s."""
    model = mujoco.MjModel.from_xml_string(XML)
    person = Person(
        id="person_1", position=(0.0, 0.0), yaw=0.0, height=1.7,
        shirt_rgba=(1, 0, 0, 1), trousers_rgba=(0, 0, 1, 1), skin_rgba=(1, 1, 1, 1),
        waypoints=((6.0, 0.0),), speed=1.0,
    )  # fmt: skip
    return People(model, (person,), walking=True, bystanders=bystanders), mujoco.MjData(model)


def _run(people: People, data: mujoco.MjData, robot: RobotNear, seconds: float) -> list[float]:
    xs = []
    for _ in range(round(seconds / DT)):
        people.update(data, robot, DT)
        xs.append(people.pose("person_1")[0])
    return xs


def test_a_bystander_walks_on_past_a_robot_beside_their_route() -> None:
    """The robot stands 1.5 m beside the route: an ordinary walker stops within 3 m of it
    and turns to face it; a bystander walks past at their pace."""
    robot = RobotNear(3.0, 1.5, -math.pi / 2)
    ordinary, data = _walker(False)
    assert max(_run(ordinary, data, robot, 5.0)) < 3.0 - math.sqrt(FACE_RADIUS_M**2 - 1.5**2) + 0.01
    bystander, data = _walker(True)
    xs = _run(bystander, data, robot, 5.0)
    # 5 s at 1 m/s, no stop: from rest at ACCEL_MPS2, the first second gains half a metre.
    assert xs[-1] == pytest.approx(5.0 - 0.5 / ACCEL_MPS2, abs=0.05)
    assert bystander.velocity("person_1") == pytest.approx((1.0, 0.0))  # the truth's velocity


def test_a_bystander_stops_for_a_robot_that_comes_to_them_carrying_something() -> None:
    """Facing them within COME_M and carrying: they stop and wait while it is near;
    heading elsewhere, or empty-handed, they walk on."""
    people, data = _walker(True)
    _run(people, data, RobotNear(10.0, 10.0), 1.0)  # walking, at x = 1
    x1 = people.pose("person_1")[0]
    at = (x1 + 1.5, 0.0)
    _run(people, data, RobotNear(*at, math.pi, carrying=False), 0.2)  # empty-handed
    x2 = people.pose("person_1")[0]
    assert x2 > x1 + 0.15
    passing = RobotNear(x2 + 1.5, 0.5, math.pi / 2, carrying=True)  # heading elsewhere
    assert people.pose("person_1")[0] < _run(people, data, passing, 0.2)[-1]
    x3 = people.pose("person_1")[0]
    coming = RobotNear(x3 + COME_M - 0.2, 0.0, math.pi, carrying=True)
    xs = _run(people, data, coming, 3.0)
    assert xs[-1] == pytest.approx(xs[0], abs=1e-3)  # stopped at once
    assert abs(math.remainder(people.pose("person_1")[2], math.tau)) < 1e-3  # facing it
    # Still near after the handover (carrying nothing): they wait until it leaves.
    after = RobotNear(x3 + COME_M - 0.2, 0.0, math.pi, carrying=False)
    assert _run(people, data, after, 1.0)[-1] == pytest.approx(xs[-1], abs=1e-3)
    assert _run(people, data, RobotNear(20.0, 20.0), 1.0)[-1] > xs[-1] + 0.5


def test_a_bystander_waits_out_a_robot_that_stands_near_them_and_again_once_it_came_again() -> None:
    """A robot that came to them carrying, then stood there (its goal beside them, the
    object not for them): they wait WAIT_S, walk on, and stop for it again only after
    it went and came again. One that keeps coming nearer keeps them waiting."""
    people, data = _walker(True)
    _run(people, data, RobotNear(10.0, 10.0), 1.0)
    x1 = people.pose("person_1")[0]
    standing = RobotNear(x1 + COME_M - 0.2, 0.0, math.pi, carrying=True)
    xs = _run(people, data, standing, WAIT_S - 0.5)
    assert xs[-1] == pytest.approx(x1, abs=1e-3)  # waiting
    xs = _run(people, data, standing, 1.5)
    assert xs[-1] > x1 + 0.3  # waited out: walking on along their route
    away = RobotNear(x1 + 10.0, 5.0, math.pi, carrying=True)
    _run(people, data, away, 0.5)  # gone from their sight ...
    x2 = people.pose("person_1")[0]
    again = RobotNear(x2 - COME_M + 0.2, 0.0, 0.0, carrying=True)  # ... and come again
    xs = _run(people, data, again, 3.0)
    assert xs[-1] == pytest.approx(xs[0], abs=2e-3)  # waiting again
    people, data = _walker(True)
    _run(people, data, RobotNear(10.0, 10.0), 1.0)
    x1 = people.pose("person_1")[0]
    for k in range(8):  # 10 cm nearer every 5 s: 40 s in all, past WAIT_S
        nearer = RobotNear(x1 + COME_M - 0.2 - 0.1 * k, 0.0, math.pi, carrying=True)
        assert _run(people, data, nearer, 5.0)[-1] == pytest.approx(x1, abs=1e-3), k


def test_a_bystander_pauses_rather_than_walk_into_the_robot_and_goes_on_once_it_moved() -> None:
    people, data = _walker(True)
    in_the_way = RobotNear(3.0, 0.0, math.pi / 2)  # standing across the route
    xs = _run(people, data, in_the_way, 5.0)  # less than GIVE_WAY_S after the stop
    assert max(xs) <= 3.0 - 1.1 + 0.002 and xs[-1] > 1.5  # stopped 1.1 m short of its base
    assert _run(people, data, RobotNear(3.0, 2.0, math.pi / 2), 2.0)[-1] > 3.0  # gone: on


def test_a_bystander_kept_waiting_by_the_robot_turns_back_along_their_route() -> None:
    people, data = _walker(True)
    in_the_way = RobotNear(3.0, 0.0, math.pi / 2)
    xs = _run(people, data, in_the_way, 9.0)
    stop = max(xs)
    assert stop <= 3.0 - 1.1 + 0.002
    # Stopped 2.4 s in (1.9 m from rest), waited GIVE_WAY_S, turned (π at 2 rad/s), then
    # walked back for 1.03 s, the first second speeding up.
    assert xs[-1] == pytest.approx(stop - 0.53, abs=0.05)
    assert people.velocity("person_1") == pytest.approx((-1.0, 0.0), abs=1e-6)
