"""A restarted localization goes on from the last T_map_odom it trusted in the run."""

from __future__ import annotations

from pathlib import Path

from common.messages.base import NS_PER_S
from services.localization.resume import FILE, Resume


def test_the_last_trusted_correction_is_kept_at_most_once_a_second(tmp_path: Path) -> None:
    r = Resume(tmp_path)
    assert r.load() is None
    r.save(0, (1.0, 2.0, 0.1))
    r.save(NS_PER_S // 2, (9.0, 9.0, 0.0))  # half a second later: not written
    held = Resume(tmp_path).load()  # a restarted process reads it
    assert held is not None and (held.stamp_ns, held.map_odom) == (0, (1.0, 2.0, 0.1))
    r.save(NS_PER_S, (1.5, 2.5, 0.2))
    held = Resume(tmp_path).load()
    assert held is not None and held.map_odom == (1.5, 2.5, 0.2)
    assert sorted(p.name for p in tmp_path.iterdir()) == [FILE], "no temporary left"


def test_an_unreadable_state_is_dropped_and_nothing_resumed(tmp_path: Path) -> None:
    (tmp_path / FILE).write_bytes(b"{not json")
    assert Resume(tmp_path).load() is None
    assert not (tmp_path / FILE).exists()


def test_without_a_run_folder_nothing_is_kept() -> None:
    r = Resume(None)
    r.save(0, (1.0, 2.0, 0.0))
    assert r.load() is None
