"""The odometry-versus-truth figures: drift over distance, tilt and velocity errors; the
localization's percentiles; and pairs matched by stamp whichever side comes first."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pinocchio as pin
import pytest

from bench.estimate_errors import (
    EstimateErrors,
    Estimates,
    LocalizationErrors,
    PlacementErrors,
    StampPairs,
)
from common.geometry import make_T, rot_z
from common.messages.localization import Localization
from common.messages.perception import Detections
from common.messages.sim import Odom, StateTruth
from common.messages.world import Artifact, Cylinder
from tests.unit.mission_fakes import detection

MS = 1_000_000
LEVEL = (0.0, 0.0, 0.0, 1.0)


def xyzw(roll: float, yaw: float) -> tuple[float, float, float, float]:
    q = pin.Quaternion(pin.rpy.rpyToMatrix(roll, 0.0, yaw))
    return (q.x, q.y, q.z, q.w)


def odom(t: int, x: float, vx: float = 0.5, quat: tuple[float, ...] = LEVEL) -> Odom:
    return Odom(
        stamp_ns=t,
        base_position_in_world=(x, 0.0, 0.5),
        base_orientation_xyzw=quat,  # type: ignore[arg-type]
        base_linear_velocity_in_world=(vx, 0.0, 0.0),
        base_angular_velocity_in_base=(0.0, 0.0, 0.0),
        gripper_angle=0.0,
        gripper_effort=0.0,
    )


def truth(t: int, x: float, vx: float = 0.5) -> StateTruth:
    return StateTruth(
        stamp_ns=t,
        base_position_in_world=(x, 0.0, 0.5),
        base_orientation_xyzw=LEVEL,
        base_linear_velocity_in_world=(vx, 0.0, 0.0),
        base_angular_velocity_in_base=(0.0, 0.0, 0.0),
    )


def test_drift_is_the_final_error_over_the_true_distance() -> None:
    e = EstimateErrors()
    for k in range(101):  # 10 m truly; the odometry says 9.8 m, 0.1 m/s slow, tilted 2°
        t = k * 20 * MS
        e.add(odom(t, 0.098 * k, 0.4, xyzw(math.radians(2.0), 0.05)), truth(t, 0.1 * k))
    f = e.figures()
    assert f["distance_m"] == pytest.approx(10.0)
    assert f["position_error_m"] == pytest.approx(0.2)
    assert f["drift_pct"] == pytest.approx(2.0)
    assert f["velocity_rmse_mps"] == pytest.approx(0.1)
    assert f["tilt_error_p95_deg"] == pytest.approx(2.0, abs=1e-3)
    assert f["yaw_error_deg"] == pytest.approx(math.degrees(0.05), abs=0.01)


def test_pairs_match_by_stamp_in_any_order_and_mismatches_are_refused() -> None:
    e = EstimateErrors()
    pairs = StampPairs(e, start_ns=20 * MS)
    pairs.truth(truth(0, 0.0))  # before the start: paired, not counted
    pairs.estimate(odom(0, 0.0))
    pairs.estimate(odom(20 * MS, 0.01))  # odom first
    pairs.truth(truth(20 * MS, 0.01))
    pairs.truth(truth(40 * MS, 0.02))  # truth first
    pairs.estimate(odom(40 * MS, 0.02))
    pairs.truth(truth(60 * MS, 0.03))  # never matched
    assert e.n == 2
    with pytest.raises(ValueError, match="odom at"):
        e.add(odom(0, 0.0), truth(MS, 0.0))


def located(t: int, x: float, yaw: float, status: str = "ok") -> Localization:
    return Localization(
        t,
        (0.0, 0.0, 0.0),
        (x, 0.0, yaw),
        (0.0,) * 9,
        status,  # type: ignore[arg-type]
        1.0,
    )


def test_localization_errors_are_percentiles_of_the_map_pose_against_truth() -> None:
    e = LocalizationErrors()
    pairs = StampPairs(e)
    for k in range(100):  # 1 cm off, 0.1° off; every 20th tick 6 cm and 1° off, lost
        t = k * 100 * MS
        bad = k % 20 == 19
        off, yaw = (0.06, 1.0) if bad else (0.01, 0.1)
        pairs.estimate(located(t, 0.1 * k + off, math.radians(yaw), "lost" if bad else "ok"))
        pairs.truth(truth(t, 0.1 * k))
    f = e.figures()
    assert f["samples"] == 100 and f["lost"] == 5 and f["not_ok"] == 5
    assert f["position_p50_m"] == pytest.approx(0.01)
    assert f["position_max_m"] == pytest.approx(0.06)
    assert 0.01 <= f["position_p95_m"] <= 0.06
    assert f["heading_max_deg"] == pytest.approx(1.0)
    assert LocalizationErrors().figures() == {"samples": 0}
    with pytest.raises(ValueError, match="localization at"):
        e.add(located(0, 0.0, 0.0), truth(MS, 0.0))


def seen(t: int, T_world_base: np.ndarray, axis_base: tuple[float, float], cls: str) -> Detections:
    """A detection of an artifact at `axis_base` (base_yaw), placed with `T_world_base`."""
    d = detection(f"{cls}_1", 0.6)
    a = T_world_base @ np.array([axis_base[0], axis_base[1], 0.0, 1.0])
    d = msgspec.structs.replace(
        d,
        axis_in_base_yaw=(axis_base[0], axis_base[1], 0.8),
        axis_in_world=(float(a[0]), float(a[1]), 0.8),
    )
    return Detections(t, "wrist", tuple(T_world_base.ravel().tolist()), "network", [d])  # type: ignore[arg-type]


def test_placement_splits_the_map_error_into_geometry_and_the_pose() -> None:
    bottle = Artifact("bottle_1", "bottle", (2.0, 0.5, 0.8), 0.0, Cylinder(0.03, 0.2), 0.3,
                      (1, 1, 1, 1), "table_1")  # fmt: skip
    box = msgspec.structs.replace(bottle, id="box_1", object_class="box", position=(9, 9, 0.8))
    e = PlacementErrors([bottle, box])
    yaw = math.radians(1.0)  # the robot thinks it is 2 cm ahead and turned 1° left
    T_est = make_T(rot_z(yaw), (0.02, 0.0, 0.5))
    # 5 mm of geometry error along y; seen first, the truth comes after
    e.detections(seen(0, T_est, (2.0, 0.505), "bottle"))
    e.detections(seen(0, T_est, (2.0, 0.5), "can"))  # no can in the world
    e.detections(seen(0, T_est, (8.0, 0.5), "bottle"))  # beyond 3 m
    e.truth(truth(0, 0.0))
    e.truth(truth(100 * MS, 0.0))
    e.detections(seen(100 * MS, T_est, (2.0, 0.505), "bottle"))  # the truth was first
    e.stop_ns = 200 * MS
    e.truth(truth(200 * MS, 0.0))
    e.detections(seen(200 * MS, T_est, (2.0, 0.505), "bottle"))  # the pick began: not kept
    f = e.figures()
    assert f["samples"] == 2
    assert f["base_error_p95_mm"] == pytest.approx(5.0, abs=0.1)
    share = 0.02 + math.hypot(2.0, 0.505) * yaw
    assert f["pose_share_p95_mm"] == pytest.approx(1e3 * share, abs=0.1)
    assert 20.0 < f["map_error_p95_mm"] <= 5.0 + 1e3 * share
    assert f["excess_p95_mm"] <= 0.0


def test_estimates_pair_the_odometry_and_the_localization_with_one_truth() -> None:
    est = Estimates()
    est.start_ns = 100 * MS
    for k in range(4):  # 0 ms is before the start: paired, not counted
        t = k * 100 * MS
        est.odom(odom(t, 0.1 * k + 0.01))
        est.located(located(t, 0.1 * k + 0.02, 0.0))
        est.truth(truth(t, 0.1 * k))
    f = est.figures()
    assert f["odometry"]["samples"] == 3 and f["localization"]["samples"] == 3
    assert f["odometry"]["position_error_m"] == pytest.approx(0.01)
    assert f["localization"]["position_max_m"] == pytest.approx(0.02)
    assert Estimates().figures() == {"odometry": {"samples": 0}, "localization": {"samples": 0}}
