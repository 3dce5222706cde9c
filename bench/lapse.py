"""`dume bench lapse`: how long a client the router cut off is gone, against how long it
stalled (`common.lifelines.LOST_GRACE_S` is sized from it).

In this process: the stack's router (`deploy/zenoh/router.json5`, on a port of its own,
no access control), a watcher of liveliness tokens, a publisher that puts 200 kB
samples every 2 ms with `BLOCK` congestion control (the robot's states and cameras go
so), and a slow client with a token that subscribes to them and, once a round, sleeps
`stall` seconds in its callback, as a service whose GIL one long call holds. The router
cuts a client off after its queue towards it has been full for 0.5 s (`wait_before_
close`); the client reconnects by itself once it reads again. Per stall length the
figures are the rounds it was cut off, how long its token was gone (the watcher's
DELETE to PUT) and how long after the stall ended it was back.

    dume bench lapse --rounds 3
"""

from __future__ import annotations

import statistics
import threading
import time
from typing import Any

import zenoh

from common.bus import open_session
from common.config import load_config

#: Wall seconds the slow client stalls in a round: under the router's 0.5 s patience
#: plus what the socket buffers hold, just over it, and well over it.
STALLS_S = (1.0, 1.5, 2.0, 3.0)
PAYLOAD_BYTES = 200_000
PUT_EVERY_S = 0.002
#: After a stall, wall seconds for the client to come back before the next round.
SETTLE_S = 2.0
PORT = 7491


def bench_lapse(rounds: int, port: int = PORT) -> dict[str, Any]:
    cfg = load_config([f"zenoh.port={port}", "zenoh.access_control=false"])
    router = open_session(cfg, "router")
    sessions = [open_session(cfg) for _ in range(3)]
    watcher, publisher, slow = sessions
    events: list[tuple[float, bool]] = []  # (monotonic, alive)
    watcher.liveliness().declare_subscriber(
        "bench/lapse/alive/**",
        lambda s: events.append((time.monotonic(), s.kind == zenoh.SampleKind.PUT)),
        history=True,
    )
    token = slow.liveliness().declare_token("bench/lapse/alive/slow")  # kept: dropped, it goes
    stall = {"s": 0.0}
    ended = {"at": 0.0}

    def on_sample(_sample: zenoh.Sample) -> None:
        if stall["s"] > 0.0:
            seconds, stall["s"] = stall["s"], 0.0
            time.sleep(seconds)
            ended["at"] = time.monotonic()

    slow.declare_subscriber("bench/lapse/data", on_sample)
    pub = publisher.declare_publisher(
        "bench/lapse/data", congestion_control=zenoh.CongestionControl.BLOCK
    )
    stop = threading.Event()

    def pump() -> None:
        payload = b"x" * PAYLOAD_BYTES
        while not stop.is_set():
            pub.put(payload)
            time.sleep(PUT_EVERY_S)

    pumper = threading.Thread(target=pump, daemon=True)
    pumper.start()
    time.sleep(SETTLE_S)
    figures: dict[str, Any] = {}
    try:
        for seconds in STALLS_S:
            gone, after = [], []
            for _ in range(rounds):
                start = len(events)
                stall["s"] = seconds
                time.sleep(seconds + SETTLE_S)
                seen = events[start:]
                down = next((t for t, alive in seen if not alive), None)
                up = next((t for t, alive in seen if alive and down is not None and t > down), None)
                if down is not None and up is not None:
                    gone.append(up - down)
                    after.append(up - ended["at"])
            figures[f"stall_{seconds:g}s"] = {
                "rounds": rounds,
                "cut_off": len(gone),
                "gone_s": _stats(gone),
                "back_after_stall_s": _stats(after),
            }
    finally:
        stop.set()
        pumper.join(timeout=2.0)
        token.undeclare()
        for s in (*sessions, router):
            s.close()
    return figures


def _stats(xs: list[float]) -> dict[str, float] | None:
    if not xs:
        return None
    return {
        "median": round(statistics.median(xs), 3),
        "min": round(min(xs), 3),
        "max": round(max(xs), 3),
    }
