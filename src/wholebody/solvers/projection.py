"""The paper's backend: pseudo-inverse with recursive null-space projection.

Without bounds, level by level (scaled coordinates ``u~``, see :mod:`.stack`)::

    u_0 = 0,  P_0 = I
    M_k = A_k P_{k-1}
    u_k = u_{k-1} + M_k^+_damped (b_k - A_k u_{k-1})
    P_k = P_{k-1} - M_k^+ M_k

``P`` is the orthogonal projector onto the directions that leave every higher level
unchanged: exact (undamped, with a rank threshold), computed from the eigen-decomposition of
the small Gram matrix ``M M^T`` (its eigenvalues are the squared singular values). A level
made only of objectives has rows ``s I``, so it is simply
``u_k = u_{k-1} + P (b/s - u_{k-1})``. With one level of tasks ``(J, v)`` and one level of
objectives, ``u = J+ v + N u0 = J+ v - k (I - J+ J) grad H``: the paper's
law. The plain pseudo-inverse is the same solver on a stack without the objective level.

Linear algebra (:mod:`wholebody.kernels.pinv`): where the Gram matrix of a level's rows is
certified to have no eigenvalue below ``eps^2`` (a Cholesky factor, and a bound or a second
factor of ``G - eps^2 I``), no damping applies and every direction counts:
``M^+ r = M^T G^-1 r`` and ``M^+ M = M^T G^-1 M`` exactly, or, for a level with more rows
than columns (a weighted sum of tasks), its well-conditioned normal equations. Otherwise (near
a singularity) the eigen-decomposition (fast path) or the SVD (saturation) decides damping and
rank as described below. What a certified level leaves free is kept as the complement of the
orthonormal rows ``L^-1 M`` (``G = L L^T``): its basis (a QR factorisation) is built only for
a level below that needs one. A level of tasks whose rows are ``s I`` (a posture task in a
uniform metric), with ``s`` far enough above ``eps`` that every certificate holds, is solved
as a level of objectives, ``P (b/s - u_{k-1})``: the same exact step without a factorisation.

Singularity robustness: each singular direction of a level whose singular value ``s_i`` is
below ``eps`` is damped with the variable damping ``lambda_i^2 = (1 - (s_i/eps)^2)
lambda_max^2`` (Chiaverini's variable factor, applied direction by direction as in the
numerical filtering of Maciejewski and Klein), the others not at all: away from singularities
the solution is the exact pseudo-inverse, and near one only the nearly singular directions
are damped. Damping every direction by the smallest singular value's factor would also damp
a level's well-conditioned tasks whenever it holds a low-weight regulariser, whose singular
values are small by its weight, not by the kinematics.

Units of ``eps``: the singular values are those of the level's rows divided by
``reference_scale = sqrt(w_min)``, the smallest positive task weight of the level
(:class:`~wholebody.solvers.stack.LevelProblem`), in the metric's scaled velocities ``u~``.
So a weight common to a level's tasks changes nothing, and a heavier task never makes a
lighter one count as singular. The price: in a level that also holds a light regulariser (a
posture task of weight 1e-5 beside the hands), a task's singular directions are measured
against that regulariser, and it is the regulariser, as in any weighted least squares, that
bounds the velocity near the task's singularity; put singular-prone tasks in a level of their
own, as the paper's stack does, for the damping proper. The metric is not normalised: ``eps``
is in the units of ``u~ = W^(1/2) u``, and a uniform metric ``c I`` moves the threshold on the
task's own singular values to ``eps sqrt(c)`` (the damping of a weighted norm, like
``lambda``).

Bounds: the unsaturated solution of the whole stack is computed first and returned when it is
inside the box. Otherwise: **Saturation in the Null Space** (Flacco, De Luca, Khatib, IEEE
T-RO 2015), from the start, written with orthogonal projectors. At each level, if ``u``
leaves the box, the most critical joint (the one that limits the task scaling factor most)
is saturated at its bound: its value is fixed, the change is absorbed by the level's free
null-space directions, and the level is re-solved on the remaining free directions. The free
directions are those of the projector ``F`` (initially the ``P`` of the higher levels);
saturating joint j at value f is a rank-one update, no factorisation::

    base <- base + F e_j (f - base_j) / F_jj,      F <- F - F e_j e_j^T F / F_jj

(skipped when ``F_jj`` is at rounding level: the joint does not move in those directions).
With ``B = A F`` (``F`` idempotent, so ``B B^T = A F A^T``), the level's move along the free
directions is ``B^T G^-1 r``; while no joint of the first level is saturated, ``F`` is a 0/1
diagonal and ``B`` is ``A`` with columns zeroed. A level made only of objectives (rows ``s I``)
needs no factorisation at all: its move is ``F (b/s - base)``. The best task scaling factor
``s*`` seen so far is kept; when the level runs out of free directions
(``rank(A_k Z_free) <`` what the level needs), its velocity is scaled by ``s*``
(``scale``). Saturated joints stay fixed for the lower levels. As a last guard, a candidate
that is still outside the box is moved along the segment from the (feasible) solution of the
higher levels, so the box always holds and the result is never NaN.

Acceleration limits (:class:`~wholebody.tasks.AccelerationLimits`) make the box a narrow
window around the last velocity, ``|u - u_prev| <= a dt``. SNS in that window alone
asks each level for its whole velocity in one step: a far target then scales a level by
0.001-0.005 and the robot crawls or oscillates. So the stack is first solved, as above, in
the box of the other limits: ``u*``, the velocity the levels want and the position and
velocity limits allow. When ``u*`` is outside the window the stack is solved again from the
last velocity (``d = u - u_c``, ``u_c`` the window's point closest to ``u_prev``), with SNS
in the window: each level asks for its own demand times the scale factor ``s_k`` SNS gave it
in the first box (``s_k b_k``: what that box could deliver, in the level's own direction),
and a last level of rows ``I`` asks for ``u*`` itself in the directions left free. Each
level gets as much of it as the window delivers, in priority order (a closed chain on top
keeps its rows, the hands' level is scaled, the joints it does not need go to ``u*``).
Asking for ``u*``'s own velocities ``A_k u*`` instead converged as often but tracked worse
where a level is unmet for another reason than the box (the arms hanging straight at the
carry's start: 4.9 mm against 3.0 mm under MuJoCo). Measured in
``benchmarks/convergence.py``: with acceleration limits the default controller reaches 78-98 %
of random reachable targets (94-96 % without them; before, with the limits, 0-47 %).

Cost: every factorisation of an SNS iteration is also its rank test (the rank the level needs
is that of the first iteration), a snapshot of the free directions is a reference (they are
never modified in place) and the scaling factor is one pass over the stacked bounds.

Inequality rows (e.g. :class:`~wholebody.tasks.CollisionAvoidance`) are held above every
level by an active set: every row the solution violates (beyond ``tolerance (1 + |bound|)``)
is held at the bound it crosses as an equality row of a new first level, above every task,
and the stack is solved again, until no row is violated (a held row stays held for the step).
Every level is then solved in the null space of the held rows, so the hands yield to a
collision row, never the reverse; rows the first solution respects cost nothing. The
result's ``message`` names the held rows (task and row, e.g. ``collision[2]``, and the pair
where the task names its rows: :meth:`wholebody.tasks.CollisionAvoidance.row_names`) and the
tasks they limited (unmet now, met without them); ``infeasible`` lists those tasks, and held
rows the box kept from their bound under the level ``"inequality rows (held)"``.

Reporting: ``infeasible`` lists every equality task whose weighted residual exceeds
``tolerance * (1 + ||v||)``, as the HQP's. The status has the HQP's meaning
(:class:`~wholebody.solvers.SolverStatus`): INFEASIBLE when a task of the first level or a
held inequality row is unmet, or when SNS ran (and no row is held) and the box raised a
task's residual above its residual at the box-free solution (the unsaturated pass, the best
the higher levels leave it) by more than that tolerance, whatever its level; else SCALED when
a level was scaled (in practice an objectives' level, whose rows are no task); else
BOUNDS_ACTIVE when some entry of ``u`` is on a bound.

Everything runs in one kernel call after the stack's evaluation
(:mod:`wholebody.kernels.projection`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from wholebody.kernels import control
from wholebody.kernels import layout as lay
from wholebody.kernels import projection as kernel
from wholebody.kernels.pinv import (
    PAR_DAMPING,
    PAR_RANK,
    PAR_SATURATE,
    PAR_THRESHOLD,
    PAR_TOLERANCE,
    PAR_WIDTH,
)
from wholebody.robot import RobotState
from wholebody.solvers.base import Setting, Solver
from wholebody.solvers.plan import Arena, Plan, ProblemArena, first_call
from wholebody.solvers.result import SolverResult
from wholebody.solvers.stack import Stack, StackProblem

__all__ = ["HELD", "ProjectionSolver"]

HELD = "inequality rows (held)"
"""The name of the level the held inequality rows form, in ``infeasible``."""


class ProjectionSolver(Solver):
    """Damped pseudo-inverse + recursive null-space projection + SNS for the box.

    Parameters
    ----------
    damping
        ``lambda_max``: the largest damping, reached at a singularity.
    singular_threshold
        ``eps``: a singular direction is damped when its singular value is below it (in the
        units of the level's lightest task and the metric's scaled velocities, see the module
        docstring).
    rank_tolerance
        Singular values below ``rank_tolerance * max(1, s_max)`` count as zero for null
        spaces and ranks.
    tolerance
        A level's residual above ``tolerance * (1 + |b|)`` counts as not met.
    saturate
        Apply SNS. When False the bounds are not enforced (the textbook solution; used to
        show what the box costs, never in control).
    """

    name = "projection"

    def __init__(
        self,
        *,
        damping: float = 0.05,
        singular_threshold: float = 0.02,
        rank_tolerance: float = 1e-9,
        tolerance: float = 1e-6,
        saturate: bool = True,
    ) -> None:
        self._par = np.zeros(PAR_WIDTH)
        self.damping = damping
        self.singular_threshold = singular_threshold
        self.rank_tolerance = rank_tolerance
        self.tolerance = tolerance
        self.saturate = saturate

    damping = Setting(PAR_DAMPING, valid=lambda v: v >= 0, rule=">= 0")
    singular_threshold = Setting(PAR_THRESHOLD, valid=lambda v: v > 0, rule="> 0")
    rank_tolerance = Setting(PAR_RANK, valid=lambda v: v > 0, rule="> 0")
    tolerance = Setting(PAR_TOLERANCE, valid=lambda v: v > 0, rule="> 0")
    saturate = Setting(PAR_SATURATE, bool)

    def parameters(self) -> np.ndarray:
        """The settings as the kernel reads them."""
        return self._par

    def solve(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        """Evaluate ``stack`` at ``state`` for a step of ``dt`` s and solve it."""
        start = time.perf_counter()
        plan = stack.synced_plan(state, dt)
        buffers = plan.step_buffers()
        buffers.batch.Q[0] = state.q
        self.run(plan, buffers.pinocchio(), buffers.batch, 1, 0)
        plan.evaluated = state.stamp
        result = self.result(plan, time.perf_counter() - start, stack)
        plan.last_result = result
        return result

    def run(
        self,
        plan: Plan,
        kinematics: control.Kinematics,
        batch: control.Batch,
        steps: int,
        what: int,
    ) -> None:
        """Whole steps in one kernel call (:func:`wholebody.kernels.control.projection_run`)
        on the synced ``plan``."""
        arena = plan.step_buffers(batch.refs.shape[1]).arena
        self.kernel_run(arena, kinematics, batch, steps, what, None)

    def _kernel_call(
        self,
        arena: control.Arena,
        workspace: control.Arena | None,
        kinematics: control.Kinematics,
        batch: control.Batch,
        steps: int,
        what: int,
    ) -> tuple[Any, ...]:
        """:func:`wholebody.kernels.control.projection_run`'s call (``workspace``: unused,
        the HQP's)."""
        return (
            "projection",
            "the projection kernels",
            control.projection_run,
            arena,
            kinematics,
            batch,
            self._par,
            steps,
            what,
        )

    def solve_problem(self, problem: StackProblem) -> SolverResult:
        """Solve an evaluated stack (rows in scaled coordinates, e.g. ``stack.evaluate()``'s
        or a synthetic one)."""
        start = time.perf_counter()
        arena = ProblemArena(problem)
        first_call(
            "projection",
            "the projection kernels",
            kernel.project,
            arena.f,
            arena.i,
            arena.h,
            self.parameters(),
        )
        return self.result(arena, time.perf_counter() - start)

    def result(self, arena: Arena, solve_time: float, stack: Stack | None = None) -> SolverResult:
        """The kernel's outcome in ``arena`` as a :class:`SolverResult`, with the held
        inequality rows and what they limited in the message (named by their pair where
        ``stack`` is given and the task names its rows)."""
        code = int(arena.view(lay.I_OUT)[lay.OUT_MESSAGE])
        result = arena.result(solve_time, _MESSAGES[code])
        held = arena.view(lay.I_HELD)
        if arena.inequality_rows and held.any():
            _held_report(arena, result, held, stack)
        return result


