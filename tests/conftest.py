"""Shared fixtures: a real dume stack (router + services as processes) on a free port."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from common.config import REPO_ROOT, Overrides, merged, parse_overrides
from deploy.stack import MODULES, ProcessStack

StartStack = Callable[..., ProcessStack]


def dume(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """Run the `dume` command line as a user would, from the repository."""
    return subprocess.run(
        [sys.executable, "-m", "deploy.cli", *args],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


#: Settings that make the PD stand-hold (`hold`) the joint commander instead of the WBC.
HOLD_COMMANDER = (
    "time.participants={}",
    'time.participants.hold.role="command"',
    "time.participants.hold.period_s=0.001",
    "time.participants.hold.latency_s=0.0",
)


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[StartStack]:
    """Start `services` (names or module paths) with `overrides`; torn down after the test.

    Recording goes to the test's temporary folder and is off unless asked for
    (`record=True`). Each stack gets its own free port, so stacks never meet.
    """
    started: list[ProcessStack] = []

    def start(
        services: list[str],
        *overrides: str | Overrides,
        record: bool = False,
        timeout_s: float = 90.0,
        wait_for: list[str] | None = None,
    ) -> ProcessStack:
        """`overrides`: data, or `section.key=value` flags as a user would type them."""
        settings = merged(
            {"recording.dir": str(tmp_path / "recordings"), "recording.enabled": record},
            *(parse_overrides([o]) if isinstance(o, str) else o for o in overrides),
        )
        s = ProcessStack(services, settings)
        started.append(s)
        s.launch()
        if wait_for is None:
            wait_for = [n for n in services if n in MODULES and n != "router"]
        s.wait_ready(wait_for, timeout_s)
        return s

    yield start
    for s in started:
        codes = s.stop()
        for name, code in codes.items():
            if code not in (0, None, -9, -2):
                print(f"--- {name} exited {code}:\n{s.log_text(name)[-3000:]}")
