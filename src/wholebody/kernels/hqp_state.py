"""The hierarchical QP cascade's state: its workspace, the records its kernels pass, and the
report of its outcome.

Between the stage kernels of :mod:`wholebody.kernels.hqp` the cascade's state lives in a
workspace arena (regions ``W_*`` below, laid out like :mod:`wholebody.kernels.layout`'s and
sized by :class:`wholebody.solvers.compiled_hqp.Workspace`): the point ``x``, the relaxed box,
the basis ``Z`` of the free directions (or, after a level certified full rank, ``Z`` and
that level's rows, their null space computed only where a later stage needs one: see
:func:`defer_basis`), the inherited inequality rows, the current level's
least squares and QP, and per level its report. Everything is in the scaled coordinates of
the evaluated stack (:mod:`wholebody.solvers.stack`). The kernels read it as a few records:

* :data:`Arena`: a stack's or a workspace's arenas and header;
* :data:`LevelRows`: a level's equality and inequality rows;
* :data:`Basis`: the free directions the levels above leave;
* :data:`Feasible`: the relaxed box and the inherited rows, which every level's answer meets;
* :data:`Multipliers`: a level's gradient against the active bounds;
* :data:`QP`: the QP a stage set up for the engine.

Also here: the small predicates the stages share (finite rows, inside the bounds, a level's
objective), what the report says of a level (non-finite rows, inequality rows left violated,
tasks the box limited) and :func:`finish`, the outcome written into the stack's arena.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.layout import fmat, fvec, imat, ivec
from wholebody.kernels.linalg import (
    combine,
    complement_solve,
    diagonal,
    dot,
    finite1,
    level_report,
    mtv,
    mv,
    null_basis,
)
from wholebody.kernels.lsq import in_box, product

__all__ = [
    "QP",
    "Arena",
    "Basis",
    "Feasible",
    "LevelRows",
    "Multipliers",
    "apply_basis",
    "bound_limited",
    "box_row",
    "compose_basis",
    "coords",
    "damped_rows",
    "defer_basis",
    "deferred_basis",
    "diagonal_step",
    "finish",
    "finite2",
    "finite_rows",
    "inside",
    "level_int",
    "level_lsq",
    "level_objective",
    "level_rows",
    "make_basis",
    "max_abs",
    "qp_views",
    "report_row",
    "restrict",
    "restrict_into",
    "set_basis",
    "skip_nonfinite",
    "slack",
    "state",
    "task_range",
    "violated",
]

# the solver's settings (par)
P_TOL, P_RANK, P_REG, P_RELAX, P_ACT, P_PROX, P_DAMP = 0, 1, 2, 3, 4, 5, 6
PAR_WIDTH = 7

# workspace regions: floats, then ints
W_X = 0  # (n,): the current point x (scaled coordinates)
W_BOX = 1  # (4, n): lo, hi (relaxed by the bound relaxation, then to contain x), lb, ub
W_Z = 2  # (n n,): the basis Z of the free directions, (n, r) C-ordered
W_INH = 3  # (P, n): the inherited inequality rows G
W_INHB = 4  # (2, P): their bounds glo, ghi
W_XC = 5  # (n,): the level's unconstrained candidate
W_CV = 6  # (m_max + n,): c = b - A x of the level (then lambda Z^T (a - x): damping rows)
W_M = 7  # ((m_max + n) n,): M = A Z of the level (then lambda I), (m (+ r), r) C-ordered
W_NULL = 8  # (n n,): the level's own null space in free coordinates, (r, cols) C-ordered
W_SCAL = 9  # (8,): scalars (C_*)
W_H = 10  # (nv_max^2,): the QP's Hessian, nv x nv row-major
W_G = 11  # (2, nv_max): the QP's gradient, and g0 of the proximal steps
W_QC = 12  # (rows_max nv_max,): the QP's constraint rows, rows x nv row-major
W_QB = 13  # (4, q_max): the QP's row bounds cl, cu and box lb, ub
W_Y = 14  # (2, n): the level's step y, and its residual c - M y (first m)
N_WFLOAT = 15
W_STATE = 15  # (S_WIDTH,): the cascade's state (S_*)
W_REPORT = 16  # (L, R_WIDTH): per level (R_*)
W_LIMITED = 17  # (T + Pt,): per equality then inequality task: limited, violated or bad
N_WREGIONS = 18

S_K, S_R, S_ZI, S_ANYQP, S_EXACT, S_NINH, S_NV, S_NROWS, S_HASBOX, S_RANK = range(10)
S_NULL, S_M, S_P, S_PROX, S_BOXBAD, S_TIEFAIL, S_TIE, S_TIESTATUS = range(10, 18)
S_DEFER_R, S_DEFER_M = 18, 19  # a deferred basis (defer_basis): Z's columns, the level's rows
S_MD = 20  # the damping rows below the level's least squares (r in its damped pass, else 0)
S_WIDTH = 21
C_SMAX, C_D, C_TOL, C_F, C_CLIP, C_RES, C_DAMP = range(7)  # C_DAMP: the level's lambda^2
R_FREE, R_RANK, R_QP, R_FAILED, R_ITER, R_RETRIES, R_STATUS, R_FAIL, R_OBJBAD = range(9)
R_DAMPED = 9  # the level was solved damped (stall damping)
R_WIDTH = 10
FAIL_NONFINITE, FAIL_DECOMPOSITION, FAIL_STEP, FAIL_ENGINE = 1, 2, 3, 4

Arena = namedtuple("Arena", ["f", "i", "h"])
"""A compiled stack's arenas and header (:mod:`wholebody.kernels.layout`), or the cascade's
workspace's (regions ``W_*``); the kernels call the stack's ``s`` and the workspace's ``w``."""

