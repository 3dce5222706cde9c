"""Every number in the settings has its range, and a value outside it is refused at
load with the key and the range (the probe: `sim.watchdog_ms=-5` and
`time.stall_timeout_s=-1` were accepted). Walks `Config`'s types, so a new setting
without a range fails here."""

from __future__ import annotations

import math
from typing import Any

import msgspec.inspect as mi
import pytest

from common.config import Config, ConfigError, load_config


def numbers(ti: Any, path: str = "") -> list[tuple[str, Any]]:
    """(dotted path, the number's type info) of every number in the settings; paths
    inside a mapping or a sequence are marked with `*` and `[]`."""
    if isinstance(ti, mi.Metadata):
        return numbers(ti.type, path)
    if isinstance(ti, mi.StructType):
        return [n for f in ti.fields for n in numbers(f.type, f"{path}.{f.name}".lstrip("."))]
    if isinstance(ti, mi.FloatType | mi.IntType):
        return [(path, ti)]
    if isinstance(ti, mi.UnionType):
        return [n for t in ti.types for n in numbers(t, path)]
    if isinstance(ti, mi.DictType):
        return numbers(ti.value_type, path + ".*")
    if isinstance(ti, mi.ListType | mi.VarTupleType):
        return numbers(ti.item_type, path + "[]")
    if isinstance(ti, mi.TupleType):
        return [n for t in ti.item_types for n in numbers(t, path + "[]")]
    return []


ALL = numbers(mi.type_info(Config))
SCALARS = [(p, ti) for p, ti in ALL if "*" not in p and "[]" not in p]


def test_every_number_in_the_settings_has_a_range() -> None:
    bounds = ("gt", "ge", "lt", "le")
    unbounded = [p for p, ti in ALL if all(getattr(ti, a) is None for a in bounds)]
    assert not unbounded, unbounded
    assert len(SCALARS) > 100


def _outside(ti: Any) -> Any:
    """A value just outside the range (below its lower bound, else above its upper)."""
    if ti.ge is not None:
        return ti.ge - 1
    if ti.gt is not None:
        return ti.gt - (1 if isinstance(ti, mi.IntType) else 0.0)
    if ti.le is not None:
        return ti.le + 1
    return ti.lt


@pytest.mark.parametrize(("path", "ti"), SCALARS, ids=[p for p, _ in SCALARS])
def test_a_value_outside_its_range_is_refused_with_the_key_and_the_range(
    path: str, ti: Any
) -> None:
    bad = _outside(ti)
    with pytest.raises(ConfigError) as err:
        load_config({path: bad})
    said = str(err.value)
    assert f"$.{path}" in said and ("Expected `" in said), said
    if isinstance(ti, mi.FloatType):
        with pytest.raises(ConfigError):
            load_config({path: math.nan})
