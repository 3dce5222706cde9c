"""`dume`: the command line of a dume stack.

    dume up [--world-seed N] [--world small] [--map FILE|truth] [--realtime]
            [--start-pose X Y YAW]                       supervisord in the foreground
    dume status [--ready S]                                 who is alive; the mission's state
    dume runs [--all]                                       the runs that are up, their folders
    dume logs [SERVICE] [--run RUN] [-f]                    a run's files, or a service's log
    dume ctl [--run RUN] [status | restart sim | ...]       supervisorctl on a run
    dume view [RUN] [--web | --snapshot FILE.png]           a run's recording in rerun
    dume down [--run RUN]                                   stop a `dume up` run
    dume world --world-seed N [--world small] [--grid]      a generated world as JSON (truth)
    dume request OBJECT --to PERSON [--wait --timeout S]    ask for an object
    dume request --put-back [--wait]                        put back what the gripper still holds
    dume cancel REQUEST_ID [--reason TEXT]                  cancel a request
    dume map [--explore | --patrol | --export FILE | --import FILE]   the semantic map (JSON)
    dume demo [--world-seed N] [--object ID --person ID]    bring an object, print a JSON line
    dume eval --worlds N --seed S --out DIR                 N worlds judged from truth: a report
    dume eval --shift --worlds W --requests M               a shift of M requests per world
    dume bench sim|wbc|nav|stack|all                        print figures (JSON last line)
    dume trial walk|turn|strafe|random|reach|pick|push [--world-seed N]   a trial (JSON)
    dume trial goto X Y [--yaw Θ] [--world hall|small]   walk to a pose over the nav stack (JSON)
    dume trial goals [--count 10] | person | crossing     random goals; people in the path (JSON)
    dume trial fuzz [--count 10000]                      every key a service takes, fuzzed (JSON)
    dume trial fetch [--world hall --world-seed N]       one fetch, probed; its handover samples
    dume train-segmenter [--seed S]                         render data, train, export ONNX
    dume train-segmenter --confusion MODEL                  its confusion by range, held out

Every command takes `--port` (default: `DUME_ZENOH_PORT` or the config's; with neither,
when nothing listens there, the one run that is up) to talk to the stack on that port,
and `--set key=value` to override settings. A run's logs, settings and recording are in
`var/run/<run>/`, printed by every command that starts a stack.
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

from common.bus import Bus, BusError, NoReply, NoRouter, WaitTimeout
from common.config import (
    ENV_START,
    REPO_ROOT,
    Config,
    ConfigError,
    Overrides,
    load_config,
    merged,
    parse_overrides,
    resolve,
)
from common.keys import SERVICES, RobotKeys, service_of_alive_key
from common.lifelines import Dependencies, OwnLink
from common.messages import encode
from common.messages.mission import MissionCancel, MissionReceipt, MissionRequest, MissionStatus
from deploy.maps import NoSavedMap, saved_map, start_from
from deploy.runs import (
    RUNS_DIR,
    RunInfo,
    RunNotFound,
    find_run,
    listening,
    now_iso,
    restarts,
    runs_up,
    shown,
    write_info,
)

#: How long a command waits for the stack's router before saying there is none.
CONNECT_TIMEOUT_S = 3.0
#: Wall seconds for the mission to hold a request, and then to take or refuse it.
SUBMIT_TIMEOUT_S = 10.0
#: Wall seconds a command waits for the router of a run that is starting on its port.
STARTING_WAIT_S = 15.0
#: Where a command that fails for a reason nobody foresaw leaves its traceback.
CLI_ERRORS = RUNS_DIR / "cli-errors.log"


class CliError(Exception):
    """What went wrong, for a person, and what to do about it: printed as one line."""

    def __init__(self, cause: str, hint: str = "") -> None:
        super().__init__(cause)
        self.cause, self.hint = cause, hint

    def line(self) -> str:
        return f"dume: {self.cause}" + (f" ({self.hint})" if self.hint else "")


def _client_config(args: argparse.Namespace, wait_s: float = 0.0) -> Config:
    """The settings of a command that talks to a stack. With no `--port` (and no
    `DUME_ZENOH_PORT`), when nothing listens on the default port and exactly one run is
    up, that run's (`dume demo` picks a free port); no stack at all is a `CliError`. A
    run that is starting on the port (its router not listening yet) is waited for, up to
    `wait_s` or `STARTING_WAIT_S`."""
    config = load_config(merged(parse_overrides(args.set), _port(args)))
    host, port = config.zenoh.host, config.zenoh.port
    up = runs_up()
    if any(r.info.port == port for r in up):
        wait_s = max(wait_s, STARTING_WAIT_S)
    deadline = time.monotonic() + wait_s
    while True:
        if listening(host, port):
            return config
        if time.monotonic() >= deadline:
            break
        time.sleep(0.25)
    chosen = args.port is not None or "DUME_ZENOH_PORT" in os.environ
    if not chosen and len(up) == 1:
        run = up[0].info
        print(f"dume: run {run.run_id} ({run.kind}) on port {run.port}", file=sys.stderr)
        return load_config(merged(parse_overrides(args.set), {"zenoh.port": run.port}))
    if up:
        listed = ", ".join(f"{r.info.run_id} ({r.info.kind}) on --port {r.info.port}" for r in up)
        hint = f"running: {listed}"
    else:
        hint = "start one with `dume up`, or pass the --port that `dume demo` printed"
    raise CliError(f"no dume stack on tcp/{host}:{port}", hint)


def _port(args: argparse.Namespace) -> dict[str, Any]:
    return {"zenoh.port": args.port} if args.port is not None else {}


def port_number(text: str) -> int:
    """argparse's type of `--port`: 1-65535."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is not a port (1-65535)")
    return port


