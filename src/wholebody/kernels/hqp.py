"""The hierarchical QP's cascade in kernels: everything but the QP engine's own solves.

The algorithm, its decisions and thresholds are those of the reference
:class:`wholebody.solvers.hqp.HierarchicalQPSolver` (method ``"cascade"``; read its module
docstring for the maths): level by level the exact unconstrained candidate by a complete
orthogonal decomposition, and where it leaves the box or an inequality, the level's QP, then
the polish that removes the Tikhonov bias (with the exact bounded least squares, BVLS, where
only the box bounds the level), the level's optimality conditions, proximal steps, the
constraints the level's optimum presses on fixed for the levels below, and at the end the
minimum-norm tie-break.

The QPs themselves are solved by the engine in Python (daqp by default), so the cascade runs
as a few kernel calls that stop where a QP is needed: :func:`begin`, :func:`advance` (the
levels), :func:`after_qp`, :func:`proximal` and :func:`tie_done` each return what to do next
(``NEXT``: call :func:`advance`; ``NEED_QP``, ``NEED_PROXIMAL``, ``NEED_TIE`` or ``DONE``);
the QP's data are in the workspace (``W_H``, ``W_G``, ``W_QC``, ``W_QB``). The stages are
separate kernels rather than one calling the next because numba compiles every kernel
together with all it calls: a chain of stages would compile the whole cascade once per
stage. The cascade's state between the calls is the workspace arena
(regions ``W_*``, laid out like :mod:`wholebody.kernels.layout`'s): the point ``x``, the
relaxed box, the basis ``Z`` of the free directions (or the identity), the inherited
inequality rows, and per level its report.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import daqp as dk
from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.lapack import gels, geqp3, gesdd, orgqr, potrf, trtri, trtrs
from wholebody.kernels.layout import fmat, fvec, imat, ivec
from wholebody.kernels.linalg import (
    NORMAL_KAPPA,
    cholesky_inverse,
    combine,
    dot,
    fortran,
    frobenius2,
    gather_rows,
    level_report,
    mm,
    mmt,
    mtm,
    mtv,
    mv,
    normal_solve,
    null_basis,
)

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
    "finish",
    "proximal",
    "tie_done",
]

DONE, NEED_QP, NEED_PROXIMAL, NEED_TIE, NEXT = 0, 1, 2, 3, 4

# the solver's settings (par)
P_TOL, P_RANK, P_REG, P_RELAX, P_ACT, P_PROX = 0, 1, 2, 3, 4, 5
PAR_WIDTH = 6

# workspace regions: floats, then ints
W_X = 0  # (n,): the current point x (scaled coordinates)
W_BOX = 1  # (4, n): lo, hi (relaxed by the bound relaxation, then to contain x), lb, ub
W_Z = 2  # (n, n): the basis Z of the free directions in its first r columns
W_INH = 3  # (P, n): the inherited inequality rows G
W_INHB = 4  # (2, P): their bounds glo, ghi
W_XC = 5  # (n,): the level's unconstrained candidate
W_CV = 6  # (m_max,): c = b - A x of the level
W_M = 7  # (m_max, n): M = A Z of the level (first r columns)
W_NULL = 8  # (n, n): the level's own null space in free coordinates (r x cols)
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
S_WIDTH = 18
C_SMAX, C_D, C_TOL, C_F, C_CLIP, C_RES = range(6)
R_FREE, R_RANK, R_QP, R_FAILED, R_ITER, R_RETRIES, R_STATUS, R_FAIL, R_OBJBAD = range(9)
R_WIDTH = 9
FAIL_NONFINITE, FAIL_DECOMPOSITION, FAIL_STEP, FAIL_ENGINE = 1, 2, 3, 4
_MARGIN = 1e3  # safety factor of the full-column-rank certificate (round-off)
_EPS = 2.220446049250313e-16
_ACT = 1e-8  # the polish's activity threshold
_FLAT = 1e-12  # a QP row whose coefficients are at most this (relative) is left unbounded


# ---------------------------------------------------------------------- small helpers
@kernel
def _column(c: np.ndarray) -> np.ndarray:
    """``c`` as a new (m, 1) matrix."""
    out = np.empty((c.shape[0], 1))
    for j in range(c.shape[0]):
        out[j, 0] = c[j]
    return out


@kernel
def _t(A: np.ndarray) -> np.ndarray:
    """``A^T`` as a new C-ordered array."""
    out = np.empty((A.shape[1], A.shape[0]))
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[j, i] = A[i, j]
    return out


@kernel
def _residual(M: np.ndarray, y: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``c - M y``."""
    return combine(c, -1.0, mv(M, y))


