"""Zenoh, typed: sessions from `deploy/zenoh/*.json5`, publishers, subscribers, queries.

- `open_session(config, role, user=…)` reads the role's JSON5 file and sets the router's
  port from the config (`DUME_ZENOH_PORT`), so stacks run side by side on one machine;
  a client logs in as `user` and the router enforces who may do what (`common.access`).
- `Bus` wraps a session. Publishers are declared once and say their traffic class:
  `control` (state, commands, acks, clock, cmd_vel: real-time priority, never dropped,
  express), `data` (everything else small) and `bulk` (camera frames: lower priority so
  they cannot stall control traffic). Nothing is dropped: lockstep counts every message.
- Subscribers decode in Zenoh's callback (no Zenoh calls, no blocking there) into a
  buffer that the service's own loop reads: `Latest` keeps the newest few samples and
  can pick the newest one at or before a sim time; `Fifo` keeps every sample in order.
  Payloads that fail to decode are counted and kept as `last_error`, never raised into
  Zenoh's thread.
- `serve` answers queries on a worker thread; a handler raises `RequestError` to reply
  with a typed `ErrorReply`. `query` waits with a timeout and raises typed errors.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import queue
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any, Generic, Literal, TypeVar

import msgspec
import zenoh

from common.access import (
    USER,
    CredentialsError,
    access_control,
    ensure_credentials,
    identities,
    link_settings,
)
from common.config import Config, resolve
from common.lifelines import Lifelines
from common.messages import ErrorReply, PayloadError, decode, encode
from common.messages.errors import ErrorCode
from common.truth import TruthGuard

log = logging.getLogger(__name__)

T = TypeVar("T")
S = TypeVar("S", bound="_Subscription[Any]")
R = TypeVar("R")
Role = Literal["client", "router", "peer"]
Traffic = Literal["control", "data", "bulk"]


class BusError(RuntimeError):
    """Base of the bus's typed errors."""


class WaitTimeout(BusError):
    """Something waited on did not arrive in time: what, and how long we waited."""


class NoReply(BusError):
    """A query reached no queryable, or every reply was lost."""


class RemoteError(BusError):
    """The queryable refused the request with a typed `ErrorReply`."""

    def __init__(self, key: str, error: ErrorReply) -> None:
        self.key = key
        self.error = error
        super().__init__(f"{key}: {error.code}: {error.message}")


def _error_of(key: str, raw: bytes) -> BusError:
    """The error a query's error reply stands for: a dume queryable's `ErrorReply`
    (`RemoteError`), or one Zenoh made itself (a timeout on the way, which carries no
    `ErrorReply`: hall eval, a loaded host), a `NoReply` the caller may ask again."""
    try:
        return RemoteError(key, decode(raw, ErrorReply, key=key))
    except PayloadError:
        return NoReply(f"{key}: the transport answered with an error ({raw[:40]!r})")


class RequestError(Exception):
    """Raised by a `serve` handler to refuse a request with a reason."""

    def __init__(self, code: ErrorCode, message: str) -> None:
        self.code = code
        self.message = message
        super().__init__(f"{code}: {message}")


def session_config(
    config: Config,
    role: Role,
    connect_timeout_s: float | None = None,
    user: str | None = USER,
) -> zenoh.Config:
    """The Zenoh config for a role, with the stack's endpoint from `config.zenoh`.

    A client waits for its router forever unless `connect_timeout_s` is given (the CLI's
    commands, which should say "no stack here" rather than hang). Under
    `zenoh.access_control` the router gets the credentials and the ACL, a client logs in
    as `user` (`common.access`; None: no login, which the router refuses).
    """
    z = config.zenoh
    endpoint = f"tcp/{z.host}:{z.port}"
    credentials = resolve(z.credentials)
    if role == "router":
        conf = zenoh.Config.from_file(str(resolve(z.router_config)))
        conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
        if z.access_control:
            ensure_credentials(credentials, identities(config))
            conf.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(credentials)))
            conf.insert_json5("access_control", json.dumps(access_control(config)))
            for path, value in link_settings(config, credentials).items():
                conf.insert_json5(path, json.dumps(value))
    else:
        conf = zenoh.Config.from_file(str(resolve(z.client_config)))
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        if role == "peer":
            conf.insert_json5("mode", json.dumps("peer"))
        if connect_timeout_s is not None:
            conf.insert_json5("connect/timeout_ms", json.dumps(round(connect_timeout_s * 1000)))
            conf.insert_json5("connect/exit_on_failure", "true")
        if z.access_control and user is not None:
            password = ensure_credentials(credentials, identities(config)).get(user)
            if password is None:
                raise CredentialsError(f"{credentials} has no password for {user!r}")
            conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return conf


