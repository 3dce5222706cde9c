"""The `fetch` trial: the mission's manipulation algorithms over the real stack, scripted.

Small world, `["sim", "wbc", "perception", "semantic_map", "navigation"]`, lockstep, dynamic
locomotion, the network segmenter, the map seeded from the world. The driver (a lockstep
participant, `bench.trial_driver`) plays the mission's part:

nav ArtifactStandoff(bottle_1) → Posture(look), walk on the trial's cmd_vel →
`ApproachController` on the wrist camera's detections of bottle_1 → arrived: manipulate,
settle, a fresh detection → `grasp_from_detection` → ready → Reach → Grasp → lift →
held? → stow → walk on navigation's → nav PersonHandover(person_1) → manipulate,
Posture(handover), hold still → `PullDetector` on `wbc/status` → Release → back off.

The robot decides from its own sensing only; the sim's truth (world description,
`HandoverTaken`, `ObjectDropped`) is read for the figures: the approach's final d/θ error,
the grasp pose's error against the truth bottle, held, each stage's sim time, and when
the pull was felt against when the person took it. `samples_path` saves the `wbc/status`
samples of the handover (the pull detector's test data).
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench.trial_driver import Driver, Script, trial_settings
from common.clients import ClientError, NavClient
from common.config import Overrides, merged
from common.geometry import FloatArray, quat_xyzw_to_matrix, wrap_angle
from common.keys import WORLD_DESCRIPTION, WORLD_EVENTS
from common.messages.base import NS_PER_S
from common.messages.navigation import (
    ArtifactStandoff,
    NavGoal,
    NavStatus,
    PersonHandover,
)
from common.messages.perception import Detection, Detections
from common.messages.sim import HandoverTaken, ObjectDropped, Odom, WorldEvents
from common.messages.wbc import Grasp, Posture, Reach, Release, WbcMode, WbcModeName
from common.messages.world import Cylinder, WorldDescription
from common.robot import D_OPT_M, THETA_OPT_RAD, arm_plane
from common.sightings import pick_detection
from deploy.stack import ProcessStack
from services.mission.approach import ApproachController, Sighting
from services.mission.grasp_pose import GraspPoseError, grasp_from_detection, plan_error
from services.mission.handover_feel import PullDetector
from services.wbc.reach import side_grasp

Figures = dict[str, Any]

CAMERA = "camera_wrist"
CAMERA_PERIOD_NS = 100_000_000
OBJECT, PERSON = "bottle_1", "person_1"
SERVICES = ["sim", "wbc", "perception", "semantic_map", "navigation"]


def fetch_settings(seed: int, db_dir: str) -> dict[str, Any]:
    participants = {"perception": 0.1, "semantic_map": 0.1, "navigation": 0.05}
    settings = trial_settings("small", seed, 0.002)
    settings["time.participants"] |= {
        name: {"role": "periodic", "period_s": period, "latency_s": period}
        for name, period in participants.items()
    }
    return merged(
        settings,
        {
            "sim.cameras": ["camera_head", "camera_wrist"],
            "semantic_map.start": "seed-from-world",
            "semantic_map.reset": True,
            "semantic_map.dir": db_dir,
            "semantic_map.name": "fetch",
            # The map stays as seeded: the network segmenter calls the robot's own arm
            # (and bits of tables) a person in both cameras, and the map would fuse those
            # into people (new ones that navigation keeps clear of, and person_1 moved
            # onto them).
            "semantic_map.cameras": [],
            "navigation.map_source": "map",
            "wbc.mode_source": "trial",
            "wbc.cmd_vel_source": "navigation",
        },
    )


def _T(odom: Odom) -> FloatArray:
    T = np.eye(4)
    T[:3, :3] = quat_xyzw_to_matrix(np.array(odom.base_orientation_xyzw))
    T[:3, 3] = odom.base_position_in_world
    return T


class Rig:
    """What the fetch script needs beyond the driver: modes with a source, nav goals, the
    wrist camera's detections (waited for in lockstep), truth for the figures."""

    def __init__(self, d: Driver) -> None:
        self.d = d
        bus, keys = d.bus, d.keys
        self.world = bus.query(WORLD_DESCRIPTION, None, WorldDescription, timeout_s=30.0)
        self.truth = next(a for a in self.world.artifacts if a.id == OBJECT)
        self._mode = bus.publisher(keys.wbc_mode, WbcMode, "control")
        self.nav = bus.latest(keys.nav_status, NavStatus, history=8)
        self.nav_goals = NavClient(bus, keys, 30.0)
        self.dets = bus.fifo(keys.detections, Detections, maxlen=1000)
        self.events = bus.fifo(WORLD_EVENTS, WorldEvents, maxlen=100_000)
        self.wrist: Detections | None = None
        self.taken: HandoverTaken | None = None
        self.dropped: list[ObjectDropped] = []
        self.world_plan = True  # grasp plans in the world (else in `base`)

    def mode(self, mode: WbcModeName, source: str = "trial") -> None:
        self._mode.put(WbcMode(stamp_ns=self.d.t_ns, mode=mode, cmd_vel_source=source))

    def poll_events(self) -> None:
        for w in self.events.drain():
            for e in w.events:
                if isinstance(e, HandoverTaken) and self.taken is None:
                    self.taken = e
                elif isinstance(e, ObjectDropped):
                    self.dropped.append(e)

    def wrist_detections(self) -> Detections | None:
        """The wrist camera's Detections that take effect now (stamped one period back),
        waited for at each camera tick; the newest such otherwise."""
        t = self.d.t_ns
        if t % CAMERA_PERIOD_NS == 0 and t >= CAMERA_PERIOD_NS:
            want = t - CAMERA_PERIOD_NS
            while self.wrist is None or self.wrist.stamp_ns < want:
                msg = self.dets.pop(timeout_s=60.0)
                if msg is None:
                    raise TimeoutError(f"no wrist detections stamped {want} within 60 s")
                if msg.camera == CAMERA and msg.stamp_ns <= want:
                    self.wrist = msg
        return self.wrist

    def target(self, dets: Detections | None) -> Detection | None:
        """bottle_1 among the detections: the bottle nearest its (truth) place."""
        if dets is None:
            return None
        there = self.truth.position[:2]  # stands in for the map's entry (seeded)
        return pick_detection(dets.detections, "bottle", (there[0], there[1]), math.inf)

    def go(self, goal: NavGoal, timeout_s: float, out: Figures, name: str) -> Script:
        try:  # sent once: navigation takes a goal sent before its map
            goal_id = self.nav_goals.send(goal)
        except ClientError as exc:
            out["failed_at"] = f"{name}: refused: {exc}"
            return
        self.mode("walk", "navigation")
        end = self.d.t + timeout_s
        while self.d.t < end:
            st = self.nav.get()
            if st is not None and st.goal_id == goal_id and st.state not in ("active", "idle"):
                if st.state != "succeeded":
                    out["failed_at"] = f"{name}: {st.state} {st.reason} {st.detail}"
                return
            yield
        out["failed_at"] = f"{name}: no result in {timeout_s} s"

    def arm(self, goal: Any, timeout_s: float, out: Figures, name: str) -> Script:
        g = yield from self.d.finish(self.d.goal(goal), timeout_s)
        if g is None or g.state != "succeeded":
            out["failed_at"] = f"{name}: " + ("timeout" if g is None else f"{g.state} {g.reason}")

    def truth_errors(self) -> tuple[float, float]:
        """(d − D_OPT, θ − θ_OPT) of the bottle's true axis from the base now (truth)."""
        assert self.d.odom is not None
        T = _T(self.d.odom)
        yaw = math.atan2(T[1, 0], T[0, 0])
        v = np.array(self.truth.position[:2]) - T[:2, 3]
        c, s = math.cos(yaw), math.sin(yaw)
        bx, by = c * v[0] + s * v[1], -s * v[0] + c * v[1]
        return math.hypot(bx, by) - D_OPT_M, wrap_angle(math.atan2(by, bx) - THETA_OPT_RAD)

    def truth_grasp(self, T_world_base: FloatArray) -> FloatArray:
        """The side grasp of the true bottle: on its axis at 3/8 of its height, from the
        shoulder's side (what `bench.wbc_harness.grasp_plan` holds, seen from here)."""
        shape = self.truth.shape
        h = shape.height if isinstance(shape, Cylinder) else 2 * shape.half_size[2]
        centre = np.array(self.truth.position) + np.array([0.0, 0.0, 0.375 * h])
        sx, sz = arm_plane()["shoulder"]
        shoulder = T_world_base[:3, :3] @ np.array([sx, 0.0, sz]) + T_world_base[:3, 3]
        return side_grasp(centre, (centre - shoulder)[:2])


