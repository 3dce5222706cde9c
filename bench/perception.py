"""`dume bench perception`: the pipeline's latency in a live stack, its accuracy on unseen seeds.

Live (a real stack `["sim", "wbc", "perception"]`, lockstep, the hall, the robot standing
under the whole-body controller, both cameras at 320 × 240): per frame, the wall time
perception spends from the frame's arrival to its `Detections` (`process_ms`: decode,
segment, geometry, publish), p50/p95, and the end-to-end latency the bench sees between a
frame's arrival and its `Detections`' arrival; throughput in frames per wall second; and,
in the same run while the stack still runs, the raw forward of the network on frames of
that run (onnxruntime, the segmenter's runtime, and OpenCV DNN on the same file and
threads, the reference), with the ratios pipeline p50 / forward p50 and OpenCV / ours.

Accuracy (in process, renders of seeds the network never saw): the robot stands at
standoff poses in `look` facing each artifact (wrist camera) and 1-3 m away (head camera),
with the trunk's height and tilt jittered. For every artifact in view with at least
`MIN_PIXELS` truth pixels, not cut by the image border: bottle mask IoU (network vs
truth), visible-centroid error (the detection's centroid vs the mean of the truth mask's
back-projected points) and axis error (horizontal distance from the detected axis to the
artifact's true axis, from the world description), per class, for the network and for the
truth segmenter (geometry alone); `near_` figures over the artifacts whose true centre is
within 1.5 m of the camera horizontally (the acceptance's), `all_` over every range.
The same frames again with the sim's depth noise (`sim.sensors.depth`, what the robot's
camera gives it): the `noisy_` figures, against the same clean references.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import math
import os
import statistics
import threading
import time
from collections import defaultdict
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2
import msgspec
import mujoco
import numpy as np
import zenoh

from common import robot
from common.camera import backproject
from common.config import DepthNoiseSettings, Overrides, load_config, merged, resolve
from common.geometry import FloatArray, matrix_to_quat_xyzw, rot_x, rot_y, rot_z, transform_points
from common.messages import as_numpy, decode, to_wire
from common.messages.perception import Detections
from common.messages.sim import CameraFrame, SegmentationTruth
from common.messages.world import WorldDescription
from deploy.stack import ProcessStack
from services.perception import metrics
from services.perception.frames import shape_check_of
from services.perception.measure import ShapeCheck
from services.perception.pipeline import detect, frame_geometry
from services.perception.segmenter import Segmenter, TruthSegmenter
from services.perception.self_filter import is_self
from services.sim import feasibility as fz
from services.sim import mjcf, scene
from services.sim.cameras import CameraRig
from services.sim.sensors import DepthNoise
from services.sim.world import generate_world

log = logging.getLogger(__name__)

#: World seeds the network never saw (checked against the model's sidecar).
EVAL_SEEDS = (9001, 9002, 9003)
MAX_RANGE_M = 1.5
MIN_PIXELS = 50
CLASSES = ("bottle", "can", "box", "person")
#: The figures' families: segmenters, each on the clean render and with the depth noise.
PREFIXES = tuple(f"{n}{s}_" for n in ("", "noisy_") for s in ("truth", "network", "reported"))


def _pct(x: Sequence[float], q: float) -> float | None:
    return round(float(np.percentile(x, q)), 4) if len(x) else None


def _stats(name: str, x: Sequence[float], scale: float = 1.0) -> dict[str, Any]:
    v = [scale * e for e in x]
    return {f"{name}_p50": _pct(v, 50), f"{name}_p95": _pct(v, 95), f"{name}_max": _pct(v, 100)}


# -- accuracy on renders -----------------------------------------------------------------


def _shots(world: WorldDescription, rng: np.random.Generator) -> Iterator[tuple[str, Any, str]]:
    """(camera, base pose, target id): wrist in `look` at standoff, head 1-3 m away from
    each artifact; head 2-7 m from each person, facing them from a free pose."""
    surfaces = {s.id: s for s in world.surfaces}
    for a in world.artifacts:
        for _ in range(2):
            d = float(rng.uniform(robot.D_OPT_M, robot.STANDOFF_DISTANCE_M + 0.15))
            pose = fz.standoff_pose_for(a, surfaces[a.surface_id], d, float(rng.uniform(-0.3, 0.3)))
            yield "camera_wrist", pose, a.id
        pose = fz.standoff_pose_for(a, surfaces[a.surface_id], float(rng.uniform(1.2, 2.0)))
        yield "camera_head", pose, a.id
    fp = fz.robot_footprint()
    for person in world.people:
        for _ in range(2):
            for _try in range(50):
                d, bearing = float(rng.uniform(2.0, 7.0)), float(rng.uniform(-math.pi, math.pi))
                x = person.position[0] + d * math.cos(bearing)
                y = person.position[1] + d * math.sin(bearing)
                yaw = math.atan2(person.position[1] - y, person.position[0] - x)
                pose = fz.Pose2D(x, y, yaw + float(rng.uniform(-0.3, 0.3)))
                if fz.footprint_free(world.occupancy, pose, fp, 0.1):
                    yield "camera_head", pose, person.id
                    break


def render_seed(
    seed: int,
) -> Iterator[tuple[WorldDescription, CameraFrame, FloatArray, SegmentationTruth]]:
    """Frames of the hall of `seed` from the bench's shots (deterministic per seed), each
    with the base's true pose at capture."""
    world = generate_world(seed, "hall")
    rng = np.random.default_rng([seed, 0xBE7C])
    model = scene.compile_scene(world)
    data = mujoco.MjData(model)
    qpos = mjcf.mj_indices(model).qpos
    rig = CameraRig(model, 320, 240, world)
    try:
        for camera, pose, _ in _shots(world, rng):
            posture = "look" if camera == "camera_wrist" else "stand"
            q = np.array(robot.standing_q(posture, pose.x, pose.y, pose.yaw))
            q[2] += rng.uniform(-0.03, 0.03)
            tilt = rot_y(rng.uniform(-0.06, 0.06)) @ rot_x(rng.uniform(-0.03, 0.03))
            q[3:7] = matrix_to_quat_xyzw(rot_z(pose.yaw) @ tilt)
            data.qpos[qpos] = mjcf.q_pin_to_mj(q)
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            frame, truth = rig.capture(data, camera, 0)
            yield world, frame, rig.base_pose(data), truth
    finally:
        rig.close()


