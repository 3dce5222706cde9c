"""`common.lifelines`: which of a job's dependencies went away or restarted since it began,
and which only lapsed (the same run back within the grace)."""

from __future__ import annotations

from common.lifelines import LOOK_AGAIN_S, Dependencies, Lifelines


def key(name: str) -> str:
    return f"dume/alive/b1/{name}"


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def lifelines(*alive: str, runs: bool = False, clock: Clock | None = None) -> Lifelines:
    lines = Lifelines() if clock is None else Lifelines(clock)
    for name in alive:
        if runs:
            lines.run_up(key(name), f"{name}-1")
        lines.up(key(name))
    return lines


def deps_of(lines: Lifelines, names: list[str], clock: Clock) -> Dependencies:
    deps = Dependencies(lines, names, key, grace_s=0.4, clock=clock)
    deps.arm()
    return deps


def gone(names: list[str], clock: Clock, going: list[str]) -> tuple[Lifelines, Dependencies]:
    """`names` alive with their runs, a job armed on them, then `going` gone."""
    lines = lifelines(*names, runs=True, clock=clock)
    deps = deps_of(lines, names, clock)
    for name in going:
        lines.down(key(name))
        lines.run_down(key(name), f"{name}-1")
    return lines, deps


def test_nothing_is_lost_while_every_dependency_stays_up() -> None:
    lines = lifelines("mission", "sim")
    deps = deps_of(lines, ["mission", "sim"], Clock())
    lines.up(key("perception"))  # someone else coming and going is no concern
    lines.down(key("perception"))
    assert deps.lost() is None
    assert deps.missing() == []


def test_a_dependency_that_goes_is_doubted_for_the_grace_then_gone() -> None:
    clock = Clock()
    lines = lifelines("mission", "sim", runs=True, clock=clock)
    deps = deps_of(lines, ["mission", "sim"], clock)
    lines.down(key("mission"))
    lines.run_down(key("mission"), "mission-1")
    assert deps.lost() is None and deps.doubted() == ["mission"]
    assert deps.missing() == ["mission"]
    clock.t += 0.39
    assert deps.lost() is None
    clock.t += 0.02
    assert deps.lost() == "mission is gone"


def test_a_holding_watcher_notices_a_loss_at_the_grace_and_calls_it_gone_at_the_hold() -> None:
    clock = Clock()
    lines = lifelines("mission", "sim", runs=True, clock=clock)
    deps = Dependencies(lines, ["mission", "sim"], key, grace_s=0.4, clock=clock, hold_s=2.0)
    deps.arm()
    lines.down(key("sim"))
    assert deps.lost() is None and deps.noticed() == []
    clock.t += 0.41
    assert deps.lost() is None and deps.noticed() == ["sim"]
    clock.t += 1.5
    assert deps.lost() is None and deps.noticed() == ["sim"]
    clock.t += 0.1
    assert deps.lost() == "sim is gone" and deps.noticed() == []
    deps.arm()
    assert deps.noticed() == []


def test_a_dependency_back_as_another_run_restarted_at_once() -> None:
    lines = lifelines("mission", "sim", runs=True)
    deps = deps_of(lines, ["mission", "sim"], Clock())
    lines.down(key("mission"))
    lines.run_down(key("mission"), "mission-1")
    lines.run_up(key("mission"), "mission-2")
    lines.up(key("mission"))
    assert deps.lost() == "mission restarted"  # a new process: the request is not in it


def test_a_new_run_is_a_restart_even_before_the_old_ones_token_is_heard_gone() -> None:
    lines = lifelines("navigation", runs=True)
    deps = deps_of(lines, ["navigation"], Clock())
    lines.down(key("navigation"))
    lines.up(key("navigation"))
    lines.run_up(key("navigation"), "navigation-2")
    assert deps.lost() == "navigation restarted"


def test_the_same_run_back_is_a_lapse_the_job_goes_on_and_a_later_loss_still_counts() -> None:
    clock = Clock()
    lines = lifelines("semantic_map", "sim", runs=True, clock=clock)
    deps = deps_of(lines, ["semantic_map", "sim"], clock)
    lines.down(key("semantic_map"))  # the router cut its link off: both tokens go
    lines.run_down(key("semantic_map"), "semantic_map-1")
    assert deps.lost() is None
    clock.t += 0.2
    lines.up(key("semantic_map"))  # its plain token back before its run's: still doubted
    assert deps.lost() is None and deps.doubted() == ["semantic_map"]
    lines.run_up(key("semantic_map"), "semantic_map-1")
    clock.t += 5.0  # long past the grace: it was resolved as a lapse when it came back
    assert deps.lost() is None and deps.doubted() == []
    assert deps.take_lapses() == ["semantic_map"] and deps.take_lapses() == []
    lines.down(key("semantic_map"))
    lines.run_down(key("semantic_map"), "semantic_map-1")
    clock.t += 0.2
    assert deps.lost() is None  # doubted from when its token went
    clock.t += 0.21
    assert deps.lost() == "semantic_map is gone"


