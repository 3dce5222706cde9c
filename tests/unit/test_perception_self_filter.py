"""People seen inside the robot's own footprint are the robot itself, and people lying flat
on the floor or in a thin horizontal slab are not people: all are dropped."""

from __future__ import annotations

import numpy as np

from common.messages.arrays import to_wire
from common.messages.perception import Detection
from common.robot import FOOTPRINT_BOUNDS
from services.perception.pipeline import Detected
from services.perception.self_filter import (
    PERSON_MIN_TOP_M,
    SELF_MARGIN_M,
    drop_self,
    is_flat,
    is_self,
    is_slab,
)

#: The frame's width, pixels.
W = 320


def _det(cls: str, x: float, y: float, top_row: int = 0, left: int = 100) -> Detection:
    return Detection(
        class_name=cls,
        score=0.8,
        bbox=(left, top_row, left + 2, top_row + 2),
        mask=to_wire(np.ones((2, 2), np.uint8)),
        centroid_in_base_yaw=(x, y, 0.6),
        centroid_in_world=(x, y, 0.6),
        axis_in_world=(x, y, 0.6),
        extent=(0.3, 0.3, 0.6),
        d_obj=float(np.hypot(x, y)),
        theta_obj=float(np.arctan2(y, x)),
        n_points=200,
    )


def test_a_person_inside_the_footprint_or_just_beyond_is_the_robot() -> None:
    _, x1, y0, _ = FOOTPRINT_BOUNDS
    assert is_self(_det("person", 0.0, 0.0))
    assert is_self(_det("person", x1 + SELF_MARGIN_M - 0.01, 0.0))
    assert is_self(_det("person", 0.0, y0 - SELF_MARGIN_M + 0.01))


def test_people_outside_and_artifacts_anywhere_are_kept() -> None:
    x0, x1, _, y1 = FOOTPRINT_BOUNDS
    assert not is_self(_det("person", x1 + SELF_MARGIN_M + 0.05, 0.0))
    assert not is_self(_det("person", 0.0, y1 + 0.6))
    assert not is_self(_det("person", x0 - 0.8, 0.0))
    assert not is_self(_det("bottle", 0.3, 0.0)), "the object in front of the base is kept"
    detected = [
        Detected(_det("person", 0.1, 0.0), np.zeros((0, 3))),
        Detected(_det("person", 3.0, 1.0), np.zeros((0, 3))),
        Detected(_det("bottle", 0.5, 0.0), np.zeros((0, 3))),
    ]
    kept, dropped = drop_self(detected, W)
    assert dropped == 1
    assert [d.detection.class_name for d in kept] == ["person", "bottle"]


def _points(top_z: float, n: int = 200) -> np.ndarray:
    """Points from the floor up to `top_z`, 3 m ahead."""
    z = np.linspace(0.0, top_z, n)
    return np.column_stack([np.full(n, 3.0), np.zeros(n), z])


def test_a_person_whose_whole_height_shows_below_half_a_metre_lies_flat_and_is_dropped() -> None:
    """A bottle knocked to the floor, read as a person: its top shows, 7 cm up."""
    lying = Detected(_det("person", 3.0, 0.0, top_row=180), _points(0.07))
    assert is_flat(lying, W)
    low = PERSON_MIN_TOP_M - 0.05
    assert is_flat(Detected(_det("person", 3.0, 0.0, top_row=120), _points(low)), W)
    stray = _points(0.07)
    stray[:3, 2] = 1.8  # a few stray points high up do not make it stand
    assert is_flat(Detected(_det("person", 3.0, 0.0, top_row=180), stray), W)
    kept, dropped = drop_self([lying, Detected(_det("person", 3.0, 1.0, 10), _points(1.7))], W)
    assert dropped == 1 and len(kept) == 1


def test_a_person_cut_by_the_frames_edges_or_standing_and_artifacts_are_kept() -> None:
    legs = Detected(_det("person", 1.0, 0.0, top_row=0), _points(0.4))  # the rest above
    assert not is_flat(legs, W)
    for left in (0, W - 2):  # a sliver of a leg at a side edge
        assert not is_flat(Detected(_det("person", 1.0, 0.0, 120, left), _points(0.4)), W)
    assert not is_flat(Detected(_det("person", 3.0, 0.0, top_row=40), _points(1.7)), W)
    under_a_table = Detected(_det("person", 3.0, 0.0, top_row=90), _points(0.75))
    assert not is_flat(under_a_table, W)
    assert not is_flat(Detected(_det("bottle", 3.0, 0.0, top_row=180), _points(0.07)), W)


def _slab(width_m: float, height_m: float, z: float = 0.8, n: int = 200) -> np.ndarray:
    """Points `width_m` across (along y, 2 m ahead) and `height_m` tall about z."""
    rng = np.random.default_rng(0)
    y = rng.uniform(-width_m / 2, width_m / 2, n)
    return np.column_stack([np.full(n, 2.0), y, z + rng.uniform(-height_m / 2, height_m / 2, n)])


def test_a_person_in_a_thin_horizontal_slab_is_a_tables_edge_and_is_dropped() -> None:
    """The small world's table underside at the head camera's top edge: 0.7 m across, level."""
    underside = Detected(_det("person", 2.0, 0.0, top_row=0), _slab(0.7, 0.0))
    assert is_slab(underside)
    assert is_slab(Detected(_det("person", 2.0, 0.0), _slab(0.5, 0.1)))  # 5 × wider than tall
    kept, dropped = drop_self([underside, Detected(_det("person", 3.0, 1.0), _points(1.7))], W)
    assert dropped == 1 and [d.detection.centroid_in_world[1] for d in kept] == [1.0]


def test_a_heads_sliver_a_standing_person_and_a_flat_artifact_are_no_slab() -> None:
    """A head at the frame's top edge is about as wide as it is tall; a bottle is no person."""
    assert not is_slab(Detected(_det("person", 2.0, 0.0, top_row=0), _slab(0.18, 0.05, 1.6)))
    assert not is_slab(Detected(_det("person", 2.0, 0.0), _slab(0.5, 0.3)))  # too tall
    assert not is_slab(Detected(_det("person", 3.0, 0.0), _points(1.7)))
    assert not is_slab(Detected(_det("person", 3.0, 0.0), np.zeros((0, 3))))
    assert not is_slab(Detected(_det("box", 2.0, 0.0), _slab(0.7, 0.0)))