LevelRows = namedtuple("LevelRows", ["A", "b", "C", "lo", "hi"])
"""A level's rows: the equality rows ``A x ~ b`` (least squares) and the inequality rows
``lo <= C x <= hi`` (views of the stack's arena)."""

Basis = namedtuple("Basis", ["Z", "r", "identity"])
"""The free directions the levels above leave, ``x + Z y``: the r columns of ``Z`` (n x r,
orthonormal), or where ``identity`` every direction (``Z`` is then not read, r = n)."""

Feasible = namedtuple("Feasible", ["lo", "hi", "G", "glo", "ghi"])
"""What every level's answer meets: the relaxed box ``lo <= x <= hi`` and the inequality rows
inherited from the levels above, ``glo <= G x <= ghi``."""

Multipliers = namedtuple("Multipliers", ["gnorm", "N", "Ny", "has_mu", "mu", "res"])
"""A level's gradient against the bounds active at a point (:mod:`wholebody.kernels.hqp_level`):
the gradient's norm in the free coordinates (negative: not computed), the active bounds' rows
``N`` (x-space) and ``Ny`` (free coordinates, signed inwards), whether the multipliers ``mu``
that best combine them into the gradient were found, and the norm of what they leave of it."""

QP = namedtuple("QP", ["H", "g", "Q", "qb"])
"""The QP in the workspace, as the engine takes it: ``min 1/2 v^T H v + g^T v`` subject to
``qb[0] <= Q v <= qb[1]`` and, where it has a box, ``qb[2] <= v <= qb[3]``."""


# ---------------------------------------------------------------------- small helpers
@kernel
def finite2(A: np.ndarray) -> bool:
    """Whether every entry of the matrix ``A`` is finite."""
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            if not math.isfinite(A[i, j]):
                return False
    return True


@kernel
def max_abs(A: np.ndarray) -> float:
    """``max |A_ij|`` (0 when empty)."""
    top = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            top = max(top, abs(A[i, j]))
    return top


