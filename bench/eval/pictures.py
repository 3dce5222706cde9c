"""Each eval world as a picture, and what the report says beside the counts.

`world_picture` draws one world from above, from the sim's truth (evaluation reads it):
the floor plan, every artifact and person with the requested ones marked, the robot's
true path coloured by the mission's stage, contacts where they happened, and where it
ended (✓ handed over, ✗ failed, with why in the title). `wilson` is the success rate's
95 % interval; `machine` says what the wall times were measured on.
"""

from __future__ import annotations

import math
import platform
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from bench.eval.judge import MissionRecord, WorldResult, static_contacts
from common.messages.arrays import as_numpy
from common.messages.mission import STAGES
from common.messages.world import WorldDescription
from common.sched import allowed_cpus


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of k successes in n (95 % by default), as fractions."""
    if n <= 0:
        return 0.0, 1.0
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def machine() -> str:
    """The CPU, its cores and the Python: what the wall times were measured on."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(allowed_cpus())
    return f"{model}, {cores} cores, Python {platform.python_version()}"


def _stage_at(record: MissionRecord, stamp_ns: float) -> int:
    """The index in STAGES of the mission's stage at a sim time (-1 before the first)."""
    index = -1
    for c in record.changes:
        if c.stamp_ns > stamp_ns:
            break
        if c.behaviour in STAGES:
            index = STAGES.index(c.behaviour)
    return index


def world_picture(
    world: WorldDescription, record: MissionRecord, result: WorldResult, path: Path
) -> None:
    """Draw the world from above with the run on it (see the module docstring)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 7), layout="constrained")
    ax = fig.add_subplot()
    occ = world.occupancy
    cells = np.asarray(as_numpy(occ.cells))
    ny, nx = cells.shape
    x0, y0 = occ.origin
    extent = (x0, x0 + nx * occ.resolution, y0, y0 + ny * occ.resolution)
    ax.imshow(cells > 0, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=1.6)
    for a in world.artifacts:
        asked = a.id == result.truth_object
        ax.plot(*a.position[:2], marker="*" if asked else "o", ms=13 if asked else 5,
                color="tab:red" if asked else "tab:brown", zorder=5)  # fmt: skip
        ax.annotate(a.id, a.position[:2], fontsize=7, xytext=(3, 3), textcoords="offset points")
    for p in world.people:
        asked = p.id == result.truth_person
        ax.plot(*p.position, marker="^", ms=11 if asked else 6,
                color="tab:purple" if asked else "k", zorder=5)  # fmt: skip
        ax.annotate(p.id, p.position, fontsize=7, xytext=(3, 3), textcoords="offset points")
    traj = np.asarray([s[:3] for s in record.trajectory], dtype=float).reshape(-1, 3)
    if len(traj):
        stage = np.array([_stage_at(record, t) for t in traj[:, 0]])
        for k, name in enumerate(STAGES):
            on = stage == k
            if on.any():
                ax.scatter(traj[on, 1], traj[on, 2], s=4, color=f"C{k}", label=name, zorder=4)
        ax.plot(traj[:, 1], traj[:, 2], color="0.3", lw=0.6, zorder=3)
        ax.plot(traj[0, 1], traj[0, 2], marker="o", ms=8, mfc="none", color="k", zorder=6)
        end, colour = ("✓", "tab:green") if result.succeeded else ("✗", "red")
        ax.annotate(end, (traj[-1, 1], traj[-1, 2]), color=colour, fontsize=18, ha="center",
                    va="center", zorder=7)  # fmt: skip
        for c in static_contacts(record.events, world):
            i = int(np.argmin(np.abs(traj[:, 0] - c.stamp_ns)))
            ax.plot(traj[i, 1], traj[i, 2], marker="x", ms=10, color="red", zorder=7)
    why = "handed over" if result.succeeded else (result.mission_reason or "failed")
    ax.set_title(
        f"seed {result.world_seed}: {result.object} → {result.person}: {why} "
        f"({result.stage_reached or '-'}, {result.sim_time_s:.0f} s sim)",
        fontsize=10,
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    if len(traj):
        ax.legend(loc="upper right", fontsize=7, markerscale=3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)


def failure_counts(results: Sequence[WorldResult]) -> dict[tuple[str, str], int]:
    """The failures counted by (typed reason, the stage they ended in)."""
    counts: dict[tuple[str, str], int] = {}
    for r in results:
        if r.succeeded:
            continue
        key = (r.mission_reason or ("error" if r.error else "none"), r.stage_reached or "-")
        counts[key] = counts.get(key, 0) + 1
    return counts


def reasons_table(results: Sequence[WorldResult]) -> list[str]:
    """Markdown rows: the failures counted by typed reason and the stage they ended in."""
    counts = failure_counts(results)
    if not counts:
        return ["- none"]
    rows = ["| reason | stage | worlds |", "|---|---|---|"]
    for (reason, stage), k in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])):
        rows.append(f"| {reason} | {stage} | {k} |")
    return rows
