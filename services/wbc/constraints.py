"""Constraints of the whole-body QP over x = [v̇ (nv), f (12)], each as rows lo ≤ A x ≤ hi.

f stacks the four feet's contact forces in world axes (FL, FR, RL, RR). Every foot has
its rows every tick, so the sparsity never changes: a swing foot's force is bounded to
zero and its no-slip rows are relaxed to ±∞. The ground is the plane z = 0 (normal +z).

- dynamics: the floating base's six rows of M v̇ + h = Sᵀτ + J_cᵀ f (no actuation there);
- contact: a stance foot does not accelerate, J_c v̇ + J̇_c v = −k_slip v_foot;
- friction: a linearised cone |f_x|, |f_y| ≤ μ f_z (four rows per foot);
- force bounds: f_min ≤ f_z ≤ f_max in stance, f = 0 in swing;
- torque: τ = M_a v̇ + h_a − J_c,aᵀ f within the URDF limits;
- joint limits: the legs' and arm's v̇ keep q + v h + ½ v̇ h² within the URDF position
  limits over a short horizon h (an unreachable arm target stops at the limit instead of
  driving the joint into MuJoCo's), clipped to ±a_max so the rows stay feasible and
  ordered even when a joint is already past its limit.

"Unbounded" is OSQP's infinity (1e30), so the bounds go to the solver as they are.

Each `fill_*` writes its block in place (the QP reuses one buffer per tick); the
functions without `fill_` return a fresh `Constraint` of the same rows, for tests.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from common.geometry import FloatArray
from services.wbc.model import RobotModel

N_FEET = 4
NF = 3 * N_FEET  # contact force variables
INF = 1e30  # OSQP_INFTY: OSQP reads bounds at or beyond it as infinite
_STANCE_LO = np.array([-INF, -INF, 0.0])
_STANCE_HI = np.array([INF, INF, 0.0])
N_LIMITED = 18  # the legs' and arm's joints (the jaw is position-controlled outside the QP)
#: The blocks in the QP's order: dynamics and torque are the rows of one [M, −J_cᵀ], which
#: `fill_equations_of_motion` writes at once.
ROWS = {
    "dynamics": 6,
    "torque": 19,
    "contact": NF,
    "friction": 4 * N_FEET,
    "force": NF,
    "limits": N_LIMITED,
}


class Constraint(NamedTuple):
    """Rows lo ≤ A x ≤ hi over x = [v̇, f]."""

    A: FloatArray
    lo: FloatArray
    hi: FloatArray


def fill_dynamics(m: RobotModel, A: FloatArray, lo: FloatArray, hi: FloatArray) -> None:
    """M_u v̇ − J_c,uᵀ f = −h_u on the six unactuated (floating-base) rows."""
    nv = m.nv
    A[:, :nv] = m.M[:6]
    A[:, nv:] = m.Jc[:, :6].T
    np.negative(A[:, nv:], out=A[:, nv:])
    np.negative(m.h[:6], out=lo)
    hi[:] = lo


def fill_contact(
    m: RobotModel, stance: FloatArray, k_slip: float, A: FloatArray, lo: FloatArray, hi: FloatArray
) -> None:
    """Stance feet: J_c v̇ = −J̇_c v − k_slip v_foot; swing feet: unconstrained rows."""
    A[:, : m.nv] = m.Jc
    np.multiply(m.v_feet, -k_slip, out=lo)
    lo -= m.dJc_v
    hi[:] = lo
    for k in range(N_FEET):
        if stance[k] < 0.5:
            lo[3 * k : 3 * k + 3] = -INF
            hi[3 * k : 3 * k + 3] = INF


def fill_friction(mu: float, nv: int, A: FloatArray, lo: FloatArray, hi: FloatArray) -> None:
    """±f_x − μ f_z ≤ 0 and ±f_y − μ f_z ≤ 0 for every foot (constant rows)."""
    A[:] = 0.0
    for k in range(N_FEET):
        for r, (axis, sign) in enumerate(((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):
            A[4 * k + r, nv + 3 * k + axis] = sign
            A[4 * k + r, nv + 3 * k + 2] = -mu
    lo[:] = -INF
    hi[:] = 0.0


def fill_force(
    stance: FloatArray,
    f_min: float,
    f_max: float,
    nv: int,
    A: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
) -> None:
    """Stance: f_min ≤ f_z ≤ f_max (x, y bounded by the cone); swing: f = 0.

    The rows select f (constant); only the bounds change with the stance.
    """
    if A[0, nv] != 1.0:  # a fresh block: the selection
        A[:, :nv] = 0.0
        A[:, nv:] = np.eye(NF)
    lo3, hi3 = lo.reshape(N_FEET, 3), hi.reshape(N_FEET, 3)
    for k in range(N_FEET):
        if stance[k] > 0.5:
            lo3[k] = _STANCE_LO
            hi3[k] = _STANCE_HI
            lo3[k, 2], hi3[k, 2] = f_min, f_max
        else:
            lo3[k] = 0.0
            hi3[k] = 0.0


def fill_torque(
    m: RobotModel, tau_max: FloatArray, A: FloatArray, lo: FloatArray, hi: FloatArray
) -> None:
    """−τ_max ≤ M_a v̇ + h_a − J_c,aᵀ f ≤ τ_max on the actuated rows."""
    nv = m.nv
    A[:, :nv] = m.M[6:]
    A[:, nv:] = m.Jc[:, 6:].T
    np.negative(A[:, nv:], out=A[:, nv:])
    np.subtract(-tau_max, m.h[6:], out=lo)
    np.subtract(tau_max, m.h[6:], out=hi)


def fill_equations_of_motion(
    m: RobotModel, tau_bound: FloatArray, A: FloatArray, lo: FloatArray, hi: FloatArray
) -> None:
    """The dynamics and torque blocks together (nv rows): [M, −J_cᵀ] x within −h ∓ τ_bound.

    tau_bound (nv,): 0 on the six base rows (equality), τ_max on the actuated ones.
    """
    nv = m.nv
    A[:, :nv] = m.M
    np.negative(m.Jc.T, out=A[:, nv:])
    np.subtract(tau_bound, m.h, out=hi)
    np.add(tau_bound, m.h, out=lo)
    np.negative(lo, out=lo)


def fill_limits_rows(nv: int, A: FloatArray) -> None:
    """The joint-limit rows' constant matrix: v̇ of the 18 limited joints (after the base)."""
    A[:] = 0.0
    A[np.arange(N_LIMITED), 6 + np.arange(N_LIMITED)] = 1.0


