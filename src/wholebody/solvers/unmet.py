"""Why a task was left unmet in a solve: the cause, from the solved stack's own rows.

A solver reports a task unmet (:attr:`SolverResult.infeasible
<wholebody.solvers.result.SolverResult.infeasible>`, ``I_INFEASIBLE``) when its weighted
residual exceeds ``tol (1 + ||b_t||)``. That alone does not say whether the solver could
have done better. :func:`classify` answers it for each unmet task of a solved
:class:`~wholebody.solvers.plan.Plan`, at its level ``k``, from the rows in the arena (scaled
coordinates ``u~``, the ones the solvers work in), keeping what the higher levels achieved
(``A_hi u~ = A_hi u~*``, their inequality rows no worse than at ``u~*``):

1. the level's *achievable minimum* under the whole box and the inequality rows (a QP): if
   the task is met there, it could have been met: :attr:`UnmetCause.FAILED` when the
   solver's residual exceeds that minimum's by more than ``FAILURE_TOLERANCE (1 + ||b_t||)``
   (so is every task of a step whose solve failed), else :attr:`UnmetCause.INEXACT` (met to
   within the solver's regularisation);
2. else the task's best residual without any bound (least squares): unmet there too, the task
   cannot be met by any velocity: :attr:`UnmetCause.UNREACHABLE` when its own rows are
   inconsistent (a singular arm, a target out of reach: its rows alone cannot be met), else
   :attr:`UnmetCause.PRIORITY` (the levels above use the freedom it needs: by design, e.g.
   a posture under the hands). A task that only a velocity more than ``UNREACHABLE_RATIO``
   times its rate limits would meet (a nearly straight arm asked to stretch) is UNREACHABLE
   too;
3. else the constraints hold it back: met with the joint position limits' box (and the
   inequality rows) alone, the rate bounds (velocity, acceleration) cannot deliver the
   demanded rate this step: :attr:`UnmetCause.SATURATED`; else met once the inequality rows
   are dropped too, an inequality task (a collision distance) holds it:
   :attr:`UnmetCause.INEQUALITY` (by design); else a joint position limit keeps it from its
   target: :attr:`UnmetCause.JOINT_LIMIT`.

When the solver itself says that no bound limited any task (a status below INFEASIBLE: both
backends compare each task's residual with its box-free optimum) and no inequality row sits
at or above the level, an unmet task of a level below the first is PRIORITY (or UNREACHABLE
if its own rows are inconsistent) without a QP.

Only FAILED is a failure: the others are tasks that could not be met this step. The causes
are ordered by severity; a step's cause is the largest of its tasks'.

This is an analysis after the solve (about 1 ms for a step whose status is INFEASIBLE, 0.1 ms
for a lower level unmet by priority, nothing for a step with every task met), not part of
the control step.
"""

from __future__ import annotations

import enum

import numpy as np

from wholebody.kernels import layout as lay
from wholebody.kernels.linalg import level_report
from wholebody.solvers.qp import DaqpEngine, QPStatus
from wholebody.solvers.result import SolverStatus

__all__ = ["CAUSE_WORDS", "UnmetCause", "classify", "worst"]

_RANK = 1e-9  # singular values below this times the largest (at least 1) are zero
_TIKHONOV = 1e-12  # added to the QP's Hessian (daqp wants it positive definite)
FAILURE_TOLERANCE = 1e-4
"""A task the constraints let meet counts as a failure only when the solver's weighted
residual exceeds the least by more than this times ``1 + ||b_t||`` (the solvers'
regularisation leaves up to about 1e-5 on weakly conditioned rows)."""
UNREACHABLE_RATIO = 100.0
"""A task met without bounds only at more than this many times the rate limits (a nearly
straight arm) counts as unreachable, not saturated."""