@kernel
def slack(Cx: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``max(Cx - hi, 0) - max(lo - Cx, 0)``: how far each row is beyond its bounds, signed."""
    out = np.empty(Cx.shape[0])
    for j in range(Cx.shape[0]):
        out[j] = max(Cx[j] - hi[j], 0.0) - max(lo[j] - Cx[j], 0.0)
    return out


@kernel
def inside(x: np.ndarray, bounds: Feasible) -> bool:
    """Whether ``x`` meets the bounds: the relaxed box and the inherited rows."""
    if not in_box(x, bounds.lo, bounds.hi):
        return False
    if bounds.G.shape[0] == 0:
        return True
    Gx = mv(bounds.G, x)
    for j in range(Gx.shape[0]):
        if not (Gx[j] >= bounds.glo[j] and Gx[j] <= bounds.ghi[j]):
            return False
    return True


@kernel
def finite_rows(rows: LevelRows) -> bool:
    """Whether the level's rows are finite (its inequality bounds may be infinite)."""
    if not (finite2(rows.A) and finite1(rows.b) and finite2(rows.C)):
        return False
    for j in range(rows.lo.shape[0]):
        if rows.lo[j] != rows.lo[j] or rows.hi[j] != rows.hi[j]:
            return False
    return True


@kernel
def level_objective(rows: LevelRows, x: np.ndarray) -> float:
    """``1/2 ||A x - b||^2 + 1/2 ||s||^2``, ``s`` the least slack of the inequality rows."""
    r = combine(mv(rows.A, x), -1.0, rows.b)
    f = 0.5 * dot(r, r)
    if rows.C.shape[0]:
        s = slack(mv(rows.C, x), rows.lo, rows.hi)
        f += 0.5 * dot(s, s)
    return f


# ---------------------------------------------------------------------- the free directions
@kernel
def apply_basis(basis: Basis, y: np.ndarray) -> np.ndarray:
    """``Z y``: the step in x of the step ``y`` in the free coordinates (a new vector)."""
    if basis.identity:
        return y.copy()
    return mv(basis.Z, y)


@kernel
def coords(basis: Basis, x: np.ndarray) -> np.ndarray:
    """``Z^T x`` (a new vector)."""
    if basis.identity:
        return x.copy()
    return mtv(basis.Z, x)


@kernel
def restrict(N: np.ndarray, basis: Basis) -> np.ndarray:
    """``N Z``: the rows ``N`` in the free coordinates (a new array)."""
    out = np.empty((N.shape[0], basis.r))
    restrict_into(N, basis, out)
    return out


@kernel
def restrict_into(N: np.ndarray, basis: Basis, out: np.ndarray) -> None:
    """``N Z`` into ``out`` (q x r; not a view of ``N`` or of the basis)."""
    if basis.identity:
        for q in range(N.shape[0]):
            for j in range(basis.r):
                out[q, j] = N[q, j]
    else:
        product(N, basis.Z, out)


# ---------------------------------------------------------------------- reading the arenas
# (A 2-D view costs a reshape, some 40 ns: the hot paths below read 2-D regions by offset.)
@kernel
def level_int(s: Arena, k: int, column: int) -> int:
    """Entry ``column`` (``LEVEL_*``) of level k's row of ``I_LEVEL``."""
    return s.i[s.h[lay.I_LEVEL, 0] + k * lay.LEVEL_INTS + column]


@kernel
def level_rows(s: Arena, k: int) -> LevelRows:
    """Level k's rows in the evaluated stack."""
    r0, r1 = level_int(s, k, lay.LEVEL_ROW0), level_int(s, k, lay.LEVEL_ROW_END)
    p0, p1 = level_int(s, k, lay.LEVEL_INEQ0), level_int(s, k, lay.LEVEL_INEQ_END)
    nu, P = s.h[lay.F_A, 3], s.h[lay.F_CB, 3]
    A = fvec(s.f, s.h, lay.F_A)[r0 * nu : r1 * nu].reshape((r1 - r0, nu))
    C = fvec(s.f, s.h, lay.F_C)[p0 * nu : p1 * nu].reshape((p1 - p0, nu))
    cb = fvec(s.f, s.h, lay.F_CB)
    return LevelRows(A, fvec(s.f, s.h, lay.F_B)[r0:r1], C, cb[p0:p1], cb[P + p0 : P + p1])


@kernel
def report_row(w: Arena, k: int) -> np.ndarray:
    """Level k's report (``R_*``; a view of ``W_REPORT``)."""
    return ivec(w.i, w.h, W_REPORT)[k * R_WIDTH : (k + 1) * R_WIDTH]


@kernel
def box_row(w: Arena, j: int) -> np.ndarray:
    """Row j of ``W_BOX`` (0, 1: the relaxed box; 2, 3: the exact one; a view)."""
    n = w.h[W_X, 1]
    return fvec(w.f, w.h, W_BOX)[j * n : (j + 1) * n]


@kernel
def task_range(tasks: np.ndarray, k: int) -> tuple[int, int]:
    """The indices ``[t0, t1)`` of the rows of ``tasks`` (``(T, 3)``: level, ...) of level k."""
    t0 = 0
    while t0 < tasks.shape[0] and tasks[t0, 0] < k:
        t0 += 1
    t1 = t0
    while t1 < tasks.shape[0] and tasks[t1, 0] == k:
        t1 += 1
    return t0, t1


@kernel
def state(w: Arena):
    """The cascade's state (views of the workspace): ``(st, x, basis, bounds)``, ``st`` the
    integers ``S_*``. Not where the basis is deferred (:func:`make_basis` first)."""
    st = ivec(w.i, w.h, W_STATE)
    x = fvec(w.f, w.h, W_X)
    n, r, ni, P = x.shape[0], st[S_R], st[S_NINH], w.h[W_INHB, 3]
    G = fvec(w.f, w.h, W_INH)[: ni * n].reshape((ni, n))
    gb = fvec(w.f, w.h, W_INHB)
    basis = Basis(fvec(w.f, w.h, W_Z)[: n * r].reshape((n, r)), r, st[S_ZI] == 1)
    return st, x, basis, Feasible(box_row(w, 0), box_row(w, 1), G, gb[:ni], gb[P : P + ni])


@kernel
def make_basis(w: Arena) -> None:
    """The basis of the free directions made where it was deferred (:func:`defer_basis`):
    ``Z N``, ``N`` the null space of the deferring level's ``M``. (Only the levels' stage
    meets a deferred basis: a level that needs a QP never defers its own.)"""
    st = ivec(w.i, w.h, W_STATE)
    if st[S_DEFER_R]:
        r, m = st[S_DEFER_R], st[S_DEFER_M]
        st[S_R], st[S_DEFER_R] = r, 0
        compose_basis(w, null_basis(fvec(w.f, w.h, W_M)[: m * r].reshape((m, r))))


@kernel
def deferred_basis(w: Arena) -> Basis:
    """The basis before the level that deferred its own null space (:func:`defer_basis`)."""
    st = ivec(w.i, w.h, W_STATE)
    n, r = fvec(w.f, w.h, W_X).shape[0], st[S_DEFER_R]
    return Basis(fvec(w.f, w.h, W_Z)[: n * r].reshape((n, r)), r, st[S_ZI] == 1)


@kernel
def defer_basis(w: Arena, m: int) -> None:
    """The free directions become ``Z`` less the row space of the level's ``M = A Z`` (m x r
    in ``W_M``, of full row rank m < r for certain), without computing its null space:
    :func:`make_basis` makes it where the next level needs it; a diagonal level needs none
    (:func:`diagonal_step`)."""
    st = ivec(w.i, w.h, W_STATE)
    st[S_DEFER_R], st[S_DEFER_M] = st[S_R], m
    st[S_R] -= m


@kernel
def diagonal_step(w: Arena, A: np.ndarray, c: np.ndarray, rtol: float):
    """``(ok, dx)``: ``dx = argmin ||A dx - c||`` over the free directions of a deferred basis
    (``Z y`` with ``M y = 0``, ``M`` in ``W_M``) for a nonsingular diagonal ``A`` (n x n),
    by :func:`~wholebody.kernels.linalg.complement_solve`: in x where Z is the identity, else
    for ``A = s I`` in the coordinates ``y`` (``||s Z y - c|| = ||s y - Z^T c||`` up to a
    constant). Not ok where A is not such, or where the certificate does not show the
    cascade's rank rule keeping every free direction (``min |a_j| > 1e3 rtol ||a||``: ``A Z``
    has singular values in ``[min |a_j|, max |a_j|]``), or the solve's."""
    st, basis = ivec(w.i, w.h, W_STATE), deferred_basis(w)
    n, m, r = A.shape[0], st[S_DEFER_M], basis.r
    ok, a = diagonal(A)
    for i in range(n):
        ok = ok and (basis.identity or a[i] == a[0])
    if not ok:
        return False, a
    amin, norm2 = math.inf, 0.0
    for i in range(n):
        amin, norm2 = min(amin, abs(a[i])), norm2 + a[i] * a[i]
    if not (amin > 1e3 * rtol * math.sqrt(norm2) and norm2 < math.inf):
        return False, a
    M = fvec(w.f, w.h, W_M)[: m * r].reshape((m, r))
    ok, dy = complement_solve(M, a[:r], coords(basis, c))
    return ok, apply_basis(basis, dy)


@kernel
def compose_basis(w: Arena, V: np.ndarray) -> None:
    """The free directions become ``Z V`` (V: r x cols, cols <= r, not a view of ``W_Z``):
    the columns of ``V`` where Z is the identity, else computed in place, row by row (a row
    of ``Z V`` only needs the same row of ``Z``, and is no longer than it)."""
    st = ivec(w.i, w.h, W_STATE)
    n, r, cols = fvec(w.f, w.h, W_X).shape[0], st[S_R], V.shape[1]
    Z = fvec(w.f, w.h, W_Z)
    if st[S_ZI] == 1:
        for i in range(n):
            for a in range(cols):
                Z[i * cols + a] = V[i, a]
    else:
        row, acc = np.empty(r), np.empty(cols)
        for i in range(n):
            for j in range(r):
                row[j] = Z[i * r + j]
            acc[:] = 0.0
            for j in range(r):
                z = row[j]
                for a in range(cols):
                    acc[a] += z * V[j, a]
            for a in range(cols):
                Z[i * cols + a] = acc[a]
    st[S_R], st[S_ZI] = cols, 0


@kernel
def set_basis(w: Arena, Z: np.ndarray) -> None:
    """The free directions become the columns of ``Z`` (n x r, a new array)."""
    st = ivec(w.i, w.h, W_STATE)
    n, r = Z.shape
    out = fvec(w.f, w.h, W_Z)[: n * r].reshape((n, r))
    for i in range(n):
        for j in range(r):
            out[i, j] = Z[i, j]
    st[S_R], st[S_ZI] = r, 0


@kernel
def level_lsq(w: Arena):
    """The current level's least squares in the free coordinates (views of the workspace):
    ``(M, c)``, ``M = A Z`` (m x r) and ``c = b - A x``; in the level's damped pass
    (``S_MD = r``) with the damping rows ``lambda I`` and ``lambda Z^T (a - x)`` below
    (``a`` the anchor), so that ``||M y - c||^2`` is the damped objective
    ``||A Z y - c||^2 + lambda^2 ||Z^T (x + Z y - a)||^2``."""
    st = ivec(w.i, w.h, W_STATE)
    m, r = st[S_M] + st[S_MD], st[S_R]
    return fvec(w.f, w.h, W_M)[: m * r].reshape((m, r)), fvec(w.f, w.h, W_CV)[:m]


@kernel
def damped_rows(s: Arena, w: Arena, k: int) -> LevelRows:
    """Level k's rows as its optimality conditions and objective take them (x-space): the
    stack's rows, and in the level's damped pass the damping rows below them,
    ``lambda Z^T x' = lambda Z^T a`` (``a`` the anchor, ``F_ANCHOR``: the damping term
    ``lambda^2 ||Z^T (x' - a)||^2``)."""
    rows = level_rows(s, k)
    st = ivec(w.i, w.h, W_STATE)
    md = st[S_MD]
    if md == 0:
        return rows
    lam = math.sqrt(fvec(w.f, w.h, W_SCAL)[C_DAMP])
    _, _, basis, _ = state(w)
    anchor = fvec(s.f, s.h, lay.F_ANCHOR)
    m, n = rows.A.shape
    # (sliced and reshaped as level_rows' views are: the same array types)
    A = np.empty((m + md) * n)[: (m + md) * n].reshape((m + md, n))
    b = np.empty(m + md)[: m + md]
    A[:m] = rows.A
    b[:m] = rows.b
    A[m:] = 0.0
    for j in range(md):
        if basis.identity:
            A[m + j, j] = lam
            b[m + j] = lam * anchor[j]
        else:
            t = 0.0
            for i in range(n):
                A[m + j, i] = lam * basis.Z[i, j]
                t += basis.Z[i, j] * anchor[i]
            b[m + j] = lam * t
    return LevelRows(A, b, rows.C, rows.lo, rows.hi)


@kernel
def qp_views(w: Arena, nv: int, rows: int) -> QP:
    """The workspace's QP in ``nv`` variables with ``rows`` constraint rows."""
    H = fvec(w.f, w.h, W_H)[: nv * nv].reshape((nv, nv))
    Q = fvec(w.f, w.h, W_QC)[: rows * nv].reshape((rows, nv))
    return QP(H, fmat(w.f, w.h, W_G)[0, :nv], Q, fmat(w.f, w.h, W_QB))


# ---------------------------------------------------------------------- the report
@kernel
def skip_nonfinite(s: Arena, w: Arena, k: int) -> None:
    """Mark level k skipped for non-finite rows, and which of its tasks have them."""
    A, b, C, lo, hi = level_rows(s, k)
    levels = imat(s.i, s.h, lay.I_LEVEL)
    r0, p0 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_INEQ0]
    rep, limited = imat(w.i, w.h, W_REPORT), ivec(w.i, w.h, W_LIMITED)
    tasks, ineq = imat(s.i, s.h, lay.I_TASK), imat(s.i, s.h, lay.I_INEQ)
    T = tasks.shape[0]
    rep[k, R_FAILED], rep[k, R_FAIL] = 1, FAIL_NONFINITE
    t0, t1 = task_range(tasks, k)
    end = r0
    for t in range(t0, t1):
        a, z = tasks[t, 1] - r0, tasks[t, 2] - r0
        end = max(end, tasks[t, 2])
        limited[t] = not (finite2(A[a:z]) and finite1(b[a:z]))
    rep[k, R_OBJBAD] = not (finite2(A[end - r0 :]) and finite1(b[end - r0 :]))
    q0, q1 = task_range(ineq, k)
    for t in range(q0, q1):
        a, z = ineq[t, 1] - p0, ineq[t, 2] - p0
        bad = not finite2(C[a:z])
        for j in range(a, z):
            bad = bad or lo[j] != lo[j] or hi[j] != hi[j]
        limited[T + t] = bad


