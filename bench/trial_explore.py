"""`dume trial explore`: exploration from nothing, its map scored against the sim's truth.

`explore_run` starts router + sim + wbc + perception + semantic_map + navigation +
mission as processes (lockstep, dynamic locomotion, the network segmenter), the map
empty in a fresh database with no floor plan (`semantic_map.floor_plan = "none"`: every
cell unknown until the head camera's depth shows floor or an obstacle there), navigation
on the map's occupancy, and the base from the sim's truth by default (`wbc.base_state =
"truth"`, the ablation: the robot is told where it is, so the exploration is measured
apart from localization; `--set wbc.base_state=estimate` explores on the robot's own
odometry and SLAM, the localization service then among the processes). It submits
`{"task": "explore"}` to the mission while the sim holds at t = 0
(`bench.eval.run.watch_mission`, start gate), follows its status to the end, then reads
the mission's job status (goals, path walked, known floor) and the map's grid.

Figures: the outcome and its reason, sim and wall time, goals walked / chosen / failed,
path walked, the known-free floor against the room's (truth), and the occupancy's
agreement with the floor plan (`bench.map_agreement`: IoU of the occupied cells within
5 cm, false and missed obstacle cells) over the area reachable from the start (the
floor connected to the robot's start in the truth, grown by 10 cm to take in the
walls' faces). The truth is read here only, through `dume/world/description`.
"""

from __future__ import annotations

import math
import re
import sys
import tempfile
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from bench.eval.explored import moved, score_entities
from bench.eval.run import Progress, read_map, start_gate_overrides, watch_mission
from bench.map_agreement import FREE, UNKNOWN, Alignment, agreement, align_to_truth, truth_on
from common.bus import Latest
from common.config import Overrides, merged
from common.keys import MAP_OCCUPANCY, WORLD_DESCRIPTION
from common.messages import as_numpy
from common.messages.mission import MissionRequest, MissionStatus, PatrolRequest, PatrolStatus
from common.messages.semantic_map import OccupancyGrid
from common.messages.sim import Clock
from common.messages.world import WorldDescription
from deploy.stack import ProcessStack

SERVICES = ["sim", "wbc", "perception", "semantic_map", "navigation", "mission"]
#: Sim seconds the trial follows the exploration (the mission's own budget,
#: `mission.explore_max_s`, ends it sooner).
SIM_TIMEOUT_S = 2400.0


def explore_settings(world: str, seed: int, db_dir: str) -> dict[str, Any]:
    return {
        "sim.world": world,
        "sim.world_seed": seed,
        "sim.locomotion": "dynamic",
        "wbc.base_state": "truth",
        "semantic_map.dir": db_dir,
        "semantic_map.name": "explore",
        "semantic_map.reset": True,
        "semantic_map.start": "empty",
        "semantic_map.floor_plan": "none",
        "navigation.map_source": "map",
        "recording.enabled": False,
    }


def reachable_truth(world: WorldDescription, shape: tuple[int, int], res: float,
                    origin: tuple[float, float]) -> NDArray[np.bool_]:  # fmt: skip
    """The cells of the map's grid the robot could reach and see from its start: the truth's
    free floor inside the hall 8-connected to the start, grown by 2 cells (the obstacles'
    faces). Inside the hall: its doors open on the floor that goes on to the grid's edge,
    which the exploration is bounded from (`mission.explore_bounds`)."""
    occupied = truth_on(world, shape, res, origin)
    x, y = world.robot_start.x, world.robot_start.y
    iy, ix = math.floor((y - origin[1]) / res), math.floor((x - origin[0]) / res)
    cy = origin[1] + (np.arange(shape[0]) + 0.5) * res
    cx = origin[0] + (np.arange(shape[1]) + 0.5) * res
    (x0, y0), (x1, y1) = world.hall.min_xy, world.hall.max_xy
    inside = ((cy >= y0) & (cy <= y1))[:, None] & ((cx >= x0) & (cx <= x1))[None, :]
    labels, _n = ndimage.label(~occupied & inside, structure=np.ones((3, 3)))
    floor = labels == labels[iy, ix]
    return np.asarray(ndimage.binary_dilation(floor, iterations=2), bool)


