"""The recording keeps the same camera frames in every service: chosen by stamp."""

from __future__ import annotations

from common.recording import FrameSelector

MS = 1_000_000


def test_every_other_frame_by_stamp_and_the_dense_ones_among_them() -> None:
    frames = FrameSelector(camera_hz=10.0, camera_every=2, dense_every=5)
    stamps = [k * 100 * MS for k in range(21)]
    assert [t // MS for t in stamps if frames.logged(t)] == list(range(0, 2001, 200))
    assert [t // MS for t in stamps if frames.dense_logged(t)] == [0, 1000, 2000]


def test_a_service_that_starts_late_keeps_the_same_frames() -> None:
    """Counting frames would shift with whoever saw the first one; stamps do not."""
    sim, perception = FrameSelector(10.0, 2, 10), FrameSelector(10.0, 2, 10)
    late = [k * 100 * MS for k in range(7, 30)]
    assert [sim.logged(t) for t in late] == [perception.logged(t) for t in late]
    assert sum(perception.logged(t) for t in late) == 11
