r"""The HQP's null-space cascade, level by level: the Python reference of the compiled one.

The cascade keeps a point ``x`` of the optimal set of the levels solved so far and an
orthonormal basis ``Z`` of the directions that leave them optimal (``Z = I``, stored as None,
at the first level), and parametrises the next level's answers as ``x + Z y``. At level k:

1. **Unconstrained candidate** (:meth:`Cascade._candidate`): with ``M = A_k Z`` and
   ``c = b_k - A_k x``, the minimum-norm least-squares step ``y = M^+ c`` plus, in the level's
   own null space ``Q_2``, the step to the minimum-norm point ``-Q_2 Q_2^T Z^T x``
   (:func:`~wholebody.solvers.linalg.cod`; a level of objectives ``s I`` needs no
   decomposition). If ``x + Z y`` lies in the box and meets the inherited and the level's
   inequality rows, it is the level's optimum: no QP. With no bound active this is the
   recursive pseudo-inverse, the projection backend's ``J+ v + (I - J+ J) u0``.
2. **Otherwise the level's QP** (:func:`~wholebody.solvers.level_qp.level_qp`, with its
   polish and proximal steps), or, with ``method="native"`` at the first such level, daqp's
   hierarchy for the rest of the stack (:mod:`wholebody.solvers.native`).
3. **The level's optimal set** (:meth:`Cascade._fix`): ``Z <- Z Q_2``; where a QP ran, the
   constraints the level's own optimum presses on (positive multipliers,
   :func:`~wholebody.solvers.optimality.strongly_active`) are fixed too, which changes nothing
   in exact arithmetic but removes the freedom that a level found only to round-off would
   leave to the next one. Its inequality rows are inherited by the levels below, an
   unavoidable violation pinned where it is.

The box and the inherited rows are relaxed by ``bound_relaxation`` and widened to contain
``x``, so ``y = 0`` is always feasible. A level whose rows are not numbers, or whose
decomposition or QP fails, is skipped and named; the rest is solved. At the end, if any QP
ran and freedom is left, the exact minimum-norm point of the last optimal set is one more QP
with ``H = I`` (:meth:`Cascade._tie_break`), and ``x`` is clipped to the exact box.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from wholebody._numeric import all_finite, all_true, count_nonzero
from wholebody.solvers.level_qp import free_constraints, level_qp, stacked
from wholebody.solvers.level_report import LevelReport
from wholebody.solvers.linalg import cod, null_space, pivot_norm
from wholebody.solvers.native import native_step
from wholebody.solvers.optimality import (
    Bounds,
    Inherited,
    bound_limited,
    finite_level,
    inside,
    inside_rows,
    nonfinite_tasks,
    on_box,
    rows_inside,
    strongly_active,
    violated,
)
from wholebody.solvers.qp import QPStatus
from wholebody.solvers.stack import LevelProblem, StackProblem

if TYPE_CHECKING:
    from wholebody.solvers.hqp import HierarchicalQPSolver

__all__ = ["Candidate", "Cascade"]


@dataclass(slots=True)
class Candidate:
    """A level's unconstrained candidate step in the free coordinates.

    Attributes
    ----------
    m
        The level's number of equality rows.
    M, c
        ``A Z`` and ``b - A x`` (None without equality rows).
    y
        The step: ``x + Z y`` is the candidate.
    null
        The level's own null space in the free coordinates (None: none left, or not
        computed for a level of objectives ``s I``).
    rank
        Rank of ``M`` under the rank rule.
    smax
        ``|R_00|`` of the decomposition (None until :meth:`sigma_max` computes it, where a
        certified full rank skipped the pivoted QR).
    """

    m: int
    M: np.ndarray | None
    c: np.ndarray | None
    y: np.ndarray
    null: np.ndarray | None
    rank: int
    smax: float | None

    def sigma_max(self) -> float:
        """``|R_00|``, the scale of the level's rows in the free directions."""
        if self.smax is None:
            self.smax = pivot_norm(self.M)
        return self.smax


