"""A service's life: config, logging, Zenoh session, recording, readiness, clean stop.

    def main(svc: Service) -> None:
        pub = svc.bus.publisher(...)      # declare what it needs
        svc.ready()                       # liveliness token: now it serves
        while not svc.stopping:           # loops wait with timeouts, never forever
            ...

    if __name__ == "__main__":
        run("perception", main)

`run` parses `--set key=value` flags, loads the config (bad config fails loudly, exit 2),
opens the session (a client that waits for the router) and the rerun stream, and turns
SIGINT/SIGTERM into `svc.stop`, so every loop ends within its wait timeout and the
session closes well inside 2 s. A service ends with its launcher (supervisord, a
test's or an eval's stack): when that process dies, even by SIGKILL, the kernel sends
the service SIGTERM (`exit_with_parent`), so a killed launcher leaves no stack behind.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import faulthandler
import json
import logging
import os
import secrets
import signal
import sys
import threading
import tracemalloc
from collections.abc import Callable, Sequence
from types import FrameType

import rerun as rr

from common.access import identity_of, not_allowed
from common.bus import Bus
from common.config import Config, ConfigError, load_config
from common.keys import RobotKeys
from common.recording import RerunHandler, open_recording
from common.sched import CpuLayout, Role, allowed_cpus, pin
from common.truth import TruthGuard

#: This process's run: its second liveliness token says it (`Service.ready`).
RUN = secrets.token_hex(6)

log = logging.getLogger(__name__)


class Service:
    """What a running service holds: config, keys, bus, recording and the stop event."""

    def __init__(
        self,
        name: str,
        config: Config,
        bus: Bus,
        rec: rr.RecordingStream,
        cpus: CpuLayout | None = None,
    ) -> None:
        self.name = name
        #: The machine's CPUs by role (`cpu.layout`), as computed before this process
        #: pinned itself: a thread of the other role pins itself to `cpus.rest`.
        self.cpus = cpus or CpuLayout()
        self.config = config
        self.keys = RobotKeys(config.robot)
        self.bus = bus
        self.rec = rec
        self.stop = threading.Event()
        self.log = logging.getLogger(f"dume.{name}")
        self.is_ready = False

    @property
    def stopping(self) -> bool:
        return self.stop.is_set()

    def ready(self) -> None:
        """Declare the liveliness tokens (its run's first, `common.lifelines`): the
        service now serves what it declared."""
        self.bus.declare_alive(self.keys.alive_run(self.name, RUN))
        self.bus.declare_alive(self.keys.alive(self.name))
        # a router lost and back: what it put into the cut is sent again (`LinkBack`)
        self.bus.watch_own_link(self.keys.alive_run(self.name, RUN))
        self.is_ready = True
        self.log.info("ready; takes %s", json.dumps(self.bus.inputs))
        if self.config.zenoh.access_control:
            for verb, key in not_allowed(self.config, self.name, self.bus.used):
                self.log.warning(
                    "%s %s: its access rule (common.access) does not allow it; the router "
                    "lets nothing through", verb, key,
                )  # fmt: skip


def place(name: str, config: Config) -> CpuLayout:
    """Pin this process to its role's CPUs (`cpu.layout`; before any thread starts: they
    inherit it); the machine's layout, for threads of the other role."""
    layout = CpuLayout.of(config.cpu.layout, allowed_cpus())
    role: Role = "control" if name in config.cpu.control else "rest"
    cpus = layout.of_role(role)
    if why := pin(cpus):
        log.warning("%s: %s runs on any CPU", why, name)
    elif cpus is not None:
        log.info("%s runs on CPUs %s (%s)", name, sorted(cpus), role)
    return layout


def parse_args(name: str, argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=f"python -m services.{name}")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a setting, e.g. --set sim.world=small (repeatable)",
    )
    parser.add_argument("--config", help="config file (default deploy/config.toml)")
    return parser.parse_args(argv)


def setup_logging(level: str, name: str) -> None:
    # A native crash (a segfault in a C extension) leaves every thread's Python stack in
    # the service's log instead of a bare "terminated by SIGSEGV" from supervisord.
    faulthandler.enable(file=sys.stderr, all_threads=True)
    # `kill -USR1 <pid>`: every thread's stack to the log, the process going on (what a
    # service that does not ack its tick is waiting for).
    faulthandler.register(signal.SIGUSR1, file=sys.stderr, all_threads=True, chain=False)
    logging.basicConfig(
        level=level,
        format=f"%(asctime)s {name} %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
        force=True,
    )


#: `prctl(2)`'s option that asks for a signal when the parent dies (Linux).
PR_SET_PDEATHSIG = 1
#: The C library, loaded once here: never inside a forked child, where loading may
#: deadlock on a lock another thread of the parent held.
_LIBC = ctypes.CDLL(None)


