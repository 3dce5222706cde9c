"""`dume trial updown`: `dume up` and `dume down`, `count` times (100), as a user runs
them, and what each cycle leaves behind (the rule: nothing).

Each cycle: `dume up` (the small world, lockstep, a port of its own, a map directory of
the trial's own so the site's map is not touched) until `dume status --ready` sees every
service; `dume down`; then the leftovers of the run:

- **processes**: any process whose environment names the run's folder (`DUME_RUN_DIR`);
- **sockets**: the router's port still accepting connections; supervisord's control
  socket or pid file still in the run's folder;
- **shared memory**: the /dev/shm files the run's processes had mapped while up (Zenoh's
  shared-memory transport), still there after the cycle (`shm_left`). Zenoh does not
  always unlink a segment when its processes exit, and removes such orphans when its
  next process starts: a segment still there after the *next* cycle has come up is
  stale (`shm_stale`, the rule: none), the only kind that would add up;
- **locks**: the map database's `-wal` / `-shm` files (SQLite removes them when the last
  connection closes cleanly); and the database itself: `PRAGMA integrity_check` and its
  entity count, which must not change from cycle to cycle (the map is resumed each time:
  the robot stands still, nothing is requested).

Per cycle the wall seconds to up (every service alive) and to down; JSON-ready figures.
"""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from common.config import REPO_ROOT, Overrides
from deploy.runs import RUNS_DIR, listening
from deploy.stack import free_port

Figures = dict[str, Any]
UP_TIMEOUT_S = 300.0
DOWN_TIMEOUT_S = 120.0


def _dume(*args: str) -> list[str]:
    return [sys.executable, "-m", "deploy.cli", *args]


def run_processes(run_dir: Path) -> list[str]:
    """`pid name` of every process whose environment names `run_dir`."""
    needle = f"DUME_RUN_DIR={run_dir}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            if needle in (entry / "environ").read_bytes().split(b"\0"):
                argv = (entry / "cmdline").read_bytes().split(b"\0")
                name = argv[argv.index(b"-m") + 1] if b"-m" in argv[:-1] else argv[0]
                found.append(f"{entry.name} {name.decode(errors='replace')}")
    return found


def mapped_shm(run_dir: Path) -> dict[str, str]:
    """The /dev/shm files the run's processes have mapped (Zenoh's shared memory), each
    with the processes (`pid name`) that map it."""
    found: dict[str, str] = {}
    for proc in run_processes(run_dir):
        with contextlib.suppress(OSError):
            for row in Path(f"/proc/{proc.split()[0]}/maps").read_text().splitlines():
                path = row.split(maxsplit=5)[-1] if row.count(" ") >= 5 else ""
                if path.startswith("/dev/shm/"):
                    path = path.removesuffix(" (deleted)")
                    if proc not in found.get(path, ""):
                        found[path] = f"{found[path]}, {proc}" if path in found else proc
    return found


def map_state(db: Path) -> tuple[str, int, list[str]]:
    """(integrity_check's answer, entity rows, the lock files beside it)."""
    locks = [p.name for p in (db.with_name(db.name + "-wal"), db.with_name(db.name + "-shm"))
             if p.exists()]  # fmt: skip
    if not db.exists():
        return "no file", -1, locks
    with contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as con:
        ok = str(con.execute("PRAGMA integrity_check").fetchone()[0])
        count = int(con.execute("SELECT count(*) FROM entities").fetchone()[0])
    return ok, count, locks


def _newest_run(before: set[str]) -> Path | None:
    new = sorted(set(os.listdir(RUNS_DIR)) - before) if RUNS_DIR.exists() else []
    return RUNS_DIR / new[-1] if new else None


