"""Weighted acceleration-level tasks of the whole-body QP, as in mink and pink.

Weights change through `set_weight`, which keeps `active` and the weighted rows current.
A task has an error e = target ⊖ current (world-aligned), a Jacobian J = ∂current/∂q in
the tangent space (so `current(q ⊕ ε dq) − current(q) ≈ ε J dq`, checked against finite
differences in the tests) and a drift J̇v. It asks for the acceleration

    a* = a_ff + kp ⊙ e + kd ⊙ (v_ref − J v)

and contributes the rows `‖√w ⊙ (J v̇ + J̇v − a*)‖²` to the objective: `compute_rows`
gives (J, b = a* − J̇v, w), `compute_qp_objective` the equivalent (H, c) over v̇. The QP
stacks every task's rows and forms H = Jᵀ W J in one product.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from common.geometry import FloatArray
from services.wbc.model import RobotModel


class TaskRows(NamedTuple):
    """Residual rows `J v̇ − b`, weighted per row by `w` (≥ 0)."""

    J: FloatArray
    b: FloatArray
    w: FloatArray


class Objective(NamedTuple):
    """The task's share of the QP objective over v̇: ½ v̇ᵀ H v̇ + cᵀ v̇ (+ const)."""

    H: FloatArray
    c: FloatArray


def _vec(x: float | FloatArray, n: int) -> FloatArray:
    out = np.empty(n)
    out[:] = x
    return out


class Task(ABC):
    """Common gains and weights; subclasses define error, Jacobian, drift and velocity.

    `columns`: None, or the v̇ columns the Jacobian selects (J = [0 I 0]): the QP then
    adds the weights to its diagonal instead of multiplying the rows out.
    """

    dim: int = 0
    columns: slice | None = None

    def __init__(self, kp: float | FloatArray, kd: float | FloatArray, weight: float | FloatArray):
        self.kp = _vec(kp, self.dim)
        self.kd = _vec(kd, self.dim)
        self.weight = _vec(weight, self.dim)
        self._weighted()
        self.v_ref = np.zeros(self.dim)
        self.a_ff = np.zeros(self.dim)

    @property
    def active(self) -> bool:
        """False when every weight is zero: the QP leaves the task out."""
        return self._active

    def set_weight(self, weight: float | FloatArray, rows: slice = slice(None)) -> None:
        """Set the weights of `rows`; change weights only through here (it keeps `active`)."""
        self.weight[rows] = weight
        self._weighted()

    def _weighted(self) -> None:
        nonzero = np.flatnonzero(self.weight)
        self._active = len(nonzero) > 0
        #: The span of rows with a weight: `compute_rows` of a frame task gives only those.
        self.rows = slice(int(nonzero[0]), int(nonzero[-1]) + 1) if self._active else slice(0)

    @abstractmethod
    def compute_error(self, m: RobotModel) -> FloatArray:
        """The task's error (dim,): target minus current, in the task's frame."""

    @abstractmethod
    def compute_jacobian(self, m: RobotModel) -> FloatArray:
        """The task's Jacobian (dim, nv)."""

    @abstractmethod
    def compute_drift(self, m: RobotModel) -> FloatArray:
        """J̇v (dim,)."""

    def compute_velocity(self, m: RobotModel) -> FloatArray:
        return self.compute_jacobian(m) @ m.v

    def compute_rows(self, m: RobotModel) -> TaskRows:
        J = self.compute_jacobian(m)
        a_star = (
            self.a_ff
            + self.kp * self.compute_error(m)
            + self.kd * (self.v_ref - self.compute_velocity(m))
        )
        return TaskRows(J, a_star - self.compute_drift(m), self.weight)

    def compute_qp_objective(self, m: RobotModel) -> Objective:
        J, b, w = self.compute_rows(m)
        WJ = J * w[:, None]
        return Objective(J.T @ WJ, -(WJ.T @ b))


