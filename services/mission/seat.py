"""Where a side-grasped cylinder sits along the jaws, from the angle the jaw closed at.

The Z1's fixed pad ends 1.9 cm past the TCP (along the TCP's x, toward the tips); its
moving jaw turns about a pivot behind the TCP. A cylinder of radius r lying on the fixed
pad with its axis x_c along the jaws (TCP frame, + toward the tips) stops the moving pad
at an angle that depends on both: `seat_angle` (the pads as the collision boxes
`common.robot.GRIPPER_BOXES`, the jaw's kinematics from pinocchio, the cylinder a circle
in the jaws' plane: a level side grasp). It opens 0.08 rad more for every cm deeper:
hall seed 10's can_3 (r 3.25 cm), grasped in the harness with its axis 2, 1, 0 cm toward
the tips and 1 cm deeper, closed at -0.616, -0.690, -0.767, -0.861 rad (`python -m
bench.wbc_harness seat --world hall --seed 10 --artifact can_3`); the geometry says
-0.640, -0.710, -0.797, -0.908, MuJoCo's soft pads closing `SOFT_RAD` further. Pitched
side grasps are not read (`LEVEL_RAD`): the axis then crosses the jaws' plane, the pad
meets it at an edge, and at 0.3 rad nose-down the same can closed 0.09 rad further than
a rigid 3-D model of it says and hardly opened deeper (harness probe).

That is worth knowing: a carried can creeps toward the tips (1.3 cm a minute walking,
`bench.wbc_harness`), and one held with its axis near the fixed pad's tip falls early.
Hall seed 10's shift fitted can_2 2.5 cm short along the line of sight; the grasp closed
on it 1.5 cm toward the tips instead of 1 cm deeper, and it fell 46 s into the carry.
`seat_x` inverts the angle measured (`WbcStatus.gripper_angle`, once held) to the axis's
place; the mission's `Seated` takes a seat shallower than planned by `SEAT_TOL_M` as a
cue to open, move the jaws deeper by the difference and close again, before the lift.
Pure: numbers in and out (pinocchio's kinematics).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from common import robot
from common.robot_description import MOVER_LINK

#: rad: how much further the jaw closes on a held cylinder in the sim than the rigid
#: geometry says (its soft pads, under the grip's effort): the harness's can_3, 0.02-0.05.
SOFT_RAD = 0.03
#: m: a seat this much shallower than planned (toward the tips) is taken again.
SEAT_TOL_M = 0.012
#: m: the most a re-seat moves the jaws deeper (the palm is 2-3 cm behind a planned seat).
RESEAT_MAX_M = 0.03
#: rad: side grasps pitched more than this are not read (the cylinder's axis then
#: crosses the jaws' plane, and a circle no longer models it).
LEVEL_RAD = 0.15
_BISECT = 40


@functools.cache
def _gripper() -> tuple[Any, Any, int, int, int, float, tuple[np.ndarray, np.ndarray]]:
    """The kinematics once: pinocchio's model and data, the jaw's q index, the TCP and
    mover frames, the fixed pad's face (z, the TCP frame) and the moving pad's face (two
    points, the mover frame)."""
    import pinocchio as pin

    model = robot.load_pinocchio()[0]
    data = model.createData()
    jaw = model.joints[model.getJointId(robot.GRIPPER_JOINT)].idx_q
    tcp = model.getFrameId(robot.TCP_FRAME)
    mover = model.getFrameId(MOVER_LINK, pin.FrameType.BODY)
    fixed = next(b for b in robot.GRIPPER_BOXES if b.name == "gripper_jaw_fixed")
    fixed_z = -float(robot.T_STATOR_TCP[2, 3] - (fixed.center[2] + fixed.half_size[2]))
    pad = next(b for b in robot.GRIPPER_BOXES if b.name == "gripper_jaw_moving")
    z = pad.center[2] - pad.half_size[2]
    face = (np.array([pad.center[0] - pad.half_size[0], 0.0, z]),
            np.array([pad.center[0] + pad.half_size[0], 0.0, z]))  # fmt: skip
    return model, data, jaw, tcp, mover, fixed_z, face


def _gap(angle: float, x_c: float, radius: float) -> float:
    """m between the moving pad's face and a cylinder of `radius` on the fixed pad with
    its axis at `x_c` (the TCP frame), the jaw at `angle`; < 0: they overlap."""
    import pinocchio as pin

    model, data, jaw, tcp, mover, fixed_z, face = _gripper()
    q = pin.neutral(model)
    q[jaw] = angle
    pin.framesForwardKinematics(model, data, q)
    T = data.oMf[tcp].inverse() * data.oMf[mover]
    a, b = T.act(face[0]), T.act(face[1])
    c = np.array([x_c, 0.0, fixed_z + radius])
    ab = b - a
    t = float(np.clip(np.dot(c - a, ab) / np.dot(ab, ab), 0.0, 1.0))
    return float(np.linalg.norm(c - (a + t * ab))) - radius


def seat_angle(x_c: float, radius: float) -> float:
    """The jaw angle (rad, `GRIPPER_WIDE`..`GRIPPER_CLOSED`) at which the moving pad meets
    a cylinder of `radius` lying on the fixed pad, its axis `x_c` along the jaws (the TCP
    frame, + toward the tips), the rigid geometry (less `SOFT_RAD` for the sim's)."""
    lo, hi = robot.GRIPPER_WIDE, robot.GRIPPER_CLOSED  # open: apart; closed: overlapping
    for _ in range(_BISECT):
        mid = 0.5 * (lo + hi)
        if _gap(mid, x_c, radius) > 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def seat_x(angle: float, radius: float) -> float:
    """Where (m, the TCP's x) the axis of a cylinder of `radius` lies when the jaw holding
    it closed at `angle` (measured: `SOFT_RAD` taken off), within [-0.05, 0.05]."""
    target = angle - SOFT_RAD
    lo, hi = -0.05, 0.05  # deeper: the jaw opens more (a smaller angle)
    for _ in range(_BISECT):
        mid = 0.5 * (lo + hi)
        if seat_angle(mid, radius) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
