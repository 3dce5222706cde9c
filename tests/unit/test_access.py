"""The stack's credentials and the router's access-control list (`common.access`)."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest
import zenoh

from common.access import (
    IDENTITIES,
    USER,
    CredentialsError,
    access_control,
    ensure_credentials,
    identity_of,
)
from common.keys import CAMERAS, WORLD_EVENTS, WORLD_PEOPLE_COMMAND, RobotKeys


def test_the_credentials_are_made_once_private_and_kept(tmp_path: Path) -> None:
    path = tmp_path / "secrets" / "zenoh-users"
    first = ensure_credentials(path)
    assert set(first) == set(IDENTITIES)
    assert len(set(first.values())) == len(IDENTITIES), "one password each"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert ensure_credentials(path) == first, "a second process reads the same"
    assert [p.name for p in path.parent.iterdir()] == ["zenoh-users"], "no temporary left"


def test_a_credentials_file_missing_an_identity_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "users"
    path.write_text("user:x\n")
    with pytest.raises(CredentialsError, match="no password for sim"):
        ensure_credentials(path)


def test_services_log_in_as_themselves_and_stand_ins_as_trusted() -> None:
    assert identity_of("wbc") == "wbc"
    assert identity_of("hold") == "trusted"


def _user_keys(*messages: str) -> list[str]:
    acl = access_control()
    rules = {r["id"]: r for r in acl["rules"]}
    (policy,) = [p for p in acl["policies"] if p["subjects"] == ["user"]]
    return [
        k
        for rid in policy["rules"]
        for k in rules[rid]["key_exprs"]
        if set(messages) & set(rules[rid]["messages"])
    ]


def test_a_user_reaches_no_command_no_sensor_and_no_world_key() -> None:
    keys = RobotKeys()
    forbidden = [
        keys.cmd_vel,
        keys.arm_goal,
        keys.wbc_mode,
        keys.command,
        keys.state,
        keys.odom,
        keys.state_truth,
        keys.scan,
        keys.nav_goal,
        keys.ack("wbc"),
        *(keys.camera_rgbd(c) for c in CAMERAS),
        WORLD_EVENTS,
        WORLD_PEOPLE_COMMAND,
    ]
    granted = _user_keys("put", "delete", "declare_subscriber", "query", "reply")
    for key in forbidden:
        hits = [g for g in granted if zenoh.KeyExpr(g).intersects(zenoh.KeyExpr(key))]
        assert hits == [], f"{USER} reaches {key} through {hits}"
    puts = _user_keys("put")
    for key in (keys.mission_request, keys.mission_cancel, keys.mission_status):
        assert any(zenoh.KeyExpr(g).intersects(zenoh.KeyExpr(key)) for g in puts), key
