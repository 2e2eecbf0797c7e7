"""The hierarchical QP's cascade in kernels: its stages, and :func:`cascade`, the whole cascade
in one call with daqp solving its QPs from the kernel.

The method is :class:`wholebody.solvers.hqp.HierarchicalQPSolver`'s (its module docstring has
the maths): level by level, in the free directions the levels above leave, the exact
unconstrained candidate by a complete orthogonal decomposition (:mod:`wholebody.kernels.lsq`;
for a level of certain full row rank, the Cholesky factor of ``M M^T``, its null space made
only where a stage needs it, and a diagonal level below it, a posture, solved on that null
space without a basis: :func:`_diagonal_deferred`);
where it leaves the bounds, the level's QP, its answer polished and checked against the
level's optimality conditions, with proximal steps where they fail
(:mod:`wholebody.kernels.hqp_level`); then the level's rows, and the constraints its optimum
presses on, are fixed for the levels below, and its inequality rows inherited. A level below
the first that its exact answer leaves unmet is solved again with the stall damping
(:func:`_damping`, :func:`_damped_pass`: rows ``lambda I`` below its least squares in the
workspace, so that its candidate, QP, polish and optimality conditions are the damped ones;
its own null space, for the levels below, stays that of its rows). At the end the
minimum-norm point of the last optimal set (the tie-break) and the clip to the exact box.

The cascade runs as a few kernels that stop where a QP is needed, so that any engine can solve
it: :func:`begin`, :func:`advance` (the levels), :func:`after_qp`, :func:`proximal` and
:func:`tie_done` each return what to do next (``NEXT``: call :func:`advance`; ``NEED_QP``,
``NEED_PROXIMAL``, ``NEED_TIE`` or ``DONE``), the QP's data in the workspace; :func:`bump`
raises the Tikhonov term for an engine's retry and :func:`finish` writes the outcome. The
stages are separate kernels rather than one calling the next because numba compiles every
kernel together with all it calls: a chain of stages would compile the whole cascade once per
stage. Between the calls the cascade's state is its workspace
(:mod:`wholebody.kernels.hqp_state`). :mod:`wholebody.solvers.compiled_hqp` drives the stages
from Python for the other engines; :func:`cascade` drives them here, daqp called from the
kernel (:mod:`wholebody.kernels.daqp`).
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import daqp as dk
from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.hqp_level import (
    optimal,
    polish,
    qp_setup,
    strongly_active,
    tie_setup,
    unknown_multipliers,
)
from wholebody.kernels.hqp_state import (
    C_CLIP,
    C_D,
    C_DAMP,
    C_F,
    C_RES,
    C_SMAX,
    C_TOL,
    FAIL_DECOMPOSITION,
    FAIL_ENGINE,
    FAIL_STEP,
    P_ACT,
    P_DAMP,
    P_PROX,
    P_RANK,
    P_REG,
    P_RELAX,
    P_TOL,
    R_DAMPED,
    R_FAIL,
    R_FAILED,
    R_FREE,
    R_ITER,
    R_QP,
    R_RANK,
    R_RETRIES,
    R_STATUS,
    S_ANYQP,
    S_BOXBAD,
    S_DEFER_R,
    S_EXACT,
    S_HASBOX,
    S_K,
    S_M,
    S_MD,
    S_NINH,
    S_NROWS,
    S_NULL,
    S_NV,
    S_P,
    S_PROX,
    S_R,
    S_RANK,
    S_TIEFAIL,
    S_TIESTATUS,
    S_ZI,
    W_BOX,
    W_CV,
    W_G,
    W_H,
    W_INH,
    W_INHB,
    W_LIMITED,
    W_M,
    W_NULL,
    W_REPORT,
    W_SCAL,
    W_STATE,
    W_X,
    W_XC,
    W_Y,
    Arena,
    Basis,
    Feasible,
    LevelRows,
    Multipliers,
    apply_basis,
    bound_limited,
    box_row,
    compose_basis,
    coords,
    damped_rows,
    defer_basis,
    diagonal_step,
    finish,
    finite_rows,
    inside,
    level_lsq,
    level_objective,
    level_rows,
    make_basis,
    max_abs,
    qp_views,
    report_row,
    restrict,
    restrict_into,
    skip_nonfinite,
    state,
    violated,
)
from wholebody.kernels.layout import fmat, fvec, ivec
from wholebody.kernels.linalg import combine, dot, finite1, frobenius2, mv, null_basis
from wholebody.kernels.lsq import cod, in_box, null_space, pivot_norm, residual, wide_solve

__all__ = [
    "DONE",
    "NEED_PROXIMAL",
    "NEED_QP",
    "NEED_TIE",
    "NEXT",
    "advance",
    "after_qp",
    "begin",
    "bump",
    "cascade",
    "finish",
    "proximal",
    "tie_done",
]

DONE, NEED_QP, NEED_PROXIMAL, NEED_TIE, NEXT = 0, 1, 2, 3, 4
DEFERRED = -2  # _level_step's null_cols where the level's null space is not computed yet

# QP statuses as the engines report them (wholebody.solvers.qp.QPStatus)
QP_SOLVED, QP_INACCURATE, QP_INFEASIBLE, QP_FAILED = 0, 1, 2, 3


# ---------------------------------------------------------------------- the levels
@kernel
def begin(f, i, h, wf, wi, wh, par) -> int:
    """Start the cascade of the evaluated stack: NEXT (:func:`advance` runs the levels), or
    DONE where the box is empty."""
    st = ivec(wi, wh, W_STATE)
    st[:] = 0
    ivec(wi, wh, W_REPORT)[:] = 0
    ivec(wi, wh, W_LIMITED)[:] = 0
    box, x = fvec(wf, wh, W_BOX), fvec(wf, wh, W_X)
    ab = fvec(f, h, lay.F_BOX)  # (2, n): lower, upper
    fvec(wf, wh, W_SCAL)[:] = 0.0
    bt = par[P_RELAX]
    n = x.shape[0]
    for j in range(n):
        if not ab[j] <= ab[n + j]:  # NaN compares false; evaluate never crosses the box
            st[S_BOXBAD] = 1
            x[:] = 0.0
            return DONE
    for j in range(n):  # (W_BOX rows: relaxed lo, hi; exact lb, ub)
        lo, hi = ab[j], ab[n + j]
        box[2 * n + j], box[3 * n + j] = lo, hi
        x[j] = min(max(0.0, lo), hi)  # the minimum-norm point of the box
        box[j], box[n + j] = lo - bt, hi + bt
    st[S_R], st[S_ZI], st[S_EXACT] = n, 1, 1
    return NEXT


@kernel
def advance(f, i, h, wf, wi, wh, par) -> int:
    """Levels from the current one until one needs a QP (NEED_QP). After the last: the exact
    minimum-norm point of the last optimal set where a QP ran and freedom is left (NEED_TIE
    where it needs one: the bounds bind it), and the clip to the exact box (DONE)."""
    s, w = Arena(f, i, h), Arena(wf, wi, wh)
    st = ivec(wi, wh, W_STATE)
    while st[S_K] < h[lay.I_LEVEL, 2]:
        if _level(s, w, par, st[S_K]) == NEED_QP:
            return NEED_QP
        st[S_K] += 1
    if not st[S_ANYQP]:  # (the candidates were taken: x is the minimum-norm point)
        return _clip(w)
    make_basis(w)
    _, x, basis, bounds = state(w)
    if basis.r:
        t = coords(basis, x)
        xc = combine(x, -1.0, apply_basis(basis, t))
        if inside(xc, bounds):
            x[:] = xc
        else:
            tie_setup(w, t)
            return NEED_TIE
    return _clip(w)


@kernel
def _level_step(
    s: Arena, w: Arena, par: np.ndarray, k: int, rows: LevelRows, x: np.ndarray, basis: Basis
):
    """Level k's unconstrained step in the free coordinates, the exact candidate:
    ``(code, y, rank, smax, known, null_cols)`` (:func:`wholebody.kernels.lsq.cod`), code
    DONE where the level is skipped (non-finite rows, a failed decomposition), else NEED_QP;
    its least squares ``M``, ``c`` go to the workspace, the null space of M to ``W_NULL``
    (``null_cols`` DEFERRED where M has full row rank for certain: not yet computed, see
    :func:`_close_deferred`).
    ``rows``, ``x``, ``basis``: the level's rows and the cascade's state."""
    rank_tol = par[P_RANK]
    A, b = rows.A, rows.b
    n, r, m = x.shape[0], basis.r, A.shape[0]
    t = coords(basis, x)
    if m == 0:
        return NEED_QP, combine(np.zeros(r), -1.0, t), 0, 0.0, True, -1
    moved = not basis.identity  # (x = 0: c = b, even where A is not finite)
    for j in range(n):
        moved = moved or x[j] != 0
    M, c = fvec(w.f, w.h, W_M)[: m * r].reshape((m, r)), fvec(w.f, w.h, W_CV)[:m]
    c[:] = residual(A, x, b) if moved else b
    restrict_into(A, basis, M)
    sw = 0.0
    if m == n:  # (F_LEVEL: L x 4)
        sw = fvec(s.f, s.h, lay.F_LEVEL)[4 * k + lay.LEVEL_IDENTITY]
    if sw > 0:  # rows sw * I: M = sw Z has r singular values sw
        y = coords(basis, c)
        for j in range(r):
            y[j] /= sw
        return NEED_QP, y, r, sw, True, -1
    floor = 0.0 if basis.identity else rank_tol * math.sqrt(frobenius2(A))
    if m < r:
        done, y, _ = wide_solve(M, c, t, rank_tol, floor)
        if done:  # full row rank for certain: the null space made only where needed
            return NEED_QP, y, m, 0.0, False, DEFERRED
    info, rank, y, Q2, smax, known = cod(M, c, t, rank_tol, floor)
    if info != 0:
        if not finite_rows(rows):
            skip_nonfinite(s, w, k)
        else:
            rep = report_row(w, k)
            rep[R_FAILED], rep[R_FAIL] = 1, FAIL_DECOMPOSITION
        return DONE, y, 0, 0.0, True, -1
    null_cols = -1
    if rank < r:
        null_cols = Q2.shape[1]
        Nw = fvec(w.f, w.h, W_NULL)[: r * null_cols].reshape((r, null_cols))
        for j in range(r):
            for q in range(null_cols):
                Nw[j, q] = Q2[j, q]
    return NEED_QP, y, rank, smax, known, null_cols


@kernel
def _level(s: Arena, w: Arena, par: np.ndarray, k: int) -> int:
    """Level k up to its QP: the unconstrained candidate, taken where it meets the bounds and
    the level's inequality rows (DONE); else the QP is set up and NEED_QP returned."""
    if _diagonal_deferred(s, w, par, k):
        return DONE
    tol = par[P_TOL]
    make_basis(w)
    st, x, basis, bounds = state(w)
    rep = report_row(w, k)
    rows = level_rows(s, k)
    m, p = rows.A.shape[0], rows.C.shape[0]
    rep[R_FREE] = basis.r
    if basis.r == 0:  # nothing left to move: report the inequality rows x leaves violated
        if not finite_rows(rows):
            skip_nonfinite(s, w, k)
        elif p:
            violated(s, w, k, mv(rows.C, x), rows, tol, True)
        return DONE
    if p and not finite_rows(rows):
        skip_nonfinite(s, w, k)
        return DONE
    code, y, rank, smax, known, null_cols = _level_step(s, w, par, k, rows, x, basis)
    if code == DONE:
        return DONE
    if m and (rank == 0 or not finite1(y)) and not finite_rows(rows):
        skip_nonfinite(s, w, k)
        return DONE
    if not finite1(y):  # finite rows, yet the decomposition overflowed
        rep[R_FAILED], rep[R_FAIL] = 1, FAIL_STEP
        return DONE
    rep[R_RANK] = rank
    xc = combine(x, 1.0, apply_basis(basis, y))
    exact = in_box(xc, box_row(w, 2), box_row(w, 3))
    st[S_RANK], st[S_NULL], st[S_M], st[S_P] = rank, null_cols, m, p
    if _meets(xc, bounds, rows, tol):
        return _take_candidate(s, w, par, k, rows, y, xc, exact, null_cols)
    if null_cols == DEFERRED:
        _close_deferred(w, False)
    st[S_ANYQP] = 1
    if m and rank == 0 and p == 0:
        # rows with nothing left to move (round-off in the free directions, or a task the
        # levels above fix): only the minimum-norm step left the box; the tie-break decides
        _close_rows(w)
        _close_rest(s, w, par, k, rows, x, bounds)
        return DONE
    rep[R_QP] = 1
    if not known:  # certified full rank: |R_00| only now needed
        smax = pivot_norm(level_lsq(w)[0])
    fvec(w.f, w.h, W_XC)[:] = xc
    fvec(w.f, w.h, W_SCAL)[C_SMAX] = smax
    qp_setup(s, w, par, k)
    return NEED_QP