def map_alignment(grid: OccupancyGrid, world: WorldDescription) -> Alignment:
    """The rigid motion laying the map's obstacles best on the truth's
    (`map_agreement.align_to_truth`, over the reachable area)."""
    cells = np.asarray(as_numpy(grid.cells), np.uint8)
    res, origin = grid.resolution_m, grid.origin_xy
    area = reachable_truth(world, cells.shape, res, origin)
    truth = truth_on(world, cells.shape, res, origin) & area
    return align_to_truth(np.where(area, cells, UNKNOWN).astype(np.uint8), truth, res, origin)


def score_map(
    grid: OccupancyGrid, world: WorldDescription, aligned: Alignment | None = None
) -> dict[str, Any]:
    """The map's grid against the truth over the reachable area (module docstring); with
    `aligned` (`map_alignment`), its IoU once so moved too, and how far it moved."""
    cells = np.asarray(as_numpy(grid.cells), np.uint8)
    res, origin = grid.resolution_m, grid.origin_xy
    area = reachable_truth(world, cells.shape, res, origin)
    truth = truth_on(world, cells.shape, res, origin) & area
    mine = np.where(area, cells, UNKNOWN).astype(np.uint8)
    floor = area & ~ndimage.binary_dilation(truth, iterations=2)
    known_free = float(np.sum((cells == FREE) & floor)) * res * res
    floor_m2 = float(np.sum(floor)) * res * res
    out = agreement(mine, truth, res)
    if aligned is not None:
        moved = np.where(area, aligned.warp(cells, res, origin), UNKNOWN).astype(np.uint8)
        out_aligned = agreement(moved, truth, res)
    return {
        "known_free_m2": round(float(np.sum(cells == FREE)) * res * res, 1),
        "floor_m2": round(floor_m2, 1),
        "floor_known_share": round(known_free / floor_m2, 3) if floor_m2 else None,
        "occupancy_iou_5cm": out["iou_within_5cm"],
        "false_occupied_cells": out["false_occupied_cells"],
        "missed_obstacle_cells": out["truth_seen_missed_cells"],
        "unknown_outside_m2": round(float(np.sum((cells != UNKNOWN) & ~area)) * res * res, 1),
        **(
            {
                "occupancy_iou_5cm_aligned": out_aligned["iou_within_5cm"],
                "frame_yaw_deg": round(float(np.degrees(aligned.yaw_rad)), 2),
                "frame_shift_cm": round(100 * float(np.hypot(*aligned.shift_xy)), 1),
            }
            if aligned is not None
            else {}
        ),
    }


