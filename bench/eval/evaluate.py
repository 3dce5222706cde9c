"""`dume eval --worlds N --seed S --out DIR`: N seeded worlds, one bring-me request each,
judged from the simulator's truth, reported in DIR.

World i is seed S + i. Each world gets a fresh stack (`ProcessStack`: the router and
every service as child processes in their own sessions, on a free port, lockstep) so no
state leaks between worlds, a crashed service shows as down rather than restarted, and
teardown is certain: the stack stops in a `finally`, on failure, on Ctrl-C and on
SIGTERM (turned into the same interrupt). The map (a fresh database per world) starts
from the world's saved map with `--map saved` (var/saved-maps/ and the maps dume ships)
or `--map DIR` (`map_source`), the robot localizing on its grid; a world with none is
explored from nothing first (`explore_first`, scored against truth) and its map saved
there, so an eval explores each world once. `--map explored` explores every world and
saves nothing. `--map truth`, the default for now, seeds the map from the truth with
noise (`seed-from-world`, noise seeded by the world seed, with the floor plan): the
ablation. The request is a random mapped artifact and person
(`bench.eval.targets.seeded_pair`, seeded by the world seed). Success is the truth's
(`bench.eval.judge`). The segmenter and the locomotion the report states are read back
from what the running stack publishes.

Progress is one compact line per stage change and one per world on stderr, not a
progress bar: a world takes minutes of wall time, so a bar would sit still, while a line
per stage says where the robot is, reads well in CI logs, and needs no dependency. The
report is rewritten after every world, so an interrupted run still leaves one (of the
worlds that finished: the one cut short is not counted).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from bench.eval.explored import moved, score_entities
from bench.eval.judge import MissionRecord, WorldResult, evaluate
from bench.eval.pictures import world_picture
from bench.eval.report import json_safe, write_report
from bench.eval.run import (
    Progress,
    read_back,
    read_map,
    read_world,
    request_result,
    sigterm_interrupts,
    start_gate_overrides,
    watch_mission,
)
from bench.eval.targets import TargetError, seeded_pair
from bench.trial_explore import map_alignment, score_map
from common.bus import BusError, Latest
from common.config import ConfigError, load_config, merged, parse_overrides, resolve
from common.keys import MAP_EXPORT, MAP_OCCUPANCY
from common.messages import PayloadError
from common.messages.mission import MissionRequest, MissionStatus
from common.messages.semantic_map import MapFile, OccupancyGrid
from common.messages.sim import Clock, SimStats
from common.messages.world import WorldDescription
from common.recording import run_dir
from deploy import maps
from deploy.demo import SERVICES
from deploy.maps import map_path, saved_map
from deploy.runs import shown
from deploy.stack import ProcessStack
from services.semantic_map.mapfile import write_map_file
from services.semantic_map.store import database_path, remove_database
from services.sim.world import generate_world

#: Wall seconds for a world's stack to come up (every service ready), and for each of
#: its processes to exit when stopped (the sim may be flushing a recording).
START_TIMEOUT_S = 300.0
STOP_TIMEOUT_S = 60.0


def scenario_of(args: argparse.Namespace) -> str:
    if getattr(args, "bystanders", False):
        return "bystanders (walking people who do not stop for the robot)"
    return "walking people" if args.walking_people else "standing people"


def map_source(map_arg: str, world: str, seed: int) -> tuple[str, Path | None]:
    """Where world `seed`'s map comes from under `--map`: `("truth", None)`, the truth
    with noise (the ablation); `("explore", None)`, explored from nothing first;
    `("file", FILE)`, the saved map FILE of the world (`<site>.json` in the folder
    `--map` names, as `dume eval` saved it; `saved`: var/saved-maps/, then the maps dume
    ships); `("explore", FILE)`, there is none yet: explored first, and its map saved as
    FILE for the next eval."""
    if map_arg in ("truth", "explored"):
        return ("truth" if map_arg == "truth" else "explore"), None
    site = load_config({"sim.world": world, "sim.world_seed": seed}).map_site()
    folder = maps.SAVED_MAPS if map_arg == "saved" else resolve(map_arg)
    found = saved_map(site, None if map_arg == "saved" else (folder,))
    return ("file", found) if found else ("explore", map_path(folder, site))


def world_overrides(args: argparse.Namespace, seed: int, map_name: str) -> dict[str, Any]:
    """The settings of world `seed`'s stack."""
    how, path = map_source(getattr(args, "map", "truth"), args.world, seed)  # truth: no --map
    start = {"truth": "seed-from-world", "explore": "empty", "file": "prior"}[how]
    return merged(
        {
            "sim.world": args.world,
            "sim.world_seed": seed,
            "sim.walking_people": bool(args.walking_people)
            or bool(getattr(args, "bystanders", False)),
            "sim.bystanders": bool(getattr(args, "bystanders", False)),
            "sim.locomotion": "dynamic",
            "semantic_map.start": start,
            "semantic_map.name": map_name,
            "semantic_map.reset": True,
            "semantic_map.seed_noise_seed": seed,
            "recording.enabled": bool(args.record),
        },
        explored_overrides(args.world, seed) if how == "explore" else {},
        {"semantic_map.floor_plan": "none", "semantic_map.prior_file": str(path)}
        if how == "file"
        else {},
        start_gate_overrides(),
        parse_overrides(args.set),
    )


