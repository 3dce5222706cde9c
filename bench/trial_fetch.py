"""The `fetch` trial: one bring-me over the full stack, the real mission deciding, the
sim's truth measuring what its manipulation algorithms achieved.

Small world, every service (the mission too), lockstep, dynamic locomotion: the run
`dume demo` makes, with probes; or a hall world with `dume eval --map truth`'s request
and map (`--world hall --world-seed N`: the eval's failures looked at closer). The
request goes to the mission as any client's does
(`bench.eval.run.watch_mission`, start-gated, so the run is the same at every seed); the
trial only watches:

- the mission's status: each stage's sim time;
- the base's trajectory (the sim's odometry) at the end of `approach_object`: the true
  bottle's (d − D_OPT, θ − θ_OPT) from the base, the visual servo's result;
- `wbc/status` and the robot's state (`Probe`, a thread): when the mission's `grasp`
  goal becomes active, the gripper's pose (forward kinematics of the measured joints)
  against the side grasp of the true bottle, where the jaws closed; whether the object
  was held after the pick;
- the world's events: when the person took the object (`HandoverTaken`) against when
  the mission felt the pull (its `release` goal after `present`); `samples_path` (the
  CLI: `var/trials/fetch-<world>-<seed>.handover.json`) saves the `wbc/status` samples
  of the handover (the pull detector's test data).

Nothing here decides for the robot: a failure is the mission's, with its reason.
"""

from __future__ import annotations

import contextlib
import json
import math
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bench.eval.judge import MissionRecord, stage_times, static_contacts
from bench.eval.run import read_map, read_world, start_gate_overrides, watch_mission
from bench.eval.targets import Pair, seeded_pair
from common import robot
from common.access import services_on
from common.bus import Bus
from common.config import Overrides, merged
from common.geometry import (
    FloatArray,
    inv_T,
    make_T,
    quat_xyzw_to_matrix,
    transform_points,
    wrap_angle,
    yaw_only,
)
from common.keys import SERVICES, RobotKeys
from common.messages.arrays import as_numpy
from common.messages.base import NS_PER_S
from common.messages.mission import MissionRequest
from common.messages.sim import HandoverTaken, ObjectDropped, RobotState, StateTruth
from common.messages.wbc import WbcStatus
from common.messages.world import Artifact, WorldDescription
from deploy.stack import ProcessStack
from services.mission.grasp_pose import plan_error
from services.wbc.reach import side_grasp

Figures = dict[str, Any]

OBJECT, PERSON = "bottle_1", "person_1"
#: Sim seconds the mission has for the whole request.
TIMEOUT_S = 240.0
#: The handover's samples go on this long past the release, ns of sim time.
AFTER_RELEASE_NS = 1_000_000_000
#: Wall seconds the probe waits for a `wbc/status` before looking at its stop flag.
POLL_S = 0.5


def fetch_settings(seed: int, db_dir: str, world: str = "small") -> dict[str, Any]:
    """The demo's small world (or `world`), in a throw-away map database seeded from the
    truth with noise (the noise seeded by the world's seed, as `dume eval --map truth`
    has it, in the hall), start-gated."""
    return merged(
        {
            "sim.world": world,
            "sim.world_seed": seed,
            "semantic_map.seed_noise_seed": 0 if world == "small" else seed,
            "sim.locomotion": "dynamic",
            "time.mode": "lockstep",
            "semantic_map.start": "seed-from-world",
            "semantic_map.reset": True,
            "semantic_map.dir": db_dir,
            "semantic_map.name": "fetch",
            "recording.enabled": False,
        },
        start_gate_overrides(),
    )


class Probe:
    """Watches `wbc/status` on a thread: keeps every sample, and the robot's state and the
    base's truth at the first sample with an active `grasp` goal (where the jaws close)."""

    def __init__(self, bus: Bus, keys: RobotKeys) -> None:
        self._status = bus.fifo(keys.wbc_status, WbcStatus, maxlen=1 << 20)
        self._state = bus.latest(keys.state, RobotState)
        self._truth = bus.latest(keys.state_truth, StateTruth)
        self.samples: list[WbcStatus] = []
        self.at_grasp: tuple[WbcStatus, RobotState, StateTruth] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fetch-probe", daemon=True)

    def __enter__(self) -> Probe:
        self._thread.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self._status.undeclare()
        self._state.undeclare()
        self._truth.undeclare()

    def _run(self) -> None:
        while not self._stop.is_set():
            st = self._status.pop(timeout_s=POLL_S)
            if st is None:
                continue
            self.samples.append(st)
            if self.at_grasp is None and any(
                g.kind == "grasp" and g.state == "active" for g in st.goals
            ):
                state, truth = self._state.get(), self._truth.get()
                if state is not None and truth is not None:
                    self.at_grasp = (st, state, truth)


