"""Perception's detections for navigation, taken at the lockstep time they apply.

Perception is a periodic participant publishing `Detections` for every camera at each of
its ticks on one key; an output stamped s applies at s + latency. `PerceptionFeed.due(b)`
waits (lockstep) until the output that applies by b is in (`UpstreamGate`) and returns
the one camera's detections stamped at or before b − latency not yet returned, in stamp
order. Both cameras share the key: when the gate is satisfied by the other camera's
message, this camera's is still on its way and is waited for (bounded).
"""

from __future__ import annotations

from common.bus import Bus
from common.config import Config
from common.keys import RobotKeys
from common.lockstep import UpstreamGate
from common.messages.perception import Detections

PRODUCER = "perception"


class PerceptionFeed:
    """One camera's detections, due by tick; see the module docstring."""

    def __init__(
        self, bus: Bus, keys: RobotKeys, config: Config, camera: str, timeout_s: float
    ) -> None:
        self.camera, self.timeout_s = camera, timeout_s
        self.enabled = bool(camera) and camera in config.perception.cameras
        self.camera_period_ns = round(1e9 / config.sim.camera_hz)
        self.latest = bus.latest(keys.detections, Detections, history=16)
        self.fifo = bus.fifo(keys.detections, Detections, maxlen=1024)
        self.pending: list[Detections] = []
        self.last = -1
        self.upstream = UpstreamGate(bus, keys, config)
        self.upstream.watch(PRODUCER, self.latest)

    def due(self, b: int) -> list[Detections]:
        if not self.enabled:
            return []
        self.upstream.wait(b, self.timeout_s)
        stamp = b - self.upstream.latency_ns(PRODUCER)
        self.pending.extend(d for d in self.fifo.drain() if d.camera == self.camera)
        if (
            self.upstream.lockstep
            and PRODUCER in self.upstream.gate.alive
            and stamp % self.camera_period_ns == 0
            and stamp > self.last
            and not any(d.stamp_ns == stamp for d in self.pending)
        ):
            msg = self.fifo.pop(timeout_s=2.0)
            while msg is not None:
                if msg.camera == self.camera:
                    self.pending.append(msg)
                    if msg.stamp_ns >= stamp:
                        break
                msg = self.fifo.pop(timeout_s=2.0)
        due = sorted((d for d in self.pending if d.stamp_ns <= stamp), key=lambda d: d.stamp_ns)
        self.pending = [d for d in self.pending if d.stamp_ns > stamp]
        if due:
            self.last = due[-1].stamp_ns
        return due
