"""Scan-to-map matching and the localizer on scans ray-cast in a synthetic room: it
finds the pose from decimetres off, people in the scan do not drag it, a start pose off
by 0.5 m and 10° converges, and a scan that fits no map is refused until lost. On noisy
scans of true geometry the map rasterises as the sim does (a cell is occupied when a
box overlaps it): the pose is off by the map's own quantisation and no more, and beams
that end inside a mapped obstacle (a desk's panel under its top) do not drag it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench import raycast
from bench.raycast import slab_ranges
from common import robot
from common.config import LocalizationSettings
from common.scan import scan_points
from services.localization.localizer import Localizer, compose, inverse
from services.localization.matcher import LikelihoodField, refine, search

RES = 0.05
ORIGIN = (-1.0, -1.0)
T_BASE_LIDAR = robot.LIDAR_MOUNT.T_parent_lidar
ANGLES = np.radians(np.linspace(-135.0, 135.0, 541))


def room() -> np.ndarray:
    """A 12 × 10 m room (walls 10 cm), a machine, two pallets and a pillar."""
    occ = np.zeros((240, 280), dtype=bool)  # 14 × 12 m from (-1, -1)

    def box(x0: float, y0: float, x1: float, y1: float) -> None:
        i0, i1 = round((y0 - ORIGIN[1]) / RES), round((y1 - ORIGIN[1]) / RES)
        j0, j1 = round((x0 - ORIGIN[0]) / RES), round((x1 - ORIGIN[0]) / RES)
        occ[i0:i1, j0:j1] = True

    box(0.0, 0.0, 12.0, 0.1)
    box(0.0, 9.9, 12.0, 10.0)
    box(0.0, 0.0, 0.1, 10.0)
    box(11.9, 0.0, 12.0, 10.0)
    box(3.0, 6.0, 5.0, 7.5)
    box(8.0, 2.0, 9.2, 3.0)
    box(9.5, 6.5, 10.5, 7.3)
    box(6.0, 4.0, 6.3, 4.3)
    return occ


OCC = room()
FIELD = LikelihoodField.of_grid(OCC, RES, ORIGIN)


def cast(pose: tuple[float, float, float], people: list[tuple[float, float]] = ()) -> np.ndarray:
    """The lidar's ranges from the base at `pose`: the first occupied cell (or person, a
    0.25 m disc) along each beam, 1 cm steps, 0 beyond 10 m."""
    T = T_BASE_LIDAR
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    ox = x + c * T[0, 3] - s * T[1, 3]
    oy = y + s * T[0, 3] + c * T[1, 3]
    r = np.arange(0.1, 10.0, 0.01)
    out = np.zeros(len(ANGLES))
    for k, a in enumerate(ANGLES):
        px, py = ox + r * math.cos(yaw + a), oy + r * math.sin(yaw + a)
        j = np.floor((px - ORIGIN[0]) / RES).astype(int)
        i = np.floor((py - ORIGIN[1]) / RES).astype(int)
        hit = OCC[np.clip(i, 0, OCC.shape[0] - 1), np.clip(j, 0, OCC.shape[1] - 1)]
        for qx, qy in people:
            hit |= np.hypot(px - qx, py - qy) < 0.25
        first = np.flatnonzero(hit)
        out[k] = r[first[0]] if len(first) else 0.0
    return out


def points(ranges: np.ndarray, stride: int = 3) -> np.ndarray:
    return scan_points(ranges, float(ANGLES[0]), float(ANGLES[1] - ANGLES[0]), T_BASE_LIDAR, stride)


TRUE = (4.0, 3.0, 0.6)


def test_refine_finds_the_pose_from_decimetres_off() -> None:
    scan = points(cast(TRUE))
    m = refine(FIELD, scan, (TRUE[0] + 0.15, TRUE[1] - 0.1, TRUE[2] + 0.06))
    assert math.hypot(m.pose[0] - TRUE[0], m.pose[1] - TRUE[1]) < 0.02
    assert abs(m.pose[2] - TRUE[2]) < math.radians(0.5)
    assert m.inliers > 0.95
    assert np.all(np.linalg.eigvalsh(m.covariance) > 0.0)


def test_people_in_the_scan_do_not_drag_the_pose() -> None:
    crowd = [(5.0, 3.5), (4.6, 2.0), (3.0, 4.0), (6.0, 2.5), (5.5, 4.5)]
    scan = points(cast(TRUE, crowd))
    m = refine(FIELD, scan, (TRUE[0] + 0.1, TRUE[1] + 0.1, TRUE[2] - 0.05))
    assert math.hypot(m.pose[0] - TRUE[0], m.pose[1] - TRUE[1]) < 0.03
    assert abs(m.pose[2] - TRUE[2]) < math.radians(1.0)
    assert m.inliers < 0.95  # the people are not on the map


def test_search_then_refine_recovers_a_start_half_a_metre_and_ten_degrees_off() -> None:
    scan = points(cast(TRUE))
    off = (TRUE[0] - 0.5, TRUE[1] + 0.1, TRUE[2] + math.radians(10.0))
    seed = search(FIELD, scan, off, window_m=0.6, window_rad=math.radians(15.0))
    m = refine(FIELD, scan, seed)
    assert math.hypot(m.pose[0] - TRUE[0], m.pose[1] - TRUE[1]) < 0.02
    assert abs(m.pose[2] - TRUE[2]) < math.radians(0.5)


Box = tuple[float, float, float, float]  # x0, y0, x1, y1


def overlap_grid(
    boxes: list[Box], origin: tuple[float, float], shape: tuple[int, int]
) -> np.ndarray:
    return raycast.overlap_grid(boxes, origin, shape, RES)


def cast_boxes(boxes: list[Box], pose: tuple[float, float, float], noise_m: float) -> np.ndarray:
    """The lidar's ranges against the boxes themselves (exact, slab test), with range noise."""
    return slab_ranges(boxes, pose, noise_m, np.random.default_rng(7))


