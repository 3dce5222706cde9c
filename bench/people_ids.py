"""`dume bench people-ids --run DIR`: how well the map keeps one id per person, replayed.

A shift run with `--trace-people` leaves, per world seed, the map's people trace
(`people-seed-<s>.trace`: what the tracker took in, `services.semantic_map.people_trace`)
and the sim's truth people (`people-truth-seed-<s>.msgpack`: every 0.25 s of sim). This
bench replays each trace through the tracker as the code now is (not as it was when the
run was made), so a change to `services/semantic_map/people.py` is measured on the same
real input in seconds, not in a half-hour shift.

Scored at each truth sample (`score`): the truth people the frame's camera could see
(within `person_look_range_m`, inside the image's horizontal field; walls not counted)
against the map's people seen within `RECENT_NS` (their estimate is current), matched when
within `MATCH_M`:

- **IDF1** (Ristani et al. 2016): truth and map ids paired one-to-one for the whole run
  to maximise the samples where they matched (Hungarian); IDTP those samples, IDFN the
  truth samples left, IDFP the map samples left; 2·IDTP / (2·IDTP + IDFP + IDFN);
- **switches**: the times a truth person's matched id changed from one sample to its
  next match;
- **ids per person**: how many map ids each truth person was matched to;
- **shared ids**: map ids matched to two truth people or more (one id for two bodies:
  the handover goes to the wrong one);
- **ghosts**: map ids seen lately at some sample that never matched anybody;
- **decisions**: each re-identification and merge the tracker made, judged right or wrong
  by who the ids stood for (`Decisions`), the wrong ones listed.

Truth appears only here, in the scoring (evaluation); the replayed map sees the trace.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
from scipy.optimize import linear_sum_assignment

from common.config import Overrides, SemanticMapSettings, load_config, resolve
from common.messages.sim import PeopleTruth
from services.semantic_map.people_trace import TraceFrame, replay

#: A map person within this of a truth person stands for them, m.
MATCH_M = 1.0
#: A map person is current when seen within this of the sample (a detection then), ns.
RECENT_NS = 500_000_000

#: Id → floor point (m, world).
Places = dict[str, tuple[float, float]]
#: One scoring sample: its sim time (ns), the truth people in view, the map's people current.
Sample = tuple[int, Places, Places]


@dataclass
class IdScore:
    """The figures of one run (module docstring), from `score`."""

    samples: int = 0
    idf1: float = 0.0
    idtp: int = 0
    idfp: int = 0
    idfn: int = 0
    switches: int = 0
    ids_per_person: dict[str, list[str]] = field(default_factory=dict)
    shared: dict[str, list[str]] = field(default_factory=dict)
    ghosts: list[str] = field(default_factory=list)
    #: Per truth person, the map ids they were matched to in turn: [id, from s, to s].
    timeline: dict[str, list[list[Any]]] = field(default_factory=dict)

    def figures(self) -> dict[str, Any]:
        return {
            "samples": self.samples,
            "idf1": round(self.idf1, 3),
            "idtp": self.idtp,
            "idfp": self.idfp,
            "idfn": self.idfn,
            "switches": self.switches,
            "ids_per_person": {k: len(v) for k, v in sorted(self.ids_per_person.items())},
            "shared_ids": self.shared,
            "ghosts": self.ghosts,
            "timeline": self.timeline,
        }


def match(
    truth: dict[str, tuple[float, float]], mapped: dict[str, tuple[float, float]]
) -> dict[str, str]:
    """Truth id → map id, one-to-one, nearest first, within `MATCH_M`."""
    if not truth or not mapped:
        return {}
    t_ids, m_ids = list(truth), list(mapped)
    d = np.array([[math.dist(truth[t], mapped[m]) for m in m_ids] for t in t_ids])
    rows, cols = linear_sum_assignment(np.where(d <= MATCH_M, d, 1e6))
    return {t_ids[i]: m_ids[j] for i, j in zip(rows, cols, strict=True) if d[i, j] <= MATCH_M}


def score(samples: list[Sample]) -> IdScore:
    """The figures over samples of (stamp, truth people in view, map people current:
    id → xy)."""
    out = IdScore(samples=len(samples))
    together: dict[tuple[str, str], int] = defaultdict(int)
    last: dict[str, str] = {}
    per_person: dict[str, set[str]] = defaultdict(set)
    per_id: dict[str, set[str]] = defaultdict(set)
    seen_ids: set[str] = set()
    n_truth = n_map = 0
    for stamp, truth, mapped in samples:
        n_truth += len(truth)
        n_map += len(mapped)
        seen_ids |= set(mapped)
        for t, m in match(truth, mapped).items():
            together[(t, m)] += 1
            per_person[t].add(m)
            per_id[m].add(t)
            if t in last and last[t] != m:
                out.switches += 1
            runs = out.timeline.setdefault(t, [])
            if runs and runs[-1][0] == m:
                runs[-1][2] = round(stamp * 1e-9, 1)
            else:
                runs.append([m, round(stamp * 1e-9, 1), round(stamp * 1e-9, 1)])
            last[t] = m
    if together:
        t_ids = sorted({t for t, _ in together})
        m_ids = sorted({m for _, m in together})
        c = np.array([[together.get((t, m), 0) for m in m_ids] for t in t_ids], float)
        rows, cols = linear_sum_assignment(-c)
        out.idtp = int(c[rows, cols].sum())
    out.idfn, out.idfp = n_truth - out.idtp, n_map - out.idtp
    denom = 2 * out.idtp + out.idfp + out.idfn
    out.idf1 = 2 * out.idtp / denom if denom else 1.0
    out.ids_per_person = {t: sorted(ms) for t, ms in per_person.items()}
    out.shared = {m: sorted(ts) for m, ts in sorted(per_id.items()) if len(ts) > 1}
    out.ghosts = sorted(seen_ids - set(per_id))
    return out


def in_view(frame: TraceFrame, xy: tuple[float, float], range_m: float) -> bool:
    """Whether the frame's camera had `xy` (a floor point) within `range_m` and inside its
    image's horizontal field (occlusion not counted)."""
    cam = frame.camera
    if cam is None:
        return False
    T = np.asarray(cam.T_world_camera).reshape(4, 4)
    p = T[:3, :3].T @ (np.array([xy[0], xy[1], 1.0]) - T[:3, 3])  # the chest's height, ~
    if p[2] <= 0.2 or math.hypot(p[0], p[2]) > range_m:
        return False
    half = math.atan2(cam.cx, cam.fx)
    return abs(math.atan2(p[0], p[2])) <= half


