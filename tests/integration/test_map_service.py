"""The semantic map service over real Zenoh: fusion of synthetic detections, ids, typed
errors, persistence across a SIGKILL in the middle of writes, export and import, seeding
from the world. The test stands in for the sim and perception: it publishes the clock and
synthetic `Detections` itself and waits for the map's acks."""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest

from common.bus import RemoteError
from common.keys import (
    MAP_ARTIFACTS,
    MAP_EXPORT,
    MAP_IMPORT,
    MAP_OCCUPANCY,
    MAP_PEOPLE,
    MAP_SUPPORTS,
    WORLD_CLOCK,
    map_artifact,
    map_person,
)
from common.messages import to_wire
from common.messages.mission import PatrolRequest
from common.messages.perception import Detection, Detections
from common.messages.semantic_map import (
    MapEntity,
    MapFile,
    MapListing,
    MapSummary,
    OccupancyGrid,
    SupportListing,
)
from common.messages.sim import Ack, Clock
from deploy.stack import ProcessStack, wait_until
from services.semantic_map.store import MapStore
from tests.conftest import HOLD_COMMANDER, StartStack

pytestmark = pytest.mark.integration

# -- a stand-in for the sim and perception: the clock and synthetic detections ---------

PERIOD_NS = 100_000_000
IDENTITY = tuple(float(v) for v in np.eye(4).ravel())


def map_settings(db_dir: str, **extra: object) -> list[str]:
    """The map alone, ticking on a clock the test publishes; no floor plan, one camera."""
    out = [
        "time.participants={}",
        'time.participants.semantic_map.role="periodic"',
        "time.participants.semantic_map.period_s=0.1",
        "time.participants.semantic_map.latency_s=0.1",
        f'semantic_map.dir="{db_dir}"',
        'semantic_map.start="empty"',
        'semantic_map.floor_plan="none"',
        'semantic_map.cameras=["camera_head"]',
        "semantic_map.grid_half_extent_m=5.0",
    ]
    return out + [f"semantic_map.{k}={v}" for k, v in extra.items()]


def detection(cls: str, xyz_: Sequence[float] | np.ndarray, d_obj: float = 1.5) -> Detection:
    xyz = (float(xyz_[0]), float(xyz_[1]), float(xyz_[2]))
    return Detection(
        class_name=cls,
        score=0.9,
        bbox=(10, 10, 20, 30),
        mask=to_wire(np.ones((20, 10), np.uint8)),
        centroid_in_base_yaw=(d_obj, 0.0, 0.3),
        centroid_in_world=xyz,
        axis_in_world=xyz,
        extent=(0.05, 0.05, 0.2),
        d_obj=d_obj,
        theta_obj=0.0,
        n_points=200,
    )