def _stage(out: Figures, name: str, t0: float, d: Driver) -> float:
    out.setdefault("stage_s", {})[name] = round(d.t - t0, 2)
    return d.t


def fetch(
    d: Driver, out: Figures, samples: list[dict[str, Any]], world_plan: bool = True
) -> Script:
    rig = Rig(d)
    rig.world_plan = world_plan
    t0 = d.t
    yield from rig.go(ArtifactStandoff(artifact_id=OBJECT), 150.0, out, "navigate_to_object")
    t0 = _stage(out, "navigate_to_object", t0, d)
    if "failed_at" in out:
        return
    yield from approach(d, rig, out)
    t0 = _stage(out, "approach_object", t0, d)
    if "failed_at" in out:
        return
    yield from pick(d, rig, out)
    t0 = _stage(out, "pick_object", t0, d)
    if "failed_at" in out:
        return
    yield from rig.go(PersonHandover(person_id=PERSON), 150.0, out, "bring_to_user")
    t0 = _stage(out, "bring_to_user", t0, d)
    if "failed_at" in out:
        return
    yield from handover(d, rig, out, samples)
    _stage(out, "release_object", t0, d)


def approach(d: Driver, rig: Rig, out: Figures) -> Script:
    rig.mode("walk", "trial")
    d.cmd(0.0)
    yield from rig.arm(Posture(name="look"), 8.0, out, "look")
    if "failed_at" in out:
        return
    ctrl = ApproachController()
    ctrl.reset(d.t)
    seen_frames = 0
    while True:
        det = rig.target(rig.wrist_detections())
        seen = None
        if det is not None and rig.wrist is not None:
            seen = Sighting(det.d_obj, det.theta_obj, rig.wrist.stamp_ns / NS_PER_S)
            seen_frames += d.t_ns % CAMERA_PERIOD_NS == 0
        cmd = ctrl.step(d.t, seen)
        d.cmd(cmd.vx, cmd.vy, cmd.wz)
        if cmd.state in ("arrived", "failed"):
            break
        yield
    d.cmd(0.0)
    out["approach"] = {"state": cmd.state, "reason": cmd.reason, "frames_seen": seen_frames}
    if cmd.state != "arrived":
        out["failed_at"] = f"approach_object: {cmd.reason}"
        return
    err = ctrl.errors()
    truth = rig.truth_errors()
    out["approach"] |= {
        "perceived_d_err_m": round(err[0], 4) if err else None,
        "perceived_theta_err_deg": round(math.degrees(err[1]), 2) if err else None,
        "truth_d_err_m": round(truth[0], 4),
        "truth_theta_err_deg": round(math.degrees(truth[1]), 2),
    }


