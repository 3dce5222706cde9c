"""`common.lifelines`: which of a job's dependencies went away or restarted since it began."""

from __future__ import annotations

from common.lifelines import Dependencies, Lifelines


def key(name: str) -> str:
    return f"dume/alive/b1/{name}"


def lifelines(*alive: str) -> Lifelines:
    lines = Lifelines()
    for name in alive:
        lines.up(key(name))
    return lines


def test_nothing_is_lost_while_every_dependency_stays_up() -> None:
    lines = lifelines("mission", "sim")
    deps = Dependencies(lines, ["mission", "sim"], key)
    deps.arm()
    lines.up(key("perception"))  # someone else coming and going is no concern
    lines.down(key("perception"))
    assert deps.lost() is None
    assert deps.missing() == []


def test_a_dependency_that_goes_is_gone_and_one_that_comes_back_restarted() -> None:
    lines = lifelines("mission", "sim")
    deps = Dependencies(lines, ["mission", "sim"], key)
    deps.arm()
    lines.down(key("mission"))
    assert deps.lost() == "mission is gone"
    assert deps.missing() == ["mission"]
    lines.up(key("mission"))
    assert deps.lost() == "mission restarted"  # a new process: the request is not in it


def test_a_restart_between_two_looks_is_still_seen() -> None:
    lines = lifelines("navigation")
    deps = Dependencies(lines, ["navigation"], key)
    deps.arm()
    lines.down(key("navigation"))
    lines.up(key("navigation"))
    assert deps.lost() == "navigation restarted"


def test_losses_before_the_job_began_do_not_count_and_disarm_forgets() -> None:
    lines = lifelines("wbc")
    lines.down(key("wbc"))
    lines.up(key("wbc"))
    deps = Dependencies(lines, ["wbc"], key)
    deps.arm()
    assert deps.lost() is None
    deps.disarm()
    lines.down(key("wbc"))
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
    names = ["sim", "wbc", "navigation", "mission"]
    lines = lifelines(*names)
    deps = Dependencies(lines, names, key)
    deps.arm()
    for name in names[:3]:
        lines.down(key(name))
    assert deps.lost() == "sim is gone"  # one still there: services, not the link
    lines.down(key("mission"))
    assert deps.lost() == (
        "the router is gone: every service went at once (sim, wbc, navigation, mission)"
    )
    lines.up(key("sim"))  # back after the router: that one restarted, the others not yet
    assert deps.lost() == "sim restarted"