def fill_limits(
    m: RobotModel,
    lower: FloatArray,
    upper: FloatArray,
    horizon_s: float,
    a_max: float,
    lo: FloatArray,
    hi: FloatArray,
) -> None:
    """2 (q_lim − q − v h) / h² bounds on v̇ (18,), clipped to ±a_max (order kept)."""
    q = m.q[7 : 7 + N_LIMITED]
    drift = m.v[6 : 6 + N_LIMITED] * horizon_s
    drift += q
    k = 2.0 / (horizon_s * horizon_s)
    np.subtract(lower, drift, out=lo)
    lo *= k
    np.subtract(upper, drift, out=hi)
    hi *= k
    np.maximum(lo, -a_max, out=lo)  # the ufuncs: np.clip costs three times as much here
    np.minimum(lo, a_max, out=lo)
    np.maximum(hi, -a_max, out=hi)
    np.minimum(hi, a_max, out=hi)


def _fresh(
    name: str, nv: int, fill: Callable[[FloatArray, FloatArray, FloatArray], None]
) -> Constraint:
    n = ROWS[name]
    c = Constraint(np.zeros((n, nv + NF)), np.zeros(n), np.zeros(n))
    fill(c.A, c.lo, c.hi)
    return c


def dynamics(m: RobotModel) -> Constraint:
    return _fresh("dynamics", m.nv, lambda A, lo, hi: fill_dynamics(m, A, lo, hi))


def contact(m: RobotModel, stance: FloatArray, k_slip: float) -> Constraint:
    return _fresh("contact", m.nv, lambda A, lo, hi: fill_contact(m, stance, k_slip, A, lo, hi))


def friction(mu: float, nv: int) -> Constraint:
    return _fresh("friction", nv, lambda A, lo, hi: fill_friction(mu, nv, A, lo, hi))


def force_bounds(stance: FloatArray, f_min: float, f_max: float, nv: int) -> Constraint:
    return _fresh("force", nv, lambda A, lo, hi: fill_force(stance, f_min, f_max, nv, A, lo, hi))


def torque_limits(m: RobotModel, tau_max: FloatArray) -> Constraint:
    return _fresh("torque", m.nv, lambda A, lo, hi: fill_torque(m, tau_max, A, lo, hi))


def joint_limits(
    m: RobotModel, lower: FloatArray, upper: FloatArray, horizon_s: float, a_max: float
) -> Constraint:
    def fill(A: FloatArray, lo: FloatArray, hi: FloatArray) -> None:
        fill_limits_rows(m.nv, A)
        fill_limits(m, lower, upper, horizon_s, a_max, lo, hi)

    return _fresh("limits", m.nv, fill)


def joint_torques(m: RobotModel, vdot: FloatArray, f: FloatArray) -> FloatArray:
    """τ (19,) that realises v̇ with contact forces f: the actuated rows of the dynamics."""
    return np.asarray(m.M[6:] @ vdot + m.h[6:] - m.Jc[:, 6:].T @ f)
