"""pose_estimation: a grasp pose ᴮH_G for `gripper_tcp` from one perception detection.

The translation comes from the object's axis estimate (perception's cylinder or box
fit, at the visible points' mid-height), the orientation from the fit's shape — better
than the paper's identity rotation:

- side grasp (upright cylinders: bottles, cans): the TCP's x (approach) horizontal along
  the line of sight from the arm's shoulder to the axis, pitched nose-down by the least
  pitch (from `pitch_rad`, within `common.robot.GRASP_PITCH_RAD`) at which the arm alone
  reaches it — low grasps come from a little above; y (the jaw pivot) up along the
  cylinder, so z (fixed jaw → moving jaw) is horizontal and the jaws close across it —
  `services.wbc.reach.side_grasp`'s frame. Held low on the body (a bottle's neck is
  narrow), clear of the surface it stands on, 1 cm deep in the jaws
  (`SIDE_GRASP_DEPTH`). One so wide that the fixed pad would pass it with less than
  `SIDE_PAD_ROOM_M` comes in wide open with its axis toward the moving jaw and closes
  in to the same pose, as a box does (`cylinder_offset`).
- top grasp (boxes): x down (tilted `top_tilt_rad` away from the robot, for reach), z
  across the box's shorter side, perpendicular to its long faces (the sign nearer the
  line of sight: the least wrist roll from the arm's natural pose), y = z × x; the TCP
  just below the top face, coming down in the jaws opened wide with the box's middle a
  little toward the moving jaw, then moving over to bring the fixed jaw to the box
  (`TOP_GRASP_OFFSET_M`, `TOP_CLOSE_IN_M`). A box whose top grasp lies out of the arm's reach
  (`common.robot.tcp_reach_gap` over `reach_slack_m`: a tall box on a bench) is held
  from the side instead: x along its long faces (the sign away from the shoulder),
  nose-down, the jaws closing across its shorter side, at half its visible height, its
  near end `BOX_SIDE_DEPTH_M` in, wide open and closed in as a top grasp — if those
  faces are within `box_side_max_off_rad` of the line of sight; otherwise it is
  refused with the reason and the yaw of those faces (`GraspPoseError.stance_yaw_rad`):
  the mission walks to a stance along them and tries again.

Frames, as the WBC's Reach reads them (`services.wbc.arm_actions`): with the base pose at
capture (`Detections.T_world_base`) the plan is in `world` — fixed, exact, whenever it is
sent. Without it the plan is in `base` as of the detection's stamp, built in `base_yaw`
(the WBC's `base` includes the trunk's pitch and roll, a few mm at arm's length while
standing) and it must reach the WBC within its 2 s pose history. `approach_axis` is in
H's own (TCP) frame, as `Reach` wants it: always the TCP's x.

Pure numpy on msgspec values; no transport.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from common import robot
from common.geometry import FloatArray, inv_T, make_T, rot_z
from common.messages.perception import Detection
from common.messages.wbc import Reach
from common.robot import GRASP_PITCH_RAD, arm_plane, tcp_reach_gap

#: Classes whose upright cylinder fit gets a side grasp, and where along the visible
#: height (0 bottom, 1 top) the TCP holds it: a bottle's body is its lower 3/4.
SIDE_GRASP_HEIGHT = {"bottle": 0.375, "can": 0.5}
#: How far (m) past the fitted axis, along the line of sight, a side grasp puts the TCP:
#: the object deeper in the jaws. The moving jaw's pad is 4.5 cm long and ends about 1 cm
#: past the TCP, and the jaws' wedge pushes a held cylinder toward their tips; hall seed
#: 3's bottle (r 2.4 cm), its axis fitted 1.4 cm short, sat 3 mm from that pad's end,
#: crept 7 mm out over a 45 s carry and fell as the arm presented it. A bottle 1 cm
#: deeper creeps no faster (`tests/unit/test_robot.py`) and a 3 cm one still clears the
#: open jaw by 6.7 mm on the way in. A can creeps out as a walk goes on (hall seed 10's
#: 6.5 cm can_3 turning on the spot: `bench.wbc_harness` carry --walk): held at its axis
#: it fell after 66 s, 1 cm deeper after 106 s, 2 cm after 118 s; 1 cm leaves the
#: widest can 12.9 mm from the palm on the way in, room for a fit that long.
SIDE_GRASP_DEPTH = {"bottle": 0.01, "can": 0.01}
#: m: how far a re-seat (`GraspPlan.reseated`) takes the fixed pad off the object first.
RESEAT_ROOM_M = 0.008
_FIXED_PAD = next(b for b in robot.GRIPPER_BOXES if b.name == "gripper_jaw_fixed")
#: m: the fixed jaw's pad from the TCP, across the jaws (3.5 cm).
FIXED_PAD_FROM_TCP_M = float(
    robot.T_STATOR_TCP[2, 3] - (_FIXED_PAD.center[2] + _FIXED_PAD.half_size[2])
)
#: m: the least room a side grasp of a cylinder leaves between the fixed pad and the
#: fitted surface on the way in. Centred, a 6.5 cm can had 2.5 mm: hall seed 10's
#: shift fitted can_1 1.5 cm toward the fixed jaw, whose tip met the can and pushed it
#: 3.5-4 cm along the bench at each of three tries (the jaw closed on nothing twice,
#: then the reach stopped 17 cm short). A cylinder with less room comes in wide open with
#: its axis that much toward the moving jaw, then closes in to the pose it had centred
#: (`cylinder_offset`), as a box does.
SIDE_PAD_ROOM_M = 0.015
TOP_GRASP_CLASSES = ("box",)
#: How far (m) toward the moving jaw a top grasp comes down with the box's middle, in the
#: jaws opened wide (`robot.GRIPPER_WIDE`), and how far it then moves over (`closed_in`)
#: before the jaw closes: the fixed pad 1.5 mm from a 6.3 cm box's face. The TCP sits
#: 3.5 cm from the fixed pad, made for a 6 cm bottle; a 6.3 cm box centred on it had 3.5 mm
#: to the fixed jaw and 2.8 mm to the open moving one, and hall seed 0's top grasp stopped
#: 4.5 cm into its descent, the fixed pad's tip corner on the box's top edge (with 9.5 mm
#: of room, too: the box's middle 4.4 mm off the plan and 2.4° of twist took it). Coming
#: down 12 mm over: 15.5 mm to the fixed jaw, 21.6 mm to the moving one. Closed from
#: there, the moving jaw pressed a 6.9 cm box down onto its table and did not push it
#: across (hall seed 17): held 15 mm off the fixed pad, in a 56° wedge, it crept out and
#: fell during the carry; hence the fixed pad is brought to the box first.
TOP_GRASP_OFFSET_M = 0.012
TOP_CLOSE_IN_M = 0.014
#: Where a box too high for a top grasp is held from the side (0 bottom, 1 top).
BOX_SIDE_HEIGHT = 0.5
#: How far (m) a box held from the side, along its long faces, goes in behind the TCP:
#: its near end that far in, not its middle. The jaws open take a 5.9 cm box only 3.45 cm
#: behind the TCP; held at its middle, hall seed 1's 13.7 cm box met the fixed jaw with
#: the TCP 11 cm out and the reach stopped 10.2 cm short (the whole-body controller in
#: MuJoCo: from 2.5 cm in, wide open and closed in as a top grasp, it reached within
#: 4-6 mm, held it and lifted it, from along its long faces to 23° off them).
BOX_SIDE_DEPTH_M = 0.025
#: The side grasps' pitches tried, from `GraspParams.pitch_rad` up (rad).
PITCH_STEP_RAD = 0.05


class GraspPoseError(Exception):
    """No grasp can be planned for this detection; `reason` says why, for a person.

    `stance_yaw_rad`: the grasp is possible from another stance: the line of sight along
    this yaw (in the plan's frame, either sign: a box's long faces), else None."""

    def __init__(self, reason: str, stance_yaw_rad: float | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.stance_yaw_rad = stance_yaw_rad


@dataclass(frozen=True)
class GraspParams:
    """Not settings (no `MissionSettings` field mirrors them): the grasp geometry's own
    numbers, overridden only by tests and benches.

    pitch_rad: side grasps' least nose-down pitch, raised (within GRASP_PITCH_RAD) until
    the arm alone reaches the grasp within comfort_gap_m (`common.robot.
    tcp_reach_gap`: the whole-body controller stoops the trunk for the rest);
    top_tilt_rad: top grasps' tilt from vertical toward the robot; clearance_m: the TCP
    at least this far above the visible bottom (the gripper reaches 4 cm below its TCP);
    top_depth_m: top grasps' TCP below the top face (4.5 cm: a box held only by its upper
    part creeps out of the jaws' wedge as the robot walks, 0.2-0.3 mm/s for a 6.8 cm box
    in a 54° wedge, and fell from 3 cm after 40 s of carrying, hall seed 16);
    pregrasp_m: the approach starts this far back; max_width_m: the widest the jaws hold;
    width_slack_m: a measured width up to this much wider is still tried (one view's fit
    overestimates: hall seed 15's box measured 8.1 cm across its 6.2 cm side, its yaw
    10° off, and the closing jaws turn a box square); reach_slack_m: a box whose top
    grasp lies further than this outside the arm's reach (`common.robot.tcp_reach_gap`;
    the trunk gives a few cm more) is taken from the side instead, nose-down at
    GRASP_PITCH_RAD's top (held level, the forearm met the support), when its long
    faces lie within box_side_max_off_rad of the line of sight; else it is refused (hall
    seed 15: a 19 cm box on a 0.94 m bench, short side to the robot: the top grasp stopped
    11.7 cm short with the gripper on the bench; a side grasp 69° off, level, met the
    bench with the forearm, nose-down, ended 1.3-3 cm / 4-15° off in three tries; held
    `BOX_SIDE_DEPTH_M` in, hall seed 1's box was held from along its faces to 23° off
    them, not from 30°: 25°, and the mission walks to a stance along them for more)."""

    pitch_rad: float = 0.0
    comfort_gap_m: float = 0.02
    top_tilt_rad: float = 0.3
    clearance_m: float = 0.05
    top_depth_m: float = 0.045
    pregrasp_m: float = 0.12
    max_width_m: float = 0.075
    width_slack_m: float = 0.015
    reach_slack_m: float = 0.06
    box_side_max_off_rad: float = math.radians(25.0)

    def __post_init__(self) -> None:
        lo, hi = GRASP_PITCH_RAD
        if not lo <= self.pitch_rad <= hi:
            raise ValueError(f"pitch_rad {self.pitch_rad} is outside GRASP_PITCH_RAD {lo, hi}")
        if not 0.0 <= self.top_tilt_rad < math.pi / 2:
            raise ValueError(f"top_tilt_rad {self.top_tilt_rad} must be in [0, pi/2)")


@dataclass(frozen=True)
class GraspPlan:
    """H: `gripper_tcp`'s goal (4×4) in `frame` as of `stamp_ns`; approach_axis in H's own
    frame; pregrasp_m back along it; kind: side or top; jaw: how far the empty jaw opens
    for it (`Reach.jaw`); close_in_m: how far the TCP then moves along its z (the fixed
    pad to the object) before the jaw closes; beyond_m: how far the object held reaches
    past the TCP along its x (the arm's `handover` posture points x at the person: a box
    held by its near end reaches 11 cm out, a bottle 2-3 cm); radius_m: a side-grasped
    cylinder's fitted radius (0: not one), seat_x_m: where its axis is to lie along the
    TCP's x (`seat`: where the jaw's angle says it does)."""

    H: FloatArray
    frame: Literal["base", "world"]
    approach_axis: tuple[float, float, float]
    pregrasp_m: float
    kind: Literal["side", "top"]
    stamp_ns: int
    jaw: Literal["open", "wide"] = "open"
    close_in_m: float = 0.0
    beyond_m: float = 0.0
    radius_m: float = 0.0
    seat_x_m: float = 0.0

    def reach(self) -> Reach:
        """The WBC's arm goal for this plan."""
        return Reach(
            H=tuple(float(x) for x in np.asarray(self.H, dtype=float).ravel()),
            frame=self.frame,
            stamp_ns=self.stamp_ns,
            approach_axis=self.approach_axis,
            pregrasp_m=self.pregrasp_m,
            jaw=self.jaw,
        )

    def closed_in(self) -> GraspPlan:
        """The grasp pose moved `close_in_m` along the TCP's z, reached straight: where
        the jaw closes."""
        H = np.array(self.H, dtype=float)
        H[:3, 3] += self.close_in_m * H[:3, 2]
        return replace(self, H=H, pregrasp_m=0.0, close_in_m=0.0)

    def lifted(self, dz_m: float) -> GraspPlan:
        """The closed-in grasp pose raised `dz_m` in the world, reached straight (no
        pre-grasp): the lift that takes the object off its surface before stowing."""
        if self.frame != "world":
            raise GraspPoseError("a lift needs a world-frame plan (give T_world_base)")
        H = np.array(self.closed_in().H, dtype=float)
        H[2, 3] += dz_m
        return replace(self, H=H, pregrasp_m=0.0, close_in_m=0.0)

    def pulled_back(self, dz_m: float, back_m: float, heading_rad: float) -> GraspPlan:
        """The lift's pose (`lifted`) moved `back_m` level against `heading_rad` (the
        base's heading, world), reached straight: a held object drawn toward the robot
        before the base backs off for the stow (`stow_room`)."""
        H = np.array(self.lifted(dz_m).H, dtype=float)
        H[0, 3] -= back_m * math.cos(heading_rad)
        H[1, 3] -= back_m * math.sin(heading_rad)
        return replace(self, H=H, pregrasp_m=0.0, close_in_m=0.0)

    def reseated(self, deeper_m: float) -> GraspPlan:
        """The closed-in grasp pose moved `deeper_m` along the TCP's x (the object that much
        nearer the palm), come to wide open and `RESEAT_ROOM_M` off toward the moving jaw
        (the fixed pad clear of the object) and closed in from there, reached straight: a
        cylinder held shallower than planned taken again where it stands (`seat`)."""
        H = np.array(self.closed_in().H, dtype=float)
        H[:3, 3] += deeper_m * H[:3, 0] - RESEAT_ROOM_M * H[:3, 2]
        return replace(self, H=H, pregrasp_m=0.0, jaw="wide", close_in_m=RESEAT_ROOM_M)

    def over_the_spot(self, dz_m: float) -> GraspPlan:
        """The lift's pose (`lifted`), reached via the pre-grasp pose as the grasp was: how
        a held object is carried back over the place it was picked from."""
        return replace(self.lifted(dz_m), pregrasp_m=self.pregrasp_m)

    def backed_out(self) -> GraspPlan:
        """The pre-grasp pose (H moved `pregrasp_m` back along the approach), reached
        straight: how the gripper leaves an object it did not pick, before the base walks."""
        H = np.array(self.H, dtype=float)
        axis = np.asarray(self.approach_axis, dtype=float)
        H[:3, 3] -= self.pregrasp_m * (H[:3, :3] @ (axis / max(float(np.linalg.norm(axis)), 1e-9)))
        return replace(self, H=H, pregrasp_m=0.0)

    def in_world(self, T_world_base: FloatArray) -> FloatArray:
        """H in the world, given the base pose at the plan's stamp (for a `base` plan)."""
        H = np.asarray(self.H, dtype=float)
        return H if self.frame == "world" else np.asarray(T_world_base, float) @ H


