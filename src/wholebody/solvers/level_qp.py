r"""One level's QP in the cascade (:mod:`wholebody.solvers.cascade`), and its exact answer.

In the free coordinates ``(y, s)`` of the level (``x + Z y``, ``Z`` the directions the levels
above leave free, ``s`` the slack of its inequality rows)::

    min  1/2 ||M y - c||^2 + d/2 ||y||^2 + 1/2 ||s||^2
    s.t. lo - x <= Z y <= hi - x                     (the box, relaxed)
         glo - G x <= G Z y <= ghi - G x             (the inherited rows, widened to hold 0)
         lo_k - C_k x <= C_k Z y - s <= hi_k - C_k x (the level's own inequality rows)

with ``M = A_k Z``, ``c = b_k - A_k x`` and ``d = regularization * sigma_max(M)^2``: the
Tikhonov term makes the Hessian positive definite for every engine (a level with free
directions has a singular one). ``y = 0`` is feasible by construction (the box and the
inherited rows are widened to contain ``x``), so a level QP is never infeasible.

The answer is then made exact: :func:`polish` re-solves the level's least squares on the face
of the constraints active at the QP's answer (removing the Tikhonov bias ``d |y|``), and where
the answer still fails the level's optimality conditions, up to ``proximal_steps`` proximal
point QPs (the Tikhonov term centred on the last answer) walk off a face the term alone would
hold the answer on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import lsq_linear

from wholebody._numeric import any_true
from wholebody.solvers.level_report import LevelReport
from wholebody.solvers.linalg import cod, null_space
from wholebody.solvers.optimality import (
    Bounds,
    Inherited,
    box_optimal,
    inside,
    level_objective,
    optimal,
)
from wholebody.solvers.qp import QPEngine, QPSolution, QPStatus
from wholebody.solvers.stack import LevelProblem

if TYPE_CHECKING:
    from wholebody.solvers.hqp import HierarchicalQPSolver

__all__ = ["QP", "free_constraints", "level_qp", "polish", "stacked"]

FLAT = 1e-12
"""A QP row whose coefficients are at most this (relative to the row's size before the
restriction to the free directions) is left unbounded: the free directions move it only by
round-off."""


@dataclass(slots=True)
class QP:
    """A QP in the engines' form (:mod:`wholebody.solvers.qp`):
    ``min 1/2 y'Hy + g'y`` s.t. ``lower <= C y <= upper``, ``lb <= y <= ub`` (no box: None)."""

    H: np.ndarray
    g: np.ndarray
    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    lb: np.ndarray | None
    ub: np.ndarray | None

    def solve(self, engine: QPEngine) -> QPSolution:
        return engine.solve(self.H, self.g, self.C, self.lower, self.upper, self.lb, self.ub)


# ------------------------------------------------------------------ the constraints
Rows = list[np.ndarray]
Box = np.ndarray | None


def free_constraints(x: np.ndarray, Z: np.ndarray | None, lo: np.ndarray, hi: np.ndarray,
                     inherited: Inherited, r: int, nv: int,
                     ) -> tuple[Rows, Rows, Rows, Box, Box]:  # fmt: skip
    """The box and the inherited rows as constraints on ``y`` (``nv`` variables, the first
    ``r`` of them the free coordinates): ``(rows, lows, ups, lb, ub)``.

    With ``Z`` the identity (None) the box is the engine's box on ``y`` (``lb``, ``ub``; the
    other variables unbounded); otherwise it is the rows ``lo - x <= Z y <= hi - x``, rows
    flat in ``y`` unbounded (:func:`_flat`). The inherited rows are widened to contain
    ``y = 0`` (:func:`_widened`)."""
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
    return rows, lows, ups, lb, ub


def stacked(rows: list[np.ndarray], lows: list[np.ndarray], ups: list[np.ndarray],
            nv: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The rows and their bounds as one matrix and two vectors (empty ones without rows)."""
    if not rows:
        return np.zeros((0, nv)), np.zeros(0), np.zeros(0)
    return np.vstack(rows), np.concatenate(lows), np.concatenate(ups)


