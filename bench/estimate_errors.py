"""How far the robot's own estimate of its base (`odom`) is from the sim's truth
(`state_truth`), for trials and evaluation: truth-side, never in the robot's loop.

`EstimateErrors.add(odom, truth)` takes one pair stamped alike; `figures()` gives:
velocity RMSE (m/s, the 3-D linear velocity in world), the tilt error's p95 (deg, the
angle between the up directions the two orientations see in the body), the height
error's p95 (m), and at the end: the position error in the floor plane (m), the yaw
error (deg), the distance the base truly walked (m) and the drift as a percentage of
it. Odometry drifts by design (its x, y and yaw are integrated); the drift figure is
what a localization must take up.

`LocalizationErrors.add(localization, truth)` does the same for the localization's
base in the map (`Localization.map_base`, at its scan's stamp): the position error's
p50, p95 and max (m), the heading error's p95 and max (deg), and how many ticks were not
`ok` (and `lost`). `StampPairs` pairs either estimate with the truth by stamp;
`Estimates` holds both pairings, what a run that watches the robot keeps.

`PlacementErrors` measures where perception puts the artifacts it sees in the map:
each artifact detection within `max_range_m`, matched to the nearest true artifact of
its class (within `gate_m`), gives the map-frame error (`axis_in_world`, placed with
the robot's own pose), the base-frame error (`axis_in_base_yaw` placed with the true
base: perception's geometry alone) and the pose's share (`T_world_base` against the
truth: position error plus range × heading error). The issue's check: the map-frame
error is within the base-frame error plus the pose's share plus 1 cm (`excess_p95_mm`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from common.geometry import quat_xyzw_to_matrix, wrap_angle, yaw_of, yaw_of_quat_xyzw
from common.messages.localization import Localization
from common.messages.perception import Detections
from common.messages.sim import Odom, StateTruth
from common.messages.world import Artifact


class EstimateErrors:
    """The odom-versus-truth errors over a run (module docstring)."""

    def __init__(self) -> None:
        self.n = 0
        self._v_sq = 0.0
        self._tilt: list[float] = []
        self._height: list[float] = []
        self.distance_m = 0.0
        self._last_xy: np.ndarray | None = None
        self.position_error_m = 0.0
        self.yaw_error_deg = 0.0

    def add(self, odom: Odom, truth: StateTruth) -> None:
        if odom.stamp_ns != truth.stamp_ns:
            raise ValueError(f"odom at {odom.stamp_ns} ns, truth at {truth.stamp_ns} ns")
        R_est = quat_xyzw_to_matrix(odom.base_orientation_xyzw)
        R_true = quat_xyzw_to_matrix(truth.base_orientation_xyzw)
        dv = np.subtract(odom.base_linear_velocity_in_world, truth.base_linear_velocity_in_world)
        self._v_sq += float(dv @ dv)
        cos_tilt = float(np.clip(R_est[2] @ R_true[2], -1.0, 1.0))
        self._tilt.append(math.degrees(math.acos(cos_tilt)))
        p_est = np.asarray(odom.base_position_in_world)
        p_true = np.asarray(truth.base_position_in_world)
        self._height.append(abs(float(p_est[2] - p_true[2])))
        if self._last_xy is not None:
            self.distance_m += float(np.linalg.norm(p_true[:2] - self._last_xy))
        self._last_xy = p_true[:2].copy()
        self.position_error_m = float(np.linalg.norm(p_est[:2] - p_true[:2]))
        self.yaw_error_deg = math.degrees(wrap_angle(yaw_of(R_est) - yaw_of(R_true)))
        self.n += 1

    def figures(self) -> dict[str, Any]:
        if self.n == 0:
            return {"samples": 0}
        drift = 100.0 * self.position_error_m / self.distance_m if self.distance_m > 0 else 0.0
        return {
            "samples": self.n,
            "velocity_rmse_mps": round(math.sqrt(self._v_sq / self.n), 4),
            "tilt_error_p95_deg": round(float(np.percentile(self._tilt, 95)), 3),
            "height_error_p95_m": round(float(np.percentile(self._height, 95)), 4),
            "distance_m": round(self.distance_m, 2),
            "position_error_m": round(self.position_error_m, 3),
            "drift_pct": round(drift, 2),
            "yaw_error_deg": round(self.yaw_error_deg, 2),
        }


class LocalizationErrors:
    """The localization-versus-truth errors over a run (module docstring)."""

    def __init__(self) -> None:
        self._position: list[float] = []
        self._heading: list[float] = []
        self.not_ok = 0
        self.lost = 0

    @property
    def n(self) -> int:
        return len(self._position)

    def add(self, loc: Localization, truth: StateTruth) -> None:
        if loc.stamp_ns != truth.stamp_ns:
            raise ValueError(f"localization at {loc.stamp_ns} ns, truth at {truth.stamp_ns} ns")
        x, y, yaw = loc.map_base
        p = truth.base_position_in_world
        self._position.append(math.hypot(x - p[0], y - p[1]))
        yaw_true = yaw_of_quat_xyzw(truth.base_orientation_xyzw)
        self._heading.append(abs(math.degrees(wrap_angle(yaw - yaw_true))))
        self.not_ok += loc.status != "ok"
        self.lost += loc.status == "lost"

    def figures(self) -> dict[str, Any]:
        if not self._position:
            return {"samples": 0}
        pos, head = np.asarray(self._position), np.asarray(self._heading)
        return {
            "samples": self.n,
            "position_p50_m": round(float(np.percentile(pos, 50)), 4),
            "position_p95_m": round(float(np.percentile(pos, 95)), 4),
            "position_max_m": round(float(pos.max()), 4),
            "heading_p95_deg": round(float(np.percentile(head, 95)), 3),
            "heading_max_deg": round(float(head.max()), 3),
            "not_ok": self.not_ok,
            "lost": self.lost,
        }


class PlacementErrors:
    """Perception's map-frame placement of artifacts against the truth (module docstring).
    `detections(msg)` and `truth(msg)` as they come, in any order; a camera's detections
    are measured once the truth at their stamp is in (kept `horizon` samples back)."""

    def __init__(
        self,
        artifacts: Sequence[Artifact],
        gate_m: float = 0.3,
        max_range_m: float = 3.0,
        horizon: int = 256,
    ) -> None:
        self.artifacts = [(a.object_class, a.position[0], a.position[1]) for a in artifacts]
        self.gate_m, self.max_range_m, self.horizon = gate_m, max_range_m, horizon
        self.stop_ns: int | None = None  # measure nothing stamped from here on
        self._truths: dict[int, StateTruth] = {}
        self._waiting: list[Detections] = []
        self._map: list[float] = []
        self._base: list[float] = []
        self._pose: list[float] = []
        self._excess: list[float] = []

    def detections(self, msg: Detections) -> None:
        truth = self._truths.get(msg.stamp_ns)
        if truth is not None:
            self._measure(msg, truth)
        elif not self._truths or msg.stamp_ns > max(self._truths):
            self._waiting.append(msg)

    def truth(self, msg: StateTruth) -> None:
        self._truths[msg.stamp_ns] = msg
        if len(self._truths) > self.horizon:
            del self._truths[min(self._truths)]
        due = [d for d in self._waiting if d.stamp_ns <= msg.stamp_ns]
        self._waiting = [d for d in self._waiting if d.stamp_ns > msg.stamp_ns]
        for d in due:
            if (t := self._truths.get(d.stamp_ns)) is not None:
                self._measure(d, t)

    def _measure(self, msg: Detections, truth: StateTruth) -> None:
        if self.stop_ns is not None and msg.stamp_ns >= self.stop_ns:
            return
        tx, ty = truth.base_position_in_world[0], truth.base_position_in_world[1]
        tyaw = yaw_of_quat_xyzw(truth.base_orientation_xyzw)
        T = np.asarray(msg.T_world_base, dtype=float).reshape(4, 4)
        pose_m = math.hypot(T[0, 3] - tx, T[1, 3] - ty)
        yaw_err = abs(wrap_angle(yaw_of(T[:3, :3]) - tyaw))
        c, s = math.cos(tyaw), math.sin(tyaw)
        for det in msg.detections:
            ax, ay = det.axis_in_base_yaw[0], det.axis_in_base_yaw[1]
            rng = math.hypot(ax, ay)
            if det.class_name == "person" or rng > self.max_range_m:
                continue
            placed = (tx + c * ax - s * ay, ty + s * ax + c * ay)  # with the true base
            near = [(math.hypot(x - placed[0], y - placed[1]), x, y)
                    for cls, x, y in self.artifacts if cls == det.class_name]  # fmt: skip
            if not near or (best := min(near))[0] > self.gate_m:
                continue
            _, x, y = best
            e_map = math.hypot(det.axis_in_world[0] - x, det.axis_in_world[1] - y)
            share = pose_m + rng * yaw_err
            self._map.append(e_map)
            self._base.append(best[0])
            self._pose.append(share)
            self._excess.append(e_map - best[0] - share)

    def figures(self) -> dict[str, Any]:
        if not self._map:
            return {"samples": 0}

        def mm(values: list[float], q: float) -> float:
            return round(1e3 * float(np.percentile(values, q)), 1)

        return {
            "samples": len(self._map),
            "map_error_p50_mm": mm(self._map, 50),
            "map_error_p95_mm": mm(self._map, 95),
            "base_error_p50_mm": mm(self._base, 50),
            "base_error_p95_mm": mm(self._base, 95),
            "pose_share_p95_mm": mm(self._pose, 95),
            "excess_p95_mm": mm(self._excess, 95),
        }


E = TypeVar("E", Odom, Localization)


class Errors(Protocol):
    def add(self, estimate: Any, truth: StateTruth) -> None: ...

    def figures(self) -> dict[str, Any]: ...


class StampPairs(Generic[E]):
    """Estimates (odom or localization) and truth samples as they come, in any order: each
    pair with one stamp goes to `errors` once both are in (from `start_ns` on); an
    unmatched sample is dropped after `horizon` newer ones of its kind."""

    def __init__(self, errors: Errors, start_ns: int = 0, horizon: int = 64) -> None:
        self.errors: Errors = errors
        self.start_ns, self.horizon = start_ns, horizon
        self._estimate: dict[int, E] = {}
        self._truth: dict[int, StateTruth] = {}

    def estimate(self, msg: E) -> None:
        truth = self._truth.pop(msg.stamp_ns, None)
        if truth is not None:
            self._pair(msg, truth)
        else:
            self._keep(self._estimate, msg.stamp_ns, msg)

    def truth(self, msg: StateTruth) -> None:
        estimate = self._estimate.pop(msg.stamp_ns, None)
        if estimate is not None:
            self._pair(estimate, msg)
        else:
            self._keep(self._truth, msg.stamp_ns, msg)

    def _pair(self, estimate: E, truth: StateTruth) -> None:
        if estimate.stamp_ns >= self.start_ns:
            self.errors.add(estimate, truth)

    def _keep(self, pending: dict[int, Any], stamp: int, msg: Any) -> None:
        pending[stamp] = msg
        if len(pending) > self.horizon:
            del pending[min(pending)]


class Estimates:
    """The robot's odometry and its localization, each paired with the truth by stamp:
    feed `odom`, `localization` and `truth` samples as they come; `figures()` gives
    `{"odometry": …, "localization": …}` (no localization samples in the truth ablation,
    which runs none). Samples stamped before `start_ns` are not counted."""

    def __init__(self) -> None:
        self.odometry: StampPairs[Odom] = StampPairs(EstimateErrors())
        self.localization: StampPairs[Localization] = StampPairs(LocalizationErrors())

    @property
    def start_ns(self) -> int:
        return self.odometry.start_ns

    @start_ns.setter
    def start_ns(self, value: int) -> None:
        self.odometry.start_ns = self.localization.start_ns = value

    def odom(self, msg: Odom) -> None:
        self.odometry.estimate(msg)

    def located(self, msg: Localization) -> None:
        self.localization.estimate(msg)

    def truth(self, msg: StateTruth) -> None:
        self.odometry.truth(msg)
        self.localization.truth(msg)

    def figures(self) -> dict[str, dict[str, Any]]:
        return {
            "odometry": self.odometry.errors.figures(),
            "localization": self.localization.errors.figures(),
        }