def seed_number(text: str) -> int:
    """argparse's type of a world seed: 0 or more."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a seed (an integer)") from None
    if seed < 0:
        raise argparse.ArgumentTypeError(f"{seed}: seeds are 0 or more")
    return seed


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
            map_start(args.map, args.world, args.world_seed, parse_overrides(args.set)),
            _port(args),
            {"zenoh.side": args.host} if args.host else {},
        )
    )
    config = load_config(settings)
    port = config.zenoh.port
    if config.zenoh.side != "all":
        _check_link(config)
    if listening(config.zenoh.host, port):
        up = [r for r in runs_up() if r.info.port == port]
        who = f"run {up[0].info.run_id}" if up else "another program"
        raise CliError(
            f"port {port} is in use ({who})",
            "stop it (`dume down`), or start this one on another port (`dume up --port 7450`)",
        )
    run_id = new_run_id()
    run_dir = RUNS_DIR / run_id
    run_dir.mkdir(parents=True, exist_ok=True)
    env = stack_env(
        port=port,
        run_id=run_id,
        run_dir=run_dir,
        settings=settings_env(run_dir, settings),
        side=config.zenoh.side,
    )
    sim = config.sim
    write_info(
        run_dir,
        RunInfo(
            run_id=run_id,
            port=port,
            pid=os.getpid(),  # supervisord's, after the exec
            kind="up",
            world=sim.world,
            world_seed=sim.world_seed,
            started=now_iso(),
        ),
    )
    exe = os.path.join(os.path.dirname(sys.executable), "supervisord")
    print(
        f"dume up: run {run_id}, zenoh port {port}, {sim.world} world seed "
        f"{sim.world_seed}, {config.time.mode}, map {config.semantic_map.start}\n"
        f"  logs and recording: {shown(run_dir)}/  (dume logs [SERVICE], dume view, "
        "dume ctl status; dume down stops it)",
        file=sys.stderr,
        flush=True,
    )
    os.execve(exe, [exe, "-c", str(SUPERVISORD_CONF)], env)
    return 0  # not reached


def _check_link(config: Config) -> None:
    """`dume up --host`: this host's certificates are there, and the robot's link port
    is free, before supervisord starts a router that would only log why it cannot."""
    from common.certs import CertsError, cert_files

    z = config.zenoh
    try:
        cert_files(resolve(z.certs), z.side)
    except CertsError as exc:
        raise CliError(str(exc), "`dume certs --help`") from None
    if z.side == "robot" and listening(z.link_host, z.link_port):
        raise CliError(
            f"the link's port tcp/{z.link_host}:{z.link_port} is in use",
            "stop what holds it, or choose another (`--set zenoh.link_port=7458`, on both hosts)",
        )


def cmd_certs(args: argparse.Namespace) -> int:
    from common.certs import CA_KEY, HOSTS, SECRET, make_certs

    config = load_config(parse_overrides(args.set))
    folder = pathlib.Path(args.out) if args.out else resolve(config.zenoh.certs)
    local = ["localhost", "127.0.0.1"]
    made = make_certs(folder, [*local, *args.robot_address], [*local, *args.station_address])
    print(f"dume certs: the link's authority, both hosts' certificates and secret in {folder}/")
    for host in HOSTS:
        print(
            f"  the {host}: copy ca.pem, {host}.pem, {host}-key.pem and {SECRET} to its "
            f"{config.zenoh.certs}/ (mode 0600 for the key and the secret)"
        )
    print(f"  {made[CA_KEY].name} signs them: keep it here, on no host of the robot's")
    return 0


def map_start(
    map_arg: str | None, world: str, seed: int, overrides: Overrides | None = None
) -> dict[str, Any]:
    """`dume up --map`'s settings. None: the site's own database, resumed; the first
    time, started from the site's saved map (`deploy.maps`), else empty (`dume map
    --explore` maps it); `truth`: seeded from the world's truth with noise and its floor
    plan (the ablation that stands in for a mapping run); a file: that map (`dume map
    --export`). Each of the last two starts over in a database of its own
    (`<site>-truth`, `<site>-prior`): the site's own map is never overwritten. Only the
    ablation has the floor plan: the others localize on their own grid. `overrides`: the
    command line's `--set` (a `semantic_map.dir` of its own is where the map is looked for)."""
    from services.semantic_map.store import database_path, site_slug

    config = load_config(merged(overrides or {}, {"sim.world": world, "sim.world_seed": seed}))
    site = config.map_site()
    slug = site_slug(site)
    if map_arg is None:
        if database_path(config.semantic_map, None, site).is_file():
            return {"semantic_map.floor_plan": "none"}  # resumed
        saved = saved_map(site)
        if saved is None:
            print(
                f"dume up: no map of {site!r} yet: the robot starts on an empty map "
                "(`dume map --explore` maps it)",
                file=sys.stderr,
            )
            return {"semantic_map.floor_plan": "none"}
        return {**start_from(str(saved), site), "semantic_map.name": slug}
    try:
        settings = start_from(map_arg, site)
    except FileNotFoundError:
        raise CliError(f"no map file {map_arg}", "`dume map --export FILE` writes one") from None
    suffix = "truth" if map_arg == "truth" else "prior"
    return {**settings, "semantic_map.name": f"{slug}-{suffix}", "semantic_map.reset": True}


def cmd_status(args: argparse.Namespace) -> int:
    config = _client_config(args, wait_s=args.ready)
    keys = RobotKeys(config.robot)
    with Bus.open(config, connect_timeout_s=CONNECT_TIMEOUT_S) as bus:
        seen: set[str] = set()
        if args.ready:  # until every service is up (or the time is out)
            watch = bus.watch_alive(keys.alive_all)
            with contextlib.suppress(WaitTimeout):
                watch.wait_for({keys.alive(s) for s in SERVICES}, args.ready)
            seen = watch.alive()
            watch.undeclare()
        # the watch's view and a query's: under load a query can end with no reply at all
        # (`dume trial updown` saw "up" fail twice in 90 cycles with every service alive)
        found = seen | bus.alive_now(keys.alive_all, 2.0)
        alive = sorted(service_of_alive_key(k) for k in found)
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
    run = next((r for r in runs_up() if r.info.port == config.zenoh.port), None)
    if run is not None:
        died = restarts(run.folder)
        out |= {"run": run.info.run_id, "folder": run.shown(), "died": died}
        for name, k in died.items():  # visible: who died, and what became of them
            back = name in alive
            then = (
                f"restarted ({k} time(s))"
                if back
                else "not restarted: the world stopped (`dume down`, then `dume up` for a new run)"
                if name == "sim"
                else "down"
            )
            print(
                f"dume: {name} died in run {run.info.run_id}, {then}: see "
                f"{run.shown()}/supervisord.log and {name}.log",
                file=sys.stderr,
            )
    print(json.dumps(out))
    return 0 if not out["missing"] else 1  # a stack missing a service is not well


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
    rid = args.request_id or uuid.uuid4().hex[:12]
    if args.put_back:
        if args.object or args.to:
            raise CliError("--put-back takes no OBJECT or --to", "dume request --put-back")
        request = MissionRequest(request_id=rid, task="put_back")
    elif not args.object or not args.to:
        raise CliError(
            "a fetch needs OBJECT and --to PERSON", "dume request bottle_1 --to person_1"
        )
    else:
        request = MissionRequest(request_id=rid, object=args.object, person=args.to)
    return _submit(config, request, args.wait, args.timeout)


def _submit(config: Config, request: MissionRequest, wait: bool, timeout_s: float) -> int:
    """Hand `request` to the mission and follow its status (to the end with `wait`, else
    until taken or refused), a JSON line each; the exit code (0 taken or succeeded)."""
    keys = RobotKeys(config.robot)
    with Bus.open(config, connect_timeout_s=CONNECT_TIMEOUT_S) as bus:
        statuses = bus.fifo(keys.mission_status, MissionStatus)
        alive = bus.watch_alive(keys.alive_all)
        mission = Dependencies(alive.lifelines, ["mission"], keys.alive)
        time.sleep(0.2)  # let the subscription reach the router before the request goes out
        with contextlib.suppress(WaitTimeout):
            alive.wait_for({keys.alive("mission")}, 2.0)
        if mission.missing():
            raise CliError(
                "the mission service is not running",
                "`dume status` says which services are up, `dume logs mission` why",
            )
        mission.arm()
        # Handed over, not just put: the mission answers once it holds the request.
        bus.query(keys.mission_submit, request, MissionReceipt, SUBMIT_TIMEOUT_S)
        print(json.dumps({"request_id": request.request_id, "sent": msgspec.to_builtins(request)}))
        # Without --wait: until the mission took it or refused it (its first status).
        deadline = time.monotonic() + (timeout_s if wait else SUBMIT_TIMEOUT_S)
        ours, link, newest_ns = False, OwnLink(), 0
        while time.monotonic() < deadline:
            status = statuses.pop(timeout_s=0.2)
            if status is not None and status.request_id == request.request_id:
                newest_ns = max(newest_ns, status.stamp_ns)
            # Nobody waits for the dead: a mission gone, restarted or without our request.
            # A lost token is doubted a while: this client's own link may have lapsed (the
            # mission's token back and our request's statuses going on: it has).
            gone = mission.lost()
            verdict = link.verdict(
                gone is not None, time.monotonic(), newest_ns, not mission.missing()
            )
            if verdict == "lapse":
                mission.arm()
            lost = gone if verdict == "lost" else None
            if lost is None and mission.missing() and verdict == "fine":
                lost = "mission is not running"
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
            if not wait:
                hint = f"follow it: `dume status`; stop it: `dume cancel {request.request_id}`"
                print(f"dume: {request.request_id} {status.state} ({hint})", file=sys.stderr)
                return 0
        said = "finish" if wait else "take it or refuse it"
        out = {"request_id": request.request_id, "outcome": "timeout"}
        print(json.dumps(out | {"reason": f"the mission did not {said} in time"}))
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
    from services.semantic_map.mapfile import MapFileError, read_map_file, write_map_file

    try:  # the file first: a bad one needs no stack to say so
        imported = read_map_file(Path(args.import_)) if args.import_ else None
    except MapFileError as exc:
        raise CliError(str(exc), "`dume map --export FILE` writes one") from None
    config = _client_config(args)
    keys = RobotKeys(config.robot)
    if args.explore:  # a request like a fetch's: its statuses to the end, exit 0 on success
        rid = args.request_id or f"explore-{uuid.uuid4().hex[:8]}"
        return _submit(config, MissionRequest(request_id=rid, task="explore"), True, args.timeout)
    with Bus.open(config, connect_timeout_s=CONNECT_TIMEOUT_S) as bus:
        if args.export:
            mf = bus.query(MAP_EXPORT, None, MapFile, 10.0)
            if args.export == "-":
                sys.stdout.buffer.write(msgspec.json.format(msgspec.json.encode(mf), indent=1))
                return 0
            write_map_file(Path(args.export), mf)
            print(json.dumps({"exported": args.export, "entities": len(mf.entities)}))
            return 0
        if imported is not None:
            summary = bus.query(MAP_IMPORT, imported, MapSummary, 10.0)
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


def _run_line(r: Any) -> dict[str, Any]:
    i = r.info
    return {
        "run": i.run_id,
        "kind": i.kind,
        "up": r.up,
        "port": i.port,
        "world": f"{i.world} {i.world_seed}",
        "started": i.started,
        "folder": r.shown(),
    }


def cmd_runs(args: argparse.Namespace) -> int:
    from deploy.runs import all_runs

    found = all_runs() if args.all else runs_up()
    for r in found[: args.limit]:
        print(json.dumps(_run_line(r)))
    if not found:
        what = "no run" if args.all else "no run is up"
        print(f"dume: {what} (runs keep their folders in {shown(RUNS_DIR)})", file=sys.stderr)
    return 0


def cmd_logs(args: argparse.Namespace) -> int:
    """The run's folder and files; with a service, its log's last lines (or follow it)."""
    run = find_run(args.run, port=args.port)
    if args.service is None:
        print(json.dumps(_run_line(run)))
        for path in sorted(run.folder.iterdir()):
            if path.is_file() and not path.name.startswith("."):
                print(f"{path.stat().st_size:>12,}  {shown(path)}")
        return 0
    path = run.folder / f"{args.service}.log"
    if not path.is_file():
        logs = sorted(p.stem for p in run.folder.glob("*.log"))
        raise CliError(f"run {run.info.run_id} has no {args.service}.log", f"it has: {logs}")
    if args.follow:
        os.execvp("tail", ["tail", "-n", str(args.lines), "-F", str(path)])
    lines = path.read_text(errors="replace").splitlines()
    print("\n".join(lines[-args.lines :]))
    return 0


def _ctl_env(run: Any) -> dict[str, str]:
    from deploy.runs import ctl_secret, current_user

    return dict(
        os.environ,
        DUME_RUN_DIR=str(run.folder),
        DUME_PYTHON=sys.executable,
        DUME_USER=current_user(),
        DUME_CTL_PASSWORD=ctl_secret(run.folder),
        # supervisorctl reads the same file; which services started is supervisord's
        **{f"{ENV_START}{s.upper()}": "false" for s in SERVICES},
    )


def cmd_ctl(args: argparse.Namespace) -> int:
    """supervisorctl on a supervised run, with the run's environment."""
    from deploy.stack import SUPERVISORD_CONF

    run = find_run(args.run, supervised=True, port=args.port)
    if not run.up:
        raise CliError(f"run {run.info.run_id} is not up", "start one with `dume up`")
    exe = os.path.join(os.path.dirname(sys.executable), "supervisorctl")
    argv = [exe, "-c", str(SUPERVISORD_CONF), *(args.ctl_args or ["status"])]
    os.execve(exe, argv, _ctl_env(run))
    return 0  # not reached


def cmd_down(args: argparse.Namespace) -> int:
    """Stop a run that is up: supervisord (or the demo) stops every service."""
    import signal

    run = find_run(args.run, port=args.port)
    if not run.up:
        raise CliError(f"run {run.info.run_id} is not up", "`dume runs` lists those that are")
    if run.info.kind == "stack":
        raise CliError(
            f"run {run.info.run_id} belongs to another command (pid {run.info.pid})",
            "stop that command (Ctrl-C); `dume down` stops `dume up` and `dume demo` runs",
        )
    os.kill(run.info.pid, signal.SIGTERM)
    deadline = time.monotonic() + args.timeout
    while time.monotonic() < deadline and run.up:
        time.sleep(0.2)
    if run.up:
        raise CliError(
            f"run {run.info.run_id} still up after {args.timeout:.0f} s",
            f"its supervisord log: {run.shown()}/supervisord.log",
        )
    print(json.dumps({"stopped": run.info.run_id, "folder": run.shown()}))
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    """The run's recording in rerun's viewer (native, or served to a browser)."""
    run = find_run(args.run, port=args.port)
    rrds = sorted(str(p) for p in run.folder.glob("*.rrd"))
    if not rrds:
        raise CliError(
            f"run {run.info.run_id} has no recording in {run.shown()}",
            "recording.enabled was off, or the run stopped before its first flush",
        )
    if args.snapshot:
        from deploy.snapshot import snapshot

        i = run.info
        title = f"run {i.run_id}: {i.world} world seed {i.world_seed}"
        t = snapshot(run.folder, pathlib.Path(args.snapshot), args.at, title)
        print(json.dumps({"snapshot": args.snapshot, "run": i.run_id, "at_s": round(t, 2)}))
        return 0
    exe = os.path.join(os.path.dirname(sys.executable), "rerun")
    web = args.web or not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    argv = [exe, *rrds]
    if web:
        argv[1:1] = ["--serve-web", "--web-viewer-port", str(args.web_port)]
        print(
            f"dume view: serving {run.info.run_id} to a browser on port {args.web_port}: "
            "open the `connect at http://…` link rerun prints (Ctrl-C stops it)",
            file=sys.stderr,
            flush=True,
        )
    os.execv(exe, argv)
    return 0  # not reached