class Cascade:
    """One run of the cascade on an evaluated stack (rows in scaled coordinates).

    Attributes
    ----------
    reports
        One :class:`LevelReport` per level (the solver's :attr:`levels`).
    failures
        What was skipped or failed, for the result's message (any makes the status FAILED).
    notes
        What the native method did, for the message.
    native_from
        The level from which daqp's hierarchy solved the stack (None: the cascade did).
    x, Z, lo, hi, inherited
        The state between levels: the point, the free directions (None: all), the relaxed
        box (widened to contain ``x``) and the inherited inequality rows.
    """

    def __init__(self, solver: HierarchicalQPSolver, problem: StackProblem) -> None:
        self.solver = solver
        self.problem = problem
        self.reports = [LevelReport(lev.name) for lev in problem.levels]
        self.failures: list[str] = []
        self.notes: list[str] = []
        self.native_from: int | None = None
        lb, ub = problem.lower, problem.upper
        bt = solver.bound_relaxation
        self.x = np.minimum(np.maximum(0.0, lb), ub)  # the minimum-norm point of the box
        self.Z: np.ndarray | None = None  # None: the identity (nothing fixed yet)
        self.r = lb.shape[0]  # Z's columns
        self.lo = lb - bt
        self.hi = ub + bt
        self.inherited: Inherited = []
        self.native_tried = False
        self.any_qp = False
        self.exact = True  # x is in the exact box (the unconstrained candidates' case)

    def bounds(self) -> Bounds:
        """The relaxed box and the inherited rows of the next level."""
        return self.lo, self.hi, self.inherited

    # ------------------------------------------------------------------ the run
    def run(self) -> tuple[np.ndarray, float]:
        """The answer ``x`` (in the exact box) and how far the final clip moved it."""
        lb, ub = self.problem.lower, self.problem.upper
        if not all_true(lb <= ub):  # NaN compares false; Stack.evaluate never crosses the box
            self.failures.append("the box is empty or not a number (NaN bounds): u = 0")
            return np.zeros(lb.shape[0]), 0.0
        for k, lev in enumerate(self.problem.levels):
            if not self._level(k, lev):
                break  # daqp's hierarchy solved the rest
        if self.r and self.any_qp:
            self.x = self._tie_break()
        elif self.exact and not self.any_qp:
            return self.x, 0.0
        xc = np.minimum(np.maximum(self.x, lb), ub)
        d = xc - self.x
        clip = float(np.maximum.reduce(np.abs(d))) if d.dot(d) != 0.0 else 0.0
        return xc, clip

    def _level(self, k: int, lev: LevelProblem) -> bool:
        """Level ``k``: its optimum and optimal set; False when nothing is left to solve."""
        report = self.reports[k]
        report.free = self.r
        if self.r == 0:  # nothing left to move: report the inequality rows x leaves violated
            if not finite_level(lev):  # (and NaN or inf rows, as at any level)
                self._skip_nonfinite(lev, report)
            elif lev.C.shape[0]:
                report.limited = violated(lev, lev.C.dot(self.x), self.solver.tolerance)[1]
            return True
        # Non-finite equality rows show in the step y (one product instead of a pass over A
        # and b); the inequality rows are checked here.
        if lev.C.shape[0] and not finite_level(lev):
            self._skip_nonfinite(lev, report)
            return True
        step = self._candidate(lev, report)
        if step is None:
            return True
        report.rank = step.rank
        xc = self.x + (step.y if self.Z is None else self.Z.dot(step.y))
        lb, ub = self.problem.lower, self.problem.upper
        in_box = all_true(xc >= lb) and all_true(xc <= ub)  # (then no clip at the end)
        if self._feasible(xc, in_box, lev):
            self.x, self.exact = xc, in_box
        elif step.m and step.rank == 0 and lev.C.shape[0] == 0:
            # rows with nothing left to move (round-off in the free directions, or a task
            # the levels above fix): only the minimum-norm step left the box, and a QP of
            # rows this small is degenerate; the final tie-break makes that choice
            self.any_qp = True
        else:
            report.qp = self.any_qp = True
            solved, report = self._solve_level(k, lev, step, xc, report)
            if solved is None:
                return True
            if not solved:
                return False
        self._fix(lev, step, report)
        self._inherit(k, lev, report)
        return True

    def _feasible(self, xc: np.ndarray, in_box: bool, lev: LevelProblem) -> bool:
        """Whether the candidate ``xc`` is in the relaxed box and meets the inherited and the
        level's own inequality rows (``in_box``: it is in the exact box)."""
        return bool(
            (in_box or (all_true(xc >= self.lo) and all_true(xc <= self.hi)))
            and inside_rows(xc, self.inherited)
            and (lev.C.shape[0] == 0
                 or rows_inside(lev.C.dot(xc), lev.lower, lev.upper, self.solver.tolerance))
        )  # fmt: skip

    # ------------------------------------------------------------------ the candidate
    def _candidate(self, lev: LevelProblem, report: LevelReport) -> Candidate | None:
        """The level's unconstrained candidate (see the module docstring), or None when the
        level is skipped (rows not numbers, or the decomposition failed)."""
        m = lev.A.shape[0]
        if m:
            step = self._decomposed(lev, report)
            if step is None:
                return None
        else:
            t = self.x if self.Z is None else self.Z.T.dot(self.x)
            step = Candidate(0, None, None, -t, None, 0, 0.0)
        if m and (step.rank == 0 or not all_finite(step.y)) and not finite_level(lev):
            # (NaN or inf rows give a non-finite step, or no rank: a NaN pivot is no pivot)
            self._skip_nonfinite(lev, report)
            return None
        if not all_finite(step.y):  # finite rows, yet the decomposition overflowed
            self.failures.append(f"{lev.name}: decomposition failed (non-finite step); "
                                 "level skipped")  # fmt: skip
            report.failed = True
            return None
        return step

    def _decomposed(self, lev: LevelProblem, report: LevelReport) -> Candidate | None:
        """The candidate of a level with equality rows: ``y = (Z^T c) / s`` for a level of
        objectives ``s I``, else the complete orthogonal decomposition of ``M``."""
        A, b, x, Z = lev.A, lev.b, self.x, self.Z
        n = x.shape[0]
        # (x = 0, the usual start: c = b; c is only read)
        c = b - A.dot(x) if Z is not None or count_nonzero(x) else b
        M = A if Z is None else A.dot(Z)
        m = A.shape[0]
        sw = lev.identity_scale if lev.A.shape == (n, n) else 0.0
        if sw > 0:  # rows sw * I: M = sw Z has r singular values sw
            y = (c if Z is None else Z.T.dot(c)) / sw
            return Candidate(m, M, c, y, None, self.r, sw)
        t = x if Z is None else Z.T.dot(x)  # current point in the free coordinates
        rtol = self.solver.rank_tolerance
        try:
            # rows below rank_tolerance |A| in the free directions are round-off
            fa = A.ravel()
            floor = rtol * math.sqrt(fa.dot(fa)) if Z is not None else 0.0
            rank, y, null, smax = cod(M, c, t, rtol, floor)
        except (np.linalg.LinAlgError, ValueError) as exc:
            if not finite_level(lev):
                self._skip_nonfinite(lev, report)
            else:
                self.failures.append(f"{lev.name}: decomposition failed ({exc}); level "
                                     "skipped")  # fmt: skip
                report.failed = True
            return None
        return Candidate(m, M, c, y, null, rank, smax)

    # ------------------------------------------------------------------ the level's QP
    def _solve_level(self, k: int, lev: LevelProblem, step: Candidate, xc: np.ndarray,
                     report: LevelReport) -> tuple[bool | None, LevelReport]:  # fmt: skip
        """The level's QP (or daqp's hierarchy), ``x`` moved to its answer: ``(True,
        report)``; ``(False, report)`` when daqp's hierarchy solved the rest of the stack;
        ``(None, report)`` when the engine failed (the level is left unsolved). ``report``
        is the level's report, a new one where the cascade took over from daqp."""
        solver = self.solver
        smax = step.sigma_max()
        xq = None  # the level's own QP, where daqp's answer was checked against it
        if solver.method == "native" and not self.native_tried:
            self.native_tried = True
            xn, xq, report = native_step(self, k, lev, step, xc, report)
            if xn is not None:
                self.x = xn
                self.r = 0  # solved to the end
                return False, report
        if xq is None:
            xq = level_qp(solver, k, lev, self.x, self.Z, step.M, step.c, smax, self.bounds(),
                          report)  # fmt: skip
        if xq is None:
            report.failed = True
            self.failures.append(f"{lev.name}: {report.engine_status.name.lower()} "
                                 f"({solver.engine_name}); level left unsolved")  # fmt: skip
            return None, report
        if step.m:
            report.limited = bound_limited(
                lev, lev.A.dot(xq) - lev.b, lev.A.dot(xc) - lev.b,
                on_box(xq, self.problem.lower, self.problem.upper), solver.tolerance,
            )  # fmt: skip
        self.x = xq
        return True, report

    # ------------------------------------------------------------------ the optimal set
    def _fix(self, lev: LevelProblem, step: Candidate, report: LevelReport) -> None:
        """The directions that keep the level optimal: ``Z <- Z Q_2``, less those of the
        constraints the level's own optimum presses on where a QP ran."""
        solver = self.solver
        Z = Z_level = self.Z  # (the free directions the level was solved in)
        if step.rank:
            null = step.null if step.null is not None else np.zeros((self.r, 0))
            Z = null if Z is None else Z.dot(null)
        if report.qp and step.m and (Z is None or Z.shape[1] > 0):
            # the Tikhonov term shifts the level's optimum by about d |y|: that much
            # gradient is not the level's own
            smax = step.sigma_max()
            delta = solver.regularization * (smax * smax if smax > 0 else 1.0)
            pins = strongly_active(lev, self.x, Z_level, self.bounds(), delta, solver.tolerance,
                                   solver.active_tolerance, solver.rank_tolerance)  # fmt: skip
            if pins is not None:
                # (pins are rows of unit size: box rows, or inherited rows, scaled below)
                floor = solver.rank_tolerance * float(np.abs(pins).max())
                Z = null_space(pins.dot(Z) if Z is not None else pins, Z,
                               solver.rank_tolerance, floor)  # fmt: skip
        self.Z = Z
        self.r = self.x.shape[0] if Z is None else Z.shape[1]

    def _inherit(self, k: int, lev: LevelProblem, report: LevelReport) -> None:
        """The level's inequality rows for the levels below (a row left violated pinned where
        it is), and the relaxed box widened to contain ``x``."""
        if lev.C.shape[0]:
            bt = self.solver.bound_relaxation
            Cx = lev.C.dot(self.x)
            viol, names = violated(lev, Cx, self.solver.tolerance)
            if report.qp:
                report.limited += names
            glo = np.minimum(np.where(viol, Cx, lev.lower), Cx) - bt
            ghi = np.maximum(np.where(viol, Cx, lev.upper), Cx) + bt
            self.inherited.append((lev.C.copy(), glo, ghi))
        if k != len(self.problem.levels) - 1 or self.any_qp:  # else nothing reads lo, hi
            np.minimum(self.lo, self.x, out=self.lo)
            np.maximum(self.hi, self.x, out=self.hi)

    # ------------------------------------------------------------------ the tie-break
    def _tie_break(self) -> np.ndarray:
        """The minimum-norm point of the last optimal set ``(x + range Z) & box & inherited``.

        Needed only when a level QP ran (its own tie-break term is weighted by the small
        ``regularization`` and resolves the minimum norm only to about eps / regularization);
        here it is exact: ``min 1/2 ||x + Z y||^2``, a Hessian of I.
        """
        x, Z = self.x, self.Z
        lo, hi, inherited = self.bounds()
        t = x if Z is None else Z.T.dot(x)
        xc = x - (t if Z is None else Z.dot(t))
        if inside(xc, lo, hi, inherited):
            return xc
        r = t.shape[0]
        # the box and the inherited rows, widened to contain x, as in the level QPs
        rows, lows, ups, lb, ub = free_constraints(x, Z, lo, hi, inherited, r, r)
        C, cl, cu = stacked(rows, lows, ups, r)
        solver = self.solver
        sol = solver._engine(len(self.reports)).solve(np.eye(r), t, C, cl, cu, lb, ub)
        if sol.status > QPStatus.INACCURATE or not np.all(np.isfinite(sol.x)):
            status = sol.status.name.lower()
            self.failures.append(f"minimum-norm tie-break: {status} ({solver.engine_name}); "
                                 "kept the last level's answer")  # fmt: skip
            return x
        return x + (sol.x if Z is None else Z.dot(sol.x))

    def _skip_nonfinite(self, lev: LevelProblem, report: LevelReport) -> None:
        """Skip a level whose rows are not numbers, naming the tasks to blame."""
        bad = nonfinite_tasks(lev)
        self.failures.append(f"{lev.name}: non-finite rows from {', '.join(bad)}; level skipped")
        report.limited, report.failed = bad, True
