"""Navigation's map without Zenoh: the semantic map fetched on a thread and adopted on sim
time (`MapFeed`), the map in use and its layers (`NavMap`), the depth layer's frames."""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator

import numpy as np
import pytest

from common.bus import WaitTimeout
from common.messages.sim import CameraFrame
from services.navigation.costmap import CostParams, ObstacleLayer, Person
from services.navigation.depth import DepthFeed
from services.navigation.grid import Footprint, Grid, Pose
from services.navigation.map_feed import MAP_ADOPT_S, MapFeed
from services.navigation.nav_map import NavMap
from services.navigation.sources import SourceError
from tests.unit.test_nav_seen_people import _det, _frame

S = 1_000_000_000
PERIOD = 50_000_000
ADOPT = round(MAP_ADOPT_S * S)
FP = Footprint.stowed()
LOG = logging.getLogger("test.nav_map_feed")


def _grid(n: int = 60) -> Grid:
    occ = np.zeros((n, n), dtype=bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    return Grid(occ, 0.05, (0.0, 0.0))


class _Source:
    """The semantic map: answers as of a tick, fails with a sentence, or holds on `gate`."""

    name = "fake map"

    def __init__(self, error: str = "") -> None:
        self.error = error
        self.asked: list[tuple[str, int | None]] = []
        self.gate = threading.Event()
        self.gate.set()

    def grid(self, at_ns: int | None = None) -> Grid:
        self.gate.wait(5.0)
        self.asked.append(("grid", at_ns))
        if self.error:
            raise SourceError(self.error)
        return _grid()

    def people(self, at_ns: int | None = None) -> list[Person]:
        self.asked.append(("people", at_ns))
        return [Person("person_1", 1.0, 1.0)]

    def artifact_xy(self, artifact_id: str, at_ns: int | None = None) -> tuple[float, float]:
        raise AssertionError("the feed asks for the grid and people only")

    def person(self, person_id: str, at_ns: int | None = None) -> Person:
        raise AssertionError("the feed asks for the grid and people only")


@pytest.fixture
def stop() -> Iterator[threading.Event]:
    event = threading.Event()
    yield event
    event.set()


def _feed(
    source: _Source, stop: threading.Event, lockstep: bool, timeout_s: float = 5.0
) -> MapFeed:
    feed = MapFeed(source, threading.Condition(threading.Lock()), LOG,
                   lockstep=lockstep, refresh_ns=S, timeout_s=timeout_s)  # fmt: skip
    feed.start(stop)
    return feed


def test_lockstep_adopts_the_map_as_of_its_fetch_tick_map_adopt_s_later(
    stop: threading.Event,
) -> None:
    source = _Source()
    feed = _feed(source, stop, lockstep=True)
    assert [feed.tick(b) for b in range(0, ADOPT, PERIOD)] == [None] * (ADOPT // PERIOD)
    got = feed.tick(ADOPT)  # waits for the fetch: every run adopts it at this tick
    assert got is not None
    grid, people, as_of = got
    assert (grid.shape, people, as_of) == ((60, 60), [Person("person_1", 1.0, 1.0)], 0)
    assert source.asked == [("grid", 0), ("people", 0)]
    assert feed.tick(ADOPT + PERIOD) is None  # adopted once
    assert feed.tick(S) is None  # the next fetch, as of 1 s
    assert feed.tick(S + ADOPT) is not None
    assert source.asked[2:] == [("grid", S), ("people", S)]


def test_lockstep_drops_a_failed_fetch_and_says_so_once(
    stop: threading.Event, caplog: pytest.LogCaptureFixture
) -> None:
    feed = _feed(_Source(error="occupancy (dume/map/occupancy): no reply"), stop, lockstep=True)
    caplog.set_level(logging.WARNING, LOG.name)
    for b in (0, ADOPT, S, S + ADOPT):
        assert feed.tick(b) is None
    said = [r.getMessage() for r in caplog.records]
    assert said == ["map unavailable: occupancy (dume/map/occupancy): no reply"]


def test_lockstep_drops_a_fetch_that_never_comes(
    stop: threading.Event, caplog: pytest.LogCaptureFixture
) -> None:
    source = _Source()
    source.gate.clear()
    feed = _feed(source, stop, lockstep=True, timeout_s=0.3)
    caplog.set_level(logging.WARNING, LOG.name)
    assert feed.tick(0) is None
    assert feed.tick(ADOPT) is None
    assert [r.getMessage() for r in caplog.records] == ["map fetch of t=0.00 s never came: dropped"]
    source.gate.set()
    assert feed.tick(ADOPT + PERIOD) is None  # the late answer is not adopted


def test_realtime_adopts_a_late_fetch_at_the_first_tick_after_it_is_in(
    stop: threading.Event,
) -> None:
    source = _Source()
    source.gate.clear()
    feed = _feed(source, stop, lockstep=False)
    assert feed.tick(0) is None
    assert feed.tick(ADOPT) is None  # not in yet: not waited for
    source.gate.set()
    for b in range(ADOPT + PERIOD, S, PERIOD):
        got = feed.tick(b)
        if got is not None:
            assert got[2] == 0
            return
        threading.Event().wait(0.05)
    raise AssertionError("the fetch was never adopted")


def test_the_map_in_use_keeps_its_layer_for_a_grid_of_the_same_shape() -> None:
    m = NavMap(FP, CostParams(), 3 * S, True, "fake map", LOG)
    assert m.costmap is None and not m.take(None, True, 0)  # no grid: nothing to merge
    m.adopt(_grid(), [Person("person_1", 1.0, 1.0)], 0, 0)
    assert m.costmap is not None and m.costmap.people == (Person("person_1", 1.0, 1.0),)
    m.layer.mark(np.array([30]), np.array([30]), 0)
    assert m.take((_grid(), [], S), False, S) is False
    assert (m.map_at, m.people, m.layer.active(S)[30, 30]) == (S, [], True)
    m.layer.mark(np.array([30]), np.array([31]), S)
    m.clear(S)  # the `clear` recovery
    assert not m.layer.active(S).any()
    m.layer.mark(np.array([30]), np.array([30]), S)
    m.take((_grid(80), [], 2 * S), False, 2 * S)
    assert m.layer.seen_ns.shape == (80, 80) and not m.layer.active(2 * S).any()


def test_people_seen_over_the_map_s_change_the_costmap_s_people() -> None:
    m = NavMap(FP, CostParams(), 3 * S, False, "fake map", LOG)
    m.adopt(_grid(), [Person("person_1", 1.0, 1.0)], 0, 0)
    assert not m.see([], 0)
    assert m.see([_frame(0, _det("person", 1.2, 1.0, map_id="person_1"))], PERIOD)
    assert m.take(None, True, PERIOD)
    m.rebuild(PERIOD)
    assert m.costmap is not None
    assert [(p.id, p.x) for p in m.costmap.people] == [("person_1", 1.2)]
    assert m.costmap.cost[20, 20] >= 0  # `people_in_costmap` off: not planned around


class _Frames:
    def __init__(self) -> None:
        self.waited: list[int] = []

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> CameraFrame:
        self.waited.append(stamp_ns)
        raise WaitTimeout("no frame")

    def at(self, stamp_ns: int) -> CameraFrame | None:
        return None


def test_the_depth_layer_waits_only_at_frame_ticks_with_a_grid(
    caplog: pytest.LogCaptureFixture,
) -> None:
    frames = _Frames()
    feed = DepthFeed(frames, "camera_head", S // 10, FP, LOG, 0.01)
    layer = ObstacleLayer((60, 60), 3 * S)
    pose = Pose(1.5, 1.5, 0.0)
    caplog.set_level(logging.WARNING, LOG.name)
    assert not feed.update(0, pose, np.eye(4), None, layer)  # no grid yet
    assert not feed.update(PERIOD, pose, np.eye(4), _grid(), layer)  # no frame due
    assert not feed.update(S // 10, pose, np.eye(4), _grid(), layer)
    assert frames.waited == [S // 10]
    assert [r.getMessage() for r in caplog.records] == ["no camera_head frame for t=0.10 s"]