#: The site's outline given to the exploration lies this far inside the hall's walls, m.
BOUNDS_INSET_M = 0.15


def explored_overrides(world: str, seed: int) -> dict[str, Any]:
    """The settings of a world explored before its request: no floor plan (the map starts
    all unknown, the localization maps while it localizes), the semantic pass after it,
    and the site's outline as an operator gives it (its doors open on floor that goes on
    to the map's edge): the hall's inside, less `BOUNDS_INSET_M` (a frontier on a wall's
    face, where the map has a few free cells in the wall's line, is none: hall seed 1's
    explorer walked to three such in a row)."""
    hall = generate_world(seed, world).hall
    margin = -BOUNDS_INSET_M
    return {
        "semantic_map.floor_plan": "none",
        "mission.explore_semantic_pass": True,
        "mission.explore_bounds": [
            hall.min_xy[0] - margin, hall.min_xy[1] - margin,
            hall.max_xy[0] + margin, hall.max_xy[1] + margin,
        ],
    }  # fmt: skip


class ExplorationFailed(Exception):
    """The exploration before a world's request did not succeed: no request is made."""


#: Sim seconds an exploration may take (the mission's own budget ends it sooner).
EXPLORE_TIMEOUT_S = 2400.0


def explore_first(
    stack: ProcessStack, world: WorldDescription, seed: int, save: Path | None = None
) -> dict[str, Any]:
    """The exploration of world `seed` on its stack, and its map judged from truth;
    with `save`, the explored map written there (`dume map --export`'s file) when the
    exploration succeeded."""
    bus, keys = stack.bus, stack.keys
    wall0 = time.perf_counter()
    request = MissionRequest(request_id=f"explore-{seed}", task="explore")
    record = watch_mission(
        bus, keys, request, EXPLORE_TIMEOUT_S, _stage_line(seed), start_gate=True
    )
    final = record.changes[-1] if record.changes else None
    arts, people = read_map(bus)
    grid = bus.query(MAP_OCCUPANCY, None, OccupancyGrid, 30.0)
    aligned = map_alignment(grid, world)
    saved = ""
    if save is not None and final is not None and final.state == "succeeded":
        write_map_file(save, bus.query(MAP_EXPORT, None, MapFile, 30.0))
        saved = shown(save)
    return {
        "saved": saved,
        "outcome": final.state if final else f"no status ({record.ended})",
        "reason": (f"{final.reason} " if final and final.reason else "")
        + (final.detail if final else ""),
        "sim_s": round((record.end_ns - record.start_ns) / 1e9, 1),
        "localization": record.localization,
        "wall_s": round(time.perf_counter() - wall0, 1),
        **score_map(grid, world, aligned),
        **score_entities(world, arts, people),
        "aligned": score_entities(world, moved(arts, aligned), moved(people, aligned)),
    }


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _stage_line(seed: int) -> Progress:
    def on_progress(status: MissionStatus | None, _clock: Clock, changed: bool) -> None:
        if changed and status is not None:
            why = f" ({status.reason})" if status.reason else ""
            _say(
                f"    seed {seed} t={status.stamp_ns / 1e9:6.1f} s: {status.state} "
                f"{status.behaviour}{why}"
            )

    return on_progress


