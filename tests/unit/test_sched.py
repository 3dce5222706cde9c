"""Real-time scheduling: all of the process's threads or none, and a refusal says why."""

from __future__ import annotations

import os
import threading

import pytest

from common.sched import CpuLayout, allowed_cpus, make_realtime, pin


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


def test_split_puts_the_control_chain_on_the_first_cpu_and_the_rest_on_the_others() -> None:
    layout = CpuLayout.of("split", {2, 3, 5})
    assert layout.of_role("control") == {2}
    assert layout.of_role("rest") == {3, 5}


def test_one_cpu_or_layout_any_leaves_placement_to_the_os() -> None:
    assert CpuLayout.of("split", {0}) == CpuLayout()
    assert CpuLayout.of("any", {0, 1}).of_role("control") is None
    assert pin(None) == ""


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="Linux affinity calls")
def test_a_pinned_thread_runs_only_there_and_its_threads_inherit_it() -> None:
    before = os.sched_getaffinity(0)
    first = min(allowed_cpus())
    seen: dict[str, set[int]] = {}

    def child() -> None:
        seen["child"] = os.sched_getaffinity(0)

    def pinned() -> None:
        assert pin(frozenset({first})) == ""
        seen["pinned"] = os.sched_getaffinity(0)
        t = threading.Thread(target=child)
        t.start()
        t.join()

    t = threading.Thread(target=pinned)
    t.start()
    t.join()
    assert seen == {"pinned": {first}, "child": {first}}
    assert os.sched_getaffinity(0) == before  # the caller's thread is untouched


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="Linux affinity calls")
def test_a_cpu_the_machine_lacks_is_refused_with_the_reason() -> None:
    why = pin(frozenset({4096}))
    assert why.startswith("CPUs [4096] refused")
