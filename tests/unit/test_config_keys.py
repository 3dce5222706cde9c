"""Settings load in layers and reject what they do not know; keys come from one place."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.config import ConfigError, load_config, merged, parse_overrides
from common.keys import RobotKeys, map_artifact


def test_defaults_load_from_the_deploy_file() -> None:
    config = load_config(env={})
    assert config.robot == "b1"
    assert config.time.mode == "lockstep"
    assert config.time.tick_hz == 1000.0
    assert config.time.participants["wbc"].role == "command"  # the deployment's


def test_the_deploy_file_holds_no_default_again() -> None:
    """Every setting's default lives in its Struct; the file sets what a deployment
    decides (the robot, the router's address, the participants), nothing else."""
    import tomllib

    import msgspec

    from common.config import DEFAULT_CONFIG, Config

    def leaves(tree: dict[str, object], path: str = "") -> dict[str, object]:
        out: dict[str, object] = {}
        for k, v in tree.items():
            if isinstance(v, dict) and k != "participants":
                out |= leaves(v, f"{path}{k}.")
            else:
                out[f"{path}{k}"] = v
        return out

    defaults = leaves(msgspec.to_builtins(Config()))
    written = leaves(tomllib.loads(DEFAULT_CONFIG.read_text()))
    deployment = {"robot", "zenoh.host", "zenoh.port"}
    again = [k for k, v in written.items() if defaults.get(k) == v and k not in deployment]
    assert not again, again


def test_environment_then_flags_override_the_file() -> None:
    env = {"DUME_ZENOH_PORT": "7450", "DUME_SIM_WORLD": "small", "DUME_SIM_WORLD_SEED": "4"}
    config = load_config(["sim.world_seed=5"], env=env)
    assert config.zenoh.port == 7450
    assert config.sim.world == "small"
    assert config.sim.world_seed == 5


def test_a_nested_section_takes_flags_and_variables_by_its_path() -> None:
    env = {
        "DUME_NAVIGATION_CONTROLLER_V_MAX": "[0.4, 0.3, 0.8]",
        "DUME_WBC_GAIT_D_MAX": "[1, 1, 1]",
    }
    config = load_config(["navigation.people.slow_speed=0.2"], env=env)
    assert config.navigation.controller.v_max == [0.4, 0.3, 0.8]
    assert config.wbc.gait.d_max == [1.0, 1.0, 1.0]
    assert config.navigation.people.slow_speed == 0.2
    # A key whose name starts like a nested section's is still the section's own.
    env = {"DUME_NAVIGATION_PEOPLE_IN_COSTMAP": "false"}
    assert load_config(env=env).navigation.people_in_costmap is False


def test_flags_parse_once_into_data_and_a_later_one_wins() -> None:
    data = parse_overrides(['sim.world="small"', "sim.world_seed=3", "sim.world=hall"])
    assert data == {"sim.world_seed": 3, "sim.world": "hall"}
    assert load_config(data, env={}).sim.world == "hall"


@pytest.mark.parametrize(
    ("overrides", "env", "says"),
    [
        (["sim.wrold=small"], {}, "unknown field `wrold`"),
        (["sim.world=moon"], {}, "$.sim.world"),
        (["sim.world_seed=abc"], {}, "$.sim.world_seed"),
        ([], {"DUME_NOPE_X": "1"}, "no section 'nope'"),
        (["zenoh.port=0"], {}, "$.zenoh.port"),
        (["navigation.controller.v_max=[0.5, 0.3]"], {}, "$.navigation.controller.v_max"),
        (["navigation.v_max=[0.5, 0.3, 0.8]"], {}, "unknown field `v_max`"),
        (["wbc.gait.v_max=[0.5, 0.0, 1.0]"], {}, "$.wbc.gait.v_max"),
        ([], {"DUME_NAVIGATION_PLANNER_GOAL_SEARCH_M": "-1"}, "$.navigation.planner"),
        (["mission.query_timeout_s=-1"], {}, "$.mission.query_timeout_s"),
        (["time.participants.p.period_s=0.0015"], {}, "whole ticks"),
        (["nonsense"], {}, "section.key=value"),
    ],
)
def test_bad_settings_fail_loudly_with_the_key(
    overrides: list[str], env: dict[str, str], says: str
) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(overrides, env=env)
    assert says in str(err.value)


def test_keys_are_built_from_the_robot_namespace() -> None:
    keys = RobotKeys("b2")
    assert keys.state == "dume/b2/state"
    assert keys.camera_rgbd("camera_wrist") == "dume/b2/camera/camera_wrist/rgbd"
    assert keys.alive("sim") == "dume/alive/b2/sim"
    assert keys.ack("perception") == "dume/b2/ack/perception"
    assert map_artifact("bottle_1") == "dume/map/artifacts/bottle_1"
    with pytest.raises(ValueError, match="unknown camera"):
        keys.camera_rgbd("camera_tail")
    with pytest.raises(ValueError, match="key chunk"):
        map_artifact("bottle/*")


def test_a_stack_of_some_services_waits_only_for_those() -> None:
    from deploy.stack import only_started

    overrides = {
        "time.participants": {},
        "time.participants.wbc.role": "command",
        "time.participants.wbc.period_s": 0.002,
        "time.participants.navigation.role": "periodic",
        "time.participants.mine.role": "periodic",
    }
    extra = only_started(["sim", "wbc"], overrides)
    participants = load_config(merged(overrides, extra), env={}).time.participants
    assert set(participants) == {"wbc", "mine"}  # navigation is not started; `mine` is a test's
    assert participants["wbc"].period_s == 0.002
    assert only_started(["sim", "wbc", "navigation"], overrides) == {}


def test_a_stack_hands_its_settings_to_every_process_as_data(tmp_path: Path) -> None:
    from deploy.stack import settings_env

    settings = {
        "sim.world": "small",
        "time.participants.nav.period_s": 0.05,
        "semantic_map.name": 'a "b"',
    }
    env = settings_env(tmp_path, settings)
    config = load_config(env=env)
    assert config.sim.world == "small" and config.semantic_map.name == 'a "b"'  # no quoting
    assert config.time.participants["nav"].period_s == 0.05
    flags = load_config(["sim.world=small"], env=env)  # flags still apply after the file
    assert flags.sim.world == "small"
