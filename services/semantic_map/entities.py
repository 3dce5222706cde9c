"""The map's in-memory entities and their ids, shared by the artifact and person trackers.

A `Track` is one artifact or person: a horizontal position with a covariance, a height,
bookkeeping (last seen, missing since, source) and, for people, a velocity and an
appearance histogram. A track is *tentative* (no id, never listed or stored) until it has
been seen `confirm_hits` times; then `IdBook` gives it the next `<class>_<n>` of its class.
Numbers are never reused: the book remembers the last number per class, also across
restarts (it is stored with the map) and after an import.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from common.appearance import Banded
from common.geometry import FloatArray
from common.messages.semantic_map import EntityKind, MapEntity, Source
from services.semantic_map.whereabouts import Whereabouts

_ID = re.compile(r"^([a-z][a-z0-9]*)_([1-9][0-9]*)$")


def split_id(entity_id: str) -> tuple[str, int] | None:
    """`("bottle", 3)` from `bottle_3`; None for anything that is not an id."""
    m = _ID.match(entity_id)
    return (m.group(1), int(m.group(2))) if m else None


class IdBook:
    """The next `<class>_<n>` per class; never gives a number twice."""

    def __init__(self, counters: dict[str, int] | None = None) -> None:
        self.counters: dict[str, int] = dict(counters or {})

    def next_id(self, class_name: str) -> str:
        n = self.counters.get(class_name, 0) + 1
        self.counters[class_name] = n
        return f"{class_name}_{n}"

    def reserve(self, entity_id: str) -> None:
        """An id that exists already (a prior, a seed, an import): never give it again."""
        parsed = split_id(entity_id)
        if parsed is not None:
            cls, n = parsed
            self.counters[cls] = max(self.counters.get(cls, 0), n)


@dataclass
class Track:
    """One artifact or person, tentative (id None) or confirmed.

    xy: (2,) m, world. cov: (2, 2) m², the horizontal position's covariance. z: m, height
    of the position (the visible centroid's for artifacts, 0 for people's feet).
    velocity: (2,) m/s (people). appearance: colour histogram (people), or None.
    vel_cov: (2, 2) (m/s)², the velocity's covariance.
    hits: detections fused. misses: consecutive looks at its place without seeing it.
    near_hits: whole detections fused from within the fusion's `near_m` (the class is
    trusted from there; not stored: a track read from the database starts at 0).
    seen_with: people, the ids of the people detected in one frame with this one (two
    bodies, never one split track; not stored).
    best_range_m: artifacts, the range of the nearest view fused (m; None: not known, as
    for a seeded or imported artifact; stored as the entity's `nearest_view_m`).
    """

    class_name: str
    kind: EntityKind
    xy: FloatArray
    cov: FloatArray
    z: float
    source: Source
    id: str | None = None
    last_seen_ns: int = 0
    first_seen_ns: int = 0
    missing_since_ns: int | None = None
    yaw: float = 0.0
    velocity: FloatArray = field(default_factory=lambda: np.zeros(2))
    vel_cov: FloatArray = field(default_factory=lambda: np.eye(2) * 0.25)
    appearance: FloatArray | None = None
    hits: int = 0
    misses: int = 0
    near_hits: int = 0
    #: Sim time the state refers to (people are predicted forward), ns.
    stamp_ns: int = 0
    #: People: the (4, 4) covariance of (x, y, vx, vy); `cov` is its position block.
    P: FloatArray | None = None
    #: People: the velocity at the last sighting was sure (extrapolated while unseen).
    moving: bool = False
    #: People: seen walking (a sure velocity) at some sighting: a body, not furniture.
    walked: bool = False
    seen_with: set[str] = field(default_factory=set)
    #: People: detections near them in somebody else's clothes standing still: (first
    #: stamp ns, first xy, last stamp ns), or None (`people.PeopleTracker._colours_lie`).
    doubt: tuple[int, FloatArray, int] | None = None
    best_range_m: float | None = None
    #: People: where they were seen (`whereabouts`), their usual places.
    whereabouts: Whereabouts = field(default_factory=Whereabouts)
    #: People: their colours by range band (`common.appearance.Banded`), which the mission
    #: checks whom it hands over to by (stored with the entry, `MapEntity.colours`).
    colours: Banded = field(default_factory=Banded)

    @property
    def confirmed(self) -> bool:
        return self.id is not None

    @property
    def sigma_m(self) -> float:
        """1-σ of the horizontal position: the root of the covariance's largest eigenvalue."""
        return float(np.sqrt(max(np.linalg.eigvalsh(self.cov)[-1], 0.0)))

    def to_message(self) -> MapEntity:
        if self.id is None:
            raise ValueError(f"a tentative {self.class_name} track has no id yet")
        return MapEntity(
            id=self.id,
            class_name=self.class_name,
            kind=self.kind,
            position_in_world=(float(self.xy[0]), float(self.xy[1]), float(self.z)),
            uncertainty_m=self.sigma_m,
            last_seen_ns=self.last_seen_ns,
            first_seen_ns=self.first_seen_ns,
            source=self.source,
            missing_since_ns=self.missing_since_ns,
            yaw=self.yaw,
            velocity_in_world=(float(self.velocity[0]), float(self.velocity[1])),
            observations=self.hits,
            nearest_view_m=self.best_range_m,
            places=self.whereabouts.places() if self.kind == "person" else (),
            colours=self.colours.to_message() if self.kind == "person" else None,
        )

    @classmethod
    def from_message(cls, e: MapEntity, appearance: FloatArray | None = None) -> Track:
        s2 = max(e.uncertainty_m, 1e-3) ** 2
        return cls(
            class_name=e.class_name,
            kind=e.kind,
            xy=np.array(e.position_in_world[:2], dtype=float),
            cov=np.eye(2) * s2,
            z=float(e.position_in_world[2]),
            source=e.source,
            id=e.id,
            last_seen_ns=e.last_seen_ns,
            first_seen_ns=e.first_seen_ns,
            missing_since_ns=e.missing_since_ns,
            yaw=e.yaw,
            velocity=np.array(e.velocity_in_world, dtype=float),
            appearance=appearance,
            hits=e.observations,
            best_range_m=e.nearest_view_m,
            whereabouts=Whereabouts.of(e.places),
            colours=Banded.from_message(e.colours),
        )


@dataclass(frozen=True)
class Observation:
    """One detection as the trackers see it.

    xy: (2,) m, world (an artifact's axis point, a person's feet). z: m. sigma_m: 1-σ
    horizontal noise of this measurement (grows with range). appearance: histogram or None.
    range_m: the detection's distance from the camera's base, d_obj. whole: its mask does
    not touch the image's border (a cut object's class is a guess: the head camera sees
    the lower half of a bottle on a table 1.5 m away, and the network calls that a can).
    """

    class_name: str
    xy: FloatArray
    z: float
    sigma_m: float
    score: float = 1.0
    appearance: FloatArray | None = None
    range_m: float = 0.0
    whole: bool = True

    def near(self, near_m: float) -> bool:
        """Whether its class counts: whole in its image and within `near_m`."""
        return self.whole and self.range_m <= near_m


def measurement_sigma(range_m: float, sigma0_m: float, per_m: float) -> float:
    """A detection's horizontal 1-σ: a floor plus a share of its range."""
    return sigma0_m + per_m * max(range_m, 0.0)
