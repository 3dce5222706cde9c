"""Where the robot is in the map: the localization's correction of the odometry."""

from __future__ import annotations

from typing import Literal

from common.messages.base import Finite, Message, StampNs, Unit

LocalizationStatus = Literal["initialising", "ok", "uncertain", "lost"]
Pose2Msg = tuple[Finite, Finite, Finite]


class Localization(Message, frozen=True):
    """`dume/<r>/localization`, every localization tick (10 Hz, stamped with the scan's
    stamp): T_map_odom as (x m, y m, yaw rad); every consumer composes
    T_map_base = T_map_odom · T_odom_base with `odom` at its own stamp.

    map_base: the base in the map at the stamp (x, y, yaw). covariance: (3, 3) row-major
    of map_base (m², rad²). status: `initialising` (no match yet; the start pose as
    given), `ok`, `uncertain` (the last scans did not match; the correction is kept and
    its covariance grows), `lost` (navigation stops). confidence: the last match's share
    of beams on the map. reason: why the last scan was refused ("" when it matched).
    grid_stamp_ns: while mapping (SLAM), the stamp of the newest grid published on
    `slam/occupancy` (0: none, or not mapping): a consumer applying this sample waits
    for that grid, so every run adopts the same grid at the same tick.
    """

    stamp_ns: StampNs
    map_odom: Pose2Msg
    map_base: Pose2Msg
    covariance: tuple[Finite, ...]
    status: LocalizationStatus
    confidence: Unit
    reason: str = ""
    grid_stamp_ns: StampNs = 0