@kernel
def _take_candidate(
    s: Arena,
    w: Arena,
    par: np.ndarray,
    k: int,
    rows: LevelRows,
    y: np.ndarray,
    xc: np.ndarray,
    exact: bool,
    null_cols: int,
) -> int:
    """Level k's exact candidate ``xc = x + Z y``, which meets the bounds, taken (DONE); or,
    where it leaves the level unmet and the stall damping applies, the level's damped pass
    (DONE, or NEED_QP where the damped candidate leaves the bounds)."""
    st, x, _, bounds = state(w)
    lam2 = _damping(s, w, par, rows, y)
    if null_cols == DEFERRED:
        _close_deferred(w, lam2 == 0.0)
    if lam2 > 0.0:
        code = _damped_pass(s, w, par, k, rows, lam2)
        if code != NEXT:
            return code
    x[:] = xc  # (or the damped pass failed: the exact candidate, its null space made)
    st[S_EXACT] = exact
    if null_cols != DEFERRED or lam2 > 0.0:
        _close_rows(w)
    _close_rest(s, w, par, k, rows, x, bounds)
    return DONE


@kernel
def _meets(xc: np.ndarray, bounds: Feasible, rows: LevelRows, tol: float) -> bool:
    """Whether the candidate ``xc`` meets the bounds (the relaxed box contains the exact one)
    and the level's inequality rows, within the tolerance."""
    met = inside(xc, bounds)
    Cx = mv(rows.C, xc) if met and rows.C.shape[0] else np.zeros(0)
    for j in range(Cx.shape[0]):
        met = met and Cx[j] >= rows.lo[j] - tol and Cx[j] <= rows.hi[j] + tol
    return met