#: The launcher's pid, set by `deploy.stack.ProcessStack` in the environment of each
#: process it starts (and read by that process alone: `exit_with_parent` drops it).
PARENT_PID_ENV = "DUME_PARENT_PID"


def exit_with_parent(sig: int = signal.SIGTERM) -> bool:
    """Ask the kernel for `sig` when this process's parent dies (Linux's
    `PR_SET_PDEATHSIG`), so a service or router whose launcher was killed stops cleanly
    instead of serving on unmanaged. False where the call is not there (not Linux).
    The kernel does not see a parent that died before the call: call it first thing
    (`run`, the router), and a parent seen to go while it is made sends `sig` now; so
    does a parent other than the launcher that `PARENT_PID_ENV` names (it died while
    this process was starting: a trial killed as its stack came up left its mission
    serving on). Safe in a `Popen(preexec_fn=...)` of a process `PARENT_PID_ENV` is not
    set in (supervisord's, by `dume up`): no lock is taken, no Python object shared."""
    if not sys.platform.startswith("linux"):
        return False
    named = os.environ.pop(PARENT_PID_ENV, "")
    parent = int(named) if named.isdigit() else os.getppid()
    if _LIBC.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
        return False
    if os.getppid() != parent:  # orphaned before the kernel could be told
        os.kill(os.getpid(), sig)
    return True


def _install_signals(stop: threading.Event, interrupt: Callable[[], None]) -> None:
    """SIGINT and SIGTERM stop the service: `stop` is set, and every wait on its bus ends
    (`interrupt`, on a thread of its own: not inside the handler, which may have
    interrupted the main thread holding a subscription's lock)."""

    def handler(signum: int, frame: FrameType | None) -> None:
        del frame
        log.info("signal %s: stopping", signal.Signals(signum).name)
        stop.set()
        threading.Thread(target=interrupt, name="interrupt", daemon=True).start()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    signal.signal(
        signal.SIGUSR2,
        lambda _s, _f: threading.Thread(target=_memory_report, name="memory", daemon=True).start(),
    )


_last_snapshot: list[tracemalloc.Snapshot] = []


def _memory_report() -> None:
    """On SIGUSR2 (on a thread of its own: the handler may have interrupted the main
    thread in the logging lock): where the process's Python memory is, to its log: the
    lines that allocated most, and what grew since the last report. Only while
    tracemalloc traces (start the service with `PYTHONTRACEMALLOC=5`); a diagnostic for
    `dume trial soak`'s growth."""
    # Not at the WBC's real-time priority, which its threads inherit: a snapshot takes
    # seconds of CPU, and at SCHED_FIFO it starved every normal thread on the core (the
    # Zenoh links of this and another stack's WBC ran out their 10 s lease).
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
    if not tracemalloc.is_tracing():
        log.info("SIGUSR2: tracemalloc is off (PYTHONTRACEMALLOC=5 turns it on)")
        return
    snap = tracemalloc.take_snapshot().filter_traces(
        [tracemalloc.Filter(False, tracemalloc.__file__)]
    )
    current, peak = tracemalloc.get_traced_memory()
    log.info("memory: %.1f MB traced (peak %.1f MB)", current / 1e6, peak / 1e6)
    for stat in snap.statistics("lineno")[:10]:
        log.info("memory: %s", stat)
    if _last_snapshot:
        for diff in snap.compare_to(_last_snapshot[0], "lineno")[:10]:
            log.info("memory grew: %s", diff)
    _last_snapshot[:] = [snap]


def run(
    name: str,
    main: Callable[[Service], None],
    argv: Sequence[str] | None = None,
    extra_overrides: Sequence[str] = (),
) -> int:
    """Run a service to completion; the process's exit code."""
    exit_with_parent()  # before anything that may wait (the router): no stack outlives it
    args = parse_args(name, argv)
    try:
        config = load_config([*extra_overrides, *args.overrides], path=args.config)
    except ConfigError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return 2
    setup_logging(config.log.level, name)
    layout = place(name, config)
    rec = open_recording(name, config.recording)
    if config.recording.enabled:
        logging.getLogger("dume").addHandler(RerunHandler(rec, name))
    user = identity_of(name, config.robot)
    bus = Bus.open(config, guard=TruthGuard.of(name, config), user=user)
    svc = Service(name, config, bus, rec, layout)
    _install_signals(svc.stop, bus.interrupt)
    try:
        main(svc)
    except Exception:
        log.exception("%s failed", name)
        return 1
    finally:
        svc.stop.set()
        log.info("%s used %s", name, json.dumps(sorted(bus.used)))  # [[verb, key], ...]
        bus.close()
        if config.recording.enabled:
            rec.flush()
            rec.disconnect()
    log.info("%s stopped", name)
    return 0