class MapDriver:
    def __init__(self, s: ProcessStack) -> None:
        self.s = s
        self.clock = s.bus.publisher(WORLD_CLOCK, Clock, "control")
        self.dets = s.bus.publisher(s.keys.detections, Detections, "data")
        self.acks = s.bus.latest(s.keys.ack("semantic_map"), Ack)
        self.t = 0

    def step(self, detections: list[Detection], timeout_s: float = 10.0) -> int:
        """Publish one frame's detections and the clock at the next tick; wait for the ack."""
        t = self.t
        self.dets.put(
            Detections(
                stamp_ns=t,
                camera="camera_head",
                T_world_base=IDENTITY,
                segmenter="truth",
                detections=detections,
            )
        )
        self.clock.put(Clock(stamp_ns=t, tick=t // 1_000_000, mode="lockstep"))
        self.acks.wait(lambda a: a.stamp_ns >= t, timeout_s)
        self.t += PERIOD_NS
        return t

    def step_until(
        self, detections: list[Detection], done: Callable[[], bool], frames: int = 20
    ) -> None:
        """Step frames of `detections` until `done()`; fail after `frames` of them."""
        for _ in range(frames):
            self.step(detections)
            if done():
                return
        raise AssertionError(f"not done after {frames} frames")


# -- the tests ----------------------------------------------------------------------------


def _listing(s, key: str = MAP_ARTIFACTS) -> list[MapEntity]:  # type: ignore[no-untyped-def]
    return s.bus.query(key, None, MapListing, 5.0).entities


def test_detections_are_fused_into_artifacts_and_people_with_ids(
    stack: StartStack, tmp_path: Path
) -> None:
    s = stack(["semantic_map"], *map_settings(str(tmp_path / "map")))
    d = MapDriver(s)
    rng = np.random.default_rng(0)
    bottle, can, person = np.array([2.0, 1.0, 0.8]), np.array([2.4, 1.0, 0.8]), [0.0, 3.0, 1.0]
    for _ in range(12):
        noisy = [bottle + rng.normal(0, 0.03, 3), can + rng.normal(0, 0.03, 3)]
        d.step(
            [detection("bottle", noisy[0]), detection("can", noisy[1]), detection("person", person)]
        )
    d.step([])
    arts = {e.id: e for e in _listing(s)}
    assert set(arts) == {"bottle_1", "can_1"}
    assert np.linalg.norm(np.array(arts["bottle_1"].position_in_world[:2]) - bottle[:2]) < 0.03
    assert arts["bottle_1"].uncertainty_m < 0.03
    assert arts["bottle_1"].source == "perception"
    one = s.bus.query(map_artifact("can_1"), None, MapEntity, 5.0)
    assert one.class_name == "can" and one.observations == 12
    people = _listing(s, MAP_PEOPLE)
    assert [p.id for p in people] == ["person_1"]
    assert people[0].position_in_world[2] == 0.0  # a person's feet
    # A second bottle 40 cm away is a new artifact with the next number.
    for _ in range(3):
        d.step([detection("bottle", bottle + np.array([0.0, 0.4, 0.0]))])
    d.step([])
    assert sorted(e.id for e in _listing(s)) == ["bottle_1", "bottle_2", "can_1"]
    only = s.bus.query(MAP_ARTIFACTS + "?class=bottle", None, MapListing, 5.0).entities
    assert sorted(e.id for e in only) == ["bottle_1", "bottle_2"]
    grid = s.bus.query(MAP_OCCUPANCY, None, OccupancyGrid, 5.0)
    assert grid.cells.shape == (200, 200) and grid.static_source == "none"


def test_malformed_and_unknown_queries_get_typed_errors(stack: StartStack, tmp_path: Path) -> None:
    s = stack(["semantic_map"], *map_settings(str(tmp_path / "map")))
    d = MapDriver(s)
    # Until it is in: the clock may overtake a frame's detections (other keys).
    d.step_until(
        [detection("bottle", [1.0, 1.0, 0.8])], lambda: [e.id for e in _listing(s)] == ["bottle_1"]
    )

    def code(key: str, request: object = None) -> str:
        with pytest.raises(RemoteError) as err:
            s.bus.query(key, request, MapEntity, 5.0)
        return err.value.error.code

    assert code(map_artifact("bottle_9")) == "unknown_id"
    assert "bottle_1" in _error_message(s, map_artifact("bottle_9"))
    assert code(map_person("person_4")) == "unknown_id"
    assert code("dume/map/artifacts/Bottle-1") == "invalid"
    assert code(map_artifact("person_1")) == "invalid"
    assert code(map_person("bottle_1")) == "invalid"
    assert code(MAP_ARTIFACTS + "?colour=red") == "invalid"
    assert code(MAP_ARTIFACTS + "?class=Bad!") == "invalid"
    assert code(MAP_ARTIFACTS + "?missing=maybe") == "invalid"
    assert code(map_artifact("bottle_1") + "?x=1") == "invalid"
    with pytest.raises(RemoteError) as err:  # a PatrolRequest where a MapFile is due
        s.bus.query(MAP_IMPORT, PatrolRequest(action="start"), MapSummary, 5.0)
    assert err.value.error.code == "malformed"
    # No floor plan here: no supports (the mission's patrol plans on the lattice alone).
    assert s.bus.query(MAP_SUPPORTS, None, SupportListing, 5.0).surfaces == []
    # The service is still there and still right.
    assert [e.id for e in _listing(s)] == ["bottle_1"]


def _error_message(s, key: str) -> str:  # type: ignore[no-untyped-def]
    try:
        s.bus.query(key, None, MapEntity, 5.0)
    except RemoteError as exc:
        return exc.error.message
    return ""


def test_ids_and_acknowledged_writes_survive_a_sigkill_in_the_middle_of_writes(
    stack: StartStack, tmp_path: Path
) -> None:
    db_dir = tmp_path / "map"
    s = stack(["semantic_map"], *map_settings(str(db_dir), confirm_hits=1))
    d = MapDriver(s)
    per_frame = 40  # many rows per transaction: the kill lands inside writes
    killed = threading.Event()

    def frame(k: int) -> list:
        return [detection("bottle", [0.5 * j, 1.0 * k, 0.8]) for j in range(per_frame)]

    acked: list[int] = []

    def killer() -> None:
        # a random moment once a few frames are in (a loaded machine acknowledges slowly)
        deadline = time.monotonic() + 60.0
        while len(acked) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(random.Random(7).uniform(0.2, 1.0))
        s.kill("semantic_map")
        killed.set()

    threading.Thread(target=killer, daemon=True).start()
    k = 0
    while not killed.is_set():
        try:
            d.step(frame(k), timeout_s=3.0)
        except Exception:
            break
        acked.append(k)
        k += 1
    assert killed.wait(70.0)
    assert len(acked) >= 2, "the map acknowledged too few frames before the kill"
    (path,) = db_dir.glob("*.sqlite")  # the site's database (hall-seed-0)
    assert path.name == "hall-seed-0.sqlite"
    store = MapStore(path)
    assert store.integrity() == "ok"
    snap = store.load()
    store.close()
    stored = {e.id: e for e, _app in snap.entities}
    # Frames stamped up to the last ack but one are surely fused by the last ack.
    for k in acked[:-1]:
        for j in range(per_frame):
            n = k * per_frame + j + 1
            e = stored.get(f"bottle_{n}")
            assert e is not None, f"bottle_{n} of acknowledged frame {k} was lost"
            assert abs(e.position_in_world[0] - 0.5 * j) < 1e-9
            assert abs(e.position_in_world[1] - 1.0 * k) < 1e-9
    assert snap.counters["bottle"] == len(stored)
    # Restarted, the map resumes with the same ids and never reuses a number.
    s.spawn("semantic_map")
    s.wait_ready(["semantic_map"], 60.0)
    assert wait_until(lambda: len(_listing(s)) == len(stored), 20.0)
    d.step([detection("can", [9.0, 9.0, 0.8])])
    d.step([detection("bottle", [-3.0, -3.0, 0.8])])
    d.step([detection("bottle", [-3.0, -3.0, 0.8])])  # the same bottle again, fused
    after_restart = f"bottle_{len(stored) + 1}"  # the next number, none reused

    def ids() -> set[str]:
        return {e.id for e in _listing(s)}

    assert wait_until(lambda: after_restart in ids(), 20.0), sorted(ids() - set(stored))


def test_a_map_exported_then_imported_is_the_same_map(stack: StartStack, tmp_path: Path) -> None:
    s = stack(["semantic_map"], *map_settings(str(tmp_path / "map")))
    d = MapDriver(s)

    def export() -> MapFile:
        return s.bus.query(MAP_EXPORT, None, MapFile, 5.0)

    def ids() -> list[str]:
        return sorted(e.id for e in _listing(s))

    # A frame's detections may land after its clock tick (no order across keys; under load
    # by several ticks): step until the map has made its entities, at most 20 frames.
    seen = [detection("bottle", [1.0, 1.0, 0.8]), detection("person", [0.0, 2.0, 1.0])]
    d.step_until(seen, lambda: sorted(e.id for e in export().entities) == ["bottle_1", "person_1"])
    exported = export()
    d.step_until([detection("box", [3.0, 1.0, 0.8])], lambda: len(_listing(s)) == 2)
    summary = s.bus.query(MAP_IMPORT, exported, MapSummary, 5.0)
    assert (summary.artifacts, summary.people) == (1, 1)
    arts = _listing(s)
    assert [e.id for e in arts] == ["bottle_1"] and arts[0].source == "import"
    # The counters came with the file: the next box is box_1, the next bottle bottle_2.
    d.step_until([detection("bottle", [2.0, 2.0, 0.8])], lambda: ids() == ["bottle_1", "bottle_2"])


def test_seed_from_world_uses_the_sims_ids_with_noise_and_its_floor_plan(
    stack: StartStack, tmp_path: Path
) -> None:
    from services.sim.world import generate_world

    s = stack(
        ["sim", "hold", "semantic_map"],
        *HOLD_COMMANDER,
        'time.participants.semantic_map.role="periodic"',
        "time.participants.semantic_map.period_s=0.1",
        "time.participants.semantic_map.latency_s=0.1",
        'sim.world="small"',
        "sim.cameras=[]",
        f'semantic_map.dir="{tmp_path / "map"}"',
        'semantic_map.start="seed-from-world"',
        "semantic_map.seed_noise_m=0.05",
        record=True,
    )
    world = generate_world(0, "small")
    arts = _listing(s)
    assert [e.id for e in arts] == [a.id for a in world.artifacts]
    assert all(e.source == "seed-from-world" for e in arts)
    err = np.linalg.norm(np.array(arts[0].position_in_world[:2]) - world.artifacts[0].position[:2])
    assert 0.0 < err < 0.25
    assert [p.id for p in _listing(s, MAP_PEOPLE)] == [p.id for p in world.people]
    grid = s.bus.query(MAP_OCCUPANCY, None, OccupancyGrid, 5.0)
    assert grid.static_source == "world"
    assert grid.cells.shape == world.occupancy.cells.shape


def test_an_artifact_looked_for_at_its_place_and_not_seen_is_marked_missing(
    stack: StartStack, tmp_path: Path
) -> None:
    """A running stack (sim, the WBC, the network segmenter, the map): a map imported
    with bottle_1 where it is and a can_1 that is not there, both ahead of the head camera;
    the robot walks 1.2 m towards the table. The can is marked missing with a time; the
    bottle, seen, is not."""
    from common.keys import WORLD_DESCRIPTION
    from common.messages.sim import Odom
    from common.messages.wbc import CmdVel, WbcMode
    from common.messages.world import WorldDescription

    s = stack(
        ["sim", "wbc", "perception", "semantic_map"],
        "time.participants={}",
        'time.participants.wbc.role="command"',
        "time.participants.wbc.period_s=0.002",
        "time.participants.wbc.latency_s=0.0",
        'time.participants.semantic_map.role="periodic"',
        "time.participants.semantic_map.period_s=0.1",
        "time.participants.semantic_map.latency_s=0.1",
        'time.participants.perception.role="periodic"',
        "time.participants.perception.period_s=0.1",
        "time.participants.perception.latency_s=0.1",
        'sim.world="small"',
        'sim.cameras=["camera_head"]',
        'perception.cameras=["camera_head"]',
        f'semantic_map.dir="{tmp_path / "map"}"',
        'semantic_map.start="empty"',
    )
    world = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 10.0)
    bottle = world.artifacts[0]
    assert bottle.id == "bottle_1"

    def entity(id_: str, cls: str, xyz: Sequence[float]) -> MapEntity:
        return MapEntity(
            id=id_,
            class_name=cls,
            kind="artifact",
            position_in_world=(float(xyz[0]), float(xyz[1]), float(xyz[2])),
            uncertainty_m=0.05,
            last_seen_ns=0,
            source="prior",
        )

    # On the floor 1.5 m in front of the robot, in plain view: nothing is there.
    start = world.robot_start
    ghost = (start.x + 1.6 * np.cos(start.yaw), start.y + 1.6 * np.sin(start.yaw), 0.05)
    mf = MapFile(
        entities=[
            entity("bottle_1", "bottle", (*bottle.position[:2], bottle.position[2] + 0.07)),
            entity("can_1", "can", ghost),
        ],
        counters={"bottle": 1, "can": 1},
        site=s.config.map_site(),
    )
    summary = s.bus.query(MAP_IMPORT, mf, MapSummary, 10.0)
    assert (summary.artifacts, summary.missing) == (2, 0)
    # Walk 1.2 m towards the table (3.4 m ahead), past the ghost's place.
    clock = s.bus.latest(WORLD_CLOCK, Clock)
    odom = s.bus.latest(s.keys.odom, Odom)
    mode = s.bus.publisher(s.keys.wbc_mode, WbcMode, "control")
    cmd = s.bus.publisher(s.keys.cmd_vel, CmdVel, "control")
    c0 = clock.wait(lambda c: c.stamp_ns > 0, 30.0)
    mode.put(WbcMode(stamp_ns=c0.stamp_ns, mode="walk", cmd_vel_source="test"))
    x0 = odom.wait(lambda o: o.stamp_ns > 0, 30.0).base_position_in_world[0]

    def walked() -> bool:
        c = clock.get()
        o = odom.get()
        far = o is not None and o.base_position_in_world[0] - x0 >= 1.2
        if c is not None:
            cmd.put(
                CmdVel(stamp_ns=c.stamp_ns, vx=0.0 if far else 0.4, vy=0.0, wz=0.0, source="test")
            )
        return far

    assert wait_until(walked, 300.0, poll_s=0.02), "the robot did not walk"
    for _ in range(20):  # stop, and keep stopped
        walked()
        time.sleep(0.05)

    def missing() -> list[str]:
        q = MAP_ARTIFACTS + "?missing=true"
        return [e.id for e in s.bus.query(q, None, MapListing, 5.0).entities]

    assert wait_until(lambda: "can_1" in missing(), 180.0), "can_1 was never marked missing"
    can = s.bus.query(map_artifact("can_1"), None, MapEntity, 5.0)
    assert can.missing_since_ns is not None and can.missing_since_ns > 0
    assert can.observations == 0
    # The bottle was looked at all along and seen: fused, never missing.
    one = s.bus.query(map_artifact("bottle_1"), None, MapEntity, 5.0)
    assert one.missing_since_ns is None
    assert one.last_seen_ns > 0 and one.observations > 0
    assert missing() == ["can_1"]