def pick(d: Driver, rig: Rig, out: Figures) -> Script:
    rig.mode("manipulate")
    yield from d.wait(1.0)  # trot → stand, settled
    settled = d.t_ns
    det = None
    while det is None or rig.wrist is None or rig.wrist.stamp_ns < settled:
        det = rig.target(rig.wrist_detections())
        if d.t_ns > settled + 2 * NS_PER_S:
            out["failed_at"] = "pose_estimation: no fresh detection of the bottle"
            return
        yield
    frame = rig.wrist
    T_wb = np.array(frame.T_world_base).reshape(4, 4)
    try:  # world frame with the base pose at capture; `base` (ᴮH_G, base_yaw) without
        plan = grasp_from_detection(det, frame.stamp_ns, T_wb if rig.world_plan else None)
    except GraspPoseError as exc:
        out["failed_at"] = f"pose_estimation: {exc.reason}"
        return
    dist, angle = plan_error(plan.in_world(T_wb), rig.truth_grasp(T_wb))
    truth_c = rig.truth_grasp(T_wb)[:3, 3]
    plan_c = plan.in_world(T_wb)[:3, 3]
    out["grasp_plan"] = {
        "kind": plan.kind,
        "frame": plan.frame,
        "error_m": round(dist, 4),
        "error_xy_m": round(float(np.linalg.norm(plan_c[:2] - truth_c[:2])), 4),
        "error_z_m": round(float(plan_c[2] - truth_c[2]), 4),
        "error_deg": round(math.degrees(angle), 2),
        "axis_fallback": det.axis_fallback,
        "fit_rms_m": round(det.fit_rms_m, 4),
    }
    lift = plan.in_world(T_wb).copy()
    lift[2, 3] += 0.10
    lift_goal = Reach(H=tuple(float(x) for x in lift.ravel()), frame="world", stamp_ns=0,
                      pregrasp_m=0.0)  # fmt: skip
    steps: list[tuple[str, Any, float]] = [
        ("ready", Posture(name="ready"), 6.0),
        ("reach", plan.reach(), 10.0),
        ("grasp", Grasp(max_effort=4.0), 4.0),
        ("lift", lift_goal, 6.0),
        ("stow", Posture(name="stow"), 6.0),
    ]
    for name, goal, timeout in steps:
        yield from rig.arm(goal, timeout, out, name)
        if "failed_at" in out:
            break
    assert d.status is not None
    rig.poll_events()
    out["held_after_pick"] = bool(d.status.held and not rig.dropped)
    if "failed_at" not in out and not out["held_after_pick"]:
        out["failed_at"] = "pick_object: not held after stow"


