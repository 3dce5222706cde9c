"""`dume up` under supervisord, as the README's "Using dume" has a user do it: the stack
comes up in the background and says where its run's files are; `dume status --ready`
waits for it; the map lists what to ask for; `dume request --wait` gets the object
handed over; `dume logs`, `dume ctl` and `dume runs` find the run; `dume down` stops it.
And a killed service comes back (supervisord restarts it), a killed sim does not (the
world is never restarted), and a killed supervisord takes its programs with it."""

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
from common.recording import default_blueprint, shown_by, view_origins
from common.service import exit_with_parent
from deploy.demo import SERVICES
from deploy.runs import RUNS_DIR, pid_alive, read_info
from deploy.stack import free_port, wait_until
from tests.conftest import dume

pytestmark = pytest.mark.integration


def alive(port: int) -> set[str]:
    out = dume("status", "--port", str(port), "--wait", "0.1")
    return set(json.loads(out.stdout)["alive"]) if out.stdout.strip() else set()


def pid_of(run_id: str, program: str) -> int:
    out = dume("ctl", "--run", run_id, "pid", program, timeout=30)
    return int(out.stdout.strip()) if out.stdout.strip().isdigit() else 0


def _up(port: int, *args: str) -> tuple[subprocess.Popen[str], str]:
    """`dume up` in the background, as `dume up &` in a shell; its run id. The stack
    ends with this test's process, even a killed one (`exit_with_parent`: `dume up`
    becomes supervisord, which stops its programs on SIGTERM)."""
    up = subprocess.Popen(
        [sys.executable, "-m", "deploy.cli", "up", "--port", str(port), *args],
        cwd=REPO_ROOT,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
        preexec_fn=exit_with_parent,
    )
    assert up.stderr is not None
    banner = up.stderr.readline() + up.stderr.readline()
    match = re.search(r"logs and recording: var/run/(\S+)/", banner)
    assert match, banner
    return up, match.group(1)


def _stop(up: subprocess.Popen[str]) -> None:
    if up.poll() is None:
        os.killpg(up.pid, signal.SIGTERM)
        up.wait(timeout=60)


@pytest.mark.slow
@pytest.mark.timeout(1800)  # a whole fetch in the small world under supervisord
def test_the_readme_sequence_hands_an_object_over_and_finds_its_runs_files() -> None:
    port = free_port()
    up, run_id = _up(port, "--world", "small", "--map", "truth")
    try:
        info = read_info(RUNS_DIR / run_id)
        assert info is not None and (info.kind, info.port) == ("up", port)
        ready = dume("status", "--port", str(port), "--ready", "300", timeout=400)
        assert ready.returncode == 0, ready.stdout + ready.stderr
        assert json.loads(ready.stdout)["missing"] == []
        mapped = json.loads(dume("map", "--port", str(port)).stdout)
        assert "bottle_1" in [a["id"] for a in mapped["artifacts"]]
        assert "person_1" in [p["id"] for p in mapped["people"]]
        # no --port: the one run that is up answers
        runs = [json.loads(line) for line in dume("runs").stdout.splitlines()]
        assert run_id in [r["run"] for r in runs]
        out = dume("request", "bottle_1", "--to", "person_1", "--port", str(port), "--wait",
                   timeout=1500)  # fmt: skip
        statuses = [json.loads(line) for line in out.stdout.splitlines()]
        assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
        assert statuses[-1]["state"] == "succeeded"
        listing = dume("logs", "--run", run_id).stdout
        for name in ("mission.log", "sim.log", "supervisord.log", "settings.json", "sim.rrd"):
            assert name in listing, (name, listing)
        assert "succeeded" in dume("logs", "mission", "--run", run_id, "-n", "400").stdout
        ctl = dume("ctl", "--run", run_id, "status").stdout
        assert re.search(r"^mission\s+RUNNING", ctl, re.M), ctl
        sup = (RUNS_DIR / run_id / "supervisord.log").read_text()
        assert "CRIT" not in sup, sup[:2000]
        down = dume("down", "--run", run_id, timeout=200)
        assert down.returncode == 0, down.stderr
        assert up.wait(timeout=30) is not None
        assert run_id not in dume("runs").stdout
    finally:
        _stop(up)
    # The recording read back: everything logged lies in one of the layout's views.
    origins = view_origins(default_blueprint())
    paths = recorded_entities(RUNS_DIR / run_id)
    for needed in ("/world/nav/plan", "/world/nav/costmap", "/world/cameras/camera_wrist",
                   "/world/map/artifacts", "/mission/tree", "/mission/decisions",
                   "/camera/camera_wrist/perception/masks", "/plots/wbc/qp_us"):  # fmt: skip
        assert needed in paths, needed
    assert "/viewport" in paths  # the layout itself travels in the recording (the sim's)
    data = {p for p in paths if not p.startswith(BLUEPRINT_ENTITIES)}
    hidden = sorted(p for p in data if not shown_by(p, origins))
    assert not hidden, hidden


