"""Navigation, the WBC, the semantic map and the mission take their settings Structs
directly: with the default config they receive exactly what the hand-glued `*Params` of
30b18ef (navigation, WBC) and of 2d70322 (map, mission) gave them.

The old values are computed here from literals copied from that commit: its settings'
defaults (`common/config.py`), the Params' defaults and the glue that joined them
(`navigation/navigator.py nav_params`, `node.py`, `wbc/commander.py`). The new ones are
read from what the services hold once built from `load_config`. Equal means the same
Python floats, value and type, so every expression computes what it did. (The people
rule's stop distance and travel cone are gone: the protective separation of ISO/TS 15066
replaced them, `services/navigation/separation.py`.)
"""

from __future__ import annotations

import logging
import math
from typing import Any

from common import robot
from common.config import load_config
from services.mission import approach, grasp_pose, handover_feel
from services.mission.algorithms import default_algorithms
from services.navigation import controller, navigator, people, planner
from services.navigation.costmap import CostParams
from services.navigation.grid import Footprint
from services.navigation.navigator import Navigator
from services.semantic_map import artifacts
from services.semantic_map import people as map_people
from services.semantic_map.mapper import SemanticMap
from services.semantic_map.occupancy import Occupancy
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
        "people.handover_speed": n["handover_speed"],
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
        "people.handover_speed": p.handover_speed,
        "people.brake_decel": p.brake_decel_mps2,
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


#: HEAD's (2d70322) SemanticMapSettings defaults that its `startup.map_params` read.
OLD_SEMANTIC_MAP: dict[str, Any] = {
    "sigma0_m": 0.02,
    "sigma_per_m": 0.02,
    "gate_min_m": 0.25,
    "gate_sigmas": 3.0,
    "confirm_hits": 2,
    "class_near_m": 2.0,
    "class_merge_m": 0.05,
    "min_score": 0.5,
    "missing_after_frames": 5,
    "look_range_m": 2.0,
    "person_look_range_m": 6.0,
    "person_obstacle_margin_m": 0.1,
    "drop_below_observations": 10,
    "person_accel_sigma": 1.5,
    "appearance_weight": 4.0,
}


def old_semantic_map(s: dict[str, Any]) -> dict[str, Any]:
    """HEAD's `map_params(s)` (MapParams, FusionParams, PeopleParams), the Params' other
    fields at their defaults."""
    return {
        "sigma0_m": s["sigma0_m"],
        "sigma_per_m": s["sigma_per_m"],
        "min_score": s["min_score"],
        "missing_after_frames": s["missing_after_frames"],
        "look_range_m": s["look_range_m"],
        "person_look_range_m": s["person_look_range_m"],
        "person_obstacle_margin_m": s["person_obstacle_margin_m"],
        "drop_below_observations": s["drop_below_observations"],
        "fusion.gate_min_m": s["gate_min_m"],
        "fusion.gate_sigmas": s["gate_sigmas"],
        "fusion.confirm_hits": s["confirm_hits"],
        "fusion.tentative_ttl_ns": 3_000_000_000,
        "fusion.near_m": s["class_near_m"],
        "fusion.class_merge_m": s["class_merge_m"],
        "people.accel_sigma": s["person_accel_sigma"],
        "people.appearance_weight": s["appearance_weight"],
        "people.max_appearance": 0.6,
        "people.gate_min_m": 0.4,
        "people.confirm_hits": s["confirm_hits"],
        "people.tentative_ttl_ns": 2_000_000_000,
        "people.coast_ns": 2_000_000_000,
        "people.v_max": 1.5,
        "people.max_sigma_m": 1.0,
        "people.max_gate_m": 1.2,
        "people.min_separation_m": 0.35,
    }


