"""Artifacts: association by class and a gated distance, a per-entity Kalman mean.

An artifact does not move, so its estimate is a static Kalman filter on the horizontal
position: each detection with noise σ(range) pulls the mean by K = P (P + R)⁻¹ and
shrinks P; a view cut by the image's border counts with `CUT_SIGMA_GAIN` × its σ (its
mask's centroid is a part's). The nearest views decide where it is, as a person trusts
their closest look: the errors of far views are not independent (the head camera sees
a table's objects from 3-5 m hundreds of times while exploring, each the front face at
the same angle), so however many they are they must not outweigh a few near ones. Only
views within `NEAR_BAND_M` of the nearest one fused so far move the estimate, and a view
nearer than that band restarts it from itself (`Track.best_range_m`, stored with it; a
seeded or imported artifact, which does not know, fuses its first view as it comes).

One object in pieces: an occluder or a depth cut splits a bottle's mask into its upper and
lower parts, two detections of one class at one place in one frame. Detections of one
class within `class_merge_m` of each other in a frame (closer than two real objects'
centres can be: the thinnest two touching stand 4 cm apart) are one: the higher score's
is kept (`pieces`). Otherwise the second piece starts an artifact of its own beside the
first (hall seed 4: bottle_1 and bottle_7 5 cm apart, their heights 4 cm apart), and two
artifacts of one class within `class_merge_m` are one object too (`class_conflicts`: the
one with more near views, then more views, keeps it).

One frame's detections are matched to the artifacts of their class greedily by distance,
each artifact taking at most one detection, inside a gate of max(gate_min, gate_sigmas ×
√(σ_track² + σ_meas²)). A detection that matches nothing starts a tentative track; the
second hit gives it the next `<class>_<n>`. Tentative tracks not seen again within
`TENTATIVE_TTL_NS` are dropped (a one-frame false positive never gets an id). An artifact
moved elsewhere shows up as a new artifact while the old one is found missing at its
place (`missing`); a false entry the map made itself, from a few detections, is dropped
instead (`drop`; the rule is the map's, see `mapper`).

One object under two classes: the network may call a can on a bench a box from 3 m and a
can from 1.5 m, which makes two artifacts at one place (their axis points within
`class_merge_m`, closer than two real objects' centres can be; within `class_merge_far_m`
when one of them was never seen whole from near: far views sit 10-16 cm off, and such a
ghost stands behind the real object's face, where the missing test cannot see it
missing). `class_conflicts()`
pairs such perception-made artifacts as (loser, winner): the class seen more often whole
(its mask off the image border) from within `class_near_m` (where the network tells the
classes apart) wins, then the one with more detections; two seen from near fewer than
`confirm_hits` times are left alone. A tentative track that would give way to a confirmed
artifact this way gets no id (it stays tentative while seen, and takes an id once its
class has the better evidence).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from common.config import SemanticMapSettings
from services.semantic_map.entities import IdBook, Observation, Track

#: Not settings (those are `SemanticMapSettings`: `gate_min_m`, `gate_sigmas`,
#: `confirm_hits`, `class_near_m`, `class_merge_m`): how long a tentative track lives
#: unseen, ns.
TENTATIVE_TTL_NS = 3_000_000_000
#: A view moves an artifact's estimate while its range is within this of the nearest
#: view's, m; a view nearer by more restarts the estimate (the module docstring).
NEAR_BAND_M = 1.0
#: A view cut by the image's border: its σ times this.
CUT_SIGMA_GAIN = 2.0


class ArtifactTracker:
    """Every artifact; `update(stamp, observations)` fuses one frame's detections."""

    def __init__(self, ids: IdBook, settings: SemanticMapSettings) -> None:
        self.ids = ids
        self.settings = settings
        self.tracks: list[Track] = []

    @property
    def confirmed(self) -> list[Track]:
        return [t for t in self.tracks if t.confirmed]

    def by_id(self, entity_id: str) -> Track | None:
        return next((t for t in self.tracks if t.id == entity_id), None)

    def add(self, track: Track) -> None:
        """A known artifact (from a prior, a seed, the database)."""
        if track.id is not None:
            self.ids.reserve(track.id)
        self.tracks.append(track)

    def drop(self, track: Track) -> None:
        """Forget an artifact (a false entry); its id is never given again."""
        self.tracks = [t for t in self.tracks if t is not track]

    def gate(self, track: Track, obs: Observation) -> float:
        spread = np.sqrt(track.sigma_m**2 + obs.sigma_m**2)
        return max(self.settings.gate_min_m, self.settings.gate_sigmas * float(spread))

    def update(
        self, stamp_ns: int, observations: list[Observation]
    ) -> tuple[list[Track], set[int]]:
        """Fuse one frame. Returns the tracks changed (confirmed ones, to store) and the
        indices (into `self.tracks`, after the update) of the tracks seen in this frame."""
        observations = pieces(observations, self.settings.class_merge_m)
        pairs: list[tuple[float, int, int]] = []
        for j, obs in enumerate(observations):
            for i, tr in enumerate(self.tracks):
                if tr.class_name != obs.class_name:
                    continue
                d = float(np.linalg.norm(tr.xy - obs.xy))
                if d <= self.gate(tr, obs):
                    pairs.append((d, i, j))
        pairs.sort()
        used_t: set[int] = set()
        used_o: set[int] = set()
        changed: list[Track] = []
        for _d, i, j in pairs:
            if i in used_t or j in used_o:
                continue
            used_t.add(i)
            used_o.add(j)
            tr = self.tracks[i]
            self._fuse(tr, observations[j], stamp_ns)
            if not tr.confirmed and tr.hits >= self.settings.confirm_hits:
                self._confirm(tr)
            if tr.confirmed:
                changed.append(tr)
        for j, obs in enumerate(observations):
            if j in used_o:
                continue
            tr = Track(
                class_name=obs.class_name,
                kind="artifact",
                xy=obs.xy.astype(float).copy(),
                cov=np.eye(2) * self._sigma(obs) ** 2,
                z=obs.z,
                source="perception",
                last_seen_ns=stamp_ns,
                first_seen_ns=stamp_ns,
                hits=1,
                near_hits=int(self._near(obs)),
                best_range_m=obs.range_m,
            )
            if self.settings.confirm_hits <= 1:
                self._confirm(tr)
                if tr.confirmed:
                    changed.append(tr)
            self.tracks.append(tr)
            used_t.add(len(self.tracks) - 1)
        self._expire(stamp_ns)
        seen = {i for i, t in enumerate(self.tracks) if t.last_seen_ns == stamp_ns}
        return changed, seen

    @staticmethod
    def _sigma(obs: Observation) -> float:
        return obs.sigma_m * (1.0 if obs.whole else CUT_SIGMA_GAIN)

    def _fuse(self, tr: Track, obs: Observation, stamp_ns: int) -> None:
        R = np.eye(2) * self._sigma(obs) ** 2
        best, r = tr.best_range_m, obs.range_m
        if best is not None and r < best - NEAR_BAND_M:  # much nearer: start from it
            tr.xy, tr.cov, tr.z = obs.xy.astype(float).copy(), R, obs.z
            tr.best_range_m = r
        elif best is None or r <= best + NEAR_BAND_M:
            K = tr.cov @ np.linalg.inv(tr.cov + R)
            tr.xy = tr.xy + K @ (obs.xy - tr.xy)
            tr.cov = (np.eye(2) - K) @ tr.cov
            tr.z += (obs.z - tr.z) / (tr.hits + 1)  # the height: a plain running mean
            tr.best_range_m = r if best is None else min(best, r)
        tr.hits += 1
        tr.near_hits += int(self._near(obs))
        tr.last_seen_ns = stamp_ns
        tr.misses = 0
        tr.missing_since_ns = None

    def _near(self, obs: Observation) -> bool:
        """A detection whose class counts: whole in its image and within `class_near_m`."""
        return obs.near(self.settings.class_near_m)

    def class_conflicts(self, fused: Sequence[Track] | None = None) -> list[tuple[Track, Track]]:
        """(loser, winner) for each perception-made artifact that is another class's
        artifact at the same place (see the module docstring); each loser once. Only pairs
        with an artifact in `fused` (the ones this frame updated; None: every artifact) are
        checked: only a fusion moves an artifact or adds to its evidence."""
        confirmed = [t for t in self.tracks if t.confirmed]
        order = {id(t): i for i, t in enumerate(confirmed)}
        out: list[tuple[Track, Track]] = []
        losers: set[int] = set()
        for a in confirmed if fused is None else [t for t in fused if id(t) in order]:
            for b in confirmed:
                if b is a or id(a) in losers or id(b) in losers:
                    continue
                old, new = (a, b) if order[id(a)] < order[id(b)] else (b, a)
                loser = self._loser(new, old)
                if loser is not None:
                    losers.add(id(loser))
                    out.append((loser, old if loser is new else new))
        return out

    def _loser(self, new: Track, old: Track) -> Track | None:
        """Of two perception-made artifacts at one place, the one that gives way (fewer
        near views, then fewer views; a tie goes against `new`); None when they are not
        one object: further apart than `class_merge_m` (of one class: one object in
        pieces), or of two classes and neither seen from near `confirm_hits` times, or
        further apart than their limit (the module docstring)."""
        p = self.settings
        if new.source != "perception" or new.source != old.source:
            return None
        limit = p.class_merge_m
        if new.class_name != old.class_name:
            if max(new.near_hits, old.near_hits) < p.confirm_hits:
                return None
            if min(new.near_hits, old.near_hits) == 0:  # one never seen whole from near
                limit = max(p.class_merge_m, p.class_merge_far_m)
        if math.hypot(new.xy[0] - old.xy[0], new.xy[1] - old.xy[1]) > limit:
            return None
        return new if (new.near_hits, new.hits) <= (old.near_hits, old.hits) else old

    def _confirm(self, tr: Track) -> None:
        """Give a tentative track its id, unless another class's artifact at its place
        outclasses it (it stays tentative: no id is spent on a class that gives way)."""
        if any(self._loser(tr, o) is tr for o in self.tracks if o.confirmed):
            return
        tr.id = self.ids.next_id(tr.class_name)

    def _expire(self, stamp_ns: int) -> None:
        ttl = TENTATIVE_TTL_NS
        self.tracks = [t for t in self.tracks if t.confirmed or stamp_ns - t.last_seen_ns <= ttl]


def pieces(observations: list[Observation], within_m: float) -> list[Observation]:
    """One frame's detections with the pieces of one object made one: of those of a class
    within `within_m` of each other, the one with the higher score (the first on a tie)."""
    kept: list[Observation] = []
    for obs in sorted(observations, key=lambda o: -o.score):
        if not any(
            k.class_name == obs.class_name and float(np.linalg.norm(k.xy - obs.xy)) <= within_m
            for k in kept
        ):
            kept.append(obs)
    keep = {id(k) for k in kept}
    return [o for o in observations if id(o) in keep]
