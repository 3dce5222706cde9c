"""Start and stop a dume stack: supervisord for users, plain processes for tests.

Both keep the run's files in its folder, `var/run/<run id>/` (`deploy.runs`: the logs,
the settings, the recording, `run.json`), and hand a run's settings to every process of
the stack, so each reads the same configuration: the Zenoh port, the run id and the
run's folder in the environment (`DUME_*`), and the overrides, given as data
(`{"sim.world": "small"}`), written once to `<run dir>/settings.json` (`DUME_SETTINGS`,
see `common.config`). `Supervised` runs `supervisord -c deploy/supervisord.conf`, which
restarts a service that dies; `ProcessStack` starts the router and any subset of
services as child processes, so a test can kill one and watch what the others do.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import msgspec

from common.access import TRUSTED, services_on
from common.bus import AliveWatch, Bus
from common.config import (
    ENV_START,
    REPO_ROOT,
    Config,
    Overrides,
    load_config,
    merged,
    write_settings,
)
from common.keys import SERVICES, RobotKeys, service_of_alive_key
from common.recording import new_run_id
from common.service import PARENT_PID_ENV, exit_with_parent
from deploy.runs import (
    RUNS_DIR,
    Kind,
    RunInfo,
    ctl_secret,
    current_user,
    mark_ended,
    now_iso,
    write_info,
)

log = logging.getLogger(__name__)

SUPERVISORD_CONF = REPO_ROOT / "deploy" / "supervisord.conf"
#: s to reap a process after its SIGKILL before the stop goes on without it (a loaded
#: machine once took longer, and the eval died with the rest of its stack left running).
KILL_WAIT_S = 10.0
#: Python modules of the processes a stack can run.
MODULES = {
    "router": "services.router",
    "sim": "services.sim",
    "hold": "services.sim.hold",
    "perception": "services.perception",
    "semantic_map": "services.semantic_map",
    "navigation": "services.navigation",
    "localization": "services.localization",
    "wbc": "services.wbc",
    "mission": "services.mission",
}


def free_port() -> int:
    """A TCP port on loopback that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def stack_env(
    *,
    port: int,
    run_id: str,
    run_dir: Path,
    settings: Mapping[str, str] | None = None,
    base: Mapping[str, str] | None = None,
    side: str = "all",
) -> dict[str, str]:
    """The environment of every process of one stack; `side`: the services this host
    runs (`zenoh.side`), which supervisord starts (`DUME_START_<SERVICE>`)."""
    env = dict(os.environ if base is None else base)
    on = services_on(side)
    env.update({f"{ENV_START}{s.upper()}": str(s in on).lower() for s in SERVICES})
    env.update(
        {
            "DUME_PYTHON": sys.executable,
            "DUME_ZENOH_PORT": str(port),
            "DUME_RECORDING_RUN_ID": run_id,
            "DUME_RUN_DIR": str(run_dir),
            "DUME_USER": current_user(),
            "DUME_CTL_PASSWORD": ctl_secret(run_dir),
            "MUJOCO_GL": env.get("MUJOCO_GL", "egl"),
            "PYTHONUNBUFFERED": "1",
            # Every process of the stack (the router, supervisord's children, a test's
            # own) prints all threads' Python stacks on a native crash.
            "PYTHONFAULTHANDLER": "1",
            # One string hash for every run: no set or dict of names iterates in an order
            # that differs from run to run.
            "PYTHONHASHSEED": "0",
        }
    )
    env.update(settings or {})
    return env


#: The localization's lockstep participation when the robot estimates its base: at the
#: lidar's rate, its correction taking effect one scan later.
LOCALIZATION = {"role": "periodic", "period_s": 0.1, "latency_s": 0.1}


def with_start_pose(overrides: Overrides, services: Sequence[str] | None = None) -> dict[str, Any]:
    """The overrides of a robot on its own odometry (`wbc.base_state = "estimate"`):
    the localization becomes a lockstep participant, and `localization.start_pose` is
    filled in from the world's start when none was given (the user's default: the pose
    a person would type for the demo's world). Unchanged for the truth ablation; the
    participant only when `services` (None: every one) includes the localization."""
    out = dict(overrides)
    config = load_config(out)
    if not config.odom_from_estimate():
        return out
    runs = services is None or "localization" in services
    if runs and "localization" not in config.time.participants:
        out["time.participants.localization"] = dict(LOCALIZATION)
    if config.localization.start_pose is None:
        from services.sim.world import generate_world

        start = generate_world(config.sim.world_seed, config.sim.world).robot_start
        out["localization.start_pose"] = [start.x, start.y, start.yaw]
    return out