def received_semantic_map(smap: SemanticMap) -> dict[str, Any]:
    s, f, p = smap.settings, smap.artifacts.settings, smap.people.settings
    return {
        "sigma0_m": s.sigma0_m,
        "sigma_per_m": s.sigma_per_m,
        "min_score": s.min_score,
        "missing_after_frames": s.missing_after_frames,
        "look_range_m": s.look_range_m,
        "person_look_range_m": s.person_look_range_m,
        "person_obstacle_margin_m": s.person_obstacle_margin_m,
        "drop_below_observations": s.drop_below_observations,
        "fusion.gate_min_m": f.gate_min_m,
        "fusion.gate_sigmas": f.gate_sigmas,
        "fusion.confirm_hits": f.confirm_hits,
        "fusion.tentative_ttl_ns": artifacts.TENTATIVE_TTL_NS,
        "fusion.near_m": f.class_near_m,
        "fusion.class_merge_m": f.class_merge_m,
        "people.accel_sigma": p.person_accel_sigma,
        "people.appearance_weight": p.appearance_weight,
        "people.max_appearance": map_people.MAX_APPEARANCE,
        "people.gate_min_m": map_people.GATE_MIN_M,
        "people.confirm_hits": p.confirm_hits,
        "people.tentative_ttl_ns": map_people.TENTATIVE_TTL_NS,
        "people.coast_ns": map_people.COAST_NS,
        "people.v_max": map_people.V_MAX,
        "people.max_sigma_m": map_people.MAX_SIGMA_M,
        "people.max_gate_m": map_people.MAX_GATE_M,
        "people.min_separation_m": map_people.MIN_SEPARATION_M,
    }


def test_the_map_receives_what_its_params_held() -> None:
    config = load_config(env={})
    smap = SemanticMap(config.semantic_map, Occupancy.unknown(1.0, 0.5), {})
    old = old_semantic_map(OLD_SEMANTIC_MAP)
    assert _typed(received_semantic_map(smap)) == _typed(old)


#: HEAD's `ApproachGains` and `PullDetector` defaults (MissionSettings' `approach_gains`
#: and `pull_detector` overrides were empty); d_opt_m / θ_opt were `common.robot`'s.
OLD_APPROACH: dict[str, Any] = {
    "k_d": 0.8,
    "k_theta": 1.2,
    "vx_max": 0.25,
    "wz_max": 0.5,
    "ax_max": 0.5,
    "az_max": 1.0,
    "tol_d_m": 0.03,
    "tol_theta_rad": 0.05,
    "settle_s": 0.6,
    "max_age_s": 0.35,
    "lost_after_s": 1.0,
    "reacquire_s": 5.0,
    "reacquire_wz": 0.3,
    "reacquire_turn_margin_rad": 0.15,
    "back_off_speed": 0.08,
    "back_off_max_m": 0.3,
    "timeout_s": 40.0,
}
#: force_n: 4 N until the hall's knock (seed 5) tripped it; 8 N since.
OLD_PULL: dict[str, Any] = {
    "force_n": 8.0,
    "effort_nm": 0.5,
    "debounce_s": 0.2,
    "baseline_s": 0.3,
    "absolute_n": 8.0,
    "toward": (1.0, 0.0, 0.0),
}


def test_the_mission_receives_what_its_params_held() -> None:
    config = load_config(env={})
    algorithms = default_algorithms(config.mission)
    ctrl = algorithms.approacher()
    assert isinstance(ctrl, approach.ApproachController)
    g = ctrl.gains
    received = {k: getattr(g, k) for k in OLD_APPROACH}
    assert _typed(received) == _typed(OLD_APPROACH)
    assert _typed((approach.D_OPT_M, approach.THETA_OPT_RAD)) == _typed((robot.D_OPT_M, 0.0))
    pull = algorithms.pull_detector()
    assert isinstance(pull, handover_feel.PullDetector)
    got = {k: getattr(pull, k) for k in OLD_PULL if k != "toward"}
    got["toward"] = tuple(pull.toward.tolist())
    assert _typed(got) == _typed(OLD_PULL)
    # grasp_pose.GraspParams mirrors no setting: its defaults are HEAD's
    assert grasp_pose.GraspParams() == grasp_pose.GraspParams(
        pitch_rad=0.0,
        comfort_gap_m=0.02,
        top_tilt_rad=0.3,
        clearance_m=0.05,
        top_depth_m=0.045,  # 0.03 until a box held by its upper part crept out (seed 16)
        pregrasp_m=0.12,
        max_width_m=0.075,
        width_slack_m=0.015,
        reach_slack_m=0.06,
        # 45° until a box held from the side by its near end (hall seed 1's shift) was
        # held from 23° off its long faces and not from 30°
        box_side_max_off_rad=math.radians(25.0),
    )
