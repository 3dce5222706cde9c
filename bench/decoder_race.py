"""`dume bench decoders`: the native crash the services died of at start-up, on demand.

Each round is a fresh Python process (msgspec builds a Struct's type information once per
process) in which six threads, released together, each take a decoder of `Detections`
and decode a payload with it at once: what two Zenoh callback threads do on a service's
first detections. `raw` builds the decoders with msgspec directly, as the services did
before; `guarded` takes them from `common.messages.decoder`, which builds one at a time.
msgspec 0.22 publishes a type's information before it is complete (it evaluates the
annotations in Python, letting other threads run), so in `raw` a thread sometimes
decodes through a half-built type and the process dies of SIGSEGV.

    dume bench decoders --rounds 300

Figures only: crashes per mode out of `rounds` processes each.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from typing import Any

THREADS = 6
DECODES = 50


def _payload() -> bytes:
    import numpy as np

    from common.messages import encode, to_wire
    from common.messages.perception import Detection, Detections

    eye = tuple(float(v) for v in np.eye(4).ravel())
    det = Detection(
        class_name="bottle",
        score=0.9,
        bbox=(0, 0, 2, 2),
        mask=to_wire(np.ones((2, 2), np.uint8)),
        centroid_in_base_yaw=(1.0, 0.0, 0.8),
        centroid_in_world=(1.0, 0.0, 0.8),
        axis_in_world=(1.0, 0.0, 0.8),
        extent=(0.07, 0.07, 0.2),
        d_obj=1.0,
        theta_obj=0.0,
        n_points=4,
    )
    msg = Detections(
        stamp_ns=0, camera="camera_head", T_world_base=eye, segmenter="network", detections=[det]
    )
    return encode(msg)


def _race(mode: str) -> None:
    """One process's race: six threads decode their first `Detections` together."""
    import msgspec

    from common.messages import decoder
    from common.messages.perception import Detections

    payload = _payload()
    start = threading.Barrier(THREADS)

    def work() -> None:
        start.wait()
        dec: Any = msgspec.msgpack.Decoder(Detections) if mode == "raw" else decoder(Detections)
        for _ in range(DECODES):
            dec.decode(payload)

    threads = [threading.Thread(target=work) for _ in range(THREADS)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


def bench_decoders(rounds: int) -> dict[str, Any]:
    out: dict[str, Any] = {"rounds": rounds}
    for mode in ("raw", "guarded"):
        crashed = 0
        for _ in range(rounds):
            proc = subprocess.run(
                [sys.executable, "-X", "faulthandler", "-m", "bench.decoder_race", mode],
                capture_output=True,
                text=True,
            )
            crashed += proc.returncode != 0
        out[f"{mode}_crashes"] = crashed
        print(f"{mode}: {crashed} of {rounds} processes crashed", file=sys.stderr, flush=True)
    return out


if __name__ == "__main__":
    _race(sys.argv[1])
