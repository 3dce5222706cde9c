"""Every payload survives the wire, and a bad one is a typed error that says why."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.messages import ArrayError, PayloadError, as_numpy, decode, encode, to_wire
from common.messages.base import Pose
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.navigation import NavGoalRequest, PersonHandover, PoseGoal
from common.messages.sim import Ack, JointCommand, Odom, RobotState, WorldEvents
from common.messages.wbc import ArmGoalRequest, CmdVel, Posture, Reach

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
vec3 = st.tuples(finite, finite, finite)
joints = st.lists(finite, min_size=19, max_size=19).map(lambda v: to_wire(np.array(v)))
quat = st.tuples(finite, finite, finite, finite)


@st.composite
def robot_states(draw: st.DrawFn) -> RobotState:
    return RobotState(
        stamp_ns=draw(st.integers(0, 2**62)),
        tick=draw(st.integers(0, 2**40)),
        q=draw(joints),
        v=draw(joints),
        tau=draw(joints),
        foot_contacts=draw(st.tuples(*[st.booleans()] * 4)),
        foot_forces=draw(st.tuples(*[finite] * 4)),
        imu_angular_velocity=draw(vec3),
        imu_specific_force=draw(vec3),
        gripper_angle=draw(finite),
        gripper_effort=draw(finite),
        watchdog=draw(st.booleans()),
    )


@given(robot_states())
@settings(max_examples=50, deadline=None)
def test_robot_state_round_trips_through_msgpack(state: RobotState) -> None:
    back = decode(encode(state), RobotState)
    assert back == state
    np.testing.assert_array_equal(as_numpy(back.q), as_numpy(state.q))


@given(
    st.builds(
        CmdVel, stamp_ns=st.integers(0, 2**62), vx=finite, vy=finite, wz=finite, source=st.text()
    )
)
def test_cmd_vel_round_trips(msg: CmdVel) -> None:
    assert decode(encode(msg), CmdVel) == msg


# No lone surrogate (category Cs): it is not UTF-8, and no client can send one.
@given(
    st.text(st.characters(exclude_categories=("Cc", "Cs")), min_size=1, max_size=128),
    st.from_regex(r"^[a-z]{1,8}(_[1-9][0-9]{0,2})?$", fullmatch=True),
)
def test_mission_requests_travel_as_json_and_round_trip(request_id: str, target: str) -> None:
    msg = MissionRequest(request_id=request_id, object=target, person="person_1")
    data = encode(msg)
    assert data.startswith(b"{")
    assert decode(data, MissionRequest) == msg


def test_tagged_unions_keep_their_variant() -> None:
    reach = ArmGoalRequest(
        goal=Reach(H=tuple(float(i) for i in range(16)), frame="base", stamp_ns=7)
    )
    assert isinstance(decode(encode(reach), ArmGoalRequest).goal, Reach)
    posture = ArmGoalRequest(goal=Posture(name="stow"))
    assert decode(encode(posture), ArmGoalRequest).goal == Posture(name="stow")
    nav = NavGoalRequest(goal=PersonHandover(person_id="person_2"))
    assert decode(encode(nav), NavGoalRequest) == nav
    events = WorldEvents(stamp_ns=1, events=[])
    assert decode(encode(events), WorldEvents) == events


@pytest.mark.parametrize(
    ("payload", "type_", "says"),
    [
        (b"not json", MissionRequest, "malformed"),
        (
            b'{"request_id": 3, "object": "bottle_1", "person": "person_1"}',
            MissionRequest,
            "$.request_id",
        ),
        (
            b'{"request_id": "r", "object": "Bottle!", "person": "person_1"}',
            MissionRequest,
            "$.object",
        ),
        (
            b'{"request_id": "r", "object": "bottle_1", "person": "person_1", "x": 1}',
            MissionRequest,
            "unknown field",
        ),
        (b'{"request_id": "r", "object": "bottle_1"}', MissionRequest, "person"),
    ],
)
def test_malformed_payloads_are_typed_errors_that_say_where(
    payload: bytes, type_: type, says: str
) -> None:
    with pytest.raises(PayloadError) as err:
        decode(payload, type_, key="dume/b1/mission/request")
    assert says in str(err.value)
    assert err.value.key == "dume/b1/mission/request"


def test_nan_and_infinity_are_rejected_where_floats_must_be_finite() -> None:
    for bad in (math.nan, math.inf, -math.inf):
        raw = msgspec.msgpack.encode(
            {"stamp_ns": 0, "vx": bad, "vy": 0.0, "wz": 0.0, "source": "x"}
        )
        with pytest.raises(PayloadError, match=r"\$\.vx"):
            decode(raw, CmdVel)
    raw = msgspec.msgpack.encode({"x": math.nan, "y": 0.0, "yaw": 0.0})
    with pytest.raises(PayloadError):
        decode(raw, PoseGoal)


def test_a_quaternion_that_is_not_unit_is_rejected() -> None:
    """A zero quaternion passed every field's check once, and the navigation died on it at
    its next tick (scipy: zero norm): now it is the payload's error, on the key."""
    odom = {
        "stamp_ns": 0, "base_position_in_world": [0.0, 0.0, 0.5],
        "base_linear_velocity_in_world": [0.0] * 3, "base_angular_velocity_in_base": [0.0] * 3,
        "gripper_angle": 0.0, "gripper_effort": 0.0,
    }  # fmt: skip
    for bad in ([0.0] * 4, [0.0, 0.0, 0.0, 2.0], [1e-9, 0.0, 0.0, 0.0]):
        raw = msgspec.msgpack.encode(odom | {"base_orientation_xyzw": bad})
        with pytest.raises(PayloadError, match="not a unit quaternion"):
            decode(raw, Odom, key="dume/b1/odom")
        with pytest.raises(PayloadError, match="not a unit quaternion"):
            decode(msgspec.msgpack.encode({"position": [0.0] * 3, "orientation_xyzw": bad}), Pose)
    ok = [0.0, 0.0, math.sin(0.3), math.cos(0.3)]
    got = decode(msgspec.msgpack.encode(odom | {"base_orientation_xyzw": ok}), Odom)
    assert got.base_orientation_xyzw == pytest.approx(ok)