@kernel
def violated(s: Arena, w: Arena, k: int, Cx: np.ndarray, rows: LevelRows, tol: float, mark: bool):
    """Level k's inequality rows that ``Cx`` violates by more than ``tol`` (a mask), and,
    where ``mark``, their tasks flagged in ``W_LIMITED``."""
    p = Cx.shape[0]
    viol = np.zeros(p, np.bool_)
    some = False
    for j in range(p):
        viol[j] = Cx[j] > rows.hi[j] + tol or Cx[j] < rows.lo[j] - tol
        some = some or viol[j]
    if mark and some:
        ineq, limited = imat(s.i, s.h, lay.I_INEQ), ivec(w.i, w.h, W_LIMITED)
        T = imat(s.i, s.h, lay.I_TASK).shape[0]
        p0 = imat(s.i, s.h, lay.I_LEVEL)[k, lay.LEVEL_INEQ0]
        q0, q1 = task_range(ineq, k)
        for t in range(q0, q1):
            for j in range(ineq[t, 1] - p0, ineq[t, 2] - p0):
                if viol[j]:
                    limited[T + t] = 1
    return viol


@kernel
def bound_limited(s: Arena, w: Arena, par: np.ndarray, k: int, xq: np.ndarray) -> None:
    """Flag level k's tasks whose residual at ``xq`` the box raised above the box-free
    optimum (the unconstrained candidate ``W_XC``); none when no entry of ``xq`` is on the
    box: then the levels above set the residual."""
    lb, ub = box_row(w, 2), box_row(w, 3)
    tasks, limited = imat(s.i, s.h, lay.I_TASK), ivec(w.i, w.h, W_LIMITED)
    t0, t1 = task_range(tasks, k)
    for t in range(t0, t1):
        limited[t] = 0
    on = False
    for j in range(xq.shape[0]):
        if xq[j] <= lb[j] + 1e-7 or xq[j] >= ub[j] - 1e-7:
            on = True
    if not on or t1 == t0:
        return
    rows = level_rows(s, k)
    r0 = level_int(s, k, lay.LEVEL_ROW0)
    unweight = fmat(s.f, s.h, lay.F_ROW)[1, r0 : r0 + rows.A.shape[0]]
    at = np.zeros((t1 - t0, 3))
    free = np.zeros((t1 - t0, 3))
    level_report(rows.A, rows.b, unweight, xq, tasks[t0:t1], r0, at)
    level_report(rows.A, rows.b, unweight, fvec(w.f, w.h, W_XC), tasks[t0:t1], r0, free)
    for t in range(t1 - t0):
        if at[t, 0] - free[t, 0] > par[P_TOL] * (1.0 + at[t, 2]):
            limited[t0 + t] = 1