def cmd_demo(args: argparse.Namespace) -> int:
    from deploy.demo import run_demo

    try:
        return run_demo(args)
    except NoSavedMap as exc:
        raise CliError(str(exc), exc.hint) from None
    except FileNotFoundError as exc:
        raise CliError(str(exc), "`dume map --export FILE` writes one") from None


def cmd_eval(args: argparse.Namespace) -> int:
    if args.shift:
        from bench.eval.shift import run_shift

        return run_shift(args)
    from bench.eval.evaluate import run_eval

    return run_eval(args)


def cmd_bench(args: argparse.Namespace) -> int:
    from bench import BenchOptions, run_bench
    from bench.eval.run import sigterm_interrupts

    with sigterm_interrupts():  # a killed bench still stops its stack
        options = BenchOptions(args.rounds, args.sim_s, args.full, args.run)
        return run_bench(args.which, args.set, options)


def _names(text: str) -> tuple[str, ...]:
    """A comma-separated list of names."""
    return tuple(n.strip() for n in text.split(",") if n.strip())


def cmd_trial(args: argparse.Namespace) -> int:
    from bench.eval.run import sigterm_interrupts
    from bench.trials import run_trial

    options: dict[str, object] = {
        "world": args.world, "count": args.count, "yaw": args.yaw,
        "services": args.services, "phases": args.phases, "signals": args.signals,
        "minutes": args.minutes, "object": args.object, "person": args.person,
    }  # fmt: skip
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
    if args.confusion is not None:
        from bench.segmenter_confusion import HeldOutError, run

        try:
            run(args.confusion)
        except HeldOutError as exc:
            raise CliError(str(exc), "held-out seeds: bench.segmenter_confusion.SEEDS") from exc
        return 0
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