def run_world(args: argparse.Namespace, seed: int, seen: dict[str, set[str]]) -> WorldResult:
    """One world, start to teardown; never raises for a failed run (only on Ctrl-C)."""
    scenario = scenario_of(args)
    result = WorldResult(world=args.world, world_seed=seed, scenario=scenario)
    # the process in the name too: two evals started in one second keep their own maps
    map_name = f"eval-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{seed}"
    # A ConfigError (a settings file this process's schema no longer reads) stops the run.
    stack = ProcessStack(list(SERVICES), world_overrides(args, seed, map_name))
    wall0 = time.perf_counter()
    step = "start the stack"
    stats: Latest[SimStats] | None = None
    try:
        stack.start(timeout_s=START_TIMEOUT_S)
        result.setup_wall_s = round(time.perf_counter() - wall0, 2)
        bus, keys = stack.bus, stack.keys
        stats = bus.latest(keys.sim_stats, SimStats)
        how, path = map_source(args.map, args.world, seed)
        explored = how == "explore"
        if explored:
            step = "explore the world"
            result.exploration = explore_first(stack, read_world(bus), seed, path)
            if result.exploration["outcome"] != "succeeded":  # no request on half a map
                e = result.exploration
                raise ExplorationFailed(f"it ended {e['outcome']}: {e['reason']}")
        step = "read the world and the map"
        world, (arts, people) = read_world(bus), read_map(bus)
        pair = seeded_pair(arts, people, seed)
        request_result(result, pair, arts, people, world)
        request = MissionRequest(request_id=f"eval-{seed}", object=pair.object, person=pair.person)
        step = "run the mission"
        record: MissionRecord = watch_mission(
            bus, keys, request, args.timeout, _stage_line(seed), start_gate=not explored
        )
        evaluate(result, record, world)
        step = "draw the world"
        result.picture = f"worlds/seed-{seed}.png"
        world_picture(world, record, result, resolve(args.out) / result.picture)
        step = "read the running settings"
        for k, v in read_back(bus, keys).items():
            seen.setdefault(k, set()).add(v)
    except (BusError, PayloadError, TargetError, ExplorationFailed) as exc:
        result.error = f"could not {step}: {exc}"
    finally:
        if stats is not None and (last := stats.get()) is not None:
            result.lockstep_stalls = last.stalls
        result.services_down = sorted(
            n for n, p in stack.procs.items() if n != "router" and p.poll() is not None
        )
        stack.stop(timeout_s=STOP_TIMEOUT_S)
        remove_database(database_path(stack.config.semantic_map, map_name))
    result.logs = shown(stack.run_dir)
    if not result.succeeded:
        result.troubles = stack.troubles()
    if args.record:
        folder = run_dir(stack.config.recording, stack.run_id)
        result.recording = shown(folder)
        if not result.succeeded and result.sim_time_s > 0:
            result.failure_frames = failure_frames(folder, resolve(args.out), seed, result)
    return result