def _finite(name: str, x: tuple[float, ...]) -> FloatArray:
    a = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(a)):
        raise GraspPoseError(f"the detection's {name} is not finite: {list(x)}")
    return a


def side_rotation(approach_xy: FloatArray, pitch_rad: float) -> FloatArray:
    """TCP rotation (z-up frame) of a side grasp: x along `approach_xy` pitched down, y up."""
    a = np.array([approach_xy[0], approach_xy[1], 0.0])
    x = a / np.linalg.norm(a)
    y = np.array([0.0, 0.0, 1.0])
    R_level = np.column_stack([x, y, np.cross(x, y)])
    return np.asarray(R_level @ rot_z(-pitch_rad))  # about the TCP's z: nose down


def top_rotation(approach_xy: FloatArray, across: FloatArray, tilt_rad: float) -> FloatArray:
    """TCP rotation (z-up frame) of a top grasp: x down, tilted by `tilt_rad` toward
    `approach_xy`; z (the jaws' closing) perpendicular to x and to the box's long side (so
    both pads meet the long faces), along ±`across` (the sign nearer `approach_xy`)."""
    a = np.array([approach_xy[0], approach_xy[1], 0.0])
    a /= np.linalg.norm(a)
    u = np.array([across[0], across[1], 0.0])
    u /= np.linalg.norm(u)
    long_side = np.array([-u[1], u[0], 0.0])
    x = math.sin(tilt_rad) * a - math.cos(tilt_rad) * np.array([0.0, 0.0, 1.0])
    z = np.cross(x, long_side)
    z /= np.linalg.norm(z)
    if z @ a < 0.0 or (abs(z @ a) < 1e-9 and z @ u < 0.0):
        z = -z
    return np.column_stack([x, np.cross(z, x), z])


