"""Real-time scheduling for a process's threads, where the OS allows it.

A controller's tick is short (a third of a millisecond) but waits for a CPU under the
normal scheduler whenever both cores are busy: on a 2-core machine running the whole
stack, one tick in a hundred waited 1-5 ms (`dume bench stack`). Under `SCHED_FIFO` a
runnable thread takes a core at once from every normal thread. `make_realtime(priority)`
moves every thread the process has now (Linux: `/proc/self/task`) to `SCHED_FIFO` at
`priority`; threads started later inherit it. Without the right (`CAP_SYS_NICE` or an
`RLIMIT_RTPRIO` that allows the priority) nothing changes and the reason is returned.
A real-time thread that never blocked would starve the machine: only for loops that
wait for their input every tick.
"""

from __future__ import annotations

import contextlib
import os


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