def _errors(
    world: WorldDescription,
    frame: CameraFrame,
    T_world_base: FloatArray,
    truth: SegmentationTruth,
    predicted: Sequence[Any],
    out: dict[str, list[float]],
    prefix: str,
    reference: CameraFrame | None = None,
) -> None:
    """Per truth artifact in view: matched detection's IoU, centroid and axis errors.
    `reference` (default `frame`): the frame whose depth gives the truth's visible
    centroid (the clean render, when `frame` carries the depth noise).

    The base is where the sim has it (`T_world_base`): the figures are perception's own
    errors, the pose's error aside. Every figure goes in twice: under `all_` (every
    range) and, when the artifact's true centre is within `MAX_RANGE_M` of the camera
    (horizontally), under `near_`, per class and for all classes together (the
    acceptance's figures are the `near_` ones).
    """
    labels = np.asarray(as_numpy(truth.labels), dtype=np.int32)
    depth = np.asarray(as_numpy((reference or frame).depth), dtype=np.float64)
    truths = TruthSegmenter(CLASSES).segment(labels, truth.instances)
    matches = metrics.match_instances(predicted, truths, [t.truth_id or "" for t in truths], depth)
    geo = frame_geometry(frame, T_world_base)
    T_world_camera = geo.T_world_base_yaw @ geo.T_base_yaw_camera
    eye = T_world_camera[:2, 3]
    artifacts = {a.id: a for a in world.artifacts}
    found, counted = metrics.person_recall(matches)
    out[f"{prefix}people_found"].append(float(found))
    out[f"{prefix}people_counted"].append(float(counted))
    matched = {m.matched for m in matches if m.matched is not None}
    false_people = [i for i, p in enumerate(predicted) if p.class_name == "person"]
    out[f"{prefix}false_people"].append(float(len(set(false_people) - matched)))
    for t, m in zip(truths, matches, strict=True):
        art = artifacts.get(t.truth_id or "")
        u0, v0, u1, v1 = t.bbox
        cut = u0 == 0 or v0 == 0 or u1 == frame.width or v1 == frame.height
        if art is None or m.pixels < MIN_PIXELS or cut:
            continue
        cls = art.object_class
        near = math.hypot(art.position[0] - eye[0], art.position[1] - eye[1]) <= MAX_RANGE_M
        ranges = ("all_", "near_") if near else ("all_",)
        figures: dict[str, float] = {}
        if cls == "bottle":
            figures["bottle_iou"] = m.iou
        pick = [predicted[m.matched]] if m.matched is not None else []
        det = detect(frame, T_world_base, pick, 0.0) if pick else []
        if not det:
            figures["missed"] = 1.0
        else:
            d = det[0].detection
            pts = backproject(depth, geo.camera, mask=t.mask)
            visible = transform_points(T_world_camera, pts).mean(axis=0)
            err = float(np.linalg.norm(np.array(d.centroid_in_world) - visible))
            figures["centroid_error_m"] = err
            figures[f"{cls}_centroid_error_m"] = err
            figures[f"{cls}_axis_error_m"] = math.hypot(
                d.axis_in_world[0] - art.position[0], d.axis_in_world[1] - art.position[1]
            )
        for r in ranges:
            for key, value in figures.items():
                out[f"{prefix}{r}{key}"].append(value)


