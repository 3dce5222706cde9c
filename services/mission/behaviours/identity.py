"""Whom the robot hands over to: the person asked for, by their clothes, not the nearest body.

The map keeps a person's id by where they walk and what they wear, and it can lose who
is who: in hall seed 0's shift the map's person_6 was one worker until 177.6 s and
another from 197.7 s (two walkers crossed unseen), and the robot handed box_1 to the
second at 203 s, saying it had succeeded. A person would look at who stands in front of
them before letting go. So:

- `NoteLook`, as a fetch begins: the colours the map has for the requested person then
  (`MapEntity.colours`: the tracker's histograms of their clothes by range band), kept
  as the request's `Look` (`PERSON_LOOK`). A person the map has not seen yet has none:
  they are noted at `ResolvePerson` when the fetch brings the object (`note_look`), if
  the map has seen them by then.
- `RightPerson`, at the person and before the arm presents: the map's colours of the
  person standing there against the `Look`, like with like (`common.appearance.differ`:
  a band both have seen often enough, its distance beyond the band's threshold). No band
  says two people (alike, or nothing to compare: a person seen only from near when
  asked and from afar since), SUCCESS: colours never refuse somebody they cannot tell
  apart. A band says two people: FAILURE `wrong_person`, and the id goes on `OTHERS`.
  The map person the noted colours do not tell apart from the one asked for, with a band
  to compare (the nearest in colours, not one of `OTHERS`), becomes the `PERSON` walked
  to next (the tree's `find_person` takes `wrong_person` as one more round when it named
  one, `another_to_try`); nobody such, the request fails there, the object still held,
  with the colour distances said.
- The ask (`LookForPerson`) is answered only by someone the colours do not tell apart
  from the one asked for (`other_clothes`).
- On the walk to the person (`NavigateTo`), the map's entry of them not seen for
  `STALE_S` while somebody stands near the robot in their colours, nearly the same in
  every band compared (`wearer_near`, `WEARER_SAME`): the map split them, and the walk
  goes to that one (hall seed 0's shift: the map's person_4 stayed where they had
  walked past, the worker themselves stood 1.2 m from the robot as person_10, and the
  robot stood 120 s by them, its walk to the old place held by their protective
  separation, until the request timed out). Not when somebody else in the map is
  dressed nearly the same (`look_alikes`): colours cannot say who, and the walk goes
  on to where the map saw them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from py_trees.common import Status

from common.appearance import OTHER, Band, differ
from common.messages.semantic_map import MapEntity, PersonColours
from services.mission import targets
from services.mission.behaviours.base import (
    OTHERS,
    PERSON,
    PERSON_LOOK,
    REQUEST,
    Context,
    Failure,
    MissionBehaviour,
    read,
)
from services.mission.ports import PortError


@dataclass(frozen=True)
class Look:
    """The requested person's colours as the map had them (`MapEntity.colours`), their
    map id then, and when (sim ns)."""

    person_id: str
    colours: PersonColours
    noted_ns: int


def compared(look: Look | None, person: MapEntity) -> list[tuple[Band, float, bool]]:
    """The noted person's colours against `person`'s, band by band (`differ`: band,
    distance, two people); empty when nothing compares."""
    if look is None or person.colours is None:
        return []
    return differ(look.colours, person.colours)


def other_clothes(look: Look | None, person: MapEntity) -> bool:
    """Whether the colours say `person` is not the one noted."""
    return any(other for _, _, other in compared(look, person))


def nearest_alike(
    look: Look, people: list[MapEntity]
) -> tuple[MapEntity, list[tuple[Band, float, bool]]] | None:
    """Of `people`, the one the noted colours compare with (a band both have seen) and
    do not tell apart from the one asked for, the nearest in colours, with the bands;
    None if nobody is."""
    alike = [(q, b) for q in people if (b := compared(look, q)) and not any(o for _, _, o in b)]
    return min(alike, key=lambda item: max(d for _, d, _ in item[1]), default=None)


def said(bands: list[tuple[Band, float, bool]]) -> str:
    return ", ".join(f"{band} {d:.2f}" for band, d, _ in bands) or "no band to compare"


def note_look(b: MissionBehaviour, person: MapEntity) -> None:
    """Keep `person`'s colours as the request's `Look` unless one is kept already (the
    behaviour must write `PERSON_LOOK`)."""
    c = person.colours
    if b.get(PERSON_LOOK) is not None or c is None or not (c.far_views or c.near_views):
        return
    b.set(PERSON_LOOK, Look(person.id, c, b.port.now_ns))
    b.ctx.decide(f"{person.id}'s colours noted ({c.far_views} views from afar, "
                 f"{c.near_views} from near): the handover goes to whoever wears them")  # fmt: skip


class NoteLook(MissionBehaviour):
    """The requested person's colours as the fetch begins (the module docstring); always
    SUCCESS (not in the map, or the map down: `ResolvePerson` says so later)."""

    WRITES = (PERSON_LOOK, OTHERS)

    def __init__(self, ctx: Context) -> None:
        super().__init__("note_look", ctx, stage="")

    def update(self) -> Status:
        self.set(OTHERS, [])
        try:
            person = targets.person_named(self.port, self.get(REQUEST).person)
        except PortError:
            return Status.SUCCESS
        if person is not None:
            note_look(self, person)
        return Status.SUCCESS


class RightPerson(MissionBehaviour):
    """SUCCESS when the person at the handover place wears the noted colours (the module
    docstring); else FAILURE `wrong_person`."""

    WRITES = (PERSON, OTHERS)

    def __init__(self, ctx: Context, stage: str) -> None:
        super().__init__("right_person", ctx, stage)

    def update(self) -> Status:
        look: Look | None = self.get(PERSON_LOOK)
        pid = str(self.get(PERSON))
        try:
            person = self.port.person(pid)
        except PortError:
            person = None
        bands = [] if person is None else compared(look, person)
        if look is None or not any(other for _, _, other in bands):
            self.feedback_message = f"{pid}: colours {said(bands)}"
            return Status.SUCCESS
        others = [*(self.get(OTHERS) or []), pid]
        self.set(OTHERS, others)
        asked = (f"{pid} stands there in other clothes than {look.person_id} wore when asked "
                 f"(colour distance {said(bands)})")  # fmt: skip
        best = self._wearer(look, others)
        if best is None:
            return self.fail("wrong_person", f"{asked}; nobody else in the map wears their "
                             "colours: not handed over")  # fmt: skip
        who, bands = best
        self.set(PERSON, who.id)
        return self.fail("wrong_person", f"{asked}; {who.id} wears them ({said(bands)}): "
                         f"walking to {who.id}")  # fmt: skip

    def _wearer(
        self, look: Look, others: list[str]
    ) -> tuple[MapEntity, list[tuple[Band, float, bool]]] | None:
        """The map person the noted colours compare with and do not tell apart from the
        one asked for, the nearest in colours, not one of `others`; None if nobody is."""
        try:
            people = self.port.people()
        except PortError:
            return None
        return nearest_alike(look, [q for q in people if q.id not in others])


#: s: the map's entry of the person asked for, unseen this long, may have come apart.
STALE_S = 5.0
#: m: how near the robot somebody in their colours stands to be taken for them.
WEARER_NEAR_M = 3.0
#: A walk goes to somebody else's id on colours alone only when every band compared is
#: this near (half of what tells two people apart, `common.appearance.OTHER`): seed 1's
#: shift, three people alike, walked to person_3 (far 0.49, near 0.01) for person_11
#: and handed the bottle to the wrong worker. Not told apart is enough not to refuse
#: somebody (`RightPerson`), not to go to them instead.
WEARER_SAME: dict[Band, float] = {band: 0.5 * d for band, d in OTHER.items()}


def look_alikes(
    look: Look, people: list[MapEntity], but: list[str]
) -> list[tuple[MapEntity, list[tuple[Band, float, bool]]]]:
    """The map people, not named in `but`, whom the noted colours compare with and find
    nearly the same in every band compared (`WEARER_SAME`), with the bands."""
    same = [(q, compared(look, q)) for q in people if q.id not in but]
    return [(q, b) for q, b in same if b and all(d <= WEARER_SAME[band] for band, d, _ in b)]


def wearer_near(
    look: Look | None,
    asked: MapEntity | None,
    people: list[MapEntity],
    robot_xy: tuple[float, float],
    now_ns: int,
    standing: Callable[[MapEntity], bool],
    others: list[str],
) -> tuple[MapEntity, list[tuple[Band, float, bool]]] | None:
    """Somebody standing (`standing`: seen lately, not walking) within `WEARER_NEAR_M` of
    the robot in the noted colours, nearly the same in every band compared
    (`look_alikes`), while the map's entry of the one asked for (`asked`; None: gone from
    the map) is not seen for `STALE_S`, and nobody else in the map is dressed so (hall
    seed 1's shift: person_3 and person_4 wore the same shirt, near 0.03, and the robot
    walked to the one standing by it for the other, twice); None otherwise (no look,
    nobody such, a look-alike, or one of `others`)."""
    if look is None or (asked is not None and now_ns - asked.last_seen_ns < STALE_S * 1e9):
        return None
    alike = look_alikes(look, people, [*others, *([asked.id] if asked is not None else [])])
    if len(alike) != 1:
        return None
    who, bands = alike[0]
    if not standing(who) or math.dist(who.position_in_world[:2], robot_xy) > WEARER_NEAR_M:
        return None
    return who, bands


def another_to_try(bb: Any) -> Callable[[Failure], bool]:
    """`find_person`'s `Recover.prepare`: a `wrong_person` is one more round only when
    `RightPerson` named somebody else to walk to (`PERSON` not one of `OTHERS`)."""

    def prepare(failure: Failure) -> bool:
        if failure.reason != "wrong_person":
            return True
        return read(bb, PERSON) not in (read(bb, OTHERS) or [])

    return prepare