class UnmetCause(enum.IntEnum):
    """Why a task was unmet in a solve, from least to most severe (see the module
    docstring); 0: met."""

    MET = 0
    INEXACT = 1
    """Met where the constraints allow it to the solver's tolerance, and the solver's answer
    within ``FAILURE_TOLERANCE`` of that (its regularisation): not a failure."""
    PRIORITY = 2
    """The levels above use the freedom the task needs (by design, not a failure)."""
    INEQUALITY = 3
    """An inequality task of its level or above (a collision distance) holds it back (by
    design)."""
    SATURATED = 4
    """A velocity or acceleration bound cannot deliver the demanded rate this step."""
    JOINT_LIMIT = 5
    """A joint position limit keeps the task from its target: no feasible step meets it."""
    UNREACHABLE = 6
    """The task's own rows cannot be met by any velocity (a singular arm; out of reach)."""
    FAILED = 7
    """The solve failed, or left the task unmet where the constraints allowed meeting it."""


CAUSE_WORDS: dict[UnmetCause, str] = {
    UnmetCause.INEXACT: "met only to the solver's accuracy",
    UnmetCause.PRIORITY: "yielding to a higher level (by design)",
    UnmetCause.INEQUALITY: "held back by an inequality task, e.g. a collision distance (by design)",
    UnmetCause.SATURATED: "held back by a velocity/acceleration limit (saturated)",
    UnmetCause.JOINT_LIMIT: "at a joint position limit",
    UnmetCause.UNREACHABLE: "out of reach (no velocity meets it)",
    UnmetCause.FAILED: "a solver failure",
}
"""Each cause in words, for summaries."""


def worst(causes: np.ndarray, axis: int = -1) -> np.ndarray:
    """The most severe cause along ``axis`` (0 where all are met)."""
    return np.max(causes, axis=axis, initial=0)


