"""A thin adapter over dense QP engines: daqp, proxsuite and osqp, selected by name.

Every engine solves the same problem::

    minimise    1/2 x^T H x + g^T x
    subject to  lower <= C x <= upper        (general rows, m >= 0; entries may be +-inf)
                lb    <= x   <= ub           (optional box on every variable; may be +-inf)

with ``H`` symmetric positive definite (the hierarchical solver always adds a small Tikhonov
term, so no engine has to handle a singular Hessian). An engine object owns one workspace
and reuses it while the problem keeps its structure (``n``, ``m``, box or not): the next
solve is then an update of the data and, with ``warm_start=True``, starts from the previous
solution (daqp: the previous working set; proxsuite: previous primal and dual iterates;
osqp: previous primal and dual iterates). A change of structure re-creates the workspace.

The adapters are written against each engine's own Python API, because the hot path needs
the workspace kept between calls; any other solver that :mod:`qpsolvers` can call serves
through the generic engine ``"qpsolvers:<solver>"``
(:mod:`wholebody.solvers.qpsolvers_engine`), which builds a new problem on every call.

``daqp``
    Dual active-set method; exact up to round-off on strictly convex problems: the fastest
    on the hierarchical solver's problems, and the default.
``proxsuite``
    Proximal augmented Lagrangian (dense backend), ``eps_abs`` 1e-9; its answers are less
    exact than daqp's. Warm start is configured *before* ``init()`` (switching it on between
    ``init()`` and the first ``solve()`` is not safe).
``osqp``
    ADMM (sparse, here with a dense pattern), ``eps`` 1e-7 and polishing; its answers are the
    least exact. Provided for comparison. Its polishing prints to the C stdout whatever
    ``verbose`` says; the adapter silences it.
"""

from __future__ import annotations

import enum
import importlib.util
import os
import sys
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

from wholebody.errors import SolverError

__all__ = [
    "ENGINES",
    "DaqpEngine",
    "OsqpEngine",
    "ProxsuiteEngine",
    "QPEngine",
    "QPSolution",
    "QPStatus",
    "available_engines",
    "make_engine",
]

#: Engine names accepted by :func:`make_engine`, fastest first on our problems.
ENGINES: tuple[str, ...] = ("daqp", "proxsuite", "osqp")

_BIG = 1e20  # stands for an infinite bound where an engine wants finite numbers


class QPStatus(enum.IntEnum):
    """Outcome of one QP solve."""

    SOLVED = 0
    """Optimal within the engine's tolerances."""
    INACCURATE = 1
    """The engine stopped with a usable but inaccurate point (iteration limit, osqp's
    "solved inaccurate")."""
    INFEASIBLE = 2
    """The engine declared the constraints infeasible."""
    FAILED = 3
    """Any other failure; ``x`` is not to be used."""


@dataclass
class QPSolution:
    """Result of :meth:`QPEngine.solve`: ``x`` (a new array; not finite only on FAILED),
    status, iterations and the engine's own status text."""

    x: np.ndarray
    status: QPStatus
    iterations: int
    message: str


_KNOWN: dict[str, frozenset[str]] = {}  # QPEngine.known_settings per engine name, once