@kernel
def _gradient(A: np.ndarray, x: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A^T (A x - b)``."""
    return mtv(A, combine(mv(A, x), -1.0, b))


@kernel
def _slack(Cx: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``max(Cx - hi, 0) - max(lo - Cx, 0)``: how far each row is beyond its bounds, signed."""
    out = np.empty(Cx.shape[0])
    for j in range(Cx.shape[0]):
        out[j] = max(Cx[j] - hi[j], 0.0) - max(lo[j] - Cx[j], 0.0)
    return out


@kernel
def _columns_of(A: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The columns ``idx`` of ``A``."""
    out = np.empty((A.shape[0], idx.shape[0]))
    for i in range(A.shape[0]):
        for q in range(idx.shape[0]):
            out[i, q] = A[i, idx[q]]
    return out


@kernel
def _where(mask: np.ndarray, value: bool) -> np.ndarray:
    """The indices where ``mask == value``."""
    count = 0
    for j in range(mask.shape[0]):
        count += mask[j] == value
    out = np.empty(count, np.int64)
    c = 0
    for j in range(mask.shape[0]):
        if mask[j] == value:
            out[c] = j
            c += 1
    return out


@kernel
def _max_abs(A: np.ndarray) -> float:
    """``max |A_ij|`` (0 when empty)."""
    top = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            top = max(top, abs(A[i, j]))
    return top


@kernel
def _all_zero(a: np.ndarray) -> bool:
    for j in range(a.shape[0]):
        if a[j] != 0:
            return False
    return True


@kernel
def _finite1(a: np.ndarray) -> bool:
    for j in range(a.shape[0]):
        if not math.isfinite(a[j]):
            return False
    return True


@kernel
def _finite2(A: np.ndarray) -> bool:
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            if not math.isfinite(A[i, j]):
                return False
    return True


# ---------------------------------------------------------------------- linear algebra
@kernel
def _rank_certificate(M: np.ndarray, Rinv: np.ndarray, rtol: float, floor: float) -> float:
    """``kappa_F^2 = ||R^-1||_F^2 ||M||_F^2`` when the rank rule of :func:`cod` is certain to
    find full column rank for a tall M (the reference's ``_rank_certificate``), else -1."""
    inv2 = frobenius2(Rinv)
    k2 = inv2 * frobenius2(M)
    m = M.shape[0]
    margin = _MARGIN * rtol
    if k2 * m * margin * margin < 1.0 and inv2 * m * floor * floor < 1.0:
        return k2
    return -1.0


@kernel
def _normal_solve(M: np.ndarray, c: np.ndarray, rtol: float, floor: float):
    """The tall ``M``'s least-squares solution by its normal equations where they are
    accurate and full column rank is certain: ``(ok, y)`` (the reference's
    ``_normal_solve``)."""
    r = M.shape[1]
    U = fortran(mtm(M, M))
    if potrf(U, False) != 0 or trtri(U, False) != 0:
        return False, c[:r].copy()
    k2 = _rank_certificate(M, U, rtol, floor)
    if not (k2 >= 0 and k2 <= NORMAL_KAPPA * NORMAL_KAPPA):
        return False, c[:r].copy()
    return True, normal_solve(M, U.T, _column(c), k2)[:, 0]


@kernel
def _transposed(M: np.ndarray) -> np.ndarray:
    """``M^T`` as a new Fortran-ordered array (its memory: M's rows)."""
    m, r = M.shape
    out = np.empty((m, r))  # C-ordered (m, r): the Fortran-ordered (r, m) transpose
    for i in range(m):
        for j in range(r):
            out[i, j] = M[i, j]
    return out.T


@kernel
def _tall_solve(M: np.ndarray, c: np.ndarray, rtol: float, floor: float):
    """A tall ``M`` (m > r): ``(done, y, have_tall, tall)``: its least squares by the normal
    equations or by LAPACK's QR (``gels``) where full column rank is certain (``done``),
    else the QR's solution if it has one (the reference's start of ``_cod``)."""
    r = M.shape[1]
    ok, y = _normal_solve(M, c, rtol, floor)
    if ok:
        return True, y, False, y
    lqr = fortran(M)
    z = c.copy()
    if gels(lqr, z) != 0:
        return False, y, False, y
    tall = z[:r].copy()
    R = fortran(lqr[:r, :r])
    done = trtri(R, False) == 0 and _rank_certificate(M, R, rtol, floor) >= 0
    return done, tall, True, tall


@kernel
def _pivoted_rank(qr: np.ndarray, k: int, rtol: float, floor: float) -> tuple[float, int]:
    """``(|R_00|, rank)`` of a pivoted QR: the diagonal entries above ``max(rtol |R_00|,
    floor)``, none where ``|R_00| <= floor``."""
    smax, rank = 0.0, 0
    if k:
        smax = abs(qr[0, 0])
        if smax > floor:
            thr = max(rtol * smax, floor)
            for j in range(k):
                if abs(qr[j, j]) > thr:
                    rank += 1
    return smax, rank


@kernel
def _triangular_solve(qr: np.ndarray, c: np.ndarray, jpvt: np.ndarray, rank: int):
    """``(info, z)``: the coordinates on the range ``Q_1`` of the pivoted ``M^T = Q R P^T``'s
    least squares, ``R_11^T z = P^T c`` (or its lower-trapezoidal least squares)."""
    m = c.shape[0]
    cp = np.empty(m)
    for j in range(m):
        cp[j] = c[jpvt[j] - 1]
    if rank == m:  # R_11^T a = P^T c, triangular
        return trtrs(qr[:rank, :rank], cp, False, True), cp
    R1t = np.zeros((rank, m)).T  # (m x rank) lower-trapezoidal least squares
    for a in range(rank):
        for b in range(a, m):
            R1t[b, a] = qr[a, b]
    return gels(R1t, cp), cp


@kernel
def cod(M: np.ndarray, c: np.ndarray, t: np.ndarray, rtol: float, floor: float):
    """Minimum-norm least squares with a rank threshold by a complete orthogonal
    decomposition (the reference's ``_cod``): ``(info, rank, y, Q2, smax, known)`` with
    ``y = Q_1 a - Q_2 Q_2^T t``, ``Q2`` the null space (r x (r - rank); None in the
    reference when rank = r: here 0 columns), ``smax = |R_00|`` when ``known``; ``info``
    nonzero where LAPACK failed (the reference raises)."""
    m, r = M.shape
    none = np.zeros((r, 0))
    have_tall = False
    tall = np.zeros(r)
    if m > r > 0:
        done, tall, have_tall, _ = _tall_solve(M, c, rtol, floor)
        if done:
            return 0, r, tall, none, 0.0, False
    k = min(m, r)
    qr = _transposed(M)  # Fortran-ordered M^T (r x m)
    jpvt = np.zeros(max(m, 1), np.int32)
    tau = np.zeros(max(k, 1))
    info = geqp3(qr, jpvt[:m], tau[:k])
    if info != 0:
        return info, 0, np.zeros(r), none, 0.0, True
    smax, rank = _pivoted_rank(qr, k, rtol, floor)
    if rank == r and have_tall:  # full column rank, more rows: the unique solution
        return 0, rank, tall, none, smax, True
    info, y, Q2 = _cod_solution(qr, tau, jpvt, c, t, k, rank)
    if info != 0:
        return info, 0, np.zeros(r), none, 0.0, True
    return 0, rank, y, Q2, smax, True


@kernel
def _cod_solution(qr, tau, jpvt, c, t, k, rank):  # fmt: skip
    """From the pivoted QR of ``M^T`` (``qr``, ``tau``, ``jpvt``; ``k`` reflectors) and its
    rank: ``(info, y, Q2)``, ``y = Q_1 a - Q_2 Q_2^T t`` and ``Q2`` the null space (0
    columns at full rank)."""
    r = qr.shape[0]
    Q = np.zeros((r, r)).T
    for j in range(k):
        for i in range(r):
            Q[i, j] = qr[i, j]
    info = orgqr(Q, tau, k, 8 * r)
    if info != 0:
        return info, np.zeros(r), np.zeros((r, 0))
    y = np.zeros(r)
    if rank:
        info, z = _triangular_solve(qr, c, jpvt, rank)
        if info != 0:
            return info, np.zeros(r), np.zeros((r, 0))
        for a in range(rank):
            for i in range(r):
                y[i] += Q[i, a] * z[a]
    if rank == r:
        return 0, y, np.zeros((r, 0))
    Q2 = np.empty((r, r - rank))
    for i in range(r):
        for a in range(r - rank):
            Q2[i, a] = Q[i, rank + a]
    for j in range(t.shape[0]):  # (t = 0: nothing to remove, often at the first level)
        if t[j] != 0:
            y = combine(y, -1.0, mv(Q2, mtv(Q2, t)))
            break
    return 0, y, Q2


@kernel
def _pivot_norm(M: np.ndarray) -> float:
    """``|R_00|`` of the pivoted QR of ``M^T``."""
    m, r = M.shape
    if min(m, r) == 0:
        return 0.0
    qr = _transposed(M)
    jpvt = np.zeros(m, np.int32)
    tau = np.zeros(min(m, r))
    if geqp3(qr, jpvt, tau) != 0:
        return 0.0
    return abs(qr[0, 0])


@kernel
def _full_row_rank(Nz: np.ndarray, rtol: float, floor: float) -> bool:
    """Whether ``Nz`` (q x r, q <= r) certainly has q singular values above
    ``max(rtol s_max, floor)`` (the reference's ``_full_row_rank``)."""
    ok, Linv = cholesky_inverse(mmt(Nz, Nz))
    if not ok:
        return False
    inv2 = frobenius2(Linv)
    margin = _MARGIN * rtol
    return inv2 * frobenius2(Nz) * margin * margin < 1.0 and inv2 * (_MARGIN * floor) ** 2 < 1.0


@kernel
def _null_space(Nz: np.ndarray, Z: np.ndarray, identity: bool, rtol: float,
                floor: float) -> np.ndarray:  # fmt: skip
    """Basis of ``{Z y : Nz y = 0}`` (``identity``: Z = I); singular values at most
    ``max(rtol s_max, floor)`` count as zero (the reference's ``_null_space``, with its
    certified QR route)."""
    q, r = Nz.shape
    if 0 < q <= r and _full_row_rank(Nz, rtol, floor):
        V2 = null_basis(Nz)
        return V2 if identity else mm(Z, V2)
    _, _, S, Vt = gesdd(fortran(Nz), True)
    rank = 0
    if S.shape[0] and S[0] > floor:
        thr = max(rtol * S[0], floor)
        for s in S:
            if thr < s:
                rank += 1
    V2 = np.empty((r, r - rank))
    for j in range(r):
        for a in range(r - rank):
            V2[j, a] = Vt[rank + a, j]
    return V2 if identity else mm(Z, V2)


# ---------------------------------------------------------------------- reading the stack
@kernel
def _rows(f, i, h, k):  # fmt: skip
    """Level k's equality rows ``A, b``, inequality rows ``C, lower, upper`` and the first
    rows of each."""
    levels = imat(i, h, lay.I_LEVEL)
    r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_ROW_END]
    p0, p1 = levels[k, lay.LEVEL_INEQ0], levels[k, lay.LEVEL_INEQ_END]
    A, b = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B)
    C, cb = fmat(f, h, lay.F_C), fmat(f, h, lay.F_CB)
    return A[r0:r1], b[r0:r1], C[p0:p1], cb[0, p0:p1], cb[1, p0:p1], r0, p0


@kernel
def _task_range(tasks: np.ndarray, k: int) -> tuple[int, int]:
    """The indices ``[t0, t1)`` of the rows of ``tasks`` (``(T, 3)``: level, ...) of level k."""
    t0 = 0
    while t0 < tasks.shape[0] and tasks[t0, 0] < k:
        t0 += 1
    t1 = t0
    while t1 < tasks.shape[0] and tasks[t1, 0] == k:
        t1 += 1
    return t0, t1


@kernel
def _finite_level(A, b, C, lo, hi) -> bool:  # fmt: skip
    """Whether the level's rows are finite (its inequality bounds may be infinite)."""
    if not (_finite2(A) and _finite1(b) and _finite2(C)):
        return False
    for j in range(lo.shape[0]):
        if lo[j] != lo[j] or hi[j] != hi[j]:
            return False
    return True


@kernel
def _skip_nonfinite(f, i, h, wi, wh, k) -> None:  # fmt: skip
    """Mark the level skipped for non-finite rows, and which of its tasks have them."""
    A, b, C, lo, hi, r0, p0 = _rows(f, i, h, k)
    rep, limited = imat(wi, wh, W_REPORT), ivec(wi, wh, W_LIMITED)
    tasks, ineq = imat(i, h, lay.I_TASK), imat(i, h, lay.I_INEQ)
    T = tasks.shape[0]
    rep[k, R_FAILED], rep[k, R_FAIL] = 1, FAIL_NONFINITE
    t0, t1 = _task_range(tasks, k)
    end = r0
    for t in range(t0, t1):
        a, z = tasks[t, 1] - r0, tasks[t, 2] - r0
        end = max(end, tasks[t, 2])
        limited[t] = not (_finite2(A[a:z]) and _finite1(b[a:z]))
    rep[k, R_OBJBAD] = not (_finite2(A[end - r0 :]) and _finite1(b[end - r0 :]))
    q0, q1 = _task_range(ineq, k)
    for t in range(q0, q1):
        a, z = ineq[t, 1] - p0, ineq[t, 2] - p0
        bad = not _finite2(C[a:z])
        for j in range(a, z):
            bad = bad or lo[j] != lo[j] or hi[j] != hi[j]
        limited[T + t] = bad


@kernel
def _violated(f, i, h, wi, wh, k, Cx, lo, hi, tol, mark) -> np.ndarray:  # fmt: skip
    """The level's inequality rows that ``Cx`` violates by more than ``tol`` (a mask), and,
    where ``mark``, their tasks flagged in ``W_LIMITED``."""
    p = Cx.shape[0]
    viol = np.zeros(p, np.bool_)
    some = False
    for j in range(p):
        viol[j] = Cx[j] > hi[j] + tol or Cx[j] < lo[j] - tol
        some = some or viol[j]
    if mark and some:
        ineq, limited = imat(i, h, lay.I_INEQ), ivec(wi, wh, W_LIMITED)
        T = imat(i, h, lay.I_TASK).shape[0]
        p0 = imat(i, h, lay.I_LEVEL)[k, lay.LEVEL_INEQ0]
        q0, q1 = _task_range(ineq, k)
        for t in range(q0, q1):
            for j in range(ineq[t, 1] - p0, ineq[t, 2] - p0):
                if viol[j]:
                    limited[T + t] = 1
    return viol


@kernel
def _inside_rows(x: np.ndarray, G: np.ndarray, glo: np.ndarray, ghi: np.ndarray) -> bool:
    """Whether ``x`` meets the inherited rows ``glo <= G x <= ghi``."""
    if G.shape[0] == 0:
        return True
    Gx = mv(G, x)
    for j in range(Gx.shape[0]):
        if not (Gx[j] >= glo[j] and Gx[j] <= ghi[j]):
            return False
    return True


@kernel
def _in_box(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    for j in range(x.shape[0]):
        if not (x[j] >= lo[j] and x[j] <= hi[j]):
            return False
    return True


@kernel
def _inside(x, lo, hi, G, glo, ghi) -> bool:  # fmt: skip
    return _in_box(x, lo, hi) and _inside_rows(x, G, glo, ghi)


@kernel
def _level_objective(A, b, C, lo, hi, x) -> float:  # fmt: skip
    """``1/2 ||A x - b||^2 + 1/2 ||s||^2``, ``s`` the least slack of the inequality rows."""
    r = combine(mv(A, x), -1.0, b)
    f = 0.5 * dot(r, r)
    if C.shape[0]:
        s = _slack(mv(C, x), lo, hi)
        f += 0.5 * dot(s, s)
    return f


# ---------------------------------------------------------------------- the state
@kernel
def _state(wf, wi, wh):  # fmt: skip
    """The cascade's state: ``(st, x, box, Z, G, gb, n_inherited)``."""
    st = ivec(wi, wh, W_STATE)
    ni = st[S_NINH]
    G, gb = fmat(wf, wh, W_INH), fmat(wf, wh, W_INHB)
    return st, fvec(wf, wh, W_X), fmat(wf, wh, W_BOX), fmat(wf, wh, W_Z), G[:ni], gb[:, :ni], ni


@kernel
def _apply_Z(Z: np.ndarray, r: int, identity: bool, y: np.ndarray) -> np.ndarray:
    """``Z y`` (Z: the first r columns; the identity)."""
    if identity:
        return y.copy()
    return mv(Z[:, :r], y)


@kernel
def _Zt(Z: np.ndarray, r: int, identity: bool, x: np.ndarray) -> np.ndarray:
    """``Z^T x``."""
    if identity:
        return x.copy()
    return mtv(Z[:, :r], x)


@kernel
def _restrict(N: np.ndarray, Z: np.ndarray, r: int, identity: bool) -> np.ndarray:
    """``N Z`` (rows in the free coordinates; a copy of N where Z is the identity)."""
    if identity:
        return N.copy()
    return mm(N, Z[:, :r])


# ---------------------------------------------------------------------- optimality
@kernel
def _active_rows(x, lo, hi, G, glo, ghi, act):  # fmt: skip
    """The rows (x-space) of the bounds and inherited rows active at ``x`` (within
    ``act``), signed inwards: ``(N, signs)``."""
    n = x.shape[0]
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
def _active_multipliers(A, b, C, clo, chi, x, Z, r, identity, lo, hi, G, glo, ghi, act,
                        rank_tol):  # fmt: skip
    """The norm of the level's gradient in the free coordinates, the rows ``N`` (x-space)
    of the constraints active at ``x`` (within ``act``), their multipliers (``has_mu``
    False when none is active) and the norm of what the normals leave of the gradient (the
    reference's ``_active_multipliers``): ``(gnorm, N, has_mu, mu, res)``."""
    g = _gradient(A, x, b)
    if C.shape[0]:
        g = combine(g, 1.0, mtv(C, _slack(mv(C, x), clo, chi)))
    gy = _Zt(Z, r, identity, g)
    gnorm = math.sqrt(dot(gy, gy))
    N, signs = _active_rows(x, lo, hi, G, glo, ghi, act)
    count = N.shape[0]
    if count == 0:
        return gnorm, N, False, np.zeros(0), gnorm
    Ny = _restrict(N, Z, r, identity)
    for q in range(count):
        for j in range(Ny.shape[1]):
            Ny[q, j] *= signs[q]
    info, _, mu, _, _, _ = cod(_t(Ny), gy, np.zeros(count), rank_tol, 0.0)
    if info != 0:
        return gnorm, N, False, np.zeros(0), gnorm
    res = combine(mtv(Ny, mu), -1.0, gy)
    return gnorm, N, True, mu, math.sqrt(dot(res, res))


@kernel
def _box_conditions(g: np.ndarray, y: np.ndarray, lb: np.ndarray, ub: np.ndarray,
                    act: float) -> bool:  # fmt: skip
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
def _box_optimal(M, c, y, lb, ub, act) -> bool:  # fmt: skip
    """Whether ``y`` meets the optimality conditions of ``min ||M y - c||`` over ``[lb, ub]``
    (the reference's ``_box_optimal``, rtol 1e-4)."""
    return _box_conditions(_gradient(M, y, c), y, lb, ub, act)


@kernel
def _optimal(A, b, x, Z, r, identity, lo, hi, G, glo, ghi, act, rank_tol) -> bool:  # fmt: skip
    """Whether ``x`` meets the optimality conditions of the level's least squares (the
    reference's ``_optimal``, rtol 1e-4)."""
    if identity and G.shape[0] == 0:  # the normals are unit vectors: mu = +-g on the bounds
        return _box_conditions(_gradient(A, x, b), x, lo, hi, act)
    C0 = np.zeros((0, x.shape[0]))
    e = np.zeros(0)
    gn, _, has_mu, mu, res = _active_multipliers(A, b, C0, e, e, x, Z, r, identity, lo, hi, G,
                                                 glo, ghi, act, rank_tol)  # fmt: skip
    if gn == 0.0:
        return True
    if not (has_mu and res <= 1e-4 * gn):
        return False
    for q in range(mu.shape[0]):
        if not mu[q] >= -1e-4 * gn:
            return False
    return True


# ---------------------------------------------------------------------- the cascade
@kernel
def begin(f, i, h, wf, wi, wh, par) -> int:  # fmt: skip
    """Start the cascade of the evaluated stack: NEXT (:func:`advance` runs the levels), or
    DONE where the box is empty."""
    st = ivec(wi, wh, W_STATE)
    st[:] = 0
    imat(wi, wh, W_REPORT)[:, :] = 0
    ivec(wi, wh, W_LIMITED)[:] = 0
    box, x = fmat(wf, wh, W_BOX), fvec(wf, wh, W_X)
    ab = fmat(f, h, lay.F_BOX)
    fvec(wf, wh, W_SCAL)[:] = 0.0
    bt = par[P_RELAX]
    for j in range(x.shape[0]):
        if not ab[0, j] <= ab[1, j]:  # NaN compares false; evaluate never crosses the box
            st[S_BOXBAD] = 1
            x[:] = 0.0
            return DONE
    for j in range(x.shape[0]):
        box[2, j], box[3, j] = ab[0, j], ab[1, j]
        x[j] = min(max(0.0, ab[0, j]), ab[1, j])  # the minimum-norm point of the box
        box[0, j], box[1, j] = ab[0, j] - bt, ab[1, j] + bt
    st[S_R], st[S_ZI], st[S_EXACT] = x.shape[0], 1, 1
    return NEXT


@kernel
def advance(f, i, h, wf, wi, wh, par) -> int:  # fmt: skip
    """Levels from the current one until one needs a QP (NEED_QP); after the last, the
    tie-break (NEED_TIE) or the clip (DONE)."""
    st = ivec(wi, wh, W_STATE)
    L = imat(i, h, lay.I_LEVEL).shape[0]
    while st[S_K] < L:
        if _level(f, i, h, wf, wi, wh, par, st[S_K]) == NEED_QP:
            return NEED_QP
        st[S_K] += 1
    return _end(wf, wi, wh)


@kernel
def _level_step(f, i, h, wf, wi, wh, par, k):  # fmt: skip
    """Level k's unconstrained step in the free coordinates (the reference's exact
    candidate): ``(code, y, rank, smax, known, null_cols)``, code DONE where the level is
    skipped (non-finite rows, a failed decomposition), else NEED_QP; ``c`` and ``M`` go to
    the workspace, the null space of M to ``W_NULL``."""
    rank_tol = par[P_RANK]
    st, x, _, Z, _, _, _ = _state(wf, wi, wh)
    rep = imat(wi, wh, W_REPORT)
    A, b, C, clo, chi, _, _ = _rows(f, i, h, k)
    n, r, identity, m = x.shape[0], st[S_R], st[S_ZI] == 1, A.shape[0]
    t = _Zt(Z, r, identity, x)
    if m == 0:
        return NEED_QP, combine(np.zeros(r), -1.0, t), 0, 0.0, True, -1
    Mw, cw, Nw = fmat(wf, wh, W_M), fvec(wf, wh, W_CV), fmat(wf, wh, W_NULL)
    c = b.copy()
    if not identity or not _all_zero(x):  # (x = 0: c = b, even where A is not finite)
        c = combine(b, -1.0, mv(A, x))
    M = _restrict(A, Z, r, identity)
    for q in range(m):
        cw[q] = c[q]
        for j in range(r):
            Mw[q, j] = M[q, j]
    sw = fmat(f, h, lay.F_LEVEL)[k, lay.LEVEL_IDENTITY] if m == n else 0.0
    if sw > 0:  # rows sw * I: M = sw Z has r singular values sw
        y = _Zt(Z, r, identity, c)
        for j in range(r):
            y[j] /= sw
        return NEED_QP, y, r, sw, True, -1
    floor = 0.0 if identity else rank_tol * math.sqrt(frobenius2(A))
    info, rank, y, Q2, smax, known = cod(M, c, t, rank_tol, floor)
    if info != 0:
        if not _finite_level(A, b, C, clo, chi):
            _skip_nonfinite(f, i, h, wi, wh, k)
        else:
            rep[k, R_FAILED], rep[k, R_FAIL] = 1, FAIL_DECOMPOSITION
        return DONE, y, 0, 0.0, True, -1
    null_cols = -1
    if rank < r:
        null_cols = Q2.shape[1]
        for j in range(r):
            for q in range(null_cols):
                Nw[j, q] = Q2[j, q]
    return NEED_QP, y, rank, smax, known, null_cols


@kernel
def _level(f, i, h, wf, wi, wh, par, k) -> int:  # fmt: skip
    """Level k up to its QP (the reference's loop body): the unconstrained candidate, taken
    where it is feasible; else the QP is set up and NEED_QP returned."""
    tol = par[P_TOL]
    st, x, box, Z, G, gb, _ = _state(wf, wi, wh)
    rep = imat(wi, wh, W_REPORT)
    A, b, C, clo, chi, _, _ = _rows(f, i, h, k)
    r, identity = st[S_R], st[S_ZI] == 1
    m, p = A.shape[0], C.shape[0]
    rep[k, R_FREE] = r
    if r == 0:  # nothing left to move: report the inequality rows x leaves violated
        if not _finite_level(A, b, C, clo, chi):
            _skip_nonfinite(f, i, h, wi, wh, k)
        elif p:
            _violated(f, i, h, wi, wh, k, mv(C, x), clo, chi, tol, True)
        return DONE
    if p and not _finite_level(A, b, C, clo, chi):
        _skip_nonfinite(f, i, h, wi, wh, k)
        return DONE
    code, y, rank, smax, known, null_cols = _level_step(f, i, h, wf, wi, wh, par, k)
    if code == DONE:
        return DONE
    if m and (rank == 0 or not _finite1(y)) and not _finite_level(A, b, C, clo, chi):
        _skip_nonfinite(f, i, h, wi, wh, k)
        return DONE
    if not _finite1(y):  # finite rows, yet the decomposition overflowed
        rep[k, R_FAILED], rep[k, R_FAIL] = 1, FAIL_STEP
        return DONE
    rep[k, R_RANK] = rank
    xc = combine(x, 1.0, _apply_Z(Z, r, identity, y))
    in_box = _in_box(xc, box[2], box[3])
    st[S_RANK], st[S_NULL], st[S_M], st[S_P] = rank, null_cols, m, p
    if ((in_box or _in_box(xc, box[0], box[1])) and _inside_rows(xc, G, gb[0], gb[1])
            and (p == 0 or _rows_inside(mv(C, xc), clo, chi, tol))):  # fmt: skip
        x[:] = xc
        st[S_EXACT] = in_box
        _close(f, i, h, wf, wi, wh, par, k)
        return DONE
    st[S_ANYQP] = 1
    if m and rank == 0 and p == 0:
        # rows with nothing left to move (round-off in the free directions, or a task the
        # levels above fix): only the minimum-norm step left the box; the tie-break decides
        _close(f, i, h, wf, wi, wh, par, k)
        return DONE
    rep[k, R_QP] = 1
    if not known:  # certified full rank: |R_00| only now needed
        smax = _pivot_norm(fmat(wf, wh, W_M)[:m, :r])
    fvec(wf, wh, W_XC)[:] = xc
    fvec(wf, wh, W_SCAL)[C_SMAX] = smax
    _qp_setup(f, i, h, wf, wi, wh, par, k)
    return NEED_QP


@kernel
def _rows_inside(v: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float) -> bool:
    for j in range(v.shape[0]):
        if not (v[j] >= lo[j] - tol and v[j] <= hi[j] + tol):
            return False
    return True


@kernel
def _flat(Q: np.ndarray, q: int, r: int, scale: float) -> bool:
    """Whether row ``q`` of the QP's rows moves with ``y`` only at rounding level: its largest
    coefficient at most ``_FLAT max(1, scale)`` (the reference's ``_flat``)."""
    top = 0.0
    for j in range(r):
        top = max(top, abs(Q[q, j]))
    return top <= _FLAT * max(1.0, scale)


@kernel
def _qp_rows(Q, qb, row, N, lo, hi, x, Z, r, identity, widen) -> None:  # fmt: skip
    """Rows ``N Z`` of the QP from ``row`` on, with the bounds ``lo - N x``, ``hi - N x``.
    Where ``widen``: widened to contain 0, so that y = 0 is feasible, and a row the free
    directions move only at rounding level left unbounded (see :func:`_qp_box`)."""
    Nx = mv(N, x)
    Nz = _restrict(N, Z, r, identity)
    for q in range(N.shape[0]):
        for j in range(r):
            Q[row + q, j] = Nz[q, j]
        lo_q, hi_q = lo[q] - Nx[q], hi[q] - Nx[q]
        if widen and _flat(Q, row + q, r, _max_abs(N[q : q + 1])):
            qb[0, row + q], qb[1, row + q] = -np.inf, np.inf
            continue
        qb[0, row + q] = min(lo_q, 0.0) if widen else lo_q
        qb[1, row + q] = max(hi_q, 0.0) if widen else hi_q


@kernel
def _qp_box(Q, qb, x, box, Z, r, identity) -> int:  # fmt: skip
    """The relaxed box of the QP in ``y``: the QP's own box where Z is the identity, else
    rows ``Z`` (returns the rows used). A joint the free directions move only at rounding
    level (``|Z_q| <= _FLAT``) gets no row bounds: it cannot leave its bound through ``y``,
    and two such rows of opposite sign on joints at their bounds pinned ``y`` to 0 (the
    engines then solved, or declared infeasible, a degenerate problem)."""
    n = x.shape[0]
    if identity:
        for j in range(r):
            qb[2, j], qb[3, j] = box[0, j] - x[j], box[1, j] - x[j]
        return 0
    for q in range(n):
        for j in range(r):
            Q[q, j] = Z[q, j]
        if _flat(Q, q, r, 1.0):
            qb[0, q], qb[1, q] = -np.inf, np.inf
        else:
            qb[0, q], qb[1, q] = box[0, q] - x[q], box[1, q] - x[q]
    return n


@kernel
def _qp_setup(f, i, h, wf, wi, wh, par, k) -> None:  # fmt: skip
    """The level's QP in ``(y, s)`` (the reference's ``_level_qp`` up to the engine):
    ``min 1/2 ||M y - c||^2 + d/2 ||y||^2 + 1/2 ||s||^2`` subject to the relaxed box (as
    rows of Z, or the QP's own box where Z is the identity), the inherited rows (widened to
    contain x) and the level's inequality rows with their slacks."""
    st, x, box, Z, G, gb, ni = _state(wf, wi, wh)
    _, _, C, clo, chi, _, _ = _rows(f, i, h, k)
    r, identity, m, p = st[S_R], st[S_ZI] == 1, st[S_M], st[S_P]
    n = x.shape[0]
    nv = r + p
    smax = fvec(wf, wh, W_SCAL)[C_SMAX]
    d = par[P_REG] * (smax * smax if smax > 0 else 1.0)
    fvec(wf, wh, W_SCAL)[C_D] = d
    H = fvec(wf, wh, W_H)[: nv * nv].reshape((nv, nv))
    g = fmat(wf, wh, W_G)[0, :nv]
    H[:, :] = 0.0
    g[:] = 0.0
    if m:
        M, c = fmat(wf, wh, W_M)[:m, :r], fvec(wf, wh, W_CV)[:m]
        MtM, Mtc = mtm(M, M), mtv(M, c)
        for a in range(r):
            g[a] = -Mtc[a]
            for j in range(r):
                H[a, j] = MtM[a, j]
    for j in range(r):
        H[j, j] += d
    for j in range(r, nv):
        H[j, j] = 1.0
    nrows = (0 if identity else n) + ni + p
    Q = fvec(wf, wh, W_QC)[: nrows * nv].reshape((nrows, nv))
    qb = fmat(wf, wh, W_QB)
    Q[:, :] = 0.0
    if identity:
        qb[2, :nv] = -np.inf
        qb[3, :nv] = np.inf
    row = _qp_box(Q, qb, x, box, Z, r, identity)
    if ni:  # widened to contain x, so that y = 0 is feasible
        _qp_rows(Q, qb, row, G, gb[0], gb[1], x, Z, r, identity, True)
        row += ni
    if p:
        _qp_rows(Q, qb, row, C, clo, chi, x, Z, r, identity, False)
        for j in range(p):
            Q[row + j, r + j] = -1.0
    st[S_NV], st[S_NROWS], st[S_HASBOX] = nv, nrows, identity


@kernel
def bump(wf, wi, wh, attempt) -> None:  # fmt: skip
    """After an engine failure: the Tikhonov term times 100 (the reference's retry)."""
    st = ivec(wi, wh, W_STATE)
    d = fvec(wf, wh, W_SCAL)[C_D]
    nv = st[S_NV]
    H = fvec(wf, wh, W_H)[: nv * nv].reshape((nv, nv))
    for j in range(st[S_R]):
        H[j, j] += d * (100.0**attempt - 100.0 ** (attempt - 1))


@kernel
def after_qp(f, i, h, wf, wi, wh, par, sol, ok) -> int:  # fmt: skip
    """The level's QP answer ``sol`` (``ok``: the engine solved it): polish, optimality
    check, then the proximal steps (NEED_PROXIMAL) or the level's close (NEXT)."""
    st, x, box, Z, G, gb, _ = _state(wf, wi, wh)
    k, r, identity, m, p = st[S_K], st[S_R], st[S_ZI] == 1, st[S_M], st[S_P]
    if not ok:
        imat(wi, wh, W_REPORT)[k, R_FAILED] = 1
        imat(wi, wh, W_REPORT)[k, R_FAIL] = FAIL_ENGINE
        st[S_K] += 1
        return NEXT
    A, b, C, clo, chi, _, _ = _rows(f, i, h, k)
    y = sol[:r].copy()
    M, c = fmat(wf, wh, W_M)[:m, :r], fvec(wf, wh, W_CV)[:m]
    if m == 0:
        if p:  # only inequality rows: their slack is the level's least squares
            y = _polish(f, i, h, wf, wi, wh, par, k, y, M, c, True)
        return _finish_level(f, i, h, wf, wi, wh, par, y)
    y = _polish(f, i, h, wf, wi, wh, par, k, y, M, c, p > 0)
    xq = combine(x, 1.0, _apply_Z(Z, r, identity, y))
    if p == 0 and _optimal(A, b, xq, Z, r, identity, box[0], box[1], G, gb[0], gb[1], par[P_ACT],
                           par[P_RANK]):  # fmt: skip
        return _finish_level(f, i, h, wf, wi, wh, par, y)
    scal, gg, yr = fvec(wf, wh, W_SCAL), fmat(wf, wh, W_G), fmat(wf, wh, W_Y)
    gg[1, :r] = gg[0, :r]
    scal[C_TOL] = par[P_TOL] * (1.0 + math.sqrt(dot(c, c)))
    scal[C_F] = _level_objective(A, b, C, clo, chi, xq) if p else 0.0
    res = _residual(M, y, c)
    scal[C_RES] = math.sqrt(dot(res, res))
    yr[0, :r] = y
    st[S_PROX] = 0
    if _next_proximal(wf, wi, wh, par) == NEED_PROXIMAL:
        return NEED_PROXIMAL
    return _finish_level(f, i, h, wf, wi, wh, par, y)


@kernel
def _next_proximal(wf, wi, wh, par) -> int:  # fmt: skip
    """Another proximal step (the Tikhonov term centred on the last answer: NEED_PROXIMAL),
    or 0 where the level is done with them."""
    st = ivec(wi, wh, W_STATE)
    scal, gg, yr = fvec(wf, wh, W_SCAL), fmat(wf, wh, W_G), fmat(wf, wh, W_Y)
    r = st[S_R]
    if st[S_PROX] >= int(par[P_PROX]) or scal[C_RES] <= scal[C_TOL]:
        return 0
    for j in range(r):
        gg[0, j] = gg[1, j] - scal[C_D] * yr[0, j]
    return NEED_PROXIMAL


@kernel
def proximal(f, i, h, wf, wi, wh, par, sol, ok) -> int:  # fmt: skip
    """A proximal step's QP answer: kept if it fits the level better (the reference's loop);
    NEED_PROXIMAL for another, or the level's close (NEXT)."""
    st, x, _, Z, _, _, _ = _state(wf, wi, wh)
    k, r, identity, m, p = st[S_K], st[S_R], st[S_ZI] == 1, st[S_M], st[S_P]
    scal, yr = fvec(wf, wh, W_SCAL), fmat(wf, wh, W_Y)
    st[S_PROX] += 1
    y = yr[0, :r].copy()
    if not ok:
        return _finish_level(f, i, h, wf, wi, wh, par, y)
    A, b, C, clo, chi, _, _ = _rows(f, i, h, k)
    M, c = fmat(wf, wh, W_M)[:m, :r], fvec(wf, wh, W_CV)[:m]
    yn = _polish(f, i, h, wf, wi, wh, par, k, sol[:r].copy(), M, c, p > 0)
    rn = _residual(M, yn, c)
    fn = 0.0
    if p:
        fn = _level_objective(A, b, C, clo, chi, combine(x, 1.0, _apply_Z(Z, r, identity, yn)))
    if p and fn > scal[C_F]:
        return _finish_level(f, i, h, wf, wi, wh, par, y)
    rnorm = math.sqrt(dot(rn, rn))
    better = scal[C_RES] - rnorm
    if better <= 0.0:
        return _finish_level(f, i, h, wf, wi, wh, par, y)
    yr[0, :r] = yn
    scal[C_RES], scal[C_F] = rnorm, fn
    if better <= 1e-3 * scal[C_TOL] or _next_proximal(wf, wi, wh, par) != NEED_PROXIMAL:
        return _finish_level(f, i, h, wf, wi, wh, par, yn)
    return NEED_PROXIMAL


@kernel
def _finish_level(f, i, h, wf, wi, wh, par, y) -> int:  # fmt: skip
    """The level's QP answer ``x + Z y`` taken: which tasks the box limited, the level's
    close; NEXT."""
    st, x, _, Z, _, _, _ = _state(wf, wi, wh)
    k, r, identity, m = st[S_K], st[S_R], st[S_ZI] == 1, st[S_M]
    xq = combine(x, 1.0, _apply_Z(Z, r, identity, y))
    if m:
        _bound_limited(f, i, h, wf, wi, wh, par, k, xq)
    x[:] = xq
    r_level, identity_level = st[S_R], st[S_ZI] == 1
    Z_level = Z[:, :r_level].copy() if not identity_level else np.zeros((x.shape[0], 0))
    _close_rows(wf, wi, wh)
    _pin(f, i, h, wf, wi, wh, par, k, Z_level, r_level, identity_level)
    _close_rest(f, i, h, wf, wi, wh, par, k)
    st[S_K] += 1
    return NEXT


@kernel
def _bound_limited(f, i, h, wf, wi, wh, par, k, xq) -> None:  # fmt: skip
    """Flag the level's tasks whose residual the box raised above the box-free optimum (none
    when no entry of ``xq`` is on the box: then the levels above set the residual)."""
    box = fmat(wf, wh, W_BOX)
    tasks, limited = imat(i, h, lay.I_TASK), ivec(wi, wh, W_LIMITED)
    t0, t1 = _task_range(tasks, k)
    for t in range(t0, t1):
        limited[t] = 0
    on = False
    for j in range(xq.shape[0]):
        if xq[j] <= box[2, j] + 1e-7 or xq[j] >= box[3, j] - 1e-7:
            on = True
    if not on or t1 == t0:
        return
    A, b, _, _, _, r0, _ = _rows(f, i, h, k)
    unweight = fmat(f, h, lay.F_ROW)[1, r0 : r0 + A.shape[0]]
    at = np.zeros((t1 - t0, 3))
    free = np.zeros((t1 - t0, 3))
    level_report(A, b, unweight, xq, tasks[t0:t1], r0, at)
    level_report(A, b, unweight, fvec(wf, wh, W_XC), tasks[t0:t1], r0, free)
    for t in range(t1 - t0):
        if at[t, 0] - free[t, 0] > par[P_TOL] * (1.0 + at[t, 2]):
            limited[t0 + t] = 1


@kernel
def _inherit(wf, wi, wh, C, Cx, clo, chi, viol, bt) -> None:  # fmt: skip
    """The level's inequality rows kept for the levels below, their bounds widened to
    contain ``Cx`` (a violated row held where it is) and relaxed by ``bt``."""
    st = ivec(wi, wh, W_STATE)
    ni, p = st[S_NINH], C.shape[0]
    Gw, gbw = fmat(wf, wh, W_INH), fmat(wf, wh, W_INHB)
    for j in range(p):
        for c in range(C.shape[1]):
            Gw[ni + j, c] = C[j, c]
        lo_j = Cx[j] if viol[j] else clo[j]
        hi_j = Cx[j] if viol[j] else chi[j]
        gbw[0, ni + j] = min(lo_j, Cx[j]) - bt
        gbw[1, ni + j] = max(hi_j, Cx[j]) + bt
    st[S_NINH] = ni + p


@kernel
def _set_Z(Z: np.ndarray, Znew: np.ndarray) -> None:
    """The basis of the free directions replaced by ``Znew``'s columns."""
    for i in range(Znew.shape[0]):
        for j in range(Znew.shape[1]):
            Z[i, j] = Znew[i, j]


@kernel
def _close(f, i, h, wf, wi, wh, par, k) -> None:  # fmt: skip
    """The level's optimal set where no QP ran (the reference's end of a level): its rows
    fixed, its inequality rows inherited, the relaxed box widened to contain x."""
    _close_rows(wf, wi, wh)
    _close_rest(f, i, h, wf, wi, wh, par, k)


@kernel
def _close_rows(wf, wi, wh) -> None:  # fmt: skip
    """The level's rows fixed: the basis Z times the level's own null space."""
    st, x, _, Z, _, _, _ = _state(wf, wi, wh)
    n, r, identity, rank = x.shape[0], st[S_R], st[S_ZI] == 1, st[S_RANK]
    if rank:
        cols = max(st[S_NULL], 0)
        null = fmat(wf, wh, W_NULL)[:r, :cols]
        _set_Z(Z, null.copy() if identity else mm(Z[:, :r], null))
        r, identity = cols, False
    st[S_R], st[S_ZI] = (n, 1) if identity else (r, 0)


@kernel
def _pin(f, i, h, wf, wi, wh, par, k, Z_level, r_level, identity_level) -> None:  # fmt: skip
    """After a QP: the constraints the level's optimum presses on fixed too (their rows
    removed from the free directions), found at the level's basis ``Z_level``."""
    st, x, box, Z, G, gb, _ = _state(wf, wi, wh)
    A, b, C, clo, chi, _, _ = _rows(f, i, h, k)
    r, identity = st[S_R], st[S_ZI] == 1
    if not (imat(wi, wh, W_REPORT)[k, R_QP] and st[S_M] and (identity or r > 0)):
        return
    smax = fvec(wf, wh, W_SCAL)[C_SMAX]
    delta = par[P_REG] * (smax * smax if smax > 0 else 1.0)
    pins = _strongly_active(A, b, C, clo, chi, x, Z_level, r_level, identity_level, box[0],
                            box[1], G, gb[0], gb[1], delta, par)  # fmt: skip
    if pins.shape[0]:
        floor = par[P_RANK] * _max_abs(pins)
        Znew = _null_space(_restrict(pins, Z, r, identity), Z[:, :r], identity, par[P_RANK],
                           floor)  # fmt: skip
        _set_Z(Z, Znew)
        st[S_R], st[S_ZI] = Znew.shape[1], 0


@kernel
def _close_rest(f, i, h, wf, wi, wh, par, k) -> None:  # fmt: skip
    """The level's inequality rows inherited by the levels below and the relaxed box widened
    to contain x."""
    st, x, box, _, _, _, _ = _state(wf, wi, wh)
    _, _, C, clo, chi, _, _ = _rows(f, i, h, k)
    if C.shape[0]:
        Cx = mv(C, x)
        qp = imat(wi, wh, W_REPORT)[k, R_QP] == 1
        viol = _violated(f, i, h, wi, wh, k, Cx, clo, chi, par[P_TOL], qp)
        _inherit(wf, wi, wh, C, Cx, clo, chi, viol, par[P_RELAX])
    if k != imat(i, h, lay.I_LEVEL).shape[0] - 1 or st[S_ANYQP]:
        for j in range(x.shape[0]):
            box[0, j] = min(box[0, j], x[j])
            box[1, j] = max(box[1, j], x[j])


@kernel
def _strongly_active(A, b, C, clo, chi, x, Z, r, identity, lo, hi, G, glo, ghi, delta,
                     par) -> np.ndarray:  # fmt: skip
    """Rows (x-space) of the constraints the level's own objective presses on at ``x`` (the
    reference's ``_strongly_active``); none where the bounds cost the level nothing."""
    gnorm, N, has_mu, mu, _ = _active_multipliers(A, b, C, clo, chi, x, Z, r, identity, lo, hi,
                                                  G, glo, ghi, par[P_ACT], par[P_RANK])  # fmt: skip
    floor = max(1e-3 * par[P_TOL] * max(1.0, math.sqrt(dot(b, b))),
                100.0 * delta * max(1.0, math.sqrt(dot(x, x))))  # fmt: skip
    n = x.shape[0]
    if gnorm <= floor or not has_mu:
        return np.zeros((0, n))
    scale = max(1.0, _max_abs(N if identity else mm(N, Z)))
    pin = np.empty(mu.shape[0], np.bool_)
    for q in range(mu.shape[0]):
        pin[q] = mu[q] > max(1e-6 * gnorm, floor) / scale
    return gather_rows(N, pin)


# ---------------------------------------------------------------------- polish and BVLS
@kernel
def _touching(M, c, Cz, Cx, v, clo, chi):  # fmt: skip
    """The level's least squares ``(M, c)`` with the inequality rows at or beyond a bound
    at ``v`` joined, as equalities on that bound."""
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
def _polish(f, i, h, wf, wi, wh, par, k, y, M, c, with_rows) -> np.ndarray:  # fmt: skip
    """Remove the Tikhonov bias (the reference's ``_polish``): the level's least squares
    solved exactly on the face of the constraints active at the QP's answer; with
    ``with_rows`` its inequality rows at or beyond a bound join the least squares and the
    result is kept only if the level's objective is lower."""
    st, x, box, Z, G, gb, _ = _state(wf, wi, wh)
    r, identity = st[S_R], st[S_ZI] == 1
    Mc, cc = M.copy(), c.copy()  # (C-ordered: one compiled polish)
    if not with_rows:
        return _polish_box(x, y, Z, r, identity, Mc, cc, box[0], box[1], G, gb[0], gb[1], par)[0]
    A, b, C, clo, chi, _, _ = _rows(f, i, h, st[S_K])
    Cz = _restrict(C, Z, r, identity)
    Cx = mv(C, x)
    M2, c2 = _touching(Mc, cc, Cz, Cx, combine(Cx, 1.0, mv(Cz, y)), clo, chi)
    yp, changed = _polish_box(x, y, Z, r, identity, M2, c2, box[0], box[1], G, gb[0], gb[1],
                              par)  # fmt: skip
    if not changed:
        return y
    xq = combine(x, 1.0, _apply_Z(Z, r, identity, y))
    xp = combine(x, 1.0, _apply_Z(Z, r, identity, yp))
    better = _level_objective(A, b, C, clo, chi, xp) < _level_objective(A, b, C, clo, chi, xq)
    return yp if better else y


@kernel
def _face(x, Z, r, identity, M, on, G, gon, rank_tol):  # fmt: skip
    """The least squares on the face of the active bounds ``on`` and inherited rows
    ``gon``: ``(MW, W)``, ``W`` an orthonormal basis (in the free coordinates) of the
    directions that keep them."""
    n = x.shape[0]
    n_on, n_g = 0, 0
    for j in range(n):
        n_on += on[j]
    for j in range(gon.shape[0]):
        n_g += gon[j]
    if n_on + n_g == 0:
        return M.copy(), np.eye(r)
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
    W = _null_space(_restrict(N, Z, r, identity), Z[:, :r], True, rank_tol, 0.0)
    return mm(M, W), W


@kernel
def _polish_box(x, y, Z, r, identity, M, c, lo, hi, G, glo, ghi, par):  # fmt: skip
    """The polish on the box and the inherited rows: ``(y', changed)``."""
    rank_tol = par[P_RANK]
    n = x.shape[0]
    xq = combine(x, 1.0, _apply_Z(Z, r, identity, y))
    on = np.empty(n, np.bool_)
    for j in range(n):
        on[j] = xq[j] <= lo[j] + _ACT or xq[j] >= hi[j] - _ACT
    Gx = mv(G, xq) if G.shape[0] else np.zeros(0)
    gon = np.empty(Gx.shape[0], np.bool_)
    n_g = 0
    for j in range(Gx.shape[0]):
        gon[j] = Gx[j] <= glo[j] + _ACT or Gx[j] >= ghi[j] - _ACT
        n_g += gon[j]
    res = _residual(M, y, c)
    only_box = identity and n_g == 0
    if only_box:  # only bounds of x: keep those entries, move the others
        idx = _where(on, False)
        MW = _columns_of(M, idx)
        W = np.zeros((0, 0))
    else:
        idx = np.zeros(0, np.int64)
        MW, W = _face(x, Z, r, identity, M, on, G, gon, rank_tol)
    if MW.shape[1] == 0:
        return y, False
    info, _, w, _, _, _ = cod(MW, res, np.zeros(MW.shape[1]), rank_tol, 0.0)
    if info != 0:
        return y, False
    yp = y.copy()
    if only_box:
        for q in range(idx.shape[0]):
            yp[idx[q]] += w[q]
    else:
        yp = combine(yp, 1.0, mv(W, w))
    if not _finite1(yp):
        return y, False
    rp = _residual(M, yp, c)
    changed = True
    if dot(rp, rp) > dot(res, res) or not _inside(combine(x, 1.0, _apply_Z(Z, r, identity, yp)),
                                                  lo, hi, G, glo, ghi):  # fmt: skip
        yp, rp, changed = y, res, False
    if only_box and math.sqrt(dot(rp, rp)) > par[P_TOL] * (1.0 + math.sqrt(dot(c, c))):
        lb, ub = combine(lo, -1.0, x), combine(hi, -1.0, x)
        if not _box_optimal(M, c, yp, lb, ub, par[P_ACT]):
            yb = _bvls(M, c, lb, ub, 20 * M.shape[1] + 20, 1e-13)
            for j in range(yb.shape[0]):
                yb[j] = min(max(yb[j], lb[j]), ub[j])
            rb = _residual(M, yb, c)
            if (_finite1(yb) and dot(rb, rb) < dot(rp, rp)
                    and _inside(combine(x, 1.0, yb), lo, hi, G, glo, ghi)):  # fmt: skip
                return yb, True
    return yp, changed


@kernel
def _lstsq(A: np.ndarray, b: np.ndarray, rcond: float) -> np.ndarray:
    """The minimum-norm least-squares solution of ``A x = b`` by the SVD, singular values
    below ``rcond s_max`` counted as zero (``rcond < 0``: machine precision)."""
    m, n = A.shape
    x = np.zeros(n)
    if min(m, n) == 0:
        return x
    info, U, s, Vt = gesdd(fortran(A), False)
    if info != 0:
        x[:] = np.nan
        return x
    cut = (_EPS if rcond < 0 else rcond) * s[0]
    c = mtv(U, b)
    for k in range(s.shape[0]):
        if s[k] > cut:
            a = c[k] / s[k]
            for j in range(n):
                x[j] += a * Vt[k, j]
    return x


@kernel
def _free_lstsq(A: np.ndarray, b: np.ndarray, x: np.ndarray, state: np.ndarray,
                rcond: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The free variables (``state == 0``) and their least squares with the others fixed
    at ``x``: ``(idx, z)``."""
    fixed = np.zeros(x.shape[0])
    idx = np.empty(_count_free(state), np.int64)
    q = 0
    for j in range(x.shape[0]):
        if state[j] != 0:
            fixed[j] = x[j]
        else:
            idx[q] = j
            q += 1
    return idx, _lstsq(_columns_of(A, idx), combine(b, -1.0, mv(A, fixed)), rcond)


@kernel
def _bvls(A: np.ndarray, b: np.ndarray, lb: np.ndarray, ub: np.ndarray, max_iter: int,
          tol: float) -> np.ndarray:  # fmt: skip
    """Bounded-variable least squares ``min ||A x - b||`` over ``lb <= x <= ub`` (Stark and
    Parker 1995) as the reference calls it, ``scipy.optimize.lsq_linear(method="bvls")``:
    from the unconstrained solution, variables outside the box set on their bounds until the
    free ones' least squares is inside; then, while the optimality conditions fail by
    ``tol``, the variable whose gradient points inwards most is freed and the free ones move
    towards their least squares, stopping at the first bound reached."""
    m, n = A.shape
    x = _lstsq(A, b, -1.0)
    if _in_box(x, lb, ub):
        return x
    state = np.zeros(n)  # -1 on lb, 1 on ub, 0 free
    for j in range(n):
        if x[j] <= lb[j]:
            x[j], state[j] = lb[j], -1.0
        elif x[j] >= ub[j]:
            x[j], state[j] = ub[j], 1.0
    rcond = _EPS * max(m, n)
    iteration = 0
    while _count_free(state):  # the free variables' least squares inside the box
        iteration += 1
        idx, z = _free_lstsq(A, b, x, state, rcond)
        violated = False
        for q in range(idx.shape[0]):
            j = idx[q]
            if z[q] < lb[j]:
                x[j], state[j], violated = lb[j], -1.0, True
            elif z[q] > ub[j]:
                x[j], state[j], violated = ub[j], 1.0, True
            else:
                x[j] = z[q]
        if not violated:
            break
    r = combine(mv(A, x), -1.0, b)
    cost = 0.5 * dot(r, r)
    g = mtv(A, r)
    for _ in range(iteration, max_iter + iteration):
        if _kkt(g, state) < tol:
            break
        state[_most_inward(g, state)] = 0.0
        _bvls_free(A, b, lb, ub, x, state, rcond)
        r = combine(mv(A, x), -1.0, b)
        new = 0.5 * dot(r, r)
        change = cost - new
        cost = new
        g = mtv(A, r)
        if change < tol * cost:
            break
    return x


@kernel
def _count_free(state: np.ndarray) -> int:
    count = 0
    for j in range(state.shape[0]):
        count += state[j] == 0
    return count


@kernel
def _most_inward(g: np.ndarray, state: np.ndarray) -> int:
    """``argmax(g * state)`` (the first of equals)."""
    best, at = -np.inf, 0
    for j in range(g.shape[0]):
        v = g[j] * state[j]
        if v != v:  # numpy's argmax: the first NaN
            return j
        if v > best:
            best, at = v, j
    return at


@kernel
def _kkt(g: np.ndarray, state: np.ndarray) -> float:
    """The largest violation of the bounded least squares' optimality conditions."""
    worst = -np.inf
    for j in range(g.shape[0]):
        v = abs(g[j]) if state[j] == 0 else g[j] * state[j]
        worst = max(worst, v)
    return worst


@kernel
def _bvls_free(A, b, lb, ub, x, state, rcond) -> None:  # fmt: skip
    """Move the free variables towards their least squares (the bound ones fixed), stopping
    at the first bound reached and fixing that variable there, until the least squares is
    inside the box."""
    while True:
        idx, z = _free_lstsq(A, b, x, state, rcond)
        alpha, hit, side = np.inf, -1, 0.0
        for q in range(idx.shape[0]):  # lower-bound violations first, then upper (argmin)
            j = idx[q]
            if z[q] < lb[j]:
                a = (lb[j] - x[j]) / (z[q] - x[j])
                if a < alpha:
                    alpha, hit, side = a, q, -1.0
        for q in range(idx.shape[0]):
            j = idx[q]
            if z[q] > ub[j]:
                a = (ub[j] - x[j]) / (z[q] - x[j])
                if a < alpha:
                    alpha, hit, side = a, q, 1.0
        if hit < 0:
            for q in range(idx.shape[0]):
                x[idx[q]] = z[q]
            return
        for q in range(idx.shape[0]):
            j = idx[q]
            x[j] = x[j] * (1.0 - alpha) + alpha * z[q]
        state[idx[hit]] = side


# ---------------------------------------------------------------------- the end
@kernel
def _end(wf, wi, wh) -> int:  # fmt: skip
    """After the last level: the exact minimum-norm point of the last optimal set where a QP
    ran and freedom is left (NEED_TIE when it needs one), and the clip to the exact box."""
    st, x, box, Z, G, gb, _ = _state(wf, wi, wh)
    r, identity = st[S_R], st[S_ZI] == 1
    if r and st[S_ANYQP]:
        t = _Zt(Z, r, identity, x)
        xc = combine(x, -1.0, _apply_Z(Z, r, identity, t))
        if _inside(xc, box[0], box[1], G, gb[0], gb[1]):
            x[:] = xc
        else:
            _tie_setup(wf, wi, wh, t)
            return NEED_TIE
    return _clip(wf, wi, wh)


@kernel
def _tie_setup(wf, wi, wh, t) -> None:  # fmt: skip
    """``min 1/2 ||x + Z y||^2`` over the relaxed box and the inherited rows: H = I, g = t."""
    st, x, box, Z, G, gb, ni = _state(wf, wi, wh)
    r, identity = st[S_R], st[S_ZI] == 1
    n = x.shape[0]
    H = fvec(wf, wh, W_H)[: r * r].reshape((r, r))
    H[:, :] = 0.0
    for j in range(r):
        H[j, j] = 1.0
    fmat(wf, wh, W_G)[0, :r] = t
    nrows = (0 if identity else n) + ni
    Q = fvec(wf, wh, W_QC)[: nrows * r].reshape((nrows, r))
    qb = fmat(wf, wh, W_QB)
    row = _qp_box(Q, qb, x, box, Z, r, identity)
    if ni:  # widened to contain x, as in the level QPs
        _qp_rows(Q, qb, row, G, gb[0], gb[1], x, Z, r, identity, True)
    st[S_NV], st[S_NROWS], st[S_HASBOX], st[S_TIE] = r, nrows, identity, 1


@kernel
def tie_done(wf, wi, wh, sol, ok) -> int:  # fmt: skip
    """The tie-break's answer (kept the last level's where the engine failed); DONE."""
    st, x, _, Z, _, _, _ = _state(wf, wi, wh)
    if ok:
        dx = _apply_Z(Z, st[S_R], st[S_ZI] == 1, sol[: st[S_R]].copy())
        for j in range(x.shape[0]):
            x[j] += dx[j]
    else:
        st[S_TIEFAIL] = 1
    return _clip(wf, wi, wh)


@kernel
def _clip(wf, wi, wh) -> int:  # fmt: skip
    """``x`` clipped to the exact box (by the relaxation and engine tolerances at most),
    where anything may have moved it outside."""
    st, x, box, _, _, _, _ = _state(wf, wi, wh)
    scal = fvec(wf, wh, W_SCAL)
    scal[C_CLIP] = 0.0
    if st[S_EXACT] and not st[S_ANYQP]:
        return DONE
    worst = 0.0
    for j in range(x.shape[0]):
        v = min(max(x[j], box[2, j]), box[3, j])
        worst = max(worst, abs(v - x[j]))
        x[j] = v
    scal[C_CLIP] = worst
    return DONE


@kernel
def finish(f, i, h, wf, wi, wh, par) -> None:  # fmt: skip
    """The outcome in the stack's arena: ``F_U``, residuals, met tasks, active bounds and the
    status (``I_OUT``), as the reference's ``_result``."""
    st, x, box, _, _, _, _ = _state(wf, wi, wh)
    rep, limited = imat(wi, wh, W_REPORT), ivec(wi, wh, W_LIMITED)
    levels, tasks = imat(i, h, lay.I_LEVEL), imat(i, h, lay.I_TASK)
    A, b, rows = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B), fmat(f, h, lay.F_ROW)
    out, lev_out = ivec(i, h, lay.I_OUT), fmat(f, h, lay.F_LEVEL_OUT)
    res, infeasible = fmat(f, h, lay.F_TASK_RES), ivec(i, h, lay.I_INFEASIBLE)
    active = ivec(i, h, lay.I_ACTIVE)
    U, D = fmat(f, h, lay.F_U), fmat(f, h, lay.F_METRIC)[0]
    for j in range(x.shape[0]):
        U[0, j] = x[j]
        U[1, j] = D[j] * x[j]
    tol, act = par[P_TOL], par[P_ACT]
    failures = st[S_BOXBAD] or st[S_TIEFAIL]
    top_unmet = any_limited = False
    for k in range(levels.shape[0]):
        r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_ROW_END]
        t0, t1 = _task_range(tasks, k)
        lev_out[k, 0], lev_out[k, 1] = 0.0, 1.0
        if r1 > r0:
            lev_out[k, 0] = level_report(A[r0:r1], b[r0:r1], rows[1, r0:r1], x, tasks[t0:t1],
                                         r0, res[t0:t1])  # fmt: skip
        failures = failures or rep[k, R_FAILED] == 1
        for t in range(t0, t1):
            met = res[t, 0] <= tol * (1.0 + res[t, 2])  # (a NaN residual is not met)
            empty = tasks[t, 2] == tasks[t, 1]
            infeasible[t] = 0 if empty or (met and not rep[k, R_FAILED]) else 1
            top_unmet = top_unmet or (k == 0 and infeasible[t] == 1)
    for t in range(limited.shape[0]):
        any_limited = any_limited or limited[t] == 1
    any_active = False
    for j in range(x.shape[0]):
        active[j] = x[j] <= box[2, j] + act or x[j] >= box[3, j] - act
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


# ---------------------------------------------------------------------- daqp in the kernel
# QP statuses as the engines report them (wholebody.solvers.qp.QPStatus)
QP_SOLVED, QP_INACCURATE, QP_INFEASIBLE, QP_FAILED = 0, 1, 2, 3


@kernel
def _daqp(wf, wi, wh, settings) -> tuple[np.ndarray, bool, int, int]:  # fmt: skip
    """The QP the cascade set up in the workspace, solved by daqp: ``(sol, ok, status,
    iterations)`` with ``sol`` padded to the workspace's width (zeros where not ok) and the
    status an engine's (``QP_*``). The box (where the QP has one) goes first, as daqp's
    simple bounds; crossed bounds are infeasible without a call."""
    st = ivec(wi, wh, W_STATE)
    nv, rows, has_box = st[S_NV], st[S_NROWS], st[S_HASBOX] != 0
    H = fvec(wf, wh, W_H)[: nv * nv].reshape((nv, nv))
    g = fmat(wf, wh, W_G)[0, :nv]
    Q = fvec(wf, wh, W_QC)[: rows * nv].reshape((rows, nv))
    qb = fmat(wf, wh, W_QB)
    ms = nv if has_box else 0
    m = ms + rows
    upper, lower = np.empty(m), np.empty(m)
    if has_box:
        upper[:nv], lower[:nv] = qb[3, :nv], qb[2, :nv]
    upper[ms:], lower[ms:] = qb[1, :rows], qb[0, :rows]
    sol = np.zeros(fmat(wf, wh, W_G).shape[1])
    for j in range(m):
        if not lower[j] <= upper[j]:
            return sol, False, QP_INFEASIBLE, 0
    x, lam = np.empty(nv), np.empty(m)
    flag, iterations = dk.solve(H, g, Q, upper, lower, np.zeros(m, np.int32), settings, x, lam)
    if flag == dk.OPTIMAL or flag == dk.SOFT_OPTIMAL:
        status = QP_SOLVED
    elif flag == dk.ITERLIMIT:
        status = QP_INACCURATE
    elif flag == dk.INFEASIBLE:
        status = QP_INFEASIBLE
    else:
        status = QP_FAILED
    ok = status <= QP_INACCURATE and _finite1(x)
    if ok:
        sol[:nv] = x
    return sol, ok, status, iterations


@kernel
def cascade(f, i, h, wf, wi, wh, par, settings) -> None:  # fmt: skip
    """The whole cascade on the evaluated stack with daqp for its QPs, in one call: the
    stages of this module in the order their codes ask for, the engine's retries (the
    Tikhonov term 100 and 10000 times larger after a failure), the proximal steps and the
    tie-break; the outcome in the arena (:func:`finish`)."""
    report = imat(wi, wh, W_REPORT)
    st = ivec(wi, wh, W_STATE)
    code = begin(f, i, h, wf, wi, wh, par)
    while code != DONE:
        if code == NEXT:
            code = advance(f, i, h, wf, wi, wh, par)
            continue
        if code == NEED_TIE:
            sol, ok, status, _ = _daqp(wf, wi, wh, settings)
            st[S_TIESTATUS] = status
            code = tie_done(wf, wi, wh, sol, ok)
            continue
        k = st[S_K]
        if code == NEED_QP:
            for attempt in range(3):
                if attempt:  # ill-conditioned and degenerate: 100x more Tikhonov
                    bump(wf, wi, wh, attempt)
                    report[k, R_RETRIES] += 1
                sol, ok, status, iterations = _daqp(wf, wi, wh, settings)
                report[k, R_STATUS] = status
                report[k, R_ITER] += iterations
                if ok:
                    break
            code = after_qp(f, i, h, wf, wi, wh, par, sol, ok)
        else:  # NEED_PROXIMAL
            sol, ok, status, iterations = _daqp(wf, wi, wh, settings)
            report[k, R_ITER] += iterations
            code = proximal(f, i, h, wf, wi, wh, par, sol, ok)
    finish(f, i, h, wf, wi, wh, par)
