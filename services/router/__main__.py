"""The stack's Zenoh router: a plain Python process in router mode, first to start.

Every service is a client of it (`deploy/zenoh/client.json5`); its port comes from
`zenoh.port` (`DUME_ZENOH_PORT`), so several stacks can run on one machine.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
from collections.abc import Sequence

from common.bus import open_session
from common.config import ConfigError, load_config
from common.service import parse_args, place, setup_logging

log = logging.getLogger("dume.router")


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args("router", argv)
    try:
        config = load_config(args.overrides, path=args.config)
    except ConfigError as exc:
        print(f"router: {exc}", file=sys.stderr)
        return 2
    setup_logging(config.log.level, "router")
    place("router", config)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with open_session(config, "router"):
        log.info("router listening on tcp/%s:%d", config.zenoh.host, config.zenoh.port)
        stop.wait()
    log.info("router stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
