"""Who may talk to the robot: the router's access-control list and the stack's credentials.

Every Zenoh session of a stack logs in to its router with a user name and a password
(`transport/auth/usrpwd`); a session without them, or with a wrong password, is refused
at the door, so it reads nothing and moves nothing. The router then allows each
identity what it needs and denies everything else (`default_permission: "deny"`):

- each of the robot's services (`keys.SERVICES`, each its own identity `<robot>.<service>`,
  `b1.mission`): exactly the keys it
  uses (`SERVICE_KEYS`: what it puts, subscribes to, asks, answers; its own liveliness
  token; its robot's liveliness when it watches it), as each service's own record of
  what it did says (`Bus.used`, logged at every stop) over demos, evals, explorations,
  trials and the test suite. The sim's truth (the robot's true pose, the segmentation
  labels, the world's description) is the sim's to publish; a service reads it only
  under its named ablation (`truth_keys`): the WBC's `wbc.base_state = "truth"`,
  perception's `segmenter = "truth"`, the map seeded from the world or given its floor
  plan, navigation's `map_source = "world"`. So "no truth in the robot's loop" is the
  router's rule, not only the code's;
- `trusted` (the tools that run and judge a stack: the demo, the eval, trials, tests;
  they read the sim's truth and put world events): everything under `dume/**`;
- `user` (`dume request`, `dume cancel`, `dume status`, `dume map`, or any Zenoh client
  given the user's password): put a request or a cancel, ask the mission to take a
  request or a patrol, read the statuses, the clock, who is alive and the map, export and
  import a map. Not the velocity, the arm, the WBC's mode, the joints, the cameras or
  the world.

The ACL is on the router's side of each link: a client's puts, declarations and
queries are its *ingress*; what the router sends it (samples, replies, tokens, others'
declarations) its *egress*, and a declaration must lie inside an allowed key (a user's
subscriber on `dume/**` is refused: they subscribe to the status keys themselves). A
publisher must also be told of the subscribers on its keys (egress
`declare_subscriber`), a querier of the queryables: Zenoh filters on the writer's side,
and a publisher that hears of no subscriber sends its first sample and nothing after.

The credentials are one file of `user:password` lines (the router's dictionary),
`zenoh.credentials` (in `var/`, outside git, mode 0600), made with random passwords by
the first session that needs it; every process of the stack reads its own line. On one
host, services and users under one Unix account can all read it: it keeps out other
accounts and anything that does not have the file, not a process of the same account.

Two hosts (`zenoh.side`): each has its router, its own credentials and the lists
above for the sessions that log in to it; the two routers are linked by mutual TLS
(`common.certs`). Each router allows the link what the other host's services do
(`SIDES`), under an identity that needs both the certificate's common name and, on the
robot's router, the login `station` with the link's secret: the robot's router lets the
link carry the station's services' keys and a user's, nothing else (not the velocity,
the joints, the WBC's mode, the world), and the station's lets it carry the robot's
services' and a user's. A trusted tool (a test, the eval: it reads the sim's truth)
runs on the robot's host, where the world is; its truth never crosses the link.

Robots of their own on one router (`zenoh.robots`: the robots besides the stack's own
whose services log in here): each robot's services have identities of their own
(`b2.mission`) and rules over their robot's keys only (`dume/b2/…`, `dume/alive/b2/…`),
so one robot's services neither see nor command another's; the map (`dume/map/…`) and
the world are shared. The sim's truth ablations are the stack's own robot's.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import secrets
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import zenoh

from common.certs import LINK_USER, cert_files, link_secret
from common.config import Config, load_config, resolve
from common.keys import ALIVE, ROOT, SERVICES, RobotKeys
from common.runfiles import write_private

USER = "user"
TRUSTED = "trusted"
#: Which services run on which host when the stack is split in two (`zenoh.side`).
#: Everything that moves the robot or decides how (the WBC, navigation, the mission and
#: its visual approach) and what feeds it (the sim or the hardware, localization,
#: perception) stays on the robot: a slow or lost link never sits inside a control loop,
#: and the cameras' frames stay on board for the network. The station keeps the
#: semantic map, the persistent place a fleet shares (`dume/map/…` is robot-free).
SIDES: dict[str, tuple[str, ...]] = {
    "robot": ("sim", "wbc", "localization", "perception", "navigation", "mission"),
    "station": ("semantic_map",),
}


def services_on(side: str) -> tuple[str, ...]:
    """The services a host of `side` runs (`all`: every one)."""
    return SERVICES if side == "all" else SIDES[side]


_ALL = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
]

#: What a user may put (ingress), query (ingress; its replies egress) and read
#: (subscribe ingress, the samples egress) or see alive, as key expressions.
USER_PUTS = (f"{ROOT}/*/mission/request", f"{ROOT}/*/mission/cancel")
USER_QUERIES = (
    f"{ROOT}/*/mission/submit",
    f"{ROOT}/*/mission/patrol",
    f"{ROOT}/map/**",
)
USER_READS = (
    f"{ROOT}/*/mission/status",
    f"{ROOT}/*/mission/patrol/status",
    f"{ROOT}/*/nav/status",
    f"{ROOT}/*/wbc/status",
    f"{ROOT}/world/clock",
    f"{ROOT}/map/**",
)
USER_ALIVE = (f"{ALIVE}/**",)


#: What each service does on the network (module docstring). Keys are templates: `{r}` is
#: the robot's prefix (`dume/<robot>`); `alive`: its own token `dume/alive/<robot>/<name>`
#: and its run's (`…/<name>/<run>`); `watch`: it follows `dume/alive/<robot>/*` (and `/*/*`).
SERVICE_KEYS: dict[str, dict[str, tuple[str, ...] | bool]] = {
    "sim": {
        "put": ("{r}/camera/*/rgbd", "{r}/camera/*/segmentation_truth", "{r}/scan",
                "{r}/scan_rear", "{r}/sim/stats", "{r}/state", "{r}/state_truth", "{r}/odom",
                f"{ROOT}/world/clock", f"{ROOT}/world/events", f"{ROOT}/world/people"),
        "subscribe": ("{r}/ack/*", "{r}/command", "{r}/wbc/cmd_vel",
                      f"{ROOT}/world/people_command", f"{ROOT}/world/push",
                      f"{ROOT}/world/artifact_command", f"{ROOT}/world/movable_command"),
        "serve": ("{r}/description", f"{ROOT}/world/description", f"{ROOT}/world/artifacts"),
        "watch": True,
    },
    "wbc": {
        "put": ("{r}/command", "{r}/odom", "{r}/wbc/status"),
        "subscribe": ("{r}/state", "{r}/wbc/cmd_vel", "{r}/wbc/mode"),
        "serve": ("{r}/wbc/arm_goal",),
        "watch": True,
    },
    "perception": {
        "put": ("{r}/ack/perception", "{r}/perception/detections"),
        "subscribe": ("{r}/camera/*/rgbd", "{r}/localization", "{r}/odom",
                      f"{ROOT}/world/clock"),
        "serve": ("{r}/perception/locate",),
        "watch": True,  # the localization's token: no waiting for a gone one (map_frame)
    },
    "semantic_map": {
        "put": ("{r}/ack/semantic_map",),
        "subscribe": ("{r}/camera/*/rgbd", "{r}/localization", "{r}/mission/patrol/status",
                      "{r}/perception/detections", "{r}/slam/occupancy", f"{ROOT}/world/clock"),
        "serve": (f"{ROOT}/map/**",),
        "watch": True,
    },
    "navigation": {
        "put": ("{r}/ack/navigation", "{r}/nav/path", "{r}/nav/status", "{r}/wbc/cmd_vel"),
        "subscribe": ("{r}/camera/*/rgbd", "{r}/localization", "{r}/nav/cancel", "{r}/odom",
                      "{r}/perception/detections", "{r}/scan", "{r}/scan_rear",
                      f"{ROOT}/world/clock"),
        "serve": ("{r}/nav/goal",),
        "query": (f"{ROOT}/map/artifacts/*", f"{ROOT}/map/occupancy", f"{ROOT}/map/people",
                  f"{ROOT}/map/people/*"),
        "watch": True,
    },
    "localization": {
        "put": ("{r}/ack/localization", "{r}/localization", "{r}/slam/occupancy"),
        "subscribe": ("{r}/odom", "{r}/scan", f"{ROOT}/world/clock"),
        "query": (f"{ROOT}/map/occupancy",),
    },
    "mission": {
        "put": ("{r}/ack/mission", "{r}/mission/patrol/status", "{r}/mission/status",
                "{r}/nav/cancel", "{r}/wbc/cmd_vel"),
        "subscribe": ("{r}/localization", "{r}/mission/cancel", "{r}/mission/request",
                      "{r}/nav/status", "{r}/odom", "{r}/perception/detections",
                      "{r}/wbc/status", f"{ROOT}/world/clock"),
        "serve": ("{r}/mission/patrol", "{r}/mission/submit"),
        "query": ("{r}/nav/goal", "{r}/wbc/arm_goal", f"{ROOT}/map/artifacts",
                  f"{ROOT}/map/artifacts/*", f"{ROOT}/map/occupancy", f"{ROOT}/map/people",
                  f"{ROOT}/map/people/*", f"{ROOT}/map/supports"),
        "watch": True,
    },
}  # fmt: skip


def truth_keys(config: Config) -> dict[str, dict[str, tuple[str, ...]]]:
    """The sim's truth a service may read under its named ablation in `config` (module
    docstring): service → verb → key templates."""
    world = f"{ROOT}/world/description"
    out: dict[str, dict[str, tuple[str, ...]]] = {}
    if config.wbc.base_state == "truth":
        out["wbc"] = {"subscribe": ("{r}/state_truth",)}
    if config.perception.segmenter == "truth":
        out["perception"] = {"subscribe": ("{r}/camera/*/segmentation_truth",)}
    m = config.semantic_map
    if m.start == "seed-from-world" or m.floor_plan == "world":
        out["semantic_map"] = {"query": (world,)}
    if config.navigation.map_source == "world":
        out["navigation"] = {"query": (world,)}
    return out


class CredentialsError(RuntimeError):
    """The stack's credentials file is missing a line or cannot be read or made."""


