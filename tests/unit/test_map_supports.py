"""The map's floor plan's supports (`services.semantic_map.supports`, `dume/map/supports`):
fetched once and only with the world's floor plan, `unavailable` when the world does not
come (asked again next time)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from common.bus import RequestError
from common.messages.world import SupportSurface
from services.semantic_map.supports import WORLD_WAIT_S, FloorPlanSupports

SURFACE = SupportSurface(
    id="table_1", centre_xy=(1.0, 1.0), half_extents=(0.5, 0.3), yaw=0.0, top_height=0.7
)


def test_the_supports_are_fetched_once_and_only_with_the_world_plan() -> None:
    asked: list[float] = []

    def world(wait_s: float) -> Any:
        asked.append(wait_s)
        return SimpleNamespace(surfaces=(SURFACE,))

    assert FloorPlanSupports("none", world).surfaces() == []
    assert asked == []
    supports = FloorPlanSupports("world", world)
    assert supports.surfaces() == [SURFACE]
    assert supports.surfaces() == [SURFACE]
    assert asked == [WORLD_WAIT_S]


def test_no_world_is_unavailable_and_asked_again() -> None:
    answers: list[Any] = [None, SimpleNamespace(surfaces=(SURFACE,))]
    supports = FloorPlanSupports("world", lambda _s: answers.pop(0))
    with pytest.raises(RequestError) as refused:
        supports.surfaces()
    assert refused.value.code == "unavailable"
    assert supports.surfaces() == [SURFACE]