def _base_yaw_in_world(det: Detection, T_world_base: FloatArray | None) -> FloatArray | None:
    """T_world_base_yaw: from the base pose when given, else from the detection's two point
    pairs (axis and centroid, in both frames) when they are far enough apart."""
    if T_world_base is not None:
        T = np.asarray(T_world_base, dtype=float)
        yaw = math.atan2(T[1, 0], T[0, 0])
        return make_T(rot_z(yaw), T[:3, 3])
    d_by = np.subtract(det.centroid_in_base_yaw, det.axis_in_base_yaw)[:2]
    d_w = np.subtract(det.centroid_in_world, det.axis_in_world)[:2]
    if np.linalg.norm(d_by) < 0.01 or np.linalg.norm(d_w) < 0.01:
        return None
    yaw = math.atan2(d_w[1], d_w[0]) - math.atan2(d_by[1], d_by[0])
    R = rot_z(yaw)
    return make_T(R, np.asarray(det.axis_in_world) - R @ np.asarray(det.axis_in_base_yaw))


def grasp_from_detection(
    det: Detection,
    stamp_ns: int,
    T_world_base: FloatArray | None = None,
    params: GraspParams | None = None,
) -> GraspPlan:
    """The grasp for `det` (captured at `stamp_ns`); `T_world_base` (4×4, the base at
    capture, e.g. `Detections.T_world_base`) makes it a world-frame plan. Raises
    `GraspPoseError` when the detection cannot be grasped (shape, size, bad numbers)."""
    p = params or GraspParams()
    if det.shape == "cylinder" and det.class_name in SIDE_GRASP_HEIGHT:
        kind: Literal["side", "top"] = "side"
    elif det.shape == "box" and det.class_name in TOP_GRASP_CLASSES:
        kind = "top"
    else:
        raise GraspPoseError(
            f"no grasp for a {det.class_name} fitted as {det.shape!r}: side grasps take "
            f"upright {'/'.join(SIDE_GRASP_HEIGHT)} cylinders, top grasps boxes"
        )
    extent = _finite("extent", det.extent)
    if det.n_points <= 0 or extent[2] <= 0.0:
        raise GraspPoseError(f"the {det.class_name} has no visible height ({det.n_points} points)")
    width = float(min(extent[0], extent[1]))
    if width > p.max_width_m + p.width_slack_m:
        raise GraspPoseError(
            f"the {det.class_name} is {width * 100:.1f} cm across: wider than the jaws "
            f"hold ({p.max_width_m * 100:.1f} cm, {p.width_slack_m * 100:.1f} cm allowed "
            "for the fit)"
        )
    T_w_by = _base_yaw_in_world(det, T_world_base)
    world = T_world_base is not None
    axis = _finite("axis", det.axis_in_world if world else det.axis_in_base_yaw)
    sx, sz = arm_plane()["shoulder"]
    shoulder = np.array([sx, 0.0, sz])
    if T_world_base is not None:
        T_wb = np.asarray(T_world_base, dtype=float)
        shoulder = T_wb[:3, :3] @ shoulder + T_wb[:3, 3]
    sight = (axis - shoulder)[:2]
    if np.linalg.norm(sight) < 0.05:
        raise GraspPoseError(f"the {det.class_name} is at the shoulder: no line of sight")
    bottom, top = axis[2] - 0.5 * extent[2], axis[2] + 0.5 * extent[2]
    centre = axis.copy()
    radius = seat = 0.0  # a cylinder's, side-grasped (`seat`)
    if kind == "side":
        z = bottom + SIDE_GRASP_HEIGHT[det.class_name] * extent[2]
        centre[2] = min(max(z, bottom + p.clearance_m), top - 0.01)
        centre[:2] += SIDE_GRASP_DEPTH[det.class_name] * sight / np.linalg.norm(sight)
        beyond = 0.5 * width - SIDE_GRASP_DEPTH[det.class_name]
        pitch = _side_pitch(centre, T_world_base, p)
        gap = tcp_reach_gap(_in_base(centre, T_world_base), pitch)
        if gap > p.reach_slack_m:  # on the floor: the trunk cannot stoop that far
            raise GraspPoseError(
                f"the {det.class_name}'s side grasp is out of the arm's reach "
                f"({gap * 100:.0f} cm beyond it at the steepest pitch, "
                f"{p.reach_slack_m * 100:.0f} cm allowed for the trunk's stoop)"
            )
        R = side_rotation(sight, pitch)
        radius, seat = 0.5 * width, -SIDE_GRASP_DEPTH[det.class_name]
    else:
        yaw = det.yaw_in_world
        if not world:
            if T_w_by is None:
                raise GraspPoseError(
                    "a box's yaw is in the world: its grasp needs the base pose at capture "
                    "(T_world_base)"
                )
            yaw -= math.atan2(T_w_by[1, 0], T_w_by[0, 0])
        fit_x = np.array([math.cos(yaw), math.sin(yaw)])
        across = fit_x if extent[0] <= extent[1] else np.array([-fit_x[1], fit_x[0]])
        centre[2] = max(top - p.top_depth_m, axis[2])
        beyond = float(centre[2] - bottom)  # x is down: the box hangs below the TCP
        R = top_rotation(sight, across, p.top_tilt_rad)
        gap = _top_gap(R, centre, T_world_base)
        if gap > p.reach_slack_m:
            # Too high for a top grasp: from the side, along the long faces, from above.
            along = np.array([-across[1], across[0]])
            along = along if along @ sight >= 0.0 else -along
            off = math.acos(min(1.0, float(along @ sight) / float(np.linalg.norm(sight))))
            if off > p.box_side_max_off_rad:
                raise GraspPoseError(
                    f"the {det.class_name}'s top is out of the arm's reach ({gap * 100:.0f} cm) "
                    f"and its long faces are {math.degrees(off):.0f}° off the line of sight "
                    f"(at most {math.degrees(p.box_side_max_off_rad):.0f}° for a side grasp): "
                    "it needs a stance along its long side",
                    stance_yaw_rad=math.atan2(float(along[1]), float(along[0])),
                )
            kind = "side"
            z = bottom + BOX_SIDE_HEIGHT * extent[2]
            centre = axis.copy()
            centre[2] = min(max(z, bottom + p.clearance_m), top - 0.01)
            half_long = 0.5 * float(max(extent[0], extent[1]))
            centre[:2] -= max(0.0, half_long - BOX_SIDE_DEPTH_M) * along
            beyond = 2.0 * half_long - min(BOX_SIDE_DEPTH_M, half_long)
            R = side_rotation(along, GRASP_PITCH_RAD[1])
    if det.class_name in TOP_GRASP_CLASSES:  # a box, from above or from the side
        offset, close_in = TOP_GRASP_OFFSET_M, TOP_CLOSE_IN_M
    else:  # a cylinder: as centred, unless the fixed pad has too little room on the way in
        offset = close_in = cylinder_offset(width)
    wide = offset > 0.0
    if wide:  # in the wide-open jaws, the object's middle toward the moving jaw
        centre -= offset * R[:, 2]
    return GraspPlan(
        H=make_T(R, centre),
        frame="world" if world else "base",
        approach_axis=(1.0, 0.0, 0.0),
        pregrasp_m=p.pregrasp_m,
        kind=kind,
        stamp_ns=stamp_ns,
        jaw="wide" if wide else "open",
        close_in_m=close_in,
        beyond_m=max(0.0, beyond),
        radius_m=radius,
        seat_x_m=seat,
    )