class NoRouter(BusError):
    """No router answered on the stack's port within the connect timeout."""


def open_session(
    config: Config,
    role: Role = "client",
    connect_timeout_s: float | None = None,
    user: str | None = USER,
) -> zenoh.Session:
    """Open a session (a client logged in as `user`); a client waits for the router
    unless given a timeout."""
    try:
        return zenoh.open(session_config(config, role, connect_timeout_s, user))
    except zenoh.ZError as exc:
        where = f"tcp/{config.zenoh.host}:{config.zenoh.port}"
        login = f", or it refused {user!r}'s login" if config.zenoh.access_control else ""
        raise NoRouter(f"no dume stack answers on {where}{login}: {exc}") from None


_TRAFFIC: dict[str, dict[str, Any]] = {
    "control": dict(
        priority=zenoh.Priority.REAL_TIME,
        congestion_control=zenoh.CongestionControl.BLOCK,
        express=True,
    ),
    "data": dict(priority=zenoh.Priority.DATA, congestion_control=zenoh.CongestionControl.BLOCK),
    "bulk": dict(
        priority=zenoh.Priority.DATA_LOW, congestion_control=zenoh.CongestionControl.BLOCK
    ),
}


class OutputTrace:
    """A running digest of one publisher's payloads, logged every `every_ns` of sim time
    (by the stamps of what it sends): where two runs of one seed part, the first line
    that differs names the key and the second."""

    def __init__(self, key: str, every_ns: int) -> None:
        self.key, self.every_ns = key, every_ns
        self._hash = hashlib.blake2b(digest_size=8)
        self._count = 0
        self._mark = 0

    def add(self, payload: bytes, stamp_ns: int | None) -> None:
        if stamp_ns is not None and stamp_ns >= self._mark + self.every_ns:
            if self._count:
                log.info(
                    "trace %s before t=%.3f s: %d sent, %s",
                    self.key,
                    stamp_ns / 1e9,
                    self._count,
                    self._hash.hexdigest(),
                )
            self._mark = (stamp_ns // self.every_ns) * self.every_ns
        self._hash.update(payload)
        self._count += 1


def _traced(msg: Any, payload: bytes) -> bytes:
    """What a trace hashes: the payload, with its wall-clock fields zeroed."""
    wall = getattr(msg, "WALL_CLOCK", ())
    return encode(msgspec.structs.replace(msg, **dict.fromkeys(wall, 0))) if wall else payload


class Publisher(Generic[T]):
    """A declared publisher of one message type. With `again`, it keeps its last sample,
    and `send_again()` puts that once more (`LinkBack`: what a lockstep participant put
    while its link to the router was cut never arrived). Keeping and putting are one step
    under a lock, so a sample sent again is never put after a newer one."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        traffic: Traffic,
        trace_every_ns: int = 0,
        again: bool = False,
    ) -> None:
        self.key = key
        self._pub = session.declare_publisher(key, **_TRAFFIC[traffic])
        self._trace = OutputTrace(key, trace_every_ns) if trace_every_ns > 0 else None
        self.again = again
        self._last: bytes | None = None
        self._lock = threading.Lock()

    def put(self, msg: T) -> None:
        payload = encode(msg)
        if self._trace is not None:
            self._trace.add(_traced(msg, payload), getattr(msg, "stamp_ns", None))
        if not self.again:
            self._pub.put(payload)
            return
        with self._lock:
            self._last = payload
            self._pub.put(payload)

    def send_again(self) -> bool:
        """Put the last sample once more (a publisher made with `again`); False: none yet."""
        with self._lock:
            if self._last is None:
                return False
            self._pub.put(self._last)
            return True

    def put_raw(self, payload: bytes) -> None:
        if self._trace is not None:
            self._trace.add(payload, None)
        self._pub.put(payload)

    def has_subscribers(self) -> bool:
        """Whether any subscriber matches this key now (Zenoh's matching status)."""
        status: Any = self._pub.matching_status  # a MatchingStatus (the stubs say bool)
        return bool(getattr(status, "matching", status))

    def undeclare(self) -> None:
        self._pub.undeclare()


#: A subscription logs a rejected sample at most this often (wall s); the ones between
#: are counted into the next line (garbage at 20 Hz must not flood a service's log).
REJECT_LOG_EVERY_S = 5.0


class Throttle:
    """At most one line per `every_s` (wall): `due(now)` says whether to log now, and how
    many were held back since the last line."""

    def __init__(self, every_s: float) -> None:
        self.every_s = every_s
        self._last = -float("inf")
        self._held = 0

    def due(self, now: float) -> tuple[bool, int]:
        if now - self._last < self.every_s:
            self._held += 1
            return False, 0
        held, self._held, self._last = self._held, 0, now
        return True, held


class _Subscription(ABC, Generic[T]):
    """One key's samples, or several keys' in one inbox (a tuple of keys: a subscriber
    each; under the router's ACL a publisher hears only of subscribers declared on keys
    it may put, so one on `dume/b1/ack/*` would hear nothing: `Bus.fifo`)."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str | tuple[str, ...],
        type_: type[T],
        stopping: threading.Event | None = None,
    ) -> None:
        keys = (key,) if isinstance(key, str) else key
        self.key = ", ".join(keys)
        self.type = type_
        self.received = 0
        self.rejected = 0
        self.last_error: PayloadError | None = None
        #: Set when the service stops: every wait on this subscription ends (`Bus.interrupt`).
        self.stopping = stopping or threading.Event()
        self._cond = threading.Condition()
        self._warn = Throttle(REJECT_LOG_EVERY_S)
        self._subs = [session.declare_subscriber(k, self._on_sample) for k in keys]

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            msg = decode(sample.payload.to_bytes(), self.type, key=str(sample.key_expr))
        except PayloadError as exc:
            with self._cond:
                self.rejected += 1
                self.last_error = exc
                due, held = self._warn.due(time.monotonic())
            if due:
                more = f" (and {held} more rejected on {self.key} since)" if held else ""
                log.warning("%s%s", exc, more)
            return
        with self._cond:
            self.received += 1
            self._store(msg, str(sample.key_expr))
            self._cond.notify_all()

    @abstractmethod
    def _store(self, msg: T, key: str) -> None:
        """Keep a decoded sample (called with the condition held)."""

    def undeclare(self) -> None:
        for sub in self._subs:
            sub.undeclare()


class Latest(_Subscription[T]):
    """The newest `history` samples. `get()` is the newest; `at(stamp_ns)` the newest at or
    before a sim time (what a lockstep participant must use for its tick)."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        type_: type[T],
        history: int,
        stopping: threading.Event | None = None,
    ) -> None:
        self._buf: deque[T] = deque(maxlen=max(1, history))
        self.last_key = ""
        super().__init__(session, key, type_, stopping)

    def _store(self, msg: T, key: str) -> None:
        self._buf.append(msg)
        self.last_key = key

    def get(self) -> T | None:
        with self._cond:
            return self._buf[-1] if self._buf else None

    def at(self, stamp_ns: int) -> T | None:
        """The newest sample whose `stamp_ns` is at or before `stamp_ns`."""
        with self._cond:
            for msg in reversed(self._buf):
                if msg.stamp_ns <= stamp_ns:  # type: ignore[attr-defined]
                    return msg
            return None

    def wait(self, predicate: Callable[[T], bool], timeout_s: float) -> T:
        """Block until the newest sample satisfies `predicate`; `WaitTimeout` otherwise."""
        met = False

        def done() -> bool:
            nonlocal met
            met = bool(self._buf) and predicate(self._buf[-1])
            return met or self.stopping.is_set()

        with self._cond:
            self._cond.wait_for(done, timeout_s)
            if not met:
                why = "the service stops" if self.stopping.is_set() else f"{timeout_s:.3g} s"
                raise WaitTimeout(f"nothing suitable on {self.key} within {why}")
            return self._buf[-1]

    def wait_stamp(self, stamp_ns: int, timeout_s: float) -> T:
        """Block until a sample stamped at or after `stamp_ns` arrived; return it."""
        return self.wait(lambda m: m.stamp_ns >= stamp_ns, timeout_s)  # type: ignore[attr-defined]


class Fifo(_Subscription[T]):
    """Every sample in arrival order (commands, requests, events), up to `maxlen`."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str | tuple[str, ...],
        type_: type[T],
        maxlen: int,
        stopping: threading.Event | None = None,
    ) -> None:
        self._q: deque[tuple[str, T]] = deque(maxlen=maxlen)
        self.overflowed = 0
        super().__init__(session, key, type_, stopping)

    def _store(self, msg: T, key: str) -> None:
        if len(self._q) == self._q.maxlen:
            self.overflowed += 1
        self._q.append((key, msg))

    def pop(self, timeout_s: float = 0.0) -> T | None:
        item = self.pop_keyed(timeout_s)
        return None if item is None else item[1]

    def pop_keyed(self, timeout_s: float = 0.0) -> tuple[str, T] | None:
        with self._cond:
            if not self._q and timeout_s > 0:
                self._cond.wait_for(lambda: bool(self._q) or self.stopping.is_set(), timeout_s)
            return self._q.popleft() if self._q else None

    def drain(self) -> Iterator[T]:
        while (msg := self.pop()) is not None:
            yield msg

    def wait(self, timeout_s: float) -> bool:
        """Block until a sample is waiting (without taking it); False on timeout."""
        with self._cond:
            self._cond.wait_for(lambda: bool(self._q) or self.stopping.is_set(), timeout_s)
            return bool(self._q)


class Server(Generic[T]):
    """A queryable served on its own thread by `handler(request) -> reply`."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        request_type: type[T] | None,
        handler: Callable[[T | None, str], Any],
    ) -> None:
        self.key = key
        self._type = request_type
        self._handler = handler
        self._q: queue.Queue[zenoh.Query | None] = queue.Queue(maxsize=256)
        self._queryable = session.declare_queryable(key, self._on_query)
        self._thread = threading.Thread(target=self._serve, name=f"serve {key}", daemon=True)
        self._thread.start()

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            self._q.put_nowait(query)
        except queue.Full:
            log.warning("%s: dropping a query, %d waiting", self.key, self._q.qsize())

    def _serve(self) -> None:
        while (query := self._q.get()) is not None:
            key = str(query.key_expr)
            try:
                request: T | None = None
                if self._type is not None:
                    if query.payload is None:
                        raise RequestError("malformed", f"{key} needs a {self._type.__name__}")
                    try:
                        request = decode(query.payload.to_bytes(), self._type, key=key)
                    except PayloadError as exc:
                        raise RequestError("malformed", str(exc)) from None
                reply = self._handler(request, str(query.selector))
                query.reply(key, encode(reply))
            except RequestError as exc:
                query.reply_err(encode(ErrorReply(code=exc.code, message=exc.message, key=key)))
            except Exception as exc:  # a handler bug: say so, keep serving
                log.exception("%s: handler failed", key)
                query.reply_err(
                    encode(
                        ErrorReply(code="internal", message=f"{type(exc).__name__}: {exc}", key=key)
                    )
                )
            finally:
                query.drop()

    def close(self) -> None:
        self._q.put(None)
        self._queryable.undeclare()
        self._thread.join(timeout=1.0)