def failure_frames(folder: Path, out: Path, seed: int, result: WorldResult) -> list[str]:
    """The run drawn from its recording 3 s before it failed and when it did (paths
    relative to the report); none when the recording cannot be read."""
    from deploy.snapshot import snapshot

    drawn: list[str] = []
    end = result.sim_time_s
    for before in (3.0, 0.0):
        name = f"worlds/seed-{seed}-failure-{before:.0f}s.png"
        title = f"seed {seed}: {result.failure[:140]} (t = {end - before:.1f} s)"
        try:
            snapshot(folder, out / name, max(0.0, end - before), title)
        except (OSError, ValueError) as exc:
            _say(f"    seed {seed}: no failure frames: {exc}")
            return drawn
        drawn.append(name)
    return drawn


def map_start_text(map_arg: str) -> str:
    """The report's line on where each world's map started."""
    if map_arg == "truth":
        return (
            "seed-from-world (truth positions with noise, for an earlier mapping run: "
            "the truth ablation)"
        )
    explored = (
        "explored from nothing first (no floor plan, SLAM, the semantic pass), then the "
        "request on the robot's own map and estimated pose"
    )
    if map_arg == "explored":
        return f"each world {explored}"
    saved = map_arg == "saved"
    where = "var/saved-maps/ (or shipped with dume)" if saved else map_arg
    return (
        f"each world's saved map in {where} (an earlier exploration; no floor plan, the "
        f"pose estimated on the map's own grid); a world with none there {explored}, and "
        f"its map saved in {'var/saved-maps/' if saved else map_arg}"
    )


def run_eval(args: argparse.Namespace) -> int:
    out = resolve(args.out)
    seeds = [args.seed + i for i in range(args.worlds)]
    seen: dict[str, set[str]] = {}
    results: list[WorldResult] = []
    wall0 = time.perf_counter()

    def settings() -> dict[str, Any]:
        return {
            "world": args.world,
            "world seeds": f"{seeds[0]}..{seeds[-1]}" if seeds else "-",
            "scenario": scenario_of(args),
            "segmenter": ", ".join(sorted(seen.get("segmenter", {"not read"}))),
            "locomotion": ", ".join(sorted(seen.get("locomotion", {"not read"}))),
            "map start": map_start_text(args.map),
            "request": "a random mapped artifact and person per world (seeded by the world seed)",
            "timeout per world": f"{args.timeout:.0f} s sim",
            "extra settings": ", ".join(args.set) or "none",
            "wall time": f"{time.perf_counter() - wall0:.0f} s",
            **({"stopped early": stopped} if stopped else {}),
        }

    _say(f"dume eval: {len(seeds)} {args.world} worlds from seed {args.seed}, out {out}")
    summary: dict[str, Any] = {}
    stopped = ""
    with sigterm_interrupts():
        try:
            for i, seed in enumerate(seeds):
                r = run_world(args, seed, seen)
                results.append(r)
                ok = sum(x.succeeded for x in results)
                _say(
                    f"[{i + 1}/{len(seeds)}] seed {seed} {r.object or '-'} → {r.person or '-'}: "
                    f"{r.outcome} (mission {r.mission_state or '-'}) sim {r.sim_time_s:.1f} s "
                    f"wall {r.wall_time_s + r.setup_wall_s:.0f} s rtf {r.rtf:.2f} | "
                    f"{ok}/{i + 1} succeeded" + (f" | {r.failure}" if not r.succeeded else "")
                )
                summary = write_report(out, settings(), results)
        except KeyboardInterrupt:
            stopped = "interrupted"
        except ConfigError as exc:
            stopped = f"the settings no longer load (changed during the run?): {exc}"
    if stopped:
        _say(f"dume eval: stopped, {stopped}; the report covers the worlds that finished")
        summary = write_report(out, settings(), results)
    print(json.dumps(json_safe({**summary, "out": str(out), "stopped": stopped})))
    if stopped:
        return 130 if stopped == "interrupted" else 2
    return 0 if results and not any(r.error for r in results) else 1
