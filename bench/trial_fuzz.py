"""`dume trial fuzz`: every key a service takes, fuzzed over a live stack; none may crash.

A full small-world stack (every service, lockstep, a throw-away map). Each service logs
what it takes when it is ready (`Bus.inputs`: its subscriptions and queryables with
their message types). For each of those keys, `count` payloads:

- derived from the key's message type by hypothesis (`st.from_type` on the msgspec
  Struct: any value of each field's Python type, its `Meta` range ignored, so NaN and
  infinities, negative stamps, wrong array sizes, unknown ids and modes), encoded in the
  key's wire format (msgpack, or JSON for the mission's requests);
- malformed: empty, random bytes, a valid payload truncated, a payload of another
  message type, one grown to 1-5 MB, NUL-laden text, a JSON array nested 100 000 deep;

put on a subscribed key, asked (a get) on a queryable. After each key every service's
process must still run and its liveliness token be there (back within `BACK_S` as the
same run: a flood of 5 MB payloads on a loaded 2-core CI host once made the router cut
a service's link off, which reconnected; such a lapse is counted, not a crash, as the
mission doubts it: `common.lifelines`); at the end a valid fetch must
still be held by the mission (`mission/submit`), so the stack still serves. Figures: per
key the cases sent and the replies (typed errors vs answers), per service the crashes and
the logged exceptions, the totals; the rule is 0 crashes.

Keys with a wildcard are aimed at with `fuzz` in its place. Fuzzing the lockstep keys
(the clock, states, acks) may slow or stall the world; that is not a crash, and the
final request only needs to be taken.
"""

from __future__ import annotations

import contextlib
import json
import random
import re
import tempfile
import time
from collections.abc import Iterator
from typing import Any

import msgspec
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

import common.messages.localization
import common.messages.mission
import common.messages.navigation
import common.messages.perception
import common.messages.semantic_map
import common.messages.sim
import common.messages.wbc
import common.messages.world
from common.bus import AliveWatch, NoReply, RemoteError, WaitTimeout
from common.config import Overrides, merged
from common.keys import SERVICES
from common.messages.mission import MissionReceipt, MissionRequest
from deploy.stack import ProcessStack

MODULES = (
    common.messages.localization,
    common.messages.mission,
    common.messages.navigation,
    common.messages.perception,
    common.messages.semantic_map,
    common.messages.sim,
    common.messages.wbc,
    common.messages.world,
)
TAKES = re.compile(r"ready; takes (\[.*\])$")
#: Wall seconds a get waits for its reply (every `ASK_EVERY`-th get is waited for).
REPLY_S = 2.0
ASK_EVERY = 25
#: Wall seconds every service's token has to be back after a key's cases.
BACK_S = 5.0


def message_types() -> dict[str, type[msgspec.Struct]]:
    """Every message Struct by its class name."""
    out: dict[str, type[msgspec.Struct]] = {}
    for module in MODULES:
        for name, cls in vars(module).items():
            if isinstance(cls, type) and issubclass(cls, msgspec.Struct):
                out.setdefault(name, cls)
    return out


def shape(type_: type[msgspec.Struct]) -> st.SearchStrategy[dict[str, Any]]:
    """Dictionaries of `type_`'s fields (any value of each field's type, every optional
    field maybe left out), its tag when it is a tagged union's variant: what a sender
    could put, unchecked by the Struct's own checks (`__post_init__`)."""
    required: dict[str, st.SearchStrategy[Any]] = {}
    optional: dict[str, st.SearchStrategy[Any]] = {}
    for f in msgspec.structs.fields(type_):
        (required if f.required else optional)[f.encode_name] = st.from_type(f.type)
    config = type_.__struct_config__
    if config.tag is not None and config.tag_field is not None:
        required[config.tag_field] = st.just(config.tag)
    return st.fixed_dictionaries(required, optional=optional)