def _flat(Nz: np.ndarray, scale: float | np.ndarray, low: np.ndarray, up: np.ndarray) -> None:
    """Unbound, in place, the QP rows ``Nz y`` that the free directions move only at rounding
    level: largest coefficient at most ``FLAT max(1, scale)`` (``scale``: the size of the
    row before the restriction to the free directions). Such a row cannot be moved through
    ``y``, and two of opposite sign on joints at their bounds would pin ``y`` to 0 (a
    degenerate problem the engines solve wrongly or declare infeasible)."""
    if not Nz.shape[1]:
        return
    flat = np.abs(Nz).max(axis=1) <= FLAT * np.maximum(1.0, scale)
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
    """``G`` with zero columns appended up to ``nv`` (itself when it has them)."""
    if G.shape[1] == nv:
        return G
    out = np.zeros((G.shape[0], nv))
    out[:, : G.shape[1]] = G
    return out


# ------------------------------------------------------------------ the level's QP
def _level_problem(lev: LevelProblem, x: np.ndarray, Z: np.ndarray | None,
                   M: np.ndarray | None, c: np.ndarray | None, d: float, r: int,
                   bounds: Bounds) -> QP:  # fmt: skip
    """The level's QP in ``(y, s)`` (see the module docstring)."""
    lo, hi, inherited = bounds
    p = lev.C.shape[0]
    nv = r + p
    H = np.zeros((nv, nv))
    g = np.zeros(nv)
    if M is not None:
        H[:r, :r] = M.T.dot(M)
        g[:r] = -(M.T.dot(c))
    H[np.arange(r), np.arange(r)] += d
    if p:
        H[np.arange(r, nv), np.arange(r, nv)] = 1.0
    rows, lows, ups, lb, ub = free_constraints(x, Z, lo, hi, inherited, r, nv)
    if p:
        Cz = lev.C if Z is None else lev.C.dot(Z)
        Cx = lev.C.dot(x)
        own = np.zeros((p, nv))
        own[:, :r] = Cz
        own[np.arange(p), r + np.arange(p)] = -1.0
        rows.append(own)
        lows.append(lev.lower - Cx)
        ups.append(lev.upper - Cx)
    return QP(H, g, *stacked(rows, lows, ups, nv), lb, ub)


def _solve_with_retries(engine: QPEngine, qp: QP, d: float, r: int,
                        report: LevelReport) -> QPSolution | None:  # fmt: skip
    """The engine's answer, retried cold with 100 and 10000 times the Tikhonov term after a
    failure (an ill-conditioned, degenerate level); None when every attempt failed."""
    diag = np.arange(r)
    for attempt in range(3):
        if attempt:
            engine.reset()
            qp.H[diag, diag] += d * (100.0**attempt - 100.0 ** (attempt - 1))
            report.retries += 1
        sol = qp.solve(engine)
        report.engine_status = sol.status
        report.iterations += sol.iterations
        if sol.status <= QPStatus.INACCURATE and np.all(np.isfinite(sol.x)):
            return sol
    return None


def level_qp(solver: HierarchicalQPSolver, k: int, lev: LevelProblem, x: np.ndarray,
             Z: np.ndarray | None, M: np.ndarray | None, c: np.ndarray | None, smax: float,
             bounds: Bounds, report: LevelReport) -> np.ndarray | None:  # fmt: skip
    """The level's optimum ``x + Z y`` from its QP (``solver``'s engine ``k``), polished and,
    where needed, walked by proximal steps to the exact optimum; None when the engine
    failed. The Tikhonov term ``d = regularization * sigma_max^2`` keeps ``x``, in the
    directions the level leaves free, where the levels above put it (the minimum-norm choice
    is made once, exactly, by the cascade's tie-break)."""
    r = report.free
    p = lev.C.shape[0]
    d = solver.regularization * (smax * smax if smax > 0 else 1.0)
    qp = _level_problem(lev, x, Z, M, c, d, r, bounds)
    engine = solver._engine(k)
    sol = _solve_with_retries(engine, qp, d, r, report)
    if sol is None:
        return None
    y = sol.x[:r]
    if M is None:
        if p:  # only inequality rows: their slack is the level's least squares
            y = polish(solver, x, y, Z, np.zeros((0, r)), np.zeros(0), bounds, lev)
        return x + (y if Z is None else Z.dot(y))
    y = polish(solver, x, y, Z, M, c, bounds, lev if p else None)
    # Not needed where the answer already meets the level's optimality conditions (a level
    # that the bounds hold back: the common case).
    if p == 0 and optimal(lev, x + (y if Z is None else Z.dot(y)), Z, bounds,
                          solver.active_tolerance, solver.rank_tolerance):  # fmt: skip
        return x + (y if Z is None else Z.dot(y))
    y = _proximal_steps(solver, engine, qp, lev, x, y, Z, M, c, d, bounds, report)
    return x + (y if Z is None else Z.dot(y))


