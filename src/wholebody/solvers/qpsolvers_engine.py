r"""Any QP solver that :mod:`qpsolvers` can call, as a QP engine: ``"qpsolvers:<solver>"``.

``HierarchicalQPSolver(engine="qpsolvers:quadprog")`` (or ``make_engine("qpsolvers:...")``)
lets a solver the user installed for qpsolvers serve the levels, beside the warm-started
adapters of :mod:`wholebody.solvers.qp`. The engine contract

.. math::

    \min_x \tfrac12 x^T H x + g^T x \quad\text{s.t.}\quad
    lower \le C x \le upper,\quad lb \le x \le ub

maps onto :func:`qpsolvers.solve_problem`'s
``min 1/2 x^T P x + q^T x`` s.t. ``G x <= h``, ``A x = b``, ``lb <= x <= ub``:

* a row with ``lower_i = upper_i`` (finite) is an equality row of ``A x = b`` (two opposite
  inequalities would make the constraints degenerate for active-set solvers);
* every other row gives one one-sided row of ``G x <= h`` per finite bound:
  ``C_i x <= upper_i`` and ``-C_i x <= -lower_i``; an infinite bound gives none;
* the box is passed as ``lb``, ``ub`` when all its entries are finite; otherwise its finite
  entries become rows ``x_j <= ub_j``, ``-x_j <= -lb_j`` of ``G x <= h`` (not every solver
  takes infinite box entries).

Statuses: SOLVED when the solver found a solution (``Solution.found``); otherwise a
feasibility LP of the same constraints (scipy's HiGHS) tells INFEASIBLE from FAILED, the
same for every solver. qpsolvers' warnings, and the solvers' prints to the C stdout, are
silenced unless the setting ``verbose`` is true: the status says what happened.

Tolerances are the solver's own defaults unless given as settings; some are loose for a
hierarchy, whose levels inherit each other's answers (qpsolvers' proxqp stops at
``eps_abs = 1e-3``): e.g. ``engine_settings={"eps_abs": 1e-9, "eps_rel": 0.0}`` for
``"qpsolvers:proxqp"``, ``{"primal_tol": 1e-9}`` for ``"qpsolvers:daqp"``.

qpsolvers builds a new problem on every call, so nothing is kept between solves but, with
``warm_start=True``, the previous solution, passed as ``initvals`` while the structure is
unchanged (solvers that take no initial guess ignore it). Settings are passed to the solver
as keyword arguments; a setting the solver refuses is an error on construction (a trial solve
of a one-variable QP).
"""

from __future__ import annotations

import importlib.util
import warnings
from typing import Any

import numpy as np

from wholebody.errors import SolverError
from wholebody.solvers.qp import QPEngine, QPSolution, QPStatus, _quiet_stdout

__all__ = ["PREFIX", "QpsolversEngine", "qpsolvers_engines"]

PREFIX = "qpsolvers:"
"""Engine names ``"qpsolvers:<solver>"`` select this engine with qpsolvers' ``<solver>``."""


def _qpsolvers() -> Any:
    """The qpsolvers package, or a :class:`SolverError` when it is not installed."""
    if importlib.util.find_spec("qpsolvers") is None:
        raise SolverError(
            "QP engines 'qpsolvers:<solver>' need the Python package "
            "'qpsolvers', which is not installed"
        )
    import qpsolvers

    return qpsolvers


def qpsolvers_engines() -> list[str]:
    """The engine names ``"qpsolvers:<solver>"`` of the solvers qpsolvers finds installed
    here (``qpsolvers.available_solvers``; empty without qpsolvers)."""
    if importlib.util.find_spec("qpsolvers") is None:
        return []
    return [PREFIX + name for name in _qpsolvers().available_solvers]


