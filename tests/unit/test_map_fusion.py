"""Artifact fusion, the missing test, the database and the map file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common.camera import PinholeCamera
from common.config import SemanticMapSettings
from common.geometry import make_T
from services.semantic_map.artifacts import ArtifactTracker
from services.semantic_map.entities import IdBook, Observation, Track
from services.semantic_map.looks import looks_at
from services.semantic_map.mapfile import seed_from_world
from services.semantic_map.occupancy import CLEAR_FRAMES, OCCUPIED, Occupancy
from services.semantic_map.store import Grid, MapStore
from services.sim.world import generate_world

S = 100_000_000


def test_repeated_noisy_detections_converge_and_noise_grows_with_range() -> None:
    rng = np.random.default_rng(0)
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    truth = np.array([2.0, 1.0])
    for k in range(30):
        sigma = 0.02 + 0.02 * 3.0
        xy = truth + rng.normal(0.0, sigma, 2)
        tracker.update(k * S, [Observation("bottle", xy, 0.8, sigma)])
    (tr,) = tracker.confirmed
    assert tr.id == "bottle_1"
    assert np.linalg.norm(tr.xy - truth) < 0.04
    assert tr.sigma_m < 0.08 / np.sqrt(30) * 1.01


def test_a_few_near_views_outweigh_many_far_ones_that_share_a_bias() -> None:
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    truth = np.array([2.0, 1.0])
    rng = np.random.default_rng(1)

    def view(k: int, rng_m: float, bias: float, whole: bool = True) -> None:
        sigma = 0.02 + 0.02 * rng_m
        xy = truth + np.array([bias, 0.0]) + rng.normal(0.0, 0.3 * sigma, 2)
        obs = Observation("can", xy, 0.8, sigma, range_m=rng_m, whole=whole)
        tracker.update(k * S, [obs])

    for k in range(200):  # exploring: the same front face from 4 m, 15 cm off
        view(k, 4.0, 0.15)
    (tr,) = tracker.confirmed
    assert abs(tr.xy[0] - 2.15) < 0.02 and tr.best_range_m == 4.0
    for k in range(200, 205):  # the semantic pass: five views from 1.2 m
        view(k, 1.2, 0.0)
    assert np.linalg.norm(tr.xy - truth) < 0.03 and tr.best_range_m == 1.2
    for k in range(205, 400):  # far views after it move it no more
        view(k, 4.0, 0.15)
    assert np.linalg.norm(tr.xy - truth) < 0.03 and tr.hits == 400
    view(400, 1.5, 0.0, whole=False)  # within the band: it fuses, at twice its σ
    assert np.linalg.norm(tr.xy - truth) < 0.03


def test_a_detection_outside_the_gate_or_of_another_class_is_a_new_artifact() -> None:
    tracker = ArtifactTracker(IdBook({"bottle": 4}), SemanticMapSettings())
    for k in range(2):
        tracker.update(
            k * S,
            [
                Observation("bottle", np.array([0.0, 0.0]), 0.8, 0.03),
                Observation("bottle", np.array([0.6, 0.0]), 0.8, 0.03),
                Observation("can", np.array([0.0, 0.1]), 0.8, 0.03),  # beside it
            ],
        )
    assert sorted(t.id or "" for t in tracker.confirmed) == ["bottle_5", "bottle_6", "can_1"]
    # made from this run's sightings: the first says when (the search's "made since")
    sent = [t.to_message() for t in tracker.confirmed]
    assert [(e.first_seen_ns, e.last_seen_ns) for e in sent] == [(0, S)] * 3
    tracker.update(2 * S, [Observation("bottle", np.array([3.0, 0.0]), 0.8, 0.03)])
    tracker.update(3 * S, [Observation("bottle", np.array([3.0, 0.0]), 0.8, 0.03)])
    made = [t for t in tracker.confirmed if t.id == "bottle_7"]
    assert [t.to_message().first_seen_ns for t in made] == [2 * S]
    assert Track.from_message(made[0].to_message()).first_seen_ns == 2 * S


def test_the_missing_test_sees_in_front_within_range_and_not_behind_an_occluder() -> None:
    # Camera at the origin looking along world +x (optical z = world x).
    R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    depth = np.full((240, 320), 5.0, np.float32)
    view = PinholeCamera(200.0, 200.0, 159.5, 119.5, make_T(R, [0, 0, 0]), depth)
    assert looks_at(view, np.array([2.0, 0.0, 0.0]), 3.0)
    assert not looks_at(view, np.array([4.0, 0.0, 0.0]), 3.0)  # beyond range
    assert not looks_at(view, np.array([-2.0, 0.0, 0.0]), 3.0)  # behind
    assert not looks_at(view, np.array([1.0, 3.0, 0.0]), 3.0)  # outside the image
    depth[:, :] = 1.0  # a wall 1 m ahead hides what is at 2 m
    assert not looks_at(view, np.array([2.0, 0.0, 0.0]), 3.0)


def test_learned_obstacles_need_several_frames_and_leave_the_floor_out() -> None:
    occ = Occupancy(np.zeros((20, 20), np.uint8), 0.1, (0.0, 0.0), hits_needed=3)
    pts = np.array([[0.55, 0.55, 0.5], [1.05, 1.05, 0.01]])
    for _ in range(2):
        occ.integrate(pts)
    assert occ.cells()[5, 5] == 0
    occ.integrate(pts)
    assert occ.cells()[5, 5] == OCCUPIED and occ.cells()[10, 10] == 0


def test_what_stood_on_the_floor_and_went_is_forgotten_a_tops_cells_stay() -> None:
    """Hall seed 4's shift: a worker's legs, missed by the detector, made a learned cell
    that wedged the robot among crossing workers for the rest of the shift."""
    occ = Occupancy(np.zeros((20, 20), np.uint8), 0.1, (0.0, 0.0), hits_needed=3)
    legs = np.array([[0.55, 0.55, 0.3], [0.55, 0.55, 0.6]])  # cell (5, 5), from 0.3 m up
    top = np.array([[1.05, 0.55, 0.72]])  # cell (5, 10): a table top's underside
    for _ in range(3):
        occ.integrate(np.vstack([legs, top]))
    assert occ.cells()[5, 5] == OCCUPIED and occ.cells()[5, 10] == OCCUPIED
    floor = np.array([[0.52, 0.52, 0.01], [1.02, 0.52, 0.01]])  # both cells seen as floor
    for _ in range(CLEAR_FRAMES - 1):
        occ.integrate(floor)
    occ.integrate(np.vstack([floor, legs[:1]]))  # a hit in the cell restarts its count
    for _ in range(CLEAR_FRAMES - 1):
        occ.integrate(floor)
    assert occ.cells()[5, 5] == OCCUPIED  # 4 frames of floor since its last hit
    version = occ.version
    occ.integrate(floor)
    assert occ.cells()[5, 5] == 0 and occ.hits[5, 5] == 0 and occ.version > version
    assert occ.cells()[5, 10] == OCCUPIED  # no low hit: the floor under a top is seen
    occ.integrate(legs)  # somebody stands there again: counted from nothing
    assert occ.hits[5, 5] == 1


def test_the_store_keeps_what_was_committed(tmp_path: Path) -> None:
    world = generate_world(0, "small")
    tracks = seed_from_world(world, 0.05, 0)
    store = MapStore(tmp_path / "m.sqlite")
    grid = Grid(np.eye(3, dtype=np.uint16), 0.05, (1.0, 2.0))
    store.commit(
        [(t.to_message(), None) for t in tracks], {"bottle": 1, "person": 1}, {"learned": grid}
    )
    store.close()
    snap = MapStore(tmp_path / "m.sqlite").load()
    assert [e.id for e, _ in snap.entities] == ["bottle_1", "person_1"]
    assert snap.entities[0][0].source == "seed-from-world"
    assert snap.counters == {"bottle": 1, "person": 1}
    assert np.array_equal(snap.grids["learned"].cells, np.eye(3))


def _seen(
    tracker: ArtifactTracker, k: int, cls: str, xy: tuple[float, float], range_m: float
) -> None:
    tracker.update(k * S, [Observation(cls, np.array(xy), 0.9, 0.03, range_m=range_m)])


def test_one_object_under_two_classes_keeps_the_class_seen_from_near() -> None:
    # A can on a bench: a box from 3 m (many times), a can from 1.5 m (a few times).
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(10):
        _seen(tracker, k, "box", (2.0, 1.0), 3.0)
    assert tracker.class_conflicts() == []  # one class only
    for k in range(10, 12):
        _seen(tracker, k, "can", (2.01, 1.0), 1.5)
    ((loser, winner),) = tracker.class_conflicts()
    assert (loser.id, winner.id) == ("box_1", "can_1")
    assert (loser.near_hits, winner.near_hits) == (0, 2)


def test_no_class_merge_without_near_evidence_apart_or_for_prior_artifacts() -> None:
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(4):
        _seen(tracker, k, "box", (2.0, 1.0), 3.0)
        _seen(tracker, k, "can", (2.0, 1.01), 2.5)  # both from far: no evidence
    assert tracker.class_conflicts() == []
    for k in range(4, 8):
        _seen(tracker, k, "bottle", (2.25, 1.0), 1.0)  # near, but 25 cm away: two objects
    assert tracker.class_conflicts() == []
    prior = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(4):
        _seen(prior, k, "can", (0.0, 0.0), 1.0)
    prior.tracks[0].source = "prior"
    for k in range(4, 8):
        _seen(prior, k, "box", (0.0, 0.01), 1.0)
    assert prior.class_conflicts() == []  # a prior artifact is the user's word


def test_a_ghost_seen_only_from_afar_beside_an_object_seen_near_is_that_object() -> None:
    # Hall seed 1: box_2 seen from 0.9 m as a box; from 3.1 m, 6-10 cm off, as a can.
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(16):
        _seen(tracker, k, "can", (2.06, 1.0), 3.1)
    for k in range(16, 20):
        _seen(tracker, k, "box", (2.0, 1.0), 0.9)
    ((loser, winner),) = tracker.class_conflicts()
    assert (loser.id, winner.id) == ("can_1", "box_1")
    # two objects seen from near 8 cm apart stay two
    both = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(4):
        _seen(both, k, "can", (2.08, 1.0), 1.2)
        _seen(both, k, "box", (2.0, 1.0), 1.2)
    assert both.class_conflicts() == []


def test_a_class_that_gives_way_spends_no_id_until_it_has_the_better_evidence() -> None:
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(3):
        _seen(tracker, k, "bottle", (1.0, 0.0), 1.5)  # bottle_1, three near views
    for k in range(3, 6):
        _seen(tracker, k, "can", (1.0, 0.01), 1.5)  # the same object as a can: no id
    assert [t.id for t in tracker.confirmed] == ["bottle_1"]
    assert tracker.class_conflicts() == []
    _seen(tracker, 6, "can", (1.0, 0.01), 1.5)  # a fourth near can view: the can wins
    ((loser, winner),) = tracker.class_conflicts()
    assert (loser.id, winner.id) == ("bottle_1", "can_1")


def test_a_view_cut_by_the_image_border_is_no_evidence_of_the_class() -> None:
    # The head camera sees a bottle's lower half 1.5 m away and calls it a can.
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(5):
        _seen(tracker, k, "bottle", (2.0, 1.0), 2.5)  # whole, from far
        tracker.update(
            k * S, [Observation("can", np.array([2.0, 1.01]), 0.5, 0.03, range_m=1.5, whole=False)]
        )
    assert [t.near_hits for t in tracker.confirmed] == [0, 0]
    assert tracker.class_conflicts() == []


def test_one_object_in_pieces_is_one_artifact() -> None:
    # Hall seed 4: a bottle's mask split in its upper and lower parts, two detections at
    # one place in one frame; the second piece made bottle_7 5 cm from bottle_1.
    tracker = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(4):
        upper = Observation("bottle", np.array([-5.87, 0.07]), 0.94, 0.03, 0.7, range_m=0.9)
        lower = Observation("bottle", np.array([-5.85, 0.03]), 0.89, 0.03, 0.9, range_m=0.9)
        side = Observation("bottle", np.array([-5.85, 0.33]), 0.9, 0.03, 0.9, range_m=0.9)
        tracker.update(k * S, [upper, lower, side])
    (one, other) = tracker.confirmed
    assert (one.hits, other.hits) == (4, 4)
    assert np.allclose(one.xy, [-5.85, 0.03])  # the piece with the higher score
    # two artifacts of one class that came to one place are one (the fewer views give way)
    late = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(6):
        _seen(late, k, "bottle", (-5.85, 0.03), 0.9)
    for k in range(6, 9):  # a piece seen alone, say a gripper in front: 25 cm off, then near
        _seen(late, k, "bottle", (-5.85, 0.3), 0.9)
    assert late.class_conflicts() == []  # 27 cm apart: two objects
    late.tracks[1].xy = np.array([-5.87, 0.07])  # it drifted onto the first
    ((loser, winner),) = late.class_conflicts()
    assert (loser.id, winner.id) == ("bottle_2", "bottle_1")
    # two real bottles side by side, 6 cm apart, seen together: two
    pair = ArtifactTracker(IdBook(), SemanticMapSettings())
    for k in range(4):
        a = Observation("bottle", np.array([1.0, 0.0]), 0.9, 0.03, range_m=1.0)
        b = Observation("bottle", np.array([1.0, 0.06]), 0.9, 0.03, range_m=1.0)
        pair.update(k * S, [a, b])
    assert len(pair.confirmed) == 2 and pair.class_conflicts() == []
