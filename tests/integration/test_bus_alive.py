"""`common.bus.AliveWatch` on a real Zenoh session (loopback, scouting off)."""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest
import zenoh

from common.bus import (
    AliveWatch,
    Bus,
    NoReply,
    RemoteError,
    RequestError,
    Throttle,
    WaitTimeout,
)
from common.messages import ErrorReply
from tests.integration.peers import loopback_peer

_session = loopback_peer


def test_a_token_whose_announcement_was_missed_is_found_by_asking() -> None:
    """A fresh-clone CI run waited 300 s for a service that was up: the watch had missed
    its token's PUT. Waiting also asks who is alive."""
    with _session() as s:
        watch = AliveWatch(s, "test/alive/*")
        token = s.liveliness().declare_token("test/alive/a")
        watch.wait_for({"test/alive/a"}, 5.0)
        watch._alive.clear()  # the PUT never arrived
        watch.wait_for({"test/alive/a"}, 5.0)
        assert watch.alive() == {"test/alive/a"}
        with pytest.raises(WaitTimeout, match="test/alive/b"):
            watch.wait_for({"test/alive/a", "test/alive/b"}, 1.5)
        token.undeclare()
        watch.undeclare()


def test_a_wait_for_the_alive_ends_when_its_service_is_told_to_stop() -> None:
    """A sim SIGTERMed while its stack came up waited at its start gate for the 120 s of
    `time.start_timeout_s`: a stop ends the wait, naming who it waited for."""
    with _session() as s:
        watch = AliveWatch(s, "test/alive/*")
        stop = threading.Event()
        threading.Timer(0.3, stop.set).start()
        with pytest.raises(WaitTimeout, match=r"stopped while waiting for \['test/alive/b'\]"):
            watch.wait_for({"test/alive/b"}, 600.0, stop)


def test_a_query_asks_again_until_a_late_queryable_answers() -> None:
    """A get nobody matches ends at once with no reply (a fresh-clone CI eval read the
    map 'within 10 s' and failed at once): `Bus.query` asks again until its deadline."""
    with _session() as s:
        bus = Bus(s)
        answer = ErrorReply("internal", "late")
        late = threading.Timer(0.5, lambda: bus.serve("test/late", None, lambda _r, _s: answer))
        late.start()
        try:
            reply = bus.query("test/late", None, ErrorReply, 5.0)
        finally:
            late.join()
        assert reply == answer
        with pytest.raises(NoReply, match="test/nobody"):
            bus.query("test/nobody", None, ErrorReply, 0.5)
        for server in bus._servers:
            server.close()


def test_an_error_reply_that_is_not_dumes_is_a_no_reply_and_ours_a_remote_error() -> None:
    """Zenoh answers a query with an error of its own (a timeout on the way: a loaded
    hall eval's localization asking for the map) that is no `ErrorReply`: it crashed
    the asker with a `PayloadError`; it is a `NoReply` the asker may ask again."""
    with _session() as s:
        bus = Bus(s)
        raw = s.declare_queryable("test/raw", lambda q: q.reply_err(b"\x05"))
        ours = bus.serve("test/ours", None, lambda _r, _s: (_ for _ in ()).throw(
            RequestError("unknown_id", "no such thing")))  # fmt: skip
        try:
            with pytest.raises(NoReply, match="the transport answered with an error"):
                bus.query("test/raw", None, ErrorReply, 2.0)
            with pytest.raises(RemoteError, match="unknown_id: no such thing"):
                bus.query("test/ours", None, ErrorReply, 2.0)
        finally:
            raw.undeclare()
            ours.close()