def settings_env(run_dir: Path, overrides: Overrides) -> dict[str, str]:
    """The overrides of every process of a stack: written to the run's settings file,
    named by `DUME_SETTINGS`."""
    path = run_dir / "settings.json"
    write_settings(path, overrides)
    return {"DUME_SETTINGS": str(path)}


class _Stack:
    """What both kinds of stack share: config, a client bus, readiness."""

    def __init__(
        self,
        overrides: Overrides,
        port: int | None,
        run_id: str | None,
        services: Sequence[str] | None = None,
        kind: Kind = "stack",
    ) -> None:
        """`services`: the ones this stack runs (None: every one); `kind`: what `run.json`
        calls it (`deploy.runs`)."""
        self.port = port or free_port()
        self.run_id = run_id or new_run_id()
        self.run_dir = RUNS_DIR / self.run_id
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.overrides = with_start_pose(overrides, services)
        self.env = stack_env(
            port=self.port,
            run_id=self.run_id,
            run_dir=self.run_dir,
            settings=settings_env(self.run_dir, self.overrides),
            side=load_config(self.overrides).zenoh.side,
        )
        self.config: Config = load_config(env=self.env)
        self.keys = RobotKeys(self.config.robot)
        sim = self.config.sim
        write_info(
            self.run_dir,
            RunInfo(
                run_id=self.run_id,
                port=self.port,
                pid=os.getpid(),
                kind=kind,
                world=sim.world,
                world_seed=sim.world_seed,
                started=now_iso(),
            ),
        )
        self._bus: Bus | None = None
        self._alive: AliveWatch | None = None

    @property
    def bus(self) -> Bus:
        """A client session on this stack (opened on first use)."""
        if self._bus is None:
            self._bus = Bus.open(self.config, user=TRUSTED)
            self._alive = self._bus.watch_alive(self.keys.alive_all)
        return self._bus

    def alive(self) -> set[str]:
        """The services alive now. One is down only when both the session's liveliness
        subscription and a liveliness query say so: under load a query can end with no
        reply at all (a demo once reported every service down at its end)."""
        bus = self.bus
        assert self._alive is not None
        keys = self._alive.alive() | bus.alive_now(self.keys.alive_all)
        return {service_of_alive_key(k) for k in keys}

    def wait_ready(self, services: Sequence[str], timeout_s: float = 60.0) -> None:
        """Wait until `services` are alive.

        The wait has a session of its own when `bus` is not open yet, so that `bus` opens
        after every service declared its queryables and receives them as current
        declarations, not as news racing the session's own start.
        """
        own = Bus.open(self.config, user=TRUSTED) if self._bus is None else None
        bus = own or self.bus
        watch = bus.watch_alive(self.keys.alive_all)
        try:
            watch.wait_for({self.keys.alive(s) for s in services}, timeout_s)
        finally:
            watch.undeclare()
            if own is not None:
                own.close()

    def ended(self) -> None:
        """The stack is down: `run.json` says so (its launcher may live on)."""
        mark_ended(self.run_dir)

    def close_bus(self) -> None:
        if self._alive is not None:
            self._alive.undeclare()
            self._alive = None
        if self._bus is not None:
            self._bus.close()
            self._bus = None


def only_started(services: Sequence[str], overrides: Overrides) -> dict[str, Any]:
    """Overrides that drop the lockstep participants of dume services not started.

    The sim waits at t = 0 for every configured participant; a stack that runs a subset
    of the services must not list the others. Participants that are not dume services
    (a test's own) stay as configured.
    """
    participants = load_config(overrides).time.participants
    kept = {n: p for n, p in participants.items() if n in services or n not in MODULES}
    if kept.keys() == participants.keys():
        return {}
    return {"time.participants": {n: msgspec.to_builtins(p) for n, p in kept.items()}}


def troubles_in(log: str) -> list[str]:
    """A service log's WARNING and ERROR lines and its tracebacks, whole."""
    said: list[str] = []
    in_traceback = False
    for line in log.splitlines():
        if line.startswith(("Traceback", "During handling")):
            in_traceback = True
        if (in_traceback and line) or " WARNING " in line or " ERROR " in line:
            said.append(line)
        if in_traceback and line and not line.startswith((" ", "Traceback", "During")):
            in_traceback = False  # the exception's own line ends it
    return said