def _progress(job: Latest[PatrolStatus], jobs: dict[str, PatrolStatus]) -> Progress:
    """The request's changes, and the job's own status every 30 s of sim time, on stderr;
    `jobs` keeps each task's latest status (the exploration's, then its semantic pass's:
    a patrol's)."""

    def show(status: MissionStatus | None, clock: Clock, changed: bool) -> None:
        now = job.get()
        if now is not None:
            jobs[now.task] = now
        if status is None or not (changed or clock.stamp_ns // 1_000_000_000 % 30 == 0):
            return
        said = status.detail if changed or now is None else (
            f"{now.waypoint} of {now.waypoints} goals, {now.travelled_m:.1f} m walked, "
            f"{now.known_m2:.1f} m² known")  # fmt: skip
        line = f"  t={clock.stamp_ns / 1e9:7.1f} s {status.state} {status.behaviour}: {said}"
        print(line, file=sys.stderr, flush=True)

    return show


def explore_run(
    world: str = "small",
    seed: int = 0,
    overrides: Overrides | None = None,
    db_dir: str | None = None,
    grid_out: str | None = None,
) -> dict[str, Any]:
    """Run an exploration on a fresh stack; the figures (JSON-ready). `grid_out`: a .npz
    to keep the final grid (`cells`, `res`, `origin`) and the truth's (`truth`, `area`)."""
    tmp = None
    if db_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="dume-explore-")
        db_dir = tmp.name
    # The sim held at t = 0 until the request waits in the mission, so the mission takes
    # it at its first tick in every run.
    settings = merged(explore_settings(world, seed, db_dir), start_gate_overrides(),
                      overrides or {})  # fmt: skip
    own = settings.get("wbc.base_state") == "estimate"
    out: dict[str, Any] = {"trial": "explore", "world": world, "world_seed": seed,
                           "base_state": settings.get("wbc.base_state")}  # fmt: skip
    # The robot on its own odometry localizes, and maps while it does (SLAM: the map has
    # no static layer), in the localization service; the truth ablation needs none.
    s = ProcessStack([*SERVICES, "localization"] if own else SERVICES, settings)
    try:
        s.start(timeout_s=180.0)
        truth = s.bus.query(WORLD_DESCRIPTION, None, WorldDescription, 30.0)
        request = MissionRequest(request_id="explore", task="explore")
        job_now = s.bus.latest(s.keys.mission_patrol_status, PatrolStatus)
        jobs: dict[str, PatrolStatus] = {}
        show = _progress(job_now, jobs)
        record = watch_mission(s.bus, s.keys, request, SIM_TIMEOUT_S, show, start_gate=True)
        job = s.bus.query(s.keys.mission_patrol, PatrolRequest(action="status"), PatrolStatus)
        jobs[job.task] = job
        grid = s.bus.query(MAP_OCCUPANCY, None, OccupancyGrid, 30.0)
        artifacts, people = read_map(s.bus)
    finally:
        s.stop()
        if tmp is not None:
            tmp.cleanup()
    last = record.changes[-1] if record.changes else None
    aligned = map_alignment(grid, truth)
    # The exploration's own figures: its final sentence's counts ("9 goal(s) walked of 9
    # chosen (0 failed)"; the last job status may be its semantic pass's), its distance
    # from its last status seen (a pass that followed took its place).
    said = last.detail if last else ""
    failed = re.search(r"\((\d+) failed\)", said)
    counts = re.search(r"(\d+) goal\(s\) walked of (\d+) chosen", said)
    explored = jobs.get("explore", job)
    passed = jobs.get("patrol")
    sim_s = (record.end_ns - record.start_ns) / 1e9
    out |= {
        "outcome": last.state if last else "none",
        "reason": last.reason if last else record.ended,
        "detail": last.detail if last else record.ended,
        "ended": record.ended,  # why the watch stopped early ("" when the job ended)
        "watch_lapses": record.lapses,  # this client's own link, gone and back (sim s)
        "sim_s": round(sim_s, 1),
        "wall_s": round(record.wall_s, 1),
        "rtf": round(sim_s / record.wall_s, 3) if record.wall_s > 0 else None,
        "goals_walked": int(counts.group(1)) if counts else explored.waypoint,
        "goals_chosen": int(counts.group(2)) if counts else explored.waypoints,
        "goals_failed": int(failed.group(1)) if failed else None,
        "travelled_m": round(explored.travelled_m, 1),
        "semantic_pass": None
        if passed is None
        else {"viewpoints": passed.waypoints, "travelled_m": round(passed.travelled_m, 1)},
        **score_map(grid, truth, aligned),
        # What the map holds, judged from the truth: as the map has it, and as its
        # alignment to the truth moves it (a map made while localizing is in its own frame).
        "entities": score_entities(truth, artifacts, people),
        "entities_aligned": score_entities(
            truth, moved(artifacts, aligned), moved(people, aligned)
        ),
    }
    if out["outcome"] != "succeeded":
        out["logs"] = str(s.run_dir)
        out["troubles"] = s.troubles()
    if grid_out:
        cells = np.asarray(as_numpy(grid.cells), np.uint8)
        shape, res, origin = cells.shape, grid.resolution_m, grid.origin_xy
        np.savez_compressed(
            grid_out, cells=cells, res=res, origin=np.array(origin),
            truth=truth_on(truth, shape, res, origin),
            area=reachable_truth(truth, shape, res, origin),
        )  # fmt: skip
    return out
