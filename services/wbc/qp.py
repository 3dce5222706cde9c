"""The whole-body inverse-dynamics QP: `build_qp` assembles it, `QpSolver.solve` solves it.

    min_x  ½ xᵀ P x + qᵀ x   s.t.  lo ≤ A x ≤ hi,      x = [v̇ (nv), f (12)]

P stacks every task's rows (H = Jᵀ W J, one product over preallocated rows; a task that
selects joints, the posture, adds its weights to the diagonal instead) plus the force
regularisation w_f ‖f − f_ref‖² and a tiny v̇ damping; A stacks the constraint blocks in a
fixed order (dynamics and torque, written together, contact, friction, force bounds,
joint limits). The problem is dense numpy arrays, so a test can read it; the solver
keeps OSQP set up once with a fixed sparsity pattern (the structural nonzeros: P's upper
triangle, A's from the kinematic tree) and each tick only pushes the values in that
pattern's CSC order (OSQP's `update_data_mat` and `update_data_vec`), warm-started from
the previous solution. OSQP's Ruiz scaling is off
by default: it is recomputed on every matrix update and costs twice the factorisation
(40 of 60 µs here); eps 1e-3 leaves < 1 N of slack on forces of hundreds of N.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import osqp
import scipy.sparse as sp

from common import robot
from common.geometry import FloatArray
from services.wbc import constraints as cons
from services.wbc.model import RobotModel
from services.wbc.tasks import Task

IntArray = npt.NDArray[np.intp]
#: OSQP statuses whose x is used: solved, and solved to the lower accuracy.
_ACCEPTED = (1, 2)


@dataclass(frozen=True)
class QpParams:
    """Constraint and regularisation parameters. Not settings: tuned with the model and
    the sim's contacts.

    mu: friction coefficient of the linearised cone (below the sim's 0.9 for margin).
    f_min, f_max: normal force bounds of a stance foot, N. k_slip: 1/s, stance foot
    velocity damping. w_force: weight of ‖f − f_ref‖² (per N²). w_vdot: v̇ damping.
    limit_horizon_s, limit_acc_max: the joint-limit rows' horizon (s) and clip (rad/s²).
    """

    mu: float = 0.6
    f_min: float = 5.0
    f_max: float = 700.0
    k_slip: float = 20.0
    w_force: float = 1e-4
    w_vdot: float = 1e-6
    limit_horizon_s: float = 0.05
    limit_acc_max: float = 300.0


@dataclass
class QpProblem:
    """½ xᵀ P x + qᵀ x, lo ≤ A x ≤ hi (dense), and where each constraint block lives."""

    P: FloatArray
    q: FloatArray
    A: FloatArray
    lo: FloatArray
    hi: FloatArray
    blocks: dict[str, slice]
    nv: int
    mu: float
    # Workspace: task rows stacked (J, b, w) and the diagonal tasks' share.
    rows_jac: FloatArray
    rows_b: FloatArray
    rows_w: FloatArray
    H: FloatArray
    diag_w: FloatArray
    diag_wb: FloatArray
    tau_bound: FloatArray  # (nv,) 0 on the base rows, τ_max on the actuated ones

    @property
    def nx(self) -> int:
        return int(self.P.shape[0])


#: Most task rows a problem stacks (every frame task, the CoM, margin).
MAX_TASK_ROWS = 96


def new_problem(nv: int, params: QpParams) -> QpProblem:
    """An empty problem with the constant blocks (friction, force selection, limits) filled."""
    nx, blocks, start = nv + cons.NF, {}, 0
    for name, n in cons.ROWS.items():
        blocks[name] = slice(start, start + n)
        start += n
    p = QpProblem(
        P=np.zeros((nx, nx)),
        q=np.zeros(nx),
        A=np.zeros((start, nx)),
        lo=np.zeros(start),
        hi=np.zeros(start),
        blocks=blocks,
        nv=nv,
        mu=params.mu,
        rows_jac=np.zeros((MAX_TASK_ROWS, nv)),
        rows_b=np.zeros(MAX_TASK_ROWS),
        rows_w=np.zeros(MAX_TASK_ROWS),
        H=np.zeros((nv, nv)),
        diag_w=np.zeros(nv),
        diag_wb=np.zeros(nv),
        tau_bound=np.zeros(nv),
    )
    if blocks["dynamics"].stop != blocks["torque"].start or nv != 6 + cons.ROWS["torque"]:
        raise ValueError(f"the dynamics and torque rows must be adjacent, nv of them: {blocks}")
    fr = blocks["friction"]
    cons.fill_friction(params.mu, nv, p.A[fr], p.lo[fr], p.hi[fr])
    fo = blocks["force"]
    cons.fill_force(np.ones(4), params.f_min, params.f_max, nv, p.A[fo], p.lo[fo], p.hi[fo])
    cons.fill_limits_rows(nv, p.A[blocks["limits"]])
    return p


def build_qp(
    m: RobotModel,
    tasks: Sequence[Task],
    stance: FloatArray,
    f_ref: FloatArray,
    params: QpParams,
    tau_max: FloatArray = robot.TORQUE_LIMITS,
    out: QpProblem | None = None,
) -> QpProblem:
    """The QP of this tick for the model's state, the tasks and the stance feet (4,).

    Tasks whose weights are all zero are left out. With `out` (from `new_problem` with
    the same params), the problem is written into it instead of allocated.
    """
    p = out if out is not None and out.mu == params.mu else new_problem(m.nv, params)
    nv = m.nv
    Jr, br, wr = p.rows_jac, p.rows_b, p.rows_w
    diag_w, diag_wb = p.diag_w, p.diag_wb
    diag_w.fill(params.w_vdot)
    diag_wb.fill(0.0)
    n = 0
    for t in tasks:
        if not t.active:
            continue
        J, b, w = t.compute_rows(m)
        cols = t.columns
        if cols is not None:  # J selects these columns: a diagonal share
            diag_w[cols] += w
            diag_wb[cols] += w * b
            continue
        k = n + len(b)
        Jr[n:k] = J
        br[n:k] = b
        wr[n:k] = w
        n = k
    WJ = Jr[:n] * wr[:n, None]
    H = p.H
    np.dot(Jr[:n].T, WJ, out=H)
    H.flat[:: nv + 1] += diag_w
    P = p.P
    P[:nv, :nv] = H
    P.flat[nv * (P.shape[0] + 1) :: P.shape[0] + 1] = params.w_force
    qv = p.q[:nv]
    np.dot(br[:n], WJ, out=qv)
    qv += diag_wb
    np.negative(qv, out=qv)
    np.multiply(f_ref, -params.w_force, out=p.q[nv:])

    A, lo, hi, bl = p.A, p.lo, p.hi, p.blocks
    s = slice(bl["dynamics"].start, bl["torque"].stop)
    if p.tau_bound[6] != tau_max[0]:
        p.tau_bound[6:] = tau_max
    cons.fill_equations_of_motion(m, p.tau_bound, A[s], lo[s], hi[s])
    s = bl["contact"]
    cons.fill_contact(m, stance, params.k_slip, A[s], lo[s], hi[s])
    s = bl["force"]
    cons.fill_force(stance, params.f_min, params.f_max, nv, A[s], lo[s], hi[s])
    s = bl["limits"]
    cons.fill_limits(
        m,
        robot.POSITION_LOWER[: cons.N_LIMITED],
        robot.POSITION_UPPER[: cons.N_LIMITED],
        params.limit_horizon_s,
        params.limit_acc_max,
        lo[s],
        hi[s],
    )
    return p


@dataclass(frozen=True)
class QpSolution:
    """v̇ (nv,), f (12,) in world axes, OSQP's status and iteration count."""

    vdot: FloatArray
    f: FloatArray
    ok: bool
    status: str
    iterations: int


def _csc_order(mask: npt.NDArray[np.bool_]) -> tuple[sp.csc_matrix, IntArray, IntArray]:
    """A CSC matrix of ones on `mask` and its (row, col) entries in CSC storage order."""
    M = sp.csc_matrix(mask.astype(float))
    M.sort_indices()
    cols = np.repeat(np.arange(M.shape[1]), np.diff(M.indptr))
    return M, M.indices.astype(np.intp), cols.astype(np.intp)


def structural_pattern(problems: Sequence[QpProblem]) -> npt.NDArray[np.bool_]:
    """A's nonzeros over problems built at generic states with all feet in stance."""
    mask = np.zeros(problems[0].A.shape, dtype=bool)
    for p in problems:
        mask |= p.A != 0.0
    return mask


class QpSolver:
    """OSQP set up once on a fixed pattern; `solve` pushes values and warm-starts."""

    def __init__(
        self,
        template: QpProblem,
        A_pattern: npt.NDArray[np.bool_],
        eps: float = 1e-3,
        max_iter: int = 200,
        scaling: int = 0,
        check_termination: int = 2,
        **settings: float | int | bool,
    ) -> None:
        """`settings`: further OSQP settings (`rho`, `adaptive_rho`, …) for experiments."""
        nx = template.nx
        P_mask = np.zeros((nx, nx), dtype=bool)
        P_mask[: template.nv, : template.nv] = np.triu(np.ones((template.nv, template.nv), bool))
        P_mask[np.arange(nx), np.arange(nx)] = True
        P0, P_rows, P_cols = _csc_order(P_mask)
        A0, A_rows, A_cols = _csc_order(A_pattern)
        self._P_flat = P_rows * nx + P_cols  # C-order flat indices, in CSC storage order
        self._A_flat = A_rows * nx + A_cols
        self._Px = np.zeros(len(P_rows))
        self._Ax = np.zeros(len(A_rows))
        self._A_outside = ~A_pattern
        self.nv = template.nv
        self.solver = osqp.OSQP()
        P0.data[:] = template.P.ravel()[self._P_flat]  # explicit zeros stay stored
        A0.data[:] = template.A.ravel()[self._A_flat]
        self.solver.setup(
            P0,
            template.q,
            A0,
            template.lo,
            template.hi,
            eps_abs=eps,
            eps_rel=eps,
            max_iter=max_iter,
            polishing=False,
            warm_starting=True,
            verbose=False,
            check_termination=check_termination,
            scaling=scaling,
            **settings,
        )
        self._ext = self.solver._solver
        if float(self.solver.constant("OSQP_INFTY")) > cons.INF:
            raise ValueError(f"constraints' INF {cons.INF} is below OSQP's infinity")
        self.solve(template)

    def solve(self, problem: QpProblem) -> QpSolution:
        """Solve `problem` (built with the template's layout) from the last solution."""
        np.take(problem.P, self._P_flat, out=self._Px)
        np.take(problem.A, self._A_flat, out=self._Ax)
        # The C solver directly: osqp 1.1's Python wrapper adds ~40 µs a tick (a results
        # namespace, a derivative cache) that a 1 kHz loop cannot spend. The bounds go
        # as they are: the constraints write OSQP's infinity, never inf.
        ext = self._ext
        ext.update_data_vec(q=problem.q, l=problem.lo, u=problem.hi)
        ext.update_data_mat(P_x=self._Px, P_i=None, A_x=self._Ax, A_i=None)
        ext.solve()
        info = ext.info
        x = ext.solution.x
        # One reduction finds any NaN or inf (they make the sum non-finite).
        ok = info.status_val in _ACCEPTED and math.isfinite(float(x.sum()))
        if not ok:
            x = np.zeros(problem.nx)
        return QpSolution(x[: self.nv], x[self.nv :], ok, info.status, info.iter)

    def outside_pattern(self, problem: QpProblem) -> float:
        """The largest |A| entry the fixed pattern drops (0 when the pattern is right)."""
        return float(np.max(np.abs(problem.A[self._A_outside]), initial=0.0))
