"""A Zenoh peer session on loopback (a free port, scouting off): for tests of the bus
itself, with no router."""

from __future__ import annotations

import json
import socket

import zenoh


def loopback_peer() -> zenoh.Session:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)