@kernel
def _damping(s: Arena, w: Arena, par: np.ndarray, rows: LevelRows, y: np.ndarray) -> float:
    """The stall damping ``lambda^2`` of the current level at its exact answer ``x + Z y``
    (:class:`wholebody.solvers.hqp.HierarchicalQPSolver` documents the rule):
    ``mu dt ||r|| |R_00|`` where the level is unmet, ``r = M y - c`` its weighted residual
    beyond ``P_TOL (1 + ||c||)`` and ``|R_00|`` the scale of M's largest singular value;
    0 for the first level, where the level is met, without equality rows, of rows in joint
    space (:func:`_joint_space`), with ``mu = 0`` or without a step duration (a problem no
    stack made)."""
    st = ivec(w.i, w.h, W_STATE)
    mu, m = par[P_DAMP], st[S_M]
    if not mu > 0.0 or m == 0 or st[S_MD] or st[S_K] == 0:
        return 0.0
    scalars = fvec(s.f, s.h, lay.F_SCALARS)
    dt = scalars[0] if scalars.shape[0] else 0.0
    if not dt > 0.0:
        return 0.0
    if _joint_space(rows.A):
        return 0.0
    M, c = level_lsq(w)
    res = residual(M, y, c)
    rn = math.sqrt(dot(res, res))
    if not rn > par[P_TOL] * (1.0 + math.sqrt(dot(c, c))):
        return 0.0
    return mu * dt * rn * pivot_norm(M)