class QPEngine(ABC):
    """One QP workspace of one engine (see the module docstring for the problem).

    Parameters
    ----------
    warm_start
        Start each solve from the previous one while the structure is unchanged.
    settings
        Engine-specific settings, passed through (daqp: ``primal_tol``, ``iter_limit``, ...;
        proxsuite: ``eps_abs``, ``max_iter``, ...; osqp: ``eps_abs``, ``polishing``, ...).
    """

    name: str = ""

    def __init__(self, *, warm_start: bool = True, **settings: Any) -> None:
        self.warm_start = warm_start
        self._check_settings(settings)
        self.settings = dict(self.default_settings())
        self.settings.update(settings)
        self._shape: tuple[int, int, bool] | None = None
        self.setups = 0
        """How many times the workspace was (re-)created."""

    @staticmethod
    def default_settings() -> dict[str, Any]:
        return {}

    def _check_settings(self, settings: dict[str, Any]) -> None:
        """Raise :class:`SolverError` for a setting the engine does not know (on
        construction, not at the first solve)."""
        known = _KNOWN.get(self.name)
        if known is None:
            known = _KNOWN[self.name] = frozenset(self.known_settings())
        unknown = sorted(set(settings) - known)
        if unknown:
            raise SolverError(
                f"{self.name}: unknown setting(s) {', '.join(unknown)}; known: "
                f"{', '.join(sorted(known))}"
            )

    def known_settings(self) -> set[str]:
        """The setting names the engine accepts."""
        raise NotImplementedError

    def reset(self) -> None:
        """Forget the workspace (the next solve starts cold)."""
        self._shape = None

    def solve(
        self,
        H: np.ndarray,
        g: np.ndarray,
        C: np.ndarray,
        lower: np.ndarray,
        upper: np.ndarray,
        lb: np.ndarray | None = None,
        ub: np.ndarray | None = None,
    ) -> QPSolution:
        """Solve ``min 1/2 x'Hx + g'x`` s.t. ``lower <= C x <= upper``, ``lb <= x <= ub``."""
        n, m = g.shape[0], C.shape[0]
        crossed = np.count_nonzero(lower > upper) + (
            0 if lb is None else np.count_nonzero(lb > ub)  # type: ignore[operator]
        )
        if crossed:  # no engine is needed to see it (and some fail on it in setup)
            return QPSolution(
                np.full(n, np.nan),
                QPStatus.INFEASIBLE,
                0,
                f"{self.name}: {crossed} lower bound(s) above the upper",
            )
        shape = (n, m, lb is not None)
        try:
            if shape != self._shape:
                self._shape = None
                self._setup(H, g, C, lower, upper, lb, ub)
                self._shape = shape
                self.setups += 1
            else:
                self._update(H, g, C, lower, upper, lb, ub)
            sol = self._solve()
        except (
            ValueError,
            RuntimeError,
            TypeError,
            ArithmeticError,
            IndexError,
            *self._errors,
        ) as exc:
            self._shape = None
            return QPSolution(np.full(n, np.nan), QPStatus.FAILED, 0, f"{self.name}: {exc}")
        if sol.status <= QPStatus.INACCURATE and not np.all(np.isfinite(sol.x)):
            sol.status = QPStatus.FAILED
            sol.message += " (non-finite solution)"
        if sol.status >= QPStatus.INFEASIBLE:
            self._shape = None  # do not warm-start from a failed solve
        return sol

    _errors: tuple[type[BaseException], ...] = ()
    """The engine package's own exception types (reported as FAILED, never raised)."""

    @abstractmethod
    def _setup(self, H, g, C, lower, upper, lb, ub) -> None: ...

    @abstractmethod
    def _update(self, H, g, C, lower, upper, lb, ub) -> None: ...

    @abstractmethod
    def _solve(self) -> QPSolution: ...

    def __repr__(self) -> str:
        return f"{type(self).__name__}(warm_start={self.warm_start})"


