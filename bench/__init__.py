"""dume's benchmarks: `dume bench <name>` prints figures, JSON on the last line.

Benchmarks measure; they never assert. Quote medians: these machines are shared.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from common.config import Overrides


def _sim(overrides: Overrides) -> dict[str, Any]:
    from bench.sim import bench_sim

    return bench_sim(overrides)


def _wbc(overrides: Overrides) -> dict[str, Any]:
    from bench.wbc import bench_wbc

    return bench_wbc(overrides)


def _perception(overrides: Overrides) -> dict[str, Any]:
    from bench.perception import bench_perception

    return bench_perception(overrides)


def _nav(overrides: Overrides) -> dict[str, Any]:
    from bench.nav import bench_nav

    return bench_nav(overrides)


@dataclass(frozen=True)
class BenchOptions:
    """The command line's bench options: `rounds` (startup, decoders, deadwatch: how
    many stacks or processes; lapse: rounds a stall length); `sim_s` and `full` (stack:
    how long it measures); `run` (people-ids: a shift's output folder)."""

    rounds: int = 10
    sim_s: float = 60.0
    full: bool = False
    run: str = ""


#: The options of the bench being run (set by `run_bench`).
OPTIONS = {"now": BenchOptions()}


def _startup(overrides: Overrides) -> dict[str, Any]:
    from bench.startup import bench_startup

    return bench_startup(overrides, OPTIONS["now"].rounds)


def _decoders(_overrides: Overrides) -> dict[str, Any]:
    from bench.decoder_race import bench_decoders

    return bench_decoders(OPTIONS["now"].rounds)


def _deadwatch(_overrides: Overrides) -> dict[str, Any]:
    from bench.deadwatch import bench_deadwatch

    return bench_deadwatch(OPTIONS["now"].rounds)


def _lapse(_overrides: Overrides) -> dict[str, Any]:
    from bench.lapse import bench_lapse

    return bench_lapse(OPTIONS["now"].rounds)


def _stack(overrides: Overrides) -> dict[str, Any]:
    from bench.stack import bench_stack

    opts = OPTIONS["now"]
    return bench_stack(overrides, opts.sim_s, opts.full)


def _person_filter(_overrides: Overrides) -> dict[str, Any]:
    from bench.person_filter import bench_person_filter

    return bench_person_filter()


def _people_ids(overrides: Overrides) -> dict[str, Any]:
    from bench.people_ids import bench_people_ids

    return bench_people_ids(OPTIONS["now"].run or "var/eval/latest", overrides)


def _slam(settings: Overrides) -> dict[str, Any]:
    from bench.slam import bench_slam

    return bench_slam(settings)


BENCHES: dict[str, Callable[[Overrides], dict[str, Any]]] = {
    "sim": _sim,
    "wbc": _wbc,
    "perception": _perception,
    "nav": _nav,
    "startup": _startup,
    "decoders": _decoders,
    "deadwatch": _deadwatch,
    "lapse": _lapse,
    "stack": _stack,
    "slam": _slam,
    "person-filter": _person_filter,
    "people-ids": _people_ids,
}
#: What `dume bench all` runs (the others start stacks or processes in a loop: alone).
ALL = ("sim", "wbc", "perception", "nav")


#: `dume trial <name>`: the trials `bench.trials.run_trial` runs (named here, so the
#: command line lists them without importing the trials' dependencies).
TRIALS = (
    "walk", "turn", "strafe", "random", "reach", "pick", "push", "localize", "localize-off", "slam",
    "goto", "goals", "person", "crossing", "fetch", "patrol", "explore", "fuzz", "faults",
    "updown", "soak",
)  # fmt: skip


def run_bench(
    which: str, overrides: Sequence[str] = (), options: BenchOptions = BenchOptions()
) -> int:
    """Run a bench (or `all`) with the `--set` flags; print its figures (JSON)."""
    from common.config import parse_overrides

    OPTIONS["now"] = options
    names = list(ALL) if which == "all" else [which]
    settings = parse_overrides(overrides)
    results = {name: BENCHES[name](settings) for name in names}
    print(json.dumps(results if which == "all" else results[which]))
    return 0