@kernel
def _joint_space(A: np.ndarray) -> bool:
    """Whether every row of ``A`` has at most one non-zero entry: rows in joint space (a
    posture, objectives' descent rows ``s I``), which do not turn with the configuration, so
    their least squares is exact from one step to the next and never needs damping."""
    for i in range(A.shape[0]):
        count = 0
        for j in range(A.shape[1]):
            count += A[i, j] != 0.0
        if count > 1:
            return False
    return True


@kernel
def _damped_pass(s: Arena, w: Arena, par: np.ndarray, k: int, rows: LevelRows, lam2: float) -> int:
    """Level k solved again with the damping ``lam2 ||Z^T (x' - a)||^2`` added to its least
    squares, ``a`` the anchor (the last step's velocity under acceleration limits, else 0):
    rows ``lambda I`` below M in the workspace, right-hand side ``lambda Z^T (a - x)``
    (``S_MD``). Its damped candidate taken where
    it meets the bounds (DONE: the level closed on its rows' own null space, ``W_NULL``,
    made by the exact pass), else the damped QP set up (NEED_QP; :func:`_finish_level`
    closes it). NEXT where the damped candidate failed: the caller keeps the exact answer."""
    st, x, basis, bounds = state(w)
    m, r = st[S_M], basis.r
    lam = math.sqrt(lam2)
    Mw, cw = fvec(w.f, w.h, W_M), fvec(w.f, w.h, W_CV)
    to_anchor = coords(basis, combine(fvec(s.f, s.h, lay.F_ANCHOR), -1.0, x))
    for j in range(r):
        row = (m + j) * r
        for a in range(r):
            Mw[row + a] = 0.0
        Mw[row + j] = lam
        cw[m + j] = lam * to_anchor[j]
    st[S_MD] = r
    scal = fvec(w.f, w.h, W_SCAL)
    scal[C_DAMP] = lam2
    M, c = level_lsq(w)
    info, _, y, _, _, _ = cod(M, c, np.zeros(r), par[P_RANK], 0.0)
    if info != 0 or not finite1(y):
        st[S_MD] = 0
        return NEXT
    rep = report_row(w, k)
    rep[R_DAMPED] = 1
    xc = combine(x, 1.0, apply_basis(basis, y))
    fvec(w.f, w.h, W_XC)[:] = xc
    if _meets(xc, bounds, rows, par[P_TOL]):
        x[:] = xc
        st[S_EXACT] = in_box(xc, box_row(w, 2), box_row(w, 3))
        st[S_MD] = 0
        _close_rows(w)
        _close_rest(s, w, par, k, rows, x, bounds)
        return DONE
    st[S_ANYQP] = 1
    rep[R_QP] = 1
    scal[C_SMAX] = pivot_norm(M[:m])  # (the level's own scale, for the Tikhonov term)
    qp_setup(s, w, par, k)
    return NEED_QP


