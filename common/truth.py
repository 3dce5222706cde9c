"""No truth in the robot's loop: which simulator truth a service may read, enforced.

What the simulator knows and a real robot would not (its pose, the world's floor plan
and objects, the renderer's labels, the world's events) travels only on truth keys
(`common.keys.is_truth_key`). Every service's bus carries a `TruthGuard`: a subscription
or a query on a truth key raises `TruthKeyError` unless `allowed_truth` grants it, and
it grants it only to the sim and to options named as ablations or as the floor-plan
prior:

- perception, `perception.segmenter = "truth"` (ablation): each camera's
  `segmentation_truth`;
- navigation, `navigation.map_source = "world"` (ablation): `dume/world/description`;
- the semantic map, `semantic_map.start = "seed-from-world"` (ablation) or
  `semantic_map.floor_plan = "world"` (the floor-plan prior, as a building drawing
  would be): `dume/world/description`;
- the WBC, `wbc.base_state = "truth"` (ablation): the base's `state_truth`.

Clients outside the stack (tests, evaluation, trials, the CLI) open their bus without
a guard. `tests/integration/test_truth_keys.py` runs the default stack under the guard.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from common.config import Config
from common.keys import CAMERAS, WORLD_DESCRIPTION, RobotKeys, is_truth_key


class TruthKeyError(RuntimeError):
    """A service asked to read simulator truth that no option of its grants."""


def allowed_truth(service: str, config: Config) -> dict[str, str] | None:
    """The truth keys `service` may read under `config`, each with the option that grants
    it; None for the sim (it is the truth)."""
    if service == "sim":
        return None
    keys = RobotKeys(config.robot)
    out: dict[str, str] = {}
    if service == "perception" and config.perception.segmenter == "truth":
        for cam in CAMERAS:
            out[keys.camera_segmentation_truth(cam)] = "perception.segmenter=truth (ablation)"
    if service == "navigation" and config.navigation.map_source == "world":
        out[WORLD_DESCRIPTION] = "navigation.map_source=world (ablation)"
    if service == "semantic_map":
        if config.semantic_map.start == "seed-from-world":
            out[WORLD_DESCRIPTION] = "semantic_map.start=seed-from-world (ablation)"
        elif config.semantic_map.floor_plan == "world":
            out[WORLD_DESCRIPTION] = "semantic_map.floor_plan=world (the floor-plan prior)"
    if service == "wbc" and config.wbc.base_state == "truth":
        out[keys.state_truth] = "wbc.base_state=truth (ablation)"
    return out


@dataclass
class TruthGuard:
    """`check(key)` before a service reads `key` (see the module docstring)."""

    service: str
    allowed: dict[str, str] = field(default_factory=dict)
    #: The truth keys read so far, with the option that granted each.
    granted: dict[str, str] = field(default_factory=dict)

    def check(self, key: str) -> None:
        if not is_truth_key(key):
            return
        why = self.allowed.get(key)
        if why is None:
            raise TruthKeyError(
                f"{self.service} may not read {key}: it is simulator truth (only the sim, "
                "evaluation, tests and options named as ablations or as the floor-plan prior "
                "read it; see common/truth.py)"
            )
        self.granted[key] = why

    @classmethod
    def of(cls, service: str, config: Config) -> TruthGuard | None:
        allowed = allowed_truth(service, config)
        return None if allowed is None else cls(service, allowed)