def accuracy(
    seeds: Sequence[int], net: Segmenter | None, noise: DepthNoiseSettings | None = None
) -> dict[str, Any]:
    """Figures on the renders of `seeds` for the truth segmenter and the network; with
    `noise`, again on the same frames with the sim's depth noise (`noisy_` figures: what
    the robot's depth camera gives it; the references stay the clean depth and the
    world's truth)."""
    out: defaultdict[str, list[float]] = defaultdict(list)
    frames = 0
    for seed in seeds:
        noisy = DepthNoise(noise, seed) if noise is not None else None
        for world, clean, T_world_base, truth in render_seed(seed):
            frames += 1
            labels = np.asarray(as_numpy(truth.labels), dtype=np.int32)
            truths = TruthSegmenter(CLASSES).segment(labels, truth.instances)
            variants = [("", clean)]
            if noisy is not None:
                depth = np.asarray(as_numpy(clean.depth), dtype=np.float32)
                shot = noisy.apply(depth, clean.camera, frames)
                variants.append(("noisy_", msgspec.structs.replace(clean, depth=to_wire(shot))))
            for tag, frame in variants:
                _errors(world, frame, T_world_base, truth, truths, out, f"{tag}truth_", clean)
                if net is None:
                    continue
                rgb = np.asarray(as_numpy(frame.rgb), dtype=np.uint8)
                depth = np.asarray(as_numpy(frame.depth), dtype=np.float32)
                predicted = net.segment(rgb, depth)
                _errors(world, frame, T_world_base, truth, predicted, out, f"{tag}network_", clean)
                shown = reported(frame, T_world_base, predicted)
                _errors(world, frame, T_world_base, truth, shown, out, f"{tag}reported_", clean)
    result = summarise(out)
    for prefix in PREFIXES:
        if frames and f"{prefix}false_people" in result:
            result[f"{prefix}false_people_per_frame"] = round(
                result[f"{prefix}false_people"] / frames, 3
            )
    return {"eval_seeds": list(seeds), "eval_frames": frames, **result}


@functools.cache
def _shape_check() -> ShapeCheck | None:
    return shape_check_of(load_config().perception)


