"""Real-time scheduling and CPU placement for a process's threads, where the OS allows it.

A controller's tick is short (a third of a millisecond) but waits for a CPU under the
normal scheduler whenever both cores are busy: on a 2-core machine running the whole
stack, one tick in a hundred waited 1-5 ms (`dume bench stack`). Under `SCHED_FIFO` a
runnable thread takes a core at once from every normal thread. `make_realtime(priority)`
moves every thread the process has now (Linux: `/proc/self/task`) to `SCHED_FIFO` at
`priority`; threads started later inherit it. Without the right (`CAP_SYS_NICE` or an
`RLIMIT_RTPRIO` that allows the priority) nothing changes and the reason is returned.
A real-time thread that never blocked would starve the machine: only for loops that
wait for their input every tick.

`CpuLayout.of(layout, allowed)` says which CPUs each role runs on under a `cpu.layout`
(`common.config.CpuSettings`): `control` gets the lowest CPU the process may use, `rest`
the others. `pin(cpus)` moves the calling thread there (threads it starts later inherit
it), so a process pins itself before it opens its session, and a thread that belongs to
the other role (the sim's renderer) pins itself first, from the layout computed before.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Set
from dataclasses import dataclass
from typing import Literal

Role = Literal["control", "rest"]


def make_realtime(priority: int) -> str:
    """Every thread of this process to `SCHED_FIFO` at `priority` (1-99); "" when done,
    else why not (nothing changed)."""
    if not hasattr(os, "sched_setscheduler"):
        return "this OS has no SCHED_FIFO"
    param = os.sched_param(priority)
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        tids = [0]
    done = []
    try:
        for tid in tids:
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, param)
            except ProcessLookupError:  # the thread ended meanwhile
                continue
            done.append(tid)
    except OSError as exc:
        for tid in done:  # all or nothing
            with contextlib.suppress(OSError):
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
        return f"SCHED_FIFO {priority} refused: {exc.strerror or exc}"
    return ""


def allowed_cpus() -> frozenset[int]:
    """The CPUs this process may run on (all of them where the OS cannot say)."""
    if hasattr(os, "sched_getaffinity"):
        return frozenset(os.sched_getaffinity(0))
    return frozenset(range(os.cpu_count() or 1))


@dataclass(frozen=True)
class CpuLayout:
    """The CPUs of each role; None: the OS places the role's threads."""

    control: frozenset[int] | None = None
    rest: frozenset[int] | None = None

    @classmethod
    def of(cls, layout: str, allowed: Set[int]) -> CpuLayout:
        """`layout` ("split" or "any") over the CPUs `allowed`."""
        if layout != "split" or len(allowed) < 2:
            return cls()
        first = min(allowed)
        return cls(frozenset({first}), frozenset(allowed) - {first})

    def of_role(self, role: Role) -> frozenset[int] | None:
        return self.control if role == "control" else self.rest


def pin(cpus: Set[int] | None) -> str:
    """Run the calling thread on `cpus` (None: unchanged); "" when done, else why not."""
    if cpus is None:
        return ""
    if not hasattr(os, "sched_setaffinity"):
        return "this OS cannot pin threads to CPUs"
    try:
        os.sched_setaffinity(0, cpus)
    except OSError as exc:
        return f"CPUs {sorted(cpus)} refused: {exc.strerror or exc}"
    return ""