class FrameTask(Task):
    """Pose of a tracked frame in world: rows 0:3 position, 3:6 orientation (rotation vector).

    The orientation error is log3(R_target Rᵀ), the world-axes rotation from the frame to
    its target; zero weights switch rows off (a swing foot uses position only).
    """

    dim = 6

    def __init__(
        self,
        frame: str,
        kp: float | FloatArray,
        kd: float | FloatArray,
        weight: float | FloatArray,
    ) -> None:
        super().__init__(kp, kd, weight)
        self.frame = frame
        self.p_ref = np.zeros(3)
        self.R_ref = np.eye(3)

    def set_target(self, p: FloatArray, R: FloatArray | None = None) -> None:
        self.p_ref[:] = p
        if R is not None:
            self.R_ref[:] = R

    def compute_error(self, m: RobotModel) -> FloatArray:
        fs = m.frames[self.frame]
        return np.concatenate([self.p_ref - fs.p, pin.log3(self.R_ref @ fs.R.T)])

    def compute_jacobian(self, m: RobotModel) -> FloatArray:
        return m.frames[self.frame].J

    def compute_drift(self, m: RobotModel) -> FloatArray:
        return m.frames[self.frame].dJv

    def compute_velocity(self, m: RobotModel) -> FloatArray:
        return m.frames[self.frame].twist

    def compute_rows(self, m: RobotModel) -> TaskRows:
        """As `Task.compute_rows`, with the frame read once, only the weighted span of rows
        (a swing foot's position, a base's height and attitude) and few temporaries."""
        fs = m.frames[self.frame]
        b = self.v_ref - fs.twist
        b *= self.kd
        e = np.empty(6)
        np.subtract(self.p_ref, fs.p, out=e[:3])
        rows = self.rows
        if rows.stop > 3:
            e[3:] = pin.log3(self.R_ref @ fs.R.T)
        else:
            e[3:] = 0.0
        e *= self.kp
        b += e
        b += self.a_ff
        b -= fs.dJv
        if rows.start == 0 and rows.stop == 6:
            return TaskRows(fs.J, b, self.weight)
        return TaskRows(fs.J[rows], b[rows], self.weight[rows])


class ComTask(Task):
    """Centre of mass position in world."""

    dim = 3

    def __init__(
        self, kp: float | FloatArray, kd: float | FloatArray, weight: float | FloatArray
    ) -> None:
        super().__init__(kp, kd, weight)
        self.p_ref = np.zeros(3)

    def compute_error(self, m: RobotModel) -> FloatArray:
        return self.p_ref - m.com

    def compute_jacobian(self, m: RobotModel) -> FloatArray:
        return m.Jcom

    def compute_drift(self, m: RobotModel) -> FloatArray:
        return m.dJcom_v

    def compute_velocity(self, m: RobotModel) -> FloatArray:
        return m.vcom

    def compute_rows(self, m: RobotModel) -> TaskRows:
        """As `Task.compute_rows`, with fewer temporaries."""
        b = self.v_ref - m.vcom
        b *= self.kd
        e = self.p_ref - m.com
        e *= self.kp
        b += e
        b += self.a_ff
        b -= m.dJcom_v
        return TaskRows(m.Jcom, b, self.weight)


class PostureTask(Task):
    """Joint positions (all revolute, so the error is a plain difference)."""

    dim = 19

    def __init__(
        self,
        q_ref: FloatArray,
        kp: float | FloatArray,
        kd: float | FloatArray,
        weight: float | FloatArray,
        nv: int = 25,
    ) -> None:
        super().__init__(kp, kd, weight)
        self.q_ref = np.array(q_ref, dtype=float)
        self._J = np.zeros((self.dim, nv))
        self._J[:, nv - self.dim :] = np.eye(self.dim)
        self._drift = np.zeros(self.dim)
        self.columns = slice(nv - self.dim, nv)
        self._b = np.zeros(self.dim)

    def compute_rows(self, m: RobotModel) -> TaskRows:
        """As `Task.compute_rows` (the drift is zero), in place."""
        b = self._b
        np.subtract(self.v_ref, m.v[m.nv - self.dim :], out=b)
        b *= self.kd
        e = self.q_ref - m.q[m.nq - self.dim :]
        e *= self.kp
        b += e
        b += self.a_ff
        return TaskRows(self._J, b, self.weight)

    def compute_error(self, m: RobotModel) -> FloatArray:
        return self.q_ref - m.q[m.nq - self.dim :]

    def compute_jacobian(self, m: RobotModel) -> FloatArray:
        return self._J

    def compute_drift(self, m: RobotModel) -> FloatArray:
        return self._drift

    def compute_velocity(self, m: RobotModel) -> FloatArray:
        return m.v[m.nv - self.dim :]