def _T_world_base(position: Any, quat_xyzw: Any) -> FloatArray:
    return make_T(quat_xyzw_to_matrix(np.asarray(quat_xyzw, float)), np.asarray(position, float))


def truth_grasp(truth: Artifact, T_world_base: FloatArray) -> FloatArray:
    """The side grasp of the true object: on its axis at 3/8 of its height, approached
    from the shoulder's side (what the grasp planner aims for, seen from the base)."""
    centre = np.array(truth.position) + np.array([0.0, 0.0, 0.375 * truth.shape.height])
    sx, sz = robot.arm_plane()["shoulder"]
    shoulder = T_world_base[:3, :3] @ np.array([sx, 0.0, sz]) + T_world_base[:3, 3]
    return side_grasp(centre, (centre - shoulder)[:2])


def approach_errors(record: MissionRecord, truth: Artifact) -> Figures:
    """The true object's (d − D_OPT, θ − θ_OPT) from the base when the approach ended."""
    ends = [c.stamp_ns for c in record.changes if c.behaviour == "pose_estimation"]
    if not ends or not record.trajectory:
        return {}
    sample = min(record.trajectory, key=lambda s: abs(s[0] - ends[0]))
    T_world_by = yaw_only(_T_world_base(sample[1:4], sample[4:8]))
    bx, by, _ = transform_points(inv_T(T_world_by), truth.position)[0]
    return {
        "truth_d_err_m": round(math.hypot(bx, by) - robot.D_OPT_M, 4),
        "truth_theta_err_deg": round(
            math.degrees(wrap_angle(math.atan2(by, bx) - robot.THETA_OPT_RAD)), 2
        ),
    }


def grasp_errors(at: tuple[WbcStatus, RobotState, StateTruth] | None, truth: Artifact) -> Figures:
    """Where the jaws closed (the measured TCP, the base where the sim had it at most
    20 ms before) against the true object's side grasp."""
    if at is None:
        return {}
    status, state, base = at
    T_wb = _T_world_base(base.base_position_in_world, base.base_orientation_xyzw)
    tcp = T_wb @ robot.frame_in_base(as_numpy(state.q).astype(float), robot.TCP_FRAME).homogeneous
    want = truth_grasp(truth, T_wb)
    dist, angle = plan_error(tcp, want)
    return {
        "at_s": round(state.stamp_ns / NS_PER_S, 3),
        "status_lag_ms": round((state.stamp_ns - status.stamp_ns) / 1e6, 1),
        "error_m": round(dist, 4),
        "error_xy_m": round(float(np.linalg.norm(tcp[:2, 3] - want[:2, 3])), 4),
        "error_z_m": round(float(tcp[2, 3] - want[2, 3]), 4),
        "error_deg": round(math.degrees(angle), 2),
    }


def handover_figures(
    record: MissionRecord, samples: list[WbcStatus]
) -> tuple[Figures, list[dict[str, Any]]]:
    """When the pull was felt against when the person took the object, and the
    handover's `wbc/status` samples (from `release_object` to `AFTER_RELEASE_NS` past
    the release)."""
    start = next((c.stamp_ns for c in record.changes if c.behaviour == "release_object"), None)
    taken = next((e for e in record.events if isinstance(e, HandoverTaken)), None)
    if start is None:
        return {}, []
    # The controller lists its recent goals: the release is one it had not before.
    before = {g.goal_id for s in samples if s.stamp_ns < start for g in s.goals}
    felt = next(
        (s.stamp_ns for s in samples if s.stamp_ns >= start
         and any(g.kind == "release" and g.goal_id not in before for g in s.goals)),
        None,
    )  # fmt: skip
    # on past the release for a while: the load leaving the jaws (taken, or fallen)
    end = math.inf if felt is None else felt + AFTER_RELEASE_NS
    window = [s for s in samples if start <= s.stamp_ns <= end]
    out = [
        {"stamp_ns": s.stamp_ns, "wrench": list(s.gripper_wrench), "effort": s.gripper_effort,
         "held": s.held, "taken": taken is not None and s.stamp_ns >= taken.stamp_ns}
        for s in window
    ]  # fmt: skip
    figures = {
        "pull_felt_s": None if felt is None else round(felt / NS_PER_S, 3),
        "taken_s": None if taken is None else round(taken.stamp_ns / NS_PER_S, 3),
        "felt_after_taken_s": None
        if felt is None or taken is None
        else round((felt - taken.stamp_ns) / NS_PER_S, 3),
    }
    return figures, out