def test_a_negative_stamp_is_rejected() -> None:
    with pytest.raises(PayloadError, match="stamp_ns"):
        decode(msgspec.msgpack.encode({"service": "x", "stamp_ns": -1}), Ack)


def test_arrays_are_zero_copy_views_and_check_their_size() -> None:
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    wire = to_wire(a)
    view = as_numpy(wire)
    np.testing.assert_array_equal(view, a)
    assert not view.flags.writeable
    with pytest.raises(ArrayError, match="needs 48 bytes"):
        as_numpy(msgspec.structs.replace(wire, data=wire.data[:-4]))
    with pytest.raises(ArrayError, match="not allowed"):
        as_numpy(msgspec.structs.replace(wire, dtype="object"))
    with pytest.raises(ArrayError):
        to_wire(np.array(["a"], dtype=object))


def test_a_command_with_a_short_array_decodes_but_its_size_is_checked_on_use() -> None:
    cmd = JointCommand(
        stamp_ns=0,
        tau_ff=to_wire(np.zeros(3)),
        q_des=to_wire(np.zeros(19)),
        v_des=to_wire(np.zeros(19)),
        kp=to_wire(np.zeros(19)),
        kd=to_wire(np.zeros(19)),
    )
    assert as_numpy(decode(encode(cmd), JointCommand).tau_ff).shape == (3,)


def test_mission_status_is_json_with_the_request_id() -> None:
    status = MissionStatus(stamp_ns=5, request_id="abc", state="failed", reason="unknown_object")
    data = encode(status)
    assert b'"request_id":"abc"' in data
    assert decode(data, MissionStatus) == status


def test_a_string_that_is_not_utf8_is_a_typed_error_not_a_crash() -> None:
    """msgpack carries strings as bytes: invalid UTF-8 raised UnicodeDecodeError past the
    bus's handler (found by `dume trial fuzz`)."""
    raw = msgspec.msgpack.encode({"stamp_ns": 1, "vx": 0.0, "vy": 0.0, "wz": 0.0, "source": "x"})
    broken = raw.replace(b"\xa1x", b"\xa1\xb8")
    with pytest.raises(PayloadError, match="UnicodeDecodeError"):
        decode(broken, CmdVel, key="dume/b1/wbc/cmd_vel")
