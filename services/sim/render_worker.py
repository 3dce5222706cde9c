"""The cameras rendered beside the physics: a thread of their own, from snapshots.

Rendering is the sim's dearest work (tens of ms a frame, `dume bench stack`). Done on
the loop it is serial with the physics and the controller; here the loop only copies the
state of tick t (`mujoco.mj_copyData`, tens of µs) into a free snapshot and goes on
stepping, while the thread renders the snapshot (MuJoCo releases the GIL while it draws)
and hands each frame to `deliver`. What a frame shows is fixed by its snapshot, so the
frames are the same as if rendered on the loop; their consumers wait for them by stamp,
and lockstep holds the sim at the first consumer's ack, so a slow render slows the sim
and never reorders anything. `submit` blocks only when every snapshot is still waiting
to be rendered (`SNAPSHOTS`).

The thread owns the `CameraRig` (an EGL context is current in the thread that made it).
It runs on `cpus` (`cpu.layout`'s rest: off the physics' CPU, whose caches it would
evict, `common.sched`); Mesa's rasterizer threads, started from it, inherit them.
`close()` renders what was submitted, then stops the thread.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco

from common.messages.sim import CameraFrame, SegmentationTruth
from common.messages.world import WorldDescription
from common.sched import pin
from services.sim.cameras import CameraRig
from services.sim.sensors import DepthNoise

log = logging.getLogger("dume.sim")

#: States that may wait to be rendered at once (two camera ticks' worth).
SNAPSHOTS = 2
#: Wall seconds `submit` waits for a free snapshot before looking at the thread again.
POLL_S = 1.0

#: Called on the render thread with each frame, and its labels when asked for.
Deliver = Callable[[CameraFrame, SegmentationTruth | None], None]


@dataclass(frozen=True)
class Shot:
    """One camera to render from a snapshot; `labels`: its segmentation too."""

    camera: str
    labels: bool


class RenderWorker:
    """Renders submitted snapshots on its own thread (see the module docstring)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        width: int,
        height: int,
        world: WorldDescription | None,
        deliver: Deliver,
        cpus: frozenset[int] | None = None,
        depth_noise: DepthNoise | None = None,
    ) -> None:
        self.model = model
        self.cpus = cpus
        self.depth_noise = depth_noise
        self.deliver = deliver
        self._free: queue.Queue[mujoco.MjData] = queue.Queue()
        for _ in range(SNAPSHOTS):
            self._free.put(mujoco.MjData(model))
        self._todo: queue.Queue[tuple[int, mujoco.MjData, Sequence[Shot]] | None] = queue.Queue()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.rig: CameraRig | None = None
        self._thread = threading.Thread(
            target=self._run, args=(width, height, world), name="render", daemon=True
        )
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise self._error

    @property
    def render_s(self) -> dict[str, float]:
        return dict(self.rig.render_s) if self.rig else {}

    @property
    def captures(self) -> dict[str, int]:
        return dict(self.rig.captures) if self.rig else {}

    def submit(self, t_ns: int, data: mujoco.MjData, shots: Sequence[Shot]) -> None:
        """Render `shots` of the state `data` holds now (copied before returning)."""
        if not shots:
            return
        while True:
            if self._error is not None:
                raise RuntimeError("the render thread failed") from self._error
            try:
                snapshot = self._free.get(timeout=POLL_S)
                break
            except queue.Empty:
                continue
        mujoco.mj_copyData(snapshot, self.model, data)
        self._todo.put((t_ns, snapshot, tuple(shots)))

    def close(self) -> None:
        """Render what is waiting, then stop the thread."""
        if self._thread.is_alive():
            self._todo.put(None)
            self._thread.join()

    def _run(self, width: int, height: int, world: WorldDescription | None) -> None:
        if why := pin(self.cpus):
            log.warning("%s: the cameras render on the physics' CPU", why)
        try:
            self.rig = CameraRig(self.model, width, height, world, self.depth_noise)
        except BaseException as exc:  # reported to the constructor's caller
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        rig = self.rig
        try:
            while (job := self._todo.get()) is not None:
                t_ns, snapshot, shots = job
                try:
                    for shot in shots:
                        frame = rig.capture_frame(snapshot, shot.camera, t_ns)
                        truth = rig.capture_labels(shot.camera, t_ns) if shot.labels else None
                        self.deliver(frame, truth)
                finally:
                    self._free.put(snapshot)
        except BaseException as exc:  # the loop's next `submit` raises it
            log.exception("the render thread stopped: %s", exc)
            self._error = exc
        finally:
            rig.close()