@kernel
def _close_deferred(w: Arena, met: bool) -> None:
    """After a level of certain full row rank: where its candidate is taken, its null space
    deferred (:func:`defer_basis`); else made into ``W_NULL`` for the QP and the close."""
    st = ivec(w.i, w.h, W_STATE)
    m, r = st[S_M], st[S_R]
    if met:
        defer_basis(w, m)
        return
    V = null_basis(fvec(w.f, w.h, W_M)[: m * r].reshape((m, r)))
    fvec(w.f, w.h, W_NULL)[: r * (r - m)].reshape((r, r - m))[:, :] = V
    st[S_NULL] = r - m


@kernel
def _diagonal_deferred(s: Arena, w: Arena, par: np.ndarray, k: int) -> bool:
    """Level k where its rows are diagonal (a posture task, objectives; no inequality rows)
    and the free directions deferred (:func:`defer_basis`; rows ``s I`` where they were not
    the identity's): its candidate ``x + dx`` (:func:`diagonal_step`), taken where it meets
    the bounds, which leaves nothing free (True); False where the level is not such or its
    candidate is not taken (:func:`_level` then solves it)."""
    st = ivec(w.i, w.h, W_STATE)
    if not st[S_DEFER_R]:
        return False
    _, x, _, bounds = state(w)  # (x and the bounds: the basis is read by diagonal_step)
    rows = level_rows(s, k)
    if rows.A.shape[0] != x.shape[0] or rows.C.shape[0]:
        return False
    ok, dx = diagonal_step(w, rows.A, residual(rows.A, x, rows.b), par[P_RANK])
    xc = combine(x, 1.0, dx)
    if not (ok and finite1(xc) and inside(xc, bounds)):
        return False
    rep = report_row(w, k)
    rep[R_FREE], rep[R_RANK] = st[S_R], st[S_R]
    x[:] = xc
    st[S_EXACT] = in_box(xc, box_row(w, 2), box_row(w, 3))
    st[S_RANK], st[S_NULL], st[S_M], st[S_P] = st[S_R], -1, rows.A.shape[0], 0
    st[S_DEFER_R], st[S_R], st[S_ZI] = 0, 0, 0
    _close_rest(s, w, par, k, rows, x, bounds)
    return True


# ---------------------------------------------------------------------- after a QP
@kernel
def bump(wf, wi, wh, attempt) -> None:
    """After an engine failure: the Tikhonov term of the QP's Hessian times 100."""
    st = ivec(wi, wh, W_STATE)
    d = fvec(wf, wh, W_SCAL)[C_D]
    nv = st[S_NV]
    H = fvec(wf, wh, W_H)[: nv * nv].reshape((nv, nv))
    for j in range(st[S_R]):
        H[j, j] += d * (100.0**attempt - 100.0 ** (attempt - 1))


