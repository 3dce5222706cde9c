"""The sim's people hook (`dume/world/people_command`) as navigation's tests use it:
a person teleported and walked through given points, whatever the robot does."""

from __future__ import annotations

import logging
import math

import mujoco
import pytest

from common.messages.sim import PersonCommand
from common.messages.world import Person
from services.sim.people import FACE_RADIUS_M, People, RobotNear
from services.sim.people_hook import PeopleHook

XML = """<mujoco><worldbody>
<body name="person_1" mocap="true"><geom type="box" size=".2 .2 .9"/></body>
</worldbody></mujoco>"""
DT = 0.001


def _people() -> tuple[People, mujoco.MjData]:
    model = mujoco.MjModel.from_xml_string(XML)
    person = Person(
        id="person_1", position=(0.0, 0.0), yaw=0.0, height=1.7,
        shirt_rgba=(1, 0, 0, 1), trousers_rgba=(0, 0, 1, 1), skin_rgba=(1, 1, 1, 1),
    )  # fmt: skip
    return People(model, (person,), walking=False), mujoco.MjData(model)


class _Fifo:
    def __init__(self, items: list[PersonCommand]) -> None:
        self.items = items

    def drain(self) -> list[PersonCommand]:
        out, self.items = self.items, []
        return out


def _hook(commands: list[PersonCommand]) -> PeopleHook:
    hook = PeopleHook.__new__(PeopleHook)
    hook._fifo = _Fifo(commands)  # type: ignore[assignment]
    hook._pending, hook.log, hook.applied = [], logging.getLogger("test"), 0
    return hook


def test_a_commanded_person_walks_into_the_robot_s_path_at_their_stamp_and_stands() -> None:
    people, data = _people()
    robot = RobotNear(1.0, 1.0)  # within FACE_RADIUS_M: an ordinary person would stop and turn
    assert math.dist(robot[:2], (2.0, 0.0)) < FACE_RADIUS_M
    hook = _hook([
        PersonCommand(stamp_ns=0, person_id="person_1", position=(2.0, 2.0), yaw=-math.pi / 2),
        PersonCommand(stamp_ns=500_000_000, person_id="person_1", yaw=-math.pi / 2,
                      walk_to=((2.0, 0.0),), speed=1.0),
    ])  # fmt: skip
    track = []
    for k in range(4000):
        hook.apply(k * 1_000_000, people)
        people.update(data, robot, DT)
        track.append(people.pose("person_1"))
    assert track[499][:2] == (2.0, 2.0)  # teleported, standing until 0.5 s
    # 1 s of walking towards 1 m/s, from rest at ACCEL_MPS2 (1 m/s²): half a metre.
    assert track[1499][1] == pytest.approx(1.5, abs=2e-3)
    assert track[-1][:2] == pytest.approx((2.0, 0.0))  # there, and staying
    assert tuple(data.mocap_pos[0, :2]) == pytest.approx((2.0, 0.0))
    assert hook.applied == 2


def test_a_command_for_an_unknown_person_is_refused_and_the_sim_goes_on() -> None:
    people, data = _people()
    hook = _hook([PersonCommand(stamp_ns=0, person_id="person_9", position=(1.0, 1.0))])
    hook.apply(0, people)
    people.update(data, RobotNear(5.0, 5.0), DT)
    assert hook.applied == 0 and people.pose("person_1")[:2] == (0.0, 0.0)
