"""`OwnLink`: a watched token that went is the watcher's own link's lapse when every
token is back and the clock ran on within the grace; otherwise the service's loss."""

from __future__ import annotations

from common.lifelines import OwnLink

S = 1_000_000_000


def test_nothing_lost_is_fine() -> None:
    assert OwnLink(5.0).verdict(False, 0.0, 3 * S, True) == "fine"


def test_tokens_back_and_the_clock_on_is_a_lapse_kept_with_its_time() -> None:
    link = OwnLink(5.0)
    assert link.verdict(True, 10.0, 30 * S, False) == "doubt"  # gone: whose?
    assert link.verdict(True, 11.0, 30 * S, True) == "doubt"  # back, the clock not yet on
    assert link.verdict(True, 11.5, 30 * S + 1, True) == "lapse"
    assert link.lapses == [30 * S]
    assert link.verdict(False, 11.6, 31 * S, True) == "fine"  # the caller re-armed


def test_a_token_still_gone_after_the_grace_is_lost() -> None:
    link = OwnLink(5.0)
    assert link.verdict(True, 10.0, 30 * S, False) == "doubt"
    assert link.verdict(True, 14.9, 31 * S, False) == "doubt"  # the world runs, it is not back
    assert link.verdict(True, 15.0, 31 * S, False) == "lost"
    assert link.lapses == []


def test_a_stopped_clock_is_lost_even_with_every_token_back() -> None:
    link = OwnLink(5.0)
    link.verdict(True, 10.0, 30 * S, True)
    assert link.verdict(True, 15.0, 30 * S, True) == "lost"


def test_a_restarted_sim_whose_clock_began_again_is_no_lapse() -> None:
    link = OwnLink(5.0)
    link.verdict(True, 10.0, 30 * S, False)
    assert link.verdict(True, 12.0, 1 * S, True) == "doubt"  # a new world at t = 1 s
    assert link.verdict(True, 15.0, 2 * S, True) == "lost"


def test_a_second_lapse_is_judged_from_its_own_start() -> None:
    link = OwnLink(5.0)
    link.verdict(True, 10.0, 30 * S, False)
    assert link.verdict(True, 11.0, 31 * S, True) == "lapse"
    link.verdict(False, 12.0, 32 * S, True)
    assert link.verdict(True, 100.0, 90 * S, False) == "doubt"  # 89 s after the first: new
    assert link.verdict(True, 104.0, 91 * S, True) == "lapse"
    assert link.lapses == [30 * S, 90 * S]