# ---------------------------------------------------------------------------------- daqp
class DaqpEngine(QPEngine):
    """daqp's reusable workspace (``daqp.Model``): setup once, then ``update`` + ``solve``.

    Warm start: ``Model.update`` without ``sense`` keeps the working set of the previous solve
    (daqp's own warm start); without warm start the sense flags are reset to zero each time.
    Infinite bounds are passed as +-1e20 (daqp treats |b| >= 1e20 as absent).
    """

    name = "daqp"

    @staticmethod
    def default_settings() -> dict[str, Any]:
        # Tighter primal tolerance than daqp's 1e-6: the hierarchical solver inherits the
        # box into the next level, where a 1e-6 violation would show.
        return {"primal_tol": 1e-9, "iter_limit": 2000}

    def __init__(self, *, warm_start: bool = True, **settings: Any) -> None:
        import daqp

        self._daqp = daqp
        super().__init__(warm_start=warm_start, **settings)

    def known_settings(self) -> set[str]:
        return set(self._daqp.Model().settings)

    def _bounds(self, lower, upper, lb, ub) -> None:
        nb = 0 if lb is None else lb.shape[0]
        if lb is not None:
            self._bl[:nb] = lb
            self._bu[:nb] = ub
        self._bl[nb:] = lower
        self._bu[nb:] = upper
        np.clip(self._bl, -_BIG, _BIG, out=self._bl)
        np.clip(self._bu, -_BIG, _BIG, out=self._bu)

    def _setup(self, H, g, C, lower, upper, lb, ub) -> None:
        self._n = g.shape[0]
        total = C.shape[0] + (0 if lb is None else lb.shape[0])
        self._bl = np.empty(total)
        self._bu = np.empty(total)
        self._sense = np.zeros(total, dtype=np.int32)
        self._bounds(lower, upper, lb, ub)
        self._model = self._daqp.Model()
        self._model.settings = self.settings
        flag, _ = self._model.setup(H, g, C, self._bu, self._bl, self._sense)
        self._infeasible = flag == -1  # setup already proved the constraints inconsistent
        if flag < 0 and not self._infeasible:
            raise RuntimeError(f"daqp setup failed with exit flag {flag}")

    def _update(self, H, g, C, lower, upper, lb, ub) -> None:
        self._bounds(lower, upper, lb, ub)
        args = {"H": H, "f": g}
        if self._bu.shape[0]:  # daqp's update indexes the first bound even when there is none
            args.update(bupper=self._bu, blower=self._bl)
        if C.shape[0]:  # and A's first row
            args["A"] = C
        if not self.warm_start:
            self._sense.fill(0)
            args["sense"] = self._sense
        flag = self._model.update(**args)
        if flag is not None and flag < 0:
            raise RuntimeError(f"daqp update failed with exit flag {flag}")

    def _solve(self) -> QPSolution:
        if self._infeasible:
            self._infeasible = False
            return QPSolution(
                np.full(self._n, np.nan), QPStatus.INFEASIBLE, 0, "daqp exit flag -1 (setup)"
            )
        x, _, flag, info = self._model.solve()
        it = int(info.get("iterations", 0))
        if flag == 1 or flag == 2:  # optimal (2: optimal with soft constraints relaxed)
            status = QPStatus.SOLVED
        elif flag == -4:  # iteration limit
            status = QPStatus.INACCURATE
        elif flag == -1:
            status = QPStatus.INFEASIBLE
        else:
            status = QPStatus.FAILED
        return QPSolution(np.array(x, dtype=float), status, it, f"daqp exit flag {flag}")


# ----------------------------------------------------------------------------- proxsuite
class ProxsuiteEngine(QPEngine):
    """proxsuite's dense ProxQP with its own box (``box_constraints=True`` when a box is
    given). Warm start: ``WARM_START_WITH_PREVIOUS_RESULT``, set before ``init()``."""

    name = "proxsuite"

    @staticmethod
    def default_settings() -> dict[str, Any]:
        # The infeasibility certificates' tolerances far below proxsuite's (1e-4): at its
        # defaults it declares benign, feasible 1-variable QPs infeasible, and the cascade's
        # QPs are feasible and strictly convex by construction.
        return {
            "eps_abs": 1e-9,
            "eps_rel": 0.0,
            "eps_primal_inf": 1e-14,
            "eps_dual_inf": 1e-14,
            "max_iter": 1000,
            "max_iter_in": 100,
            "verbose": False,
        }

    def __init__(self, *, warm_start: bool = True, **settings: Any) -> None:
        from proxsuite import proxqp

        self._proxqp = proxqp
        self.update_preconditioner = bool(settings.pop("update_preconditioner", True))
        super().__init__(warm_start=warm_start, **settings)

    def known_settings(self) -> set[str]:
        return {a for a in dir(self._proxqp.Settings()) if not a.startswith("_")}

    @staticmethod
    def _finite(v: np.ndarray | None) -> np.ndarray | None:
        return None if v is None else np.clip(v, -_BIG, _BIG)

    def _setup(self, H, g, C, lower, upper, lb, ub) -> None:
        pq = self._proxqp
        n, m = g.shape[0], C.shape[0]
        qp = pq.dense.QP(n, 0, m, lb is not None)
        for key, value in self.settings.items():
            setattr(qp.settings, key, value)
        # Before init(): switching warm start on between init() and the first solve() is not
        # safe.
        guess = pq.InitialGuess
        qp.settings.initial_guess = (
            guess.WARM_START_WITH_PREVIOUS_RESULT if self.warm_start else guess.NO_INITIAL_GUESS
        )
        args: dict[str, Any] = {"H": H, "g": g, "A": None, "b": None}
        if m:
            args.update(C=C, l=self._finite(lower), u=self._finite(upper))
        if lb is not None:
            args.update(l_box=self._finite(lb), u_box=self._finite(ub))
        qp.init(**args)
        self._qp = qp

    def _update(self, H, g, C, lower, upper, lb, ub) -> None:
        args: dict[str, Any] = {"H": H, "g": g}
        if C.shape[0]:
            args.update(C=C, l=self._finite(lower), u=self._finite(upper))
        if lb is not None:
            args.update(l_box=self._finite(lb), u_box=self._finite(ub))
        self._qp.update(update_preconditioner=self.update_preconditioner, **args)

    def _solve(self) -> QPSolution:
        pq = self._proxqp
        self._qp.solve()
        res = self._qp.results
        st = res.info.status
        if st == pq.PROXQP_SOLVED:
            status = QPStatus.SOLVED
        elif st in (pq.PROXQP_MAX_ITER_REACHED, pq.PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE):
            # proxsuite runs out of iterations on an infeasible problem instead of detecting
            # it: usable only if the constraints nearly hold
            tol = 1e3 * max(float(self.settings.get("eps_abs", 1e-9)), 1e-9)
            status = QPStatus.INACCURATE if res.info.pri_res <= tol else QPStatus.INFEASIBLE
        elif st == pq.PROXQP_PRIMAL_INFEASIBLE:
            status = QPStatus.INFEASIBLE
        else:
            status = QPStatus.FAILED
        return QPSolution(
            np.array(res.x, dtype=float), status, int(res.info.iter), f"proxsuite {st}"
        )