def robots_of(config: Config) -> tuple[str, ...]:
    """The robots whose services log in to the stack's router: its own, then
    `zenoh.robots`."""
    others = [r for r in config.zenoh.robots if r != config.robot]
    for r in (config.robot, *others):
        RobotKeys(r)  # a name that cannot be a key's chunk is refused here
    return (config.robot, *dict.fromkeys(others))


def identity_of(service: str, robot: str) -> str:
    """The user name a process of robot `robot`'s stack logs in with: `<robot>.<service>`
    for a service; a test's or a tool's stand-in service (`hold`) is trusted."""
    return f"{robot}.{service}" if service in SERVICES else TRUSTED


def identities(config: Config) -> tuple[str, ...]:
    """Every identity of the stack's router: each robot's services, a user, trusted."""
    return (*(identity_of(s, r) for r in robots_of(config) for s in SERVICES), USER, TRUSTED)


def _rule(rule_id: str, messages: list[str], flow: str, keys: tuple[str, ...]) -> dict[str, Any]:
    flows = ["ingress", "egress"] if flow == "both" else [flow]
    return {
        "id": rule_id,
        "permission": "allow",
        "messages": messages,
        "flows": flows,
        "key_exprs": list(keys),
    }


def _service_rules(name: str, spec: dict[str, Any], robot: str) -> list[dict[str, Any]]:
    """The rules that let robot `robot`'s service `name` do what `spec` lists, and
    nothing else (rule ids start with its identity)."""
    prefix, alive = f"{ROOT}/{robot}", f"{ALIVE}/{robot}"
    who = identity_of(name, robot)

    def keys(verb: str) -> tuple[str, ...]:
        return tuple(sorted({k.format(r=prefix) for k in spec.get(verb, ())}))

    rules = []
    for verb, flows in (
        # a publisher hears of the subscribers (egress declarations) or it sends nothing
        # after its first sample: Zenoh filters on the writer's side
        ("put", (("ingress", ["put", "delete"]), ("egress", ["declare_subscriber"]))),
        ("subscribe", (("ingress", ["declare_subscriber"]), ("egress", ["put", "delete"]))),
        ("query", (("ingress", ["query"]), ("egress", ["reply", "declare_queryable"]))),
        ("serve", (("ingress", ["declare_queryable", "reply"]), ("egress", ["query"]))),
    ):
        if found := keys(verb):
            for flow, messages in flows:
                rules.append(_rule(f"{who}-{verb}-{flow}", messages, flow, found))
    own = (f"{alive}/{name}", f"{alive}/{name}/*")  # its token and its run's
    rules.append(_rule(f"{who}-alive", ["liveliness_token"], "ingress", own))
    # it follows its own tokens: its link to the router (`common.bus.LinkBack`)
    rules.append(_rule(f"{who}-own-link", ["declare_liveliness_subscriber"], "ingress", own))
    rules.append(_rule(f"{who}-own-link-back", ["liveliness_token"], "egress", own))
    if spec.get("watch"):
        asks = ["declare_liveliness_subscriber", "liveliness_query"]
        watched = (f"{alive}/*", f"{alive}/*/*")
        rules.append(_rule(f"{who}-watch", asks, "ingress", watched))
        rules.append(_rule(f"{who}-watched", ["liveliness_token"], "egress", watched))
    return rules


