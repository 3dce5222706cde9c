"""A run's picture from its recording (`deploy.snapshot`): entities read back from real
`.rrd` files, the cameras shown at the frame before the pick started, perception's masks
drawn over them, and a PNG written."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import rerun as rr

from deploy.snapshot import camera_image, moment, read_run, snapshot


def _record(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for service in ("sim", "mission", "perception", "semantic_map"):
        rec = rr.RecordingStream("dume", recording_id="test-run")
        rec.save(str(folder / f"{service}.rrd"))
        for k in range(5):
            t = float(k)
            rec.set_time("sim_time", duration=t)
            if service == "sim":
                rec.log("world/truth/robot_trail", rr.Points3D([(k * 0.5, 0.0, 0.01)]))
                img = np.full((24, 32, 3), 40 * k, dtype=np.uint8)
                rec.log("camera/camera_wrist/rgb", rr.Image(img).compress(jpeg_quality=95))
            if service == "mission" and k == 3:
                rec.log("mission/status", rr.TextLog("r1 running pick_object 50%"))
            if service == "perception":
                ids = np.zeros((24, 32), dtype=np.uint8)
                ids[5:10, 5:10] = 1
                rec.log("camera/camera_wrist/perception/masks", rr.SegmentationImage(ids))
            if service == "semantic_map":
                rec.log("world/map/artifacts",
                        rr.Points3D([(1.0, 2.0, 0.8)], labels=["bottle_1"]))  # fmt: skip
        rec.flush()
        rec.disconnect()


def test_a_runs_picture_is_drawn_from_its_recording(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    _record(run_dir)
    run = read_run(run_dir)
    trail = run["/world/truth/robot_trail"]
    assert trail.times == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert run["/world/map/artifacts"].last()["labels"] == ["bottle_1"]  # type: ignore[index]
    assert moment(run, None) == 3.0  # the wrist frame before pick_object began
    assert moment(run, 1.5) == 1.5
    img = camera_image(run, "camera_wrist", 2.0)
    assert img is not None and img.shape == (24, 32, 3)
    assert abs(int(img[15, 20].mean()) - 80) <= 3  # the frame of t = 2 (JPEG)
    assert not np.allclose(img[7, 7], img[15, 20], atol=10)  # the mask tinted
    out = tmp_path / "snap.png"
    assert snapshot(run_dir, out, title="test") == 3.0
    png = cv2.imread(str(out))
    assert png is not None and png.shape[:2] == (900, 1600)
