"""A periodic lockstep participant for the determinism test: it feeds back the base height.

Every 20 ms of sim time it reads odom as of its tick, publishes an arm offset that depends
on it (on `dume/<r>/test/wiggle`, stamped with the tick), and acks. If the sim's
lockstep did not model its timing, the offset would reach the commander at different
ticks from run to run, and the trajectories would differ.
"""

from __future__ import annotations

import math
import sys

from common.lockstep import PeriodicTicker
from common.messages.sim import Odom
from common.messages.wbc import CmdVel
from common.service import Service, run

NAME = "wiggle"


def key(svc: Service) -> str:
    return f"{svc.keys.prefix}/test/wiggle"


def main(svc: Service) -> None:
    period = svc.config.time.participants[NAME].period_s
    odom = svc.bus.latest(svc.keys.odom, Odom, history=32)
    out = svc.bus.publisher(key(svc), CmdVel, "control")
    ticker = PeriodicTicker(svc.bus, svc.keys, NAME, period, svc.stop)
    svc.ready()
    for stamp in ticker.ticks():
        # odom comes at 50 Hz, on this participant's ticks: wait for the one stamped now
        odom.wait_stamp(stamp, svc.config.time.stall_timeout_s)
        o = odom.at(stamp)
        z = o.base_position_in_world[2] if o is not None else 0.5
        offset = 0.4 * math.sin(2 * math.pi * 0.7 * stamp * 1e-9) + 5.0 * (z - 0.5)
        out.put(CmdVel(stamp_ns=stamp, vx=offset, vy=0.0, wz=0.0, source=NAME))
        ticker.ack(stamp)


if __name__ == "__main__":
    sys.exit(run(NAME, main))
