"""The mission's own base motions stop short of the static world: navigation publishes the
clearance along each of the base's axes (`body_guard.clearance`, on `nav/status`) and the
mission's cmd_vel goes out within the room it leaves the body (`within_room`).

The scene: a bench (a solid block, as the hall's are) whose front edge lies at x = 1.0,
the base facing it. Hall seed 0's shift approached a bottle 0.3 m deep on a bench and
pressed the front hip into the bench's front until the approach's stall gave up.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.config import ApproachSettings
from common.robot import posture_front_m
from services.mission.approach import ApproachCommand, ApproachController, Sighting
from services.mission.robot import ROOM_KEEP_M, within_room
from services.navigation.body_guard import MARGIN_M, clearance
from services.navigation.grid import Footprint, Grid, Pose

FP = Footprint.stowed()
RES = 0.05
EDGE = 1.0
GROW = MARGIN_M + 0.5 * RES
DT = 0.02


def _bench(x0: float = EDGE, x1: float = EDGE + 0.7, y0: float = -1.0, y1: float = 1.0) -> Grid:
    occ = np.zeros((120, 120), dtype=bool)
    c = -3.0 + (np.arange(120) + 0.5) * RES
    occ[(c[:, None] > y0) & (c[:, None] < y1) & (c[None, :] > x0) & (c[None, :] < x1)] = True
    return Grid(occ, RES, (-3.0, -3.0))


def _body(posture: str) -> tuple[float, float, float, float]:
    return (posture_front_m(posture), FP.back, FP.half_width, FP.half_width)


def test_the_clearance_is_the_distance_to_the_nearest_obstacle_in_the_band_each_axis_sweeps() -> (
    None
):
    grid = _bench()
    ahead, behind, left, right = clearance(grid.occupied, grid, FP, Pose(0.0, 0.0, 0.0))
    assert ahead == pytest.approx(EDGE + 0.5 * RES - GROW, abs=1e-9)  # the first cell's centre
    assert behind == left == right == math.inf
    # Turned to face +y, the bench lies to the right; beyond the reach, nothing.
    ahead, behind, left, right = clearance(grid.occupied, grid, FP, Pose(0.3, 0.0, math.pi / 2))
    assert right == pytest.approx(0.7 + 0.5 * RES - GROW, abs=1e-9)
    assert ahead == behind == left == math.inf
    far = clearance(grid.occupied, grid, FP, Pose(-1.2, 0.0, 0.0))
    assert far == (math.inf,) * 4
    # A cell under the body counts where it lies: the body may only move off it.
    under = _bench(x0=0.1, x1=0.2, y0=-0.05, y1=0.05)
    ahead, behind, *_ = clearance(under.occupied, under, FP, Pose(0.0, 0.0, 0.0))
    assert ahead < FP.front and behind == math.inf


def test_the_mission_command_goes_out_within_the_room_the_body_has() -> None:
    body = (0.435, 0.62, 0.24, 0.24)
    clear = (0.6, 0.7, math.inf, 0.25)
    room = 0.6 - 0.435 - ROOM_KEEP_M
    (vx, vy, wz), cut = within_room((0.25, 0.0, 0.3), clear, body)
    assert cut and vx == pytest.approx(room) and (vy, wz) == (0.0, 0.3)  # turns pass
    assert within_room((0.1, 0.0, 0.0), clear, body) == ((0.1, 0.0, 0.0), False)
    (vx, _, _), cut = within_room((-0.1, 0.0, 0.0), clear, body)
    assert cut and vx == pytest.approx(-(0.7 - 0.62 - ROOM_KEEP_M))
    assert within_room((0.0, 0.3, 0.0), clear, body) == ((0.0, 0.3, 0.0), False)
    assert within_room((0.0, -0.1, 0.0), clear, body) == ((0.0, -0.0, 0.0), True)
    assert within_room((0.2, 0.0, 0.0), None, body) == ((0.2, 0.0, 0.0), False)
    inside = (0.3, 0.7, math.inf, math.inf)  # the legs' front past the obstacle already
    assert within_room((0.2, 0.0, 0.0), inside, body)[0] == (0.0, 0.0, 0.0)


def _approach(depth_m: float) -> tuple[ApproachCommand, float]:
    """The approach to an object `depth_m` beyond the bench's front edge, from 1.2 m off,
    its commands within the room (the clearance from the plant's pose each tick, as
    navigation publishes it): the last command and the least room the legs had."""
    grid, obj = _bench(), np.array([EDGE + depth_m, 0.05])
    ctrl = ApproachController(ApproachSettings())
    ctrl.reset(0.0)
    pose, newest, least = np.array([EDGE - 1.2, 0.0, 0.0]), None, math.inf
    front = posture_front_m("look")
    for k in range(round(40.0 / DT)):
        t = k * DT
        x, y, yaw = pose
        if k % 5 == 0:  # 10 Hz frames, used at once
            dx, dy = obj - (x, y)
            c, s = math.cos(yaw), math.sin(yaw)
            bx, by = c * dx + s * dy, -s * dx + c * dy
            newest = Sighting(math.hypot(bx, by), math.atan2(by, bx), t)
        cmd = ctrl.step(t, newest)
        if cmd.state in ("arrived", "failed"):
            return cmd, least
        clear = clearance(grid.occupied, grid, FP, Pose(float(x), float(y), float(yaw)))
        (vx, vy, wz), _ = within_room((cmd.vx, cmd.vy, cmd.wz), clear, _body("look"))
        least = min(least, EDGE - (x + front * math.cos(yaw)))
        c, s = math.cos(yaw), math.sin(yaw)
        pose = pose + DT * np.array([c * vx - s * vy, s * vx + c * vy, wz])
    raise AssertionError("the approach neither arrived nor failed in 40 s")


@pytest.mark.parametrize("depth_m", [0.3, 0.4])
def test_an_object_deep_on_a_bench_is_approached_until_the_legs_stop_short_of_it(
    depth_m: float,
) -> None:
    cmd, least = _approach(depth_m)
    assert cmd.state == "arrived" and cmd.reason.startswith("blocked"), cmd
    # The legs came within a few cm of the bench's front and never reached it.
    assert ROOM_KEEP_M - 0.01 <= least <= ROOM_KEEP_M + 0.06


def test_an_object_near_the_front_edge_is_approached_to_d_opt_as_before() -> None:
    cmd, least = _approach(0.15)
    assert cmd.state == "arrived" and not cmd.reason.startswith("blocked"), cmd
    assert least > ROOM_KEEP_M