def not_allowed(
    config: Config, name: str, used: Iterable[tuple[str, str]]
) -> list[tuple[str, str]]:
    """What of `used` ((verb, key) as `Bus.used` has them) service `name`'s rule does not
    let through the router: a subscription it denies hears nothing and says nothing (the
    lidar's scan for navigation, once). Verbs other than put, subscribe, query and
    serve are not checked; a service without a rule has everything denied."""
    spec = _merged(SERVICE_KEYS.get(name, {}), truth_keys(config).get(name, {}))
    prefix = f"{ROOT}/{config.robot}"
    out = []
    for verb, key in used:
        if verb not in ("put", "subscribe", "query", "serve"):
            continue
        allowed = [zenoh.KeyExpr(k.format(r=prefix)) for k in spec.get(verb, ())]
        if not any(a.includes(zenoh.KeyExpr(key)) for a in allowed):
            out.append((verb, key))
    return out


def _merged(*specs: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for spec in specs:
        for verb, value in spec.items():
            out[verb] = value if isinstance(value, bool) else (*out.get(verb, ()), *value)
    return out


def access_control(config: Config | None = None) -> dict[str, Any]:
    """The router's `access_control` section for the stack of `config` (its robot, and
    the ablations it names: `truth_keys`; None: the defaults). Module docstring."""
    config = config or load_config({})
    truths = truth_keys(config)
    everything = (f"{ROOT}/**",)
    rules = [_rule("trusted", _ALL, "both", everything)]
    subjects = [{"id": "trusted", "usernames": [TRUSTED]}]
    policies = [{"id": "trusted", "rules": ["trusted"], "subjects": ["trusted"]}]
    rule_ids: dict[str, list[str]] = {}  # each of the stack's own services' rules, by id
    for robot in robots_of(config):
        for name in SERVICES:
            spec = SERVICE_KEYS[name]
            if robot == config.robot:  # the ablations are the stack's own robot's
                spec = _merged(spec, truths.get(name, {}))
            own = _service_rules(name, spec, robot)
            rules += own
            who = identity_of(name, robot)
            if robot == config.robot:
                rule_ids[name] = [r["id"] for r in own]
            subjects.append({"id": who, "usernames": [who]})
            policies.append({"id": who, "rules": [r["id"] for r in own], "subjects": [who]})
    users = [
        _rule("user-put", ["put", "delete"], "ingress", USER_PUTS),
        _rule("user-put-to", ["declare_subscriber"], "egress", USER_PUTS),
        _rule("user-ask", ["query"], "ingress", USER_QUERIES),
        _rule("user-answers", ["reply", "declare_queryable"], "egress", USER_QUERIES),
        _rule("user-subscribe", ["declare_subscriber"], "ingress", USER_READS),
        _rule("user-read", ["put", "delete"], "egress", USER_READS),
        _rule(
            "user-alive-ask",
            ["declare_liveliness_subscriber", "liveliness_query"],
            "ingress",
            USER_ALIVE,
        ),
        _rule("user-alive", ["liveliness_token"], "egress", USER_ALIVE),
    ]
    rules += users
    subjects.append({"id": "user", "usernames": [USER]})
    policies.append({"id": "user", "rules": [r["id"] for r in users], "subjects": ["user"]})
    side = config.zenoh.side
    if side != "all":  # the link to the other host's router (module docstring)
        other = "station" if side == "robot" else "robot"
        carried = [rid for name in SIDES[other] for rid in rule_ids[name]]
        carried += [r["id"] for r in users]  # a user's requests, from either host
        subject: dict[str, Any] = {"id": f"link-{other}", "cert_common_names": [other]}
        if other == "station":  # the station's router logs in; the robot's is listened to
            subject["usernames"] = [LINK_USER]
        subjects.append(subject)
        policies.append({"id": f"link-{other}", "rules": carried, "subjects": [subject["id"]]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def read_credentials(path: Path) -> dict[str, str]:
    """The `user:password` lines of `path`."""
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise CredentialsError(f"cannot read the stack's credentials {path}: {exc}") from None
    out: dict[str, str] = {}
    for line in lines:
        user, sep, password = line.strip().partition(":")
        if sep and user and password:
            out[user] = password
    return out


def write_once(path: Path, text: str) -> str:
    """What `path` holds, writing `text` there first (mode 0600) when there is nothing.
    Atomic: of processes starting together one writes it, whole, and the others read
    theirs (a temporary file, then `os.link`, which never replaces)."""
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".private-")
        try:
            with os.fdopen(fd, "w") as f:  # mkstemp's file is 0600
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            with contextlib.suppress(FileExistsError):  # another made it first: theirs stands
                os.link(tmp, path)
        finally:
            os.unlink(tmp)
    return path.read_text()


def ensure_credentials(path: Path, wanted: tuple[str, ...]) -> dict[str, str]:
    """The credentials in `path`, made first with a random password per identity of
    `wanted` when there is no such file (`write_once`; its folder the owner's only); an
    identity the file lacks (a robot added to `zenoh.robots`, a file from before
    `<robot>.<service>`) gets a line appended, under a lock, and nothing in it changes."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    write_once(path, "".join(f"{who}:{secrets.token_urlsafe(24)}\n" for who in wanted))
    found = read_credentials(path)
    if all(who in found for who in wanted):
        return found
    try:
        with path.open("a+") as f:
            fcntl.flock(f, fcntl.LOCK_EX)  # another process may be adding the same ones
            found = read_credentials(path)
            missing = [who for who in wanted if who not in found]
            f.write("".join(f"{who}:{secrets.token_urlsafe(24)}\n" for who in missing))
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise CredentialsError(f"cannot add identities to {path}: {exc}") from None
    return read_credentials(path)


def link_settings(config: Config, credentials: Path) -> dict[str, Any]:
    """What a router of a split stack (`zenoh.side` robot or station) adds to its Zenoh
    config for the link to the other host's (module docstring), as config path → value:
    TLS with its host's certificate, both sides checked; the robot's listens on
    `link_host:link_port`, and its user dictionary (`credentials` and the station's login
    with the link's secret) is written beside `credentials`, the owner's only; the
    station's connects there and logs in. {} for a stack on one host."""
    z = config.zenoh
    if z.side == "all":
        return {}
    files = cert_files(resolve(z.certs), z.side)
    tls = {
        "root_ca_certificate": str(files["ca"]),
        "listen_certificate": str(files["cert"]),
        "listen_private_key": str(files["key"]),
        "connect_certificate": str(files["cert"]),
        "connect_private_key": str(files["key"]),
        "enable_mtls": True,
        "verify_name_on_connect": True,
    }
    link = f"tls/{z.link_host}:{z.link_port}"
    out: dict[str, Any] = {"transport/link/tls": tls}
    secret = link_secret(files["secret"].parent)
    if z.side == "robot":
        users = read_credentials(credentials)
        users[LINK_USER] = secret
        dictionary = credentials.with_name(f"{credentials.name}-with-link")
        write_private(dictionary, "".join(f"{u}:{p}\n" for u, p in users.items()).encode())
        out["listen/endpoints"] = [f"tcp/{z.host}:{z.port}", link]
        out["transport/auth/usrpwd/dictionary_file"] = str(dictionary)
    else:
        out["connect/endpoints"] = [link]
        out["transport/auth/usrpwd/user"] = LINK_USER
        out["transport/auth/usrpwd/password"] = secret
    return out
