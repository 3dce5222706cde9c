"""Where a run's files are, and which runs are up.

Every stack (`dume up`, `dume demo`, each world of `dume eval`, a trial's, a test's) has
one folder, `var/run/<run id>/`: each service's log, supervisord's, the settings it ran
with (`settings.json`), its recording (`<service>.rrd`: `recording.dir` is `var/run`),
and `run.json` (`RunInfo`: its Zenoh port, the process that holds it, what started it,
the world). A run is up while that process lives and its stack has not been stopped.
The command line finds runs here: `dume runs` lists them, `dume logs` and `dume ctl`
take a run id (or a prefix of one) or the newest, and a command given no `--port` talks
to the one run that is up when nothing listens on the default port.
"""

from __future__ import annotations

import calendar
import contextlib
import math
import os
import pwd
import re
import secrets
import socket
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import msgspec

from common.access import write_once
from common.config import REPO_ROOT
from common.runfiles import write_whole

RUNS_DIR = REPO_ROOT / "var" / "run"
INFO = "run.json"
Kind = Literal["up", "demo", "stack"]


class RunInfo(msgspec.Struct, frozen=True, kw_only=True):
    """`run.json`: a run's identity and how to reach it.

    pid: the process that holds the stack (supervisord for `dume up`, the demo's or the
    eval's own process for theirs). kind: `up` (supervisord in the foreground), `demo`
    (supervisord under the demo), `stack` (plain child processes: eval, trials, tests).
    started, ended: wall time (ISO 8601, UTC); ended is empty while it runs.
    """

    run_id: str
    port: int
    pid: int
    kind: Kind
    world: str
    world_seed: int
    started: str
    ended: str = ""

    @property
    def supervised(self) -> bool:
        return self.kind in ("up", "demo")


class RunNotFound(LookupError):
    """No run matches: which were looked for and what there is."""


@dataclass(frozen=True)
class Run:
    """A run's folder and what its `run.json` says."""

    folder: Path
    info: RunInfo

    @property
    def up(self) -> bool:
        """Not ended, and its process lives: the very process, not a later one that was
        given its pid (a run whose holder died unmarked left a pid that the system hands
        out again; `dume down` once sent SIGTERM to another stack's map service so)."""
        info = self.info
        if info.ended or not pid_alive(info.pid):
            return False
        born = process_started(info.pid)
        return born is None or born <= iso_seconds(info.started) + PID_SLACK_S

    def shown(self) -> str:
        """The folder as a person would type it (relative to the repository)."""
        return shown(self.folder)


def shown(path: Path) -> str:
    return str(path.relative_to(REPO_ROOT) if path.is_relative_to(REPO_ROOT) else path)


def now_iso() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def pid_alive(pid: int) -> bool:
    """Whether process `pid` runs (a zombie, exited but not yet reaped by its parent,
    does not)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's: alive
        return True
    with contextlib.suppress(OSError, IndexError):
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat.rsplit(")", 1)[1].split()[0] != "Z"
    return True


#: Seconds a run's holder may have started after the run's `started` (that is written
#: after the process began; the slack covers the clocks' rounding to whole seconds).
PID_SLACK_S = 2.0


def iso_seconds(stamp: str) -> float:
    """`now_iso()`'s text as seconds since the epoch (inf when it cannot be read: no
    process is ruled out by a stamp nobody can read)."""
    try:
        return float(calendar.timegm(time.strptime(stamp, "%Y-%m-%dT%H:%M:%SZ")))
    except ValueError:
        return math.inf


def process_started(pid: int) -> float | None:
    """When process `pid` started, s since the epoch (the boot time plus its start in
    clock ticks, /proc); None when it cannot be read."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        btime = next(
            int(line.split()[1])
            for line in Path("/proc/stat").read_text().splitlines()
            if line.startswith("btime ")
        )
        return btime + int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError, StopIteration):
        return None


