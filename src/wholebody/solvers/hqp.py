r"""Hierarchical (lexicographic) QP: strict priorities, hard bounds at every level.

The solver takes the same :class:`~wholebody.solvers.stack.Stack` as the projection backend
and works on the rows :meth:`Stack.evaluate` returns, in the scaled coordinates
``x = u~ = W^(1/2) u`` (so "minimum norm" means ``min ||u||_W``).

The problem solved
------------------
Let ``B = {x : l <= x <= h}`` be the box of the stack's constraints (joint position limits as
velocity bounds for the step ``dt``, joint and wheel velocity limits; :meth:`Stack.evaluate`
already resolves a box crossed by an out-of-limits state, so ``B`` is never empty). Level ``k``
(k = 1..p) has equality rows ``A_k x ~ b_k`` (weighted least squares: tasks, and the
objectives' rows, see below) and inequality rows ``lo_k <= C_k x <= hi_k``. With
``F_0 = B``, level k solves

.. math::

    (w_k^*, s_k^*) = \arg\min_{x \in F_{k-1},\, s}\;
        \tfrac12 \|A_k x - b_k\|^2 + \tfrac12 \|s\|^2
        \quad\text{s.t.}\quad lo_k \le C_k x - s \le hi_k

    F_k = \{x \in F_{k-1} : A_k x = A_k x_k^*,\; lo_k + s_k^* \le C_k x \le hi_k + s_k^*\}

(the optimal ``A_k x`` and slack ``s`` are unique because the objective is strictly convex in
them, so ``F_k`` is exactly the set of the level's optima; an inequality row that had to be
violated, ``s_i^* != 0``, stays pinned at ``C_i x = C_i x_k^*``). The answer is the minimum norm
point of the last set, ``x = argmin_{x in F_p} ||x||^2``. So a lower level can never change a
higher level's residual, and every level, including the first, respects the box.

How it is solved
----------------
Level by level, in the null space of the levels above (the stages in
:mod:`wholebody.kernels.hqp`, the least squares in :mod:`wholebody.kernels.lsq`, a level's QP
and polish in :mod:`wholebody.kernels.hqp_level`): each level's unconstrained least-squares
candidate, exact, by a complete orthogonal decomposition (rank-deficient levels, such as two
hands plus the closed chain between them, solve without error; a level of certain full row
rank by the Cholesky factor of its Gram matrix, and a posture level below it without forming
the basis of the free directions); where the candidate leaves the
box or an inequality row, one QP for that level
(``min 1/2 ||M y - c||^2 + d/2 ||y||^2 + 1/2 ||s||^2`` in the free coordinates ``y``, with a
Tikhonov term ``d = regularization * sigma_max^2`` and slacks ``s`` of the level's inequality
rows), made exact by a polish on the active face (the level's least squares solved on the face
of the constraints active at the QP's answer; where only the box bounds the level, the exact
bounded least squares, BVLS), a check of the level's optimality conditions and proximal steps
where it fails; the constraints the level's optimum presses on are then fixed for the levels
below; at the end the exact minimum-norm point (one more QP where the box binds it). With no
bound active this is the recursive pseudo-inverse, so it equals the projection backend's
``J+ v + (I - J+ J) u0``.

With daqp (the default engine) the whole cascade is one kernel call: daqp's C entry point is
called from the kernel (:mod:`wholebody.kernels.daqp`). Another engine solves the QPs in
Python between the cascade's kernel stages (:mod:`wholebody.solvers.compiled_hqp`).

**Tolerance of the priorities.** A level never sees the levels below it (they are solved
after it, in the null space of its rows), so a lower level
changes a higher level's residual only through the directions dropped by the rank threshold,
the engine's primal tolerance and the final clip (``x`` is clipped to the exact box: it can
only be outside by the relaxation and engine tolerances; ``message`` says so if the clip moved
it by more than ten times ``bound_relaxation``). The tests check ``1e-8 (1 + residual)``
(weighted, scaled units) for the priorities and certify each level's optimum against its KKT
conditions to 1e-6 relative, with bounds active, on synthetic and robot stacks. The
lexicographic problem itself can be ill-conditioned where a level's optimal set is a thin
sliver of the box: there a tiny change in one level's residual can move the next level's
answer far; both methods return a point that satisfies the optimality conditions of every
level.

**Reporting.** ``infeasible`` lists, like the projection backend, every equality task whose
residual exceeds ``tolerance * (1 + ||v||)`` (weighted), the objectives' rows excepted, plus
inequality tasks left violated and the tasks of a skipped level. The status is INFEASIBLE when
the first level is not met or when the box cost some level part of its box-free optimum
(:attr:`LevelReport.limited`, computed at every QP level); FAILED after an engine
failure or non-finite rows (the level is skipped, named, and the rest is solved);
BOUNDS_ACTIVE when some entry of ``u`` sits on the box. The projection backend gives the status
the same meaning (:class:`~wholebody.solvers.SolverStatus`).

Stalled levels: damped
----------------------
A task's rows are its linearisation at the current configuration, so each level's least
squares is one Gauss-Newton step of the task's error. Where a level below the first cannot
be met (a hand sent beyond what its joint limits and a closed chain above it allow) its
exact optimum moves along the directions its rows barely see (small singular values, on the
face of the bounds), at up to the velocity limits: the linearisation's error over such a
step (the task's curvature times its remaining error) exceeds the step's own first-order
effect, so the next step goes back. The undamped cascade then alternates between two
answers every step, the closed chain above drifting off by the second-order effect of
those steps (measured: ``benchmarks/limit_cycles.py``, every QP engine). So a level below
the first that its exact answer leaves unmet, with weighted residual ``r = ||A x - b||``
beyond ``tolerance (1 + ||c||)`` (``c``: what it asks beyond the levels above), is solved
again, damped (Levenberg-Marquardt)::

    min ||A x - b||^2 + lambda^2 ||P (x - a)||^2    over F_(k-1)
    lambda^2 = stall_damping * dt * r * |R_00|

(``P``: the projector onto the directions the levels above leave free; ``a`` the anchor, the
last step's velocity under acceleration limits, else 0, so that the damping holds back the
change the level makes, as the projection's saturation scales around it; ``|R_00|``, the
norm of the level's largest row in the free directions, the scale of its largest singular
value; ``dt`` the step). The damping is of the order of the term the linearisation drops
(the residual, as a distance per step, times a curvature taken at the scale of the rows), so
the stalled level settles: its ``u`` decays, it does not reverse. The levels below keep
``A x`` at the damped answer's value and move in the null space of ``A`` (the damping rows
never use up freedom). Not damped: the first level (the stack's requirement, whose residual sets
the status), a met level (then the cascade is unchanged, bit for bit), a level whose rows
are in joint space (a posture, objectives: their rows do not turn with the configuration), a
problem without a step ``dt`` (:meth:`solve_problem`). ``stall_damping = 0`` gives the exact
lexicographic optimum. The price: an unmet lower level far from its target converges more
slowly (its weakly seen directions are damped while its residual is large). :attr:`levels`
says which levels were damped (``LevelReport.damped``).

Objectives: a descent step at their level
-----------------------------------------
:meth:`Stack.evaluate` turns a level's objectives ``H = sum_i w_i f_i`` into the rows
``I x = -k D grad H`` (weight ``objective_weight``): the quadratic cost
``1/2 ||u - u0||_W^2`` with ``u0 = -k W^-1 grad H``, i.e. one gradient-descent step of length
``k``, projected onto what the higher levels leave free and clipped by the box. This is
exactly the paper's ``(I - J+ J)(-k grad H)`` when no bound is active, so both backends agree
there, and it keeps the step size meaningful (``k`` in 1/s). The alternative,
a single row ``grad^T u = -gamma |grad|`` per level, only fixes the rate of decrease of ``H``
and leaves ``nu - 1`` directions to the next levels, but it is not the paper's law, its
minimum-norm solution is the same direction scaled by ``gamma / |grad|`` (so nothing is
gained when it is the last level), and it becomes an infeasible equality whenever the box
blocks the descent direction. The consequence of the chosen treatment is worth knowing: an
objective level has full rank, so **levels below an objective level cannot move u** (they are
only reported); put posture regulation in the same level as the objectives, or above them.

Engines (``engine=``, see :mod:`wholebody.solvers.qp`)
-----------------------------------------------------
``"daqp"`` (default: a dual active-set method, exact up to round-off on these strictly
convex problems; called from the kernel, each QP from a cold start: the answers do not depend
on the previous steps), ``"proxsuite"``, ``"osqp"``: each level keeps its own engine workspace
across control steps (warm start), re-created only when its number of free directions
changes. ``"qpsolvers:<solver>"`` lets any QP solver installed for :mod:`qpsolvers` serve the
levels (:mod:`wholebody.solvers.qpsolvers_engine`; no workspace is kept between calls).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from wholebody.errors import SolverError
from wholebody.kernels import control, hqp_state
from wholebody.kernels import daqp as dk
from wholebody.robot import RobotState
from wholebody.solvers import compiled_hqp
from wholebody.solvers.base import Setting, Solver
from wholebody.solvers.level_report import LevelReport
from wholebody.solvers.plan import Arena, Plan, ProblemArena
from wholebody.solvers.qp import QPEngine, make_engine
from wholebody.solvers.result import SolverResult
from wholebody.solvers.stack import Stack, StackProblem

__all__ = ["STALL_DAMPING", "HierarchicalQPSolver", "LevelReport"]

STALL_DAMPING = 0.1
"""The default ``mu`` of :attr:`HierarchicalQPSolver.stall_damping`."""


def _positive(value: float) -> bool:
    return value > 0


class HierarchicalQPSolver(Solver):
    """Strict lexicographic priorities with hard bounds at every level (see module docstring).

    Parameters
    ----------
    engine
        QP engine by name: ``"daqp"`` (default), ``"proxsuite"``, ``"osqp"``, or
        ``"qpsolvers:<solver>"`` for any solver :mod:`qpsolvers` has installed.
    tolerance
        A task is not met when its weighted residual exceeds ``tolerance * (1 + ||v||)``, and
        limited by the box when the box raised its residual by more than that; also the
        threshold for an inequality row counted as violated.
    rank_tolerance
        Singular values below ``rank_tolerance * sigma_max`` of a level count as zero.
    regularization
        Relative Tikhonov term ``d = regularization * sigma_max^2`` of the level QPs (its
        bias is polished away).
    bound_relaxation
        The box and inherited inequality rows are relaxed by this much at the levels below the
        first (round-off of the engine must not make a later level infeasible).
    warm_start
        Keep each level's engine workspace and warm-start it at the next control step
        (engines other than daqp).
    stall_damping
        ``mu`` (dimensionless, >= 0) of the damping of a level below the first that is left
        unmet ("Stalled levels: damped" above); 0 solves every level exactly.
    engine_settings
        Passed to the engine (see :func:`wholebody.solvers.qp.make_engine`; daqp: the fields
        of :data:`wholebody.kernels.daqp.SETTING_NAMES`).
    """

    name = "hqp"

    def __init__(
        self,
        engine: str = "daqp",
        *,
        tolerance: float = 1e-6,
        rank_tolerance: float = 1e-9,
        regularization: float = 1e-9,
        bound_relaxation: float = 1e-9,
        warm_start: bool = True,
        stall_damping: float = STALL_DAMPING,
        engine_settings: dict[str, Any] | None = None,
    ) -> None:
        self._par = np.zeros(hqp_state.PAR_WIDTH)
        self.engine_name = str(engine).lower()
        self.engine_settings = dict(engine_settings or {})
        self.warm_start = bool(warm_start)
        make_engine(self.engine_name, warm_start=self.warm_start, **self.engine_settings)
        self.in_kernel = self.engine_name == "daqp"
        """Whether the QPs are solved inside the kernel (daqp), not in Python."""
        self._daqp_settings = self._settings() if self.in_kernel else np.zeros(0)
        self.tolerance = tolerance
        self.rank_tolerance = rank_tolerance
        self.regularization = regularization
        self.bound_relaxation = bound_relaxation
        self.proximal_steps = 3
        self.active_tolerance = 1e-7
        self.stall_damping = stall_damping
        self._engines: list[QPEngine] = []
        self.qp_time = 0.0
        """Wall time (s) of the last solve (the stack's evaluation included: one kernel call
        with daqp)."""
        self._workspace: compiled_hqp.Workspace | None = None
        self._levels: list[LevelReport] | None = []

    def _settings(self) -> np.ndarray:
        """daqp's settings: a primal tolerance far below its default 1e-6 (the cascade
        inherits the box into the next level, where a 1e-6 violation would show), at most
        2000 iterations, then the user's ``engine_settings``."""
        values = {"primal_tol": 1e-9, "iter_limit": 2000, **self.engine_settings}
        return dk.settings(**values)

    @property
    def levels(self) -> list[LevelReport]:
        """Per-level report of the last solve."""
        if self._levels is None:
            ws = self._workspace
            self._levels = compiled_hqp.reports(ws.arena, ws)  # type: ignore[union-attr]
        return self._levels

    def __repr__(self) -> str:
        return f"HierarchicalQPSolver(engine={self.engine_name!r})"

    def reset(self) -> None:
        """Drop the engine workspaces (the next solve starts cold)."""
        self._engines.clear()

    def engine(self, k: int) -> QPEngine:
        """The Python engine workspace of level ``k`` (the last one, ``k`` = the number of
        levels, serves the final tie-break)."""
        while len(self._engines) <= k:
            self._engines.append(
                make_engine(self.engine_name, warm_start=self.warm_start, **self.engine_settings)
            )
        return self._engines[k]

    tolerance = Setting(hqp_state.P_TOL, valid=_positive, rule="> 0")
    rank_tolerance = Setting(hqp_state.P_RANK, valid=_positive, rule="> 0")
    regularization = Setting(hqp_state.P_REG, valid=_positive, rule="> 0")
    bound_relaxation = Setting(hqp_state.P_RELAX, valid=_positive, rule="> 0")
    active_tolerance = Setting(hqp_state.P_ACT, valid=_positive, rule="> 0")
    """Distance (scaled units) within which an entry of ``u`` counts as at its bound."""
    stall_damping = Setting(hqp_state.P_DAMP, valid=lambda v: v >= 0, rule=">= 0")
    """``mu`` of the damping of an unmet level (dimensionless, 0: off; module docstring,
    "Stalled levels")."""
    proximal_steps = Setting(hqp_state.P_PROX, int, valid=lambda v: v >= 0, rule=">= 0")
    """Most proximal-point QPs after a level's QP whose answer fails the level's optimality
    conditions."""

    def parameters(self) -> np.ndarray:
        """The settings as the kernels read them."""
        return self._par

    def workspace(self, arena: Arena) -> compiled_hqp.Workspace:
        """The cascade's workspace for ``arena`` (kept with the arena, made at its first
        solve), which then holds the last solve's report."""
        ws = arena.workspaces.get("hqp")
        if ws is None:
            ws = arena.workspaces["hqp"] = compiled_hqp.Workspace(arena)
        self._workspace = ws
        return ws

    # ------------------------------------------------------------------ public
    def solve(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        """Evaluate ``stack`` at ``state`` for a step of ``dt`` s and solve it.

        ``solve_time`` and :attr:`qp_time` cover the evaluation and the solve (one kernel
        call).
        """
        t0 = time.perf_counter()
        plan = stack.synced_plan(state, dt)
        buffers = plan.step_buffers()
        buffers.batch.Q[0] = state.q
        self.run(plan, buffers.pinocchio(), buffers.batch, 1, 0)
        plan.evaluated = state.stamp
        result = self.result(plan, 0.0)
        self.qp_time = result.solve_time = time.perf_counter() - t0
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
        """Whole steps on the synced ``plan``: one kernel call with daqp
        (:func:`wholebody.kernels.control.hqp_run`), else the stages with the engine's QPs
        between them (one state, one step; :mod:`wholebody.solvers.compiled_hqp`)."""
        ws = self.workspace(plan)
        compiled_hqp.run_steps(self, plan, ws, kinematics, batch, steps, what)

    def kernel_run(
        self,
        arena: control.Arena,
        kinematics: control.Kinematics,
        batch: control.Batch,
        steps: int,
        what: int,
        workspace: control.Arena | None,
    ) -> None:
        """:func:`wholebody.kernels.control.hqp_run` on an arena and the cascade's workspace
        (a plan's, or copies of them: a thread's share of a batch); daqp only."""
        if not self.in_kernel:
            raise SolverError(
                f"HierarchicalQPSolver({self.engine_name!r}): a batch or several steps in "
                "one call need the engine 'daqp' (the QPs are then solved inside the kernel)"
            )
        super().kernel_run(arena, kinematics, batch, steps, what, workspace)

    def stepper(
        self, plan: Plan, kinematics: control.Kinematics, batch: control.Batch, what: int
    ) -> Callable[[], None]:
        """The kernel call of one step with its arguments bound (daqp; another engine's step
        is the cascade's stages with its QPs in between: :meth:`run`)."""
        if not self.in_kernel:
            return lambda: self.run(plan, kinematics, batch, 1, what)
        return super().stepper(plan, kinematics, batch, what)

    def _step_workspace(self, plan: Plan) -> control.Arena:
        return self.workspace(plan).record

    def _kernel_call(
        self,
        arena: control.Arena,
        workspace: control.Arena | None,
        kinematics: control.Kinematics,
        batch: control.Batch,
        steps: int,
        what: int,
    ) -> tuple[Any, ...]:
        """:func:`wholebody.kernels.control.hqp_run`'s call."""
        return (
            "hqp",
            "the hierarchical QP kernels",
            control.hqp_run,
            arena,
            workspace,
            kinematics,
            batch,
            self._par,
            self._daqp_settings,
            steps,
            what,
        )

    def solve_problem(self, problem: StackProblem) -> SolverResult:
        """Solve an evaluated stack (rows in scaled coordinates)."""
        return self._solve_arena(ProblemArena(problem))

    def _solve_arena(self, arena: Arena) -> SolverResult:
        """The cascade on an evaluated arena."""
        t0 = time.perf_counter()
        compiled_hqp.run(self, arena, self.workspace(arena))
        result = self.result(arena, 0.0)
        self.qp_time = result.solve_time = time.perf_counter() - t0
        return result

    def result(self, arena: Arena, solve_time: float, stack: Stack | None = None) -> SolverResult:
        """The last cascade's outcome in ``arena`` as a :class:`SolverResult` (``stack``:
        unused, for the same call as the projection's)."""
        self._levels = None
        result = compiled_hqp.result(self, arena, self.workspace(arena))
        result.solve_time = solve_time
        return result
