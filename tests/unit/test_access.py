"""The stack's credentials and the router's access-control list (`common.access`)."""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Any

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
from common.config import load_config
from common.keys import (
    CAMERAS,
    SERVICES,
    WORLD_DESCRIPTION,
    WORLD_EVENTS,
    WORLD_PEOPLE_COMMAND,
    RobotKeys,
)


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


def _granted(subject: str, *messages: str, flow: str = "", acl: Any = None) -> list[str]:
    """The key expressions the ACL lets `subject` use for any of `messages` (a flow: that
    flow only)."""
    acl = acl or access_control()
    rules = {r["id"]: r for r in acl["rules"]}
    (policy,) = [p for p in acl["policies"] if p["subjects"] == [subject]]
    return [
        k
        for rid in policy["rules"]
        for k in rules[rid]["key_exprs"]
        if set(messages) & set(rules[rid]["messages"]) and (not flow or flow in rules[rid]["flows"])
    ]


def _user_keys(*messages: str) -> list[str]:
    return _granted("user", *messages)


def _reaches(granted: list[str], key: str) -> bool:
    return any(zenoh.KeyExpr(g).intersects(zenoh.KeyExpr(key)) for g in granted)


TRUTH = [RobotKeys().state_truth, *(RobotKeys().camera_segmentation_truth(c) for c in CAMERAS),
         WORLD_DESCRIPTION]  # fmt: skip


def test_no_service_but_the_sim_reads_the_truth_unless_its_ablation_is_on() -> None:
    own = access_control(load_config({"semantic_map.floor_plan": "none"}))  # the robot's own map
    for name in SERVICES:
        reads = _granted(name, "declare_subscriber", "query", flow="ingress", acl=own)
        for key in TRUTH:
            assert not _reaches(reads, key) or name == "sim", f"{name} reads {key}"
    ablations = load_config(
        {"wbc.base_state": "truth", "perception.segmenter": "truth",
         "semantic_map.start": "seed-from-world", "navigation.map_source": "world"}
    )  # fmt: skip
    acl = access_control(ablations)
    keys = RobotKeys()
    assert _reaches(_granted("wbc", "declare_subscriber", acl=acl), keys.state_truth)
    seg = keys.camera_segmentation_truth(CAMERAS[0])
    assert _reaches(_granted("perception", "declare_subscriber", acl=acl), seg)
    assert _reaches(_granted("semantic_map", "query", acl=acl), WORLD_DESCRIPTION)
    assert _reaches(_granted("navigation", "query", acl=acl), WORLD_DESCRIPTION)
    assert not _reaches(
        _granted("mission", "declare_subscriber", "query", acl=acl), keys.state_truth
    )


def test_each_service_puts_only_its_own_outputs() -> None:
    keys = RobotKeys()
    puts = {name: _granted(name, "put", flow="ingress") for name in SERVICES}
    # the joints are the WBC's (and the sim's world), the base velocity navigation's and
    # the mission's: a perception or a map that misbehaves cannot move the robot
    assert [n for n in SERVICES if _reaches(puts[n], keys.command)] == ["wbc"]
    assert sorted(n for n in SERVICES if _reaches(puts[n], keys.cmd_vel)) == [
        "mission", "navigation"
    ]  # fmt: skip
    assert [n for n in SERVICES if _reaches(puts[n], keys.mission_status)] == ["mission"]
    assert [n for n in SERVICES if _reaches(puts[n], WORLD_EVENTS)] == ["sim"]
    for name in SERVICES:  # its own liveliness, no one else's
        tokens = _granted(name, "liveliness_token", flow="ingress")
        assert tokens == [keys.alive(name)], (name, tokens)


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
