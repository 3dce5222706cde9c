"""Where the robot was: the localization's last trusted T_map_odom, kept on disk so that a
restarted localization goes on from it instead of the start pose.

The WBC's odometry lives on when the localization dies (supervisord restarts it in a few
seconds), so the last T_map_odom the localization trusted (status `ok`) still places
odom in the map. It is written to `localization-state.json` in the run's folder at most
every `EVERY_NS` of sim time (written whole, `common.runfiles`); a localization that
starts and finds it resumes from it: the matcher searches around the pose it gives (status
`initialising`, as at the start pose), and the robot walks on where it was. Without it, a
restart put the robot back at the start pose in the map while it stood 10 m away (the
fault battery: the request ran on, every scan refused, the sim at a tenth of real time).
A new run is a new folder: nothing carries over. No run folder: nothing is kept.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import msgspec

from common.messages.base import NS_PER_S
from common.runfiles import run_folder, write_whole

FILE = "localization-state.json"
EVERY_NS = NS_PER_S


class Held(msgspec.Struct, frozen=True):
    """T_map_odom (x m, y m, yaw rad) the localization trusted at sim time `stamp_ns`."""

    stamp_ns: int
    map_odom: tuple[float, float, float]


class Resume:
    """The last trusted T_map_odom of this run, in `folder` (None: kept nowhere)."""

    def __init__(self, folder: Path | None) -> None:
        self.path = folder / FILE if folder is not None else None
        self._saved_ns = -EVERY_NS

    @classmethod
    def of_run(cls) -> Resume:
        return cls(run_folder())

    def save(self, stamp_ns: int, map_odom: tuple[float, float, float]) -> None:
        if self.path is None or stamp_ns - self._saved_ns < EVERY_NS:
            return
        write_whole(self.path, msgspec.json.encode(Held(stamp_ns, map_odom)))
        self._saved_ns = stamp_ns

    def load(self) -> Held | None:
        """What a previous localization of this run trusted last; None: nothing (or a
        file that cannot be read, which is removed)."""
        if self.path is None or not self.path.exists():
            return None
        try:
            return msgspec.json.decode(self.path.read_bytes(), type=Held)
        except (OSError, msgspec.DecodeError, msgspec.ValidationError):
            with contextlib.suppress(OSError):
                self.path.unlink()
            return None
