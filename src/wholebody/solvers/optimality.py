r"""A level's objective, feasibility and optimality conditions at a point (the HQP's checks).

A level of the lexicographic problem (:mod:`wholebody.solvers.hqp`) minimises

.. math::

    f(x) = \tfrac12 \|A x - b\|^2 + \tfrac12 \|s(x)\|^2, \qquad
    s_i(x) = \max(C_i x - hi_i, 0) + \max(lo_i - C_i x, 0)

(``s`` the least slack that puts its inequality rows within their bounds) over ``x + Z y``
inside the box ``lo <= x <= hi`` and the inherited rows ``glo <= G x <= ghi`` of the levels
above. ``x`` is optimal exactly when the gradient in the free coordinates,
``Z^T grad f(x)``, is a combination of the active constraints' normals with multipliers of the
right signs (KKT; sufficient for this convex problem). The cascade uses these checks to skip
work where an answer is already optimal, to fix the constraints a level's optimum presses on
(:func:`strongly_active`), and to report what the box cost a level (:func:`bound_limited`).
"""

from __future__ import annotations

import math

import numpy as np

from wholebody._numeric import all_true, any_true, count_nonzero, entry_sum
from wholebody.solvers.linalg import cod
from wholebody.solvers.stack import LevelProblem

__all__ = [
    "Bounds",
    "Inherited",
    "active_multipliers",
    "bound_limited",
    "box_optimal",
    "finite_level",
    "inside",
    "inside_rows",
    "level_objective",
    "nonfinite_tasks",
    "on_box",
    "optimal",
    "rows_inside",
    "strongly_active",
    "violated",
    "worse",
]

Inherited = list[tuple[np.ndarray, np.ndarray, np.ndarray]]
"""The inequality rows fixed by the levels above: ``(G, glo, ghi)``, ``glo <= G x <= ghi``."""
Bounds = tuple[np.ndarray, np.ndarray, Inherited]
"""The box ``lo <= x <= hi`` and the inherited rows ``(G, glo, ghi)`` of a level."""


# ------------------------------------------------------------------ the objective
def level_objective(lev: LevelProblem, x: np.ndarray) -> float:
    """The level's objective at ``x``: ``1/2 ||A x - b||^2 + 1/2 ||s||^2``, ``s`` the least
    slack that puts its inequality rows within their bounds."""
    r = lev.A.dot(x) - lev.b
    f = 0.5 * float(r.dot(r))
    if lev.C.shape[0]:
        Cx = lev.C.dot(x)
        s = np.maximum(Cx - lev.upper, 0.0) + np.maximum(lev.lower - Cx, 0.0)
        f += 0.5 * float(s.dot(s))
    return f


def worse(lev: LevelProblem, x: np.ndarray, best: np.ndarray, tol: float) -> bool:
    """Whether the level's residual (slacks included) at ``x`` exceeds that at ``best`` by
    more than ``tol (1 + |b|)``."""
    return math.sqrt(2.0 * level_objective(lev, x)) > math.sqrt(
        2.0 * level_objective(lev, best)
    ) + tol * (1.0 + math.sqrt(lev.b.dot(lev.b)))


def violated(lev: LevelProblem, Cx: np.ndarray, tol: float) -> tuple[np.ndarray, list[str]]:
    """The inequality rows of ``lev`` that ``Cx`` violates by more than ``tol`` (a mask) and
    the names of their tasks."""
    viol = (Cx > lev.upper + tol) | (Cx < lev.lower - tol)
    if not count_nonzero(viol):
        return viol, []
    return viol, [name for name, sl in lev.inequality_rows.items() if count_nonzero(viol[sl])]


def bound_limited(lev: LevelProblem, res: np.ndarray, res_free: np.ndarray, on_box: bool,
                  tol: float) -> list[str]:  # fmt: skip
    """Tasks whose residual ``res`` the hard constraints raised above the box-free optimum's
    ``res_free`` by more than ``tol (1 + |b_t|)`` (none when no entry is on the box,
    ``on_box`` False: then the levels above, not the box, set the residual)."""
    if not on_box:
        return []
    return [name for (name, r, _, b), (_, r0, _, _)
            in zip(lev.task_residuals(res), lev.task_residuals(res_free), strict=True)
            if r - r0 > tol * (1.0 + b)]  # fmt: skip


# ------------------------------------------------------------------ finiteness
def finite_level(lev: LevelProblem) -> bool:
    """Whether the level's rows, right-hand side and inequality bounds are numbers (infinite
    inequality bounds allowed). One reduction per array: a sum is finite iff every entry is
    (barring overflow of absurdly large rows, which are then reported as non-finite too)."""
    C = lev.C
    if not math.isfinite(entry_sum(lev.A) + entry_sum(lev.b)):
        return False
    if not C.shape[0]:
        return True
    if not math.isfinite(entry_sum(C)):
        return False
    return not (any_true(np.isnan(lev.lower)) or any_true(np.isnan(lev.upper)))


def nonfinite_tasks(lev: LevelProblem) -> list[str]:
    """The tasks of ``lev`` with non-finite rows (the level's name if none is to blame)."""
    bad = [name for name, sl in lev.task_rows.items()
           if not (np.isfinite(lev.A[sl]).all() and np.isfinite(lev.b[sl]).all())]  # fmt: skip
    bad += [name for name, sl in lev.inequality_rows.items()
            if not np.isfinite(lev.C[sl]).all() or np.isnan(lev.lower[sl]).any()
            or np.isnan(lev.upper[sl]).any()]  # fmt: skip
    return bad or [lev.name]


# ------------------------------------------------------------------ feasibility
def inside(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, inherited: Inherited) -> bool:
    """Whether ``x`` is in the box ``[lo, hi]`` and within the inherited rows."""
    return all_true(x >= lo) and all_true(x <= hi) and inside_rows(x, inherited)


