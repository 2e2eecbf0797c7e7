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
**Unconstrained candidates, level by level (always).** The solver keeps a point ``x`` of
``F_{k-1}`` and an orthonormal basis ``Z`` of the null space of the rows fixed above
(``Z = I`` at the first level) and parametrises ``x + Z y``. At level k, with ``M = A_k Z``
and ``c = b_k - A_k x``, a complete orthogonal decomposition of ``M`` (QR with column
pivoting; diagonal entries below ``rank_tolerance * |R_00|`` count as zero, which is what makes
rank-deficient levels, such as two hands plus the closed chain between them or a duplicated
task, solve without error) gives the minimum-norm least-squares step ``y = M^+ c`` plus, in the
level's own null space ``Q_2``, the step to the minimum-norm point ``-Q_2 Q_2^T Z^T x``. If
``x + Z y`` lies in the box and satisfies the inherited and the level's inequality rows, it is
the level's optimum: no QP. With no bound active this is the recursive pseudo-inverse, so it
equals the projection backend's ``J+ v + (I - J+ J) u0``. Then ``Z <- Z Q_2``.

**At the first level whose candidate leaves the box**, one of two methods (``method=``):

``"cascade"`` (the default) is described below.

``"native"`` (daqp only, opt-in)
    One call of daqp's own hierarchical mode for the whole stack: the box as the first level,
    then each level's equality rows (``b <= A x <= b``) and inequality rows, soft, with
    break points between levels and ``H = I`` (the minimum-norm tie-break). daqp solves the
    levels in turn, fixing each level's slacks before the next. Its soft weights are set
    **uniform** (``rho_soft``, 1e-7) on every row: with its defaults daqp minimises a
    row-normalised residual (measured: 0.5 instead of the least-squares 0.0099 on a
    two-row example), not the level's least squares. Each level's optimum is then exact up to
    about ``rho_soft |x|^2`` in its objective (KKT residuals 1e-11 to 1e-8 on the tests'
    problems). If daqp fails, the cascade below solves the step. Where the box costs the level
    daqp starts from something, daqp's answer is checked against that level's optimality
    conditions and, where those do not certify it, against the level's own QP (one cascade
    QP); the cascade takes over if daqp missed it: the soft weights can let a
    lower level pull a higher one off its optimum (2 in 5000 random stacks, fuzzed against an
    exact reference). The levels below that one are not checked, and daqp misses a lower
    level's optimum often enough to make this the exception, not the default: on a robot
    stack with inequality tasks at lower levels (hand > table half-space and other hand >
    half-space > posture, joint limits, dt = 0.05 s) its posture residual was worse than the
    cascade's by more than 0.1 % in 8 to 16 of 100 random states (15.3 against the optimal
    12.46 at worst), and its soft weights let a lower level pull a top level with task weight
    1e-6 or a metric of 1e6 off a reachable target (residual 5.8e-2 against 3e-9). Where no
    bound is active, as in the benchmarks, both methods run the same closed-form levels. What
    opting in buys, on the coordinated carry scenario (same answers there): a whole control
    step's median 1.30-1.42 ms against 1.55-1.57 ms, p90 1.9 against 4.0 ms.
``"cascade"`` (any engine, default)
    One QP per level that needs one, in the free coordinates ``(y, s)``::

        min  1/2 ||M y - c||^2 + d/2 ||y||^2 + 1/2 ||s||^2
        s.t. l - x <= Z y <= h - x                     (box, relaxed by bound_relaxation)
             inherited inequality rows of the levels above
             lo_k - C_k x <= C_k Z y - s <= hi_k - C_k x

    ``d = regularization * sigma_max^2`` (1e-9) only makes the Hessian positive definite for
    every engine (a level with free directions has a singular one); its bias is removed by
    re-solving the level's least squares exactly on the face of the constraints active at
    the QP's answer (kept if it stays feasible; the level's inequality rows at or beyond a
    bound join the least squares, kept if the level's objective is lower), and where the
    answer still fails the level's optimality conditions and its residual is above the
    tolerance, by up to ``proximal_steps`` (3) proximal-point QPs,
    the Tikhonov term centred on the last answer, which walk off a face the term alone
    would hold the answer on (a 2.7e-5 residual found in fuzzing). Constraints the
    level's own optimum presses on (positive multipliers of its least squares) are fixed for
    the levels below, which changes nothing in exact arithmetic (every optimum of a convex
    level shares them) but removes the freedom that a level found only to round-off would
    leave to the next one (on this robot a 1e-10 slack at one level moved the next level by
    up to 1e-3). The relaxed box and the inherited rows' bounds are widened to contain ``x``,
    so ``y = 0`` is always feasible: a level QP is never infeasible; an engine failure leaves
    that level unsolved (status FAILED) and keeps the higher levels' answer. At the end, if
    any QP ran and freedom is left, the exact minimum-norm point of the last optimal set is
    one more QP with ``H = I``.

When ``Z`` has no columns left the remaining levels cannot move ``x`` (their residuals are
still reported). Finally ``x`` is clipped to the exact box (it can only be outside by the
relaxation and engine tolerances, about 1e-9; ``message`` says so if the clip moved it by
more than ten times ``bound_relaxation``), and ``u = D x``.

**Tolerance of the priorities.** A level never sees the levels below it (they are solved
after it, in the null space of its rows or, natively, with its slacks fixed), so a lower level
changes a higher level's residual only through the directions dropped by the rank threshold,
the engine's primal tolerance and the final clip: below 1e-8 (weighted, scaled units) in the
tests, which check ``1e-8 (1 + residual)``. A level's own optimum is exact to the KKT
tolerance above (the tests certify 1e-6 relative, with bounds active, on synthetic and robot
stacks). Beware that the lexicographic problem itself can be ill-conditioned where a level's
optimal set is a thin sliver of the box: there, 1e-10 in one level's residual can move the
next level's answer by 1e-3; both methods return a point that satisfies the optimality
conditions of every level.

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
``"daqp"`` (default), ``"proxsuite"``, ``"osqp"``: each level keeps its own engine workspace
across control steps (warm start), re-created only when its number of free directions
changes; the native method keeps one daqp workspace for the whole stack. Measured on this
machine (2 cores shared with other jobs; median / p90), on the problems of
``benchmarks/control_step.py``'s 3-level stack (hands + closed chain; arm energy; posture and
joint-limit avoidance; 23 variables, 18 + 23 + 46 rows, the wheels' cheap metric), 1200
closed-loop steps and 600 random states:

=================  =================  ==============  ================================
engine             one level's QP     whole solve     failures, accuracy
=================  =================  ==============  ================================
daqp, native       (one call: 50-80)  184 / 255 us    none; KKT <= 1e-8
daqp, cascade      18 / 21 us         209 / 403 us    none; KKT <= 2e-8
proxsuite          130 / 200-300 us   316 / 852 us    0.3-0.7 % of QPs unsolved, 4.5 %
                                                      of random states FAILED (before the
                                                      fixes below); answers off daqp's by
                                                      up to 0.2
osqp               88 / 130-145 us    307 / 654 us    none reported, but answers off by
                                                      up to 0.3-1.6 (eps 1e-7, polished)
=================  =================  ==============  ================================