_MESSAGES = {
    0: "",
    kernel.MESSAGE_EMPTY_BOX: "the box is empty or not a number (NaN bounds): u = 0",
    kernel.MESSAGE_NON_FINITE: "non-finite solution replaced by the box's closest point to 0",
}


def _held_report(arena: Arena, result: SolverResult, held: np.ndarray, stack: Stack | None) -> None:
    """The held rows into ``result``: their names in the message with the tasks they
    limited (unmet now, met before any row was held), the unmet ones in ``infeasible``."""
    names = _row_names(arena, stack)
    rows = np.flatnonzero(held)
    before = arena.view(lay.I_UNMET0)
    unmet_before = {arena.task_names[t] for t in np.flatnonzero(before)}
    limited = [task for _, task in result.infeasible if task not in unmet_before]
    text = f"held inequality rows: {', '.join(names[r] for r in rows)}"
    if limited:
        text += f"; they limited: {', '.join(limited)}"
    result.infeasible += [(HELD, names[r]) for r in rows if held[r] == lay.HELD_UNMET]
    result.message = "; ".join(m for m in (result.message, text) if m)


def _row_names(arena: Arena, stack: Stack | None) -> list[str]:
    """A name per inequality row: ``task[k]``, followed by the row's own name where the
    task gives one (``row_names()``: a collision pair)."""
    own: dict[str, list[str]] = {}
    if stack is not None:
        for level in stack.levels:
            for task in level.inequalities:
                row_names = getattr(task, "row_names", None)
                own[task.name] = row_names() if callable(row_names) else []
    out = [""] * arena.view(lay.I_HELD).size
    for _, first, last, name in arena.inequality_rows:
        extra = own.get(name, [])
        for k in range(last - first):
            label = f"{name}[{k}]"
            out[first + k] = f"{label} {extra[k]}" if k < len(extra) and extra[k] else label
    return out
