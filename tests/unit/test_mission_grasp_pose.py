"""Grasp plans for synthetic detections: upright cylinders (side) and boxes (top), at
several bearings, in the world frame (with the base pose) and in `base` (without)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.geometry import inv_T, make_T, rot_z
from common.messages.arrays import to_wire
from common.messages.perception import Detection
from common.messages.wbc import Reach
from common.robot import D_OPT_M, GRASP_PITCH_RAD, arm_plane, tcp_reach_gap
from services.mission.grasp_pose import (
    BOX_SIDE_DEPTH_M,
    FIXED_PAD_FROM_TCP_M,
    RESEAT_ROOM_M,
    SIDE_GRASP_DEPTH,
    SIDE_PAD_ROOM_M,
    TOP_CLOSE_IN_M,
    TOP_GRASP_OFFSET_M,
    GraspParams,
    GraspPoseError,
    cylinder_offset,
    grasp_from_detection,
    plan_error,
)

STAMP = 3_000_000_000
BASE_Z = 0.53


def base_pose(x: float, y: float, yaw: float) -> np.ndarray:
    return make_T(rot_z(yaw), (x, y, BASE_Z))


def detection(
    T_wb: np.ndarray,
    axis_by: tuple[float, float, float],
    shape: str = "cylinder",
    class_name: str = "bottle",
    extent: tuple[float, float, float] = (0.05, 0.05, 0.2),
    yaw_in_world: float = 0.0,
) -> Detection:
    """A detection whose axis is at `axis_by` (base_yaw), the centroid a radius nearer."""
    axis_by_a = np.array(axis_by)
    sight = axis_by_a[:2] / np.linalg.norm(axis_by_a[:2])
    centroid_by = axis_by_a - 0.025 * np.array([*sight, 0.0])
    T_wby = make_T(rot_z(math.atan2(T_wb[1, 0], T_wb[0, 0])), T_wb[:3, 3])
    to_w = lambda p: tuple(float(v) for v in T_wby[:3, :3] @ p + T_wby[:3, 3])  # noqa: E731
    return Detection(
        class_name=class_name,
        score=0.9,
        bbox=(0, 0, 2, 2),
        mask=to_wire(np.ones((2, 2), np.uint8)),
        centroid_in_base_yaw=tuple(float(v) for v in centroid_by),  # type: ignore[arg-type]
        centroid_in_world=to_w(centroid_by),  # type: ignore[arg-type]
        axis_in_world=to_w(axis_by_a),  # type: ignore[arg-type]
        axis_in_base_yaw=tuple(float(v) for v in axis_by_a),  # type: ignore[arg-type]
        extent=extent,
        d_obj=float(np.linalg.norm(centroid_by[:2])),
        theta_obj=float(math.atan2(centroid_by[1], centroid_by[0])),
        n_points=500,
        shape=shape,  # type: ignore[arg-type]
        yaw_in_world=yaw_in_world,
        radius=extent[0] / 2 if shape == "cylinder" else 0.0,
    )


BEARINGS = [-0.6, -0.2, 0.0, 0.3, 0.7]
BASES = [base_pose(0.0, 0.0, 0.0), base_pose(2.0, -1.0, 2.5), base_pose(-3.0, 4.0, -1.2)]


def _shoulder_in(T: np.ndarray) -> np.ndarray:
    sx, sz = arm_plane()["shoulder"]
    return T[:3, :3] @ np.array([sx, 0.0, sz]) + T[:3, 3]


@pytest.mark.parametrize("bearing", BEARINGS)
@pytest.mark.parametrize("with_base", [True, False])
def test_a_side_grasp_approaches_from_the_shoulder_and_closes_across_the_cylinder(
    bearing: float, with_base: bool
) -> None:
    for T_wb in BASES:
        # High enough (0.93 m) for the arm to hold it level; 4 cm across, narrow enough
        # to come in centred (the fixed pad passes it with 1.5 cm).
        axis = (D_OPT_M * math.cos(bearing), D_OPT_M * math.sin(bearing), 0.4)
        det = detection(T_wb, axis, extent=(0.04, 0.04, 0.2))
        plan = grasp_from_detection(det, STAMP, T_wb if with_base else None)
        assert plan.kind == "side" and plan.stamp_ns == STAMP
        assert plan.frame == ("world" if with_base else "base")
        H = plan.in_world(T_wb)
        R = H[:3, :3]
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0.0
        approach = R @ np.array(plan.approach_axis)
        axis_w = np.array(det.axis_in_world)
        # The approach is horizontal, from the shoulder toward the cylinder's axis.
        sight = axis_w - _shoulder_in(T_wb)
        sight[2] = 0.0
        assert approach[2] == pytest.approx(0.0, abs=1e-9)
        assert approach @ sight / np.linalg.norm(sight) == pytest.approx(1.0, abs=1e-9)
        # The TCP is on the line of sight 1 cm past the axis (the bottle deeper in the
        # jaws), below its mid-height on a bottle's body.
        deeper = SIDE_GRASP_DEPTH["bottle"] * sight[:2] / np.linalg.norm(sight)
        assert SIDE_GRASP_DEPTH["bottle"] == pytest.approx(0.01)
        assert np.allclose(H[:2, 3], axis_w[:2] + deeper, atol=1e-9)
        assert axis_w[2] - 0.1 + 0.05 <= H[2, 3] < axis_w[2]
        # Jaw pivot (y) along the cylinder; the jaws close (z) across it, horizontally.
        assert R[:, 1] @ np.array([0.0, 0.0, 1.0]) == pytest.approx(1.0)
        assert R[2, 2] == pytest.approx(0.0, abs=1e-9)
        assert abs(R[:, 2] @ sight) < 1e-9
        # And the Reach the WBC gets carries all of it.
        reach = plan.reach()
        assert isinstance(reach, Reach)
        assert reach.frame == plan.frame and reach.stamp_ns == STAMP
        assert np.allclose(np.array(reach.H).reshape(4, 4), plan.H)
        assert reach.pregrasp_m == plan.pregrasp_m > 0.0


@pytest.mark.parametrize("width", [0.05, 0.058, 0.065])
def test_a_wide_cylinder_comes_in_wide_open_toward_the_moving_jaw_and_closes_in(
    width: float,
) -> None:
    """Hall seed 10's can_1 (6.5 cm): centred, the fixed pad passed it with 2.5 mm, the
    fit was 1.5 cm toward that jaw, and its tip pushed the can along the bench."""
    T_wb = BASES[1]
    det = detection(T_wb, (D_OPT_M, 0.1, 0.4), class_name="can", extent=(width, width, 0.12))
    plan = grasp_from_detection(det, STAMP, T_wb)
    offset = cylinder_offset(width)
    assert offset == pytest.approx(SIDE_PAD_ROOM_M - (FIXED_PAD_FROM_TCP_M - width / 2))
    assert offset > 0.0 and plan.jaw == "wide" and plan.reach().jaw == "wide"
    H = plan.in_world(T_wb)
    closing = H[:3, 2]  # fixed jaw -> moving jaw
    axis_w = np.array(det.axis_in_world)
    # On the way in, the fixed pad's plane passes the fitted surface with the room asked.
    pad = H[:3, 3] - FIXED_PAD_FROM_TCP_M * closing
    room = float((axis_w - pad) @ closing) - width / 2
    assert room == pytest.approx(SIDE_PAD_ROOM_M, abs=1e-9)
    # Then it closes in by the offset: the TCP where a centred grasp holds it, on the
    # line of sight `SIDE_GRASP_DEPTH` past the axis.
    assert plan.close_in_m == pytest.approx(offset)
    H_in = plan.closed_in().in_world(T_wb)
    deeper = SIDE_GRASP_DEPTH["can"] * H[:2, 0] / np.linalg.norm(H[:2, 0])
    assert np.allclose(H_in[:2, 3], axis_w[:2] + deeper, atol=1e-9)
    assert np.allclose(H_in[:3, :3], H[:3, :3])
    assert pytest.approx(0.035) == FIXED_PAD_FROM_TCP_M


def test_a_cylinder_s_plan_says_its_radius_and_seat_and_a_reseat_takes_it_deeper() -> None:
    """`seat` reads where the cylinder sits from the jaw's angle against the plan's
    radius and seat (`SIDE_GRASP_DEPTH` deeper than its axis); too shallow, `reseated`
    comes to the grasp pose that much deeper, wide open, the fixed pad off the can by
    `RESEAT_ROOM_M`, and closes in to it."""
    T_wb = BASES[1]
    det = detection(T_wb, (D_OPT_M, 0.1, 0.4), class_name="can", extent=(0.065, 0.065, 0.12))
    plan = grasp_from_detection(det, STAMP, T_wb)
    assert plan.radius_m == pytest.approx(0.0325)
    assert plan.seat_x_m == pytest.approx(-SIDE_GRASP_DEPTH["can"])
    again = plan.reseated(0.02)
    H_in, H = plan.closed_in().in_world(T_wb), again.in_world(T_wb)
    assert again.jaw == "wide" and again.pregrasp_m == 0.0
    assert again.close_in_m == pytest.approx(RESEAT_ROOM_M)
    assert np.allclose(H[:3, 3], H_in[:3, 3] + 0.02 * H_in[:3, 0] - RESEAT_ROOM_M * H_in[:3, 2])
    assert np.allclose(again.closed_in().in_world(T_wb)[:3, 3], H_in[:3, 3] + 0.02 * H_in[:3, 0])
    assert np.allclose(H[:3, :3], H_in[:3, :3])
    box = detection(T_wb, (D_OPT_M, 0.1, 0.4), shape="box", class_name="box",
                    extent=(0.05, 0.05, 0.05))  # fmt: skip
    assert grasp_from_detection(box, STAMP, T_wb).radius_m == 0.0  # only cylinders are read


def test_a_narrow_cylinder_is_reached_centred() -> None:
    det = detection(BASES[0], (D_OPT_M, 0.0, 0.4), class_name="can", extent=(0.04, 0.04, 0.12))
    plan = grasp_from_detection(det, STAMP, BASES[0])
    assert cylinder_offset(0.04) == 0.0
    assert plan.jaw == "open" and plan.close_in_m == 0.0


def test_a_base_plan_is_the_world_plan_seen_from_the_level_base() -> None:
    T_wb = base_pose(1.0, 2.0, 0.7)
    det = detection(T_wb, (0.7, 0.1, 0.3))
    world = grasp_from_detection(det, STAMP, T_wb)
    base = grasp_from_detection(det, STAMP)
    d, angle = plan_error(world.H, T_wb @ base.H)
    assert d < 1e-9 and angle < 1e-6
    assert np.allclose(inv_T(T_wb) @ world.H, base.H, atol=1e-9)


def test_a_pitched_side_grasp_points_nose_down_with_the_jaws_still_horizontal() -> None:
    T_wb = base_pose(0.0, 0.0, 0.0)
    pitch = GRASP_PITCH_RAD[1]
    plan = grasp_from_detection(
        detection(T_wb, (0.7, 0.0, 0.3)), STAMP, T_wb, GraspParams(pitch_rad=pitch)
    )
    R = plan.H[:3, :3]
    assert R[2, 0] == pytest.approx(-math.sin(pitch))  # x dips
    assert R[2, 2] == pytest.approx(0.0, abs=1e-9)  # jaws close horizontally
    with pytest.raises(ValueError, match="GRASP_PITCH_RAD"):
        GraspParams(pitch_rad=1.2)


@pytest.mark.parametrize("bearing", BEARINGS)
@pytest.mark.parametrize("box_yaw", [0.0, 0.5, 1.3, -2.0])
@pytest.mark.parametrize("with_base", [True, False])
def test_a_top_grasp_comes_down_with_the_jaws_across_the_shorter_side(
    bearing: float, box_yaw: float, with_base: bool
) -> None:
    for T_wb in BASES:
        axis = (D_OPT_M * math.cos(bearing), D_OPT_M * math.sin(bearing), 0.3)
        extent = (0.12, 0.05, 0.16)  # the fit's x is the long side
        det = detection(T_wb, axis, "box", "box", extent, yaw_in_world=box_yaw)
        plan = grasp_from_detection(det, STAMP, T_wb if with_base else None)
        assert plan.kind == "top"
        H = plan.in_world(T_wb)
        R = H[:3, :3]
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0.0
        approach = R @ np.array(plan.approach_axis)
        assert approach[2] < -0.9  # down
        sight = np.array(det.axis_in_world) - _shoulder_in(T_wb)
        assert approach[:2] @ sight[:2] >= 0.0  # tilted away from the robot, not toward it
        short_side = np.array([-math.sin(box_yaw), math.cos(box_yaw), 0.0])
        long_side = np.array([math.cos(box_yaw), math.sin(box_yaw), 0.0])
        closing = R[:, 2]
        assert abs(closing @ long_side) < 1e-9  # the pads meet the long faces
        assert abs(closing @ short_side) > 0.9  # the jaws close across the short side
        top = det.axis_in_world[2] + extent[2] / 2
        assert top - 0.05 < H[2, 3] < top
        # Opened wide, the box's middle TOP_GRASP_OFFSET_M from the TCP toward the moving
        # jaw (the TCP's z), on the box's axis.
        assert plan.jaw == "wide" and plan.reach().jaw == "wide"
        middle = H[:3, 3] + TOP_GRASP_OFFSET_M * closing
        assert np.allclose(middle[:2], np.array(det.axis_in_world)[:2], atol=1e-9)
        # Then it moves over, the fixed pad to the box, and lifts from there.
        assert plan.close_in_m == TOP_CLOSE_IN_M > TOP_GRASP_OFFSET_M
        closed = plan.closed_in()
        assert closed.pregrasp_m == 0.0 and closed.close_in_m == 0.0
        H_in = closed.in_world(T_wb)
        assert np.allclose(H_in[:3, 3], H[:3, 3] + TOP_CLOSE_IN_M * closing, atol=1e-9)
        if with_base:
            lifted = plan.lifted(0.1).H
            assert np.allclose(lifted[:3, 3], H_in[:3, 3] + [0.0, 0.0, 0.1], atol=1e-9)


@pytest.mark.parametrize(
    ("shape", "class_name", "extent", "match"),
    [
        ("centroid", "person", (0.4, 0.4, 1.7), "no grasp for a person"),
        ("cylinder", "bottle", (0.12, 0.12, 0.2), "wider than the jaws"),
        ("cylinder", "bottle", (0.05, 0.05, 0.0), "no visible height"),
        ("box", "bottle", (0.05, 0.05, 0.2), "no grasp for a bottle"),
    ],
)
def test_what_cannot_be_grasped_is_refused_with_a_reason(
    shape: str, class_name: str, extent: tuple[float, float, float], match: str
) -> None:
    T_wb = base_pose(0.0, 0.0, 0.0)
    det = detection(T_wb, (0.7, 0.0, 0.3), shape, class_name, extent)
    with pytest.raises(GraspPoseError, match=match) as err:
        grasp_from_detection(det, STAMP, T_wb)
    assert err.value.reason == str(err.value)


def test_a_short_bottle_is_held_clear_of_its_table() -> None:
    T_wb = base_pose(0.0, 0.0, 0.0)
    det = detection(T_wb, (0.7, 0.0, 0.3), extent=(0.05, 0.05, 0.12))
    plan = grasp_from_detection(det, STAMP, T_wb)
    bottom = 0.3 - 0.06
    assert plan.H[2, 3] >= bottom + GraspParams().clearance_m - 1e-9


def test_a_box_measured_a_little_wider_than_the_jaws_is_still_tried() -> None:
    """Hall seed 15: a 6.2 cm box side measured 8.1 cm from one view (yaw 10° off)."""
    T_wb = base_pose(0.0, 0.0, 0.0)
    det = detection(T_wb, (0.7, 0.0, 0.3), "box", "box", (0.081, 0.13, 0.12))
    assert grasp_from_detection(det, STAMP, T_wb).kind == "top"
    wide = detection(T_wb, (0.7, 0.0, 0.3), "box", "box", (0.095, 0.13, 0.12))
    with pytest.raises(GraspPoseError, match="wider than the jaws"):
        grasp_from_detection(wide, STAMP, T_wb)


def test_backing_out_goes_back_along_the_approach_to_the_pregrasp_pose() -> None:
    T_wb = base_pose(1.0, 2.0, 0.7)
    plan = grasp_from_detection(detection(T_wb, (0.7, 0.0, 0.3)), STAMP, T_wb)
    out = plan.backed_out()
    H, H_out = np.asarray(plan.H), np.asarray(out.H)
    approach = H[:3, :3] @ np.asarray(plan.approach_axis)
    assert np.allclose(H_out[:3, 3], H[:3, 3] - plan.pregrasp_m * approach)
    assert np.allclose(H_out[:3, :3], H[:3, :3]) and out.pregrasp_m == 0.0
    # back toward the robot: the pre-grasp pose is nearer the base than the grasp
    base = T_wb[:3, 3]
    assert np.linalg.norm(H_out[:2, 3] - base[:2]) < np.linalg.norm(H[:2, 3] - base[:2])


@pytest.mark.parametrize("box_yaw", [0.0, 0.6, -0.5, 1.2, 2.77, 3.0])
def test_a_box_too_high_for_a_top_grasp_is_held_from_the_side_across_its_short_side(
    box_yaw: float,
) -> None:
    """Hall seed 15: a 19 cm box on a 0.94 m bench; its top grasp stopped 11.7 cm short.
    From the side along its long faces when they lie near the line of sight; else refused
    (69° off, the arm could not turn the gripper that far at that height)."""
    T_wb = base_pose(1.0, -2.0, 0.4)
    extent = (0.083, 0.062, 0.19)  # the fit's x is the long side
    low = detection(T_wb, (D_OPT_M, 0.0, 0.15), "box", "box", extent, yaw_in_world=box_yaw)
    assert grasp_from_detection(low, STAMP, T_wb).kind == "top"
    high = detection(T_wb, (D_OPT_M, 0.0, 0.49), "box", "box", extent, yaw_in_world=box_yaw)
    sight = np.array(high.axis_in_world) - _shoulder_in(T_wb)
    sight[2] = 0.0
    long_side = np.array([math.cos(box_yaw), math.sin(box_yaw), 0.0])
    off = math.acos(abs(long_side @ sight) / np.linalg.norm(sight))
    if off > GraspParams().box_side_max_off_rad:
        with pytest.raises(GraspPoseError, match=r"out of the arm's reach .* off the line") as e:
            grasp_from_detection(high, STAMP, T_wb)
        # the stance it needs: the line of sight along the long faces (either way)
        stance = e.value.stance_yaw_rad
        assert stance is not None
        assert abs(math.sin(stance - box_yaw)) < 1e-9
        # and from a base on that line, facing the box, the grasp is a side grasp
        box = np.array(high.axis_in_world)
        T_on = base_pose(*(box[:2] - D_OPT_M * np.array([math.cos(stance), math.sin(stance)])),
                         stance)  # fmt: skip
        there = detection(T_on, (D_OPT_M, 0.0, 0.49), "box", "box", extent, yaw_in_world=box_yaw)
        assert grasp_from_detection(there, STAMP, T_on).kind == "side"
        return
    plan = grasp_from_detection(high, STAMP, T_wb)
    assert plan.kind == "side"
    H = plan.H
    R = H[:3, :3]
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0.0
    short_side = np.array([-math.sin(box_yaw), math.cos(box_yaw), 0.0])
    approach = R @ np.array(plan.approach_axis)
    assert approach[2] == pytest.approx(-math.sin(GRASP_PITCH_RAD[1]))  # nose-down
    level = approach[:2] / np.linalg.norm(approach[:2])
    assert abs(abs(level @ long_side[:2]) - 1.0) < 1e-9  # in along the long faces
    assert approach[:2] @ sight[:2] > 0.0  # away from the robot
    assert abs(abs(R[:, 2] @ short_side) - 1.0) < 1e-9  # the jaws close across 6.2 cm
    assert np.isclose(H[2, 3], high.axis_in_world[2])  # half way up
    # its near end BOX_SIDE_DEPTH_M in (not its middle: the jaws have no room), its
    # middle toward the moving jaw, wide open, then closed in: as a top grasp
    back = np.array(high.axis_in_world)[:2] - H[:2, 3]
    in_along = 0.5 * extent[0] - BOX_SIDE_DEPTH_M
    assert back @ level == pytest.approx(in_along, abs=1e-9)
    assert back @ R[:2, 2] == pytest.approx(TOP_GRASP_OFFSET_M, abs=1e-9)
    assert plan.jaw == "wide" and plan.close_in_m == TOP_CLOSE_IN_M


def test_a_low_side_grasp_comes_from_a_little_above_at_the_least_pitch_that_reaches() -> None:
    """Hall seed 11: a can on a 0.72 m table, held level, stopped 2.4 cm short."""
    T_wb = base_pose(2.0, 1.0, -0.5)
    params = GraspParams()
    pitches = []
    for z_axis in (0.45, 0.3, 0.25, 0.2):  # the can's centre above the base, high to low
        can = detection(T_wb, (D_OPT_M, 0.0, z_axis), class_name="can", extent=(0.064, 0.064, 0.12))
        plan = grasp_from_detection(can, STAMP, T_wb, params)
        R = plan.H[:3, :3]
        pitch = math.asin(-R[2, 0])
        assert R[2, 2] == pytest.approx(0.0, abs=1e-9)  # the jaws still close horizontally
        assert GRASP_PITCH_RAD[0] <= pitch <= GRASP_PITCH_RAD[1] + 1e-9
        tcp_base = (inv_T(T_wb) @ plan.H)[:3, 3]
        assert tcp_reach_gap(tcp_base, pitch) <= params.comfort_gap_m
        if pitch > 1e-9:  # and no less pitch would have done
            assert tcp_reach_gap(tcp_base, pitch - 0.05) > params.comfort_gap_m
        pitches.append(pitch)
    assert pitches[0] == pytest.approx(0.0, abs=1e-9)
    assert pitches == sorted(pitches) and pitches[-1] > 0.1


def test_a_bottle_on_the_floor_is_refused_as_out_of_the_arms_reach() -> None:
    """Knocked from the gripper, a bottle stands on the floor by the robot: its side
    grasp lies 30 cm and more below what the arm reaches at the steepest pitch, which no
    stoop of the trunk makes up. Refused, not reached for."""
    T_wb = base_pose(0.0, 0.0, 0.0)
    on_floor = detection(T_wb, (0.7, 0.0, 0.1 - BASE_Z))
    with pytest.raises(GraspPoseError, match="out of the arm's reach"):
        grasp_from_detection(on_floor, STAMP, T_wb)
    on_table = detection(T_wb, (0.7, 0.0, 0.8 - BASE_Z))
    assert grasp_from_detection(on_table, STAMP, T_wb).kind == "side"


def test_what_lies_lower_than_any_grasp_is_said_to() -> None:
    from services.mission.grasp_pose import below_reach, lowest_reach_z_m

    T_wb = base_pose(0.0, 0.0, 0.0)
    assert 0.4 < lowest_reach_z_m() < 0.75  # tables stand 0.7-0.95 m
    lying = detection(T_wb, (1.4, 0.0, 0.03 - BASE_Z), extent=(0.06, 0.06, 0.06))
    assert "below the lowest the gripper reaches" in below_reach(lying)
    assert below_reach(detection(T_wb, (0.7, 0.0, 0.8 - BASE_Z))) == ""


def test_the_plan_says_how_far_the_object_reaches_past_the_gripper() -> None:
    """What the handover holds out toward the person (the TCP's x in the `handover`
    posture): a bottle's far side, a box's height below the top grasp, a tall box's
    length past the near end a side grasp takes (hall seed 1's box_2: 11 cm)."""
    T_wb = base_pose(1.0, -2.0, 0.0)
    bottle = detection(T_wb, (D_OPT_M, 0.0, 0.15), extent=(0.07, 0.07, 0.22))
    assert grasp_from_detection(bottle, STAMP, T_wb).beyond_m == pytest.approx(0.035 - 0.01)
    extent = (0.137, 0.059, 0.194)
    low = detection(T_wb, (D_OPT_M, 0.0, 0.15), "box", "box", extent)
    top = grasp_from_detection(low, STAMP, T_wb)
    assert top.kind == "top"
    assert top.beyond_m == pytest.approx(0.194 - GraspParams().top_depth_m, abs=1e-9)
    high = detection(T_wb, (D_OPT_M, 0.0, 0.49), "box", "box", extent)
    side = grasp_from_detection(high, STAMP, T_wb)
    assert side.kind == "side"
    assert side.beyond_m == pytest.approx(0.137 - BOX_SIDE_DEPTH_M, abs=1e-9)