def reported(frame: CameraFrame, T_world_base: FloatArray, instances: Sequence[Any]) -> list[Any]:
    """The instances the service reports (`reported_` figures): a person without depth
    points, or one the robot sees inside itself (`services.perception.self_filter`), is
    dropped; a can or box takes the class of perception's shape check (the default
    settings')."""
    check = _shape_check()
    out = []
    for inst in instances:
        if inst.class_name == "person":
            det = detect(frame, T_world_base, [inst], 0.0)
            if not det or is_self(det[0].detection):
                continue
        elif check is not None and inst.class_name in check.classes:
            det = detect(frame, T_world_base, [inst], 0.0, check)
            if det and det[0].detection.class_name != inst.class_name:
                inst = dataclasses.replace(inst, class_name=det[0].detection.class_name)
        out.append(inst)
    return out


def summarise(out: dict[str, list[float]]) -> dict[str, Any]:
    """The figures' statistics: recall, mean IoU, p50/p95/max of errors in mm, counts."""
    result: dict[str, Any] = {}
    for prefix in PREFIXES:
        counted = sum(out.get(f"{prefix}people_counted", []))
        if counted:
            found = sum(out[f"{prefix}people_found"])
            result[f"{prefix}person_recall"] = round(found / counted, 4)
    for key in sorted(out):
        values = out[key]
        if key.endswith("missed"):
            result[key] = len(values)
        elif key.endswith(("people_found", "people_counted", "false_people")):
            result[key] = int(sum(values))
        elif key.endswith("iou"):
            result[f"{key}_mean"] = round(float(np.mean(values)), 4) if values else None
            result[f"{key}_n"] = len(values)
        else:
            result.update(_stats(key.removesuffix("_m") + "_mm", values, 1000.0))
            result[f"{key.removesuffix('_m')}_n"] = len(values)
    return result


# -- the live stack ----------------------------------------------------------------------


class _Arrivals:
    """Wall arrival times of frames and detections per (camera, stamp), from raw callbacks
    (no decoding of images beyond the stamp's message)."""

    def __init__(self, session: zenoh.Session, keys: Any, cameras: Sequence[str]) -> None:
        self.lock = threading.Lock()
        self.frames: dict[tuple[str, int], float] = {}
        self.detections: dict[tuple[str, int], tuple[float, Detections]] = {}
        self.kept: list[CameraFrame] = []
        self._subs = [
            session.declare_subscriber(keys.camera_rgbd(c), self._on_frame) for c in cameras
        ]
        self._subs.append(session.declare_subscriber(keys.detections, self._on_detections))

    def _on_frame(self, sample: zenoh.Sample) -> None:
        now = time.perf_counter()
        frame = decode(sample.payload.to_bytes(), CameraFrame)
        with self.lock:
            self.frames[(frame.camera, frame.stamp_ns)] = now
            if len(self.kept) < 20 and frame.stamp_ns >= 1_000_000_000:
                self.kept.append(frame)

    def _on_detections(self, sample: zenoh.Sample) -> None:
        now = time.perf_counter()
        msg = decode(sample.payload.to_bytes(), Detections)
        with self.lock:
            self.detections[(msg.camera, msg.stamp_ns)] = (now, msg)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def _forward_ms(
    net: Segmenter, frames: Sequence[CameraFrame], model: Path, threads: int
) -> tuple[list[float], list[float]]:
    """The network's forward per frame, ms: through the segmenter's runtime
    (onnxruntime), and through OpenCV DNN on the same file and thread budget (the
    reference it replaced), interleaved frame by frame so both see the same load."""
    cv2.setNumThreads(threads)
    reference = cv2.dnn.readNetFromONNX(str(model))
    ours, theirs = [], []
    for frame in frames:
        rgb = np.asarray(as_numpy(frame.rgb), dtype=np.uint8)
        blob = net.blob(rgb, np.asarray(as_numpy(frame.depth), dtype=np.float32))
        t0 = time.perf_counter()
        net.forward(blob)
        t1 = time.perf_counter()
        reference.setInput(blob)
        reference.forward()
        t2 = time.perf_counter()
        ours.append((t1 - t0) * 1e3)
        theirs.append((t2 - t1) * 1e3)
    return ours, theirs


