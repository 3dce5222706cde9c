"""The map frame for a consumer of `odom`: T_map_base = T_map_odom · T_odom_base.

`odom` is the robot's odometry (it drifts); `localization` publishes T_map_odom at the
lidar's rate (`common.messages.localization`). `MapFrame.wait(t)` blocks (bounded) until
the localization due at t is in: its tick d, the newest multiple of its period with
d + latency ≤ t, as every lockstep consumer of a periodic producer does; `at(t)` is that
sample; `base(odom, t)` the base in the map as (4 × 4) and `pose(odom, t)` as (x, y,
yaw); `to_odom(H, capture, now)` a pose planned in the map from a capture, back in odom
(the mission's grasps). `status(t)` says whether the robot knows where it is (`lost`:
navigation stops).

Nobody waits for the dead: `wait` waits in slices of `WAIT_SLICE_S` and gives up as soon
as a localization it once saw alive has lost its liveliness (a SIGSTOPped localization
made navigation wait its full 30 s timeout at every tick, and the lockstep world crawl:
1 s of sim time in 7 min). Before it was first seen alive, it waits as before.

Off (`enabled` false) when the stack runs no localization (`localization` is not a
lockstep participant: the truth ablation, where odom is the map): T_map_odom is the
identity and the status `ok`. Before the first sample, and while it is missing, the
identity too (odometry starts at the start pose in the map), status `initialising`.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from common.bus import Bus, WaitTimeout
from common.config import Config
from common.geometry import FloatArray, T_of_pose, inv_T, make_T, rot_z, yaw_of, yaw_of_quat_xyzw
from common.keys import RobotKeys
from common.messages.localization import Localization, LocalizationStatus
from common.messages.sim import Odom, StateTruth

NAME = "localization"
#: Wall seconds between two looks at the localization's liveliness while waiting.
WAIT_SLICE_S = 0.05
log = logging.getLogger(__name__)


def odom_pose(msg: Odom | StateTruth) -> tuple[float, float, float]:
    """(x, y, yaw) of a base pose message (the odometry's, or the sim's truth)."""
    p = msg.base_position_in_world
    return p[0], p[1], yaw_of_quat_xyzw(msg.base_orientation_xyzw)


class MapFrame:
    def __init__(self, bus: Bus, keys: RobotKeys, config: Config, history: int = 64) -> None:
        """history: samples kept (at the localization's 10 Hz, 64 is 6.4 s); a consumer
        that looks back further (the mission, at a grasp plan's capture) keeps more."""
        p = config.time.participants.get(NAME)
        self.enabled = p is not None
        self.period_ns = round(p.period_s * 1e9) if p is not None else 0
        self.latency_ns = round(p.latency_s * 1e9) if p is not None else 0
        self.lockstep = config.time.mode == "lockstep"
        self._latest = (
            bus.latest(keys.localization, Localization, history=history) if self.enabled else None
        )
        self._alive_key = keys.alive(NAME)
        self._watch = bus.watch_alive(self._alive_key) if self.enabled else None
        self._seen_alive = False

    def gone(self) -> bool:
        """Whether the localization, once seen alive, has lost its liveliness."""
        if self._watch is None:
            return False
        alive = self._alive_key in self._watch.alive()
        self._seen_alive = self._seen_alive or alive
        return self._seen_alive and not alive

    def due(self, t_ns: int) -> int:
        """The localization tick whose output takes effect at t."""
        d = t_ns - self.latency_ns
        return -1 if d < 0 else (d // self.period_ns) * self.period_ns

    def wait(self, t_ns: int, timeout_s: float) -> bool:
        """Wait for the sample due at t (lockstep); whether it is in."""
        if self._latest is None:
            return True
        d = self.due(t_ns)
        if d < 0:
            return True
        if self.lockstep:
            deadline = time.perf_counter() + timeout_s
            while not self.gone():
                left = deadline - time.perf_counter()
                try:
                    self._latest.wait_stamp(d, max(0.0, min(WAIT_SLICE_S, left)))
                    break
                except WaitTimeout:
                    if left <= WAIT_SLICE_S:
                        break
        msg = self._latest.at(d)
        return msg is not None and msg.stamp_ns == d

    def at(self, t_ns: int) -> Localization | None:
        if self._latest is None:
            return None
        d = self.due(t_ns)
        return None if d < 0 else self._latest.at(d)

    def status(self, t_ns: int) -> LocalizationStatus:
        if not self.enabled:
            return "ok"
        msg = self.at(t_ns)
        return "initialising" if msg is None else msg.status

    def map_odom(self, t_ns: int) -> FloatArray:
        """T_map_odom (4 × 4) in effect at t."""
        msg = self.at(t_ns)
        if msg is None:
            return np.eye(4)
        x, y, yaw = msg.map_odom
        return make_T(rot_z(yaw), (x, y, 0.0))

    def to_odom(self, H_map: FloatArray, capture_ns: int, now_ns: int) -> FloatArray:
        """A map pose planned from what was seen at `capture_ns`, in odom (4 × 4): with the
        correction that placed it (due at the capture), so the pose stays where the base
        saw it; a correction made since (a few cm) would move it off the thing seen. The
        newest correction (with a warning) when the capture's is no longer kept."""
        if self.at(capture_ns) is None and self.at(now_ns) is not None:
            log.warning(
                "no localization kept from t=%.2f s: the newest correction", capture_ns / 1e9
            )
            capture_ns = now_ns
        return inv_T(self.map_odom(capture_ns)) @ np.asarray(H_map, dtype=float)

    def base(self, odom: Odom, t_ns: int) -> FloatArray:
        """T_map_base (4 × 4) of an odom sample, with the correction in effect at t."""
        T = T_of_pose(odom.base_position_in_world, odom.base_orientation_xyzw)
        return T if not self.enabled else self.map_odom(t_ns) @ T

    def pose(self, odom: Odom, t_ns: int) -> tuple[float, float, float]:
        """(x, y, yaw) of the base in the map."""
        if not self.enabled:
            return odom_pose(odom)
        T = self.base(odom, t_ns)
        return float(T[0, 3]), float(T[1, 3]), yaw_of(T[:3, :3])