def test_garbage_on_a_subscribed_key_is_counted_and_logged_at_most_every_5_s(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The probe: garbage at 20 Hz on `wbc/cmd_vel` logged one WARNING per sample."""
    with _session() as s, caplog.at_level("WARNING", logger="common.bus"):
        bus = Bus(s)
        sub = bus.fifo("test/garbage", ErrorReply)
        pub = s.declare_publisher("test/garbage")
        for _ in range(200):
            pub.put(b"\\x00 not a payload")
        deadline = time.monotonic() + 5.0
        while sub.rejected < 200 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sub.rejected == 200 and sub.received == 0
        lines = [r for r in caplog.records if "test/garbage" in r.getMessage()]
        assert len(lines) == 1  # the first; the rest wait for the next line, 5 s on
        pub.undeclare()
        sub.undeclare()


def test_the_throttle_says_when_to_log_and_how_many_it_held_back() -> None:
    t = Throttle(5.0)
    assert t.due(100.0) == (True, 0)
    assert [t.due(100.0 + k)[0] for k in range(1, 5)] == [False] * 4
    assert t.due(105.0) == (True, 4)
    assert t.due(106.0) == (False, 0)


def test_a_stopping_service_ends_every_wait_on_its_bus_at_once() -> None:
    """A lockstep service waiting for a dead WBC's odom sat out its 30 s timeout before it
    could stop: `interrupt` ends every wait, a `Latest`'s (raises) and a `Fifo`'s."""
    with _session() as s:
        bus = Bus(s)
        latest = bus.latest("test/odom", ErrorReply)
        fifo = bus.fifo("test/requests", ErrorReply)
        ended: list[str] = []

        def wait_latest() -> None:
            try:
                latest.wait_stamp(1, 60.0)
            except WaitTimeout as exc:
                ended.append(str(exc))

        threads = [
            threading.Thread(target=wait_latest),
            threading.Thread(target=lambda: ended.append(str(fifo.pop(timeout_s=60.0)))),
        ]
        for t in threads:
            t.start()
        time.sleep(0.2)
        bus.interrupt()
        for t in threads:
            t.join(timeout=20.0)
        assert not any(t.is_alive() for t in threads), "a wait sat out its 60 s"
        assert sorted(ended) == ["None", "nothing suitable on test/odom within the service stops"]


def _linked(port: int, mode: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    where = "listen/endpoints" if mode == "router" else "connect/endpoints"
    conf.insert_json5(where, json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if mode == "client":
        conf.insert_json5(
            "connect/retry", "{period_init_ms: 50, period_max_ms: 500, period_increase_factor: 2}"
        )
    return zenoh.open(conf)


def test_what_was_put_while_the_router_was_gone_is_sent_again_when_it_is_back() -> None:
    """A router killed and restarted: a lockstep participant's ack put into the cut never
    arrives, and the sim waited for it until its stall timeout (24.9 s held in a trial).
    The participant's own token tells it the link is back; its `again` publishers then
    put their last sample once more (and a plain publisher does not)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    router = _linked(port, "router")
    producer, consumer = Bus(_linked(port, "client")), Bus(_linked(port, "client"))
    try:
        producer.declare_alive("test/alive/p/run")
        link = producer.watch_own_link("test/alive/p/run")
        acks = consumer.fifo("test/ack", ErrorReply, 64)
        plain = consumer.fifo("test/plain", ErrorReply, 64)
        ack = producer.publisher("test/ack", ErrorReply, "control", again=True)
        other = producer.publisher("test/plain", ErrorReply)
        time.sleep(0.5)
        ack.put(ErrorReply("internal", "tick 1"))
        assert acks.pop(2.0) == ErrorReply("internal", "tick 1")
        router.close()
        time.sleep(1.0)
        ack.put(ErrorReply("internal", "tick 2"))  # into the cut
        other.put(ErrorReply("internal", "plain"))
        assert acks.pop(0.5) is None
        router = _linked(port, "router")
        assert acks.pop(10.0) == ErrorReply("internal", "tick 2")
        assert link.backs == 1
        time.sleep(1.0)
        again = list(acks.drain())
        assert again and set(again) == {ErrorReply("internal", "tick 2")}, again
        assert plain.pop(0.0) is None
    finally:
        producer.close()
        consumer.close()
        router.close()
