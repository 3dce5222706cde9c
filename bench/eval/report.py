"""`dume eval`'s outputs from its per-world results: a summary, `report.md`,
`results.json` and two PNG plots.

`summarize` counts: success rate (truth), how many worlds got through each stage of the
tree, how often the mission's own outcome agreed with the truth, sim and wall times and
the real-time factor. `write_report` writes the Markdown report (settings with the commit
and the machine, the success rate with its Wilson interval, per-stage table, every
failure with its world seed, reason and pictures, the failures counted by reason and
stage, times, a per-world table linking each world's picture and run folder), the JSON
(settings, summary, every `WorldResult`) and the plots, drawn with matplotlib's Agg
canvas on `Figure` objects (no pyplot state, no display needed). Pure but for the files.
"""

from __future__ import annotations

import json
import math
import os
import statistics
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import msgspec

from bench.eval.judge import WorldResult
from bench.eval.pictures import failure_counts, machine, reasons_table, wilson
from common.config import REPO_ROOT
from common.messages.mission import STAGES
from deploy.runs import source_commit

PLOTS = ("stage_times.png", "outcomes.png", "reasons.png")


def _stats(values: Sequence[float]) -> dict[str, float]:
    if not values:
        return {"mean": math.nan, "median": math.nan}
    return {
        "mean": round(statistics.fmean(values), 2),
        "median": round(statistics.median(values), 2),
    }


def summarize(results: Sequence[WorldResult]) -> dict[str, Any]:
    """The figures a reader wants first; JSON-ready."""
    n = len(results)
    ok = [r for r in results if r.succeeded]
    ran = [r for r in results if not r.error]
    through = {s: sum(s in r.stages_passed for r in results) for s in STAGES}
    wall = sum(r.wall_time_s for r in ran)
    sim = sum(r.sim_time_s for r in ran)
    return {
        "worlds": n,
        "succeeded": len(ok),
        "success_rate": round(len(ok) / n, 4) if n else 0.0,
        "stages_through": through,
        "mission_agrees": sum(r.agree for r in ran),
        "errors": sum(bool(r.error) for r in results),
        "sim_time_s": _stats([r.sim_time_s for r in ran]),
        "sim_time_s_succeeded": _stats([r.sim_time_s for r in ok]),
        "wall_time_s": _stats([r.wall_time_s for r in ran]),
        "rtf": round(sim / wall, 3) if wall > 0 else 0.0,
        "contacts_static": sum(r.contacts_static for r in results),
        "drops": sum(r.drops for r in results),
        "lockstep_stalls": sum(max(r.lockstep_stalls, 0) for r in results),
    }


def _pct(k: int, n: int) -> str:
    return f"{100 * k / n:.0f} %" if n else "-"


def _fmt(x: float) -> str:
    return "-" if math.isnan(x) else f"{x:.1f}"


def _odom(r: WorldResult, key: str) -> str:
    """One of the odometry's figures for the table ("-" when none was measured)."""
    x = r.odometry.get(key)
    return "-" if x is None else f"{x:g}"


def _located(r: WorldResult, key: str, scale: float = 1.0) -> str:
    """One of the localization's figures for the table ("-" when it did not run)."""
    x = r.localization.get(key)
    return "-" if x is None else f"{x * scale:.3g}"


def _placed(r: WorldResult, key: str) -> str:
    """One of the placement's figures for the table ("-" when nothing was placed)."""
    x = r.placement.get(key) if r.placement.get("samples") else None
    return "-" if x is None else f"{x:g}"


def localization_summary(results: Sequence[WorldResult]) -> str:
    """The localization's worst world, for the summary ("" when it did not run)."""
    located = [r for r in results if r.localization.get("samples")]
    if not located:
        return ""
    worst = max(located, key=lambda r: r.localization["position_p95_m"])
    heading = max(r.localization["heading_p95_deg"] for r in located)
    lost = sum(int(r.localization.get("lost", 0)) for r in located)
    return (
        f"Localization against the truth: position p95 ≤ "
        f"{100 * worst.localization['position_p95_m']:.1f} cm in every world (worst: seed "
        f"{worst.world_seed}), heading p95 ≤ {heading:.2f}°; {lost} ticks lost."
    )


def _link(path: str, out: Path | None) -> str:
    """`path` (relative to the repository, or absolute) as seen from the report's folder."""
    target = Path(path) if Path(path).is_absolute() else REPO_ROOT / path
    return os.path.relpath(target, out) if out is not None else str(target)


