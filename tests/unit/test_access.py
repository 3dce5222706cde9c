"""The stack's credentials and the router's access-control list (`common.access`)."""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Any

import pytest
import zenoh

from common.access import (
    USER,
    access_control,
    ensure_credentials,
    identities,
    identity_of,
    not_allowed,
    read_credentials,
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

IDENTITIES = identities(load_config({}))


def test_the_credentials_are_made_once_private_and_kept(tmp_path: Path) -> None:
    path = tmp_path / "secrets" / "zenoh-users"
    first = ensure_credentials(path, IDENTITIES)
    assert set(first) == set(IDENTITIES)
    assert len(set(first.values())) == len(IDENTITIES), "one password each"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert ensure_credentials(path, IDENTITIES) == first, "a second process reads the same"
    assert [p.name for p in path.parent.iterdir()] == ["zenoh-users"], "no temporary left"


def test_an_identity_the_file_lacks_is_added_and_nothing_else_changes(tmp_path: Path) -> None:
    path = tmp_path / "users"
    path.write_text("user:x\nmission:old\n")  # a file from before <robot>.<service>
    found = ensure_credentials(path, IDENTITIES)
    assert set(found) == set(IDENTITIES) | {"mission"}
    assert (found["user"], found["mission"]) == ("x", "old")
    two = identities(load_config({"zenoh.robots": ["b2"]}))
    assert ensure_credentials(path, two)["b1.wbc"] == found["b1.wbc"]
    assert "b2.wbc" in read_credentials(path)


def test_a_robot_name_that_cannot_be_a_key_is_refused() -> None:
    with pytest.raises(ValueError, match="robot"):
        identities(load_config({"zenoh.robots": ["b/2"]}))


def test_services_log_in_as_their_robots_and_stand_ins_as_trusted() -> None:
    assert identity_of("wbc", "b1") == "b1.wbc"
    assert identity_of("wbc", "b2") == "b2.wbc"
    assert identity_of("hold", "b1") == "trusted"


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


_ALL_MESSAGES = (
    "put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
    "liveliness_token", "declare_liveliness_subscriber", "liveliness_query",
)  # fmt: skip


def _user_keys(*messages: str) -> list[str]:
    return _granted("user", *messages)


def _reaches(granted: list[str], key: str) -> bool:
    return any(zenoh.KeyExpr(g).intersects(zenoh.KeyExpr(key)) for g in granted)


TRUTH = [RobotKeys().state_truth, *(RobotKeys().camera_segmentation_truth(c) for c in CAMERAS),
         WORLD_DESCRIPTION]  # fmt: skip


def test_no_service_but_the_sim_reads_the_truth_unless_its_ablation_is_on() -> None:
    own = access_control(load_config({"semantic_map.floor_plan": "none"}))  # the robot's own map
    for name in SERVICES:
        reads = _granted(f"b1.{name}", "declare_subscriber", "query", flow="ingress", acl=own)
        for key in TRUTH:
            assert not _reaches(reads, key) or name == "sim", f"{name} reads {key}"
    ablations = load_config(
        {"wbc.base_state": "truth", "perception.segmenter": "truth",
         "semantic_map.start": "seed-from-world", "navigation.map_source": "world"}
    )  # fmt: skip
    acl = access_control(ablations)
    keys = RobotKeys()
    assert _reaches(_granted("b1.wbc", "declare_subscriber", acl=acl), keys.state_truth)
    seg = keys.camera_segmentation_truth(CAMERAS[0])
    assert _reaches(_granted("b1.perception", "declare_subscriber", acl=acl), seg)
    assert _reaches(_granted("b1.semantic_map", "query", acl=acl), WORLD_DESCRIPTION)
    assert _reaches(_granted("b1.navigation", "query", acl=acl), WORLD_DESCRIPTION)
    assert not _reaches(
        _granted("b1.mission", "declare_subscriber", "query", acl=acl), keys.state_truth
    )


def test_each_service_puts_only_its_own_outputs() -> None:
    keys = RobotKeys()
    puts = {name: _granted(f"b1.{name}", "put", flow="ingress") for name in SERVICES}
    # the joints are the WBC's (and the sim's world), the base velocity navigation's and
    # the mission's: a perception or a map that misbehaves cannot move the robot
    assert [n for n in SERVICES if _reaches(puts[n], keys.command)] == ["wbc"]
    assert sorted(n for n in SERVICES if _reaches(puts[n], keys.cmd_vel)) == [
        "mission", "navigation"
    ]  # fmt: skip
    assert [n for n in SERVICES if _reaches(puts[n], keys.mission_status)] == ["mission"]
    assert [n for n in SERVICES if _reaches(puts[n], WORLD_EVENTS)] == ["sim"]
    for name in SERVICES:  # its own liveliness, no one else's
        tokens = _granted(f"b1.{name}", "liveliness_token", flow="ingress")
        assert tokens == [keys.alive(name), f"{keys.alive(name)}/*"], (name, tokens)


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
        keys.scan_rear,
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


def test_two_robots_on_one_router_reach_only_their_own_keys() -> None:
    acl = access_control(load_config({"zenoh.robots": ["b2"]}))
    b1, b2 = RobotKeys("b1"), RobotKeys("b2")
    for name in SERVICES:
        mine = _granted(f"b2.{name}", *_ALL_MESSAGES, acl=acl)
        assert mine, name
        for key in mine:  # nothing of b1's: its commands, sensors, tokens
            assert not key.startswith((b1.prefix, f"dume/alive/{b1.robot}")), (name, key)
    puts = {n: _granted(f"b2.{n}", "put", flow="ingress", acl=acl) for n in SERVICES}
    assert [n for n in SERVICES if _reaches(puts[n], b2.command)] == ["wbc"]
    assert not [n for n in SERVICES if _reaches(puts[n], b1.command)]
    assert not [n for n in SERVICES if _reaches(puts[n], b1.cmd_vel)]
    # b1's own identities are untouched by the second robot
    assert _granted("b1.wbc", "put", flow="ingress", acl=acl) == _granted(
        "b1.wbc", "put", flow="ingress"
    )


def test_what_a_service_uses_beyond_its_rule_is_named() -> None:
    """The lidar's scan, before navigation's rule had it: the subscription heard nothing."""
    config = load_config({})
    used = [("subscribe", "dume/b1/odom"), ("subscribe", "dume/b1/camera/camera_head/rgbd"),
            ("put", "dume/b1/wbc/cmd_vel"), ("alive", "dume/alive/b1/navigation"),
            ("subscribe", "dume/b1/state_truth"), ("put", "dume/b1/command")]  # fmt: skip
    assert not_allowed(config, "navigation", used) == [
        ("subscribe", "dume/b1/state_truth"),
        ("put", "dume/b1/command"),
    ]
    # An ablation's truth is allowed where the settings name it.
    truth = load_config({"wbc.base_state": "truth"})
    assert not_allowed(truth, "wbc", [("subscribe", "dume/b1/state_truth")]) == []
    assert not_allowed(config, "wbc", [("subscribe", "dume/b1/state_truth")]) != []