@kernel
def after_qp(f, i, h, wf, wi, wh, par, sol, ok) -> int:
    """The level's QP answer ``sol`` (``ok``: the engine solved it): polish, optimality
    check, then the proximal steps (NEED_PROXIMAL) or the level's close (NEXT)."""
    s, w = Arena(f, i, h), Arena(wf, wi, wh)
    st, x, basis, bounds = state(w)
    k, m, p = st[S_K], st[S_M], st[S_P]
    if not ok:
        rep = report_row(w, k)
        rep[R_FAILED], rep[R_FAIL] = 1, FAIL_ENGINE
        st[S_K] += 1
        return NEXT
    rows = damped_rows(s, w, k)
    y = sol[: basis.r].copy()
    M, c = level_lsq(w)
    if m == 0:
        if p:  # only inequality rows: their slack is the level's least squares
            y = polish(s, w, par, y, True)
        return _finish_level(s, w, par, y, unknown_multipliers(x.shape[0]))
    y = polish(s, w, par, y, p > 0)
    xq = combine(x, 1.0, apply_basis(basis, y))
    if p == 0:
        ok, mult = optimal(rows, xq, basis, bounds, par[P_ACT], par[P_RANK])
        if ok:  # (the same point as _finish_level's: the multipliers carry over)
            return _finish_level(s, w, par, y, mult)
    scal, gg, yr = fvec(wf, wh, W_SCAL), fmat(wf, wh, W_G), fmat(wf, wh, W_Y)
    gg[1, : basis.r] = gg[0, : basis.r]
    scal[C_TOL] = par[P_TOL] * (1.0 + math.sqrt(dot(c, c)))
    scal[C_F] = level_objective(rows, xq) if p else 0.0
    res = residual(M, y, c)
    scal[C_RES] = math.sqrt(dot(res, res))
    yr[0, : basis.r] = y
    st[S_PROX] = 0
    if _next_proximal(w, par) == NEED_PROXIMAL:
        return NEED_PROXIMAL
    return _finish_level(s, w, par, y, unknown_multipliers(x.shape[0]))


@kernel
def _next_proximal(w: Arena, par: np.ndarray) -> int:
    """Another proximal step, the Tikhonov term centred on the last answer (NEED_PROXIMAL),
    or 0 where the level is done with them (``P_PROX`` steps, or within its tolerance)."""
    st = ivec(w.i, w.h, W_STATE)
    scal, gg, yr = fvec(w.f, w.h, W_SCAL), fmat(w.f, w.h, W_G), fmat(w.f, w.h, W_Y)
    r = st[S_R]
    if st[S_PROX] >= int(par[P_PROX]) or scal[C_RES] <= scal[C_TOL]:
        return 0
    for j in range(r):
        gg[0, j] = gg[1, j] - scal[C_D] * yr[0, j]
    return NEED_PROXIMAL


@kernel
def proximal(f, i, h, wf, wi, wh, par, sol, ok) -> int:
    """A proximal step's QP answer: kept if, polished, it fits the level better;
    NEED_PROXIMAL for another, or the level's close (NEXT)."""
    s, w = Arena(f, i, h), Arena(wf, wi, wh)
    st, x, basis, _ = state(w)
    k, p = st[S_K], st[S_P]
    scal, yr = fvec(wf, wh, W_SCAL), fmat(wf, wh, W_Y)
    st[S_PROX] += 1
    y = yr[0, : basis.r].copy()
    if not ok:
        return _finish_level(s, w, par, y, unknown_multipliers(x.shape[0]))
    rows = damped_rows(s, w, k)
    M, c = level_lsq(w)
    yn = polish(s, w, par, sol[: basis.r].copy(), p > 0)
    rn = residual(M, yn, c)
    fn = 0.0
    if p:
        fn = level_objective(rows, combine(x, 1.0, apply_basis(basis, yn)))
    if p and fn > scal[C_F]:
        return _finish_level(s, w, par, y, unknown_multipliers(x.shape[0]))
    rnorm = math.sqrt(dot(rn, rn))
    better = scal[C_RES] - rnorm
    if better <= 0.0:
        return _finish_level(s, w, par, y, unknown_multipliers(x.shape[0]))
    yr[0, : basis.r] = yn
    scal[C_RES], scal[C_F] = rnorm, fn
    if better <= 1e-3 * scal[C_TOL] or _next_proximal(w, par) != NEED_PROXIMAL:
        return _finish_level(s, w, par, yn, unknown_multipliers(x.shape[0]))
    return NEED_PROXIMAL