def inside_rows(x: np.ndarray, inherited: Inherited) -> bool:
    """Whether ``glo <= G x <= ghi`` holds for every inherited row."""
    for G, glo, ghi in inherited:
        Gx = G.dot(x)
        if not (all_true(Gx >= glo) and all_true(Gx <= ghi)):
            return False
    return True


def rows_inside(v: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float) -> bool:
    """Whether ``lo - tol <= v <= hi + tol``."""
    return all_true(v >= lo - tol) and all_true(v <= hi + tol)


def on_box(x: np.ndarray, lb: np.ndarray, ub: np.ndarray, act: float = 1e-7) -> bool:
    """Whether some entry of ``x`` is on (within ``act`` of) the box ``[lb, ub]``."""
    return any_true((x <= lb + act) | (x >= ub - act))


# ------------------------------------------------------------------ optimality conditions
def optimal(lev: LevelProblem, x: np.ndarray, Z: np.ndarray | None, bounds: Bounds,
            act: float, rank_tolerance: float, rtol: float = 1e-4) -> bool:  # fmt: skip
    """Whether ``x`` meets the optimality conditions of the level's least squares (no
    inequality rows of its own) over ``x + Z y`` within ``bounds``: its gradient is a
    combination of the active constraints' normals with multipliers of the right signs (see
    :func:`active_multipliers`), both to ``rtol |g|``. A sufficient test: degenerate
    multipliers may fail it, and then the caller only does more work."""
    lo, hi, inherited = bounds
    if Z is None and not inherited:  # the normals are unit vectors: mu = +-g on the bounds
        g = lev.A.T.dot(lev.A.dot(x) - lev.b)
        up, low = x >= hi - act, x <= lo + act
        tol = rtol * math.sqrt(g.dot(g))
        free = g[~(up | low)]
        return bool(free.dot(free) <= tol * tol and np.all(g[up] <= tol)
                    and np.all(g[low] >= -tol))  # fmt: skip
    gn, _, mu, res = active_multipliers(lev, x, Z, bounds, act, rank_tolerance)
    if gn == 0.0:
        return True
    return mu is not None and res <= rtol * gn and bool(np.all(mu >= -rtol * gn))


def box_optimal(M: np.ndarray, c: np.ndarray, y: np.ndarray, lb: np.ndarray, ub: np.ndarray,
                act: float, rtol: float = 1e-4) -> bool:  # fmt: skip
    """Whether ``y`` meets the optimality conditions of ``min ||M y - c||`` over the box
    ``[lb, ub]`` (as :func:`optimal` where only the box bounds a level): the gradient
    vanishes on the free entries and points outwards on the bound ones, to ``rtol |g|``."""
    g = M.T.dot(M.dot(y) - c)
    up, low = y >= ub - act, y <= lb + act
    tol = rtol * math.sqrt(g.dot(g))
    free = g[~(up | low)]
    return bool(free.dot(free) <= tol * tol and np.all(g[up] <= tol) and np.all(g[low] >= -tol))


def active_multipliers(lev: LevelProblem, x: np.ndarray, Z: np.ndarray | None, bounds: Bounds,
                       act: float, rank_tolerance: float,
                       ) -> tuple[float, np.ndarray, np.ndarray | None, float]:  # fmt: skip
    """The norm of the level's gradient ``gy = Z^T grad f(x)`` in the free coordinates,
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
    N, signs = _active_rows(x, lo, hi, inherited, act)
    if not N.shape[0]:
        return gnorm, N, None, gnorm
    Ny = (N if Z is None else N.dot(Z)) * signs[:, None]
    try:
        _, mu, _, _ = cod(Ny.T, gy, np.zeros(N.shape[0]), rank_tolerance)
    except (np.linalg.LinAlgError, ValueError):
        return gnorm, N, None, gnorm
    res = Ny.T.dot(mu) - gy
    return gnorm, N, mu, math.sqrt(res.dot(res))


def _active_rows(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, inherited: Inherited,
                 act: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The normals (x-space rows) of the box bounds and inherited rows active at ``x``
    (within ``act``), and their signs: +1 at a lower, -1 at an upper bound."""
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
    return np.vstack(rows), np.concatenate(signs)


def strongly_active(lev: LevelProblem, x: np.ndarray, Z: np.ndarray | None, bounds: Bounds,
                    delta: float, tolerance: float, act: float,
                    rank_tolerance: float) -> np.ndarray | None:  # fmt: skip
    """Rows (x-space) of the constraints the level's own objective presses on at ``x``.

    Every optimum of a convex level shares the constraints with a positive multiplier
    (complementary slackness), so fixing them for the lower levels does not change the
    problem; it removes the freedom that a level's optimum found only to round-off would
    otherwise leave to the next level (where a tiny slack can move a lower level far).
    The multipliers are those of the level's own least-squares objective, without the
    Tikhonov term, from the stationarity condition on the active constraints; a gradient
    or multiplier of the size the Tikhonov term alone produces (``delta |x|``) is not
    counted.
    """
    gnorm, N, mu, _ = active_multipliers(lev, x, Z, bounds, act, rank_tolerance)
    floor = max(1e-3 * tolerance * max(1.0, float(np.linalg.norm(lev.b))),
                100.0 * delta * max(1.0, float(np.linalg.norm(x))))  # fmt: skip
    if gnorm <= floor or mu is None:
        return None  # the bounds did not cost this level anything
    Ny = N if Z is None else N.dot(Z)
    pin = mu > max(1e-6 * gnorm, floor) / max(1.0, float(np.abs(Ny).max()))
    return N[pin] if np.any(pin) else None