# ---------------------------------------------------------------------------------- osqp
class OsqpEngine(QPEngine):
    """OSQP with a dense sparsity pattern (so that ``update(Px, Ax)`` keeps the structure);
    the box is appended to the rows as an identity block. Polishing is on by default."""

    name = "osqp"

    @staticmethod
    def default_settings() -> dict[str, Any]:
        return {
            "eps_abs": 1e-7,
            "eps_rel": 1e-7,
            "polishing": True,
            "max_iter": 10000,
            "verbose": False,
        }

    def __init__(self, *, warm_start: bool = True, **settings: Any) -> None:
        import osqp
        import scipy.sparse

        self._osqp = osqp
        self._sparse = scipy.sparse
        self._errors = (osqp.OSQPException,)
        super().__init__(warm_start=warm_start, **settings)

    def _check_settings(self, settings: dict[str, Any]) -> None:
        # osqp lists no names (it takes aliases and deprecated ones): a 1 x 1 setup says
        if "warm_starting" in settings:
            raise SolverError("osqp: warm_starting is set by the engine's warm_start argument")
        if not settings:
            return
        one = self._sparse.csc_matrix(np.ones((1, 1)))
        try:
            self._osqp.OSQP().setup(
                one, np.zeros(1), one, -np.ones(1), np.ones(1), **{"verbose": False, **settings}
            )
        except (ValueError, TypeError) as exc:
            raise SolverError(f"osqp: {exc}") from None

    def _data(self, H, C, lower, upper, lb, ub) -> None:
        m = C.shape[0]
        self._Px[:] = H[self._iu]
        self._Ax[:, :m] = C.T
        np.clip(lower, -_BIG, _BIG, out=self._l[:m])
        np.clip(upper, -_BIG, _BIG, out=self._u[:m])
        if lb is not None:
            np.clip(lb, -_BIG, _BIG, out=self._l[m:])
            np.clip(ub, -_BIG, _BIG, out=self._u[m:])

    def _setup(self, H, g, C, lower, upper, lb, ub) -> None:
        sp = self._sparse
        n, m = g.shape[0], C.shape[0]
        self._n = n
        box = lb is not None
        # Upper triangle of H, column by column (CSC order).
        rows, cols = np.triu_indices(n)
        order = np.lexsort((rows, cols))
        self._iu = (rows[order], cols[order])
        self._Px = np.empty(order.size)
        # Rows: C (dense) then the identity of the box; CSC, column j holds C[:, j] then 1.
        k = m + (1 if box else 0)
        self._Ax = np.ones((n, k))
        indices = np.tile(np.arange(m), (n, 1))
        if box:
            indices = np.hstack([indices, m + np.arange(n)[:, None]])
        self._l = np.empty(m + (n if box else 0))
        self._u = np.empty_like(self._l)
        self._data(H, C, lower, upper, lb, ub)
        P = sp.csc_matrix(
            (self._Px, self._iu[0], np.r_[0, np.cumsum(np.arange(1, n + 1))]), shape=(n, n)
        )
        A = sp.csc_matrix(
            (self._Ax.ravel(), indices.ravel(), np.arange(n + 1) * k), shape=(self._l.shape[0], n)
        )
        solver = self._osqp.OSQP()
        solver.setup(P, g, A, self._l, self._u, warm_starting=self.warm_start, **self.settings)
        self._solver = solver

    def _update(self, H, g, C, lower, upper, lb, ub) -> None:
        self._data(H, C, lower, upper, lb, ub)
        self._solver.update(q=g, l=self._l, u=self._u, Px=self._Px, Ax=self._Ax.ravel())

    def _solve(self) -> QPSolution:
        if self.settings.get("polishing"):
            # osqp's C code prints "Polishing not needed ..." whatever ``verbose`` says
            with _quiet_stdout():
                res = self._solver.solve(raise_error=False)
        else:
            res = self._solver.solve(raise_error=False)
        st = int(res.info.status_val)
        S = self._osqp.SolverStatus
        if st == S.OSQP_SOLVED:
            status = QPStatus.SOLVED
        elif st in (S.OSQP_SOLVED_INACCURATE, S.OSQP_MAX_ITER_REACHED):
            status = QPStatus.INACCURATE
        elif st in (S.OSQP_PRIMAL_INFEASIBLE, S.OSQP_PRIMAL_INFEASIBLE_INACCURATE):
            status = QPStatus.INFEASIBLE
        else:
            status = QPStatus.FAILED
        x = res.x
        x = np.full(self._n, np.nan) if x is None else np.array(x, dtype=float)
        return QPSolution(x, status, int(res.info.iter), f"osqp {res.info.status}")