@kernel
def finish(f, i, h, wf, wi, wh, par) -> None:
    """The outcome in the stack's arena: ``F_U``, the level and task residuals, the tasks met,
    the active bounds and the status (``I_OUT``)."""
    w = Arena(wf, wi, wh)
    st, x, lb, ub = ivec(wi, wh, W_STATE), fvec(wf, wh, W_X), box_row(w, 2), box_row(w, 3)
    rep, limited = ivec(wi, wh, W_REPORT), ivec(wi, wh, W_LIMITED)
    tasks = imat(i, h, lay.I_TASK)
    A, b, rows = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B), fmat(f, h, lay.F_ROW)
    out, lev_out = ivec(i, h, lay.I_OUT), fvec(f, h, lay.F_LEVEL_OUT)
    res, infeasible = fmat(f, h, lay.F_TASK_RES), ivec(i, h, lay.I_INFEASIBLE)
    active = ivec(i, h, lay.I_ACTIVE)
    n = x.shape[0]
    U, D = fvec(f, h, lay.F_U), fvec(f, h, lay.F_METRIC)
    for j in range(n):
        U[j] = x[j]
        U[n + j] = D[j] * x[j]
    tol, act = par[P_TOL], par[P_ACT]
    failures = st[S_BOXBAD] or st[S_TIEFAIL]
    top_unmet = any_limited = False
    s = Arena(f, i, h)
    for k in range(h[lay.I_LEVEL, 2]):
        r0, r1 = level_int(s, k, lay.LEVEL_ROW0), level_int(s, k, lay.LEVEL_ROW_END)
        t0, t1 = task_range(tasks, k)
        lev_out[2 * k], lev_out[2 * k + 1] = 0.0, 1.0
        if r1 > r0:
            lev_out[2 * k] = level_report(
                A[r0:r1], b[r0:r1], rows[1, r0:r1], x, tasks[t0:t1], r0, res[t0:t1]
            )
        failed = rep[k * R_WIDTH + R_FAILED] == 1
        failures = failures or failed
        for t in range(t0, t1):
            met = res[t, 0] <= tol * (1.0 + res[t, 2])  # (a NaN residual is not met)
            empty = tasks[t, 2] == tasks[t, 1]
            infeasible[t] = 0 if empty or (met and not failed) else 1
            top_unmet = top_unmet or (k == 0 and infeasible[t] == 1)
    for t in range(limited.shape[0]):
        any_limited = any_limited or limited[t] == 1
    any_active = False
    for j in range(n):
        active[j] = x[j] <= lb[j] + act or x[j] >= ub[j] - act
        any_active = any_active or active[j] == 1
    if failures:
        status = 4
    elif any_limited or top_unmet:
        status = 3
    elif any_active:
        status = 1
    else:
        status = 0
    out[lay.OUT_STATUS], out[lay.OUT_FAILED] = status, failures