#: Entities of the blueprint's own store, saved in the same file as the data.
BLUEPRINT_ENTITIES = (
    "/viewport", "/view/", "/container/", "/blueprint_panel", "/time_panel", "/selection_panel"
)  # fmt: skip


def recorded_entities(folder: Path) -> set[str]:
    """The entity paths of every `.rrd` in `folder` (`rerun rrd stats`)."""
    rerun = Path(sys.executable).with_name("rerun")
    paths: set[str] = set()
    for rrd in folder.glob("*.rrd"):
        out = subprocess.run([str(rerun), "rrd", "stats", str(rrd)], capture_output=True,
                             text=True, timeout=300).stdout  # fmt: skip
        entities = re.findall(r"^(/[^\s:]*): \d+$", out, re.M)
        paths |= {p for p in entities if not p.startswith("/__")}
    return paths


def test_dume_up_restarts_a_killed_service_but_never_the_world() -> None:
    port = free_port()
    up, run_id = _up(port, "--world", "small", "--set", "sim.cameras=[]")
    programs: list[int] = []
    try:
        assert wait_until(lambda: set(SERVICES) <= alive(port), 180, poll_s=1.0)
        status = json.loads(dume("status", "--port", str(port)).stdout)
        assert set(SERVICES) <= set(status["alive"])
        assert status["missing"] == []
        busy = dume("up", "--port", str(port), "--world", "small")
        assert busy.returncode == 1
        assert f"port {port} is in use (run {run_id})" in busy.stderr

        first = pid_of(run_id, "perception")
        assert first > 0
        os.kill(first, signal.SIGKILL)  # a service: restarted
        assert wait_until(lambda: pid_of(run_id, "perception") not in (0, first), 60, 0.5)
        assert wait_until(lambda: "perception" in alive(port), 120, poll_s=1.0)
        os.kill(pid_of(run_id, "sim"), signal.SIGKILL)  # the world: never restarted
        assert wait_until(lambda: "sim" not in alive(port), 30, poll_s=0.5)

        def died() -> dict[str, int]:
            return dict(json.loads(dume("status", "--port", str(port)).stdout)["died"])

        # Its liveliness goes with its socket; supervisord logs the exit when it reaps it.
        assert wait_until(lambda: "sim" in died(), 30, poll_s=0.5)
        said = dume("status", "--port", str(port))
        assert said.returncode == 1 and json.loads(said.stdout)["missing"] == ["sim"]
        assert json.loads(said.stdout)["died"] == {"perception": 1, "sim": 1}
        assert f"perception died in run {run_id}, restarted (1 time(s))" in said.stderr
        assert f"sim died in run {run_id}, not restarted: the world stopped" in said.stderr
        assert pid_of(run_id, "sim") == 0

        # supervisord itself killed: its programs stop (each asked the kernel for SIGTERM
        # when its parent dies), none serves on unmanaged
        programs += [pid_of(run_id, name) for name in ("router", *SERVICES) if name != "sim"]
        assert all(programs), programs
        os.kill(up.pid, signal.SIGKILL)
        up.wait(timeout=10)
        assert wait_until(lambda: not any(pid_alive(p) for p in programs), 30, poll_s=0.5)
    finally:
        _stop(up)
        for pid in filter(pid_alive, programs):  # what a failed check left
            os.kill(pid, signal.SIGKILL)
    assert wait_until(lambda: not alive(port), 30, poll_s=1.0)
