"""The arm stays within its joint limits on an unreachable target, and a held payload
the model does not know does not sag the gripper (integral action), in process."""

from __future__ import annotations

import mujoco
import numpy as np

from bench.wbc_harness import floor_spec, read_state, set_initial_pose, simulate
from common import robot
from common.geometry import make_T, rot_z
from services.sim import mjcf
from services.wbc.controller import WbcReferences, WbcState
from services.wbc.reach import PoseSegment

READY = robot.POSTURES["ready"][12:18]


def tcp_pose(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    site = model.site(robot.TCP_FRAME).id
    return make_T(data.site_xmat[site].reshape(3, 3).copy(), data.site_xpos[site].copy())


def hold_target(payload_kg: float, offset: np.ndarray, seconds: float) -> tuple[dict, np.ndarray]:
    """Stand in `ready`, then move the TCP by `offset` (world) in 1 s and hold it there.

    Returns the figures and the arm joints' extreme excursion past their limits (rad).
    """
    model = floor_spec(payload_kg).compile()
    data = mujoco.MjData(model)
    q0 = robot.standing_q()
    q0[19:25] = READY
    set_initial_pose(model, data, q0)
    T0 = tcp_pose(model, data)
    T1 = T0.copy()
    T1[:3, 3] += offset
    T1[:3, :3] = rot_z(0.3) @ T0[:3, :3]
    segment = PoseSegment(T0, T1, 1.0)
    past = np.zeros(6)
    idx = mjcf.mj_indices(model)

    def refs_at(t: float, state: WbcState) -> WbcReferences:
        s = segment.sample(t)
        q_arm = read_state(model, data, idx).q[12:18]
        over = np.maximum(q_arm - robot.POSITION_UPPER[12:18], robot.POSITION_LOWER[12:18] - q_arm)
        np.maximum(past, over, out=past)
        return WbcReferences(
            T_world_tcp=s.T, tcp_twist=s.twist, tcp_acceleration=s.acceleration,
            arm_posture=READY.copy(),
        )  # fmt: skip

    log, ctrl, _ = simulate(model, data, seconds, refs_at)
    err = float(np.linalg.norm(tcp_pose(model, data)[:3, 3] - T1[:3, 3]))
    height = float(log.pos[-1][2])
    return {"error_m": err, "height_m": height, "qp_failures": ctrl.qp_failures}, past


def test_a_half_kilo_payload_does_not_sag_the_held_gripper() -> None:
    out, _ = hold_target(0.5, np.array([0.05, 0.0, 0.05]), 3.0)
    assert out["error_m"] < 0.004, out  # without the integral: about 1 cm
    assert out["qp_failures"] == 0


def test_an_unreachable_target_leaves_every_arm_joint_within_its_limits() -> None:
    out, past = hold_target(0.0, np.array([0.0, 0.0, 1.5]), 2.5)  # 1.5 m overhead
    assert out["height_m"] > 0.4, out  # still standing
    assert np.all(past < 0.02), dict(zip(robot.ARM_JOINTS, past.round(4), strict=True))
