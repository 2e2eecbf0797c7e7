"""One level of the hierarchical QP's cascade: its QP, the polish of the QP's answer and the
level's optimality conditions.

Where a level's exact unconstrained candidate leaves the bounds (:mod:`wholebody.kernels.hqp`),
:func:`qp_setup` writes the level's QP into the workspace, in the free coordinates ``y``
(``x + Z y``) and the slacks ``s`` of its inequality rows:

    min 1/2 ||M y - c||^2 + d/2 ||y||^2 + 1/2 ||s||^2
    s.t. the relaxed box (rows Z, or the QP's own box where Z is the identity),
         the inherited rows (widened to contain x), lo - C x <= C Z y - s <= hi - C x,

with ``M = A Z``, ``c = b - A x`` and the Tikhonov term ``d = regularization * s_max^2``;
:func:`tie_setup` the final minimum-norm tie-break's. The Tikhonov term biases the engine's
answer: :func:`polish` removes the bias by solving the level's least squares exactly on the
face of the constraints active at the answer (with the bounded least squares, BVLS, where only
the box bounds the level), :func:`optimal` checks the level's optimality conditions (the
gradient a combination of the active constraints' normals with multipliers of the right sign)
and :func:`strongly_active` finds the constraints the level's optimum presses on, fixed for
the levels below. In a level's damped pass (the stall damping) its least squares ``(M, c)``
carries the damping rows ``lambda I`` and its rows (:func:`~wholebody.kernels.hqp_state.
damped_rows`) the same rows in x, so all of this is the damped problem's. The maths is in
:mod:`wholebody.solvers.hqp`'s module docstring.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.hqp_state import (
    C_D,
    C_SMAX,
    P_ACT,
    P_RANK,
    P_REG,
    P_TOL,
    QP,
    S_HASBOX,
    S_K,
    S_M,
    S_NROWS,
    S_NV,
    S_P,
    S_TIE,
    W_SCAL,
    Arena,
    Basis,
    Feasible,
    LevelRows,
    Multipliers,
    apply_basis,
    coords,
    damped_rows,
    inside,
    level_lsq,
    level_objective,
    level_rows,
    max_abs,
    qp_views,
    restrict,
    slack,
    state,
)
from wholebody.kernels.layout import fvec
from wholebody.kernels.linalg import combine, dot, finite1, gather_rows, mm, mtm, mtv, mv
from wholebody.kernels.lsq import bvls, cod, columns_of, gradient, null_space, residual

__all__ = [
    "optimal",
    "polish",
    "qp_setup",
    "strongly_active",
    "tie_setup",
    "unknown_multipliers",
]

_ACT = 1e-8  # the polish's activity threshold
_FLAT = 1e-12  # a QP row whose coefficients are at most this (relative) is left unbounded


# ---------------------------------------------------------------------- optimality
@kernel
def _active_rows(x: np.ndarray, bounds: Feasible, act: float):
    """The rows (x-space) of the bounds active at ``x`` (within ``act``), signed inwards:
    ``(N, signs)``."""
    n = x.shape[0]
    lo, hi, G, glo, ghi = bounds
    Gx = mv(G, x) if G.shape[0] else np.zeros(0)
    count = 0
    for j in range(n):
        count += x[j] <= lo[j] + act or x[j] >= hi[j] - act
    for j in range(Gx.shape[0]):
        count += Gx[j] <= glo[j] + act or Gx[j] >= ghi[j] - act
    N = np.zeros((count, n))
    signs = np.zeros(count)
    q = 0
    for j in range(n):
        low = x[j] <= lo[j] + act
        if low or x[j] >= hi[j] - act:
            N[q, j] = 1.0
            signs[q] = 1.0 if low else -1.0
            q += 1
    for j in range(Gx.shape[0]):
        low = Gx[j] <= glo[j] + act
        if low or Gx[j] >= ghi[j] - act:
            for c in range(n):
                N[q, c] = G[j, c]
            signs[q] = 1.0 if low else -1.0
            q += 1
    return N, signs


@kernel
def unknown_multipliers(n: int) -> Multipliers:
    """Multipliers not computed (for a point of ``n`` coordinates)."""
    return Multipliers(-1.0, np.zeros((0, n)), np.zeros((0, 0)), False, np.zeros(0), 0.0)


@kernel
def _active_multipliers(
    rows: LevelRows, x: np.ndarray, basis: Basis, bounds: Feasible, act: float, rank_tol: float
) -> Multipliers:
    """At ``x``: the level's gradient against the bounds active at ``x`` (within ``act``),
    the multipliers by the least squares of the active rows (``has_mu`` False where none is
    active or the decomposition failed). Where only the box bounds the level and Z is the
    identity, the active rows are unit rows: then ``mu`` is the gradient's entry on each,
    signed, and the residual its free entries, as the least squares gives them exactly."""
    n = x.shape[0]
    g = gradient(rows.A, x, rows.b)
    if rows.C.shape[0]:
        g = combine(g, 1.0, mtv(rows.C, slack(mv(rows.C, x), rows.lo, rows.hi)))
    gy = coords(basis, g)
    gnorm = math.sqrt(dot(gy, gy))
    N, signs = _active_rows(x, bounds, act)
    count = N.shape[0]
    Ny = restrict(N, basis)
    if count == 0:
        return Multipliers(gnorm, N, Ny, False, np.zeros(0), gnorm)
    for q in range(count):
        for j in range(Ny.shape[1]):
            Ny[q, j] *= signs[q]
    if basis.identity and bounds.G.shape[0] == 0:
        mu = np.empty(count)
        free2 = 0.0
        q = 0
        for j in range(n):
            if q < count and N[q, j] == 1.0:
                mu[q] = signs[q] * gy[j]
                q += 1
            else:
                free2 += gy[j] * gy[j]
        return Multipliers(gnorm, N, Ny, True, mu, math.sqrt(free2))
    NyT = np.empty((Ny.shape[1], count))
    for q in range(count):
        for j in range(Ny.shape[1]):
            NyT[j, q] = Ny[q, j]
    info, _, mu, _, _, _ = cod(NyT, gy, np.zeros(count), rank_tol, 0.0)
    if info != 0:
        return Multipliers(gnorm, N, Ny, False, np.zeros(0), gnorm)
    res = combine(mtv(Ny, mu), -1.0, gy)
    return Multipliers(gnorm, N, Ny, True, mu, math.sqrt(dot(res, res)))


@kernel
def _box_conditions(g: np.ndarray, y: np.ndarray, lb: np.ndarray, ub: np.ndarray, act: float):
    """The optimality conditions of a least squares over a box with gradient ``g`` at
    ``y`` (relative tolerance 1e-4): pushing outwards on the bounds it is on, zero
    elsewhere."""
    tol = 1e-4 * math.sqrt(dot(g, g))
    free2 = 0.0
    for j in range(y.shape[0]):
        up, low = y[j] >= ub[j] - act, y[j] <= lb[j] + act
        if up and not g[j] <= tol:
            return False
        if low and not g[j] >= -tol:
            return False
        if not (up or low):
            free2 += g[j] * g[j]
    return free2 <= tol * tol


@kernel
def optimal(
    rows: LevelRows, x: np.ndarray, basis: Basis, bounds: Feasible, act: float, rank_tol: float
) -> tuple[bool, Multipliers]:
    """Whether ``x`` meets the optimality conditions of the least squares of a level without
    inequality rows over the bounds (relative tolerance 1e-4): the gradient a combination of
    the active bounds' inward normals with nonnegative multipliers; and those multipliers
    where they were computed (for :func:`strongly_active` at the same point)."""
    if basis.identity and bounds.G.shape[0] == 0:  # unit normals: mu = +-g on the bounds
        ok = _box_conditions(gradient(rows.A, x, rows.b), x, bounds.lo, bounds.hi, act)
        return ok, unknown_multipliers(x.shape[0])
    mult = _active_multipliers(rows, x, basis, bounds, act, rank_tol)
    gn, mu = mult.gnorm, mult.mu
    if gn == 0.0:
        return True, mult
    if not (mult.has_mu and mult.res <= 1e-4 * gn):
        return False, mult
    for q in range(mu.shape[0]):
        if not mu[q] >= -1e-4 * gn:
            return False, mult
    return True, mult


@kernel
def strongly_active(
    rows: LevelRows,
    x: np.ndarray,
    basis: Basis,
    bounds: Feasible,
    delta: float,
    par: np.ndarray,
    mult: Multipliers,
) -> np.ndarray:
    """Rows (x-space) of the bounds the level's own objective presses on at its optimum
    ``x``, ``basis`` the level's free directions: those whose multiplier is clearly positive.
    None where the gradient is at the level of the tolerance or of the Tikhonov term
    ``delta`` (then the bounds cost the level nothing). ``mult``: the multipliers at ``x``
    if :func:`optimal` computed them (else computed here)."""
    if mult.gnorm < 0:
        mult = _active_multipliers(rows, x, basis, bounds, par[P_ACT], par[P_RANK])
    gnorm, N, mu = mult.gnorm, mult.N, mult.mu
    floor = max(
        1e-3 * par[P_TOL] * max(1.0, math.sqrt(dot(rows.b, rows.b))),
        100.0 * delta * max(1.0, math.sqrt(dot(x, x))),
    )
    n = x.shape[0]
    if gnorm <= floor or not mult.has_mu:
        return np.zeros((0, n))
    scale = max(1.0, max_abs(mult.Ny))  # (signs do not change |N Z|)
    pin = np.empty(mu.shape[0], np.bool_)
    for q in range(mu.shape[0]):
        pin[q] = mu[q] > max(1e-6 * gnorm, floor) / scale
    return gather_rows(N, pin)


# ---------------------------------------------------------------------- the QPs
@kernel
def _flat(Q: np.ndarray, q: int, r: int, scale: float) -> bool:
    """Whether row ``q`` of the QP's rows moves with ``y`` only at rounding level: its largest
    coefficient at most ``_FLAT max(1, scale)``."""
    top = 0.0
    for j in range(r):
        top = max(top, abs(Q[q, j]))
    return top <= _FLAT * max(1.0, scale)


@kernel
def _qp_rows(qp: QP, row: int, N, lo, hi, x: np.ndarray, basis: Basis, widen: bool) -> None:
    """Rows ``N Z`` of the QP from ``row`` on, with the bounds ``lo - N x``, ``hi - N x``.
    Where ``widen``: widened to contain 0, so that y = 0 is feasible, and a row the free
    directions move only at rounding level left unbounded (see :func:`_qp_box`)."""
    Q, qb, r = qp.Q, qp.qb, basis.r
    Nx = mv(N, x)
    Nz = restrict(N, basis)
    for q in range(N.shape[0]):
        for j in range(r):
            Q[row + q, j] = Nz[q, j]
        lo_q, hi_q = lo[q] - Nx[q], hi[q] - Nx[q]
        if widen and _flat(Q, row + q, r, max_abs(N[q : q + 1])):
            qb[0, row + q], qb[1, row + q] = -np.inf, np.inf
            continue
        qb[0, row + q] = min(lo_q, 0.0) if widen else lo_q
        qb[1, row + q] = max(hi_q, 0.0) if widen else hi_q


@kernel
def _qp_box(qp: QP, x: np.ndarray, basis: Basis, bounds: Feasible) -> int:
    """The relaxed box of the QP in ``y``: the QP's own box where Z is the identity, else
    rows ``Z`` (returns the rows used). A joint the free directions move only at rounding
    level (``|Z_q| <= _FLAT``) gets no row bounds: it cannot leave its bound through ``y``,
    and two such rows of opposite sign on joints at their bounds pinned ``y`` to 0 (the
    engines then solved, or declared infeasible, a degenerate problem)."""
    n, r = x.shape[0], basis.r
    Q, qb, lo, hi = qp.Q, qp.qb, bounds.lo, bounds.hi
    if basis.identity:
        for j in range(r):
            qb[2, j], qb[3, j] = lo[j] - x[j], hi[j] - x[j]
        return 0
    for q in range(n):
        for j in range(r):
            Q[q, j] = basis.Z[q, j]
        if _flat(Q, q, r, 1.0):
            qb[0, q], qb[1, q] = -np.inf, np.inf
        else:
            qb[0, q], qb[1, q] = lo[q] - x[q], hi[q] - x[q]
    return n


@kernel
def qp_setup(s: Arena, w: Arena, par: np.ndarray, k: int) -> None:
    """Level k's QP in ``(y, s)`` (module docstring) into the workspace: the Tikhonov term
    from ``|R_00|`` (``C_SMAX``), the level's least squares (``level_lsq``)."""
    st, x, basis, bounds = state(w)
    rows = level_rows(s, k)
    r, m, p = basis.r, st[S_M], st[S_P]
    n, ni = x.shape[0], bounds.G.shape[0]
    nv = r + p
    scal = fvec(w.f, w.h, W_SCAL)
    smax = scal[C_SMAX]
    d = par[P_REG] * (smax * smax if smax > 0 else 1.0)
    scal[C_D] = d
    nrows = (0 if basis.identity else n) + ni + p
    qp = qp_views(w, nv, nrows)
    H, g = qp.H, qp.g
    H[:, :] = 0.0
    g[:] = 0.0
    if m:
        M, c = level_lsq(w)
        MtM, Mtc = mtm(M, M), mtv(M, c)
        for a in range(r):
            g[a] = -Mtc[a]
            for j in range(r):
                H[a, j] = MtM[a, j]
    for j in range(r):
        H[j, j] += d
    for j in range(r, nv):
        H[j, j] = 1.0
    qp.Q[:, :] = 0.0
    if basis.identity:
        qp.qb[2, :nv] = -np.inf
        qp.qb[3, :nv] = np.inf
    row = _qp_box(qp, x, basis, bounds)
    if ni:  # widened to contain x, so that y = 0 is feasible
        _qp_rows(qp, row, bounds.G, bounds.glo, bounds.ghi, x, basis, True)
        row += ni
    if p:
        _qp_rows(qp, row, rows.C, rows.lo, rows.hi, x, basis, False)
        for j in range(p):
            qp.Q[row + j, r + j] = -1.0
    st[S_NV], st[S_NROWS], st[S_HASBOX] = nv, nrows, basis.identity


