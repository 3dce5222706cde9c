"""Files a process keeps for its run, written whole.

`write_whole(path, data)` writes a temporary file beside `path` and renames it over it
(`os.replace`): a reader, or a process started after a kill mid-write, finds the old
content or the new, never half. `run_folder()` is the run's folder (`DUME_RUN_DIR`, set
by every stack for its processes), None for a bare process or a unit test: what a
service keeps there (the mission's held request, the localization's last correction)
lives as long as the run, and a new run starts without it.
"""

from __future__ import annotations

import os
from pathlib import Path


def run_folder() -> Path | None:
    folder = os.environ.get("DUME_RUN_DIR")
    return Path(folder) if folder else None


def write_whole(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)
