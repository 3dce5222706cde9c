"""`dume up` under supervisord: the stack comes up, says so, and a killed sim comes back."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from common.config import REPO_ROOT
from deploy.demo import SERVICES
from deploy.stack import SUPERVISORD_CONF, free_port, wait_until
from tests.conftest import dume

pytestmark = pytest.mark.integration


def alive(port: int) -> set[str]:
    out = dume("status", "--port", str(port), "--wait", "0.1")
    return set(json.loads(out.stdout)["alive"]) if out.stdout.strip() else set()


def sim_pid(run_dir: str) -> int:
    env = dict(os.environ, DUME_RUN_DIR=run_dir, DUME_PYTHON=sys.executable)
    out = subprocess.run(
        [
            str(Path(sys.executable).with_name("supervisorctl")),
            "-c",
            str(SUPERVISORD_CONF),
            "pid",
            "sim",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=30,
    )
    return int(out.stdout.strip()) if out.stdout.strip().isdigit() else 0


def test_dume_up_runs_the_stack_and_restarts_a_killed_sim(tmp_path: Path) -> None:
    port = free_port()
    up = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "deploy.cli",
            "up",
            "--port",
            str(port),
            "--world",
            "small",
            "--set",
            f'recording.dir="{tmp_path}"',
            "--set",
            "sim.cameras=[]",
        ],
        cwd=REPO_ROOT,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
    )
    try:
        assert up.stderr is not None
        banner = up.stderr.readline()
        match = re.search(r"logs in (\S+)", banner)
        assert match, banner
        run_dir = match.group(1)
        assert wait_until(lambda: set(SERVICES) <= alive(port), 180, poll_s=1.0)
        status = json.loads(dume("status", "--port", str(port)).stdout)
        assert set(SERVICES) <= set(status["alive"])
        assert status["missing"] == []

        first = sim_pid(run_dir)
        assert first > 0
        os.kill(first, signal.SIGKILL)
        assert wait_until(lambda: sim_pid(run_dir) not in (0, first), 60, poll_s=0.5)
        assert wait_until(lambda: "sim" in alive(port), 120, poll_s=1.0)
    finally:
        os.killpg(up.pid, signal.SIGTERM)
        up.wait(timeout=30)
    assert wait_until(lambda: not alive(port), 30, poll_s=1.0)
