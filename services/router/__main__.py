"""The stack's Zenoh router: a plain Python process in router mode, first to start.

Every service is a client of it (`deploy/zenoh/client.json5`); its port comes from
`zenoh.port` (`DUME_ZENOH_PORT`), so several stacks can run on one machine. On one host
of two (`zenoh.side`) it is also linked to the other host's router (`common.access`).
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
from collections.abc import Sequence

from common.access import CredentialsError
from common.bus import open_session
from common.certs import CertsError
from common.config import ConfigError, load_config
from common.service import exit_with_parent, parse_args, place, setup_logging

log = logging.getLogger("dume.router")


def main(argv: Sequence[str] | None = None) -> int:
    exit_with_parent()
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
    try:
        session = open_session(config, "router")
    except (CertsError, CredentialsError) as exc:  # nothing to retry: say what is missing
        log.error("router cannot start: %s", exc)
        return 2
    with session:
        z = config.zenoh
        log.info("router listening on tcp/%s:%d", z.host, z.port)
        if z.side != "all":
            how = "listens for the station" if z.side == "robot" else "connects to the robot"
            log.info("the %s's router %s on tls/%s:%d", z.side, how, z.link_host, z.link_port)
        stop.wait()
    log.info("router stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