class QpsolversEngine(QPEngine):
    """A qpsolvers solver behind the engine contract (see the module docstring).

    Parameters
    ----------
    solver
        qpsolvers' name of the solver, one of ``qpsolvers.available_solvers``.
    warm_start
        Pass the previous solution as ``initvals`` while the problem keeps its structure.
    settings
        Keyword arguments of the solver (e.g. ``eps_abs`` for proxqp and osqp,
        ``primal_tol`` for daqp), passed through :func:`qpsolvers.solve_problem`.
    """

    def __init__(self, solver: str, *, warm_start: bool = True, **settings: Any) -> None:
        qpsolvers = _qpsolvers()
        solver = str(solver).lower()
        if solver not in qpsolvers.available_solvers:
            raise SolverError(
                f"unknown qpsolvers solver {solver!r} (engine {PREFIX + solver!r}); "
                "qpsolvers.available_solvers here: "
                f"{', '.join(qpsolvers.available_solvers) or 'none'}"
            )
        self._qp = qpsolvers
        self.solver = solver
        self.name = PREFIX + solver
        self._sparse = solver not in qpsolvers.dense_solvers  # takes scipy.sparse matrices
        self._errors = (qpsolvers.QPError,)
        self._x: np.ndarray | None = None
        super().__init__(warm_start=warm_start, **settings)

    def _check_settings(self, settings: dict[str, Any]) -> None:
        """Refuse on construction a setting the solver does not take: a trial solve of
        ``min x^2/2`` with ``-1 <= x <= 1``."""
        if not settings:
            return
        problem = self._qp.Problem(np.eye(1), np.zeros(1), lb=-np.ones(1), ub=np.ones(1))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._qp.solve_problem(self._matrices(problem), self.solver, **settings)
        except (TypeError, ValueError, self._qp.QPError) as exc:
            raise SolverError(
                f"{self.name}: setting(s) {', '.join(sorted(settings))} refused: {exc}"
            ) from None

    def _setup(self, H, g, C, lower, upper, lb, ub) -> None:
        self._x = None  # a new structure: nothing to warm-start from
        self._update(H, g, C, lower, upper, lb, ub)

    def _update(self, H, g, C, lower, upper, lb, ub) -> None:
        self._problem = self._matrices(_problem(self._qp, H, g, C, lower, upper, lb, ub))

    def _matrices(self, problem: Any) -> Any:
        """``problem`` with its matrices in the solver's format (scipy.sparse CSC for a
        solver that takes no dense ones)."""
        if self._sparse:
            from scipy import sparse

            for key in ("P", "G", "A"):
                value = getattr(problem, key)
                if value is not None:
                    setattr(problem, key, sparse.csc_matrix(value))
        return problem

    def _solve(self) -> QPSolution:
        problem = self._problem
        initvals = self._x if self.warm_start else None
        with warnings.catch_warnings(), _quiet_stdout(self.settings.get("verbose", False)):
            warnings.simplefilter("ignore")
            sol = self._qp.solve_problem(problem, self.solver, initvals=initvals, **self.settings)
        n = problem.q.shape[0]
        x = None if sol.x is None else np.array(sol.x, dtype=float).reshape(-1)
        if sol.found and x is not None and x.shape[0] == n:
            self._x = x
            return QPSolution(x, QPStatus.SOLVED, _iterations(sol), f"{self.name}: solved")
        self._x = None
        status = QPStatus.INFEASIBLE if _infeasible(problem) else QPStatus.FAILED
        return QPSolution(
            np.full(n, np.nan),
            status,
            _iterations(sol),
            f"{self.name}: no solution found ({status.name.lower()})",
        )


def _problem(
    qpsolvers: Any,
    H: np.ndarray,
    g: np.ndarray,
    C: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    lb: np.ndarray | None,
    ub: np.ndarray | None,
) -> Any:
    """The engine's QP as a :class:`qpsolvers.Problem` (see the module docstring)."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    rows, bounds = [C], [(lower, upper)]
    infinite_box = lb is not None and not (np.all(np.isfinite(lb)) and np.all(np.isfinite(ub)))
    if infinite_box:  # its finite entries as rows
        n = g.shape[0]
        rows.append(np.eye(n))
        bounds.append((np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)))
        lb = ub = None
    R = np.vstack(rows)
    lo = np.concatenate([b[0] for b in bounds])
    hi = np.concatenate([b[1] for b in bounds])
    equal = (lo == hi) & np.isfinite(lo)
    up = np.isfinite(hi) & ~equal
    down = np.isfinite(lo) & ~equal
    G = np.vstack((R[up], -R[down]))
    h = np.concatenate((hi[up], -lo[down]))
    return qpsolvers.Problem(
        H,
        g,
        G if h.size else None,
        h if h.size else None,
        R[equal] if equal.any() else None,
        lo[equal] if equal.any() else None,
        None if lb is None else np.asarray(lb, dtype=float),
        None if ub is None else np.asarray(ub, dtype=float),
    )


def _infeasible(problem: Any) -> bool:
    """Whether the constraints of ``problem`` admit no point: a feasibility LP (HiGHS)."""
    from scipy.optimize import linprog
    from scipy.sparse import issparse

    def dense(M: Any) -> Any:
        return M.toarray() if issparse(M) else M

    n = problem.q.shape[0]
    lb = [None] * n if problem.lb is None else [v if np.isfinite(v) else None for v in problem.lb]
    ub = [None] * n if problem.ub is None else [v if np.isfinite(v) else None for v in problem.ub]
    try:
        lp = linprog(
            np.zeros(n),
            A_ub=dense(problem.G),
            b_ub=problem.h,
            A_eq=dense(problem.A),
            b_eq=problem.b,
            bounds=list(zip(lb, ub, strict=True)),
            method="highs",
        )
    except ValueError:
        return False
    return lp.status == 2


def _iterations(sol: Any) -> int:
    """The solver's iteration count where qpsolvers reports it (``extras``), else 0."""
    extras = sol.extras if isinstance(sol.extras, dict) else {}
    if "iterations" in extras:
        return int(
            extras["iterations"][0] if np.ndim(extras["iterations"]) else extras["iterations"]
        )
    info = extras.get("info")
    for attr in ("iter", "iterations"):
        value = getattr(info, attr, None)
        if isinstance(value, (int, np.integer)):
            return int(value)
    return 0
