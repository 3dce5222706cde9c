"""A slow consumer, for the fault battery (`dume trial faults --services client
--signals slow`): a client of the stack's router that subscribes to everything the
robot publishes (`dume/<robot>/**`: states at 1 kHz, the cameras, the scan) and stalls
`--stall` seconds in its first callback, as a viewer or a logger that hangs would. Zenoh
runs a subscriber's callback on the session's own receiving thread, so for those
seconds it reads nothing from its link and the router's queue towards it fills. After
the stall it takes everything as it comes, until it is killed.

Usage: python -m bench.slow_consumer --stall 5 (the stack's environment: DUME_*).
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

import zenoh

from common.access import TRUSTED
from common.bus import open_session
from common.config import load_config
from common.keys import RobotKeys


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--stall", type=float, default=5.0, help="wall seconds the first callback takes")
    args = p.parse_args(argv)
    config = load_config()
    stalled = threading.Event()

    def on_sample(_sample: zenoh.Sample) -> None:
        if not stalled.is_set():
            stalled.set()
            print(f"slow consumer: stalling {args.stall} s", flush=True)
            time.sleep(args.stall)
            print("slow consumer: taking samples again", flush=True)

    with open_session(config, user=TRUSTED) as session:
        sub = session.declare_subscriber(f"{RobotKeys(config.robot).prefix}/**", on_sample)
        try:
            threading.Event().wait()
        finally:
            sub.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main())