# ---------------------------------------------------------------------- a level's close
@kernel
def _finish_level(s: Arena, w: Arena, par: np.ndarray, y: np.ndarray, mult: Multipliers) -> int:
    """The level's QP answer ``x + Z y`` taken: which tasks the box limited; the level's rows
    fixed, and the constraints its optimum presses on (found in the level's free directions:
    their rows removed from the free directions too); its inequality rows inherited; NEXT.
    ``mult``: the level's multipliers at ``x + Z y`` where they are known."""
    st, x, basis, bounds = state(w)
    k = st[S_K]
    xq = combine(x, 1.0, apply_basis(basis, y))
    if st[S_M] and not st[S_MD]:  # (the exact pass: what the box cost the level)
        bound_limited(s, w, par, k, xq)
        lam2 = _damping(s, w, par, level_rows(s, k), y)
        if lam2 > 0.0:
            code = _damped_pass(s, w, par, k, level_rows(s, k), lam2)
            if code == NEED_QP:
                return NEED_QP
            if code == DONE:
                st[S_K] += 1
                return NEXT
    rows = damped_rows(s, w, k)  # (in the damped pass: with its damping rows)
    x[:] = xq
    # (found in the level's free directions, before _close_rows fixes its rows)
    left = st[S_NULL] > 0 if st[S_RANK] else basis.identity or basis.r > 0
    pins = np.zeros((0, x.shape[0]))
    if report_row(w, k)[R_QP] and st[S_M] and left:
        smax = fvec(w.f, w.h, W_SCAL)[C_SMAX]
        delta = par[P_REG] * (smax * smax if smax > 0 else 1.0)
        pins = strongly_active(rows, x, basis, bounds, delta, par, mult)
    _close_rows(w)
    if pins.shape[0]:
        _, _, basis, _ = state(w)
        floor = par[P_RANK] * max_abs(pins)
        compose_basis(w, null_space(restrict(pins, basis), par[P_RANK], floor))
    _close_rest(s, w, par, k, rows, x, bounds)
    st[S_MD] = 0
    st[S_K] += 1
    return NEXT


@kernel
def _close_rows(w: Arena) -> None:
    """The level's rows fixed: the basis Z times the level's own null space (``W_NULL``)."""
    st = ivec(w.i, w.h, W_STATE)
    if st[S_RANK]:
        r, cols = st[S_R], max(st[S_NULL], 0)
        compose_basis(w, fvec(w.f, w.h, W_NULL)[: r * cols].reshape((r, cols)))


@kernel
def _close_rest(
    s: Arena, w: Arena, par: np.ndarray, k: int, rows: LevelRows, x: np.ndarray, bounds: Feasible
) -> None:
    """Level k's inequality rows inherited by the levels below, their bounds widened to
    contain ``C x`` (a violated row held where it is) and relaxed by ``P_RELAX``; the relaxed
    box widened to contain x. ``rows``, ``x``, ``bounds``: the level's rows and the cascade's
    state (the inherited rows' count is read anew)."""
    st = ivec(w.i, w.h, W_STATE)
    C, ni, p = rows.C, st[S_NINH], rows.C.shape[0]
    if p:
        Cx = mv(C, x)
        qp = report_row(w, k)[R_QP] == 1
        viol = violated(s, w, k, Cx, rows, par[P_TOL], qp)
        bt = par[P_RELAX]
        Gw, gbw = fmat(w.f, w.h, W_INH), fmat(w.f, w.h, W_INHB)
        for j in range(p):
            for c in range(C.shape[1]):
                Gw[ni + j, c] = C[j, c]
            lo_j = Cx[j] if viol[j] else rows.lo[j]
            hi_j = Cx[j] if viol[j] else rows.hi[j]
            gbw[0, ni + j] = min(lo_j, Cx[j]) - bt
            gbw[1, ni + j] = max(hi_j, Cx[j]) + bt
        st[S_NINH] = ni + p
    if k != s.h[lay.I_LEVEL, 2] - 1 or st[S_ANYQP]:
        for j in range(x.shape[0]):
            bounds.lo[j] = min(bounds.lo[j], x[j])
            bounds.hi[j] = max(bounds.hi[j], x[j])


# ---------------------------------------------------------------------- the end
@kernel
def tie_done(wf, wi, wh, sol, ok) -> int:
    """The tie-break's answer (kept the last level's where the engine failed); DONE."""
    w = Arena(wf, wi, wh)
    st, x, basis, _ = state(w)
    if ok:
        dx = apply_basis(basis, sol[: basis.r].copy())
        for j in range(x.shape[0]):
            x[j] += dx[j]
    else:
        st[S_TIEFAIL] = 1
    return _clip(w)