def cylinder_offset(width_m: float) -> float:
    """How far (m) toward the moving jaw a side grasp brings a cylinder `width_m` across
    in, so the fixed pad passes it with `SIDE_PAD_ROOM_M` (0: centred, room enough)."""
    return max(0.0, SIDE_PAD_ROOM_M - (FIXED_PAD_FROM_TCP_M - 0.5 * width_m))


@functools.cache
def lowest_reach_z_m(slack_m: float = GraspParams.reach_slack_m) -> float:
    """The lowest world height (m) a side grasp reaches from the approach's standoff
    (`D_OPT_M` ahead, standing) at any pitch it may take, within `slack_m` of the arm's
    reach (the trunk's stoop): about 0.6 m. Nothing with its top below it is picked."""
    base_z, ahead = robot.STAND_BASE_HEIGHT_M, robot.D_OPT_M  # computed on first access
    for z in np.arange(0.0, 1.2, 0.01):
        p_base = np.array([ahead, 0.0, float(z) - base_z])
        pitches = np.arange(GRASP_PITCH_RAD[0], GRASP_PITCH_RAD[1] + 1e-9, PITCH_STEP_RAD)
        if min(tcp_reach_gap(p_base, float(p)) for p in pitches) <= slack_m:
            return float(z)
    return math.inf


