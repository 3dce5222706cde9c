"""The render thread: a frame shows the state of the tick it was submitted at, whatever
the loop does to its `MjData` afterwards; it equals what the loop would have rendered;
`close` delivers what was waiting."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; before mujoco is imported

import mujoco
import numpy as np

from common.messages import as_numpy
from common.messages.sim import CameraFrame, SegmentationTruth
from services.sim.cameras import CameraRig
from services.sim.core import SimCore
from services.sim.render_worker import RenderWorker, Shot
from services.sim.world import generate_world


def test_a_frame_shows_the_state_it_was_submitted_with() -> None:
    core = SimCore(generate_world(1, "small"))
    got: list[tuple[CameraFrame, SegmentationTruth | None]] = []
    worker = RenderWorker(core.model, 160, 120, core.world, lambda f, t: got.append((f, t)))
    worker.submit(7, core.data, [Shot("camera_head", labels=True)])
    before = core.data.qpos.copy()
    core.data.qpos[0] += 0.5  # the loop moves the robot on at once
    mujoco.mj_forward(core.model, core.data)
    worker.submit(8, core.data, [Shot("camera_head", labels=False)])
    worker.close()
    assert [(f.stamp_ns, t is not None) for f, t in got] == [(7, True), (8, False)]
    assert got[0][0].depth.data != got[1][0].depth.data  # the second saw the move

    # What the loop itself would have rendered at tick 7: the same pixels.
    core.data.qpos[:] = before
    mujoco.mj_forward(core.model, core.data)
    rig = CameraRig(core.model, 160, 120, world=core.world)
    frame, truth = rig.capture(core.data, "camera_head", 7)
    rig.close()
    assert np.array_equal(as_numpy(frame.rgb), as_numpy(got[0][0].rgb))
    assert np.array_equal(as_numpy(frame.depth), as_numpy(got[0][0].depth))
    assert got[0][1] is not None
    assert np.array_equal(as_numpy(truth.labels), as_numpy(got[0][1].labels))
    assert worker.captures == {"camera_head": 2}