class _quiet_stdout:  # noqa: N801 - used as a context manager
    """Silence file descriptor 1 (C-level prints) for the duration of a ``with`` block
    (nothing is silenced with ``keep=True``)."""

    _null: int | None = None

    def __init__(self, keep: bool = False) -> None:
        self.keep = keep

    def __enter__(self) -> None:
        if self.keep:
            return
        if _quiet_stdout._null is None:
            _quiet_stdout._null = os.open(os.devnull, os.O_WRONLY)
        sys.stdout.flush()
        self._saved = os.dup(1)
        os.dup2(_quiet_stdout._null, 1)

    def __exit__(self, *exc: object) -> None:
        if self.keep:
            return
        os.dup2(self._saved, 1)
        os.close(self._saved)


# ------------------------------------------------------------------------------ registry
_CLASSES: dict[str, tuple[type[QPEngine], str]] = {
    "daqp": (DaqpEngine, "daqp"),
    "proxsuite": (ProxsuiteEngine, "proxsuite"),
    "osqp": (OsqpEngine, "osqp"),
}


def available_engines() -> list[str]:
    """The built-in engine names whose Python package is importable here (the qpsolvers
    ones: :func:`wholebody.solvers.qpsolvers_engine.qpsolvers_engines`)."""
    return [name for name, (_, mod) in _CLASSES.items() if importlib.util.find_spec(mod)]


def make_engine(name: str, *, warm_start: bool = True, **settings: Any) -> QPEngine:
    """A new engine workspace by name: ``"daqp"``, ``"proxsuite"``, ``"osqp"``, or
    ``"qpsolvers:<solver>"`` for any solver in ``qpsolvers.available_solvers``
    (:mod:`wholebody.solvers.qpsolvers_engine`).

    Raises
    ------
    SolverError
        Unknown name, or the engine's package is not installed.
    """
    key = str(name).lower()
    if key.startswith("qpsolvers:"):
        from wholebody.solvers.qpsolvers_engine import PREFIX, QpsolversEngine

        return QpsolversEngine(key[len(PREFIX) :], warm_start=warm_start, **settings)
    if key not in _CLASSES:
        raise SolverError(
            f"unknown QP engine {name!r}; expected one of {', '.join(ENGINES)} "
            "or 'qpsolvers:<solver>'"
        )
    cls, module = _CLASSES[key]
    if importlib.util.find_spec(module) is None:
        raise SolverError(
            f"QP engine {name!r} needs the Python package {module!r}, which is not installed"
        )
    return cls(warm_start=warm_start, **settings)
