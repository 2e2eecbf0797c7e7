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
Level by level, in the null space of the levels above (:mod:`wholebody.solvers.cascade`):
each level's unconstrained least-squares candidate, exact, by a complete orthogonal
decomposition (:mod:`wholebody.solvers.linalg`; rank-deficient levels, such as two hands plus
the closed chain between them, solve without error); where the candidate leaves the box or
an inequality row, one QP for that level (:mod:`wholebody.solvers.level_qp`), made exact by
a polish on the active face and proximal steps; at the end the exact minimum-norm point. With
no bound active this is the recursive pseudo-inverse, so it equals the projection backend's
``J+ v + (I - J+ J) u0``. The compiled kernels (:mod:`wholebody.kernels.hqp`, the default,
driven by :mod:`wholebody.solvers.compiled_hqp`) run the same cascade; ``compiled=False``
runs the Python reference they are tested against.

``method="native"`` (daqp only, opt-in) hands the rest of the stack, from the first level
whose candidate leaves the box, to one call of daqp's own hierarchical mode
(:mod:`wholebody.solvers.native`). Its answer is checked at that level only: the cascade,
checked at every level, is the default.

**Tolerance of the priorities.** A level never sees the levels below it (they are solved
after it, in the null space of its rows or, natively, with its slacks fixed), so a lower level
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
(:attr:`LevelReport.limited`: computed at every QP level by the cascade; by the native method
for the level where the box first bites and for inequality rows); FAILED after an engine
failure or non-finite rows (the level is skipped, named, and the rest is solved);
BOUNDS_ACTIVE when some entry of ``u`` sits on the box. The projection backend gives the status
the same meaning (:class:`~wholebody.solvers.SolverStatus`).

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
convex problems), ``"proxsuite"``, ``"osqp"``: each level keeps its own engine workspace
across control steps (warm start), re-created only when its number of free directions
changes; the native method keeps one daqp workspace for the whole stack.
``"qpsolvers:<solver>"`` lets any QP solver installed for :mod:`qpsolvers` serve the levels
(:mod:`wholebody.solvers.qpsolvers_engine`; no workspace is kept between calls).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from wholebody._numeric import ones
from wholebody.errors import DimensionError, SolverError
from wholebody.kernels import hqp as hqp_kernel
from wholebody.kernels.evaluate import evaluate
from wholebody.robot import RobotState
from wholebody.solvers import compiled_hqp
from wholebody.solvers.base import Solver
from wholebody.solvers.cascade import Cascade
from wholebody.solvers.level_report import LevelReport
from wholebody.solvers.native import NativeHierarchy
from wholebody.solvers.optimality import Bounds as Bounds  # (its former home: a re-export)
from wholebody.solvers.plan import Arena, ProblemArena, first_call
from wholebody.solvers.qp import QPEngine, QPStatus, make_engine
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import Stack, StackProblem