def _proximal_steps(solver: HierarchicalQPSolver, engine: QPEngine, qp: QP, lev: LevelProblem,
                    x: np.ndarray, y: np.ndarray, Z: np.ndarray | None, M: np.ndarray,
                    c: np.ndarray, d: float, bounds: Bounds,
                    report: LevelReport) -> np.ndarray:  # fmt: skip
    """Up to ``solver.proximal_steps`` proximal-point QPs from ``y``: the Tikhonov term
    ``d/2 ||y - y_last||^2`` centred on the last answer, each polished; kept while the
    level's residual (its objective, with inequality rows) decreases. The term alone can hold
    the answer on a face the exact optimum is not on (a long step bought with a small
    residual); these steps walk to the level's exact optimum within the constraints."""
    r = y.shape[0]
    p = lev.C.shape[0]
    g = qp.g
    g0 = g[:r].copy()
    tol = solver.tolerance * (1.0 + math.sqrt(c.dot(c)))
    f = level_objective(lev, x + (y if Z is None else Z.dot(y))) if p else 0.0
    res = c - M.dot(y)
    for _ in range(solver.proximal_steps):
        if math.sqrt(res.dot(res)) <= tol:
            break
        g[:r] = g0 - d * y
        sol = qp.solve(engine)
        report.iterations += sol.iterations
        if sol.status > QPStatus.INACCURATE or not np.all(np.isfinite(sol.x)):
            break
        yn = polish(solver, x, sol.x[:r], Z, M, c, bounds, lev if p else None)
        rn = c - M.dot(yn)
        fn = level_objective(lev, x + (yn if Z is None else Z.dot(yn))) if p else 0.0
        if p and fn > f:
            break
        better = math.sqrt(res.dot(res)) - math.sqrt(rn.dot(rn))
        if better <= 0.0:
            break
        y, res, f = yn, rn, fn
        if better <= 1e-3 * tol:
            break
    return y


# ------------------------------------------------------------------ the exact answer
def polish(solver: HierarchicalQPSolver, x: np.ndarray, y: np.ndarray, Z: np.ndarray | None,
           M: np.ndarray, c: np.ndarray, bounds: Bounds,
           lev: LevelProblem | None = None) -> np.ndarray:  # fmt: skip
    """Remove the Tikhonov bias: on the face of the constraints active at the QP's answer,
    the level's least squares is solved exactly (``y + W (M W)^+ (c - M y)``, ``W`` the
    directions that keep the active constraints still); kept if it stays feasible.

    With ``lev``, a level with inequality rows: the rows at or beyond a bound at the QP's
    answer join the least squares (their slack is ``C x - bound``), and the polished point
    is kept only if the level's objective (:func:`~.optimality.level_objective`) is lower
    there: otherwise the Tikhonov term would trade slack for step length, leaving a row met
    exactly at the optimum slightly violated.

    The Tikhonov term can also move the QP's answer onto another face than the exact
    optimum's. Where only the box bounds the level (the first level with a QP), a residual
    still above the tolerance is checked against the exact bounded least squares (BVLS,
    ``scipy.optimize.lsq_linear``), which is taken if it fits better."""
    if lev is not None:
        return _polish_with_rows(solver, x, y, Z, M, c, bounds, lev)
    return _polish_on_face(solver, x, y, Z, M, c, bounds)


