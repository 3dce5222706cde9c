"""The map's queryables, as functions of the map: listings, one entity, and their errors.

A listing may be filtered with selector parameters (`dume/map/artifacts?class=bottle`,
`?missing=true`); an entity is named by the key's last chunk. Every bad query is a typed
refusal: a wildcard or a malformed id is `invalid`, an id that is not in the map is
`unknown_id` (the message lists the ids there are), an unknown parameter is `invalid`.
Any of them may carry `at=<ns>` (`split_at`): the node answers from the map as of then.
"""

from __future__ import annotations

import re
from typing import Protocol

from common.bus import RequestError
from common.messages.semantic_map import EntityKind, MapEntity, MapListing
from services.semantic_map.entities import split_id

_CLASS = re.compile(r"^[a-z][a-z0-9]*$")
PARAMS = ("class", "missing")


def parse_selector(selector: str) -> tuple[str, dict[str, str]]:
    """(key, parameters) of `key?a=1;b=2` (also `&`-separated)."""
    key, _, query = selector.partition("?")
    params: dict[str, str] = {}
    for item in re.split(r"[;&]", query):
        if not item:
            continue
        name, sep, value = item.partition("=")
        if not sep:
            raise RequestError("invalid", f"parameter {item!r} is not name=value")
        params[name] = value
    return key, params


class MapReader(Protocol):
    """What the queries read: the map now (`SemanticMap`) or as of a tick (`MapView`)."""

    stamp_ns: int

    def entities(self, kind: EntityKind) -> list[MapEntity]: ...
    def entity(self, kind: EntityKind, entity_id: str) -> MapEntity | None: ...


def split_at(selector: str) -> tuple[str, int | None]:
    """The selector without its `at=<ns>` parameter (a lockstep consumer's sim time: the
    map as of then, `common.keys.as_of`), and that time (None without one)."""
    key, params = parse_selector(selector)
    raw = params.pop("at", None)
    if raw is None:
        return selector, None
    if not raw.isdigit():
        raise RequestError("invalid", f"at={raw!r}: a sim time in integer nanoseconds")
    rest = ";".join(f"{k}={v}" for k, v in params.items())
    return (f"{key}?{rest}" if rest else key), int(raw)


def listing(smap: MapReader, kind: EntityKind, selector: str) -> MapListing:
    _key, params = parse_selector(selector)
    unknown = sorted(set(params) - set(PARAMS))
    if unknown:
        raise RequestError("invalid", f"unknown parameter(s) {unknown}; known: {list(PARAMS)}")
    entities = smap.entities(kind)
    cls = params.get("class")
    if cls is not None:
        if not _CLASS.match(cls):
            raise RequestError("invalid", f"class {cls!r} is not a class name (like bottle)")
        entities = [e for e in entities if e.class_name == cls]
    missing = params.get("missing")
    if missing is not None:
        if missing not in ("true", "false"):
            raise RequestError("invalid", f"missing={missing!r}: use true or false")
        want = missing == "true"
        entities = [e for e in entities if (e.missing_since_ns is not None) == want]
    return MapListing(stamp_ns=smap.stamp_ns, entities=entities)


def one(smap: MapReader, kind: EntityKind, selector: str) -> MapEntity:
    key, params = parse_selector(selector)
    if params:
        raise RequestError("invalid", f"{key} takes no parameters, got {sorted(params)}")
    entity_id = key.rsplit("/", 1)[-1]
    if "*" in entity_id or "$" in entity_id:
        raise RequestError("invalid", f"{key}: name one id; the listing is {key.rsplit('/', 1)[0]}")
    parsed = split_id(entity_id)
    if parsed is None:
        raise RequestError("invalid", f"{entity_id!r} is not an id like bottle_1 or person_2")
    if kind == "person" and parsed[0] != "person":
        raise RequestError("invalid", f"{entity_id!r} is not a person's id (person_<n>)")
    if kind == "artifact" and parsed[0] == "person":
        raise RequestError("invalid", f"{entity_id!r} is a person: ask dume/map/people/{entity_id}")
    entity = smap.entity(kind, entity_id)
    if entity is None:
        known = [e.id for e in smap.entities(kind)]
        raise RequestError("unknown_id", f"no {kind} {entity_id!r} in the map; there are {known}")
    return entity