class ProcessStack(_Stack):
    """The router and some services as child processes (for tests and benchmarks).

    Only the started services are lockstep participants (see `only_started`), and on one
    host of a split stack (`zenoh.side`) the other host's as well.
    """

    def __init__(
        self,
        services: Sequence[str],
        overrides: Overrides | None = None,
        *,
        port: int | None = None,
        run_id: str | None = None,
    ) -> None:
        names = [n for n in services if n in MODULES]
        overrides = overrides or {}
        # one host of two (`zenoh.side`): the other host's services are participants too
        split = load_config(overrides).zenoh.side != "all"
        started = only_started(list(MODULES) if split else names, overrides)
        super().__init__(merged(overrides, started), port, run_id, names)
        self.services = list(services)
        self.procs: dict[str, subprocess.Popen[bytes]] = {}

    def launch(self) -> ProcessStack:
        """Spawn the router and the services, without waiting for them (`start` waits)."""
        self.spawn("router")
        for name in self.services:
            self.spawn(name)
        return self

    def start(self, timeout_s: float = 60.0) -> ProcessStack:
        self.launch()
        self.wait_ready([s for s in self.services if s in MODULES], timeout_s)
        return self

    def spawn(self, name: str, *args: str) -> subprocess.Popen[bytes]:
        module = MODULES.get(name, name)
        logfile = open(self.run_dir / f"{name.replace('.', '_')}.log", "ab")  # noqa: SIM115
        proc = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            cwd=REPO_ROOT,
            env={**self.env, PARENT_PID_ENV: str(os.getpid())},  # `exit_with_parent`
            stdout=logfile,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        logfile.close()
        self.procs[name] = proc
        return proc

    def kill(self, name: str, sig: int = signal.SIGKILL) -> None:
        proc = self.procs[name]
        if proc.poll() is None:
            os.killpg(proc.pid, sig)
        proc.wait(timeout=10)

    def log_text(self, name: str) -> str:
        path = self.run_dir / f"{name.replace('.', '_')}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def troubles(self, lines: int = 12) -> dict[str, list[str]]:
        """Each service's last `lines` WARNING/ERROR lines and traceback lines (its log's,
        for a failed run's report: CI keeps nothing else of it); services with none left
        out."""
        out: dict[str, list[str]] = {}
        for name in self.procs:
            if said := troubles_in(self.log_text(name)):
                out[name] = said[-lines:]
        return out

    def stop(self, timeout_s: float = 5.0) -> dict[str, int | None]:
        """SIGINT everything (services first, the router last); SIGKILL what lingers; each
        one's exit code (None: not reaped even after its SIGKILL)."""
        self.close_bus()
        order = [n for n in self.procs if n != "router"] + (
            ["router"] if "router" in self.procs else []
        )
        codes: dict[str, int | None] = {}
        for name in order:
            proc = self.procs[name]
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGINT)
            try:
                codes[name] = proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                log.warning("%s did not stop within %.1f s: killed", name, timeout_s)
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                try:
                    codes[name] = proc.wait(timeout=KILL_WAIT_S)
                except subprocess.TimeoutExpired:  # not reaped yet: the rest still stop
                    log.error("%s (pid %d) still there %.0f s after SIGKILL", name, proc.pid,
                              KILL_WAIT_S)  # fmt: skip
                    codes[name] = None
        self.ended()
        return codes

    def __enter__(self) -> ProcessStack:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


class Supervised(_Stack):
    """`supervisord -c deploy/supervisord.conf` with the run's environment."""

    def __init__(
        self,
        overrides: Overrides | None = None,
        *,
        port: int | None = None,
        run_id: str | None = None,
    ) -> None:
        super().__init__(overrides or {}, port, run_id, kind="demo")
        self.proc: subprocess.Popen[bytes] | None = None

    def command(self) -> list[str]:
        exe = Path(sys.executable).with_name("supervisord")
        return [str(exe), "-c", str(SUPERVISORD_CONF)]

    def ctl(self, *args: str) -> str:
        exe = Path(sys.executable).with_name("supervisorctl")
        out = subprocess.run(
            [str(exe), "-c", str(SUPERVISORD_CONF), *args],
            env=self.env,
            capture_output=True,
            text=True,
            timeout=30,
        )
        return out.stdout

    def start(self) -> Supervised:
        self.proc = subprocess.Popen(
            self.command(),
            cwd=REPO_ROOT,
            env=self.env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
            preexec_fn=exit_with_parent,  # its launcher killed: supervisord stops its programs
        )
        return self

    def stop(self, timeout_s: float = 20.0) -> int | None:
        self.close_bus()
        if self.proc is None:
            self.ended()
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            return self.proc.wait(timeout=5)
        finally:
            self.ended()


def wait_until(predicate: Callable[[], bool], timeout_s: float, poll_s: float = 0.05) -> bool:
    """Poll `predicate()` until true or the timeout; True when it became true."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return False