def live(
    overrides: Overrides, segmenter: str, sim_s: float, net: Segmenter | None, model: Path
) -> dict[str, Any]:
    """The pipeline's timing in a running stack (see the module docstring)."""
    settings = merged(
        {
            "sim.world": "hall",
            "sim.world_seed": 0,
            "time.participants": {
                "wbc": {"role": "command", "period_s": 0.002, "latency_s": 0.0},
                "perception": {"role": "periodic", "period_s": 0.1, "latency_s": 0.1},
            },
            "perception.segmenter": segmenter,
            "recording.enabled": False,
            "sim.duration_s": sim_s + 60.0,
        },
        overrides,
    )
    start_ns, end_ns = 1_000_000_000, round((1.0 + sim_s) * 1e9)
    with ProcessStack(["sim", "wbc", "perception"], settings) as stack:
        cams = stack.config.perception.cameras
        arrivals = _Arrivals(stack.bus.session, stack.keys, cams)
        last = stack.bus.latest(stack.keys.detections, Detections)
        last.wait(lambda m: m.stamp_ns >= start_ns, 300.0)
        t0 = time.perf_counter()
        last.wait(lambda m: m.stamp_ns >= end_ns, 1200.0)
        wall = time.perf_counter() - t0
        threads = stack.config.perception.dnn_threads or os.cpu_count() or 1
        forward, opencv = (
            _forward_ms(net, arrivals.kept, model, threads) if net is not None else ([], [])
        )
        arrivals.close()
    process, e2e, reasons = [], [], set()
    for (cam, stamp), (t_det, msg) in arrivals.detections.items():
        if not start_ns <= stamp <= end_ns:
            continue
        if msg.reason:
            reasons.add(msg.reason)
            continue
        process.append(msg.process_ms)
        if (cam, stamp) in arrivals.frames:
            e2e.append((t_det - arrivals.frames[(cam, stamp)]) * 1e3)
    result: dict[str, Any] = {
        "live_segmenter": segmenter,
        "live_frames": len(process),
        "live_frames_per_wall_s": round(len(process) / wall, 2),
        "live_sim_rtf": round(sim_s / wall, 3),
        **_stats("pipeline_ms", process),
        **_stats("end_to_end_ms", e2e),
        **_stats("dnn_forward_ms", forward),
        **_stats("opencv_dnn_forward_ms", opencv),
    }
    if forward and process:
        result["pipeline_over_forward_p50"] = round(
            statistics.median(process) / statistics.median(forward), 2
        )
        result["opencv_over_onnxruntime_p50"] = round(
            statistics.median(opencv) / statistics.median(forward), 2
        )
    if reasons:
        result["live_reasons"] = sorted(reasons)
    return result


def _unseen(seeds: Sequence[int], model: Path) -> list[int]:
    """`seeds` minus any in the model's training or validation ranges (from its sidecar)."""
    try:
        meta = json.loads(model.with_suffix(".json").read_text())
        meta = meta.get("training", meta)  # the ranges sit under "training" in the sidecar
        ranges = [meta[k] for k in ("train_seeds", "val_seeds") if k in meta]
    except (OSError, ValueError):
        return list(seeds)
    return [s for s in seeds if not any(lo <= s <= hi for lo, hi in ranges)]


def bench_perception(overrides: Overrides | None = None, sim_s: float = 8.0) -> dict[str, Any]:
    overrides = overrides or {}
    settings = load_config(overrides).perception
    model = resolve(settings.model)
    # the reference forward with the service's thread count, so that the ratio is fair
    net = Segmenter(model, threads=settings.dnn_threads or None) if model.exists() else None
    segmenter = "network" if net is not None else "truth"
    result: dict[str, Any] = {"bench": "perception", "network": net is not None}
    result.update(live(overrides, segmenter, sim_s, net, model))
    noise = load_config(overrides).sim.sensors.depth
    result.update(accuracy(_unseen(EVAL_SEEDS, model), net, noise if noise.enabled else None))
    for key, value in result.items():
        print(f"{key:40s} {value}")
    return result