@dataclass
class Decisions:
    """The tracker's identity decisions judged against the truth: per kind (`reid`: a
    person known again by their clothes; `body`, `place`, `split`: two ids merged as one
    body, at a stale place in their clothes, as a standing person's split track), how
    many were right, wrong, or could not be judged (an id not yet matched to anybody)."""

    tally: dict[str, dict[str, int]] = field(default_factory=dict)
    wrong: list[str] = field(default_factory=list)

    def add(self, kind: str, verdict: str, said: str) -> None:
        row = self.tally.setdefault(kind, {"right": 0, "wrong": 0, "unjudged": 0})
        row[verdict] += 1
        if verdict == "wrong":
            self.wrong.append(said)


def merge_kind(reason: str) -> str:
    """Which rule merged two people, from the map's reason."""
    if "one body" in reason:
        return "body"
    return "split" if "track split" in reason else "place"


def replay_samples(
    trace: Path, truth: list[PeopleTruth], settings: SemanticMapSettings
) -> tuple[list[Sample], Decisions]:
    """The trace replayed through the map as the code now is, sampled at each truth stamp
    by the first frame at or after it: the truth people that frame's camera could see, the
    map's people current then. And each identity decision judged: a re-identification is
    right when the id went to the truth person it stood for (its last match), a merge when
    both ids stood for one truth person."""
    samples: list[Sample] = []
    decisions = Decisions()
    owner: dict[str, str] = {}  # map id → the truth person it was last matched to
    k = 0
    for frame, smap, report in replay(trace, settings):
        stamp = frame.stamp_ns
        now = truth[min(k, len(truth) - 1)] if truth else None
        for pid, _, to, app in report.reidentified:
            there = {p.id: p.position for p in now.people} if now is not None else {}
            who = match(there, {"x": (float(to[0]), float(to[1]))})
            was, found = owner.get(pid), next(iter(who), None)
            verdict = "unjudged" if was is None or found is None else (
                "right" if was == found else "wrong")  # fmt: skip
            decisions.add("reid", verdict, f"{stamp * 1e-9:.1f} s: {pid} ({was}) re-identified "
                          f"on {found} (colour distance {app:.2f})")  # fmt: skip
        for gone, reason in report.dropped:
            keep = smap.aliases.get(gone)
            if keep is None or "in their clothes (colour distance" in reason:
                continue  # a false entry deleted; a re-identification, judged above
            a, b = owner.get(gone), owner.get(keep)
            verdict = "unjudged" if a is None or b is None else ("right" if a == b else "wrong")
            said = f"{stamp * 1e-9:.1f} s: {gone} ({a}) merged into {keep} ({b})"
            decisions.add(merge_kind(reason), verdict, said)
        while k < len(truth) and truth[k].stamp_ns <= stamp:
            sample = truth[k]
            k += 1
            if sample.stamp_ns < stamp - RECENT_NS or frame.camera is None:
                continue  # no frame near it, or no image to say who was in view
            inside = {
                p.id: p.position
                for p in sample.people
                if in_view(frame, p.position, settings.person_look_range_m)
            }
            mapped = {
                t.id: (float(t.xy[0]), float(t.xy[1]))
                for t in smap.people.confirmed
                if t.id is not None and stamp - t.last_seen_ns <= RECENT_NS
            }
            samples.append((stamp, inside, mapped))
            owner |= {m: t for t, m in match(inside, mapped).items()}
    return samples, decisions


def bench_people_ids(run: str, overrides: Overrides) -> dict[str, Any]:
    """Every world of the run `run` (a shift's output folder) replayed and scored, the map
    under the settings `overrides` (`--set`: what to try)."""
    folder = resolve(run)
    settings = load_config(overrides).semantic_map
    out: dict[str, Any] = {}
    traces = sorted(folder.glob("people-seed-*.trace"))
    if not traces:
        raise FileNotFoundError(
            f"no people-seed-*.trace in {folder}: run the shift with --trace-people"
        )
    for trace in traces:
        seed = trace.stem.removeprefix("people-seed-")
        truth_path = folder / f"people-truth-seed-{seed}.msgpack"
        truth = msgspec.msgpack.decode(truth_path.read_bytes(), type=list[PeopleTruth])
        samples, decisions = replay_samples(trace, truth, settings)
        out[f"seed {seed}"] = score(samples).figures() | {
            "decisions": decisions.tally,
            "wrong_decisions": decisions.wrong,
        }
    return out