def handover(d: Driver, rig: Rig, out: Figures, samples: list[dict[str, Any]]) -> Script:
    rig.mode("manipulate")
    yield from d.wait(0.5)
    yield from rig.arm(Posture(name="handover"), 8.0, out, "handover")
    if "failed_at" in out:
        return
    yield from d.wait(0.3)
    assert d.status is not None
    feel = PullDetector()
    feel.reset(d.status)
    start = d.t
    felt_ns = None
    while d.t < start + 20.0:
        yield
        assert d.status is not None
        st = d.status
        rig.poll_events()
        samples.append({"stamp_ns": st.stamp_ns, "wrench": list(st.gripper_wrench),
                        "effort": st.gripper_effort, "held": st.held,
                        "taken": rig.taken is not None})  # fmt: skip
        if feel.update(st):
            felt_ns = feel.tripped_at_ns
            break
    taken = rig.taken
    out["handover"] = {
        "pull_felt_s": None if felt_ns is None else round(felt_ns / NS_PER_S, 3),
        "taken_s": None if taken is None else round(taken.stamp_ns / NS_PER_S, 3),
        "felt_after_taken_s": None
        if felt_ns is None or taken is None
        else round((felt_ns - taken.stamp_ns) / NS_PER_S, 3),
        "baseline_force_n": [round(float(x), 2) for x in feel.baseline[0]],
        "pull_n": round(feel.pull_n, 2),
    }
    if felt_ns is None:
        out["failed_at"] = "release_object: no pull felt in 20 s"
        return
    yield from rig.arm(Release(), 4.0, out, "release")
    rig.mode("walk", "trial")
    d.cmd(-0.15)
    yield from d.wait(2.0)
    d.cmd(0.0)
    yield from d.wait(1.5)
    rig.poll_events()
    out["handed_over"] = rig.taken is not None and rig.taken.object_id == OBJECT


def run_fetch(
    seed: int = 1,
    overrides: Overrides | None = None,
    samples_path: Path | None = None,
    world_plan: bool = True,
) -> Figures:
    """One fetch on a fresh stack; its figures (JSON-ready). `world_plan=False` sends
    the grasp as ᴮH_G in `base` (what `grasp_from_detection` gives without a base pose)."""
    out: Figures = {"trial": "fetch", "world": "small", "world_seed": seed}
    out["grasp_frame"] = "world" if world_plan else "base"
    samples: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="dume-fetch-") as db:
        settings = merged(fetch_settings(seed, db), overrides or {})
        with ProcessStack(SERVICES, settings) as stack:
            d = Driver(stack)
            d.start()
            figures: Figures = {}
            d.run(fetch(d, figures, samples, world_plan), timeout_s=120.0)
    if samples_path is not None:
        samples_path.write_text(json.dumps(samples))
    figures["success"] = bool(figures.get("handed_over")) and "failed_at" not in figures
    return out | d.figures() | figures