@pytest.mark.parametrize("offset", [-0.02, -0.01, 0.0, 0.01, 0.02])
def test_a_wall_alone_on_an_axis_costs_only_the_maps_quantisation(offset: float) -> None:
    """A corridor (open behind the robot) ending in a wall whose face lies `offset` from
    its boundary cells' centres: the only hold on x. With 1.5 cm range noise the pose is
    off along x by the map's own error, no more (a field blind inside the obstacles let
    the noise pull the scan 16 to 19 cm into the wall)."""
    origin, shape = (-12.5, -2.5), (100, 300)
    face = origin[0] + 290.5 * RES + offset  # cell 290's centre (x = 2.025) + offset
    boxes = [(-12.0, -1.6, face, -1.4), (-12.0, 1.4, face, 1.6), (face, -1.6, face + 0.2, 1.6)]
    occ = overlap_grid(boxes, origin, shape)
    centre = origin[0] + (np.flatnonzero(occ[50])[0] + 0.5) * RES  # the face as mapped
    assert abs(centre - face) <= 0.5 * RES
    field = LikelihoodField.of_grid(occ, RES, origin)
    pose = (0.0, 0.1, 0.05)
    m = refine(field, points(cast_boxes(boxes, pose, 0.015)), pose)
    assert m.pose[0] - pose[0] == pytest.approx(centre - face, abs=0.005)
    assert abs(m.pose[1] - pose[1]) < 0.005
    assert abs(m.pose[2] - pose[2]) < math.radians(0.2)


