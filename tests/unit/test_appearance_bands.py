"""A person's colours by range band: fed, pooled and compared like with like."""

from __future__ import annotations

import numpy as np

from common.appearance import MIN_VIEWS, OTHER, SIZE, Banded, band_of, bhattacharyya, differ
from common.config import SemanticMapSettings
from common.messages.semantic_map import PersonColours
from services.semantic_map.entities import IdBook, Observation
from services.semantic_map.people import PeopleTracker, merge_split_people

S = 1_000_000_000


def _hist(*peaks: int) -> np.ndarray:
    h = np.full(SIZE, 0.01)
    h[list(peaks)] += 1.0
    return h / h.sum()


SHIRT, LEGS, OTHER_SHIRT = _hist(2, 3, 49), _hist(50, 51), _hist(30, 31, 49)


def test_a_view_feeds_the_band_of_its_range() -> None:
    assert band_of(4.0, whole=True) == "far"
    assert band_of(4.0, whole=False) is None  # cut by the image's border: part of them
    assert band_of(2.5, whole=True) is None  # between the bands
    assert band_of(1.0, whole=False) == "near"
    assert band_of(0.0, whole=True) is None  # range unknown


def test_bands_compare_like_with_like_once_each_side_has_its_views() -> None:
    asked, there = Banded(), Banded()
    for _ in range(MIN_VIEWS):
        asked.see(SHIRT, 4.0, True)
        there.see(LEGS, 1.0, True)  # the same person from near: legs only
    assert bhattacharyya(SHIRT, LEGS) > OTHER["far"]  # one model would call them two
    assert differ(asked.to_message(), there.to_message()) == []  # no band in common
    for _ in range(MIN_VIEWS - 1):
        there.see(OTHER_SHIRT, 4.0, True)
    assert differ(asked.to_message(), there.to_message()) == []  # too few far views yet
    there.see(OTHER_SHIRT, 4.0, True)
    [(band, d, two)] = differ(asked.to_message(), there.to_message())
    assert band == "far" and two and d > OTHER["far"]


def test_absorbed_views_are_pooled_by_their_counts() -> None:
    a, b = Banded(), Banded()
    for _ in range(3):
        a.see(SHIRT, 4.0, True)
    b.see(OTHER_SHIRT, 4.0, True)
    a.absorb(b)
    assert a.far_views == 4 and a.near is None and a.near_views == 0
    assert a.far is not None
    np.testing.assert_allclose(a.far, (3 * SHIRT + OTHER_SHIRT) / 4, atol=1e-9)
    empty = Banded()
    empty.absorb(a)
    assert empty.far_views == 4 and empty.far is not a.far  # a copy, not shared


def test_the_tracker_keeps_a_persons_colours_by_band_and_the_map_entry_says_them() -> None:
    tracker = PeopleTracker(IdBook(), SemanticMapSettings())
    for k in range(12):
        rng, view = (4.0, SHIRT) if k < 6 else (1.2, LEGS)
        obs = Observation("person", np.array([1.0, 2.0]), 0.0, 0.05, appearance=view,
                          range_m=rng, whole=True)  # fmt: skip
        tracker.update(k * S // 10, [obs])
    [person] = tracker.confirmed
    c = person.to_message().colours
    assert c is not None and (c.far_views, c.near_views) == (6, 6)
    assert bhattacharyya(np.asarray(c.far), SHIRT) < 0.01
    assert bhattacharyya(np.asarray(c.near), LEGS) < 0.01


def test_colours_read_back_from_a_map_entry_are_the_ones_written() -> None:
    c = Banded()
    for _ in range(4):
        c.see(SHIRT, 4.0, True)
    back = Banded.from_message(c.to_message())
    assert (back.far_views, back.near_views, back.near) == (4, 0, None)
    assert back.far is not None and bhattacharyya(back.far, SHIRT) < 1e-3
    bad = PersonColours(far=(0.5, 0.5), far_views=4)  # not a histogram of this size
    assert Banded.from_message(bad).far is None and Banded.from_message(None).far_views == 0


def test_pieces_of_one_body_merged_keep_their_range_and_count_as_cut() -> None:
    """The segmenter split a person 4 m away in two: the merged observation is 4 m away
    and a piece of them, so its colours feed no far band (a whole view's would)."""
    top = Observation("person", np.array([4.0, 0.1]), 0.0, 0.1, 0.9, SHIRT, 4.0, whole=True)
    legs = Observation("person", np.array([4.0, -0.1]), 0.0, 0.1, 0.6, LEGS, 4.1, whole=True)
    [one] = merge_split_people([legs, top], radius_m=0.5)
    assert one.range_m == 4.0 and not one.whole
    assert band_of(one.range_m, one.whole) is None
