"""Real-time scheduling: all of the process's threads or none, and a refusal says why."""

from __future__ import annotations

import os
import threading

import pytest

from common.sched import make_realtime


def _policies() -> set[int]:
    return {os.sched_getscheduler(int(t)) for t in os.listdir("/proc/self/task")}


@pytest.mark.skipif(not hasattr(os, "sched_setscheduler"), reason="Linux scheduling calls")
def test_every_thread_moves_to_fifo_or_none_does() -> None:
    stop = threading.Event()
    helper = threading.Thread(target=stop.wait)
    helper.start()
    try:
        why = make_realtime(5)
        if why:  # no right to it here: nothing changed, and the reason names the refusal
            assert "refused" in why
            assert _policies() == {os.SCHED_OTHER}
        else:
            assert _policies() == {os.SCHED_FIFO}
            for t in os.listdir("/proc/self/task"):
                os.sched_setscheduler(int(t), os.SCHED_OTHER, os.sched_param(0))
    finally:
        stop.set()
        helper.join()


@pytest.mark.skipif(not hasattr(os, "sched_setscheduler"), reason="Linux scheduling calls")
def test_a_priority_the_os_refuses_changes_nothing_and_says_why() -> None:
    why = make_realtime(100)  # beyond SCHED_FIFO's 1-99
    assert why.startswith("SCHED_FIFO 100 refused")
    assert _policies() == {os.SCHED_OTHER}