@kernel
def tie_setup(w: Arena, t: np.ndarray) -> None:
    """The tie-break's QP, ``min 1/2 ||x + Z y||^2`` over the bounds (``t = Z^T x``): H = I,
    g = t, the inherited rows widened to contain x as in the level QPs."""
    st, x, basis, bounds = state(w)
    r, ni = basis.r, bounds.G.shape[0]
    nrows = (0 if basis.identity else x.shape[0]) + ni
    qp = qp_views(w, r, nrows)
    qp.H[:, :] = 0.0
    for j in range(r):
        qp.H[j, j] = 1.0
    qp.g[:] = t
    row = _qp_box(qp, x, basis, bounds)
    if ni:
        _qp_rows(qp, row, bounds.G, bounds.glo, bounds.ghi, x, basis, True)
    st[S_NV], st[S_NROWS], st[S_HASBOX], st[S_TIE] = r, nrows, basis.identity, 1


# ---------------------------------------------------------------------- the polish
@kernel
def _touching(M, c, Cz, Cx, v, clo, chi):
    """The level's least squares ``(M, c)`` with the inequality rows at or beyond a bound
    at ``v`` (their values; ``Cz``, ``Cx``: the rows in the free coordinates and at x)
    joined, as equalities on that bound."""
    p, m = v.shape[0], M.shape[0]
    nt = 0
    for j in range(p):
        nt += v[j] <= clo[j] + 1e-8 or v[j] >= chi[j] - 1e-8
    if nt == 0:
        return M, c
    M2 = np.zeros((m + nt, M.shape[1]))
    c2 = np.zeros(m + nt)
    for q in range(m):
        c2[q] = c[q]
        for a in range(M.shape[1]):
            M2[q, a] = M[q, a]
    q = m
    for j in range(p):
        low = v[j] <= clo[j] + 1e-8
        if low or v[j] >= chi[j] - 1e-8:
            for a in range(M.shape[1]):
                M2[q, a] = Cz[j, a]
            c2[q] = (clo[j] if low else chi[j]) - Cx[j]
            q += 1
    return M2, c2