def derived(type_: type[msgspec.Struct], count: int, seed: int) -> list[bytes]:
    """`count` payloads of `type_`'s shape, drawn by hypothesis, in its wire format."""
    out: list[bytes] = []
    wire = msgspec.json if getattr(type_, "WIRE", "msgpack") == "json" else msgspec.msgpack

    @hypothesis_seed(seed)
    @settings(
        max_examples=count,
        database=None,
        deadline=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(shape(type_))
    def draw(fields: dict[str, Any]) -> None:
        # Not even encodable (an int past 64 bits): nothing a sender could put.
        with contextlib.suppress(OverflowError, TypeError, ValueError, msgspec.EncodeError):
            out.append(wire.encode(fields))

    draw()
    return out


def malformed(
    valid: list[bytes], other: list[bytes], count: int, rng: random.Random
) -> Iterator[bytes]:
    """`count` broken payloads (see the module docstring)."""

    def truncated() -> bytes:
        v = rng.choice(valid) if valid else b"\x81\xa1"
        return v[: rng.randint(0, max(len(v) - 1, 0))]

    makers = [
        lambda: b"",
        lambda: rng.randbytes(rng.randint(1, 256)),
        truncated,
        lambda: rng.choice(other) if other else b"\x00",
        lambda: (rng.choice(valid) if valid else b"") + rng.randbytes(rng.randint(1, 5) << 20),
        lambda: b'{"request_id": "\x00\x00", "object": "bottle_1\x00"}',
        lambda: b"[" * 100_000,
        lambda: json.dumps({"stamp_ns": float("nan"), "x": [1e308] * 10}).encode(),
    ]
    for k in range(count):
        yield makers[k % len(makers)]()


def concrete(key: str) -> str:
    """A key to put on for a subscription's key expression."""
    return "/".join("fuzz" if part in ("*", "**") else part for part in key.split("/"))


Input = tuple[str, str, str]


def takes(stack: ProcessStack) -> dict[str, list[Input]]:
    """What each service said it takes when it was ready (its log)."""
    out: dict[str, list[Input]] = {}
    for name in stack.services:
        for line in stack.log_text(name).splitlines():
            m = TAKES.search(line)
            if m:
                out[name] = [(k, t, kind) for k, t, kind in json.loads(m.group(1))]
    return out


def fuzz_settings(seed: int, db_dir: str) -> dict[str, Any]:
    return {
        "sim.world": "small",
        "sim.world_seed": seed,
        "time.mode": "lockstep",
        "semantic_map.start": "seed-from-world",
        "semantic_map.reset": True,
        "semantic_map.dir": db_dir,
        "semantic_map.name": "fuzz",
        "recording.enabled": False,
    }


def fuzz_key(
    stack: ProcessStack,
    target: Input,
    cases: list[bytes],
    watch: AliveWatch,
    runs: dict[str, frozenset[str]],
) -> dict[str, Any]:
    """Send the cases to one key; the stack's state after them (`watch`: the services'
    liveliness tokens, followed since the start; `runs`: each one's run then)."""
    key, type_name, kind = target
    bus, where = stack.bus, concrete(key)
    t0 = time.monotonic()
    answers = errors = 0
    for k, payload in enumerate(cases):
        if kind == "serve":
            replies = bus.session.get(where, payload=payload, timeout=REPLY_S)
            if k % ASK_EVERY == 0:  # wait for one in so many: the queryable keeps up
                for r in replies:
                    answers += r.ok is not None
                    errors += r.err is not None
        else:
            bus.session.put(where, payload)
    losses = _losses(stack, watch)
    with contextlib.suppress(WaitTimeout):
        watch.wait_for({stack.keys.alive(n) for n in SERVICES}, BACK_S)
    down = [n for n, p in stack.procs.items() if p.poll() is not None]
    alive = {k.rsplit("/", 1)[-1] for k in watch.alive()}
    lines = watch.lifelines
    return {
        "key": key, "type": type_name, "kind": kind, "cases": len(cases),
        "answers": answers, "errors": errors, "wall_s": round(time.monotonic() - t0, 1),
        "down": down, "not_alive": sorted(set(SERVICES) - alive),
        "restarted": sorted(n for n in SERVICES
                            if lines.runs(stack.keys.alive(n)) - runs[n]),
        "token_losses": losses,
    }  # fmt: skip


def _runs(stack: ProcessStack, watch: AliveWatch) -> dict[str, frozenset[str]]:
    """Each service's run (its second token, declared just before its first)."""
    deadline = time.monotonic() + BACK_S
    while True:
        runs = {n: watch.lifelines.runs(stack.keys.alive(n)) for n in SERVICES}
        if all(runs.values()) or time.monotonic() > deadline:
            return runs
        time.sleep(0.05)


def _losses(stack: ProcessStack, watch: AliveWatch) -> dict[str, int]:
    """How often each service's token went since the start (a lapse or worse)."""
    _, losses = watch.lifelines.snapshot()
    return {n: c for n in SERVICES if (c := losses.get(stack.keys.alive(n), 0))}


def still_serves(stack: ProcessStack) -> str:
    """Whether the mission still holds a valid fetch handed to it."""
    request = MissionRequest(request_id="after-fuzz", object="bottle_1", person="person_1")
    try:
        receipt = stack.bus.query(stack.keys.mission_submit, request, MissionReceipt, 10.0)
    except (RemoteError, NoReply) as exc:
        return f"not taken: {exc}"
    return f"held: {receipt.request_id}"


def run_fuzz(
    count: int = 10_000, seed: int = 0, overrides: Overrides | None = None
) -> dict[str, Any]:
    """Fuzz every key every service takes with `count` payloads each; the figures."""
    rng = random.Random(seed)
    types = message_types()
    out: dict[str, Any] = {"trial": "fuzz", "world": "small", "seed": seed, "count": count}
    with (
        tempfile.TemporaryDirectory(prefix="dume-fuzz-") as db,
        ProcessStack(list(SERVICES), merged(fuzz_settings(seed, db), overrides or {})) as stack,
    ):
        targets = sorted({t for got in takes(stack).values() for t in got})
        names = sorted({t[1] for t in targets if t[1] in types})
        others = [p for n in names for p in derived(types[n], 20, seed)]
        watch = stack.bus.watch_alive(stack.keys.alive_all)
        watch.wait_for({stack.keys.alive(n) for n in SERVICES}, 30.0)
        runs = _runs(stack, watch)
        started = time.monotonic()
        per_key = []
        for target in targets:
            cls = types.get(target[1])
            valid = derived(cls, count // 2, seed) if cls is not None else []
            cases = [*valid, *malformed(valid, others, count - len(valid), rng)]
            per_key.append(fuzz_key(stack, target, cases, watch, runs))
        wall_s = round(time.monotonic() - started, 1)
        taken = still_serves(stack)
        crashed = sorted(n for n, p in stack.procs.items() if p.poll() is not None)
        losses = _losses(stack, watch)
        tracebacks = {n: stack.log_text(n).count("Traceback") for n in stack.services}
    return out | {
        "keys": len(targets),
        "cases": sum(k["cases"] for k in per_key),
        "wall_s": wall_s,
        "crashed": crashed,
        "keys_with_a_service_down": [
            k["key"] for k in per_key if k["down"] or k["not_alive"] or k["restarted"]
        ],
        "token_losses": losses,
        "logged_exceptions": {n: c for n, c in tracebacks.items() if c},
        "fetch_after": taken,
        "per_key": per_key,
    }