Since then (2026-12-03), on the paper's stack: no FAILED step in 30 000 (daqp) and
15 000 (proxsuite) closed-loop steps from the neutral posture to far targets, and none in 600
random states (answers off daqp's: proxsuite up to 1.7, p99 2e-5; osqp up to 4e-4). The
fixes: QP rows that the free directions move only by round-off are left unbounded (two of
them on joints resting on their bounds pinned the QP's only direction to 0: proxsuite called
it infeasible on 15.6 % of those steps), and proxsuite's infeasibility certificates get
tolerances of 1e-14 (at its default 1e-4 it declared feasible 1-variable QPs infeasible).

About half of the steps need a QP at all (the wheels' metric makes the objective step large);
the rest are the exact candidates. Native and cascade daqp have the same median; the
native method has the shorter tail (p90 286 against 425 us on the 3-level stack, 187 against
332 us on the paper's stack, interleaved), but the cascade is the default because its answers
are checked at every level (see ``"native"`` above). The stack evaluation (kinematics,
tasks, objectives) takes 220-310 us of the step besides.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import lapack as _lapack
from scipy.optimize import lsq_linear

from wholebody._numeric import NORMAL_KAPPA, normal_solve
from wholebody._numeric import count_nonzero as _count_nonzero
from wholebody.errors import DimensionError, SolverError
from wholebody.kernels import hqp as hqp_kernel
from wholebody.kernels.evaluate import evaluate
from wholebody.robot import RobotState
from wholebody.solvers import compiled_hqp
from wholebody.solvers.base import Solver
from wholebody.solvers.plan import Arena, ProblemArena, first_call
from wholebody.solvers.qp import QPEngine, QPStatus, make_engine
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import LevelProblem, Stack, StackProblem

__all__ = ["HierarchicalQPSolver", "LevelReport"]


@dataclass(slots=True)
class LevelReport:
    """What happened at one level of the last solve (for logs, tests and benchmarks).

    Attributes
    ----------
    name
        The level's name.
    free
        Directions left free by the higher levels when this level was solved (``Z``'s columns).
    rank
        Rank of the level's equality rows in those directions.
    qp
        Whether a QP was solved (False: the unconstrained candidate was feasible, or no freedom).
    engine_status
        The engine's status when a QP was solved.
    iterations
        Engine iterations.
    retries
        QP solves repeated with 100 and 10000 times the Tikhonov term after an engine failure
        (a nearly singular level with degenerate bounds).
    residual
        Weighted residual ``||A x - b||`` of the level's equality rows at the final answer.
    limited
        Names of the tasks (and inequality tasks) that the hard constraints kept from their
        best residual given the higher levels: the box cost this level something.
    failed
        The level was skipped (engine failure or non-finite rows).
    """

    name: str
    free: int = 0
    rank: int = 0
    qp: bool = False
    engine_status: QPStatus | None = None
    iterations: int = 0
    residual: float = 0.0
    retries: int = 0
    limited: list[str] = field(default_factory=list)
    failed: bool = False


class HierarchicalQPSolver(Solver):
    """Strict lexicographic priorities with hard bounds at every level (see module docstring).

    Parameters
    ----------
    engine
        QP engine by name: ``"daqp"`` (default), ``"proxsuite"`` or ``"osqp"``.
    tolerance
        A task is not met when its weighted residual exceeds ``tolerance * (1 + ||v||)``, and
        limited by the box when the box raised its residual by more than that; also the
        threshold for an inequality row counted as violated.
    rank_tolerance
        Singular values below ``rank_tolerance * sigma_max`` of a level count as zero.
    regularization
        Relative Tikhonov term ``d = regularization * sigma_max^2`` of the cascade's level QPs
        (its bias is polished away; see the module docstring).
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
        own hierarchical mode for the whole stack (see the module docstring); if daqp fails,
        the cascade. The default is the cascade: native's answer is not checked below the
        level it starts at, and on a robot stack with inequality tasks at lower levels it
        missed a lower level's optimum in 8 to 16 % of the states where it ran (``"auto"``
        is the default too).
    rho_soft
        daqp's soft-constraint weight in native mode (uniform on every row, so that each level
        minimises its true least squares): a level's optimum is exact up to about
        ``rho_soft |x|^2`` in its objective.
    compiled
        Run the cascade's arithmetic in the compiled kernels (:mod:`wholebody.kernels.hqp`,
        the default), or, with False, in this module's Python, the reference the kernels are
        tested against (same decisions, to rounding). The native method always runs here.
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
        self._native_key: tuple | None = None
        self._native_model: Any = None
        self.tolerance = float(tolerance)
        self.rank_tolerance = float(rank_tolerance)
        self.regularization = float(regularization)
        self.bound_relaxation = float(bound_relaxation)
        self.proximal_steps = 3
        """Most proximal-point QPs after a level's QP whose answer fails the level's
        optimality conditions (see :meth:`_level_qp`)."""
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
        self._native_key = self._native_model = None

    def _engine(self, k: int) -> QPEngine:
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
        """The Python implementation, the reference of the kernels."""
        t0 = time.perf_counter()
        x, failures, clip = self._cascade(problem)
        u = problem.to_u(x)
        result = self._result(problem, x, u, failures, clip)
        self.qp_time = result.solve_time = time.perf_counter() - t0
        return result

    # ------------------------------------------------------------------ the cascade
    def _cascade(self, problem: StackProblem) -> tuple[np.ndarray, list[str], float]:
        lb, ub = problem.lower, problem.upper
        n = lb.shape[0]
        bt = self.bound_relaxation
        failures: list[str] = []
        self.levels = [LevelReport(lev.name) for lev in problem.levels]
        self._notes: list[str] = []
        self._native_from: int | None = None
        if not _all(lb <= ub):  # NaN compares false; Stack.evaluate never crosses the box
            failures.append("the box is empty or not a number (NaN bounds): u = 0")
            return np.zeros(n), failures, 0.0
        x = np.minimum(np.maximum(0.0, lb), ub)  # the minimum-norm point of the box
        lo = lb - bt
        hi = ub + bt
        Z: np.ndarray | None = None  # None: the identity (nothing fixed yet)
        r = n
        inherited: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        native_tried = False
        any_qp = False
        exact = True  # x is in the exact box (the unconstrained candidates' case)
        last = len(problem.levels) - 1
        for k, lev in enumerate(problem.levels):
            report = self.levels[k]
            report.free = r
            if r == 0:  # nothing left to move: report the inequality rows x leaves violated
                if not _finite_level(lev):  # (and NaN or inf rows, as at any level)
                    self._skip_nonfinite(lev, report, failures)
                elif lev.C.shape[0]:
                    report.limited = _violated(lev, lev.C.dot(x), self.tolerance)[1]
                continue
            A, b, C = lev.A, lev.b, lev.C
            m, p = A.shape[0], C.shape[0]
            # Non-finite equality rows show in the step y (checked below, one product instead
            # of a pass over A and b); the inequality rows are checked here.
            if p and not _finite_level(lev):
                self._skip_nonfinite(lev, report, failures)
                continue
            t = x if Z is None else Z.T.dot(x)  # current point in the free coordinates
            null: np.ndarray | None = None  # the level's own null space in the free coordinates
            smax = 0.0
            rank = 0
            if m:
                # (x = 0, the usual start: c = b; c is only read)
                c = b - A.dot(x) if Z is not None or _count_nonzero(x) else b
                M = A if Z is None else A.dot(Z)
                sw = lev.identity_scale if lev.A.shape == (n, n) else 0.0
                if sw > 0:  # rows sw * I: M = sw Z has r singular values sw
                    rank, smax = r, sw
                    y = (c if Z is None else Z.T.dot(c)) / sw
                else:
                    try:
                        # rows below rank_tolerance |A| in the free directions are round-off
                        fa = A.ravel()
                        floor = (
                            self.rank_tolerance * math.sqrt(fa.dot(fa)) if Z is not None else 0.0
                        )
                        rank, y, null, smax = _cod(M, c, t, self.rank_tolerance, floor)
                    except (np.linalg.LinAlgError, ValueError) as exc:
                        if not _finite_level(lev):
                            self._skip_nonfinite(lev, report, failures)
                        else:
                            failures.append(f"{lev.name}: decomposition failed ({exc}); "
                                            "level skipped")  # fmt: skip
                            report.failed = True
                        continue
            else:
                c = M = None
                y = -t
            if m and (rank == 0 or not _finite(y)) and not _finite_level(lev):
                # (NaN or inf rows give a non-finite step, or no rank: a NaN pivot is no pivot)
                self._skip_nonfinite(lev, report, failures)
                continue
            if not _finite(y):  # finite rows, yet the decomposition overflowed
                failures.append(f"{lev.name}: decomposition failed (non-finite step); "
                                "level skipped")  # fmt: skip
                report.failed = True
                continue
            report.rank = rank
            xc = x + (y if Z is None else Z.dot(y))
            in_box = _all(xc >= lb) and _all(xc <= ub)  # (then no clip is needed at the end)
            if (
                (in_box or (_all(xc >= lo) and _all(xc <= hi)))
                and _inside_rows(xc, inherited)
                and (p == 0 or _rows_inside(C.dot(xc), lev.lower, lev.upper, self.tolerance))
            ):
                x, exact = xc, in_box
            elif m and rank == 0 and p == 0:
                # rows with nothing left to move (round-off in the free directions, or a task
                # the levels above fix): only the minimum-norm step left the box, and a QP of
                # rows this small is degenerate; the final tie-break makes that choice
                any_qp = True
            else:
                report.qp = any_qp = True
                if smax is None:  # certified full rank: |R_00| only now needed
                    smax = _pivot_norm(M)
                xq = None  # the level's own QP, where daqp's answer was checked against it
                if self.method == "native" and not native_tried:
                    native_tried = True
                    xn = None
                    if all(_finite_level(lv) for lv in problem.levels[k + 1 :]):
                        xn = self._native(problem, k)
                    if xn is not None:
                        if m:
                            report.limited = self._bound_limited(
                                lev, A.dot(xn) - b, A.dot(xc) - b, _on_box(xn, lb, ub)
                            )
                        if p:
                            report.limited += _violated(lev, C.dot(xn), self.tolerance)[1]
                        # Where the box cost this level something, daqp's answer is checked:
                        # by the level's optimality conditions, and where they do not certify
                        # it, against the level's QP alone, which is kept if daqp missed it.
                        # (daqp's soft-weighted levels can let a lower level pull a higher one
                        # off its optimum: 2 in 5000 random stacks, the top level 8 % worse.)
                        if report.limited and not (
                            p == 0 and _optimal(lev, xn, Z, (lo, hi, inherited),
                                                self.active_tolerance, self.rank_tolerance)
                        ):  # fmt: skip
                            own = LevelReport(lev.name, free=report.free, rank=report.rank)
                            xq = self._level_qp(k, lev, x, Z, M, c, smax, lo, hi, inherited, own)
                            if xq is not None and _worse(lev, xn, xq, self.tolerance):
                                for rep in self.levels[k + 1 :]:
                                    rep.qp, rep.engine_status, rep.iterations = False, None, 0
                                own.qp = True
                                self.levels[k] = report = own  # the level is the cascade's now
                                self._notes.append(
                                    f"daqp hierarchy missed the optimum of {lev.name}; solved "
                                    "by the cascade"
                                )
                                xn = None
                            else:
                                xq = None
                    if xn is not None:
                        self._native_from = k
                        for lv, rep in zip(problem.levels[k + 1 :], self.levels[k + 1 :],
                                           strict=True):  # fmt: skip
                            if lv.C.shape[0]:
                                rep.limited += _violated(lv, lv.C.dot(xn), self.tolerance)[1]
                        x = xn
                        r = 0  # solved to the end
                        break
                if xq is None:
                    xq = self._level_qp(k, lev, x, Z, M, c, smax, lo, hi, inherited, report)
                if xq is None:
                    report.failed = True
                    failures.append(f"{lev.name}: {report.engine_status.name.lower()} "
                                    f"({self.engine_name}); level left unsolved")  # fmt: skip
                    continue
                if m:
                    report.limited = self._bound_limited(
                        lev, A.dot(xq) - b, A.dot(xc) - b, _on_box(xq, lb, ub)
                    )
                x = xq
            # The level's optimal set: fix its rows (and the constraints the level's optimum
            # presses on), keep its inequality rows.
            Z_level = Z
            if rank:
                if null is None:  # the level used up every free direction
                    null = np.zeros((r, 0))
                Z = null if Z is None else Z.dot(null)
            if report.qp and m and (Z is None or Z.shape[1] > 0):
                # the Tikhonov term shifts the level's optimum by about d |y|: that much
                # gradient is not the level's own
                if smax is None:
                    smax = _pivot_norm(M)
                delta = self.regularization * (smax * smax if smax > 0 else 1.0)
                pins = self._strongly_active(lev, x, Z_level, lo, hi, inherited, delta)
                if pins is not None:
                    # (pins are rows of unit size: box rows, or inherited rows, scaled below)
                    floor = self.rank_tolerance * float(np.abs(pins).max())
                    Z = _null_space(pins.dot(Z) if Z is not None else pins, Z,
                                    self.rank_tolerance, floor)  # fmt: skip
            r = n if Z is None else Z.shape[1]
            if p:
                Cx = C.dot(x)
                viol, names = _violated(lev, Cx, self.tolerance)
                if report.qp:
                    report.limited += names
                glo = np.minimum(np.where(viol, Cx, lev.lower), Cx) - bt
                ghi = np.maximum(np.where(viol, Cx, lev.upper), Cx) + bt
                inherited.append((C.copy(), glo, ghi))
            if k != last or any_qp:  # else nothing reads lo and hi again
                np.minimum(lo, x, out=lo)
                np.maximum(hi, x, out=hi)
        if r and any_qp:
            x = self._tie_break(x, Z, lo, hi, inherited, failures)
        elif exact and not any_qp:
            return x, failures, 0.0
        xc = np.minimum(np.maximum(x, lb), ub)
        d = xc - x
        clip = float(np.maximum.reduce(np.abs(d))) if d.dot(d) != 0.0 else 0.0
        return xc, failures, clip

    def _level_qp(
        self,
        k: int,
        lev: LevelProblem,
        x: np.ndarray,
        Z: np.ndarray | None,
        M: np.ndarray | None,
        c: np.ndarray | None,
        smax: float,
        lo: np.ndarray,
        hi: np.ndarray,
        inherited: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        report: LevelReport,
    ) -> np.ndarray | None:
        """The level's QP in ``(y, s)``; returns the new x, or None when the engine failed.

        ``min 1/2 ||M y - c||^2 + d/2 ||y||^2 + 1/2 ||s||^2``: the Tikhonov term
        ``d = regularization * sigma_max^2`` makes the Hessian positive definite and, in the
        directions the level leaves free, keeps ``x`` where the levels above put it (the
        minimum-norm choice is made once, exactly, by :meth:`_tie_break`).
        """
        r = report.free
        p = lev.C.shape[0]
        nv = r + p
        d = self.regularization * (smax * smax if smax > 0 else 1.0)
        H = np.zeros((nv, nv))
        g = np.zeros(nv)
        if M is not None:
            H[:r, :r] = M.T.dot(M)
            g[:r] = -(M.T.dot(c))
        H[np.arange(r), np.arange(r)] += d
        if p:
            H[np.arange(r, nv), np.arange(r, nv)] = 1.0
        rows: list[np.ndarray] = []
        lows: list[np.ndarray] = []
        ups: list[np.ndarray] = []
        lb = ub = None
        if Z is None:
            lb = np.full(nv, -np.inf)
            ub = np.full(nv, np.inf)
            lb[:r] = lo - x
            ub[:r] = hi - x
        else:
            rows.append(_pad(Z, nv))
            lows.append(lo - x)
            ups.append(hi - x)
            _flat(Z, 1.0, lows[-1], ups[-1])
        for G, glo, ghi in inherited:
            rows.append(_pad(G if Z is None else G.dot(Z), nv))
            lows.append(glo.copy())
            ups.append(ghi.copy())
            _widened(G, x, rows[-1][:, :r], lows[-1], ups[-1])
        if p:
            Cz = lev.C if Z is None else lev.C.dot(Z)
            Cx = lev.C.dot(x)
            own = np.zeros((p, nv))
            own[:, :r] = Cz
            own[np.arange(p), r + np.arange(p)] = -1.0
            rows.append(own)
            lows.append(lev.lower - Cx)
            ups.append(lev.upper - Cx)
        if rows:
            Cm = np.vstack(rows)
            cl = np.concatenate(lows)
            cu = np.concatenate(ups)
        else:
            Cm = np.zeros((0, nv))
            cl = cu = np.zeros(0)
        engine = self._engine(k)
        diag = np.arange(r)
        for attempt in range(3):
            if attempt:  # ill-conditioned and degenerate: retry cold, 100x more Tikhonov
                engine.reset()
                H[diag, diag] += d * (100.0**attempt - 100.0 ** (attempt - 1))
                report.retries += 1
            sol = engine.solve(H, g, Cm, cl, cu, lb, ub)
            report.engine_status = sol.status
            report.iterations += sol.iterations
            if sol.status <= QPStatus.INACCURATE and np.all(np.isfinite(sol.x)):
                break
        else:
            return None
        y = sol.x[:r]
        if M is None:
            if p:  # only inequality rows: their slack is the level's least squares
                y = self._polish(x, y, Z, np.zeros((0, r)), np.zeros(0), lo, hi, inherited, lev)
            return x + (y if Z is None else Z.dot(y))
        y = self._polish(x, y, Z, M, c, lo, hi, inherited, lev if p else None)
        # The Tikhonov term d/2 |y|^2 can also hold the answer on a face the exact optimum is
        # not on (a long step bought with a 1e-5 residual): proximal-point steps, the term
        # centred on the last answer, walk to the level's exact optimum within the constraints.
        # Not needed where the answer already meets the level's optimality conditions (a level
        # that the bounds hold back: the common case).
        if p == 0 and _optimal(lev, x + (y if Z is None else Z.dot(y)), Z, (lo, hi, inherited),
                               self.active_tolerance, self.rank_tolerance):  # fmt: skip
            return x + (y if Z is None else Z.dot(y))
        g0 = g[:r].copy()
        tol = self.tolerance * (1.0 + math.sqrt(c.dot(c)))
        f = _level_objective(lev, x + (y if Z is None else Z.dot(y))) if p else 0.0
        res = c - M.dot(y)
        for _ in range(self.proximal_steps):
            if math.sqrt(res.dot(res)) <= tol:
                break
            g[:r] = g0 - d * y
            sol = engine.solve(H, g, Cm, cl, cu, lb, ub)
            report.iterations += sol.iterations
            if sol.status > QPStatus.INACCURATE or not np.all(np.isfinite(sol.x)):
                break
            yn = self._polish(x, sol.x[:r], Z, M, c, lo, hi, inherited, lev if p else None)
            rn = c - M.dot(yn)
            fn = _level_objective(lev, x + (yn if Z is None else Z.dot(yn))) if p else 0.0
            if p and fn > f:
                break
            better = math.sqrt(res.dot(res)) - math.sqrt(rn.dot(rn))
            if better <= 0.0:
                break
            y, res, f = yn, rn, fn
            if better <= 1e-3 * tol:
                break
        return x + (y if Z is None else Z.dot(y))

    def _polish(
        self,
        x: np.ndarray,
        y: np.ndarray,
        Z: np.ndarray | None,
        M: np.ndarray,
        c: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        inherited: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        lev: LevelProblem | None = None,
    ) -> np.ndarray:
        """Remove the Tikhonov bias: on the face of the constraints active at the QP's answer,
        the level's least squares is solved exactly (``y + W (M W)^+ (c - M y)``, ``W`` the
        directions that keep the active constraints still); kept if it stays feasible.

        With ``lev``, a level with inequality rows: the rows at or beyond a bound at the QP's
        answer join the least squares (their slack is ``C x - bound``), and the polished point
        is kept only if the level's objective (:func:`_level_objective`) is lower there.
        Without it the Tikhonov term trades slack for step length: a row met exactly at the
        optimum was left violated by 1e-5 and reported INFEASIBLE.

        The Tikhonov term can also move the QP's answer onto another face than the exact
        optimum's. Where only the box bounds the level (the first level with a QP), a residual
        still above the tolerance is checked against the exact bounded least squares (BVLS,
        ``scipy.optimize.lsq_linear``), which is taken if it fits better."""
        xq = x + (y if Z is None else Z.dot(y))
        if lev is not None:
            Cz = lev.C if Z is None else lev.C.dot(Z)
            Cx = lev.C.dot(x)
            v = Cx + Cz.dot(y)
            low = v <= lev.lower + 1e-8
            touch = low | (v >= lev.upper - 1e-8)
            if _any(touch):
                bound = np.where(low, lev.lower, lev.upper)[touch]
                M = np.vstack((M, Cz[touch]))
                c = np.concatenate((c, bound - Cx[touch]))
            yp = self._polish(x, y, Z, M, c, lo, hi, inherited)
            if yp is y:
                return y
            xp = x + (yp if Z is None else Z.dot(yp))
            return yp if _level_objective(lev, xp) < _level_objective(lev, xq) else y
        act = 1e-8
        on = (xq <= lo + act) | (xq >= hi - act)
        grows = []
        for G, glo, ghi in inherited:
            Gx = G.dot(xq)
            gon = (Gx <= glo + act) | (Gx >= ghi - act)
            if gon.any():
                grows.append(G[gon])
        res = c - M.dot(y)
        W: np.ndarray | None = None
        free: np.ndarray | None = None
        if Z is None and not grows:  # only bounds of x: keep those entries, move the others
            free = ~on
            MW = M[:, free]
        else:
            rows = list(grows)
            if on.any():
                rows.insert(0, np.eye(x.shape[0])[on])
            if rows:
                N = np.vstack(rows)
                W = _null_space(N if Z is None else N.dot(Z), None, self.rank_tolerance)
                MW = M.dot(W)
            else:
                MW = M
        if MW.shape[1] == 0:
            return y
        try:
            _, w, _, _ = _cod(MW, res, np.zeros(MW.shape[1]), self.rank_tolerance)
        except (np.linalg.LinAlgError, ValueError):
            return y
        yp = y.copy()
        if free is not None:
            yp[free] += w
        else:
            yp += w if W is None else W.dot(w)
        if not np.isfinite(yp).all():
            return y
        rp = c - M.dot(yp)
        if rp.dot(rp) > res.dot(res) or not _inside(x + (yp if Z is None else Z.dot(yp)), lo, hi,
                                                inherited):  # fmt: skip
            yp, rp = y, res
        if (
            free is not None
            and math.sqrt(rp.dot(rp)) > self.tolerance * (1.0 + math.sqrt(c.dot(c)))
            and not _box_optimal(M, c, yp, lo - x, hi - x, self.active_tolerance)
        ):
            fit = lsq_linear(
                M,
                c,
                bounds=(lo - x, hi - x),
                method="bvls",
                tol=1e-13,
                max_iter=20 * M.shape[1] + 20,
            )  # (scipy's default: n)
            yb = np.minimum(np.maximum(fit.x, lo - x), hi - x)
            rb = c - M.dot(yb)
            if (
                np.isfinite(yb).all()
                and rb.dot(rb) < rp.dot(rp)
                and _inside(x + yb, lo, hi, inherited)
            ):  # fmt: skip  (BVLS sees the box only)
                return yb
        return yp

    def _native(self, problem: StackProblem, first: int) -> np.ndarray | None:
        """The whole stack in one call of daqp's hierarchical mode (see the module docstring);
        None if daqp failed (the cascade then takes over from level ``first``)."""
        n = problem.lower.shape[0]
        key = (n, *((lev.A.shape[0], lev.C.shape[0]) for lev in problem.levels))
        if key != self._native_key:
            total = sum(a + c for a, c in key[1:])
            self._nA = np.zeros((total, n))
            self._nbl = np.empty(n + total)
            self._nbu = np.empty(n + total)
            self._nsense = np.zeros(n + total, dtype=np.int32)
            points, k = [n], n
            for a, c in key[1:]:
                if a + c:
                    k += a + c
                    points.append(k)
            self._nbp = np.array(points, dtype=np.int32)
            self._native_model = None
            self._native_key = key
        A, bl, bu = self._nA, self._nbl, self._nbu
        bl[:n] = problem.lower
        bu[:n] = problem.upper
        k = 0
        for lev in problem.levels:
            m, p = lev.A.shape[0], lev.C.shape[0]
            A[k : k + m] = lev.A
            bl[n + k : n + k + m] = lev.b
            bu[n + k : n + k + m] = lev.b
            k += m
            A[k : k + p] = lev.C
            bl[n + k : n + k + p] = lev.lower
            bu[n + k : n + k + p] = lev.upper
            k += p
        # daqp normalises rows: a zero row (a zero weight, a zero Jacobian row) becomes an
        # inactive dummy row; so do the rows of a level skipped for NaN or inf rows (the
        # cascade reports it), which would crash daqp
        norms = np.add.reduce(A * A, axis=1)
        zero = ~((norms >= 1e-24) & (norms < np.inf))
        zero |= np.isnan(bl[n:])
        zero |= np.isnan(bu[n:])
        if _any(zero):
            A[zero] = 0.0
            A[zero, 0] = 1.0
            bl[n:][zero] = -_DAQP_BIG
            bu[n:][zero] = _DAQP_BIG
        for bound in (bl, bu):  # clip to +-_DAQP_BIG (np.clip without its Python wrapper)
            np.maximum(bound, -_DAQP_BIG, out=bound)
            np.minimum(bound, _DAQP_BIG, out=bound)
        model = self._native_model
        try:
            if model is None:
                import daqp

                model = daqp.Model()
                model.settings = {"rho_soft": self.rho_soft, "primal_tol": 1e-9,
                                  "iter_limit": 2000, **self.engine_settings}  # fmt: skip
                self._nsense.fill(0)
                flag, _ = model.setup(np.eye(n), np.zeros(n), A, bu, bl, self._nsense,
                                      self._nbp)  # fmt: skip
                if flag < 0:
                    raise RuntimeError(f"setup exit flag {flag}")
                rho = np.full(bu.shape[0], self.rho_soft)
                model.soft_weights(rho_l=rho, rho_u=rho)
                self._native_model = model
            elif self.warm_start:
                model.update(A=A, bupper=bu, blower=bl)
            else:
                self._nsense.fill(0)
                model.update(A=A, bupper=bu, blower=bl, sense=self._nsense)
            x, _, flag, info = model.solve()
        except (RuntimeError, ValueError, TypeError) as exc:
            flag, x, info = -100, None, {"iterations": 0, "error": str(exc)}
        ok = flag in (1, 2) and x is not None and _finite(np.asarray(x, dtype=float))
        status = QPStatus.SOLVED if ok else QPStatus.FAILED
        for rep in self.levels[first:]:
            rep.qp, rep.engine_status = True, status
        self.levels[first].iterations = int(info.get("iterations", 0))
        if not ok:
            self._native_model = None
            self._notes.append(f"daqp hierarchy failed (exit flag {flag}); solved by the cascade")
            return None
        return np.array(x, dtype=float)

    def _tie_break(
        self,
        x: np.ndarray,
        Z: np.ndarray | None,
        lo: np.ndarray,
        hi: np.ndarray,
        inherited: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        failures: list[str],
    ) -> np.ndarray:
        """The minimum-norm point of the last optimal set ``(x + range Z) & box & inherited``.

        Needed only when a level QP ran (its own tie-break term is weighted by the small
        ``regularization`` and resolves the minimum norm only to about eps / regularization);
        here it is exact: ``min 1/2 ||x + Z y||^2``, a Hessian of I.
        """
        t = x if Z is None else Z.T.dot(x)
        xc = x - (t if Z is None else Z.dot(t))
        if _inside(xc, lo, hi, inherited):
            return xc
        r = t.shape[0]
        rows, lows, ups = [], [], []
        lb = ub = None
        if Z is None:
            lb, ub = lo - x, hi - x
        else:
            rows.append(Z)
            lows.append(lo - x)
            ups.append(hi - x)
            _flat(Z, 1.0, lows[-1], ups[-1])
        for G, glo, ghi in inherited:  # widened to contain x, as in the level QPs
            rows.append(G if Z is None else G.dot(Z))
            lows.append(glo.copy())
            ups.append(ghi.copy())
            _widened(G, x, rows[-1], lows[-1], ups[-1])
        Cm = np.vstack(rows) if rows else np.zeros((0, r))
        cl = np.concatenate(lows) if rows else np.zeros(0)
        cu = np.concatenate(ups) if rows else np.zeros(0)
        sol = self._engine(len(self.levels)).solve(np.eye(r), t, Cm, cl, cu, lb, ub)
        if sol.status > QPStatus.INACCURATE or not np.all(np.isfinite(sol.x)):
            failures.append(f"minimum-norm tie-break: {sol.status.name.lower()} "
                            f"({self.engine_name}); kept the last level's answer")  # fmt: skip
            return x
        return x + (sol.x if Z is None else Z.dot(sol.x))

    def _strongly_active(
        self,
        lev: LevelProblem,
        x: np.ndarray,
        Z: np.ndarray | None,
        lo: np.ndarray,
        hi: np.ndarray,
        inherited: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        delta: float,
    ) -> np.ndarray | None:
        """Rows (x-space) of the constraints the level's own objective presses on at ``x``.

        Every optimum of a convex level shares the constraints with a positive multiplier
        (complementary slackness), so fixing them for the lower levels does not change the
        problem; it removes the freedom that a level-k optimum found only to round-off would
        otherwise leave to the next level (where a 1e-10 slack can move a lower level by 1e-3).
        The multipliers are those of the level's own least-squares objective, without the
        Tikhonov term, from the stationarity condition on the active constraints; a gradient
        or multiplier of the size the Tikhonov term alone produces (``delta |x|``) is not
        counted.
        """
        gnorm, N, mu, _ = _active_multipliers(
            lev, x, Z, (lo, hi, inherited), self.active_tolerance, self.rank_tolerance
        )
        floor = max(1e-3 * self.tolerance * max(1.0, float(np.linalg.norm(lev.b))),
                    100.0 * delta * max(1.0, float(np.linalg.norm(x))))  # fmt: skip
        if gnorm <= floor or mu is None:
            return None  # the bounds did not cost this level anything
        Ny = N if Z is None else N.dot(Z)
        pin = mu > max(1e-6 * gnorm, floor) / max(1.0, float(np.abs(Ny).max()))
        return N[pin] if np.any(pin) else None

    @staticmethod
    def _skip_nonfinite(lev: LevelProblem, report: LevelReport, failures: list[str]) -> None:
        bad = _nonfinite_tasks(lev)
        failures.append(f"{lev.name}: non-finite rows from {', '.join(bad)}; level skipped")
        report.limited, report.failed = bad, True

    def _bound_limited(self, lev: LevelProblem, res: np.ndarray, res_free: np.ndarray,
                       on_box: bool = True) -> list[str]:  # fmt: skip
        """Tasks whose residual the hard constraints raised above the box-free optimum (none
        when no entry is on the box, ``on_box`` False: then the levels above, not the box,
        set the residual)."""
        if not on_box:
            return []
        tol = self.tolerance
        return [name for (name, r, _, b), (_, r0, _, _)
                in zip(lev.task_residuals(res), lev.task_residuals(res_free), strict=True)
                if r - r0 > tol * (1.0 + b)]  # fmt: skip

    # ------------------------------------------------------------------ the result
    def _result(
        self,
        problem: StackProblem,
        x: np.ndarray,
        u: np.ndarray,
        failures: list[str],
        clip: float,
    ) -> SolverResult:
        failed = [k for k, rep in enumerate(self.levels) if rep.failed]
        level_res, task_res, infeasible = problem.residuals(x, self.tolerance, failed)
        for k, lev in enumerate(problem.levels):
            report = self.levels[k]
            report.residual = float(level_res[k])
            if report.failed:  # a skipped level: all its tasks, inequalities included
                infeasible += [(lev.name, t) for t in lev.inequality_rows
                               if t not in report.limited]  # fmt: skip
            if report.limited:
                infeasible += [(lev.name, t) for t in report.limited if t in lev.inequality_rows]
        act = self.active_tolerance
        active = ((x <= problem.lower + act) | (x >= problem.upper - act)).nonzero()[0]
        top = problem.levels[0].name if problem.levels else ""
        if failures:
            status = SolverStatus.FAILED
        elif any([rep.limited for rep in self.levels]) or top in [lv for lv, _ in infeasible]:
            status = SolverStatus.INFEASIBLE
        elif active.size:
            status = SolverStatus.BOUNDS_ACTIVE
        else:
            status = SolverStatus.OK
        if self._native_from is not None:
            first = self.levels[self._native_from]
            msg = [f"daqp hierarchy from {first.name}: {first.iterations} it"]
        else:
            qps = [f"{rep.name}: {rep.iterations} it" for rep in self.levels if rep.qp]
            msg = [f"{self.engine_name}: " + ("; ".join(qps) if qps else "no QP needed")]
        msg += self._notes + failures
        if infeasible:
            msg.append("infeasible: " + ", ".join(f"{lv}/{t}" for lv, t in infeasible))
        if clip > 10 * self.bound_relaxation:
            msg.append(f"clipped u by {clip:.2e} (scaled units) to the box")
        return SolverResult(
            u=u,
            status=status,
            level_residuals=level_res,
            task_residuals=task_res,
            active_bounds=active,
            scale=_ones(len(problem.levels)),
            infeasible=infeasible,
            message="; ".join(msg),
        )


# ---------------------------------------------------------------------- helpers
def _finite_level(lev: LevelProblem) -> bool:
    # One reduction per array: a sum is finite iff every entry is (barring overflow of
    # absurdly large rows, which are then reported as non-finite too).
    C = lev.C
    if not math.isfinite(_sum(lev.A) + _sum(lev.b)):
        return False
    if not C.shape[0]:
        return True
    if not math.isfinite(_sum(C)):
        return False
    return not (_any(np.isnan(lev.lower)) or _any(np.isnan(lev.upper)))


Bounds = tuple[np.ndarray, np.ndarray, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]
"""The box ``lo <= x <= hi`` and the inherited rows ``(G, glo, ghi)`` of a level."""


def _optimal(lev: LevelProblem, x: np.ndarray, Z: np.ndarray | None, bounds: Bounds,
             act: float, rank_tolerance: float, rtol: float = 1e-4) -> bool:  # fmt: skip
    """Whether ``x`` meets the optimality conditions of the level's least squares (no
    inequality rows of its own) over ``x + Z y`` within ``bounds``: its gradient is a
    combination of the active constraints' normals with multipliers of the right signs (see
    :func:`_active_multipliers`), both to ``rtol |g|``. A sufficient test: degenerate
    multipliers may fail it, and then the caller only does more work."""
    lo, hi, inherited = bounds
    if Z is None and not inherited:  # the normals are unit vectors: mu = +-g on the bounds
        g = lev.A.T.dot(lev.A.dot(x) - lev.b)
        up, low = x >= hi - act, x <= lo + act
        tol = rtol * math.sqrt(g.dot(g))
        free = g[~(up | low)]
        return bool(free.dot(free) <= tol * tol and np.all(g[up] <= tol)
                    and np.all(g[low] >= -tol))  # fmt: skip
    gn, _, mu, res = _active_multipliers(lev, x, Z, bounds, act, rank_tolerance)
    if gn == 0.0:
        return True
    return mu is not None and res <= rtol * gn and bool(np.all(mu >= -rtol * gn))


def _box_optimal(M: np.ndarray, c: np.ndarray, y: np.ndarray, lb: np.ndarray, ub: np.ndarray,
                 act: float, rtol: float = 1e-4) -> bool:  # fmt: skip
    """Whether ``y`` meets the optimality conditions of ``min ||M y - c||`` over the box
    ``[lb, ub]`` (as :func:`_optimal` where only the box bounds a level): the gradient
    vanishes on the free entries and points outwards on the bound ones, to ``rtol |g|``."""
    g = M.T.dot(M.dot(y) - c)
    up, low = y >= ub - act, y <= lb + act
    tol = rtol * math.sqrt(g.dot(g))
    free = g[~(up | low)]
    return bool(free.dot(free) <= tol * tol and np.all(g[up] <= tol) and np.all(g[low] >= -tol))


def _active_multipliers(lev: LevelProblem, x: np.ndarray, Z: np.ndarray | None, bounds: Bounds,
                        act: float, rank_tolerance: float,
                        ) -> tuple[float, np.ndarray, np.ndarray | None, float]:  # fmt: skip
    """The norm of the level's gradient ``gy = Z^T A^T (A x - b)`` in the free coordinates,
    the rows ``N`` (x-space) of the constraints of ``bounds`` active at ``x`` (within
    ``act``), their multipliers ``mu`` (``gy = sum_i mu_i s_i Z^T n_i``, ``s_i = +1`` at a
    lower and -1 at an upper bound, so ``mu >= 0`` at an optimum; least squares; None when
    nothing is active) and the norm of what the normals leave of ``gy``."""
    lo, hi, inherited = bounds
    g = lev.A.T.dot(lev.A.dot(x) - lev.b)
    if lev.C.shape[0]:  # the slack of the level's violated inequality rows is its objective too
        Cx = lev.C.dot(x)
        g = g + lev.C.T.dot(np.maximum(Cx - lev.upper, 0.0) - np.maximum(lev.lower - Cx, 0.0))
    gy = g if Z is None else Z.T.dot(g)
    gnorm = math.sqrt(gy.dot(gy))
    low, up = x <= lo + act, x >= hi - act
    idx = np.flatnonzero(low | up)
    E = np.zeros((idx.size, x.shape[0]))
    E[np.arange(idx.size), idx] = 1.0
    rows, signs = [E], [np.where(low[idx], 1.0, -1.0)]
    for G, glo, ghi in inherited:
        Gx = G.dot(x)
        gl, gu = Gx <= glo + act, Gx >= ghi - act
        if np.any(gl | gu):
            rows.append(G[gl | gu])
            signs.append(np.where(gl[gl | gu], 1.0, -1.0))
    N = np.vstack(rows)
    if not N.shape[0]:
        return gnorm, N, None, gnorm
    Ny = (N if Z is None else N.dot(Z)) * np.concatenate(signs)[:, None]
    try:
        _, mu, _, _ = _cod(Ny.T, gy, np.zeros(N.shape[0]), rank_tolerance)
    except (np.linalg.LinAlgError, ValueError):
        return gnorm, N, None, gnorm
    res = Ny.T.dot(mu) - gy
    return gnorm, N, mu, math.sqrt(res.dot(res))


def _on_box(x: np.ndarray, lb: np.ndarray, ub: np.ndarray, act: float = 1e-7) -> bool:
    """Whether some entry of ``x`` is on (within ``act`` of) the box ``[lb, ub]``."""
    return _any((x <= lb + act) | (x >= ub - act))


def _worse(lev: LevelProblem, x: np.ndarray, best: np.ndarray, tol: float) -> bool:
    """Whether the level's residual (slacks included) at ``x`` exceeds that at ``best`` by
    more than ``tol (1 + |b|)``."""
    return math.sqrt(2.0 * _level_objective(lev, x)) > math.sqrt(
        2.0 * _level_objective(lev, best)
    ) + tol * (1.0 + math.sqrt(lev.b.dot(lev.b)))


def _level_objective(lev: LevelProblem, x: np.ndarray) -> float:
    """The level's objective at ``x``: ``1/2 ||A x - b||^2 + 1/2 ||s||^2``, ``s`` the least
    slack that puts its inequality rows within their bounds."""
    r = lev.A.dot(x) - lev.b
    f = 0.5 * float(r.dot(r))
    if lev.C.shape[0]:
        Cx = lev.C.dot(x)
        s = np.maximum(Cx - lev.upper, 0.0) + np.maximum(lev.lower - Cx, 0.0)
        f += 0.5 * float(s.dot(s))
    return f


def _violated(lev: LevelProblem, Cx: np.ndarray, tol: float) -> tuple[np.ndarray, list[str]]:
    """The inequality rows of ``lev`` that ``Cx`` violates by more than ``tol`` (a mask) and
    the names of their tasks."""
    viol = (Cx > lev.upper + tol) | (Cx < lev.lower - tol)
    if not _count_nonzero(viol):
        return viol, []
    return viol, [name for name, sl in lev.inequality_rows.items() if _count_nonzero(viol[sl])]


def _nonfinite_tasks(lev: LevelProblem) -> list[str]:
    bad = [name for name, sl in lev.task_rows.items()
           if not (np.isfinite(lev.A[sl]).all() and np.isfinite(lev.b[sl]).all())]  # fmt: skip
    bad += [name for name, sl in lev.inequality_rows.items()
            if not np.isfinite(lev.C[sl]).all() or np.isnan(lev.lower[sl]).any()
            or np.isnan(lev.upper[sl]).any()]  # fmt: skip
    return bad or [lev.name]


def _inside(x: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            inherited: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> bool:  # fmt: skip
    return _all(x >= lo) and _all(x <= hi) and _inside_rows(x, inherited)


def _inside_rows(x: np.ndarray,
                 inherited: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> bool:  # fmt: skip
    for G, glo, ghi in inherited:
        Gx = G.dot(x)
        if not (_all(Gx >= glo) and _all(Gx <= ghi)):
            return False
    return True


def _rows_inside(v: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float) -> bool:
    return _all(v >= lo - tol) and _all(v <= hi + tol)


# ndarray.all()/.any()/.sum() go through Python wrappers; these are the C-level equivalents.

_ONES: dict[int, np.ndarray] = {}


def _sum(a: np.ndarray) -> float:
    """Sum of all entries of ``a``, as a dot product with ones (a BLAS call: cheaper than
    ``np.add.reduce``; a NaN or inf entry makes it non-finite all the same)."""
    f = a.ravel()
    n = f.shape[0]
    ones = _ONES.get(n)
    if ones is None:
        ones = _ONES[n] = np.ones(n)
        ones.setflags(write=False)
    return float(f.dot(ones))


def _ones(n: int) -> np.ndarray:
    """``np.ones(n)`` (a fresh array) without its Python wrapper."""
    out = np.empty(n)
    out.fill(1.0)
    return out


def _all(mask: np.ndarray) -> bool:
    """``mask.all()``."""
    return _count_nonzero(mask) == mask.size


def _any(mask: np.ndarray) -> bool:
    """``mask.any()``."""
    return _count_nonzero(mask) > 0


def _finite(x: np.ndarray) -> bool:
    """``np.isfinite(x).all()``: ``x . x`` is finite iff every entry is, unless it
    overflows (then the entry-wise test decides)."""
    return math.isfinite(x.dot(x)) or _all(np.isfinite(x))


_geqp3, _orgqr, _gels, _trtrs = (getattr(_lapack, f) for f in ("dgeqp3", "dorgqr", "dgels",
                                                                  "dtrtrs"))  # fmt: skip


def _cod(
    M: np.ndarray, c: np.ndarray, t: np.ndarray, rtol: float, floor: float = 0.0
) -> tuple[int, np.ndarray, np.ndarray | None, float | None]:
    """Minimum-norm least squares with a rank threshold, by a complete orthogonal
    decomposition (LAPACK ``dgeqp3`` + ``dorgqr``, about 3x faster than an SVD here).

    ``M^T P = Q R`` (QR with column pivoting of ``M^T``, Q square); the rank is the number of
    ``|R_ii| > max(rtol |R_00|, floor)`` (``floor``: the size below which a row of ``M`` is
    round-off, e.g. a level's rows projected on directions they do not move); ``Q_1`` spans
    ``M``'s row space and ``Q_2`` its null space. Returns
    ``(rank, y, Q_2 or None when rank = r, |R_00|)`` with ``y = Q_1 a - Q_2 Q_2^T t``, ``a`` the
    least-squares solution of ``R_1^T a = P^T c``: ``M y`` is the best fit of ``c``, and among
    the ``y`` that achieve it, ``t + y`` has the smallest norm. When ``M`` has full column
    rank (``rank = r < m``), ``y`` is its unique least-squares solution, solved by ``dgels``
    on ``M`` itself (no ``Q`` needed).

    A tall ``M`` (``m > r``) that is certified to have full column rank under the rule (see
    :func:`_full_column_rank`) skips the pivoted QR: then ``|R_00|`` is returned as None (the
    caller computes it with :func:`_pivot_norm` when it needs it). A well-conditioned one is
    solved by its normal equations (:func:`_normal_solve`), otherwise by ``dgels``.
    """
    m, r = M.shape
    tall: np.ndarray | None = None  # M's least-squares solution when M is tall (m > r)
    if m > r > 0:
        y = _normal_solve(M, c, rtol, floor)
        if y is not None:
            return r, y, None, None
        lqr, z, info = _gels(M, c)
        if info == 0:
            tall = z[:r]
            if _full_column_rank(M, lqr, rtol, floor):
                return r, tall, None, None
    k = min(m, r)
    qr, jpvt, tau, _, info = _geqp3(M.T, lwork=8 * (m + 1))
    if info != 0:
        raise np.linalg.LinAlgError(f"dgeqp3 info {info}")
    if k:
        diag = qr.diagonal()[:k].tolist()
        smax = abs(diag[0])
        if smax > floor:
            thr = max(rtol * smax, floor)
            rank = 0
            for v in diag:  # |R_ii| is non-increasing, but count every one like the rule
                if abs(v) > thr:
                    rank += 1
        else:
            rank = 0
    else:
        smax, rank = 0.0, 0
    if rank == r and tall is not None:  # full column rank, more rows: the unique solution
        return rank, tall, None, smax  # (no dgels answer: an exactly singular R, path below)
    if k < r:
        a = np.zeros((r, r), order="F")
        a[:, :k] = qr[:, :k]
        Q, _, info = _orgqr(a, tau[:k], lwork=8 * r, overwrite_a=1)  # a is ours
    else:
        Q, _, info = _orgqr(qr[:, :r], tau[:k], lwork=8 * r)
    if info != 0:
        raise np.linalg.LinAlgError(f"dorgqr info {info}")
    if rank:
        cp = c.take(jpvt - 1)
        if rank == m:  # R_11^T a = P^T c, triangular
            z, info = _trtrs(qr[:rank, :rank], cp, lower=0, trans=1)
        else:  # (m x rank) lower-trapezoidal least squares
            R1t = qr[:rank].T * _lower_mask(m, rank)
            _, z, info = _gels(R1t, cp)
            z = z[:rank]
        if info != 0:
            raise np.linalg.LinAlgError(f"triangular solve info {info}")
        y = Q[:, :rank].dot(z)
    else:
        y = np.zeros(r)
    if rank == r:
        return rank, y, None, smax
    Q2 = Q[:, rank:]
    if _count_nonzero(t):  # (t = 0: nothing to remove, often at the first level)
        y -= Q2.dot(Q2.T.dot(t))
    return rank, y, Q2, smax


_trtri, _potrf = _lapack.dtrtri, _lapack.dpotrf
_CERTIFY_MARGIN = 1e3  # safety factor of the full-column-rank certificate (round-off)


def _normal_solve(M: np.ndarray, c: np.ndarray, rtol: float, floor: float = 0.0
                  ) -> np.ndarray | None:  # fmt: skip
    """The least-squares solution of a tall ``M`` (m x r, m > r) by its normal equations,
    where they are accurate and the rank rule of :func:`_cod` certainly finds full column
    rank; None otherwise (the caller then uses a QR of ``M``).

    Cholesky ``M^T M = U^T U`` (U is the R of ``M = Q R`` up to the signs of its rows) and
    ``U^-1``; ``kappa_F = ||U^-1||_F ||M||_F`` bounds the condition number of ``M`` from
    above. Certified by :func:`_rank_certificate` (with ``U`` for ``R``), used only when
    ``kappa_F <= NORMAL_KAPPA`` (1e4) and solved by :func:`~wholebody._numeric.normal_solve`
    (its accuracy is documented there, far below the solver's tolerances of 1e-8 and up):
    17 us against 35 us for ``dgels`` with its certificate on the 35 x 23 level of the peers
    benchmark.
    """
    U, info = _potrf(M.T.dot(M))
    if info != 0:
        return None
    Ui, info = _trtri(U, lower=0)
    if info != 0:
        return None
    k2 = _rank_certificate(M, Ui, rtol, floor)
    if k2 is None or not k2 <= NORMAL_KAPPA * NORMAL_KAPPA:
        return None
    return normal_solve(M, Ui.T, c, k2)  # (M^T M)^-1 = U^-1 U^-T


def _full_column_rank(M: np.ndarray, lqr: np.ndarray, rtol: float, floor: float = 0.0) -> bool:
    """Whether the rank rule of :func:`_cod` is certain to find full column rank, from the
    unpivoted QR ``M = Q R`` in ``lqr`` (``dgels``'s output) of a tall ``M`` (m x r, m > r);
    see :func:`_rank_certificate`."""
    r = M.shape[1]
    Rinv, info = _trtri(lqr[:r, :r], lower=0)
    return info == 0 and _rank_certificate(M, Rinv, rtol, floor) is not None


def _rank_certificate(M: np.ndarray, Rinv: np.ndarray, rtol: float,
                      floor: float = 0.0) -> float | None:  # fmt: skip
    """``kappa_F^2 = ||R^-1||_F^2 ||M||_F^2`` when the rank rule of :func:`_cod`
    (``|R_ii| > rtol |R_00|`` in the pivoted QR of ``M^T``) is certain to find full column
    rank for a tall ``M`` (m x r, m > r) with ``M^T M = R^T R`` (``Rinv = R^-1``), else None.

    In the pivoted QR of ``M^T`` (columns: the m rows of M), ``|R_ii|`` is the largest column
    norm of the trailing block, whose 2-norm is at least ``sigma_r(M)`` (a rank-i matrix is at
    least that far from ``M^T``), so ``|R_ii| >= sigma_r / sqrt(m)``; ``|R_00|`` is a column
    norm, at most ``||M||_F``; and ``sigma_r(M) = sigma_min(R) >= 1 / ||R^-1||_F``. Hence full
    rank when ``||R^-1||_F ||M||_F sqrt(m) rtol < 1``, here with a margin of 1e3; and every
    ``|R_ii| > floor`` when ``||R^-1||_F sqrt(m) floor < 1``.
    """
    fi = Rinv.ravel(order="K")
    fm = M.ravel(order="K")
    inv2 = fi.dot(fi)  # >= 1 / sigma_r^2
    k2 = inv2 * fm.dot(fm)
    m = M.shape[0]  # (m inv2 >= 1 / |R_ii|^2 for every pivot of the rule)
    margin = _CERTIFY_MARGIN * rtol
    if k2 * m * margin * margin < 1.0 and inv2 * m * floor * floor < 1.0:
        return k2
    return None


def _pivot_norm(M: np.ndarray) -> float:
    """``|R_00|`` of the pivoted QR of ``M^T`` (what :func:`_cod` returns as its last value)."""
    if not min(M.shape):
        return 0.0
    qr, _, _, _, info = _geqp3(M.T, lwork=8 * (M.shape[0] + 1))
    if info != 0:
        return 0.0
    return abs(float(qr[0, 0]))


_DAQP_BIG = 1e20  # an infinite bound for daqp

_MASKS: dict[tuple[int, int], np.ndarray] = {}


def _lower_mask(m: int, k: int) -> np.ndarray:
    """Cached ``(m, k)`` lower-trapezoidal mask of ones."""
    mask = _MASKS.get((m, k))
    if mask is None:
        mask = _MASKS[(m, k)] = np.tril(np.ones((m, k)))
    return mask


def _full_row_rank(Nz: np.ndarray, rtol: float, floor: float) -> bool:
    """Whether ``Nz`` (q x r, q <= r) certainly has q singular values above
    ``max(rtol s_max, floor)``: with ``Nz Nz^T = L L^T``, ``sigma_min >= 1 / ||L^-1||_F`` and
    ``s_max <= ||Nz||_F``, so it does when ``||L^-1||_F ||Nz||_F rtol`` and
    ``||L^-1||_F floor`` are below 1, here with the certificates' margin of 1e3."""
    L, info = _potrf(Nz.dot(Nz.T), lower=1)
    if info != 0:
        return False
    Li, info = _trtri(L, lower=1)
    if info != 0:
        return False
    fi, fn = Li.ravel(), Nz.ravel()
    inv2 = fi.dot(fi)
    margin = _CERTIFY_MARGIN * rtol
    return bool(inv2 * fn.dot(fn) * margin * margin < 1.0
                and inv2 * (_CERTIFY_MARGIN * floor) ** 2 < 1.0)  # fmt: skip


def _null_space(Nz: np.ndarray, Z: np.ndarray | None, rank_tolerance: float,
                floor: float = 0.0) -> np.ndarray:  # fmt: skip
    """Basis of ``{Z y : Nz y = 0}`` (``Z = None``: the identity); singular values at most
    ``max(rank_tolerance s_max, floor)`` count as zero (``floor``: the size of a row of
    ``Nz`` that is round-off, a constraint on directions it does not move).

    Where that rule certainly keeps every row (:func:`_full_row_rank`), the basis is the
    complement of the rows from the complete QR of ``Nz^T``, the same subspace as the SVD's
    (5 us against 30 us for the SVD of the 10 x 11 pins of the tight peers level)."""
    q, r = Nz.shape
    if 0 < q <= r and _full_row_rank(Nz, rank_tolerance, floor):
        V2 = np.linalg.qr(Nz.T, mode="complete")[0][:, q:]
        return V2 if Z is None else Z.dot(V2)
    _, S, Vt = np.linalg.svd(Nz, full_matrices=True)
    thr = max(rank_tolerance * S[0], floor) if S.size else 0.0
    rank = int(np.count_nonzero(thr < S)) if S.size and S[0] > floor else 0
    V2 = Vt[rank:].T
    return V2 if Z is None else Z.dot(V2)


_FLAT = 1e-12  # a QP row whose coefficients are at most this (relative) is left unbounded


def _flat(Nz: np.ndarray, scale: float | np.ndarray, low: np.ndarray, up: np.ndarray) -> None:
    """Unbound, in place, the QP rows ``Nz y`` that the free directions move only at rounding
    level: largest coefficient at most ``_FLAT max(1, scale)`` (``scale``: the size of the
    row before the restriction to the free directions). Such a row cannot be moved through
    ``y``; two of opposite sign on joints at their bounds pinned ``y`` to 0 (the engines then
    solved, or declared infeasible, a degenerate problem: proxsuite on 15 % of the paper
    stack's steps)."""
    if not Nz.shape[1]:
        return
    flat = np.abs(Nz).max(axis=1) <= _FLAT * np.maximum(1.0, scale)
    low[flat] = -np.inf
    up[flat] = np.inf


def _widened(G: np.ndarray, x: np.ndarray, Gz: np.ndarray, low: np.ndarray,
             up: np.ndarray) -> None:  # fmt: skip
    """The bounds ``glo - G x <= G Z y <= ghi - G x`` of inherited rows, given as ``low``,
    ``up`` (new arrays, shifted in place), widened to contain 0 so that y = 0 is feasible
    (the levels since may have moved ``G x`` out by round-off, in directions the QP cannot
    undo), and rows flat in ``y`` unbounded (:func:`_flat`)."""
    Gx = G.dot(x)
    low -= Gx
    up -= Gx
    np.minimum(low, 0.0, out=low)
    np.maximum(up, 0.0, out=up)
    if G.shape[0]:
        _flat(Gz, np.abs(G).max(axis=1), low, up)


def _pad(G: np.ndarray, nv: int) -> np.ndarray:
    if G.shape[1] == nv:
        return G
    out = np.zeros((G.shape[0], nv))
    out[:, : G.shape[1]] = G
    return out