@kernel
def polish(s: Arena, w: Arena, par: np.ndarray, y: np.ndarray, with_rows: bool) -> np.ndarray:
    """The QP's answer ``y`` without the Tikhonov bias: the level's least squares solved
    exactly on the face of the constraints active at ``y``; with ``with_rows`` its
    inequality rows at or beyond a bound join the least squares and the result is kept only
    if the level's objective is lower."""
    st, x, basis, bounds = state(w)
    M, c = level_lsq(w)
    if not with_rows:
        return _polish_box(x, y, basis, M, c, bounds, par)[0]
    rows = damped_rows(s, w, st[S_K])
    Cz = restrict(rows.C, basis)
    Cx = mv(rows.C, x)
    M2, c2 = _touching(M, c, Cz, Cx, combine(Cx, 1.0, mv(Cz, y)), rows.lo, rows.hi)
    yp, changed = _polish_box(x, y, basis, M2, c2, bounds, par)
    if not changed:
        return y
    xq = combine(x, 1.0, apply_basis(basis, y))
    xp = combine(x, 1.0, apply_basis(basis, yp))
    return yp if level_objective(rows, xp) < level_objective(rows, xq) else y


@kernel
def _face(xq: np.ndarray, basis: Basis, M: np.ndarray, bounds: Feasible, rank_tol: float):
    """The least squares ``M`` restricted to the face of the bounds active at ``xq`` (within
    ``_ACT``): ``(MW, W, idx, only_box)``. Where only bounds of x are active and Z is the
    identity (``only_box``) the face keeps those entries: ``MW`` the columns ``idx`` of M
    (the entries off the box); else ``W`` is an orthonormal basis (in the free coordinates)
    of the directions that keep the active bounds, ``MW = M W``."""
    n = xq.shape[0]
    lo, hi, G, glo, ghi = bounds
    on = np.empty(n, np.bool_)
    n_on = 0
    for j in range(n):
        on[j] = xq[j] <= lo[j] + _ACT or xq[j] >= hi[j] - _ACT
        n_on += on[j]
    Gx = mv(G, xq) if G.shape[0] else np.zeros(0)
    gon = np.empty(Gx.shape[0], np.bool_)
    n_g = 0
    for j in range(Gx.shape[0]):
        gon[j] = Gx[j] <= glo[j] + _ACT or Gx[j] >= ghi[j] - _ACT
        n_g += gon[j]
    idx = np.empty(n - n_on if basis.identity and n_g == 0 else 0, np.int64)
    if basis.identity and n_g == 0:  # only bounds of x: keep those entries, move the others
        q = 0
        for j in range(n):
            if not on[j]:
                idx[q] = j
                q += 1
        return columns_of(M, idx), np.zeros((0, 0)), idx, True
    if n_on + n_g == 0:
        return M.copy(), np.eye(basis.r), idx, False
    N = np.zeros((n_on + n_g, n))
    q = 0
    for j in range(n):
        if on[j]:
            N[q, j] = 1.0
            q += 1
    for j in range(gon.shape[0]):
        if gon[j]:
            for a in range(n):
                N[q, a] = G[j, a]
            q += 1
    W = null_space(restrict(N, basis), rank_tol, 0.0)
    return mm(M, W), W, idx, False


