"""Which keys are truth, and which service may read which under which option."""

from __future__ import annotations

import pytest

from common.config import load_config
from common.keys import WORLD_CLOCK, WORLD_DESCRIPTION, WORLD_EVENTS, RobotKeys, is_truth_key
from common.truth import TruthGuard, TruthKeyError, allowed_truth

K = RobotKeys("b1")


def test_truth_keys_are_the_worlds_and_the_truth_suffixed_ones() -> None:
    truth = [
        WORLD_DESCRIPTION,
        WORLD_EVENTS,
        K.state_truth,
        K.camera_segmentation_truth("camera_head"),
    ]
    robot = [WORLD_CLOCK, K.odom, K.state, K.scan, K.camera_rgbd("camera_head"), K.detections]
    assert all(is_truth_key(k) for k in truth)
    assert not any(is_truth_key(k) for k in robot)


def test_by_default_only_the_floor_plan_prior_is_granted() -> None:
    config = load_config()
    assert allowed_truth("sim", config) is None
    granted = {s: allowed_truth(s, config) for s in ("perception", "navigation", "mission")}
    assert granted == {"perception": {}, "navigation": {}, "mission": {}}
    assert allowed_truth("semantic_map", config) == {
        WORLD_DESCRIPTION: "semantic_map.floor_plan=world (the floor-plan prior)"
    }
    assert allowed_truth("semantic_map", load_config({"semantic_map.floor_plan": "none"})) == {}


@pytest.mark.parametrize(
    ("service", "option", "key"),
    [
        (
            "perception",
            {"perception.segmenter": "truth"},
            K.camera_segmentation_truth("camera_wrist"),
        ),
        ("navigation", {"navigation.map_source": "world"}, WORLD_DESCRIPTION),
        ("semantic_map", {"semantic_map.start": "seed-from-world"}, WORLD_DESCRIPTION),
        ("wbc", {"wbc.base_state": "truth"}, K.state_truth),
    ],
)
def test_an_ablation_grants_its_truth_and_names_itself(
    service: str, option: dict[str, str], key: str
) -> None:
    guard = TruthGuard.of(service, load_config(option))
    assert guard is not None
    guard.check(key)
    assert "ablation" in guard.granted[key]
    with pytest.raises(TruthKeyError, match=f"{service} may not read {WORLD_EVENTS}"):
        guard.check(WORLD_EVENTS)
    guard.check(K.odom)  # not truth: nothing to grant
    assert K.odom not in guard.granted