def test_beams_inside_a_mapped_obstacle_do_not_drag_the_pose() -> None:
    """The map has a desk's top where the lidar's plane meets only the panel between its
    legs, 0.15 m in from the top's edge: the beams on it end that far inside a mapped
    obstacle, and pull nothing (the walls around hold the pose)."""
    origin, shape = (-1.0, -1.0), (140, 160)
    # every face on its boundary cells' centres: the map's quantisation is nil here
    walls = [(-0.5, -0.5, 6.5, -0.325), (-0.5, 5.325, 6.5, 5.5), (-0.5, -0.5, -0.325, 5.5)]
    walls += [(6.325, -0.5, 6.5, 5.5)]
    desk = (3.025, 0.625, 4.625, 1.625)
    panel = (3.175, 0.7, 3.2, 1.55)
    occ = overlap_grid([*walls, desk], origin, shape)
    field = LikelihoodField.of_grid(occ, RES, origin)
    pose = (1.8, 1.1, 0.0)
    m = refine(field, points(cast_boxes([*walls, panel], pose, 0.0), stride=1), pose)
    assert math.hypot(m.pose[0] - pose[0], m.pose[1] - pose[1]) < 0.01
    assert abs(m.pose[2] - pose[2]) < math.radians(0.2)


def test_the_localizer_corrects_drifting_odometry_along_a_path() -> None:
    """The odometry starts where the localizer was told (0.4 m, 8° off the truth) and
    drifts 3 % and 0.5°/m; the localizer's T_map_base stays on the truth."""
    s = LocalizationSettings()
    loc = Localizer(s, FIELD, (TRUE[0] + 0.4, TRUE[1] - 0.2, TRUE[2] + math.radians(8.0)))
    odom = (0.0, 0.0, 0.0)
    truth = TRUE
    errors = []
    for k in range(40):  # 4 m along a gentle arc
        est = loc.update(points(cast(truth)), odom)
        if k > 0:
            errors.append(math.hypot(est.map_base[0] - truth[0], est.map_base[1] - truth[1]))
            assert est.status == "ok", est.refused
        step = (0.1, 0.0, 0.02)
        truth = compose(truth, step)
        odom = compose(odom, (0.103, 0.0, 0.02 + math.radians(0.05)))
    assert max(errors) < 0.03
    assert est.confidence > 0.9


def test_a_scan_that_fits_no_map_is_refused_until_lost_and_the_covariance_grows() -> None:
    s = LocalizationSettings(lost_after=3)
    loc = Localizer(s, FIELD, TRUE)
    assert loc.update(points(cast(TRUE)), (0.0, 0.0, 0.0)).status == "ok"
    junk = points(np.full(len(ANGLES), 0.6))  # a ring of clutter 0.6 m away all round
    statuses, cov = [], []
    for k in range(4):
        est = loc.update(junk, (0.1 * (k + 1), 0.0, 0.0))
        statuses.append(est.status)
        cov.append(est.covariance[0, 0])
        assert est.refused.startswith(f"{est.confidence:.0%} of the beams")
    assert statuses == ["uncertain", "uncertain", "lost", "lost"]
    assert cov == sorted(cov) and cov[-1] > cov[0]
    # The room seen again: found by the search, tracking again.
    est = loc.update(points(cast(compose(TRUE, (0.4, 0.0, 0.0)))), (0.4, 0.0, 0.0))
    assert est.status == "ok"


def test_se2_compose_and_inverse() -> None:
    a, b = (1.0, 2.0, 0.5), (-0.3, 0.7, -1.2)
    back = compose(compose(a, b), inverse(b))
    assert back == pytest.approx(a)


def test_a_restarted_localizer_goes_on_from_the_correction_it_resumes() -> None:
    """Odometry lived on through a restart: with the last T_map_odom it trusted (0.2 m
    off, as drift left it), the new localizer finds the robot where it is, far from the
    start pose it was told."""
    s = LocalizationSettings()
    odom = (3.0, -1.0, 0.4)  # odom's pose now: the robot walked since the start
    truth = TRUE
    map_odom = compose(truth, inverse(odom))  # what the old localizer trusted...
    resumed = (map_odom[0] + 0.2, map_odom[1] - 0.1, map_odom[2] + math.radians(3.0))
    loc = Localizer(s, FIELD, (0.0, 0.0, 0.0))  # the start pose, metres away
    loc.map_odom = resumed  # ...and what the restarted one is given
    est = loc.update(points(cast(truth)), odom)
    assert est.status == "ok", est.refused
    assert math.hypot(est.map_base[0] - truth[0], est.map_base[1] - truth[1]) < 0.02