def report_markdown(
    settings: Mapping[str, Any],
    summary: Mapping[str, Any],
    results: Sequence[WorldResult],
    out: Path | None = None,
) -> str:
    """The report's Markdown text (links relative to `out`, the report's folder)."""
    n = summary["worlds"]
    lo, hi = wilson(summary["succeeded"], n)
    lines = [
        "# dume eval",
        "",
        "## Settings",
        "",
        *(f"- {k}: {v}" for k, v in settings.items()),
        "",
        "## Result",
        "",
        f"**Success: {summary['succeeded']}/{n} ({_pct(summary['succeeded'], n)}; 95 % "
        f"interval {lo * 100:.0f}-{hi * 100:.0f} %, Wilson)**, judged "
        "from sim truth (the requested object in the requested person's hand). The "
        f"mission's own outcome agreed with the truth in {summary['mission_agrees']} of "
        f"{n - summary['errors']} runs.",
        "",
        "| stage | worlds through | rate |",
        "|---|---|---|",
        *(f"| {s} | {k} | {_pct(k, n)} |" for s, k in summary["stages_through"].items()),
        "",
        "## Times",
        "",
        "| | mean | median |",
        "|---|---|---|",
        *(
            f"| {label} | {_fmt(summary[key]['mean'])} | {_fmt(summary[key]['median'])} |"
            for label, key in (
                ("sim time per world, s", "sim_time_s"),
                ("sim time per success, s", "sim_time_s_succeeded"),
                ("wall time per world, s", "wall_time_s"),
            )
        ),
        "",
        f"Real-time factor (sim / wall, over the missions): {summary['rtf']:.2f}. "
        f"Contacts with static obstacles: {summary['contacts_static']}; "
        f"objects dropped: {summary['drops']}; lockstep stalls (the sim stepped on "
        f"without a participant): {summary['lockstep_stalls']}.",
        *(["", line] if (line := localization_summary(results)) else []),
        "",
        "## Failures",
        "",
    ]
    failures = [r for r in results if not r.succeeded]
    for r in failures:
        lines.append(f"- world seed {r.world_seed} ({r.object} → {r.person}): {r.failure}")
        shots = [r.picture, *r.failure_frames] if r.picture else r.failure_frames
        lines += [f"  ![seed {r.world_seed}]({p})" for p in shots]
    lines += ["- none"] if not failures else []
    lines += ["", "By reason and the stage it ended in:", "", *reasons_table(results)]
    lines += [
        "",
        "## Worlds",
        "",
        "The picture: the world from above, the robot's true path coloured by stage; logs: "
        "the run's folder (every service's log; its recording with `--record`).",
        "",
        "| seed | object → person | truth | mission | agree | stage reached | sim s | wall s "
        "| rtf | contacts | drops | picture | logs |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        mission = r.mission_state + (f" ({r.mission_reason})" if r.mission_reason else "")
        picture = f"[top-down]({r.picture})" if r.picture else "-"
        logs = f"[{Path(r.logs).name}]({_link(r.logs, out)})" if r.logs else "-"
        lines.append(
            f"| {r.world_seed} | {r.object} → {r.person} | {r.outcome} | {mission or '-'} "
            f"| {'yes' if r.agree else 'no'} | {r.stage_reached or '-'} | {r.sim_time_s:.1f} "
            f"| {r.wall_time_s:.0f} | {r.rtf:.2f} | {r.contacts_static} | {r.drops} "
            f"| {picture} | {logs} |"
        )
    lines += [
        "",
        "## The robot's estimates against the truth",
        "",
        "Odometry: its drift over the distance walked and its final error. Localization: "
        "the base in the map. Placement: the artifacts perception saw within 3 m before the "
        "pick, in the map (with the robot's pose) and placed with the true base (its "
        "geometry alone); excess: the map error beyond the geometry's plus the pose's share "
        "(≤ 10 mm is the acceptance).",
        "",
        "| seed | odom drift % | odom error m | loc p95 cm | loc max cm | loc heading p95 ° "
        "| placed | map p95 mm | geometry p95 mm | excess p95 mm |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *(
            f"| {r.world_seed} | {_odom(r, 'drift_pct')} | {_odom(r, 'position_error_m')} "
            f"| {_located(r, 'position_p95_m', 100)} | {_located(r, 'position_max_m', 100)} "
            f"| {_located(r, 'heading_p95_deg')} | {_placed(r, 'samples')} "
            f"| {_placed(r, 'map_error_p95_mm')} | {_placed(r, 'base_error_p95_mm')} "
            f"| {_placed(r, 'excess_p95_mm')} |"
            for r in results
        ),
    ]
    lines += _exploration(results)
    lines += ["", "## Plots", "", *(f"![{p}]({p})\n" for p in PLOTS)]
    return "\n".join(lines)


