"""The semantic map as a value: detections in, entities, missing flags and occupancy out.

`SemanticMap` holds the artifact and person trackers, one id book and the occupancy layer,
and no transport: `ingest(detections, frame)` fuses one camera frame's detections (the
frame, when at hand, gives the people's colour histograms, the frustum and depth of the
missing test, and the depth points of the learned obstacles). What changed since the last
`take_changes()` (and `take_deletions()`) is what the node writes to the database in one
transaction.
False entries: an entity the map created itself (source `perception`) from fewer than
`drop_below_observations` detections, or an artifact it only ever saw from beyond
`class_near_m` (a can read as a box from 3-5 m while exploring, however often), that is
then looked for at its place (within `look_range_m`) and not seen
(`missing_after_frames` looks) is deleted with the reason, not marked missing: a table
leg read as a box a few times during a patrol should not send the mission searching, and
a person made of a few stray detections (a split track, a false positive) should not
stand in navigation's way or answer a request. People are looked for at chest height
within `person_look_range_m` (the segmenter finds people farther than artifacts).
Prior, seeded and imported entities, and well-observed ones, are only marked missing
(artifacts) or kept (people). One object the map made under two classes (a can on a bench
read as a box from 3 m and as a can from 1.5 m) keeps the class seen from near, and the
other entry is deleted with the reason (`ArtifactTracker.class_conflicts`); so is one of
two artifacts of one class at one place (an object's mask split in pieces).
Measurement conventions: an artifact is placed at the detection's axis point (about a
radius behind the visible surface) at the visible centroid's height; a person at the
axis point's floor projection; the horizontal noise grows with the range d_obj. Person
detections of one frame within `PERSON_MERGE_M` of each other are one person, and an
artifact detection that close to a person of the same frame is dropped (clothes). A
person detection within `person_obstacle_margin_m` of a static obstacle cell (a person
cannot stand inside a machine or on a bench) is a fixed thing the network read as a
person: ignored, and it hides no artifact (the hall patrol lost cans on benches that
way); nor does any "person" hide an artifact that stands on a static obstacle (the wrist
camera reads a bench's front as a person 15-35 cm from the can on it, outside the
margin). Only the static layer counts: a learned cell may be a person perception missed.
On a map whose static layer the robot is still sensing, the people it made are checked
again as the layer grows (`drop_doubtful`): the network reads a machine's edges as a
person (their masks lie on its faces, the centroid within 3 cm of them), seen before the
lidar had mapped the face (the explored hall's person_13, 36 detections).
What the robot takes away is not at its place any more: `taken(takes)` (the mission's
latest takes, on its patrol status) marks missing, since the take, the entry of the
class nearest where the jaw closed (within `TAKEN_M`) and the entry the mission picked
it as (within `TAKEN_NAMED_M`: the approach may have closed on its neighbour), unless the
map saw it after the take (`TAKEN_GRACE_S`: put back and seen again, the take read
again after a restart); a detection clears it, as any missing flag.
Nor is a "person" within `SELF_MARGIN_M` of the robot's own footprint (`common.robot`'s,
arm stowed) at capture: that is the robot itself, seen by its own cameras (nobody stands
inside the robot; a person there would give navigation a lethal disc around the robot).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from common import robot
from common.appearance import colour_histogram
from common.camera import PinholeCamera
from common.config import SemanticMapSettings
from common.geometry import FloatArray
from common.grid import occupied_near
from common.messages import as_numpy, to_wire
from common.messages.mission import Taken
from common.messages.perception import Detection, Detections
from common.messages.semantic_map import EntityKind, MapEntity, OccupancyGrid
from common.messages.sim import CameraFrame
from common.messages.world import SupportSurface
from services.semantic_map.artifacts import ArtifactTracker
from services.semantic_map.entities import IdBook, Observation, Track, measurement_sigma
from services.semantic_map.evidence import (
    PERSON_MERGE_M,
    PERSON_REACH_M,
    PERSON_RECENT_NS,
    artifact_doubt,
    on_obstacle,
    person_doubt,
    surface_under,
)
from services.semantic_map.looks import looks_at, sees_over
from services.semantic_map.occupancy import Occupancy
from services.semantic_map.people import PeopleTracker, merge_split_people
from services.semantic_map.supports import surfaces_from_tops, with_kept

log = logging.getLogger("dume.semantic_map")

#: Depth points this close to the base (horizontally) are the robot itself, m.
SELF_RADIUS_M = 0.7
#: The learned obstacles' depth points: every LEARN_STRIDE-th pixel, with a depth strictly
#: between LEARN_DEPTH_M (m).
LEARN_STRIDE = 4
LEARN_DEPTH_M = (0.05, 6.0)
#: A person is looked for at this height above their floor point, m (the chest).
PERSON_LOOK_HEIGHT_M = 1.0
#: Detections farther than this (d_obj, m) are not fused: the segmenter is validated
#: within 8 m, and a depth read through to the background (a person "143 m" away, seen in
#: the hall) must not move an entity across the map.
MAX_RANGE_M = 8.0
#: A person observed within this of the robot's own footprint at capture is the robot
#: (its arm, or a leg, read as a person): nobody stands inside it, m (a person's radius).
SELF_MARGIN_M = 0.2


class PeopleTraceSink(Protocol):
    """Where each fused frame's person observations and camera go for replay
    (`people_trace.PeopleTrace`)."""

    def frame(
        self, stamp_ns: int, people: list[Observation], cam: PinholeCamera | None
    ) -> None: ...


@dataclass
class IngestReport:
    """What one frame did: fused detections, new ids, newly missing ids, learned cells,
    deleted false entries."""

    fused: int = 0
    ignored: int = 0
    new_ids: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    learned_cells: int = 0
    #: (id, reason) of the false entries deleted in this frame.
    dropped: list[tuple[str, str]] = field(default_factory=list)
    #: People moved far by one detection: (id, from xy, to xy, the detection's xy).
    jumps: list[tuple[str, FloatArray, FloatArray, FloatArray]] = field(default_factory=list)
    #: Far detections of standing people held for a second one: (id, the detection's xy).
    held: list[tuple[str, FloatArray]] = field(default_factory=list)
    #: People known by their colours where the map did not expect them: (id, from xy, to
    #: xy, colour distance).
    reidentified: list[tuple[str, FloatArray, FloatArray, float]] = field(default_factory=list)


def _mat(values: tuple[float, ...]) -> FloatArray:
    return np.asarray(values, dtype=float).reshape(4, 4)


def on_footprint(
    observations: list[Observation], T_world_base: FloatArray, margin_m: float
) -> list[bool]:
    """Whether each observation's place lies within `margin_m` of the robot's footprint
    (its rectangle with the arm stowed, in the base frame at capture)."""
    if not observations:
        return []
    x0, x1, y0, y1 = robot.FOOTPRINT_BOUNDS
    R, p = T_world_base[:2, :2], T_world_base[:2, 3]
    local = (np.array([o.xy for o in observations]) - p) @ R  # world → base, horizontal
    return [
        bool(x0 - margin_m <= x <= x1 + margin_m and y0 - margin_m <= y <= y1 + margin_m)
        for x, y in local
    ]


#: m: a take marks the nearest entry of its class this near where the jaw closed, and
#: the entry it was picked as this near (`SemanticMap.taken`).
TAKEN_M = 0.25
TAKEN_NAMED_M = 0.5
#: s: an entry seen later than this after a take is not marked by it.
TAKEN_GRACE_S = 2.0


class SemanticMap:
    """Artifacts, people and occupancy; see the module docstring."""

    def __init__(
        self, settings: SemanticMapSettings, occupancy: Occupancy, counters: dict[str, int]
    ) -> None:
        self.settings = settings
        self.ids = IdBook(counters)
        self.artifacts = ArtifactTracker(self.ids, settings)
        self.people = PeopleTracker(self.ids, settings)
        self.occupancy = occupancy
        self.stamp_ns = 0
        #: Where the static occupancy layer came from: world, file, slam or none.
        self.static_source: Literal["world", "file", "slam", "none"] = "none"
        #: The static layer changed since it was last written (the SLAM grid adopted).
        self.static_dirty = False
        #: The surfaces artifacts stand on, as last found in the tops layer (or kept from
        #: a database or file while the tops find none); `surfaces_dirty`: not yet written.
        self.surfaces: list[SupportSurface] = []
        self.surfaces_dirty = False
        #: The surfaces the map started with (a file's, a database's): kept where the
        #: tops this run builds show nothing of them yet (a run from a saved map looks
        #: at a few tables, and the others stay served).
        self.surfaces_before: list[SupportSurface] = []
        #: The place this is a map of (`Config.map_site`), kept with it and its files.
        self.site = ""
        self._dirty: dict[str, Track] = {}
        self._deleted: list[str] = []
        self._counters_dirty = False
        self.grid_dirty = False
        #: A person's id merged away → the id kept (one person whose track split): a
        #: request for the old id still finds them (`entity`). This run's only.
        self.aliases: dict[str, str] = {}
        #: Where the people tracker's input is written for replay (`people_trace`), or None.
        self.people_trace: PeopleTraceSink | None = None
        #: The takes applied (`taken`), by stamp and map id.
        self._takes: set[tuple[int, str]] = set()

    # -- contents ------------------------------------------------------------------------

    def forget_people_in_static(self) -> int:
        """A sensed static layer read back: the blobs of the people the map has made
        unknown (`Occupancy.forget_people`); how many cells."""
        if self.static_source not in ("slam", "file"):
            return 0
        people = np.array([t.xy for t in self.people.tracks], float).reshape(-1, 2)
        return self.occupancy.forget_people(people)

    def add(self, track: Track) -> None:
        """A known entity (prior, seed, database, import)."""
        (self.people if track.kind == "person" else self.artifacts).add(track)
        if track.id is not None:
            self._dirty[track.id] = track
        self._counters_dirty = True

    def clear(self) -> None:
        self.artifacts.tracks.clear()
        self.people.tracks.clear()
        self.ids.counters.clear()
        self._dirty.clear()
        self._deleted.clear()

    def entities(self, kind: EntityKind) -> list[MapEntity]:
        tracker = self.people if kind == "person" else self.artifacts
        return sorted((t.to_message() for t in tracker.confirmed), key=_id_order)

    def entity(self, kind: EntityKind, entity_id: str) -> MapEntity | None:
        """The entity of that id, or (a person) of the id it was merged into."""
        tracker = self.people if kind == "person" else self.artifacts
        tr = tracker.by_id(
            resolve_alias(self.aliases, entity_id) if kind == "person" else entity_id
        )
        return None if tr is None else tr.to_message()

    def tracks(self) -> list[Track]:
        return self.artifacts.confirmed + self.people.confirmed

    def grid(self) -> OccupancyGrid:
        occ = self.occupancy
        return OccupancyGrid(
            stamp_ns=self.stamp_ns,
            resolution_m=occ.resolution_m,
            origin_xy=occ.origin_xy,
            cells=to_wire(occ.cells()),
            static_source=self.static_source,
            learned_cells=int(occ.learned_mask().sum()),
        )

    def take_changes(self) -> tuple[list[Track], dict[str, int] | None]:
        """The confirmed tracks changed since the last call, and the counters if changed."""
        changed = [t for t in self._dirty.values() if t.id is not None]
        counters = dict(self.ids.counters) if self._counters_dirty else None
        self._dirty.clear()
        self._counters_dirty = False
        return changed, counters

    def take_deletions(self) -> list[str]:
        """The ids deleted since the last call (to remove from the database)."""
        deleted, self._deleted = self._deleted, []
        return deleted

    def is_false_entry(self, tr: Track) -> bool:
        """An entity the map made itself from too few detections, or only from afar, to
        be trusted missing."""
        least = self.settings.drop_below_observations  # 0: every entry is kept
        return tr.source == "perception" and least > 0 and (tr.hits < least or self._only_far(tr))

    def _only_far(self, tr: Track) -> bool:
        """An artifact the map saw only from beyond `class_near_m` (a seeded or imported
        one does not say how near it was seen, and is no false entry anyway)."""
        return tr.best_range_m is not None and tr.best_range_m > self.settings.class_near_m

    def find_surfaces(self) -> None:
        """The surfaces the tops layer shows now (kept as they were when it shows none)."""
        occ = self.occupancy
        found = surfaces_from_tops(occ.top_z, occ.top_n, occ.resolution_m, occ.origin_xy)
        found = with_kept(found, self.surfaces_before)
        if found and found != self.surfaces:
            self.surfaces = found
            self.surfaces_dirty = True
            log.info("surfaces now: %s", "; ".join(
                f"{s.id} at ({s.centre_xy[0]:.2f}, {s.centre_xy[1]:.2f}) "
                f"{2 * s.half_extents[0]:.2f} × {2 * s.half_extents[1]:.2f} m, "
                f"top {s.top_height:.2f} m" for s in found))  # fmt: skip

    # -- fusion --------------------------------------------------------------------------

    def observation(self, det: Detection, rgb: np.ndarray | None) -> Observation:
        p = self.settings
        sigma = measurement_sigma(det.d_obj, p.sigma0_m, p.sigma_per_m)
        axis = np.asarray(det.axis_in_world, float)
        centroid = np.asarray(det.centroid_in_world, float)
        xy = axis[:2] if np.all(np.isfinite(axis)) and axis.any() else centroid[:2]
        u0, v0, u1, v1 = det.bbox
        cut = rgb is not None and (u0 == 0 or v0 == 0 or u1 >= rgb.shape[1] or v1 >= rgb.shape[0])
        if det.class_name == "person":
            app = None
            if rgb is not None:
                mask = np.asarray(as_numpy(det.mask))
                app = colour_histogram(rgb, det.bbox, mask.astype(np.uint8))
            return Observation(
                "person", xy.copy(), 0.0, sigma, det.score, app, det.d_obj, whole=not cut
            )
        return Observation(
            det.class_name,
            xy.copy(),
            float(centroid[2]),
            sigma,
            det.score,
            range_m=det.d_obj,
            whole=not cut,
        )

    def _plausible(
        self, people: list[Observation], report: IngestReport, T_world_base: FloatArray
    ) -> list[Observation]:
        """The people observations not on a static obstacle and not on the robot itself
        (module docstring)."""
        inside = self._near_static(people, self.settings.person_obstacle_margin_m)
        on_robot = on_footprint(people, T_world_base, SELF_MARGIN_M)
        bad = [
            a or b or bool(self._doubt_person(o.xy))
            for a, b, o in zip(inside, on_robot, people, strict=True)
        ]
        report.ignored += sum(bad)
        return [o for o, b in zip(people, bad, strict=True) if not b]

    def _doubt_person(self, xy: FloatArray) -> str:
        """`evidence.person_doubt` on this map (the floor check on a sensed static layer)."""
        sensed = self.static_source in ("slam", "file")
        return person_doubt(xy, self.surfaces, self.occupancy if sensed else None)

    def _doubt_artifact(self, xy: FloatArray, z: float, t: int) -> str:
        """`evidence.artifact_doubt` (off every surface, over the floor only once the map
        knows surfaces), and off every surface and every obstacle beside a person seen
        lately, one the map would keep (`drop_below_observations` detections or more):
        hall seed 1 explored, a "person" of 4 wrist-camera detections at a table's edge
        deleted box_2 (off the table's explored top, which lay 0.4 m short of that edge)
        and was itself deleted as a false entry 14 s later; the box stayed lost. On the
        table's cells the box stands on the table whoever is beside it."""
        why = artifact_doubt(xy, z, self.surfaces, self.occupancy if self.surfaces else None)
        if why or not self.surfaces or surface_under(xy, self.surfaces) is not None:
            return why
        if on_obstacle(self.occupancy, xy):
            return ""  # on a table whose top the map has not seen (`evidence`)
        for tr in self.people.confirmed:
            if tr.hits < self.settings.drop_below_observations:
                continue  # a person of a few detections is no evidence against anything
            if t - tr.last_seen_ns <= PERSON_RECENT_NS and np.linalg.norm(tr.xy - xy) < (
                PERSON_REACH_M
            ):
                return f"on no surface, {np.linalg.norm(tr.xy - xy):.2f} m from {tr.id}"
        return ""

    def drop_doubtful(self) -> list[tuple[str, str]]:
        """Delete the entities the map made itself that its surfaces and floor now say
        cannot be (`evidence`): (id, reason)."""
        out: list[tuple[Track, str]] = []
        margin = self.settings.person_obstacle_margin_m
        made = [tr for tr in self.people.confirmed if tr.source == "perception"]
        near = self._near_static(made, margin)
        on_static = {id(tr) for tr, b in zip(made, near, strict=True) if b}
        for tr in [*self.artifacts.confirmed, *self.people.confirmed]:
            if tr.source != "perception":
                continue
            if id(tr) in on_static:
                why = f"within {margin:g} m of a static obstacle (its face, read as a person)"
            elif tr.kind == "person":
                why = self._doubt_person(tr.xy)
            else:
                why = self._doubt_artifact(tr.xy, tr.z, self.stamp_ns)
            if why:
                out.append((tr, f"not where a {tr.class_name} can be: {why}"))
        return self._delete(out)

    def _near_static(
        self, observations: Sequence[Observation | Track], margin_m: float
    ) -> list[bool]:
        """Whether each observation's (or track's) place is within `margin_m` of a static
        obstacle cell
        (furniture, walls: the static layer, not the learned one; of a lidar map, not the
        blobs people standing leave: `Occupancy.furniture`)."""
        if not observations:
            return []
        occ = self.occupancy
        near = occupied_near(
            occ.furniture,
            occ.resolution_m,
            occ.origin_xy,
            np.array([o.xy for o in observations]),
            margin_m,
        )
        return [bool(b) for b in near]

    def ingest(self, dets: Detections, frame: CameraFrame | None = None) -> IngestReport:
        """Fuse one camera frame's detections (`frame`: the same camera at the same stamp)."""
        report = IngestReport()
        t = dets.stamp_ns
        self.stamp_ns = max(self.stamp_ns, t)
        rgb = None if frame is None else np.asarray(as_numpy(frame.rgb))
        arts: list[Observation] = []
        people: list[Observation] = []
        for det in dets.detections:
            if (
                det.score < self.settings.min_score
                or not _mask_fits(det)
                or not 0.0 < det.d_obj <= MAX_RANGE_M
            ):
                report.ignored += 1
                continue
            obs = self.observation(det, rgb)
            (people if obs.class_name == "person" else arts).append(obs)
        people = self._plausible(
            merge_split_people(people, PERSON_MERGE_M), report, _mat(dets.T_world_base)
        )
        # A person's clothes are not artifacts: an artifact detection on a person is dropped,
        # unless it stands on a static obstacle (a table, a bench) where nobody stands.
        near = [
            o for o in arts if any(np.linalg.norm(o.xy - p.xy) < PERSON_MERGE_M for p in people)
        ]
        on_person = [
            o for o, sup in zip(near, self._near_static(near, 0.0), strict=True) if not sup
        ]
        if on_person:
            report.ignored += len(on_person)
            arts = [o for o in arts if all(o is not q for q in on_person)]
        kept = [o for o in arts if not self._doubt_artifact(o.xy, o.z, t)]
        report.ignored += len(arts) - len(kept)
        cam = None
        if frame is not None and not dets.reason:  # a frame perception did process
            cam = PinholeCamera(
                frame.fx,
                frame.fy,
                frame.cx,
                frame.cy,
                _mat(dets.T_world_base) @ _mat(frame.T_base_camera),
                np.asarray(as_numpy(frame.depth), np.float32),
            )
        self.fuse(t, kept, people, cam, report)
        if self.people_trace is not None:
            self.people_trace.frame(t, people, cam)
        if cam is not None:
            report.learned_cells = self._learn(dets, cam)
        return report

    def fuse(
        self,
        t: int,
        arts: list[Observation],
        people: list[Observation],
        cam: PinholeCamera | None,
        report: IngestReport | None = None,
    ) -> IngestReport:
        """Fuse one frame's observations (already filtered) stamped `t`, and count the
        looks of its camera (None: the frame had no image); what it did, into `report`.
        `ingest` calls it; a people trace's replay calls it with the traced people."""
        report = IngestReport() if report is None else report
        before = {id(tr) for tr in self.tracks()}
        changed_a, seen = self.artifacts.update(t, arts)
        changed_p = self.people.update(t, people)
        self.people.rejoin(t)
        splits = self.people.take_merged()
        report.jumps, report.held = self.people.take_jumps()
        report.reidentified = self.people.take_reidentified()
        for keep, gone, _ in splits:
            if keep.id is not None and gone.id is not None:
                self.aliases[gone.id] = keep.id
        report.dropped += self._delete(
            [(gone, f"the same person as {keep.id}: {why}") for keep, gone, why in splits]
        )
        changed_p += [k for k, _, _ in splits if all(k is not c for c in changed_p)]
        for tr in [*changed_a, *changed_p]:
            assert tr.id is not None
            self._dirty[tr.id] = tr
            if id(tr) not in before:
                report.new_ids.append(tr.id)
                self._counters_dirty = True
        report.fused = len(arts) + len(people)
        merged = [
            (lo, self._class_reason(lo, win))
            for lo, win in self.artifacts.class_conflicts(changed_a)
        ]
        if merged:
            report.dropped += self._delete(merged)
            seen = {i for i, tr in enumerate(self.artifacts.tracks) if tr.last_seen_ns == t}
        if cam is not None:
            report.missing, dropped = self._look(t, cam, seen)
            report.dropped += dropped
        return report

    def taken(self, takes: Sequence[Taken]) -> list[tuple[str, Taken]]:
        """Mark what the robot took missing (the module docstring); (id marked, take)
        for each entry marked, each take applied once."""
        marked: list[tuple[str, Taken]] = []
        for take in takes:
            if (take.stamp_ns, take.map_id) in self._takes:
                continue
            self._takes.add((take.stamp_ns, take.map_id))
            grace = take.stamp_ns + round(TAKEN_GRACE_S * 1e9)
            at = np.array(take.xy, float)
            near = [
                (float(np.linalg.norm(tr.xy - at)), tr) for tr in self.artifacts.tracks
                if tr.id is not None and tr.class_name == take.class_name
                and tr.missing_since_ns is None and tr.last_seen_ns <= grace
            ]  # fmt: skip
            hit = [tr for d, tr in sorted(near, key=lambda n: n[0])[:1] if d <= TAKEN_M]
            hit += [tr for d, tr in near if tr.id == take.map_id and d <= TAKEN_NAMED_M]
            for tr in hit:
                if tr.missing_since_ns is None and tr.id is not None:
                    tr.missing_since_ns = take.stamp_ns
                    self._dirty[tr.id] = tr
                    marked.append((tr.id, take))
        return marked

    def _look(
        self, t: int, cam: PinholeCamera, seen: set[int]
    ) -> tuple[list[str], list[tuple[str, str]]]:
        """Count a miss for each entity this frame looked at and did not see; after
        `missing_after_frames` of them an artifact is missing; a false entry is deleted.
        Returns the newly missing ids and the (id, reason) of the deleted ones."""
        p = self.settings
        newly: list[str] = []
        dropped: list[tuple[Track, str]] = []
        for i, tr in enumerate(self.artifacts.tracks):
            if tr.id is None or i in seen:
                continue
            if not self._missed(tr, cam, tr.z, p.look_range_m):
                continue
            if self.is_false_entry(tr):
                dropped.append((tr, self._false_entry_reason(tr)))
            elif tr.missing_since_ns is None:
                tr.missing_since_ns = t
                self._dirty[tr.id] = tr
                newly.append(tr.id)
        # People move: nobody looked for and not seen is missing (a walker out of view
        # is, `PeopleTracker.walked_off`); a false entry is deleted, and anyone else not
        # seen where the map has them counts the looks (`PeopleTracker.reidentify`).
        for tr in self.people.tracks:
            if tr.id is None or tr.last_seen_ns == t:
                continue
            missed = self._missed(tr, cam, PERSON_LOOK_HEIGHT_M, p.person_look_range_m)
            if missed and self.is_false_entry(tr):
                dropped.append((tr, self._false_entry_reason(tr)))
        return newly, self._delete(dropped)

    def _delete(self, entries: list[tuple[Track, str]]) -> list[tuple[str, str]]:
        """Forget these entities (and delete them from the database); (id, reason)."""
        out: list[tuple[str, str]] = []
        for tr, reason in entries:
            assert tr.id is not None
            (self.people if tr.kind == "person" else self.artifacts).drop(tr)
            self._dirty.pop(tr.id, None)
            self._deleted.append(tr.id)
            out.append((tr.id, reason))
        return out

    def _class_reason(self, loser: Track, winner: Track) -> str:
        if loser.class_name == winner.class_name:
            apart = float(np.linalg.norm(loser.xy - winner.xy))
            return (
                f"the same object as {winner.id}, {apart * 100:.0f} cm apart (seen "
                f"{winner.hits} and {loser.hits} time(s): one {loser.class_name} in pieces)"
            )
        return (
            f"the same object as {winner.id}, seen as a {winner.class_name} from within "
            f"{self.settings.class_near_m:g} m {winner.near_hits} time(s) and as a "
            f"{loser.class_name} {loser.near_hits} time(s)"
        )

    def _missed(self, tr: Track, cam: PinholeCamera, z: float, range_m: float) -> bool:
        """Count a miss if this frame looked at the entity's place (at height z); whether
        it has now been missed `missing_after_frames` times in a row."""
        if not looks_at(cam, np.array([tr.xy[0], tr.xy[1], z]), range_m):
            return False
        tr.misses += 1
        return tr.misses >= self.settings.missing_after_frames

    def _false_entry_reason(self, tr: Track) -> str:
        p = self.settings
        if tr.hits < p.drop_below_observations:
            made = f"made from {tr.hits} detection(s) (fewer than {p.drop_below_observations})"
        else:
            made = (f"seen {tr.hits} times, only from beyond {p.class_near_m:g} m (nearest "
                    f"{tr.best_range_m:.1f} m)")  # fmt: skip
        return f"a false entry: {made}, then not seen in {tr.misses} looks at its place"

    def _learn(self, dets: Detections, cam: PinholeCamera) -> int:
        """Obstacles seen in this frame's depth, leaving out people and the robot."""
        shape = cam.depth_image().shape
        exclude = np.zeros(shape, bool)
        for det in dets.detections:
            if det.class_name == "person" and _mask_fits(det, shape):
                u0, v0, u1, v1 = det.bbox
                exclude[v0:v1, u0:u1] |= np.asarray(as_numpy(det.mask)) > 0
        pts = cam.points_world(
            stride=LEARN_STRIDE,
            mask=~exclude,
            min_depth_m=LEARN_DEPTH_M[0],
            max_depth_m=LEARN_DEPTH_M[1],
        )
        base = _mat(dets.T_world_base)[:2, 3]
        pts = pts[np.linalg.norm(pts[:, :2] - base, axis=1) > SELF_RADIUS_M]
        learned = self.occupancy.integrate(pts, lambda p: sees_over(cam, p))
        self.grid_dirty = True
        return learned


def _mask_fits(det: Detection, image: tuple[int, ...] | None = None) -> bool:
    """The mask is the bbox's crop (and the bbox inside the image, when its size is given)."""
    u0, v0, u1, v1 = det.bbox
    if det.mask.shape != (v1 - v0, u1 - u0) or u1 <= u0 or v1 <= v0 or u0 < 0 or v0 < 0:
        return False
    return image is None or (v1 <= image[0] and u1 <= image[1])


def resolve_alias(aliases: dict[str, str], entity_id: str) -> str:
    """The id `entity_id` was merged into, through every later merge (itself when none)."""
    seen = {entity_id}
    while entity_id in aliases and aliases[entity_id] not in seen:
        entity_id = aliases[entity_id]
        seen.add(entity_id)
    return entity_id


def _id_order(e: MapEntity) -> tuple[str, int]:
    cls, _, n = e.id.rpartition("_")
    return cls, int(n)