def version() -> str:
    """dume's version, and the commit of a git checkout."""
    import importlib.metadata

    from deploy.runs import source_commit

    try:
        v = importlib.metadata.version("dume")
    except importlib.metadata.PackageNotFoundError:
        v = "unknown"
    commit = source_commit()
    return f"dume {v}" + (f" ({commit})" if commit != "unknown" else "")


def build_parser() -> argparse.ArgumentParser:
    assert __doc__ is not None
    parser = argparse.ArgumentParser(
        prog="dume",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=version())
    sub = parser.add_subparsers(dest="command", required=True)

    def add(name: str, help_: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_, description=help_)
        p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
        p.add_argument("--port", type=port_number, default=None, help="the stack's Zenoh port")
        return p

    p = add("up", "run the stack under supervisord in the foreground")
    p.add_argument("--world-seed", type=seed_number, default=0)
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--realtime", action="store_true", help="pace the sim to the wall clock")
    p.add_argument(
        "--start-pose",
        nargs=3,
        type=float,
        metavar=("X", "Y", "YAW"),
        help="where the robot stands, m m rad in the map (default: the world's start)",
    )
    p.add_argument(
        "--map",
        default=None,
        metavar="FILE|truth",
        help="start the map from a file (dume map --export), or from the world's truth "
        "with noise and its floor plan (the ablation standing in for a mapping run); "
        "default: this world's own map, resumed (the first time: its saved map, else empty)",
    )
    p.add_argument(
        "--host",
        choices=["robot", "station"],
        default=None,
        help="run one host's side of a stack split over two (the station: the semantic "
        "map; the robot: every other service), "
        "its router linked to the other's by TLS (`dume certs`; zenoh.link_host, link_port)",
    )
    p.set_defaults(func=cmd_up)

    p = add("certs", "make the certificates and secret of the link between two hosts")
    p.add_argument("--out", default=None, help="the folder (default: zenoh.certs)")
    p.add_argument(
        "--robot-address",
        action="append",
        default=[],
        metavar="NAME|IP",
        help="a name or address the station reaches the robot by (its certificate holds "
        "it; repeatable; localhost and 127.0.0.1 always)",
    )
    p.add_argument(
        "--station-address", action="append", default=[], metavar="NAME|IP",
        help="the same for the station",
    )  # fmt: skip
    p.set_defaults(func=cmd_certs)

    p = add("status", "which services are alive and ready; the latest mission status")
    p.add_argument("--wait", type=float, default=0.5, help="seconds to listen for a status")
    p.add_argument(
        "--ready",
        type=float,
        default=0.0,
        metavar="S",
        help="wait up to S wall seconds for every service (exit 0 only when all are up)",
    )
    p.set_defaults(func=cmd_status)

    p = add("world", "print a generated world as JSON (the simulator's truth)")
    p.add_argument("--world-seed", "--seed", dest="seed", type=seed_number, default=0)
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--walking-people", action="store_true")
    p.add_argument("--grid", action="store_true", help="include the occupancy grid")
    p.add_argument("--pretty", action="store_true")
    p.set_defaults(func=cmd_world)

    p = add("request", "ask the robot to bring OBJECT to PERSON (or --put-back what it holds)")
    p.add_argument("object", nargs="?", default="", help="a map id (bottle_1) or a class (bottle)")
    p.add_argument("--to", default="", help="a person's map id (person_1)")
    p.add_argument(
        "--put-back",
        action="store_true",
        help="put what the gripper still holds from an unfinished request back where it was picked",
    )
    p.add_argument("--request-id", default=None)
    p.add_argument("--wait", action="store_true", help="follow the status until it ends")
    p.add_argument("--timeout", type=float, default=600.0)
    p.set_defaults(func=cmd_request)

    p = add("runs", "the runs that are up (--all: every run kept in var/run), JSON lines")
    p.add_argument("--all", action="store_true")
    p.add_argument("--limit", type=int, default=20)
    p.set_defaults(func=cmd_runs)

    p = add("logs", "a run's folder (logs, recording, settings), or a service's log")
    p.add_argument("service", nargs="?", help="sim, wbc, mission, supervisord, router, ...")
    p.add_argument("--run", default=None, help="a run id or its prefix (default: the newest)")
    p.add_argument("-n", "--lines", type=int, default=40)
    p.add_argument("-f", "--follow", action="store_true")
    p.set_defaults(func=cmd_logs)

    p = add("ctl", "supervisorctl on a `dume up` or `dume demo` run (default: status)")
    p.add_argument("--run", default=None, help="a run id or its prefix (default: the newest)")
    p.add_argument("ctl_args", nargs=argparse.REMAINDER, help="status, restart sim, tail -f wbc")
    p.set_defaults(func=cmd_ctl)

    p = add("down", "stop a `dume up` (or `dume demo`) run")
    p.add_argument("--run", default=None, help="a run id or its prefix (default: the newest)")
    p.add_argument("--timeout", type=float, default=120.0, help="wall seconds to wait")
    p.set_defaults(func=cmd_down)

    p = add("view", "open a run's recording in rerun (served to a browser when headless)")
    p.add_argument("run", nargs="?", default=None, help="a run id or its prefix (the newest)")
    p.add_argument("--web", action="store_true", help="serve it to a browser")
    p.add_argument("--web-port", type=port_number, default=9090)
    p.add_argument(
        "--snapshot",
        metavar="FILE.png",
        help="no viewer: draw the run from its recording (the hall from above, both cameras)",
    )
    p.add_argument("--at", type=float, default=None, help="--snapshot: the cameras at S sim s")
    p.set_defaults(func=cmd_view)

    p = add("cancel", "cancel a request")
    p.add_argument("request_id")
    p.add_argument("--reason", default="cancelled by the user")
    p.set_defaults(func=cmd_cancel)

    p = add("map", "the semantic map: explore, walk the mapping patrol, export, import; lists it")
    what = p.add_mutually_exclusive_group()
    what.add_argument(
        "--patrol", action="store_true", help="the mission walks a coverage route; the map maps it"
    )
    what.add_argument(
        "--explore",
        action="store_true",
        help="the mission explores from nothing, frontier after frontier; its status to the end",
    )
    p.add_argument("--request-id", default=None, help="--explore: the request's id")
    what.add_argument("--export", metavar="FILE", help="write the map as JSON (-: stdout)")
    what.add_argument("--import", dest="import_", metavar="FILE", help="replace the map")
    p.add_argument("--spacing", type=float, default=0.0, help="patrol viewpoint spacing, m")
    p.add_argument("--timeout", type=float, default=3600.0, help="wall seconds for the job")
    p.set_defaults(func=cmd_map)

    p = add("demo", "start a stack, bring an object to a person, stop it, print a JSON result")
    p.description = (
        "Start every service under supervisord, ask for an object for a person (by default "
        "the bottle and the person farthest apart in the map), show the mission's progress, "
        "stop, and print a JSON line; exit 0 only on success. The semantic map starts from "
        "the world's truth with noise (--map truth, the default for now: the ablation "
        "standing in for a mapping run), or with --map saved from the world's saved map "
        "(the robot's own, explored from nothing; dume ships hall and small seed 0's), "
        "localized on from the robot's own sensors, or from --map FILE."
    )
    p.add_argument("--world-seed", type=seed_number, default=0)
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--object", default=None, help="a map id or class (default: a bottle)")
    p.add_argument("--person", default=None, help="a person's map id (default: the farthest)")
    p.add_argument(
        "--map",
        default="saved",
        metavar="saved|FILE|truth",
        help="saved (the default): the world's saved map, the robot's own (var/saved-maps/, "
        "then deploy/maps/, which ships hall and small seed 0); FILE: a map file (dume map "
        "--export); truth: the ablation, the map seeded from the world's truth with noise "
        "and its floor plan",
    )
    p.add_argument("--timeout", type=float, default=600.0, help="sim seconds for the mission")
    p.set_defaults(func=cmd_demo)

    p = add("eval", "N seeded worlds, one request each, judged from sim truth; a report")
    p.description = (
        "N seeded worlds (seeds S..S+N-1), each on a fresh stack with the default segmenter and "
        "the dynamic controller, from the world's saved map (explored from nothing first, and "
        "saved, when it has none; --map truth: seeded from the truth, the ablation); one "
        "random mapped artifact and person requested per world; success judged from the sim's "
        "handover event. Writes DIR/report.md, DIR/results.json and PNG plots; the last "
        "stdout line is a JSON summary."
    )
    p.add_argument("--worlds", type=int, default=20, help="how many worlds")
    p.add_argument("--seed", type=seed_number, default=0, help="world i is seed S + i")
    p.add_argument("--out", default="var/eval/latest", metavar="DIR")
    p.add_argument("--world", choices=["hall", "small"], default="hall")
    p.add_argument("--walking-people", action="store_true", help="the walking-people scenario")
    p.add_argument(
        "--bystanders", action="store_true",
        help="people walk their routes past the robot and across its path, not stopping for it",
    )  # fmt: skip
    p.add_argument("--timeout", type=float, default=300.0, help="sim seconds per request")
    p.add_argument(
        "--shift", action="store_true",
        help="a shift per world: --requests on one stack, the hall changing between them",
    )  # fmt: skip
    p.add_argument("--requests", type=int, default=10, help="--shift: requests per world")
    p.add_argument(
        "--no-changes", dest="changes", action="store_false",
        help="--shift: nobody moves an artifact between requests",
    )  # fmt: skip
    p.add_argument(
        "--slips", type=float, default=0.2, metavar="F",
        help="--shift: the fraction of carries knocked (seeded)",
    )  # fmt: skip
    p.add_argument(
        "--trace-people", action="store_true",
        help="--shift: keep the map's people input and the truth people in DIR, for `dume "
        "bench people-ids --run DIR`",
    )  # fmt: skip
    p.add_argument("--record", action="store_true", help="write each world's recording")
    p.add_argument(
        "--map", default="saved", metavar="saved|DIR|explored|truth",
        help="saved (the default): each world's saved map (var/saved-maps/, then the maps "
        "dume ships), the world explored from nothing first and its map saved in "
        "var/saved-maps/ when it has none (half an hour a hall); DIR: the same in that "
        "folder; explored: every world explored first, nothing saved; truth: the ablation, "
        "the map seeded from the world's truth with noise and its floor plan",
    )  # fmt: skip
    p.set_defaults(func=cmd_eval)

    p = add("bench", "benchmarks; each prints JSON on its last line")
    from bench import BENCHES, TRIALS

    p.add_argument("which", choices=[*BENCHES, "all"])
    p.add_argument(
        "--rounds", type=int, default=10, help="startup, decoders: rounds; lapse: a stall length"
    )
    p.add_argument("--sim-s", type=float, default=60.0, help="stack: sim seconds measured")
    p.add_argument("--full", action="store_true", help="stack: the whole demo request")
    p.add_argument(
        "--run", default="", metavar="DIR",
        help="people-ids: a shift's output folder (default var/eval/latest)",
    )  # fmt: skip
    p.set_defaults(func=cmd_bench)

    p = add("trial", "a whole-body controller trial over a real stack; JSON on the last line")
    p.add_argument("which", choices=TRIALS)
    p.add_argument("xy", nargs="*", type=float, help="goto: the goal's X Y, m in the world")
    p.add_argument("--yaw", type=float, default=0.0, help="goto: the goal's yaw, rad")
    p.add_argument("--world", choices=["hall", "small"], default=None, help="goto, goals, fetch")
    p.add_argument(
        "--count", type=int, default=None,
        help="goals: how many (10); fuzz: cases a key (10 000); faults: seeds (5)",
    )  # fmt: skip
    p.add_argument("--services", type=_names, default=None, help="faults: A,B (every one)")
    p.add_argument("--phases", type=_names, default=None, help="faults: A,B (every one)")
    p.add_argument(
        "--signals",
        type=_names,
        default=None,
        help="faults: kill,stop,slow (all three; slow goes with the service `client`)",
    )
    p.add_argument("--minutes", type=float, default=None, help="soak: wall minutes (120)")
    p.add_argument("--object", default="", help="fetch: an artifact's id (the world's pair)")
    p.add_argument("--person", default="", help="fetch: a person's id (the world's pair)")
    p.add_argument("--world-seed", type=seed_number, default=None, help="default: the trial's own")
    p.add_argument("--wbc-period", type=float, default=0.002, help="the controller's period, s")
    p.set_defaults(func=cmd_trial)

    p = add("train-segmenter", "render sim data, train the segmenter, export and validate it")
    p.add_argument("--seed", type=int, default=0, help="seeds torch and the data order")
    p.add_argument("--train-seeds", type=int, default=180, help="worlds 0..N-1 to train on")
    p.add_argument("--val-seeds", type=int, default=24, help="held-out worlds from 10000")
    p.add_argument("--steps", type=int, default=6000, help="batches (TrainSettings.steps)")
    p.add_argument("--out", type=pathlib.Path, default=None, help="default: the shipped model")
    p.add_argument(
        "--confusion",
        type=pathlib.Path,
        metavar="MODEL",
        default=None,
        help="no training: MODEL's per-class confusion by range on held-out renders",
    )
    p.set_defaults(func=cmd_train_segmenter)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run a command; every error ends as one line on stderr with a hint, never a
    traceback (one nobody foresaw is kept in `var/run/cli-errors.log`)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except ConfigError as exc:
        print(f"dume: {exc}", file=sys.stderr)
        return 2
    except CliError as exc:
        print(exc.line(), file=sys.stderr)
        return 1
    except RunNotFound as exc:
        print(f"dume: {exc.args[0]}", file=sys.stderr)
        return 1
    except NoRouter as exc:
        print(CliError(_plain(exc), _NO_STACK).line(), file=sys.stderr)
        return 1
    except (NoReply, WaitTimeout) as exc:
        hint = "is the stack still starting? `dume status` says who is ready"
        print(CliError(f"no answer from the stack: {_plain(exc)}", hint).line(), file=sys.stderr)
        return 1
    except BusError as exc:
        print(CliError(_plain(exc), "`dume logs` shows the run's logs").line(), file=sys.stderr)
        return 1
    except OSError as exc:  # a file to read or write
        name = f" {exc.filename}" if exc.filename else ""
        print(f"dume: cannot use{name}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # a bug: one line here, the traceback in the file
        import traceback

        CLI_ERRORS.parent.mkdir(parents=True, exist_ok=True)
        with CLI_ERRORS.open("a") as f:
            f.write(f"--- {now_iso()} dume {' '.join(sys.argv[1:])}\n{traceback.format_exc()}")
        print(
            f"dume: internal error: {type(exc).__name__}: {_plain(exc)} "
            f"(the traceback is in {shown(CLI_ERRORS)})",
            file=sys.stderr,
        )
        return 70


_NO_STACK = "start one with `dume up`, or pass the --port that `dume demo` printed"


def _plain(exc: BaseException) -> str:
    """An exception's message without what a person cannot use (Zenoh's Rust source
    locations: `... at /root/.cargo/.../orchestrator.rs:388.`)."""
    import re

    text = str(exc).strip()
    return re.sub(r"\s*at /\S+\.rs:\d+\.?", "", text) or type(exc).__name__


if __name__ == "__main__":
    sys.exit(main())
