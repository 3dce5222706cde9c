"""What the mission holds, kept on disk so that a restarted mission can say what it lost.

Each status the mission publishes for a request (or mapping job) it runs, `accepted` or
`running`, is written to `mission-request.json` in the run's folder; the request's end
(`succeeded`, `failed`, `cancelled`) removes the file. A mission that starts and finds
the file was stopped with that request in hand (killed, crashed, restarted by
supervisord): its first status fails the request `dependency_lost`, naming the stage it
was in and when, and says it is not run again. A client hears what became of its
request, not only an `idle`; and nothing is re-run behind a person's back.

The file is written whole (`common.runfiles.write_whole`): a kill mid-write leaves the
old status or the new one. A file that cannot be read is reported as an unknown interrupted request
and removed. No run folder (a unit test, a bare process): nothing is kept.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import msgspec

from common.messages.base import NS_PER_S
from common.messages.mission import MissionStatus
from common.runfiles import run_folder, write_whole

FILE = "mission-request.json"
HELD = ("accepted", "running")
ENDED = ("succeeded", "failed", "cancelled")


class Journal:
    """The request the mission holds, in `folder` (None: kept nowhere)."""

    def __init__(self, folder: Path | None) -> None:
        self.path = folder / FILE if folder is not None else None
        self._held = ""  # the request id on disk now

    @classmethod
    def of_run(cls) -> Journal:
        """The journal of this process's run (`common.runfiles.run_folder`)."""
        return cls(run_folder())

    def note(self, status: MissionStatus) -> None:
        """A status the mission published: held, or its request ended."""
        if self.path is None or not status.request_id:
            return
        if status.state in HELD:
            write_whole(self.path, msgspec.json.encode(status))
            self._held = status.request_id
        elif status.state in ENDED and status.request_id == self._held:
            self.path.unlink(missing_ok=True)
            self._held = ""

    def take(self, stamp_ns: int) -> MissionStatus | None:
        """At start: the request a previous mission of this run held, failed as of
        `stamp_ns` (the file removed); None when it held none."""
        if self.path is None or not self.path.exists():
            return None
        try:
            held = msgspec.json.decode(self.path.read_bytes(), type=MissionStatus)
            stage = held.behaviour or "its start"
        except (OSError, msgspec.DecodeError, msgspec.ValidationError) as exc:
            held = MissionStatus(stamp_ns=0, request_id="unknown", state="running")
            stage = f"a stage not known (its record unreadable: {exc})"
        with contextlib.suppress(OSError):
            self.path.unlink()
        return MissionStatus(
            stamp_ns=stamp_ns,
            request_id=held.request_id,
            state="failed",
            behaviour=held.behaviour,
            progress=held.progress,
            reason="dependency_lost",
            detail=(
                f"mission restarted at t={stamp_ns / NS_PER_S:.2f} s: the request was "
                f"interrupted in {stage} (last status t={held.stamp_ns / NS_PER_S:.2f} s); "
                "it is not run again"
            ),
        )
