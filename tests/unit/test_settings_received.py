"""Navigation and the WBC take their settings Structs directly: with the default config they
receive exactly what the hand-glued `*Params` of 30b18ef gave them.

The old values are computed here from literals copied from that commit: its settings'
defaults (`common/config.py`), the Params' defaults and the glue that joined them
(`navigation/navigator.py nav_params`, `node.py`, `wbc/commander.py`). The new ones are
read from what the services hold once built from `load_config`. Equal means the same
Python floats, value and type, so every expression computes what it did.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from common.config import load_config
from services.navigation import controller, navigator, people, planner
from services.navigation.costmap import CostParams
from services.navigation.grid import Footprint
from services.navigation.navigator import Navigator
from services.wbc import gait
from services.wbc.commander import WbcCommander

#: 30b18ef's NavigationSettings and WbcSettings defaults (deploy/config.toml set none).
OLD_NAVIGATION: dict[str, Any] = {
    "obstacle_ttl_s": 3.0,
    "v_max": [0.5, 0.3, 0.8],
    "a_max": [0.8, 0.8, 1.5],
    "lookahead_m": 0.6,
    "goal_tolerance_m": 0.08,
    "goal_tolerance_rad": 0.1,
    "goal_search_m": 0.5,
    "cost_weight": 4.0,
    "slow_radius_m": 2.0,
    "slow_speed": 0.3,
    "stop_distance_m": 0.6,
    "handover_speed": 0.15,
    "people_in_costmap": True,
    "replan_s": 1.0,
    "blocked_timeout_s": 3.0,
    "goal_timeout_s": 180.0,
}
OLD_WBC: dict[str, Any] = {
    "cmd_vel_max": [0.8, 0.4, 1.0],
    "cmd_vel_accel_max": [1.0, 1.0, 2.0],
    "cmd_vel_decel_max": [2.0, 2.0, 3.0],
    "grip_effort_max_nm": 5.0,
}


def old_navigation(n: dict[str, Any]) -> dict[str, Any]:
    """30b18ef's `nav_params(n)` (NavParams, ControllerParams, PlanParams, PeopleParams)
    and the node's `CostParams`, the Params' other fields at their defaults."""
    return {
        # NavParams
        "replan_s": n["replan_s"],
        "blocked_lookahead_m": 1.5,
        "blocked_timeout_s": n["blocked_timeout_s"],
        "rotate_s": 3.0,
        "backoff_s": 1.5,
        "backoff_speed": 0.15,
        "timeout_s": n["goal_timeout_s"],
        # ControllerParams
        "controller.v_max": (n["v_max"][0], n["v_max"][1], n["v_max"][2]),
        "controller.a_max": (n["a_max"][0], n["a_max"][1], n["a_max"][2]),
        "controller.lookahead_m": n["lookahead_m"],
        "controller.k_heading": 1.5,
        "controller.heading_blend_m": 0.8,
        "controller.turn_first_rad": 1.0,
        "controller.cost_slowdown": 0.5,
        "controller.min_speed": 0.05,
        "controller.k_position": 1.2,
        "controller.min_turn_rate": 0.25,
        "controller.align_release_m": 0.05,
        # PlanParams (goal_tolerance_m was the settings' goal_search_m)
        "planner.cost_weight": n["cost_weight"],
        "planner.goal_tolerance_m": n["goal_search_m"],
        "planner.goal_margin_m": 0.03,
        "planner.spacing_m": 0.05,
        "planner.start_escape_cost": 3.0,
        # PeopleParams
        "people.slow_radius_m": n["slow_radius_m"],
        "people.slow_speed": n["slow_speed"],
        "people.stop_distance_m": n["stop_distance_m"],
        "people.handover_speed": n["handover_speed"],
        "people.travel_half_angle_rad": math.radians(60.0),
        "people.brake_decel": 0.5,
        "people.brake_lead_m": 0.1,
        "people.resume_margin_m": 0.15,
        "people.tracking_margin": 0.2,
        "people.ramp_top_mps": max(n["v_max"][0], n["v_max"][1]),
        # node.py: CostParams(obstacle_ttl_s=…), the layer's ttl, the goal tolerances
        "cost.lethal_margin_m": 0.06,
        "cost.inflation_m": 1.0,
        "cost.decay_per_m": 4.0,
        "cost.person_lethal_m": 0.85,
        "cost.person_cost_m": 2.0,
        "obstacle_ttl_s": n["obstacle_ttl_s"],
        "people_in_costmap": n["people_in_costmap"],
        "goal_tolerance": (n["goal_tolerance_m"], n["goal_tolerance_rad"]),
        # goals.py: standoff and handover poses' margin
        "goals.margin": 0.03,
    }


def received_navigation(nav: Navigator, cost: CostParams) -> dict[str, Any]:
    """The same values where the services now take them from."""
    n = nav.n
    c, p, pl = n.controller, n.people, n.planner
    return {
        "replan_s": n.replan_s,
        "blocked_lookahead_m": navigator.BLOCKED_LOOKAHEAD_M,
        "blocked_timeout_s": n.blocked_timeout_s,
        "rotate_s": navigator.ROTATE_S,
        "backoff_s": navigator.BACKOFF_S,
        "backoff_speed": navigator.BACKOFF_SPEED,
        "timeout_s": n.goal_timeout_s,
        "controller.v_max": tuple(c.v_max),
        "controller.a_max": tuple(c.a_max),
        "controller.lookahead_m": c.lookahead_m,
        "controller.k_heading": controller.K_HEADING,
        "controller.heading_blend_m": controller.HEADING_BLEND_M,
        "controller.turn_first_rad": controller.TURN_FIRST_RAD,
        "controller.cost_slowdown": controller.COST_SLOWDOWN,
        "controller.min_speed": controller.MIN_SPEED,
        "controller.k_position": controller.K_POSITION,
        "controller.min_turn_rate": controller.MIN_TURN_RATE,
        "controller.align_release_m": controller.ALIGN_RELEASE_M,
        "planner.cost_weight": pl.cost_weight,
        "planner.goal_tolerance_m": pl.goal_search_m,
        "planner.goal_margin_m": planner.GOAL_MARGIN_M,
        "planner.spacing_m": planner.SPACING_M,
        "planner.start_escape_cost": planner.START_ESCAPE_COST,
        "people.slow_radius_m": p.slow_radius_m,
        "people.slow_speed": p.slow_speed,
        "people.stop_distance_m": p.stop_distance_m,
        "people.handover_speed": p.handover_speed,
        "people.travel_half_angle_rad": people.TRAVEL_HALF_ANGLE_RAD,
        "people.brake_decel": people.BRAKE_DECEL,
        "people.brake_lead_m": people.BRAKE_LEAD_M,
        "people.resume_margin_m": people.RESUME_MARGIN_M,
        "people.tracking_margin": people.TRACKING_MARGIN,
        "people.ramp_top_mps": nav.top_mps,
        "cost.lethal_margin_m": cost.lethal_margin_m,
        "cost.inflation_m": cost.inflation_m,
        "cost.decay_per_m": cost.decay_per_m,
        "cost.person_lethal_m": cost.person_lethal_m,
        "cost.person_cost_m": cost.person_cost_m,
        "obstacle_ttl_s": n.obstacle_ttl_s,
        "people_in_costmap": n.people_in_costmap,
        "goal_tolerance": (n.goal_tolerance_m, n.goal_tolerance_rad),
        "goals.margin": planner.GOAL_MARGIN_M,
    }


def old_wbc(w: dict[str, Any]) -> dict[str, Any]:
    """30b18ef's commander: GaitParams from the cmd_vel limits, ArmParams with the grip cap;
    the Params' other fields at their defaults."""
    return {
        "gait.v_max": tuple(w["cmd_vel_max"]),
        "gait.a_max": tuple(w["cmd_vel_accel_max"]),
        "gait.d_max": tuple(w["cmd_vel_decel_max"]),
        "gait.period_s": 0.5,
        "gait.step_height_m": 0.08,
        "gait.stop_threshold": 0.02,
        "gait.max_step_m": 0.25,
        "gait.hip_offsets": (
            (0.3455, 0.19875),
            (0.3455, -0.19875),
            (-0.3455, 0.19875),
            (-0.3455, -0.19875),
        ),
        "arm.grip_effort_max_nm": w["grip_effort_max_nm"],
        "arm.reach_speed_m_s": 0.4,
        "arm.reach_rate_rad_s": 1.5,
        "arm.approach_speed_m_s": 0.1,
        "arm.joint_rate_rad_s": 1.0,
        "arm.min_segment_s": 0.5,
        "arm.reach_tol_m": 0.01,
        "arm.reach_tol_rad": math.radians(3.0),
        "arm.held_tol_m": 0.03,
        "arm.held_tol_rad": math.radians(6.0),
        "arm.posture_tol_rad": 0.05,
        "arm.held_posture_tol_rad": 0.15,
        "arm.settle_s": 2.0,
        "arm.grasp_timeout_s": 3.0,
        "arm.release_s": 1.5,
    }


