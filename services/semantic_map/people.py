"""People: a constant-velocity Kalman filter per person and an appearance cue, so ids
survive walking, passing each other and short occlusions.

Each frame every person is predicted to the frame's stamp (state x, y, vx, vy; white
acceleration noise σ_a). A person missed in a frame is extrapolated only along a
velocity the filter was sure of at the last sighting (vᵀ Σv⁻¹ v ≥ χ²₂ 95 %: a walker
tracked for a second at a walking pace); an unsure velocity (a person of a few
detections, or one standing still, whose jitter reads as motion) is taken as zero, its
covariance kept, so nobody drifts along a velocity that is noise. A person unseen for
`COAST_NS` stops being extrapolated at all: the velocity is reset to zero with a
covariance of (V_MAX)², so the position's uncertainty then grows like a walker's reach
instead of drifting along an old heading. Detections are assigned to people by the
Hungarian method on a cost that adds the Mahalanobis distance of the innovation (gated
at χ²₂ 99.9 %, or within `GATE_MIN_M`; never beyond `MAX_GATE_M`), the likelihood's
spread (½ ln |S| over the detection's own: a person the map is unsure of, long unseen,
takes a detection only where nobody better placed is expected; the Mahalanobis distance
alone let a stale wide track take a walker's detections from the walker's own track)
and the Bhattacharyya distance of the colour histograms: two people crossing are told
apart by their clothes where their positions are ambiguous. A detection in clothes that
are clearly another known person's (`clothes_owner`: within `REID_APPEARANCE` of theirs
and `REID_MARGIN` nearer than anybody else's) is never matched to a confirmed person
with other colours, however near: two people crossing where the camera sees only the
nearer (the hall's shift: the requested person's id went over to a passer-by in the
frame the two met, followed them for 50 s, and the robot handed the box to the passer),
unless such detections stand still within `GATE_MIN_M` of that person for
`DOUBT_NS` (`_colours_lie`): a passer-by walks on, and one who stands where the person
stands is the person, the colours seen from here misleading (hall seed 1: two people in
one red shirt; the near view of one showed the shirt and little else, the other's
colours from afar, and the person handed over to went unseen for 15 s in front of the
robot's camera while it looked round for them).
The colours veto a match (beyond `MAX_APPEARANCE`) when the detection is not where the
person is expected (outside χ²₂ 95 %), or when the person is unseen for `VETO_STALE_NS`
and the detection lies beyond `GATE_MIN_M` of where they were (a stale place says
little: the σ of a long-unseen person spans the gate, and in the hall's shift walkers
passing within a metre of it took the id of whoever had stood there): a person standing
where they were, seen from behind or under another light, is still them (the small-world
patrol gave one standing person four ids when the colours vetoed). A detection left over
starts a tentative person, who gets the next `person_<n>` at `confirm_hits` detections,
unless it lies within `MIN_SEPARATION_M` of a person (then it is a piece of that body,
e.g. legs whose colours did not match the shirt).

A person's facing (`yaw`: a seeded map's, where they stood facing) is forgotten (0,
unknown) once they are seen walking: navigation puts a handover pose in front of a known
facing, else on the robot's side (seed 0's shift: the worker who came to the robot's
ask was walked round, a 4.2 m path, to the front their seed had faced).

A person standing still (no sure velocity) is not moved by one detection far from them
(beyond `GATE_MIN_M`): it is held, and the person moves there only when a second
detection within `GATE_MIN_M` of it comes within `LEAP_CONFIRM_NS`; a detection near
where they are forgets it. One stray reading does not drag a person across the floor
(hall seed 14: a seeded person_5, never seen yet, went 1.0 m and then 1.1 m on two single
head-camera detections of nobody while the robot turned from the table; the real
person_5 became person_6 where they stood, and the handover went to the empty spot).
A person who walked off unseen is detected there again and again, and moves one frame
later than before. One who walked off farther than the gate (`MAX_GATE_M`) is somebody
new to the filter; when the new person is confirmed, their colours are compared with
the people not seen since they appeared (and not for `REID_UNSEEN_NS`), whose place the
robot looked at without seeing them (`missing_after_frames` looks, counted by the map):
within
`REID_APPEARANCE` of one, and clearly nearer to that one than to any other
(`REID_MARGIN`), they are that person, come back (`reidentify`): the known id moves to
the new place instead of a new id being made. A person unseen for `REID_STALE_NS` may be
anywhere in the hall, looked for there or not (a walker on their round, a person of a
saved map not seen yet this run): a newcomer seen walking (`Track.walked`: a body, not
furniture the network read as a person) whose clothes are theirs, and nearer to theirs
than to anybody else's the map has, is them. A person who was walking when last seen
(`Track.moving`: a walker on their round has left the place, looked at or not) and is
unseen for `WALKED_OFF_NS` may be anywhere within walking reach of it (`V_MAX` of the
time unseen, plus `MAX_GATE_M`): a newcomer there in their clothes, nearer to theirs
than to anybody else's, is them (`_walked_off`; hall seed 0's shift: each walker's id
was renewed at each return, 5-12 ids a person, IDF1 0.27-0.38 on three traces, 0.35-0.42
with the rule; under 5 s a second walker in like clothes on the same route may follow
the first). Nobody is known by their clothes while a person the map was given without
colours (a seed not seen yet) could be them: nothing says the newcomer is not that one
(`_only_them`; hall seed 1's shift, four seeded people, three alike: a walker's id went
to another 49 s in). People's colours are kept in the map file (`MapFile.appearances`),
so a map saved after an exploration knows them.

A track still splits now and then: while the robot walks round a standing person their
visible surface and the depth behind it move, a detection falls outside the gate, and a
second id grows beside the first (the explored hall: three people with two ids each, 8 cm
to 1.4 m apart). Two people never in one frame together (`Track.seen_with`) are merged
back into one (`merge_splits`) when they are closer than `BODY_M` and both seen within
`BODY_RECENT_NS` (two bodies do not overlap), or closer than `BODY_M` to where the other
was last seen in their clothes (within `REID_APPEARANCE`: nobody stands at a stale place
now, so the place alone proves nothing), or, neither of them ever seen walking, closer
than `SPLIT_M` with like colours, both seen within `SPLIT_RECENT_NS` (the detections
alternate between them). Walkers on their routes pass each other's places all the time:
in the hall's shift (`dume bench people-ids`) all three split merges of walkers joined
two people, and one body merge with a place 22 s stale did. The id kept is the one seen
more often from near (`SemanticMapSettings.class_near_m`), a person the map was given (a
prior, a seed) before one it made; the other's id is deleted. The place is the two
moment-matched, its covariance spanning both, so the next detection at either place
joins it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from common.appearance import bhattacharyya, blend
from common.config import SemanticMapSettings
from common.geometry import FloatArray
from services.semantic_map.entities import IdBook, Observation, Track

CHI2_2D_999 = 13.82
CHI2_2D_95 = 5.99
_BIG = 1e6


#: Not settings (those are `SemanticMapSettings`: `person_accel_sigma`, `appearance_weight`,
#: `confirm_hits`): the colour distance beyond which appearance vetoes a match away from
#: where the person is expected; the gate's floor, m; how long a tentative person lives
#: unseen and how long an unseen person is extrapolated, ns; a walker's top speed, m/s.
MAX_APPEARANCE = 0.6
GATE_MIN_M = 0.4
TENTATIVE_TTL_NS = 2_000_000_000
COAST_NS = 2_000_000_000
V_MAX = 1.5
#: The position's σ never grows past this, m: a person long unseen is gated within
#: about 3.7 m of where they were last seen, so a stray detection far away (a false
#: positive) never drags them across the hall; one back after a long walk unseen gets
#: a new id instead.
MAX_SIGMA_M = 1.0
#: Never farther than this from where a person is predicted, m, whatever the σ: a
#: seeded or prior person has no colours yet, and a table or pallet the segmenter
#: read as a person 1.6-2.6 m away once pulled one 3.7 m off in a hall eval. A
#: walker's prediction carries their velocity, so the innovation stays small.
MAX_GATE_M = 1.2
#: A detection left over this close to a person is a piece of them, never a new
#: person (two bodies do not overlap), m.
MIN_SEPARATION_M = 0.35
#: A person moved farther than this by one detection is said in the log, m.
JUMP_M = 0.4
#: A standing person's far detection waits this long for a second one there, ns.
LEAP_CONFIRM_NS = 1_500_000_000
#: Two people never seen together this close are one body, m (a person is 0.4-0.5 m across).
BODY_M = 0.5
#: Two people never seen together, alike in colours and both seen lately this close are one
#: person whose track split, m (the explored hall's farthest split: 1.36 m).
SPLIT_M = 1.5
SPLIT_RECENT_NS = 10_000_000_000
#: Two tracks overlapping are one body when both were seen this lately, ns.
BODY_RECENT_NS = 2_000_000_000
#: Re-identification: a new person whose colours lie within `REID_APPEARANCE` of a
#: known person's, and nearer by `REID_MARGIN` than anyone else's, who has not been seen
#: since the new one first was (two bodies seen in turn, not together), not for
#: `REID_UNSEEN_NS`, and not where the map has them when the robot looked there, is that
#: person, come back where the map did not expect them. 0.35 before: on the people traces
#: of two shifts (hall seeds 0 and 1, `dume bench people-ids`) 0.30 halved the wrong
#: identity decisions (10 to 5) for 2 right ones of 28 lost; one of the wrong ones, at
#: 0.33, handed seed 0's bottle to another person.
REID_APPEARANCE = 0.30
REID_MARGIN = 0.15
REID_UNSEEN_NS = 3_000_000_000
#: The colour distance a detection is taken to be from a person whose colours the map
#: does not know yet (a seed not seen this run), not 0: at 0 a colourless seed outbid
#: the person the detection was of, standing on it (hall seed 8's shift: person_2's
#: detections 0.01 m from them, 0.19 off their colours, cost 0.81 for them and 0.40 for
#: a stale person_3 1.05 m off; person_3 jumped onto them, was merged with them as one
#: body, and the box asked for person_3 went to person_2; seed 9's the same with
#: person_3 and person_2, 1.07 m). Replayed (`dume bench people-ids`, hall seeds 5-9):
#: neither jump, IDF1 0.574/0.598/0.514/0.384/0.313 → 0.572/0.598/0.515/0.449/0.359,
#: wrong identity decisions 4 → 3 (0.1: 0.572/0.598/0.555/0.360/0.332, 3).
UNKNOWN_APPEARANCE = 0.2
#: A person unseen this long may be anywhere in the hall (1.5 m/s for a minute): one
#: known again by their clothes alone, without the map having looked at their place, ns.
REID_STALE_NS = 60_000_000_000
#: A walker unseen this long may be anywhere within walking reach (`_walked_off`); before
#: it, a second walker in like clothes on the same route may be following the first; and
#: they are missing from their last place (`walked_off`), ns.
WALKED_OFF_NS = 5_000_000_000
#: A person unseen this long is matched away from their place only in their clothes, ns.
VETO_STALE_NS = 2_000_000_000
#: Detections in clearly another's clothes that stand within `STILL_M` of where they
#: were for this long, within `GATE_MIN_M` of a person, are that person after all, ns.
DOUBT_NS = 1_000_000_000
STILL_M = 0.15
#: A gap this long between such detections starts the count again, ns.
DOUBT_GAP_NS = 500_000_000


def merge_split_people(observations: list[Observation], radius_m: float) -> list[Observation]:
    """One observation per person: detections of one frame closer than `radius_m` are
    pieces of one body the segmenter split (a person is about 0.5 m across), merged into
    the best-scored one at their mean position, its range kept and counted cut (its
    colours are of a piece of them)."""
    out: list[Observation] = []
    left = sorted(observations, key=lambda o: -o.score)
    while left:
        best, rest = left[0], left[1:]
        near = [o for o in rest if float(np.linalg.norm(o.xy - best.xy)) < radius_m]
        left = [o for o in rest if float(np.linalg.norm(o.xy - best.xy)) >= radius_m]
        if near:
            xy = np.mean([best.xy, *(o.xy for o in near)], axis=0)
            best = replace(best, xy=xy, whole=False)
        out.append(best)
    return out


def _rank(tr: Track) -> tuple[bool, int, int]:
    """Which of two tracks of one person to keep: given before made, then more near views."""
    return (tr.source != "perception", tr.near_hits, tr.hits)


def sure_velocity(tr: Track) -> bool:
    """Whether the track's velocity differs from standing still beyond its own
    uncertainty (χ²₂ 95 %)."""
    v = tr.velocity
    if not v.any():
        return False
    return float(v @ np.linalg.solve(tr.vel_cov, v)) >= CHI2_2D_95


def _F(dt: float) -> FloatArray:
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


def _Q(dt: float, sigma_a: float) -> FloatArray:
    q = sigma_a**2
    a, b, c = dt**4 / 4.0, dt**3 / 2.0, dt**2
    return q * np.array([[a, 0, b, 0], [0, a, 0, b], [b, 0, c, 0], [0, b, 0, c]])


class PeopleTracker:
    """Every person; `update(stamp, observations)` predicts, associates and fuses."""

    def __init__(self, ids: IdBook, settings: SemanticMapSettings) -> None:
        self.ids = ids
        self.settings = settings
        self.tracks: list[Track] = []
        self.merged: list[tuple[Track, Track, str]] = []
        #: People moved more than `JUMP_M` by one detection since the last `take_jumps`:
        #: (id, from xy, to xy, the detection's xy), for the log.
        self.jumps: list[tuple[str, FloatArray, FloatArray, FloatArray]] = []
        #: A standing person's far detection held for a second one (id → (xy, stamp)).
        self.leaps: dict[str, tuple[FloatArray, int]] = {}
        #: Far detections held since the last `take_jumps` (id, the detection's xy), for
        #: the log.
        self.held: list[tuple[str, FloatArray]] = []
        #: People re-identified since the last `take_reidentified` (`reidentify`).
        self.reidentified: list[tuple[str, FloatArray, FloatArray, float]] = []

    @property
    def confirmed(self) -> list[Track]:
        return [t for t in self.tracks if t.confirmed]

    def by_id(self, entity_id: str) -> Track | None:
        return next((t for t in self.tracks if t.id == entity_id), None)

    def drop(self, track: Track) -> None:
        """Forget a person (a false entry); the id is never given again."""
        self.tracks = [t for t in self.tracks if t is not track]

    def add(self, track: Track, stamp_ns: int = 0) -> None:
        """A known person (from a prior, a seed, the database)."""
        if track.id is not None:
            self.ids.reserve(track.id)
        self._init_P(track)
        self.tracks.append(track)
        track.stamp_ns = max(stamp_ns, track.last_seen_ns, track.stamp_ns)

    @staticmethod
    def _init_P(tr: Track) -> None:
        if tr.P is None:
            tr.P = np.zeros((4, 4))
            tr.P[:2, :2] = tr.cov
            tr.P[2:, 2:] = tr.vel_cov

    def predict(self, stamp_ns: int) -> None:
        s = self.settings
        for tr in self.tracks:
            last = tr.stamp_ns
            if stamp_ns <= last:
                continue
            assert tr.P is not None
            if tr.last_seen_ns and stamp_ns - tr.last_seen_ns > COAST_NS and tr.velocity.any():
                tr.velocity = np.zeros(2)
                tr.P[2:, :] = 0.0
                tr.P[:, 2:] = 0.0
                tr.P[2:, 2:] = np.eye(2) * V_MAX**2
            elif last > tr.last_seen_ns and not tr.moving and tr.velocity.any():
                tr.velocity = np.zeros(2)  # missed, and the velocity was not sure
            dt = (stamp_ns - last) * 1e-9
            x = np.concatenate([tr.xy, tr.velocity])
            F = _F(dt)
            x = F @ x
            P = F @ tr.P @ F.T + _Q(dt, s.person_accel_sigma)
            cap = MAX_SIGMA_M**2
            if P[0, 0] > cap or P[1, 1] > cap:
                # Long unseen: somewhere within the capped σ, at an unknown walking
                # velocity, the two uncorrelated. Scaling the position block alone left
                # the velocity's variance in the hundreds and the cross terms stale, and
                # the next detection then flung the velocity (and the person) away.
                P[:2, :2] *= cap / max(P[0, 0], P[1, 1])
                P[:2, 2:] = P[2:, :2] = 0.0
                P[2:, 2:] = np.eye(2) * V_MAX**2
            self._set(tr, x, P)
            tr.stamp_ns = stamp_ns

    def walked_off(self, stamp_ns: int) -> list[Track]:
        """Mark missing (`missing_since_ns`, now) each confirmed person who was walking
        when last seen (`Track.moving`) and is unseen for `WALKED_OFF_NS`: where they
        are is not known, and their last place is not where they stand (navigation
        leaves missing people out of its rules). Seen again, they are not missing."""
        out = []
        for tr in self.confirmed:
            gone = tr.moving and tr.last_seen_ns and stamp_ns - tr.last_seen_ns >= WALKED_OFF_NS
            if tr.missing_since_ns is None and gone:
                tr.missing_since_ns = stamp_ns
                out.append(tr)
        return out

    @staticmethod
    def _set(tr: Track, x: FloatArray, P: FloatArray) -> None:
        tr.xy, tr.velocity = x[:2].copy(), x[2:].copy()
        tr.P = 0.5 * (P + P.T)
        tr.cov = tr.P[:2, :2].copy()
        tr.vel_cov = tr.P[2:, 2:].copy()

    def cost(self, tr: Track, obs: Observation, owner: Track | None = None) -> float:
        """Association cost, or `_BIG` outside the gates; `owner`: the person whose
        clothes the detection's are, clearly (`clothes_owner`), if anybody's."""
        s = self.settings
        assert tr.P is not None
        S = tr.P[:2, :2] + np.eye(2) * obs.sigma_m**2
        nu = obs.xy - tr.xy
        d2 = float(nu @ np.linalg.solve(S, nu))
        dist = float(np.linalg.norm(nu))
        if dist > MAX_GATE_M or (d2 > CHI2_2D_999 and dist > GATE_MIN_M):
            return _BIG
        if owner is not None and owner is not tr and tr.confirmed and tr.appearance is not None:
            return _BIG  # in somebody else's clothes, clearly: not this person
        app = UNKNOWN_APPEARANCE if obs.appearance is not None else 0.0
        if tr.appearance is not None and obs.appearance is not None:
            app = bhattacharyya(tr.appearance, obs.appearance)
            stale = not tr.last_seen_ns or tr.stamp_ns - tr.last_seen_ns > VETO_STALE_NS
            if app > MAX_APPEARANCE and (d2 > CHI2_2D_95 or (stale and dist > GATE_MIN_M)):
                return _BIG  # unlike, and not where they are expected: somebody else
        # The likelihood's spread (ln |S| over the detection's own): a person the map is
        # unsure of takes a detection only where nobody better placed is expected.
        spread = 0.5 * math.log(max(float(np.linalg.det(S)), 1e-12) / max(obs.sigma_m, 1e-3) ** 4)
        return (min(d2, CHI2_2D_999) + max(spread, 0.0)) / CHI2_2D_999 + s.appearance_weight * app

    def update(self, stamp_ns: int, observations: list[Observation]) -> list[Track]:
        """Fuse one frame's person detections; the confirmed people updated (and those
        who walked off out of view, `walked_off`)."""
        self.predict(stamp_ns)
        changed: list[Track] = self.walked_off(stamp_ns)
        confirmed_now: list[Track] = []
        used: set[int] = set()
        if self.tracks and observations:
            owners = [self.clothes_owner(o) for o in observations]
            lie = [self._colours_lie(t, observations, owners, stamp_ns) for t in self.tracks]
            C = np.array(
                [[self.cost(t, o, None if liar else w)
                  for o, w in zip(observations, owners, strict=True)]
                 for t, liar in zip(self.tracks, lie, strict=True)]
            )  # fmt: skip
            rows, cols = linear_sum_assignment(C)
            for i, j in zip(rows, cols, strict=True):
                if C[i, j] >= _BIG:
                    continue
                tr = self.tracks[i]
                if self._leap_held(tr, observations[j], stamp_ns):
                    used.add(int(j))  # held: neither fused nor somebody new
                    continue
                was = tr.xy.copy()
                self._fuse(tr, observations[j], stamp_ns)
                if tr.id is not None and float(np.linalg.norm(tr.xy - was)) > JUMP_M:
                    self.jumps.append((tr.id, was, tr.xy.copy(), observations[j].xy.copy()))
                used.add(int(j))
                if not tr.confirmed and tr.hits >= self.settings.confirm_hits:
                    confirmed_now.append(tr)
                elif tr.confirmed:
                    changed.append(tr)
        for tr in confirmed_now:
            back = self.reidentify(tr, stamp_ns)
            if back is None:
                tr.id = self.ids.next_id("person")
            changed.append(tr if back is None else back)
        sep = MIN_SEPARATION_M
        for j, obs in enumerate(observations):
            if j in used or any(float(np.linalg.norm(t.xy - obs.xy)) < sep for t in self.tracks):
                continue
            tr = Track(
                class_name="person",
                kind="person",
                xy=obs.xy.astype(float).copy(),
                cov=np.eye(2) * obs.sigma_m**2,
                z=0.0,
                source="perception",
                last_seen_ns=stamp_ns,
                first_seen_ns=stamp_ns,
                appearance=None if obs.appearance is None else obs.appearance.copy(),
                hits=1,
            )
            tr.vel_cov = np.eye(2) * V_MAX**2
            tr.whereabouts.see(tr.xy, stamp_ns)
            if obs.appearance is not None:
                tr.colours.see(obs.appearance, obs.range_m, obs.whole)
            self.add(tr, stamp_ns)
            if self.settings.confirm_hits <= 1:
                tr.id = self.ids.next_id("person")
                changed.append(tr)
        ttl = TENTATIVE_TTL_NS
        self.tracks = [t for t in self.tracks if t.confirmed or stamp_ns - t.last_seen_ns <= ttl]
        seen = [t for t in changed if t.last_seen_ns == stamp_ns]
        for tr in seen:
            assert tr.id is not None
            tr.seen_with.update(o.id for o in seen if o is not tr and o.id is not None)
        self.merged.extend(self.merge_splits(seen, stamp_ns))
        gone = {id(g) for _, g, _ in self.merged}
        return [t for t in changed if id(t) not in gone]

    def _gone_from_their_place(self, t: Track, since_ns: int) -> bool:
        """A person the map looked for where it has them and did not see, unseen since
        `since_ns`, with colours to know them by."""
        return (
            t.appearance is not None
            and t.last_seen_ns < since_ns
            and t.misses >= self.settings.missing_after_frames
        )

    @staticmethod
    def _long_unseen(t: Track, stamp_ns: int) -> bool:
        """A person with colours to know them by, unseen for `REID_STALE_NS`."""
        return t.appearance is not None and stamp_ns - t.last_seen_ns >= REID_STALE_NS

    def _only_them(self, new: Track, old: Track) -> bool:
        """`new` is nearer in clothes to `old` than to anybody else the map has, and
        nobody else who may be them goes without colours (a seeded person not seen yet:
        their clothes are not known, so nothing says the newcomer is not them)."""
        assert new.appearance is not None
        others = [t for t in self.confirmed if t is not new]
        if any(t.appearance is None and t.source != "perception" and t is not old for t in others):
            return False
        return self._same_clothes(new.appearance, others)[1] is old

    def _colours_lie(
        self,
        tr: Track,
        observations: list[Observation],
        owners: list[Track | None],
        stamp_ns: int,
    ) -> bool:
        """Whether detections in somebody else's clothes have stood still within
        `GATE_MIN_M` of confirmed person `tr` for `DOUBT_NS` (module docstring): the
        person there is `tr`, whatever the colours say. Keeps `tr.doubt`."""
        if not tr.confirmed or tr.appearance is None:
            return False
        near = [
            o.xy
            for o, w in zip(observations, owners, strict=True)
            if w is not None and w is not tr and np.linalg.norm(o.xy - tr.xy) <= GATE_MIN_M
        ]
        if not near:
            return False
        xy = min(near, key=lambda p: float(np.linalg.norm(p - tr.xy)))
        d = tr.doubt
        if d is None or stamp_ns - d[2] > DOUBT_GAP_NS or np.linalg.norm(xy - d[1]) > STILL_M:
            tr.doubt = (stamp_ns, xy.copy(), stamp_ns)  # from here (a passer-by walks on)
            return False
        tr.doubt = (d[0], d[1], stamp_ns)
        return stamp_ns - d[0] >= DOUBT_NS

    def clothes_owner(self, obs: Observation) -> Track | None:
        """The person the detection's colours are, clearly (`_same_clothes` over everyone
        the map has), or None: no colours, nobody's, or two people's alike."""
        if obs.appearance is None:
            return None
        return self._same_clothes(obs.appearance, self.confirmed)[1]

    def _same_clothes(self, look: FloatArray, pool: list[Track]) -> tuple[float, Track | None]:
        """Of `pool`, the one wearing `look` (within `REID_APPEARANCE`, and `REID_MARGIN`
        nearer than any other), and the colour distance; None when nobody is, or two are."""
        ranked = sorted(
            ((bhattacharyya(t.appearance, look), t) for t in pool if t.appearance is not None),
            key=lambda p: p[0],
        )
        if not ranked or ranked[0][0] > REID_APPEARANCE:
            return math.inf, None
        if len(ranked) > 1 and ranked[1][0] - ranked[0][0] < REID_MARGIN:
            return ranked[0][0], None
        return ranked[0]

    def _walked_off(self, old: Track, new: Track) -> bool:
        """`old`, seen walking and unseen since before `new` was first seen (for
        `REID_UNSEEN_NS`), could have walked to where `new` is: within `V_MAX` of the
        time unseen (plus `MAX_GATE_M`, the places' own error) of where they were."""
        if old.appearance is None or not old.moving or not old.last_seen_ns:
            return False
        unseen_ns = (new.first_seen_ns or new.last_seen_ns) - old.last_seen_ns
        if unseen_ns < WALKED_OFF_NS:
            return False
        reach = V_MAX * unseen_ns * 1e-9 + MAX_GATE_M
        return float(np.linalg.norm(new.xy - old.xy)) <= reach

    def reidentify(self, new: Track, stamp_ns: int) -> Track | None:
        """The known person a person about to be confirmed is (module docstring), moved to
        the new one's place, the new one forgotten; None when they are somebody new."""
        if new.appearance is None:
            return None
        since = min(new.first_seen_ns or stamp_ns, stamp_ns - REID_UNSEEN_NS)
        gone = [t for t in self.confirmed if self._gone_from_their_place(t, since)]
        by_looks = {id(t) for t in gone}  # tracks by identity: their `==` compares arrays
        stale = [
            t
            for t in self.confirmed
            if id(t) not in by_looks
            and t is not new
            and t.id not in new.seen_with
            and (
                (new.walked and self._long_unseen(t, stamp_ns))
                or (t.last_seen_ns < since and self._walked_off(t, new))
            )
        ]
        app, old = self._same_clothes(new.appearance, [*gone, *stale])
        if old is None or (id(old) not in by_looks and not self._only_them(new, old)):
            return None
        self._take_place(old, new, app)
        return old

    def rejoin(self, stamp_ns: int) -> list[tuple[Track, Track, str]]:
        """People found gone from their place (the map's looks) after somebody in their
        clothes was confirmed elsewhere: that somebody is them (the same test as
        `reidentify`, the other way round); (kept, merged away, why), as `take_merged`."""
        out: list[tuple[Track, Track, str]] = []
        for old in list(self.confirmed):
            if all(old is not t for t in self.tracks):
                continue  # merged away already
            gone = self._gone_from_their_place(old, stamp_ns - REID_UNSEEN_NS)
            long_unseen = self._long_unseen(old, stamp_ns)
            if not gone and not long_unseen and not old.moving:
                continue
            if old.appearance is None:
                continue
            newer = [
                t
                for t in self.confirmed
                if t.source == "perception"
                and t.first_seen_ns > old.last_seen_ns
                and old.id not in t.seen_with
                and t.appearance is not None
                and (gone or (long_unseen and t.walked) or self._walked_off(old, t))
            ]
            app, new = self._same_clothes(old.appearance, newer)
            if new is None or new.appearance is None:
                continue
            # ...and they are nearer in clothes to `old` than to anybody else
            if not self._only_them(new, old):
                continue
            self._take_place(old, new, app)
            out.append((old, new, f"{old.id} in their clothes (colour distance {app:.2f})"))
        self.merged.extend(out)
        return out

    def _take_place(self, old: Track, new: Track, app: float) -> None:
        """`old` is `new`: it takes new's place, velocity and views; new is forgotten."""
        assert new.P is not None and old.id is not None and new.appearance is not None
        was = old.xy.copy()
        self._set(old, np.concatenate([new.xy, new.velocity]), new.P.copy())
        old.appearance = blend(old.appearance, new.appearance)
        old.colours.absorb(new.colours)
        old.hits += new.hits
        old.near_hits += new.near_hits
        old.last_seen_ns, old.stamp_ns, old.moving = new.last_seen_ns, new.stamp_ns, new.moving
        old.walked |= new.walked
        old.misses, old.missing_since_ns = 0, None
        old.seen_with |= new.seen_with
        old.whereabouts.absorb(new.whereabouts)
        self._seen_with_as(new, old)
        self.leaps.pop(old.id, None)
        self.drop(new)
        self.reidentified.append((old.id, was, old.xy.copy(), app))

    def take_reidentified(self) -> list[tuple[str, FloatArray, FloatArray, float]]:
        """The people re-identified since the last call: (id, from xy, to xy, colour
        distance)."""
        out, self.reidentified = self.reidentified, []
        return out

    def merge_splits(self, seen: list[Track], stamp_ns: int) -> list[tuple[Track, Track, str]]:
        """Merge each person seen in this frame with a person that is the same body (module
        doc): (kept, merged away, why), the merged one forgotten."""
        out: list[tuple[Track, Track, str]] = []
        for a in seen:
            if all(a is not t for t in self.tracks):
                continue  # merged away already
            for b in self.confirmed:
                why = self._same_body(a, b, stamp_ns)
                if why:
                    keep, gone = (b, a) if _rank(b) > _rank(a) else (a, b)
                    self._absorb(keep, gone)
                    out.append((keep, gone, why))
                    if gone is a:
                        break
        return out

    def _same_body(self, a: Track, b: Track, stamp_ns: int) -> str:
        """Why a and b are one person; "" when they may be two."""
        if a is b or b.id in a.seen_with or a.id in b.seen_with:
            return ""
        d = float(np.linalg.norm(a.xy - b.xy))
        if d < BODY_M and stamp_ns - b.last_seen_ns <= BODY_RECENT_NS:
            return f"{d:.2f} m apart and never seen together: one body"
        if d >= SPLIT_M or a.appearance is None or b.appearance is None:
            return ""  # the colours are compared only for the few near enough
        app = bhattacharyya(a.appearance, b.appearance)
        if d < BODY_M and app <= REID_APPEARANCE:
            return f"{d:.2f} m from where they were last seen, in their clothes ({app:.2f})"
        recent = stamp_ns - b.last_seen_ns <= SPLIT_RECENT_NS
        if not recent or a.walked or b.walked or app > MAX_APPEARANCE:
            return ""
        return (
            f"{d:.2f} m apart, alike (colour distance {app:.2f}), seen in turn within "
            f"{SPLIT_RECENT_NS * 1e-9:g} s and never together: one person whose track split"
        )

    def _absorb(self, keep: Track, gone: Track) -> None:
        """One track of the two: the place moment-matched (the detections' weights), so
        its covariance spans both places and the next detection at either one fuses."""
        assert keep.P is not None and gone.P is not None
        w = np.array([keep.hits, gone.hits], float) / max(keep.hits + gone.hits, 1)
        mean = w[0] * keep.xy + w[1] * gone.xy
        dk, dg = keep.xy - mean, gone.xy - mean
        cov = w[0] * (keep.P[:2, :2] + np.outer(dk, dk))
        cov += w[1] * (gone.P[:2, :2] + np.outer(dg, dg))
        P = np.zeros((4, 4))
        P[:2, :2], P[2:, 2:] = cov, keep.P[2:, 2:]
        self._set(keep, np.concatenate([mean, keep.velocity]), P)
        keep.hits += gone.hits
        keep.near_hits += gone.near_hits
        keep.first_seen_ns = min(keep.first_seen_ns or gone.first_seen_ns, gone.first_seen_ns)
        keep.last_seen_ns = max(keep.last_seen_ns, gone.last_seen_ns)
        if keep.appearance is None and gone.appearance is not None:
            keep.appearance = gone.appearance.copy()
        keep.colours.absorb(gone.colours)
        keep.whereabouts.absorb(gone.whereabouts)
        keep.walked |= gone.walked
        assert keep.id is not None and gone.id is not None
        self._seen_with_as(gone, keep)
        self.drop(gone)

    def _seen_with_as(self, gone: Track, keep: Track) -> None:
        """Who was seen with `gone` (merged into `keep`) was seen with `keep`."""
        if gone.id is None or keep.id is None:
            return
        for tr in self.tracks:
            if gone.id in tr.seen_with and tr.id is not None:
                tr.seen_with.discard(gone.id)
                tr.seen_with.add(keep.id)
                keep.seen_with.add(tr.id)

    def _leap_held(self, tr: Track, obs: Observation, stamp_ns: int) -> bool:
        """Whether the detection matched to `tr` is held back: far from a standing person,
        with no second one there yet (module docstring)."""
        if tr.id is None or tr.moving:
            return False
        if float(np.linalg.norm(obs.xy - tr.xy)) <= GATE_MIN_M:
            self.leaps.pop(tr.id, None)
            return False
        first = self.leaps.pop(tr.id, None)
        if (
            first is not None
            and stamp_ns - first[1] <= LEAP_CONFIRM_NS
            and float(np.linalg.norm(obs.xy - first[0])) <= GATE_MIN_M
        ):
            return False  # seen there twice: they did move
        self.leaps[tr.id] = (obs.xy.copy(), stamp_ns)
        self.held.append((tr.id, obs.xy.copy()))
        return True

    def take_jumps(
        self,
    ) -> tuple[list[tuple[str, FloatArray, FloatArray, FloatArray]], list[tuple[str, FloatArray]]]:
        """The jumps and the held far detections since the last call (`jumps`, `held`)."""
        jumps, held, self.jumps, self.held = self.jumps, self.held, [], []
        return jumps, held

    def take_merged(self) -> list[tuple[Track, Track, str]]:
        """The merges since the last call: (kept, merged away, why)."""
        merged, self.merged = self.merged, []
        return merged

    def _fuse(self, tr: Track, obs: Observation, stamp_ns: int) -> None:
        assert tr.P is not None
        H = np.zeros((2, 4))
        H[0, 0] = H[1, 1] = 1.0
        R = np.eye(2) * obs.sigma_m**2
        x = np.concatenate([tr.xy, tr.velocity])
        S = H @ tr.P @ H.T + R
        K = tr.P @ H.T @ np.linalg.inv(S)
        x = x + K @ (obs.xy - H @ x)
        P = (np.eye(4) - K @ H) @ tr.P
        self._set(tr, x, P)
        if obs.appearance is not None:
            tr.appearance = blend(tr.appearance, obs.appearance)
            tr.colours.see(obs.appearance, obs.range_m, obs.whole)
        tr.hits += 1
        tr.near_hits += int(obs.near(self.settings.class_near_m))
        tr.moving = sure_velocity(tr)
        tr.walked |= tr.moving
        if tr.moving:  # the facing it had (a seed's) is not theirs once they walk
            tr.yaw = 0.0
        tr.last_seen_ns = stamp_ns
        tr.misses = 0
        tr.missing_since_ns = None
        tr.whereabouts.see(tr.xy, stamp_ns)