def alive_now(session: zenoh.Session, key_expr: str, timeout_s: float) -> set[str]:
    """The liveliness tokens the router knows under `key_expr` now."""
    replies = session.liveliness().get(key_expr, timeout=timeout_s)
    return {str(r.ok.key_expr) for r in replies if r.ok is not None}


#: How often a query that nobody answered is asked again (`Bus.query_all`).
QUERY_RETRY_S = 0.1


class AliveWatch:
    """Who is alive under a liveliness key expression, kept current by Zenoh.

    `wait_for` also asks `liveliness().get` once a second while someone is missing: a
    token announced as the subscription was still reaching the router can be missed by
    the subscriber (a fresh-clone CI run waited 300 s for a mission that was up).
    """

    def __init__(self, session: zenoh.Session, key_expr: str) -> None:
        self._session, self._key_expr = session, key_expr
        self._alive: set[str] = set()
        #: Counts changes, so a hot loop can skip looking when nothing changed.
        self.version = 0
        #: The same, with how often each token went away (`common.lifelines`).
        self.lifelines = Lifelines()
        self._cond = threading.Condition()
        self._sub = session.liveliness().declare_subscriber(key_expr, self._on_sample, history=True)
        # each service's second token, its run (`common.lifelines`)
        self._runs = session.liveliness().declare_subscriber(
            f"{key_expr}/*", self._on_run, history=True
        )

    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        with self._cond:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive.add(key)
                self.lifelines.up(key)
            else:
                self._alive.discard(key)
                self.lifelines.down(key)
            self.version += 1
            self._cond.notify_all()

    def _on_run(self, sample: zenoh.Sample) -> None:
        key, run = str(sample.key_expr).rsplit("/", 1)
        if sample.kind == zenoh.SampleKind.PUT:
            self.lifelines.run_up(key, run)
        else:
            self.lifelines.run_down(key, run)

    def alive(self) -> set[str]:
        with self._cond:
            return set(self._alive)

    def wait_for(
        self, keys: set[str], timeout_s: float, stop: threading.Event | None = None
    ) -> None:
        """Return once every key is alive; `WaitTimeout` after `timeout_s`, or within a
        second or two of `stop` being set (a service told to stop while it waits)."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if stop is not None and stop.is_set():
                raise WaitTimeout(f"stopped while waiting for {sorted(keys - self.alive())}")
            with self._cond:
                if self._cond.wait_for(lambda: keys <= self._alive, max(0.0, min(1.0, left))):
                    return
                if left <= 1.0:
                    missing = sorted(keys - self._alive)
                    raise WaitTimeout(f"not alive after {timeout_s:.3g} s: {missing}")
            self._ask()

    def _ask(self) -> None:
        """Who the router says is alive now (added; a DELETE still removes them)."""
        try:
            found = alive_now(self._session, self._key_expr, 1.0)
        except zenoh.ZError as exc:
            log.debug("liveliness get %s: %s", self._key_expr, exc)
            return
        with self._cond:
            if found - self._alive:
                for key in found - self._alive:
                    self.lifelines.up(key)
                self._alive |= found
                self.version += 1
                self._cond.notify_all()

    def undeclare(self) -> None:
        self._sub.undeclare()
        self._runs.undeclare()


#: After a service's link to the router comes back, what it put into the cut is sent
#: again this often (wall s), for this long: a subscriber's declaration can reach the
#: router after the first resend, and the sim waits up to `lockstep.LINK_BACK_S` (5 s) for
#: every service to be back before it sends its own state again.
AGAIN_EVERY_S = 0.25
AGAIN_FOR_S = 8.0


class LinkBack:
    """A service's own link to the router, seen through its own liveliness token.

    Zenoh removes a client's token from its own view when the link to the router goes
    and puts it back once the session has reconnected (a router killed and restarted).
    Whatever the service put in between never arrived: a lockstep participant's ack for
    the tick the sim waits on, the output a consumer's `UpstreamGate` waits on. So on
    the way back `on_back()` is called every `every_s` wall seconds for `for_s`
    (`Bus.send_again`: each kept publisher's last sample); it stops early if the link
    goes again. `backs` counts the returns.
    """

    def __init__(
        self,
        session: zenoh.Session,
        own_key: str,
        on_back: Callable[[], object],
        every_s: float = AGAIN_EVERY_S,
        for_s: float = AGAIN_FOR_S,
    ) -> None:
        self.own_key = own_key
        self._on_back, self._every_s, self._for_s = on_back, every_s, for_s
        self.backs = 0
        self._lost = False
        self._until = 0.0
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed = threading.Event()
        self._sub = session.liveliness().declare_subscriber(own_key, self._on_sample, history=True)
        self._thread = threading.Thread(target=self._run, name=f"link back {own_key}", daemon=True)
        self._thread.start()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._lock:
            if sample.kind != zenoh.SampleKind.PUT:
                self._lost = True
                return
            if not self._lost:
                return  # declared, not back
            self._lost = False
            self.backs += 1
            self._until = time.monotonic() + self._for_s
        log.info("the link to the router is back: sending the last outputs again")
        self._wake.set()

    def _sending(self) -> bool:
        with self._lock:
            return not self._lost and time.monotonic() < self._until

    def _run(self) -> None:
        while not self._closed.is_set():
            if not self._wake.wait(1.0):
                continue
            self._wake.clear()
            while self._sending() and not self._closed.is_set():
                try:
                    self._on_back()
                except Exception:  # a failed round must not end the watch
                    log.exception("sending again after the link came back")
                self._closed.wait(self._every_s)

    def close(self) -> None:
        self._closed.set()
        self._wake.set()
        self._thread.join(timeout=2.0)
        with contextlib.suppress(zenoh.ZError):
            self._sub.undeclare()


class Bus:
    """A Zenoh session with typed helpers. Close it (or use `with`) when done."""

    def __init__(
        self,
        session: zenoh.Session,
        trace_every_s: float = 0.0,
        guard: TruthGuard | None = None,
    ) -> None:
        self.session = session
        self.trace_every_ns = round(trace_every_s * 1e9)
        #: A service's bus refuses to read simulator truth it was not granted.
        self.guard = guard
        self._servers: list[Server[Any]] = []
        self._tokens: list[zenoh.LivelinessToken] = []
        #: Everything this bus did on the network, in order, as (verb, key expression) ->
        #: the message type's name ("" where none): verbs `put`, `subscribe`, `serve`,
        #: `query`, `alive` (a token), `watch_alive`. A service logs it when it stops: what
        #: the router's access list must let it do (`common.access`).
        self.used: dict[tuple[str, str], str] = {}
        #: Set by `interrupt`: every wait on this bus's subscriptions ends at once.
        self.stopping = threading.Event()
        self._subscriptions: list[_Subscription[Any]] = []
        self._again: list[Publisher[Any]] = []
        self._link_back: LinkBack | None = None

    @classmethod
    def open(
        cls,
        config: Config,
        role: Role = "client",
        connect_timeout_s: float | None = None,
        guard: TruthGuard | None = None,
        user: str | None = USER,
    ) -> Bus:
        session = open_session(config, role, connect_timeout_s, user)
        return cls(session, config.log.trace_every_s, guard)

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def publisher(
        self, key: str, type_: type[T], traffic: Traffic = "data", again: bool = False
    ) -> Publisher[T]:
        """A publisher; with `again`, its last sample is put once more when this
        service's link to the router comes back (`watch_own_link`)."""
        self._uses("put", key, type_)
        pub: Publisher[T] = Publisher(self.session, key, traffic, self.trace_every_ns, again)
        if again:
            self._again.append(pub)
        return pub

    def send_again(self) -> int:
        """Put each `again` publisher's last sample once more; how many were put."""
        sent = 0
        for pub in self._again:
            try:
                sent += pub.send_again()
            except zenoh.ZError as exc:  # the link went again: the next round tries
                log.debug("sending %s again: %s", pub.key, exc)
        return sent

    def watch_own_link(self, own_key: str) -> LinkBack:
        """Follow this service's own liveliness token `own_key`: when the link to the
        router comes back after a cut, every `again` publisher sends its last sample
        again (`LinkBack`)."""
        if self._link_back is None:
            self._link_back = LinkBack(self.session, own_key, self.send_again)
        return self._link_back

    def _reads(self, key: str) -> None:
        if self.guard is not None:
            self.guard.check(key)

    def _uses(self, verb: str, key: str, type_: type[Any] | None = None) -> None:
        self.used.setdefault((verb, key), "None" if type_ is None else type_.__name__)

    @property
    def inputs(self) -> list[tuple[str, str, str]]:
        """What this bus takes from outside, in order: (key, type name, "subscribe" or
        "serve"); a service logs it when ready, and the fuzzing trial aims at it."""
        return [(k, t, v) for (v, k), t in self.used.items() if v in ("subscribe", "serve")]

    def latest(self, key: str, type_: type[T], history: int = 1) -> Latest[T]:
        self._reads(key)
        self._uses("subscribe", key, type_)
        return self._keep(Latest(self.session, key, type_, history, self.stopping))

    def fifo(self, key: str | tuple[str, ...], type_: type[T], maxlen: int = 1024) -> Fifo[T]:
        """Every sample of `key` (or of each of a tuple of keys, in one inbox: a key
        each, not a wildcard, where the publishers must hear of the subscription)."""
        for k in (key,) if isinstance(key, str) else key:
            self._reads(k)
            self._uses("subscribe", k, type_)
        return self._keep(Fifo(self.session, key, type_, maxlen, self.stopping))

    def _keep(self, sub: S) -> S:
        self._subscriptions.append(sub)
        return sub

    def interrupt(self) -> None:
        """The service stops: every wait on this bus's subscriptions ends now (raising
        `WaitTimeout` or returning nothing), so no loop sits out an input's timeout (a
        lockstep service waiting for a dead WBC's odom took 30 s to stop)."""
        self.stopping.set()
        for sub in self._subscriptions:
            with sub._cond:
                sub._cond.notify_all()

    def raw(self, key: str, type_: type[Any], callback: Callable[[bytes], None]) -> Any:
        """Every sample of `key` to `callback` as bytes, on Zenoh's thread (the caller
        decodes `type_` itself, later, on its own thread)."""
        self._reads(key)
        self._uses("subscribe", key, type_)
        return self.session.declare_subscriber(key, lambda s: callback(s.payload.to_bytes()))

    def serve(
        self,
        key: str,
        request_type: type[T] | None,
        handler: Callable[[T | None, str], Any],
    ) -> Server[T]:
        self._uses("serve", key, request_type)
        server = Server(self.session, key, request_type, handler)
        self._servers.append(server)
        return server

    def query(self, key: str, request: Any, reply_type: type[R], timeout_s: float = 5.0) -> R:
        """One reply of `reply_type`; `RemoteError`, `NoReply` or `PayloadError` otherwise."""
        replies = self.query_all(key, request, reply_type, timeout_s)
        if not replies:
            raise NoReply(f"no queryable answered {key} within {timeout_s:.3g} s")
        return replies[0]

    def query_all(
        self, key: str, request: Any, reply_type: type[R], timeout_s: float = 5.0
    ) -> list[R]:
        """Every reply; asks again until `timeout_s` while nobody answers.

        A get that no queryable matches ends at once with no reply. A queryable this
        session has not heard of yet (its declaration still on its way, or one a fresh-
        clone CI run never saw reach a session opened as the services started) is
        therefore asked again every `QUERY_RETRY_S` until the deadline.
        """
        self._reads(key)
        self._uses("query", key.split("?", 1)[0], reply_type)
        payload = None if request is None else encode(request)
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            out: list[R] = []
            for reply in self.session.get(key, payload=payload, timeout=max(left, 0.01)):
                if reply.ok is not None:
                    out.append(decode(reply.ok.payload.to_bytes(), reply_type, key=key))
                elif reply.err is not None:
                    raise _error_of(key, reply.err.payload.to_bytes())
            if out or deadline - time.monotonic() < QUERY_RETRY_S:
                return out
            time.sleep(QUERY_RETRY_S)

    def declare_alive(self, key: str) -> None:
        """Declare a liveliness token (kept until the bus closes)."""
        self._uses("alive", key)
        self._tokens.append(self.session.liveliness().declare_token(key))

    def watch_alive(self, key_expr: str) -> AliveWatch:
        self._uses("watch_alive", key_expr)
        return AliveWatch(self.session, key_expr)

    def alive_now(self, key_expr: str, timeout_s: float = 2.0) -> set[str]:
        self._uses("watch_alive", key_expr)
        return alive_now(self.session, key_expr, timeout_s)

    def close(self) -> None:
        if self._link_back is not None:
            self._link_back.close()
            self._link_back = None
        for server in self._servers:
            server.close()
        for token in self._tokens:
            token.undeclare()
        self._servers.clear()
        self._tokens.clear()
        self.session.close()