def received_wbc(core: WbcCommander) -> dict[str, Any]:
    limits, a = core.ctrl.gait.limits, core.actions.params
    return {
        "gait.v_max": tuple(limits.v_max),
        "gait.a_max": tuple(limits.a_max),
        "gait.d_max": tuple(limits.d_max),
        "gait.period_s": gait.TROT_PERIOD_S,
        "gait.step_height_m": gait.STEP_HEIGHT_M,
        "gait.stop_threshold": gait.STOP_THRESHOLD,
        "gait.max_step_m": gait.MAX_STEP_M,
        "gait.hip_offsets": tuple(tuple(row) for row in gait.HIP_OFFSETS.tolist()),
        "arm.grip_effort_max_nm": core.actions.settings.grip_effort_max_nm,
        "arm.reach_speed_m_s": a.reach_speed_m_s,
        "arm.reach_rate_rad_s": a.reach_rate_rad_s,
        "arm.approach_speed_m_s": a.approach_speed_m_s,
        "arm.joint_rate_rad_s": a.joint_rate_rad_s,
        "arm.min_segment_s": a.min_segment_s,
        "arm.reach_tol_m": a.reach_tol_m,
        "arm.reach_tol_rad": a.reach_tol_rad,
        "arm.held_tol_m": a.held_tol_m,
        "arm.held_tol_rad": a.held_tol_rad,
        "arm.posture_tol_rad": a.posture_tol_rad,
        "arm.held_posture_tol_rad": a.held_posture_tol_rad,
        "arm.settle_s": a.settle_s,
        "arm.grasp_timeout_s": a.grasp_timeout_s,
        "arm.release_s": a.release_s,
    }


def _typed(tree: Any) -> Any:
    """The value with each leaf's type beside it (1 == 1.0, but int and float arithmetic
    need not agree)."""
    if isinstance(tree, dict):
        return {k: _typed(v) for k, v in tree.items()}
    if isinstance(tree, tuple):
        return tuple(_typed(v) for v in tree)
    return (type(tree).__name__, tree)


def test_navigation_receives_what_its_params_held() -> None:
    config = load_config(env={})
    period_s = config.time.period_of("navigation", 0.05)
    nav = Navigator(Footprint.stowed(), config.navigation, period_s)
    old = old_navigation(OLD_NAVIGATION)
    assert _typed(received_navigation(nav, CostParams())) == _typed(old)


def test_the_wbc_receives_what_its_params_held() -> None:
    config = load_config(env={})
    core = WbcCommander(config.wbc, config.time.latencies_ns(), 2_000_000, logging.getLogger("t"))
    assert _typed(received_wbc(core)) == _typed(old_wbc(OLD_WBC))
    assert core.ctrl.gait.half_period == 0.25
