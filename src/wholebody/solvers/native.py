r"""daqp's own hierarchical mode: the HQP's ``method="native"`` (opt-in, daqp only).

At the first level whose unconstrained candidate leaves the box, the cascade
(:mod:`wholebody.solvers.cascade`) hands the rest of the stack to **one** call of daqp's
hierarchical mode: the box as the first level, then each level's equality rows
(``b <= A x <= b``) and inequality rows, soft, with break points between levels and ``H = I``
(the minimum-norm tie-break). daqp solves the levels in turn, fixing each level's slacks
before the next.

Its soft weights are set **uniform** (``rho_soft``) on every row: with its defaults daqp
minimises a row-normalised residual, not the level's least squares. Each level's optimum is
then exact up to about ``rho_soft |x|^2`` in its objective.

The soft weights can also let a lower level pull a higher one off its optimum. So, where the
box cost the level daqp starts from something, daqp's answer is checked against that level's
optimality conditions and, where those do not certify it, against the level's own QP (one
cascade QP, :func:`~wholebody.solvers.level_qp.level_qp`); the cascade takes over if daqp
missed it (:func:`native_step`). The levels below are not checked: that is why the method is
opt-in. If daqp fails, the cascade solves the step.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from wholebody._numeric import all_finite, any_true
from wholebody.solvers.level_qp import level_qp
from wholebody.solvers.level_report import LevelReport
from wholebody.solvers.optimality import (
    bound_limited,
    finite_level,
    on_box,
    optimal,
    violated,
    worse,
)
from wholebody.solvers.qp import QPStatus
from wholebody.solvers.stack import LevelProblem, StackProblem

if TYPE_CHECKING:
    from wholebody.solvers.cascade import Candidate, Cascade
    from wholebody.solvers.hqp import HierarchicalQPSolver

__all__ = ["DAQP_BIG", "NativeHierarchy", "native_step"]

DAQP_BIG = 1e20
"""An infinite bound for daqp (it treats ``|b| >= 1e20`` as absent)."""


class NativeHierarchy:
    """One daqp workspace for the whole stack, kept across control steps (warm start) while
    the stack's row counts stay the same.

    Attributes
    ----------
    model
        The ``daqp.Model``, or None before the first call and after a failure.
    """

    def __init__(self) -> None:
        self.key: tuple | None = None
        self.model: Any = None

    def reset(self) -> None:
        """Drop the workspace (the next call starts cold)."""
        self.key = self.model = None

    def _layout(self, problem: StackProblem) -> None:
        """The row buffers and daqp's break points (the last row of each level), made anew
        when the stack's row counts change."""
        n = problem.lower.shape[0]
        key = (n, *((lev.A.shape[0], lev.C.shape[0]) for lev in problem.levels))
        if key == self.key:
            return
        total = sum(a + c for a, c in key[1:])
        self._A = np.zeros((total, n))
        self._bl = np.empty(n + total)
        self._bu = np.empty(n + total)
        self._sense = np.zeros(n + total, dtype=np.int32)
        points, k = [n], n
        for a, c in key[1:]:
            if a + c:
                k += a + c
                points.append(k)
        self._bp = np.array(points, dtype=np.int32)
        self.model = None
        self.key = key

    def _rows(self, problem: StackProblem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """daqp's rows and bounds: the box, then each level's equality rows (``b <= A x <=
        b``) and inequality rows; rows daqp cannot take (zero, or non-finite: a level the
        cascade skips and reports) become inactive dummy rows; bounds clipped to
        ``+-DAQP_BIG``."""
        self._layout(problem)
        n = problem.lower.shape[0]
        A, bl, bu = self._A, self._bl, self._bu
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
        # inactive dummy row; so do NaN or inf rows, which would crash daqp
        norms = np.add.reduce(A * A, axis=1)
        zero = ~((norms >= 1e-24) & (norms < np.inf))
        zero |= np.isnan(bl[n:])
        zero |= np.isnan(bu[n:])
        if any_true(zero):
            A[zero] = 0.0
            A[zero, 0] = 1.0
            bl[n:][zero] = -DAQP_BIG
            bu[n:][zero] = DAQP_BIG
        for bound in (bl, bu):  # clip to +-DAQP_BIG (np.clip without its Python wrapper)
            np.maximum(bound, -DAQP_BIG, out=bound)
            np.minimum(bound, DAQP_BIG, out=bound)
        return A, bl, bu

    def _call(self, solver: HierarchicalQPSolver, A: np.ndarray, bl: np.ndarray,
              bu: np.ndarray, n: int) -> tuple[Any, int, dict]:  # fmt: skip
        """daqp's ``(x, exit flag, info)``: set up on the first call (soft weights
        ``rho_soft`` on every row), updated after (keeping the working set with warm start)."""
        model = self.model
        try:
            if model is None:
                import daqp

                model = daqp.Model()
                model.settings = {"rho_soft": solver.rho_soft, "primal_tol": 1e-9,
                                  "iter_limit": 2000, **solver.engine_settings}  # fmt: skip
                self._sense.fill(0)
                flag, _ = model.setup(np.eye(n), np.zeros(n), A, bu, bl, self._sense,
                                      self._bp)  # fmt: skip
                if flag < 0:
                    raise RuntimeError(f"setup exit flag {flag}")
                rho = np.full(bu.shape[0], solver.rho_soft)
                model.soft_weights(rho_l=rho, rho_u=rho)
                self.model = model
            elif solver.warm_start:
                model.update(A=A, bupper=bu, blower=bl)
            else:
                self._sense.fill(0)
                model.update(A=A, bupper=bu, blower=bl, sense=self._sense)
            x, _, flag, info = model.solve()
        except (RuntimeError, ValueError, TypeError) as exc:
            flag, x, info = -100, None, {"iterations": 0, "error": str(exc)}
        return x, flag, info

    def solve(self, solver: HierarchicalQPSolver, problem: StackProblem, first: int,
              reports: list[LevelReport], notes: list[str]) -> np.ndarray | None:  # fmt: skip
        """The whole stack in one call of daqp's hierarchical mode, the levels from ``first``
        marked as solved by it in ``reports``; None if daqp failed (the cascade then takes
        over from level ``first``; ``notes`` says so)."""
        A, bl, bu = self._rows(problem)
        x, flag, info = self._call(solver, A, bl, bu, problem.lower.shape[0])
        ok = flag in (1, 2) and x is not None and all_finite(np.asarray(x, dtype=float))
        status = QPStatus.SOLVED if ok else QPStatus.FAILED
        for rep in reports[first:]:
            rep.qp, rep.engine_status = True, status
        reports[first].iterations = int(info.get("iterations", 0))
        if not ok:
            self.model = None
            notes.append(f"daqp hierarchy failed (exit flag {flag}); solved by the cascade")
            return None
        return np.array(x, dtype=float)


def native_step(run: Cascade, k: int, lev: LevelProblem, step: Candidate, xc: np.ndarray,
                report: LevelReport,
                ) -> tuple[np.ndarray | None, np.ndarray | None, LevelReport]:  # fmt: skip
    """daqp's hierarchy from level ``k`` of the cascade ``run`` (its unconstrained candidate
    ``xc`` left the box), checked where the box cost the level something (see the module
    docstring). Returns ``(x, None, report)`` when daqp's answer stands (the levels below
    are solved); ``(None, xq, report)`` when it missed level k's optimum, ``xq`` that
    optimum and ``report`` the level's new report (the cascade goes on from there); and
    ``(None, None, report)`` when daqp failed or was not called (rows below that are not
    numbers)."""
    solver, problem = run.solver, run.problem
    if not all(finite_level(lv) for lv in problem.levels[k + 1 :]):
        return None, None, report
    xn = solver._native.solve(solver, problem, k, run.reports, run.notes)
    if xn is None:
        return None, None, report
    tol = solver.tolerance
    p = lev.C.shape[0]
    if step.m:
        report.limited = bound_limited(lev, lev.A.dot(xn) - lev.b, lev.A.dot(xc) - lev.b,
                                       on_box(xn, problem.lower, problem.upper), tol)  # fmt: skip
    if p:
        report.limited += violated(lev, lev.C.dot(xn), tol)[1]
    if report.limited and not (p == 0 and optimal(lev, xn, run.Z, run.bounds(),
                                                  solver.active_tolerance,
                                                  solver.rank_tolerance)):  # fmt: skip
        own = LevelReport(lev.name, free=report.free, rank=report.rank)
        xq = level_qp(solver, k, lev, run.x, run.Z, step.M, step.c, step.sigma_max(),
                      run.bounds(), own)  # fmt: skip
        if xq is not None and worse(lev, xn, xq, tol):
            for rep in run.reports[k + 1 :]:
                rep.qp, rep.engine_status, rep.iterations = False, None, 0
            own.qp = True
            run.reports[k] = own  # the level is the cascade's now
            run.notes.append(f"daqp hierarchy missed the optimum of {lev.name}; solved by the "
                             "cascade")  # fmt: skip
            return None, xq, own
    run.native_from = k
    for lv, rep in zip(problem.levels[k + 1 :], run.reports[k + 1 :], strict=True):
        if lv.C.shape[0]:
            rep.limited += violated(lv, lv.C.dot(xn), tol)[1]
    return xn, None, report