def write_info(folder: Path, info: RunInfo) -> None:
    """Write `run.json` whole (a reader never sees half of it)."""
    folder.mkdir(parents=True, exist_ok=True)
    write_whole(folder / INFO, msgspec.json.encode(info))


def mark_ended(folder: Path) -> None:
    """The run's stack was stopped (its launcher may live on: an eval's next world)."""
    info = read_info(folder)
    if info is not None and not info.ended:
        write_info(folder, msgspec.structs.replace(info, ended=now_iso()))


def read_info(folder: Path) -> RunInfo | None:
    """A folder's `run.json`, or None (none, or not readable: a run from before them)."""
    with contextlib.suppress(OSError, msgspec.DecodeError, msgspec.ValidationError):
        return msgspec.json.decode((folder / INFO).read_bytes(), type=RunInfo)
    return None


def all_runs(root: Path = RUNS_DIR) -> list[Run]:
    """Every run with a `run.json`, newest first (run ids sort by their start)."""
    if not root.is_dir():
        return []
    found = []
    for folder in root.iterdir():
        info = read_info(folder) if folder.is_dir() else None
        if info is not None:
            found.append(Run(folder, info))
    return sorted(found, key=lambda r: r.info.run_id, reverse=True)


def runs_up(root: Path = RUNS_DIR) -> list[Run]:
    return [r for r in all_runs(root) if r.up]


def find_run(
    name: str | None, root: Path = RUNS_DIR, supervised: bool = False, port: int | None = None
) -> Run:
    """The run whose id is or starts with `name`; None: the newest (that is up, if any
    is). `supervised`: only runs under supervisord; `port`: only runs on that Zenoh port
    (`--port`). `RunNotFound` says what there is."""
    runs = [
        r
        for r in all_runs(root)
        if (r.info.supervised or not supervised) and port in (None, r.info.port)
    ]
    what = ("supervised run" if supervised else "run") + (f" on port {port}" if port else "")
    if name is None:
        if not runs:
            raise RunNotFound(f"no {what} in {shown(root)}: start one with `dume up`")
        up = [r for r in runs if r.up]
        return (up or runs)[0]
    matches = [r for r in runs if r.info.run_id.startswith(name)]
    if len(matches) == 1 or (matches and matches[0].info.run_id == name):
        return matches[0]
    if not matches:
        newest = ", ".join(r.info.run_id for r in runs[:3]) or "none kept"
        raise RunNotFound(f"no {what} {name!r} in {shown(root)} (newest: {newest})")
    ids = ", ".join(r.info.run_id for r in matches[:5])
    raise RunNotFound(f"{name!r} names {len(matches)} runs ({ids}): give more of the id")


_EXITED = re.compile(r"exited: (\S+) \((.*); not expected\)")


def restarts(folder: Path) -> dict[str, int]:
    """Per program, how often supervisord saw it die unexpectedly in this run (it
    restarts every one but the sim), from `supervisord.log`; empty for a run without
    one."""
    counts: dict[str, int] = {}
    with contextlib.suppress(OSError):
        for line in (folder / "supervisord.log").read_text(errors="replace").splitlines():
            m = _EXITED.search(line)
            if m:
                counts[m.group(1)] = counts.get(m.group(1), 0) + 1
    return counts


def ctl_secret(folder: Path) -> str:
    """The run's supervisord control password (`ctl.secret`, the owner's only), made on
    first use."""
    return write_once(folder / "ctl.secret", secrets.token_hex(16)).strip()


def current_user() -> str:
    """Who runs this (supervisord's `user`)."""
    try:
        return pwd.getpwuid(os.getuid()).pw_name
    except KeyError:  # a uid without a passwd entry (some containers)
        return str(os.getuid())


def source_commit() -> str:
    """The repository's commit (`git describe --always --dirty`), or `unknown` (not a
    git checkout, no git)."""
    try:
        out = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() or "unknown"


def listening(host: str, port: int, timeout_s: float = 0.5) -> bool:
    """Whether something accepts TCP connections on host:port now."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False