def _polish_with_rows(solver: HierarchicalQPSolver, x: np.ndarray, y: np.ndarray,
                      Z: np.ndarray | None, M: np.ndarray, c: np.ndarray, bounds: Bounds,
                      lev: LevelProblem) -> np.ndarray:  # fmt: skip
    """:func:`polish` for a level with inequality rows (see there)."""
    xq = x + (y if Z is None else Z.dot(y))
    Cz = lev.C if Z is None else lev.C.dot(Z)
    Cx = lev.C.dot(x)
    v = Cx + Cz.dot(y)
    low = v <= lev.lower + 1e-8
    touch = low | (v >= lev.upper - 1e-8)
    if any_true(touch):
        bound = np.where(low, lev.lower, lev.upper)[touch]
        M = np.vstack((M, Cz[touch]))
        c = np.concatenate((c, bound - Cx[touch]))
    yp = _polish_on_face(solver, x, y, Z, M, c, bounds)
    if yp is y:
        return y
    xp = x + (yp if Z is None else Z.dot(yp))
    return yp if level_objective(lev, xp) < level_objective(lev, xq) else y


def _face(x: np.ndarray, xq: np.ndarray, Z: np.ndarray | None, M: np.ndarray, bounds: Bounds,
          rank_tolerance: float,
          ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:  # fmt: skip
    """The level's rows restricted to the face of the constraints active at ``xq`` (within
    1e-8): ``(M W, W, None)`` with ``W`` a basis of the directions that keep them still (None:
    all of them), or ``(M[:, free], None, free)`` where only bounds of ``x`` itself are active
    (``Z`` the identity): the entries not on a bound."""
    lo, hi, inherited = bounds
    act = 1e-8
    on = (xq <= lo + act) | (xq >= hi - act)
    grows = []
    for G, glo, ghi in inherited:
        Gx = G.dot(xq)
        gon = (Gx <= glo + act) | (Gx >= ghi - act)
        if gon.any():
            grows.append(G[gon])
    if Z is None and not grows:  # only bounds of x: keep those entries, move the others
        free = ~on
        return M[:, free], None, free
    rows = list(grows)
    if on.any():
        rows.insert(0, np.eye(x.shape[0])[on])
    if not rows:
        return M, None, None
    N = np.vstack(rows)
    W = null_space(N if Z is None else N.dot(Z), None, rank_tolerance)
    return M.dot(W), W, None


def _polish_on_face(solver: HierarchicalQPSolver, x: np.ndarray, y: np.ndarray,
                    Z: np.ndarray | None, M: np.ndarray, c: np.ndarray,
                    bounds: Bounds) -> np.ndarray:  # fmt: skip
    """:func:`polish` without inequality rows of the level's own: the exact least squares on
    the active face, then, where only the box bounds the level, the BVLS check. Returns
    ``y`` itself when nothing better was found."""
    lo, hi, inherited = bounds
    xq = x + (y if Z is None else Z.dot(y))
    res = c - M.dot(y)
    MW, W, free = _face(x, xq, Z, M, bounds, solver.rank_tolerance)
    if MW.shape[1] == 0:
        return y
    try:
        _, w, _, _ = cod(MW, res, np.zeros(MW.shape[1]), solver.rank_tolerance)
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
    if rp.dot(rp) > res.dot(res) or not inside(x + (yp if Z is None else Z.dot(yp)), lo, hi,
                                               inherited):  # fmt: skip
        yp, rp = y, res
    if (
        free is not None
        and math.sqrt(rp.dot(rp)) > solver.tolerance * (1.0 + math.sqrt(c.dot(c)))
        and not box_optimal(M, c, yp, lo - x, hi - x, solver.active_tolerance)
    ):
        yb = _bounded_least_squares(x, M, c, bounds, rp)
        if yb is not None:
            return yb
    return yp


def _bounded_least_squares(x: np.ndarray, M: np.ndarray, c: np.ndarray, bounds: Bounds,
                           rp: np.ndarray) -> np.ndarray | None:  # fmt: skip
    """The exact ``min ||M y - c||`` over the box ``lo - x <= y <= hi - x`` (BVLS), when it
    fits better than the residual ``rp`` and keeps the inherited rows; else None."""
    lo, hi, inherited = bounds
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
    # (BVLS sees the box only: the inherited rows are checked here)
    if np.isfinite(yb).all() and rb.dot(rb) < rp.dot(rp) and inside(x + yb, lo, hi, inherited):
        return yb
    return None
