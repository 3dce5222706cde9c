"""Who may talk to the robot: the router's access-control list and the stack's credentials.

Every Zenoh session of a stack logs in to its router with a user name and a password
(`transport/auth/usrpwd`); a session without them, or with a wrong password, is refused
at the door, so it reads nothing and moves nothing. The router then allows each
identity what it needs and denies everything else (`default_permission: "deny"`):

- the robot's services (`keys.SERVICES`, each its own name) and `trusted` (the tools
  that run and judge a stack: the demo, the eval, trials, tests; they read the sim's
  truth and put world events): everything under `dume/**`;
- `user` (`dume request`, `dume cancel`, `dume status`, `dume map`, or any Zenoh client
  given the user's password): put a request or a cancel, ask the mission to take a
  request or a patrol, read the statuses, the clock, who is alive and the map, export and
  import a map. Not the velocity, the arm, the WBC's mode, the joints, the cameras or
  the world.

The ACL is on the router's side of each link: a client's puts, declarations and
queries are its *ingress*; what the router sends it (samples, replies, tokens) its
*egress*, and a declaration must lie inside an allowed key (a user's subscriber on
`dume/**` is refused: they subscribe to the status keys themselves).

The credentials are one file of `user:password` lines (the router's dictionary),
`zenoh.credentials` (in `var/`, outside git, mode 0600), made with random passwords by
the first session that needs it; every process of the stack reads its own line. On one
host, services and users under one Unix account can all read it: it keeps out other
accounts and anything that does not have the file, not a process of the same account.

Not yet: a narrower list per service (each service puts and subscribes exactly its keys),
TLS on links between hosts.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import tempfile
from pathlib import Path
from typing import Any

from common.keys import ALIVE, ROOT, SERVICES

USER = "user"
TRUSTED = "trusted"
IDENTITIES = (*SERVICES, USER, TRUSTED)

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


class CredentialsError(RuntimeError):
    """The stack's credentials file is missing a line or cannot be read or made."""


def identity_of(service: str) -> str:
    """The user name a process of the stack logs in with: a service's own name; a test's
    or a tool's stand-in service (`hold`) is trusted."""
    return service if service in SERVICES else TRUSTED


def _rule(rule_id: str, messages: list[str], flow: str, keys: tuple[str, ...]) -> dict[str, Any]:
    flows = ["ingress", "egress"] if flow == "both" else [flow]
    return {
        "id": rule_id,
        "permission": "allow",
        "messages": messages,
        "flows": flows,
        "key_exprs": list(keys),
    }


def access_control() -> dict[str, Any]:
    """The router's `access_control` section (module docstring)."""
    everything = (f"{ROOT}/**",)
    rules = [
        _rule("robot", _ALL, "both", everything),
        _rule("user-put", ["put", "delete"], "ingress", USER_PUTS),
        _rule("user-ask", ["query"], "ingress", USER_QUERIES),
        _rule("user-answers", ["reply"], "egress", USER_QUERIES),
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
    user_rules = [r["id"] for r in rules if r["id"].startswith("user-")]
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": [
            {"id": "robot", "usernames": [*SERVICES, TRUSTED]},
            {"id": "user", "usernames": [USER]},
        ],
        "policies": [
            {"id": "robot", "rules": ["robot"], "subjects": ["robot"]},
            {"id": "user", "rules": user_rules, "subjects": ["user"]},
        ],
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


def ensure_credentials(path: Path) -> dict[str, str]:
    """The credentials in `path`, made first with a random password per identity when
    there is no such file (`write_once`; its folder the owner's only)."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    write_once(path, "".join(f"{who}:{secrets.token_urlsafe(24)}\n" for who in IDENTITIES))
    found = read_credentials(path)
    missing = [who for who in IDENTITIES if who not in found]
    if missing:
        raise CredentialsError(
            f"{path} has no password for {', '.join(missing)} (delete it to make a new one)"
        )
    return found