class _Level:
    """One level's rows, the solution and the constraints the higher levels set, in scaled
    coordinates."""

    def __init__(self, plan, k: int, tol: float) -> None:
        v = plan.view
        levels = v(lay.I_LEVEL)
        self.plan, self.k, self.tol = plan, k, tol
        A, b = v(lay.F_A), v(lay.F_B)
        r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_TASKS_END]
        self.r0 = int(r0)
        self.A, self.b = A[r0:r1], b[r0:r1]
        self.unweight = v(lay.F_ROW)[1, r0:r1]
        tasks = v(lay.I_TASK)
        self.tasks = np.ascontiguousarray(tasks[tasks[:, 0] == k])
        self.first = int(np.flatnonzero(tasks[:, 0] == k)[0])
        self.u = v(lay.F_U)[0].copy()
        higher = [A[levels[j, lay.LEVEL_ROW0] : levels[j, lay.LEVEL_TASKS_END]] for j in range(k)]
        Ahi = np.vstack(higher) if higher else np.zeros((0, self.u.size))
        self.N = _null_space(Ahi, self.u.size)
        ineq = v(lay.I_INEQ)
        C, cb = v(lay.F_C), v(lay.F_CB)
        rows = [r for lv, a, z in ineq[:, :3] if lv <= k for r in range(a, z)] if ineq.size else []
        self.C = C[rows]
        at = self.C @ self.u
        self.c_lo = np.minimum(cb[0, rows], at)  # no worse than the solution (higher levels
        self.c_hi = np.maximum(cb[1, rows], at)  # may have left one violated)

    def residuals(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """The level's residual at ``x`` and per task (weighted, unweighted, ``||b_t||``)."""
        out = np.zeros((self.tasks.shape[0], 3))
        total = level_report(self.A, self.b, self.unweight, x, self.tasks, self.r0, out)
        return total, out

    def met(self, x: np.ndarray) -> np.ndarray:
        """Per task of the level, whether it is met at ``x`` (the solvers' rule)."""
        _, out = self.residuals(x)
        return out[:, 0] <= self.tol * (1.0 + out[:, 2])

    def free(self) -> np.ndarray:
        """The level's best ``u~`` without bounds or inequality rows (the QP's objective
        unconstrained: the same Tikhonov term, so that a nearly singular direction counts as
        unreachable in both)."""
        return self._least(*self._objective())

    def boxed(self, lo: np.ndarray, hi: np.ndarray, rows: bool = True) -> np.ndarray | None:
        """The level's best ``u~`` within ``[lo, hi]`` and (``rows``) the inequality rows (a
        QP in the higher levels' null space); None if the QP engine does not solve it."""
        N = self.N
        if N.shape[1] == 0:
            return self.u
        H, g = self._objective()
        fin = np.isfinite(lo) | np.isfinite(hi)
        C, c_lo, c_hi = (self.C, self.c_lo, self.c_hi) if rows else (self.C[:0], [], [])
        if not fin.any() and not C.shape[0]:
            return self._least(H, g)
        Cz = np.vstack([N[fin], C @ N])
        lower = np.concatenate([lo[fin] - self.u[fin], c_lo - C @ self.u])
        upper = np.concatenate([hi[fin] - self.u[fin], c_hi - C @ self.u])
        # the solution is feasible (z = 0): widen by round-off so that it stays so
        slack = 1e-12 * (1.0 + np.abs(np.concatenate([lo[fin], c_lo])))
        lower = np.minimum(lower, 0.0) - slack
        upper = np.maximum(upper, 0.0) + slack
        sol = DaqpEngine(warm_start=False).solve(H, g, Cz, lower, upper)
        if sol.status > QPStatus.INACCURATE:
            return None
        return self.u + N @ sol.x

    def _objective(self, rows: slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """``H, g`` of ``1/2 ||A (u~* + N z) - b||^2`` (plus the Tikhonov term) in ``z``, over
        the level's ``rows``."""
        A, b = self.A[rows], self.b[rows]
        M = A @ self.N
        H = M.T @ M + _TIKHONOV * np.eye(self.N.shape[1])
        return H, -M.T @ (b - A @ self.u)

    def rate_ratio(self, t: int, rate: np.ndarray) -> float:
        """How many times the rate box ``rate`` (2, nu) the velocity that meets task ``t``
        (index in the level) alone needs, at least (its least-change solution; 0 within)."""
        x = self._least(
            *self._objective(slice(self.tasks[t, 1] - self.r0, self.tasks[t, 2] - self.r0))
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            need = np.where(x > 0, x / rate[1], np.where(x < 0, x / rate[0], 0.0))
        return float(np.max(np.nan_to_num(need, nan=0.0), initial=0.0))

    def _least(self, H: np.ndarray, g: np.ndarray) -> np.ndarray:
        """The unconstrained minimiser ``u~* + N z``, ``H z = -g``."""
        if self.N.shape[1] == 0:
            return self.u
        return self.u + self.N @ np.linalg.solve(H, -g)

    def alone(self, t: int) -> bool:
        """Whether task ``t`` (index in the level) can be met by its own rows alone."""
        a, z = self.tasks[t, 1] - self.r0, self.tasks[t, 2] - self.r0
        return _consistent(self.A[a:z], self.b[a:z], self.tol)


def _consistent(A: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """Whether some ``x`` meets ``A x = b`` within ``tol (1 + ||b||)`` (least squares)."""
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    return bool(np.linalg.norm(A @ x - b) <= tol * (1.0 + np.linalg.norm(b)))


def _null_space(A: np.ndarray, n: int) -> np.ndarray:
    """An orthonormal basis (n, n - rank) of the null space of ``A``."""
    if A.shape[0] == 0:
        return np.eye(n)
    _, s, Vt = np.linalg.svd(A)
    rank = int(np.count_nonzero(s > _RANK * max(1.0, s[0] if s.size else 0.0)))
    return Vt[rank:].T


def _boxes(plan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The whole box, the joint position limits' box alone and the other limits' (the rate
    box), scaled (2, nu) each."""
    from wholebody.tasks import JointPositionLimits

    v = plan.view
    D = v(lay.F_METRIC)[0]
    boxes = v(lay.F_BOXES)
    pos = np.vstack([np.full(D.size, -np.inf), np.full(D.size, np.inf)])
    rate = pos.copy()
    for j, c in enumerate(plan.constraints):
        part = pos if isinstance(c, JointPositionLimits) else rate
        part[0] = np.fmax(part[0], boxes[j, 0])
        part[1] = np.fmin(part[1], boxes[j, 1])
    pos = np.vstack([np.minimum(pos[0], pos[1]), np.maximum(pos[0], pos[1])]) / D
    return v(lay.F_BOX), pos, rate / D


def _level_causes(level: _Level, unmet: np.ndarray, box, pos, rate) -> np.ndarray:
    """The causes of the unmet tasks (mask ``unmet``) of one level (module docstring)."""
    causes = np.where(unmet, UnmetCause.PRIORITY, UnmetCause.MET).astype(np.int8)
    best = level.boxed(box[0], box[1])
    if best is not None:  # met at the level's best under every constraint: a failure
        could = unmet & level.met(best)
        at, least = level.residuals(level.u)[1], level.residuals(best)[1]
        gap = at[:, 0] - least[:, 0] > FAILURE_TOLERANCE * (1.0 + at[:, 2])
        causes[could & gap] = UnmetCause.FAILED
        causes[could & ~gap] = UnmetCause.INEXACT
        unmet = unmet & ~could
    free = level.met(level.free())
    far = np.zeros_like(free)
    for t in np.flatnonzero(unmet & free):  # met only at rates far beyond the limits
        far[t] = level.rate_ratio(int(t), rate) > UNREACHABLE_RATIO
    causes[far] = UnmetCause.UNREACHABLE
    limited = unmet & free & ~far
    if limited.any():  # met without the rate bounds: saturated
        rated = _met_or_not(level, level.boxed(pos[0], pos[1]))
        causes[limited & rated] = UnmetCause.SATURATED
        limited = limited & ~rated
    if limited.any() and level.C.shape[0]:  # ... and without the inequality rows
        held = limited & _met_or_not(level, level.boxed(pos[0], pos[1], rows=False))
        causes[held] = UnmetCause.INEQUALITY
        limited = limited & ~held
    causes[limited] = UnmetCause.JOINT_LIMIT
    for t in np.flatnonzero(unmet & ~free):
        if level.k == 0 or not level.alone(int(t)):
            causes[t] = UnmetCause.UNREACHABLE
    return causes


def _met_or_not(level: _Level, x: np.ndarray | None) -> np.ndarray:
    """Per task of the level, whether it is met at ``x`` (none when the QP gave no ``x``)."""
    return level.met(x) if x is not None else np.zeros(level.tasks.shape[0], dtype=bool)


def _unlimited_causes(plan, k: int, unmet: np.ndarray, tol: float) -> np.ndarray:
    """The causes of the unmet tasks of level ``k > 0`` when the solver says no bound limited
    any task (its status below INFEASIBLE) and no inequality row sits at or above the level:
    the levels above leave them their residual (PRIORITY), unless a task's own rows are
    inconsistent (UNREACHABLE). The solver's own account, without a QP."""
    v = plan.view
    A, b = v(lay.F_A), v(lay.F_B)
    tasks = v(lay.I_TASK)[v(lay.I_TASK)[:, 0] == k]
    causes = np.where(unmet, UnmetCause.PRIORITY, UnmetCause.MET).astype(np.int8)
    for t in np.flatnonzero(unmet):
        rows = slice(tasks[t, 1], tasks[t, 2])
        if not _consistent(A[rows], b[rows], tol):
            causes[t] = UnmetCause.UNREACHABLE
    return causes


def classify(plan, tol: float = 1e-6) -> tuple[np.ndarray, bool]:
    """Per equality task of a solved plan (the order of ``plan.task_names``), the
    :class:`UnmetCause` of the last solve (MET for a met task), and whether the step is a
    failure (the solve FAILED, or some task's cause is FAILED). ``tol``: the solvers'
    tolerance (both backends default to 1e-6)."""
    v = plan.view
    unmet = v(lay.I_INFEASIBLE).astype(bool)
    tasks = v(lay.I_TASK)
    causes = np.zeros(unmet.size, dtype=np.int8)
    status = int(v(lay.I_OUT)[lay.OUT_STATUS])
    if status == SolverStatus.FAILED:
        causes[unmet] = UnmetCause.FAILED
        return causes, True
    if not unmet.any():
        return causes, False
    ineq = v(lay.I_INEQ)
    top_rows = int(ineq[:, 0].min()) if ineq.size else np.iinfo(np.int64).max
    boxes = None
    for k in np.unique(tasks[unmet, 0]).tolist():
        mask = tasks[:, 0] == k
        if status < SolverStatus.INFEASIBLE and 0 < k < top_rows:
            causes[mask] = _unlimited_causes(plan, k, unmet[mask], tol)
            continue
        boxes = boxes or _boxes(plan)
        causes[mask] = _level_causes(_Level(plan, k, tol), unmet[mask], *boxes)
    return causes, bool(np.any(causes == UnmetCause.FAILED))