@kernel
def _polish_box(x, y, basis: Basis, M, c, bounds: Feasible, par: np.ndarray):
    """The polish of ``y`` for ``min ||M y - c||`` on the bounds: ``(y', changed)``. The
    least squares on the face of the bounds active at ``y``, kept if it fits better and
    stays inside; where only the box bounds the level and the result is not its optimum,
    the exact bounded least squares (BVLS)."""
    res = residual(M, y, c)
    MW, W, idx, only_box = _face(
        combine(x, 1.0, apply_basis(basis, y)), basis, M, bounds, par[P_RANK]
    )
    if MW.shape[1] == 0:
        return y, False
    info, _, dw, _, _, _ = cod(MW, res, np.zeros(MW.shape[1]), par[P_RANK], 0.0)
    if info != 0:
        return y, False
    yp = y.copy()
    if only_box:
        for q in range(idx.shape[0]):
            yp[idx[q]] += dw[q]
    else:
        yp = combine(yp, 1.0, mv(W, dw))
    if not finite1(yp):
        return y, False
    rp = residual(M, yp, c)
    changed = True
    if dot(rp, rp) > dot(res, res) or not inside(combine(x, 1.0, apply_basis(basis, yp)), bounds):
        yp, rp, changed = y, res, False
    if only_box and math.sqrt(dot(rp, rp)) > par[P_TOL] * (1.0 + math.sqrt(dot(c, c))):
        lb, ub = combine(bounds.lo, -1.0, x), combine(bounds.hi, -1.0, x)
        if not _box_conditions(gradient(M, yp, c), yp, lb, ub, par[P_ACT]):
            yb = bvls(M, c, lb, ub, 20 * M.shape[1] + 20, 1e-13)
            for j in range(yb.shape[0]):
                yb[j] = min(max(yb[j], lb[j]), ub[j])
            rb = residual(M, yb, c)
            if finite1(yb) and dot(rb, rb) < dot(rp, rp) and inside(combine(x, 1.0, yb), bounds):
                return yb, True
    return yp, changed