def test_a_loss_is_doubted_from_when_its_token_went_not_from_when_a_tick_saw_it() -> None:
    clock = Clock()
    lines = lifelines("wbc", "sim", runs=True, clock=clock)
    deps = deps_of(lines, ["wbc", "sim"], clock)
    lines.down(key("wbc"))  # Zenoh's thread, while the watcher's tick was busy
    lines.run_down(key("wbc"), "wbc-1")
    assert lines.lost_at(key("wbc")) == clock.t and lines.lost_at(key("sim")) is None
    clock.t += 0.41  # the watcher's first look at it, late: past the grace already
    assert deps.lost() is None  # but it looks again first (`LOOK_AGAIN_S`)
    clock.t += LOOK_AGAIN_S + 0.01
    assert deps.lost() == "wbc is gone"


def test_a_starved_watcher_that_first_sees_a_loss_late_hears_its_return_before_it_judges() -> None:
    """A shift's mission, starved for 3 s by a second stack on two cores, saw the sim's
    token gone 3 s after it went, its return still queued behind it."""
    clock = Clock()
    lines = lifelines("sim", "wbc", runs=True, clock=clock)
    deps = deps_of(lines, ["sim", "wbc"], clock)
    lines.down(key("sim"))
    lines.run_down(key("sim"), "sim-1")
    clock.t += 3.0
    assert deps.lost() is None
    clock.t += 0.05
    lines.run_up(key("sim"), "sim-1")  # the backlog: it came back as the same process
    lines.up(key("sim"))
    assert deps.lost() is None and deps.take_lapses() == ["sim"]


def test_without_a_run_token_a_token_that_comes_back_restarted() -> None:
    lines = lifelines("navigation")
    deps = deps_of(lines, ["navigation"], Clock())
    lines.down(key("navigation"))
    lines.up(key("navigation"))
    assert deps.lost() == "navigation restarted"


def test_losses_before_the_job_began_do_not_count_and_disarm_forgets() -> None:
    clock = Clock()
    lines = lifelines("wbc")
    lines.down(key("wbc"))
    lines.up(key("wbc"))
    deps = deps_of(lines, ["wbc"], clock)
    assert deps.lost() is None
    deps.disarm()
    lines.down(key("wbc"))
    clock.t += 1.0
    assert deps.lost() is None


def test_a_dependency_not_running_when_the_job_began_is_missing_not_lost() -> None:
    lines = lifelines("sim")
    deps = Dependencies(lines, ["sim", "perception"], key)
    assert deps.missing() == ["perception"]
    deps.arm()
    assert deps.lost() is None
    lines.up(key("perception"))
    lines.down(key("perception"))
    assert deps.lost() is None  # it was never part of this job


def test_every_dependency_gone_at_once_is_the_router_not_each_service() -> None:
    clock = Clock()
    names = ["sim", "wbc", "navigation", "mission"]
    _, deps = gone(names, clock, names[:3])
    deps.lost()
    clock.t += 0.5
    assert deps.lost() == "sim is gone"  # one still there: services, not the link

    _, deps = gone(names, clock, names)
    assert deps.lost() is None
    clock.t += 4.9  # every one gone at once: the link to them all, doubted longer
    assert deps.lost() is None
    clock.t += 0.2
    assert deps.lost() == (
        "the router is gone: every service went at once (sim, wbc, navigation, mission)"
    )


def test_every_dependency_back_as_the_same_run_after_the_router_came_back_is_a_lapse() -> None:
    clock = Clock()
    names = ["sim", "wbc", "navigation", "mission"]
    lines, deps = gone(names, clock, names)
    assert deps.lost() is None
    clock.t += 1.5  # supervisord restarted the router; the services reconnect one by one
    for name in names:
        lines.run_up(key(name), f"{name}-1")
        lines.up(key(name))
        assert deps.lost() is None  # the others still doubted as long as the link
        clock.t += 0.3
    assert deps.take_lapses() == names


def test_a_run_heard_after_the_job_was_armed_is_the_armed_one() -> None:
    clock = Clock()
    lines = lifelines("sim")  # the watch has heard the token, not yet its run's
    deps = deps_of(lines, ["sim"], clock)
    lines.run_up(key("sim"), "sim-1")
    assert deps.lost() is None
    lines.down(key("sim"))
    lines.run_down(key("sim"), "sim-1")
    assert deps.lost() is None
    lines.run_up(key("sim"), "sim-1")
    lines.up(key("sim"))
    assert deps.lost() is None and deps.take_lapses() == ["sim"]
