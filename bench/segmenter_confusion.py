"""`dume train-segmenter --confusion MODEL`: a segmenter's per-class confusion by range on
held-out renders (`services.perception.training.confusion`).

The frames: hall worlds of `SEEDS`, which no model trains or validates on (checked against
the model's sidecar), rendered once from the held-out plan
(`services.sim.dataset_shots.plan_heldout_shots`: each artifact from its standoff and from
about 1, 2 and 4 m with both cameras, each person from 1-5 m with both, furniture edges)
and kept as shards in `SHARDS`. Every frame goes through the runtime `Segmenter` as the
robot runs it: on the depth its camera gives (the sim's depth noise, `sim.sensors.depth`,
drawn per seed, camera and frame), on `perception.dnn_threads`, instance separation
included, the instances scored under `perception.min_score` dropped as
`pipeline.detect` drops them. Truth: the frame's instance labels and its clean depth.
Deterministic for a seed list and a model. Not what the robot reports near the camera:
within `perception.shape_check_range_m` (1.2 m) its shape check re-decides a can or a box
from the depth, after the network.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from common.config import REPO_ROOT, load_config, resolve
from services.perception.segmenter import Segmenter
from services.perception.training.confusion import Confusion, markdown
from services.perception.training.data import load_frames
from services.sim.dataset import write_dataset
from services.sim.sensors import DepthNoise

log = logging.getLogger(__name__)

#: Held-out worlds: no training (0-179) or validation (10000-10023) seed, nor the
#: perception bench's (9001-9003).
SEEDS = tuple(range(20_000, 20_016))
SHARDS = REPO_ROOT / "var" / "datasets" / "segmenter-heldout"
OUT = REPO_ROOT / "var" / "eval" / "segmenter-confusion"


class HeldOutError(ValueError):
    """Seeds the model was trained or validated on: says which and the model's ranges."""


def check_held_out(seeds: Sequence[int], model: Path) -> None:
    """Raise `HeldOutError` when a seed lies in the model's training or validation range
    (its sidecar's `training.train_seeds` / `val_seeds`, [first, last])."""
    meta = json.loads(model.with_suffix(".json").read_text())
    ranges = {k: meta.get("training", {}).get(k) for k in ("train_seeds", "val_seeds")}
    used = [s for s in seeds for lo_hi in ranges.values() if lo_hi and lo_hi[0] <= s <= lo_hi[1]]
    if used:
        raise HeldOutError(f"seeds {sorted(set(used))} are not held out from {model}: {ranges}")


def confusion_report(
    model: Path, seeds: Sequence[int] = SEEDS, shards: Path = SHARDS
) -> dict[str, Any]:
    """The confusion of `model` on the held-out frames of `seeds` (see the module)."""
    check_held_out(seeds, model)
    perception = load_config().perception
    noise = load_config().sim.sensors.depth
    paths = list(write_dataset(seeds, shards, plan="heldout"))
    frames = load_frames(paths)
    net = Segmenter(model, threads=perception.dnn_threads or None)
    counts = Confusion()
    index: dict[int, int] = {}
    t0 = time.monotonic()
    for k in range(len(frames)):
        seed = frames.seeds[k]
        index[seed] = index.get(seed, -1) + 1
        depth = frames.depth_mm[k].astype(np.float32) * np.float32(1e-3)
        seen = DepthNoise(noise, seed).apply(depth, frames.camera[k], index[seed])
        found = net.segment(frames.rgb[k], seen if noise.enabled else depth)
        found = [i for i in found if i.score >= perception.min_score]
        counts.add(found, frames.labels[k], frames.names[k], depth)
    log.info("%d frames in %.0f s", len(frames), time.monotonic() - t0)
    return {
        "model": str(model),
        "sha256": hashlib.sha256(model.read_bytes()).hexdigest(),
        "seeds": [min(seeds), max(seeds)],
        "depth_noise": noise.enabled,
        "min_score": perception.min_score,
        **counts.to_dict(),
    }


def write_report(report: dict[str, Any], out: Path) -> tuple[Path, Path]:
    """`<out>/<model stem>-<sha256[:8]>.json` and `.md`."""
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"{Path(report['model']).stem}-{report['sha256'][:8]}"
    json_path, md_path = stem.with_suffix(".json"), stem.with_suffix(".md")
    json_path.write_text(json.dumps(report, indent=2) + "\n")
    md_path.write_text(header(report) + "\n\n" + markdown(report) + "\n")
    return json_path, md_path


def header(report: dict[str, Any]) -> str:
    """One line: the model, the frames and how they were read."""
    lo, hi = report["seeds"]
    return (
        f"{report['model']} (sha256 {report['sha256'][:12]}): {report['frames']} held-out "
        f"frames, hall seeds {lo}-{hi}, depth noise {'on' if report['depth_noise'] else 'off'}, "
        f"min score {report['min_score']}, paired at IoU >= {report['match_iou']}; "
        f"not counted: {report['small']} too small, {report['beyond']['truth']} truth and "
        f"{report['beyond']['false']} false beyond the bins"
    )


def run(model: Path, seeds: Sequence[int] = SEEDS, out: Path = OUT) -> dict[str, Any]:
    """Report, write the files and print the markdown; the report's JSON on the last line."""
    report = confusion_report(model if model.exists() else resolve(str(model)), seeds)
    json_path, md_path = write_report(report, out)
    print(header(report) + "\n\n" + markdown(report))
    print(f"written: {json_path} {md_path}")
    print(json.dumps({k: report[k] for k in ("model", "frames", "correct", "false_total")}))
    return report


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", type=Path)
    parser.add_argument("--seeds", type=int, nargs=2, default=(SEEDS[0], SEEDS[-1] + 1))
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    try:
        run(args.model, range(*args.seeds), args.out)
    except HeldOutError as exc:
        print(f"segmenter_confusion: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