def cycle(k: int, map_dir: Path, env: dict[str, str], overrides: Overrides) -> Figures:
    """One `dume up` / `dume down`; its times and leftovers."""
    port = free_port()
    runs0 = set(os.listdir(RUNS_DIR)) if RUNS_DIR.exists() else set()
    sets = ["--world", "small", "--set", f'semantic_map.dir="{map_dir}"']
    for key, value in overrides.items():
        sets += ["--set", f"{key}={json.dumps(value)}"]
    t0 = time.perf_counter()
    up = subprocess.Popen(
        _dume("up", "--port", str(port), *sets), cwd=REPO_ROOT, env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )  # fmt: skip
    out: Figures = {"cycle": k}
    run_dir: Path | None = None
    shm: dict[str, str] = {}
    try:
        ready = subprocess.run(
            _dume("status", "--port", str(port), "--ready", str(UP_TIMEOUT_S)),
            cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=UP_TIMEOUT_S + 30,
        )  # fmt: skip
        out["up_s"] = round(time.perf_counter() - t0, 2)
        out["up_ok"] = ready.returncode == 0
        run_dir = _newest_run(runs0)
        shm = mapped_shm(run_dir) if run_dir is not None else {}
        out["shm_mapped"] = len(shm)
        t1 = time.perf_counter()
        down = subprocess.run(
            _dume("down", "--run", run_dir.name if run_dir else "", "--timeout",
                  str(DOWN_TIMEOUT_S)),
            cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=DOWN_TIMEOUT_S + 30,
        )  # fmt: skip
        up.wait(timeout=DOWN_TIMEOUT_S)
        out["down_s"] = round(time.perf_counter() - t1, 2)
        out["down_ok"] = down.returncode == 0 and up.returncode == 0
    finally:
        if up.poll() is None:  # a cycle that failed: leave nothing for the next
            os.killpg(up.pid, 9)
            up.wait(timeout=10)
    left: list[str] = []
    if run_dir is not None:
        left += [f"process {p}" for p in run_processes(run_dir)]
        left += [f"file {n}" for n in ("supervisor.sock", "supervisord.pid")
                 if (run_dir / n).exists()]  # fmt: skip
    if listening("127.0.0.1", port):
        left.append(f"port {port} still open")
    out["shm_left"] = sorted(f"{p} ({who})" for p, who in shm.items() if Path(p).exists())
    dbs = sorted(map_dir.glob("*.sqlite"))
    for db in dbs:
        ok, count, locks = map_state(db)
        out |= {"map_integrity": ok, "map_entities": count}
        left += [f"lock {n}" for n in locks]
    out["left"] = left
    return out


def run_updown(count: int, overrides: Overrides | None = None) -> Figures:
    """`count` cycles, one line each on stderr; the figures."""
    env = dict(os.environ)
    cycles: list[Figures] = []
    stale: set[str] = set()
    with tempfile.TemporaryDirectory(prefix="dume-updown-") as tmp:
        for k in range(count):
            c = cycle(k, Path(tmp), env, overrides or {})
            if cycles:  # what the last cycle left, still there after this one came up
                stale |= {x for x in cycles[-1]["shm_left"] if Path(x.split()[0]).exists()}
            cycles.append(c)
            print(
                f"cycle {k}: up {c.get('up_s')} s ({'ok' if c.get('up_ok') else 'FAILED'}), "
                f"down {c.get('down_s')} s ({'ok' if c.get('down_ok') else 'FAILED'}), map "
                f"{c.get('map_integrity')} {c.get('map_entities')}, left {c['left'] or 'nothing'}, "
                f"shm left {len(c['shm_left'])}",
                file=sys.stderr, flush=True,
            )  # fmt: skip
    counts = {c.get("map_entities") for c in cycles}
    return {
        "trial": "updown",
        "cycles": count,
        "up_failed": sum(not c.get("up_ok") for c in cycles),
        "down_failed": sum(not c.get("down_ok") for c in cycles),
        "left_something": sum(bool(c["left"]) for c in cycles),
        "left": sorted({x for c in cycles for x in c["left"]})[:20],
        "shm_left": sum(len(c["shm_left"]) for c in cycles),
        "shm_stale": sorted(stale)[:20],
        "map_integrity_ok": sum(c.get("map_integrity") == "ok" for c in cycles),
        "map_entity_counts": sorted(x for x in counts if x is not None),
        "up_s_p50": float(np.median([c["up_s"] for c in cycles if "up_s" in c] or [np.nan])),
        "down_s_p50": float(np.median([c["down_s"] for c in cycles if "down_s" in c] or [np.nan])),
    }