def held_after_pick(record: MissionRecord, samples: list[WbcStatus]) -> bool | None:
    """Whether the controller held the object when the mission set off to the person."""
    start = next((c.stamp_ns for c in record.changes if c.behaviour == "bring_to_user"), None)
    if start is None:
        return None
    after = next((s for s in samples if s.stamp_ns >= start), None)
    dropped = any(isinstance(e, ObjectDropped) and e.stamp_ns <= start for e in record.events)
    return after is not None and after.held and not dropped


def request_ids(
    world: WorldDescription, seeded: Callable[[], Pair], asked: tuple[str, str] = ("", "")
) -> tuple[str, str]:
    """The fetch's object and person: `asked` (ids of the world's, each or both; a shift's
    failing pair looked at again), else the small world's `OBJECT` for `PERSON`, else
    `dume eval`'s pair for the world (`seeded()`). An id the world lacks is a ValueError."""
    if all(asked):
        obj, person = asked
    else:
        pair = Pair(OBJECT, PERSON, math.nan) if world.name == "small" else seeded()
        obj, person = asked[0] or pair.object, asked[1] or pair.person
    if obj not in {a.id for a in world.artifacts}:
        raise ValueError(f"no artifact {obj} in {world.name} seed {world.seed}")
    if person not in {p.id for p in world.people}:
        raise ValueError(f"no person {person} in {world.name} seed {world.seed}")
    return obj, person


def run_fetch(
    seed: int = 1,
    overrides: Overrides | None = None,
    samples_path: Path | None = None,
    hosts: Overrides | None = None,
    world_name: str = "small",
    asked: tuple[str, str] = ("", ""),
) -> Figures:
    """One fetch on a fresh stack; its figures (JSON-ready). The request is `asked`
    (`request_ids`), else the small world's `OBJECT` for `PERSON`, another world's
    `dume eval`'s (`seeded_pair`). `hosts`: the
    stack split over two hosts (`zenoh.side`), with these link settings (`zenoh.certs`,
    `zenoh.link_port`): two routers, the map behind the link; the trial's own session
    on the robot's router, where the world's truth is."""
    out: Figures = {"trial": "fetch", "world": world_name, "world_seed": seed}
    with tempfile.TemporaryDirectory(prefix="dume-fetch-") as db, contextlib.ExitStack() as on:
        settings = merged(fetch_settings(seed, db, world_name), overrides or {})
        if hosts is None:
            stack = on.enter_context(ProcessStack(list(SERVICES), settings))
        else:
            out["hosts"] = "robot, station"
            # both hosts' processes first: a service may wait for one behind the link
            split = [
                ProcessStack(services_on(n), merged(settings, hosts, {"zenoh.side": n}))
                for n in ("robot", "station")
            ]
            for s in split:
                on.callback(s.stop)
                s.launch()
            for s in split:
                s.wait_ready(s.services)
            stack = split[0]
        bus, keys = stack.bus, stack.keys
        world = read_world(bus, timeout_s=30.0)
        obj, person = request_ids(world, lambda: seeded_pair(*read_map(bus), seed), asked)
        out["request"] = f"{obj} for {person}"
        truth = next(a for a in world.artifacts if a.id == obj)
        request = MissionRequest(request_id=f"fetch-{seed}", object=obj, person=person)
        with Probe(bus, keys) as probe:
            record = watch_mission(bus, keys, request, TIMEOUT_S, start_gate=True)
    final = record.changes[-1] if record.changes else None
    handover, samples = handover_figures(record, probe.samples)
    if samples_path is not None:
        samples_path.write_text(json.dumps(samples))
    return out | {
        "success": final is not None and final.state == "succeeded",
        "mission": {
            "state": final.state if final else "none",
            "reason": final.reason if final else record.ended,
            "detail": final.detail if final else "",
        },
        "stage_s": {k: round(v, 2) for k, v in stage_times(record.changes).items()},
        "approach": approach_errors(record, truth),
        "grasp": grasp_errors(probe.at_grasp, truth),
        "held_after_pick": held_after_pick(record, probe.samples),
        "handover": handover,
        "handed_over": any(
            isinstance(e, HandoverTaken) and e.object_id == truth.id for e in record.events
        ),
        "contacts_static": len(static_contacts(record.events, world)),
        "wall_s": round(record.wall_s, 1),
    }