def _exploration(results: Sequence[WorldResult]) -> list[str]:
    """With `--map explored`: each world's exploration and its map judged from truth."""
    rows = [r for r in results if r.exploration]
    if not rows:
        return []
    lines = [
        "",
        "## The exploration before each request",
        "",
        "Each world explored from nothing (no floor plan; SLAM), judged from truth: the "
        "occupancy's IoU with the floor plan within 5 cm over the reachable area, as the "
        "map lies and once aligned (the map is in the robot's own frame, anchored at the "
        "start pose it was told: the rigid motion that lays it best on the floor plan, "
        "the frame's error, is given), the floor known, the artifacts found within 10 cm "
        "(of the right class) as the map lies and aligned, false entries, the people found.",
        "",
        "| seed | outcome | sim s | wall s | occupancy IoU (aligned) | frame off | floor "
        "known | artifacts found (right class) / all | aligned | false entries | people "
        "found / all | missed |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        e = r.exploration
        a = e.get("aligned", {})
        missed = ", ".join([*e.get("missed", []), *e.get("wrong_class", [])]) or "-"
        lines.append(
            f"| {r.world_seed} | {e.get('outcome', '-')} | {e.get('sim_s', '-')} "
            f"| {e.get('wall_s', '-')} | {e.get('occupancy_iou_5cm', '-')} "
            f"({e.get('occupancy_iou_5cm_aligned', '-')}) "
            f"| {e.get('frame_yaw_deg', '-')}° {e.get('frame_shift_cm', '-')} cm "
            f"| {e.get('floor_known_share', '-')} | {e.get('found_within_10cm', '-')} "
            f"({e.get('found_right_class', '-')}) / {e.get('artifacts', '-')} "
            f"| {a.get('found_within_10cm', '-')} ({a.get('found_right_class', '-')}) "
            f"| {', '.join(e.get('false_entries', [])) or '0'} "
            f"| {e.get('people_found', '-')} / {e.get('people', '-')} | {missed} |"
        )
    return lines


def plot_stage_times(results: Sequence[WorldResult], path: Path) -> None:
    """A stacked horizontal bar per world: sim seconds in each stage; failures marked."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 1.5 + 0.35 * max(1, len(results))), layout="constrained")
    ax = fig.add_subplot()
    for i, r in enumerate(results):
        left = 0.0
        for j, stage in enumerate(STAGES):
            w = r.stage_times_s.get(stage, 0.0)
            ax.barh(i, w, left=left, color=f"C{j}", label=stage if i == 0 else None)
            left += w
        if not r.succeeded:
            ax.text(left, i, "  ✗", va="center", color="red")
    ax.set_yticks(range(len(results)), [f"seed {r.world_seed}" for r in results])
    ax.invert_yaxis()
    ax.set_xlabel("sim time, s")
    ax.set_title("Time per stage (✗: failed)")
    if results:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    fig.savefig(path, dpi=100)


def plot_outcomes(results: Sequence[WorldResult], path: Path) -> None:
    """Per world, the stages got through; green succeeded, red failed."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(6.5, 0.45 * len(results) + 3), 3.5), layout="constrained")
    ax = fig.add_subplot()
    xs = range(len(results))
    heights = [len(r.stages_passed) for r in results]
    ax.bar(xs, heights, color=["tab:green" if r.succeeded else "tab:red" for r in results])
    for x, r in zip(xs, results, strict=True):
        if not r.stages_passed:  # nothing to draw: mark it, with why when the run failed
            ax.text(x, 0.1, "✗" if not r.error else "✗ error", ha="center", color="tab:red")
    ax.set_xticks(xs, [str(r.world_seed) for r in results])
    ax.set_yticks(range(len(STAGES) + 1), ["none", *STAGES], fontsize="small")
    ax.set_ylim(0, len(STAGES) + 0.3)
    ax.set_xlabel("world seed")
    ax.set_title("Stages got through (green: succeeded, red: failed)", fontsize="medium")
    fig.savefig(path, dpi=100)


def plot_reasons(results: Sequence[WorldResult], path: Path) -> None:
    """The failures as a histogram of their typed reasons, stacked by the stage each
    ended in."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    counts = failure_counts(results)
    reasons = sorted({r for r, _ in counts}, key=lambda r: -sum(
        k for (q, _), k in counts.items() if q == r))  # fmt: skip
    fig = Figure(figsize=(8, 1.8 + 0.4 * max(1, len(reasons))), layout="constrained")
    ax = fig.add_subplot()
    for j, stage in enumerate(["-", *STAGES]):
        left = [sum(counts.get((r, s), 0) for s in ["-", *STAGES][:j]) for r in reasons]
        widths = [counts.get((r, stage), 0) for r in reasons]
        if any(widths):
            ax.barh(range(len(reasons)), widths, left=left, color=f"C{j}", label=stage)
    ax.set_yticks(range(max(1, len(reasons))), reasons or ["no failure"])
    ax.invert_yaxis()
    ax.set_xlabel("worlds")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title("Failures by reason (colour: the stage it ended in)", fontsize="medium")
    if reasons:
        ax.legend(loc="lower right", fontsize="small")
    fig.savefig(path, dpi=100)


def json_safe(x: Any) -> Any:
    """`x` with every NaN as None (JSON has no NaN)."""
    if isinstance(x, float) and math.isnan(x):
        return None
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    return x


def write_report(
    out: Path, settings: Mapping[str, Any], results: Sequence[WorldResult]
) -> dict[str, Any]:
    """Write report.md, results.json and the plots under `out`; return the summary."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(results)
    settings = {**settings, "commit": source_commit(), "machine": machine()}
    (out / "report.md").write_text(report_markdown(settings, summary, results, out))
    doc = {"settings": dict(settings), "summary": summary, "worlds": msgspec.to_builtins(results)}
    (out / "results.json").write_text(json.dumps(json_safe(doc), indent=2) + "\n")
    plot_stage_times(results, out / PLOTS[0])
    plot_outcomes(results, out / PLOTS[1])
    plot_reasons(results, out / PLOTS[2])
    return summary