def below_reach(det: Detection) -> str:
    """Why a detected object lies too low for any grasp (its top below `lowest_reach_z_m`:
    on the floor, fallen from the gripper), or "" when it does not; world heights."""
    top = float(det.axis_in_world[2]) + 0.5 * float(det.extent[2])
    lowest = lowest_reach_z_m()
    if not math.isfinite(top) or top >= lowest:
        return ""
    return f"its top at {top:.2f} m lies below the lowest the gripper reaches ({lowest:.2f} m)"


def _in_base(centre: FloatArray, T_world_base: FloatArray | None) -> FloatArray:
    if T_world_base is None:
        return centre
    return (inv_T(np.asarray(T_world_base, dtype=float)) @ np.append(centre, 1.0))[:3]


def _top_gap(R: FloatArray, centre: FloatArray, T_world_base: FloatArray | None) -> float:
    """`common.robot.tcp_reach_gap` of a top grasp (TCP `centre`, rotation `R`, in the
    world when `T_world_base` is given, else in the base): how far out of the arm's reach."""
    x = R[:, 0]
    pitch = math.atan2(-float(x[2]), float(np.hypot(x[0], x[1])))
    return tcp_reach_gap(_in_base(centre, T_world_base), pitch)


def _side_pitch(centre: FloatArray, T_world_base: FloatArray | None, p: GraspParams) -> float:
    """The least nose-down pitch from `p.pitch_rad` up to `GRASP_PITCH_RAD`'s top (in
    `PITCH_STEP_RAD`) at which the arm alone reaches the TCP within `p.comfort_gap_m`;
    the best of them when none does. A low side grasp held level needs the trunk to
    stoop for it (hall seed 11: a can on a 0.72 m table, its level reach 2.4 cm short)."""
    p_base = _in_base(centre, T_world_base)
    best = (math.inf, p.pitch_rad)
    for pitch in np.arange(p.pitch_rad, GRASP_PITCH_RAD[1] + 1e-9, PITCH_STEP_RAD):
        gap = tcp_reach_gap(p_base, float(pitch))
        if gap <= p.comfort_gap_m:
            return float(pitch)
        best = min(best, (gap, float(pitch)))
    return best[1]


def plan_error(H_plan_world: FloatArray, H_truth_world: FloatArray) -> tuple[float, float]:
    """(distance m, rotation rad) between two world poses, e.g. a plan and the truth's."""
    d = float(np.linalg.norm(H_plan_world[:3, 3] - H_truth_world[:3, 3]))
    R = inv_T(H_truth_world)[:3, :3] @ H_plan_world[:3, :3]
    return d, float(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))))
