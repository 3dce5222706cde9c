"""Files a process keeps for its run, written whole.

`write_whole(path, data)` writes a temporary file beside `path` and renames it over it
(`os.replace`): a reader, or a process started after a kill mid-write, finds the old
content or the new, never half. `run_folder()` is the run's folder (`DUME_RUN_DIR`, set
by every stack for its processes), None for a bare process or a unit test: what a
service keeps there (the mission's held request, the localization's last correction)
lives as long as the run, and a new run starts without it. `write_private` is
`write_whole` for a secret: the file is its owner's only (0600) from its first byte.
"""

from __future__ import annotations

import os
from pathlib import Path


def run_folder() -> Path | None:
    folder = os.environ.get("DUME_RUN_DIR")
    return Path(folder) if folder else None


def write_whole(path: Path, data: bytes, mode: int | None = None) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    if mode is None:
        tmp.write_bytes(data)
    else:
        tmp.unlink(missing_ok=True)
        with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode), "wb") as f:
            f.write(data)
    os.replace(tmp, path)


def write_private(path: Path, data: bytes) -> None:
    """`write_whole`, readable and writable by the owner only (a key, a password)."""
    write_whole(path, data, 0o600)
