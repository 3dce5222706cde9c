"""`troubles_in`: what a failed run's report keeps of a service's log (CI keeps no logs);
and a stack's stop that goes on past a process it cannot reap."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

import deploy.stack as stack_module
from deploy.stack import ProcessStack, troubles_in

LOG = """\
2026-11-27 12:51:32,727 navigation INFO common.service: navigation runs on CPUs [1] (rest)
2026-11-27 12:51:35,638 navigation WARNING dume.navigation: body guard: stand
2026-11-27 12:51:36,062 navigation INFO dume.navigation: map from semantic map
Traceback (most recent call last):
  File "services/navigation/node.py", line 10, in tick
    self._caps(now)
ValueError: math domain error

During handling of the above exception, another exception occurred:

Traceback (most recent call last):
  File "common/service.py", line 3, in run
RuntimeError: tick failed
2026-11-27 12:51:37,000 navigation INFO dume.navigation: goal nav_2 succeeded
2026-11-27 12:51:38,000 navigation ERROR common.service: navigation stopped
"""


def test_a_log_gives_its_warnings_errors_and_whole_tracebacks_and_nothing_else() -> None:
    said = troubles_in(LOG)
    assert said[0].endswith("body guard: stand")
    assert said[1:5] == LOG.splitlines()[3:7]  # the first traceback, its exception's line last
    assert "During handling of the above exception, another exception occurred:" in said
    assert said[-2] == "RuntimeError: tick failed"
    assert said[-1].endswith("navigation stopped")
    assert not any(" INFO " in line for line in said)


def test_a_quiet_log_gives_nothing() -> None:
    assert troubles_in("2026-11-27 12:51:32,727 sim INFO common.service: ready\n") == []


def _child(code: str) -> subprocess.Popen[bytes]:
    """A Python child in a session of its own, returned once it runs `code` (it printed
    "up": its signal handlers are in place; a child of a background job inherits SIGINT
    ignored, and Python then leaves it so)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", f"{code}; print('up', flush=True); import time; time.sleep(60)"],
        start_new_session=True, stdout=subprocess.PIPE,
    )  # fmt: skip
    assert proc.stdout is not None and proc.stdout.readline() == b"up\n"
    return proc


class _Unreaped:
    """A child deaf to SIGINT that dies by its SIGKILL but, as on a loaded machine, is not
    reaped in time: every `wait` times out."""

    def __init__(self) -> None:
        self.proc = _child("import signal; signal.signal(signal.SIGINT, signal.SIG_IGN)")
        self.pid = self.proc.pid

    def poll(self) -> int | None:
        return self.proc.poll()

    def wait(self, timeout: float | None = None) -> int:
        raise subprocess.TimeoutExpired("unreaped", timeout or 0.0)


def test_a_process_not_reaped_after_its_sigkill_does_not_keep_the_rest_of_the_stack_up(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The eval's stack stop raised when the sim was not reaped within 5 s of its SIGKILL,
    and left every other service of that stack running."""
    monkeypatch.setattr(stack_module, "KILL_WAIT_S", 0.1)
    stack = object.__new__(ProcessStack)
    hears = "import signal; signal.signal(signal.SIGINT, signal.default_int_handler)"
    stuck, other, router = _Unreaped(), _child(hears), _child(hears)  # as a service does
    stack.procs = {"sim": stuck, "navigation": other, "router": router}  # type: ignore[dict-item]
    stack._alive, stack._bus, stack.run_dir = None, None, tmp_path
    try:
        codes = stack.stop(timeout_s=30.0)  # the unreaped one's wait fails at once
    finally:
        stuck.proc.kill()
        stuck.proc.communicate()
        for p in (other, router):
            p.communicate()
    assert codes["sim"] is None  # said, and passed over
    assert codes["navigation"] == -signal.SIGINT and codes["router"] == -signal.SIGINT
    assert stuck.proc.returncode == -signal.SIGKILL  # it was killed all the same