__all__ = ["HierarchicalQPSolver", "LevelReport"]


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
        Relative Tikhonov term ``d = regularization * sigma_max^2`` of the cascade's level QPs
        (its bias is polished away; see :mod:`wholebody.solvers.level_qp`).
    bound_relaxation
        The box and inherited inequality rows are relaxed by this much at the levels below the
        first (round-off of the engine must not make a later level infeasible).
    warm_start
        Keep each level's engine workspace and warm-start it at the next control step.
    engine_settings
        Passed to the engine (see :func:`wholebody.solvers.qp.make_engine`).
    method
        ``"cascade"``: the null-space cascade with one QP per level that needs one (any
        engine). ``"native"`` (daqp only): the same exact unconstrained candidates level by
        level, and at the first level whose candidate leaves the box, **one** call of daqp's
        own hierarchical mode for the whole stack (:mod:`wholebody.solvers.native`); if daqp
        fails, the cascade. The default is the cascade, because native's answer is not
        checked below the level it starts at (``"auto"`` is the default too).
    rho_soft
        daqp's soft-constraint weight in native mode (uniform on every row, so that each level
        minimises its true least squares): a level's optimum is exact up to about
        ``rho_soft |x|^2`` in its objective.
    compiled
        Run the cascade's arithmetic in the compiled kernels (:mod:`wholebody.kernels.hqp`,
        the default), or, with False, in Python (:mod:`wholebody.solvers.cascade`), the
        reference the kernels are tested against (same decisions, to rounding). The native
        method always runs in Python.
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
        engine_settings: dict[str, Any] | None = None,
        method: str = "cascade",
        rho_soft: float = 1e-7,
        compiled: bool = True,
    ) -> None:
        for label, value in (("tolerance", tolerance), ("rank_tolerance", rank_tolerance),
                             ("regularization", regularization),
                             ("bound_relaxation", bound_relaxation),
                             ("rho_soft", rho_soft)):  # fmt: skip
            if not (np.isfinite(value) and value > 0):
                raise SolverError(f"HierarchicalQPSolver: {label} must be finite and > 0, "
                                  f"got {value!r}")  # fmt: skip
        self.engine_name = str(engine).lower()
        self.engine_settings = dict(engine_settings or {})
        self.warm_start = bool(warm_start)
        make_engine(self.engine_name, warm_start=self.warm_start, **self.engine_settings)
        method = str(method).lower()
        if method == "auto":  # the default, by its former name
            method = "cascade"
        if method not in ("cascade", "native") or (method == "native"
                                                    and self.engine_name != "daqp"):  # fmt: skip
            raise SolverError(
                "HierarchicalQPSolver: method must be 'cascade', or 'native' with engine "
                f"'daqp'; got {method!r} with {self.engine_name!r}"
            )
        self.method = method
        self.rho_soft = float(rho_soft)
        self._native = NativeHierarchy()
        self.tolerance = float(tolerance)
        self.rank_tolerance = float(rank_tolerance)
        self.regularization = float(regularization)
        self.bound_relaxation = float(bound_relaxation)
        self.proximal_steps = 3
        """Most proximal-point QPs after a level's QP whose answer fails the level's
        optimality conditions (see :mod:`wholebody.solvers.level_qp`)."""
        self.active_tolerance = 1e-7
        """Distance (scaled units) within which an entry of ``u`` counts as at its bound."""
        self._engines: list[QPEngine] = []
        self.levels = []
        self.qp_time = 0.0
        """Wall time (s) of the last solve without the stack evaluation."""
        self.compiled = bool(compiled)
        self._par = np.zeros(hqp_kernel.PAR_WIDTH)
        self._workspace: compiled_hqp.Workspace | None = None
        self._tie_status = QPStatus.SOLVED

    @property
    def levels(self) -> list[LevelReport]:
        """Per-level report of the last solve."""
        if self._pending is not None:
            self._levels = compiled_hqp.reports(*self._pending, LevelReport)
            self._pending = None
        return self._levels

    @levels.setter
    def levels(self, value: list[LevelReport]) -> None:
        self._levels, self._pending = value, None

    def __repr__(self) -> str:
        return f"HierarchicalQPSolver(engine={self.engine_name!r}, method={self.method!r})"

    def reset(self) -> None:
        """Drop the engine workspaces (the next solve starts cold)."""
        self._engines.clear()
        self._native.reset()

    def _engine(self, k: int) -> QPEngine:
        """The engine workspace of level ``k`` (the last one, ``k`` = the number of levels,
        serves the final tie-break)."""
        while len(self._engines) <= k:
            self._engines.append(make_engine(self.engine_name, warm_start=self.warm_start,
                                             **self.engine_settings))  # fmt: skip
        return self._engines[k]

    # ------------------------------------------------------------------ public
    def solve(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        """Evaluate ``stack`` at ``state`` for a step of ``dt`` s and solve it.

        ``solve_time`` covers the evaluation and the solve; :attr:`qp_time` the solve only.
        """
        t0 = time.perf_counter()
        if self.compiled and self.method == "cascade":
            if not dt > 0:
                raise DimensionError(f"control step dt must be > 0 s, got {dt}")
            plan = stack.plan()
            plan.sync(state, dt)
            if plan.stale:  # an arm energy's stiffness was replaced: lay the stack out anew
                plan = stack.plan()
                plan.sync(state, dt)
            first_call("evaluate", "the control kernels", evaluate, *plan.kernel_args(state))
            plan.written(state)
            result = self._solve_arena(plan)
        else:
            problem = stack.evaluate(state, dt, compiled=self.compiled)
            result = self.solve_problem(problem)
        result.solve_time = time.perf_counter() - t0
        return result

    def solve_problem(self, problem: StackProblem) -> SolverResult:
        """Solve an evaluated stack (rows in scaled coordinates): with the kernels, or with
        ``compiled=False`` (and with the native method) in Python, the reference."""
        if self.compiled and self.method == "cascade":
            return self._solve_arena(ProblemArena(problem))
        return self._solve_reference(problem)

    def _solve_arena(self, arena: Arena) -> SolverResult:
        """The compiled cascade on an evaluated arena (:mod:`.compiled_hqp`)."""
        t0 = time.perf_counter()
        ws = self._workspace
        if ws is None or ws.arena is not arena:
            ws = self._workspace = compiled_hqp.Workspace(arena)
        self._par[:] = (self.tolerance, self.rank_tolerance, self.regularization,
                        self.bound_relaxation, self.active_tolerance,
                        self.proximal_steps)  # fmt: skip
        compiled_hqp.run(self, arena, ws)
        self._pending = (arena, ws)
        result = compiled_hqp.result(self, arena, ws, 0.0)
        self.qp_time = result.solve_time = time.perf_counter() - t0
        return result

    def _solve_reference(self, problem: StackProblem) -> SolverResult:
        """The Python implementation (:class:`~wholebody.solvers.cascade.Cascade`), the
        reference of the kernels."""
        t0 = time.perf_counter()
        run = Cascade(self, problem)
        self.levels = run.reports
        x, clip = run.run()
        result = self._result(problem, x, run, clip)
        self.qp_time = result.solve_time = time.perf_counter() - t0
        return result

    # ------------------------------------------------------------------ the result
    def _result(self, problem: StackProblem, x: np.ndarray, run: Cascade,
                clip: float) -> SolverResult:  # fmt: skip
        """The reference's answer ``x`` (scaled coordinates) as a :class:`SolverResult`."""
        reports = run.reports
        failed = [k for k, rep in enumerate(reports) if rep.failed]
        level_res, task_res, infeasible = problem.residuals(x, self.tolerance, failed)
        for k, lev in enumerate(problem.levels):
            report = reports[k]
            report.residual = float(level_res[k])
            if report.failed:  # a skipped level: all its tasks, inequalities included
                infeasible += [(lev.name, t) for t in lev.inequality_rows
                               if t not in report.limited]  # fmt: skip
            if report.limited:
                infeasible += [(lev.name, t) for t in report.limited if t in lev.inequality_rows]
        act = self.active_tolerance
        active = ((x <= problem.lower + act) | (x >= problem.upper - act)).nonzero()[0]
        top = problem.levels[0].name if problem.levels else ""
        if run.failures:
            status = SolverStatus.FAILED
        elif any([rep.limited for rep in reports]) or top in [lv for lv, _ in infeasible]:
            status = SolverStatus.INFEASIBLE
        elif active.size:
            status = SolverStatus.BOUNDS_ACTIVE
        else:
            status = SolverStatus.OK
        return SolverResult(
            u=problem.to_u(x),
            status=status,
            level_residuals=level_res,
            task_residuals=task_res,
            active_bounds=active,
            scale=ones(len(problem.levels)),
            infeasible=infeasible,
            message=self._message(run, infeasible, clip),
        )

    def _message(self, run: Cascade, infeasible: list[tuple[str, str]], clip: float) -> str:
        """The result's message: QP iterations per level, notes, failures, infeasible tasks
        and a clip to the box beyond the relaxation."""
        if run.native_from is not None:
            first = run.reports[run.native_from]
            msg = [f"daqp hierarchy from {first.name}: {first.iterations} it"]
        else:
            qps = [f"{rep.name}: {rep.iterations} it" for rep in run.reports if rep.qp]
            msg = [f"{self.engine_name}: " + ("; ".join(qps) if qps else "no QP needed")]
        msg += run.notes + run.failures
        if infeasible:
            msg.append("infeasible: " + ", ".join(f"{lv}/{t}" for lv, t in infeasible))
        if clip > 10 * self.bound_relaxation:
            msg.append(f"clipped u by {clip:.2e} (scaled units) to the box")
        return "; ".join(msg)