@kernel
def _clip(w: Arena) -> int:
    """``x`` clipped to the exact box (by the relaxation and engine tolerances at most),
    where anything may have moved it outside; DONE."""
    st, x = ivec(w.i, w.h, W_STATE), fvec(w.f, w.h, W_X)
    scal = fvec(w.f, w.h, W_SCAL)
    scal[C_CLIP] = 0.0
    if st[S_EXACT] and not st[S_ANYQP]:
        return DONE
    lb, ub = box_row(w, 2), box_row(w, 3)
    worst = 0.0
    for j in range(x.shape[0]):
        v = min(max(x[j], lb[j]), ub[j])
        worst = max(worst, abs(v - x[j]))
        x[j] = v
    scal[C_CLIP] = worst
    return DONE


# ---------------------------------------------------------------------- daqp in the kernel
@kernel
def _daqp(w: Arena, settings: np.ndarray) -> tuple[np.ndarray, bool, int, int]:
    """The QP the cascade set up in the workspace, solved by daqp: ``(sol, ok, status,
    iterations)`` with ``sol`` padded to the workspace's width (zeros where not ok) and the
    status an engine's (``QP_*``). The box (where the QP has one) goes first, as daqp's
    simple bounds; crossed bounds are infeasible without a call."""
    st = ivec(w.i, w.h, W_STATE)
    nv, rows, has_box = st[S_NV], st[S_NROWS], st[S_HASBOX] != 0
    qp = qp_views(w, nv, rows)
    qb = qp.qb
    ms = nv if has_box else 0
    m = ms + rows
    upper, lower = np.empty(m), np.empty(m)
    if has_box:
        upper[:nv], lower[:nv] = qb[3, :nv], qb[2, :nv]
    upper[ms:], lower[ms:] = qb[1, :rows], qb[0, :rows]
    sol = np.zeros(w.h[W_G, 3])  # (W_G: 2 x nv_max)
    for j in range(m):
        if not lower[j] <= upper[j]:
            return sol, False, QP_INFEASIBLE, 0
    x, lam = np.empty(nv), np.empty(m)
    flag, iterations = dk.solve(
        qp.H, qp.g, qp.Q, upper, lower, np.zeros(m, np.int32), settings, x, lam
    )
    if flag == dk.OPTIMAL or flag == dk.SOFT_OPTIMAL:
        status = QP_SOLVED
    elif flag == dk.ITERLIMIT:
        status = QP_INACCURATE
    elif flag == dk.INFEASIBLE:
        status = QP_INFEASIBLE
    else:
        status = QP_FAILED
    ok = status <= QP_INACCURATE and finite1(x)
    if ok:
        sol[:nv] = x
    return sol, ok, status, iterations


@kernel
def cascade(f, i, h, wf, wi, wh, par, settings) -> None:
    """The whole cascade on the evaluated stack with daqp for its QPs, in one call: the
    stages of this module in the order their codes ask for, the engine's retries (the
    Tikhonov term 100 and 10000 times larger after a failure), the proximal steps and the
    tie-break; the outcome in the arena (:func:`finish`)."""
    w = Arena(wf, wi, wh)
    st = ivec(wi, wh, W_STATE)
    code = begin(f, i, h, wf, wi, wh, par)
    while code != DONE:
        if code == NEXT:
            code = advance(f, i, h, wf, wi, wh, par)
            continue
        if code == NEED_TIE:
            sol, ok, status, _ = _daqp(w, settings)
            st[S_TIESTATUS] = status
            code = tie_done(wf, wi, wh, sol, ok)
            continue
        report = report_row(w, st[S_K])
        if code == NEED_QP:
            for attempt in range(3):
                if attempt:  # ill-conditioned and degenerate: 100x more Tikhonov
                    bump(wf, wi, wh, attempt)
                    report[R_RETRIES] += 1
                sol, ok, status, iterations = _daqp(w, settings)
                report[R_STATUS] = status
                report[R_ITER] += iterations
                if ok:
                    break
            code = after_qp(f, i, h, wf, wi, wh, par, sol, ok)
        else:  # NEED_PROXIMAL
            sol, ok, status, iterations = _daqp(w, settings)
            report[R_ITER] += iterations
            code = proximal(f, i, h, wf, wi, wh, par, sol, ok)
    finish(f, i, h, wf, wi, wh, par)
