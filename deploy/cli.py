"""`dume`: the command line of a dume stack.

    dume up [--world-seed N] [--world small] [--realtime] [--start-pose X Y YAW]
                                                         supervisord in the foreground
    dume status                                             who is alive; the mission's state
    dume world --seed N [--world small] [--grid]            a generated world as JSON
    dume request OBJECT --to PERSON [--wait --timeout S]    ask for an object
    dume cancel REQUEST_ID [--reason TEXT]                  cancel a request
    dume map [--patrol | --export FILE | --import FILE]     the semantic map (JSON)
    dume demo [--world-seed N] [--object ID --person ID]    bring an object, print a JSON line
    dume eval --worlds N --seed S --out DIR                 N worlds judged from truth: a report
    dume bench sim|wbc|nav|stack|all                        print figures (JSON last line)
    dume trial walk|turn|strafe|random|reach|pick|push [--world-seed N]   a trial (JSON)
    dume trial goto X Y [--yaw Θ] [--world hall|small]   walk to a pose over the nav stack (JSON)
    dume trial goals [--count 10] | person             random goals; a person stepping in (JSON)
    dume train-segmenter [--seed S]                         render data, train, export ONNX

Every command takes `--port` (default: `DUME_ZENOH_PORT` or the config's) to talk to the
stack on that port, and `--set key=value` to override settings.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import sys
import time
import uuid
from collections.abc import Sequence
from typing import Any

import msgspec

from common.bus import Bus, NoRouter, WaitTimeout
from common.config import REPO_ROOT, Config, ConfigError, load_config, merged, parse_overrides
from common.keys import SERVICES, RobotKeys, service_of_alive_key
from common.lifelines import Dependencies
from common.messages import encode
from common.messages.mission import MissionCancel, MissionRequest, MissionStatus

#: How long a command waits for the stack's router before saying there is none.
CONNECT_TIMEOUT_S = 3.0


def _client_config(args: argparse.Namespace) -> Config:
    return load_config(merged(parse_overrides(args.set), _port(args)))


def _port(args: argparse.Namespace) -> dict[str, Any]:
    return {"zenoh.port": args.port} if args.port else {}


def cmd_up(args: argparse.Namespace) -> int:
    from common.recording import new_run_id
    from deploy.stack import SUPERVISORD_CONF, settings_env, stack_env, with_start_pose

    realtime = {"time.mode": "realtime"} if args.realtime else {}
    start = {"localization.start_pose": list(args.start_pose)} if args.start_pose else {}
    settings = with_start_pose(
        merged(
            {"sim.world_seed": args.world_seed, "sim.world": args.world},
            parse_overrides(args.set),
            realtime,
            start,
            _port(args),
        )
    )
    config = load_config(settings)
    run_id = new_run_id()
    run_dir = REPO_ROOT / "var" / "run" / run_id
    run_dir.mkdir(parents=True, exist_ok=True)
    env = stack_env(
        port=config.zenoh.port,
        run_id=run_id,
        run_dir=run_dir,
        settings=settings_env(run_dir, settings),
    )
    exe = os.path.join(os.path.dirname(sys.executable), "supervisord")
    print(
        f"dume up: run {run_id}, zenoh port {config.zenoh.port}, {config.sim.world} world "
        f"seed {config.sim.world_seed}, {config.time.mode}; logs in {run_dir}",
        file=sys.stderr,
    )
    os.execve(exe, [exe, "-c", str(SUPERVISORD_CONF)], env)
    return 0  # not reached


def cmd_status(args: argparse.Namespace) -> int:
    config = _client_config(args)
    keys = RobotKeys(config.robot)
    with Bus.open(config, connect_timeout_s=CONNECT_TIMEOUT_S) as bus:
        alive = sorted(service_of_alive_key(k) for k in bus.alive_now(keys.alive_all, 2.0))
        status_sub = bus.latest(keys.mission_status, MissionStatus)
        try:
            status: MissionStatus | None = status_sub.wait(lambda _m: True, args.wait)
        except WaitTimeout:
            status = None
    out = {
        "robot": config.robot,
        "port": config.zenoh.port,
        "alive": alive,
        "missing": [s for s in SERVICES if s not in alive],
        "mission": None if status is None else msgspec.to_builtins(status),
    }
    print(json.dumps(out))
    return 0 if alive else 1


def cmd_world(args: argparse.Namespace) -> int:
    from services.sim.world import generate_world

    world = generate_world(args.seed, args.world, walking_people=args.walking_people)
    data = msgspec.to_builtins(world)
    if not args.grid:
        data.pop("occupancy", None)
    print(json.dumps(data, indent=2 if args.pretty else None))
    return 0


def cmd_request(args: argparse.Namespace) -> int:
    config = _client_config(args)
    keys = RobotKeys(config.robot)
    request = MissionRequest(
        request_id=args.request_id or uuid.uuid4().hex[:12], object=args.object, person=args.to
    )
    with Bus.open(config, connect_timeout_s=CONNECT_TIMEOUT_S) as bus:
        statuses = bus.fifo(keys.mission_status, MissionStatus)
        alive = bus.watch_alive(keys.alive_all)
        mission = Dependencies(alive.lifelines, ["mission"], keys.alive)
        time.sleep(0.2)  # let the subscription reach the router before the request goes out
        with contextlib.suppress(WaitTimeout):
            alive.wait_for({keys.alive("mission")}, 2.0)
        mission.arm()
        bus.session.put(keys.mission_request, encode(request))
        print(json.dumps({"request_id": request.request_id, "sent": msgspec.to_builtins(request)}))
        if not args.wait:
            return 0
        deadline = time.monotonic() + args.timeout
        ours = False
        while time.monotonic() < deadline:
            status = statuses.pop(timeout_s=0.2)
            # Nobody waits for the dead: a mission gone, restarted or without our request.
            lost = mission.lost() or ("mission is not running" if mission.missing() else None)
            if status is not None and status.request_id != request.request_id:
                if ours and status.state == "idle":
                    lost = "mission restarted: it has no request in progress"
                status = None
            if lost is not None:
                out = {"request_id": request.request_id, "outcome": "dependency_lost"}
                print(json.dumps(out | {"reason": lost}))
                return 3
            if status is None:
                continue
            ours = True
            print(json.dumps(msgspec.to_builtins(status)), flush=True)
            if status.state == "succeeded":
                return 0
            if status.state in ("failed", "cancelled", "rejected"):
                return 1
        print(
            json.dumps(
                {
                    "request_id": request.request_id,
                    "outcome": "timeout",
                    "reason": "the mission did not finish in time",
                }
            )
        )
        return 3


def cmd_cancel(args: argparse.Namespace) -> int:
    config = _client_config(args)
    keys = RobotKeys(config.robot)
    with Bus.open(config, connect_timeout_s=CONNECT_TIMEOUT_S) as bus:
        bus.session.put(
            keys.mission_cancel,
            encode(MissionCancel(request_id=args.request_id, reason=args.reason)),
        )
    print(json.dumps({"cancelled": args.request_id}))
    return 0


def cmd_map(args: argparse.Namespace) -> int:
    from pathlib import Path

    from common.keys import MAP_ARTIFACTS, MAP_EXPORT, MAP_IMPORT, MAP_PEOPLE
    from common.messages.mission import PatrolRequest, PatrolStatus
    from common.messages.semantic_map import MapFile, MapListing, MapSummary
    from services.semantic_map.mapfile import read_map_file, write_map_file

    config = _client_config(args)
    keys = RobotKeys(config.robot)
    with Bus.open(config, connect_timeout_s=CONNECT_TIMEOUT_S) as bus:
        if args.export:
            mf = bus.query(MAP_EXPORT, None, MapFile, 10.0)
            write_map_file(Path(args.export), mf)
            print(json.dumps({"exported": args.export, "entities": len(mf.entities)}))
            return 0
        if args.import_:
            summary = bus.query(MAP_IMPORT, read_map_file(Path(args.import_)), MapSummary, 10.0)
            print(json.dumps(msgspec.to_builtins(summary)))
            return 0

        def listings() -> dict[str, list[Any]]:
            return {
                kind: bus.query(key, None, MapListing, 5.0).entities
                for kind, key in (("artifacts", MAP_ARTIFACTS), ("people", MAP_PEOPLE))
            }

        if args.patrol:  # the mission walks it; the map's counts beside its status
            req = PatrolRequest(action="start", spacing_m=args.spacing)
            status = bus.query(keys.mission_patrol, req, PatrolStatus, 30.0)
            deadline = time.monotonic() + args.timeout
            while status.state == "running" and time.monotonic() < deadline:
                time.sleep(2.0)
                status = bus.query(
                    keys.mission_patrol, PatrolRequest(action="status"), PatrolStatus
                )
                counts = {kind: len(es) for kind, es in listings().items()}
                line = msgspec.to_builtins(status) | counts
                print(json.dumps(line), file=sys.stderr, flush=True)
            if status.state == "running":
                status = bus.query(keys.mission_patrol, PatrolRequest(action="stop"), PatrolStatus)
            if status.state == "rejected":
                print(json.dumps(msgspec.to_builtins(status)))
                return 1
        mapped = listings()
    print(json.dumps({k: [msgspec.to_builtins(e) for e in v] for k, v in mapped.items()}))
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from deploy.demo import run_demo

    return run_demo(args)


def cmd_eval(args: argparse.Namespace) -> int:
    from bench.eval.evaluate import run_eval

    return run_eval(args)


def cmd_bench(args: argparse.Namespace) -> int:
    from bench import BenchOptions, run_bench
    from bench.eval.run import sigterm_interrupts

    with sigterm_interrupts():  # a killed bench still stops its stack
        return run_bench(args.which, args.set, BenchOptions(args.rounds, args.sim_s, args.full))


def cmd_trial(args: argparse.Namespace) -> int:
    from bench.eval.run import sigterm_interrupts
    from bench.trials import run_trial

    options: dict[str, object] = {"world": args.world, "count": args.count, "yaw": args.yaw}
    if args.which == "goto":
        if len(args.xy) != 2:
            print("dume trial goto needs X Y (m, world)", file=sys.stderr)
            return 2
        options |= {"x": args.xy[0], "y": args.xy[1]}
    with sigterm_interrupts():  # a killed trial still stops its stack
        settings = parse_overrides(args.set)
        result = run_trial(args.which, args.world_seed, args.wbc_period, settings, options)
    print(json.dumps(result))
    return 0


def cmd_train_segmenter(args: argparse.Namespace) -> int:
    import logging

    from services.perception.segmenter import DEFAULT_MODEL
    from services.perception.training.train import TrainSettings, train_segmenter
    from services.sim.dataset import write_dataset

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    shards = REPO_ROOT / "var" / "datasets" / "segmenter"
    train = list(range(args.train_seeds))
    val = list(range(10_000, 10_000 + args.val_seeds))  # held out: never trained on
    for _ in write_dataset([*val, *train], shards):
        pass
    settings = TrainSettings(
        shards=shards,
        out=args.out or DEFAULT_MODEL,
        train_seeds=train,
        val_seeds=val,
        seed=args.seed,
        steps=args.steps,
    )
    print(json.dumps(train_segmenter(settings)["validation"]))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dume", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)

    def add(name: str, help_: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_)
        p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
        p.add_argument("--port", type=int, default=None, help="the stack's Zenoh port")
        return p

    p = add("up", "run the stack under supervisord in the foreground")
    p.add_argument("--world-seed", type=int, default=0)
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--realtime", action="store_true", help="pace the sim to the wall clock")
    p.add_argument(
        "--start-pose",
        nargs=3,
        type=float,
        metavar=("X", "Y", "YAW"),
        help="where the robot stands, m m rad in the map (default: the world's start)",
    )
    p.set_defaults(func=cmd_up)

    p = add("status", "which services are alive and ready; the latest mission status")
    p.add_argument("--wait", type=float, default=0.5, help="seconds to listen for a status")
    p.set_defaults(func=cmd_status)

    p = add("world", "print a generated world as JSON")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--walking-people", action="store_true")
    p.add_argument("--grid", action="store_true", help="include the occupancy grid")
    p.add_argument("--pretty", action="store_true")
    p.set_defaults(func=cmd_world)

    p = add("request", "ask the robot to bring OBJECT to PERSON")
    p.add_argument("object", help="a map id (bottle_1) or a class (bottle)")
    p.add_argument("--to", required=True, help="a person's map id (person_1)")
    p.add_argument("--request-id", default=None)
    p.add_argument("--wait", action="store_true", help="follow the status until it ends")
    p.add_argument("--timeout", type=float, default=600.0)
    p.set_defaults(func=cmd_request)

    p = add("cancel", "cancel a request")
    p.add_argument("request_id")
    p.add_argument("--reason", default="cancelled by the user")
    p.set_defaults(func=cmd_cancel)

    p = add("map", "the semantic map: walk the mapping patrol, export, import; lists it")
    what = p.add_mutually_exclusive_group()
    what.add_argument(
        "--patrol", action="store_true", help="the mission walks a coverage route; the map maps it"
    )
    what.add_argument("--export", metavar="FILE", help="write the map as JSON")
    what.add_argument("--import", dest="import_", metavar="FILE", help="replace the map")
    p.add_argument("--spacing", type=float, default=0.0, help="patrol viewpoint spacing, m")
    p.add_argument("--timeout", type=float, default=3600.0, help="wall seconds for the patrol")
    p.set_defaults(func=cmd_map)

    p = add("demo", "start a stack, bring an object to a person, stop it, print a JSON result")
    p.description = (
        "Start every service under supervisord, ask for an object for a person (by default "
        "the bottle and the person farthest apart in the map), show the mission's progress, "
        "stop, and print a JSON line; exit 0 only on success. The semantic map starts from "
        "the world's truth positions with noise (seed-from-world), standing in for an earlier "
        "mapping run, unless --map gives a prior map file."
    )
    p.add_argument("--world-seed", type=int, default=0)
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--object", default=None, help="a map id or class (default: a bottle)")
    p.add_argument("--person", default=None, help="a person's map id (default: the farthest)")
    p.add_argument("--map", default=None, metavar="FILE", help="a prior map file (dume map)")
    p.add_argument("--timeout", type=float, default=600.0, help="sim seconds for the mission")
    p.set_defaults(func=cmd_demo)

    p = add("eval", "N seeded worlds, one request each, judged from sim truth; a report")
    p.description = (
        "N seeded worlds (seeds S..S+N-1), each on a fresh stack with the default segmenter and "
        "the dynamic controller, the map seeded from the world's truth with noise; one random "
        "mapped artifact and person requested per world; success judged from the sim's "
        "handover event. Writes DIR/report.md, DIR/results.json and PNG plots; the last "
        "stdout line is a JSON summary."
    )
    p.add_argument("--worlds", type=int, default=20, help="how many worlds")
    p.add_argument("--seed", type=int, default=0, help="world i is seed S + i")
    p.add_argument("--out", default="var/eval/latest", metavar="DIR")
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--walking-people", action="store_true", help="the walking-people scenario")
    p.add_argument("--timeout", type=float, default=300.0, help="sim seconds per world")
    p.add_argument("--record", action="store_true", help="write each world's recording")
    p.set_defaults(func=cmd_eval)

    p = add("bench", "benchmarks; each prints JSON on its last line")
    from bench import BENCHES, TRIALS

    p.add_argument("which", choices=[*BENCHES, "all"])
    p.add_argument("--rounds", type=int, default=10, help="startup, decoders: rounds")
    p.add_argument("--sim-s", type=float, default=60.0, help="stack: sim seconds measured")
    p.add_argument("--full", action="store_true", help="stack: the whole demo request")
    p.set_defaults(func=cmd_bench)

    p = add("trial", "a whole-body controller trial over a real stack; JSON on the last line")
    p.add_argument("which", choices=TRIALS)
    p.add_argument("xy", nargs="*", type=float, help="goto: the goal's X Y, m in the world")
    p.add_argument("--yaw", type=float, default=0.0, help="goto: the goal's yaw, rad")
    p.add_argument("--world", choices=["hall", "small"], default=None, help="goto, goals")
    p.add_argument("--count", type=int, default=10, help="goals: how many")
    p.add_argument("--world-seed", type=int, default=None, help="default: the trial's own")
    p.add_argument("--wbc-period", type=float, default=0.002, help="the controller's period, s")
    p.set_defaults(func=cmd_trial)

    p = add("train-segmenter", "render sim data, train the segmenter, export and validate it")
    p.add_argument("--seed", type=int, default=0, help="seeds torch and the data order")
    p.add_argument("--train-seeds", type=int, default=180, help="worlds 0..N-1 to train on")
    p.add_argument("--val-seeds", type=int, default=24, help="held-out worlds from 10000")
    p.add_argument("--steps", type=int, default=4000)
    p.add_argument("--out", type=pathlib.Path, default=None, help="default: the shipped model")
    p.set_defaults(func=cmd_train_segmenter)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except ConfigError as exc:
        print(f"dume: {exc}", file=sys.stderr)
        return 2
    except NoRouter as exc:
        print(f"dume: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
