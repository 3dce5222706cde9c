"""A stack whose launcher is killed does not outlive it: a test run or an eval killed
by SIGKILL once left a whole stack serving on for hours. Every service and router asks
the kernel for SIGTERM when its parent dies (`common.service.exit_with_parent`) and
stops as it does on Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from common.config import REPO_ROOT
from common.service import PARENT_PID_ENV
from deploy.runs import pid_alive
from deploy.stack import wait_until
from tests.integration.test_map_service import map_settings

pytestmark = pytest.mark.integration

#: A launcher as a test or an eval is one: it starts a stack, says its processes, waits.
LAUNCHER = """
import json, sys, time
from deploy.stack import ProcessStack
from common.config import parse_overrides
stack = ProcessStack(["semantic_map"], parse_overrides(json.loads(sys.argv[1])))
stack.start()
print(json.dumps({"run_dir": str(stack.run_dir),
                  "pids": {n: p.pid for n, p in stack.procs.items()}}), flush=True)
time.sleep(600)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_the_services_of_a_killed_launcher_stop_cleanly(tmp_path: Path) -> None:
    settings = [*map_settings(str(tmp_path / "map")), "recording.enabled=false"]
    launcher = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(LAUNCHER), json.dumps(settings)],
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    pids: dict[str, int] = {}
    try:
        assert launcher.stdout is not None
        started = json.loads(launcher.stdout.readline())
        pids = started["pids"]
        assert set(pids) == {"router", "semantic_map"}
        launcher.kill()  # SIGKILL: nothing of its own cleans up
        launcher.wait(timeout=10)
        assert wait_until(lambda: not any(map(pid_alive, pids.values())), 20, poll_s=0.2), pids
        # they stopped as on Ctrl-C, not killed: each says so in its log
        for name in pids:
            log = (Path(started["run_dir"]) / f"{name}.log").read_text()
            assert f"{name} stopped" in log, log[-1500:]
    finally:
        for pid in pids.values():
            if pid_alive(pid):
                os.kill(pid, signal.SIGKILL)


#: A process that asks for its parent's death as a service does, then lives 2 s.
CHILD = (
    "import time; from common.service import exit_with_parent; "
    "print(exit_with_parent(), flush=True); time.sleep(2)"
)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_service_whose_launcher_died_as_it_started_stops_at_once() -> None:
    """The kernel does not see a parent that died before `exit_with_parent`: a trial
    killed as its stack came up left its mission serving on. The launcher names itself
    (`PARENT_PID_ENV`); a process whose parent is another stops with SIGTERM."""

    def child(parent_pid: int) -> subprocess.CompletedProcess[str]:
        env = {**os.environ, PARENT_PID_ENV: str(parent_pid)}
        return subprocess.run(
            [sys.executable, "-c", CHILD], cwd=REPO_ROOT, env=env, capture_output=True,
            text=True, timeout=30,
        )  # fmt: skip

    launched = child(os.getpid())  # its parent is the launcher it names: it lives on
    assert launched.returncode == 0 and launched.stdout.strip() == "True", launched
    orphan = child(1)  # named a launcher that is not its parent: it has gone
    assert orphan.returncode == -signal.SIGTERM, orphan
