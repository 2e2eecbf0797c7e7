"""Least squares for the hierarchical QP's cascade: the minimum-norm least squares of a level
with a rank threshold, null spaces, and the bounded least squares (BVLS).

One rank rule everywhere: singular values (or the diagonal of a pivoted QR) above
``max(rtol s_max, floor)`` count. :func:`cod` solves ``min ||M y - c||`` at minimum norm by a
complete orthogonal decomposition (the pivoted QR of ``M^T``); where full column rank is
certain it takes a cheaper route to the same answer: the normal equations where they are
accurate, else LAPACK's QR. :func:`wide_solve` is the route of a wide ``M`` of certain full
row rank (the Cholesky factor of ``M M^T``), which leaves the null space to be made only where
it is needed. "Certain" is a certificate, not a guess: the Frobenius condition
number from the triangular factor's inverse, times a safety margin (``_MARGIN``) for
round-off, proves that the rank rule would keep every column. :func:`null_space` does the same
for a basis of a null space (a QR where full row rank is certain, else the SVD). :func:`bvls`
is the bounded least squares of Stark and Parker (1995), as ``scipy.optimize.lsq_linear(
method="bvls")``: the polish of a level that only the box bounds
(:mod:`wholebody.kernels.hqp_level`).

Plain functions of arrays: they know nothing of the cascade's workspace.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.lapack import gels, geqp3, geqrf, gesdd, orgqr, trtri, trtrs
from wholebody.kernels.linalg import (
    NORMAL_KAPPA,
    REFINE_KAPPA,
    cholesky_inverse,
    combine,
    dot,
    fortran,
    frobenius2,
    gram_rows,
    gram_solve,
    mtv,
    mv,
)

__all__ = [
    "bvls",
    "cod",
    "columns_of",
    "gradient",
    "in_box",
    "lstsq",
    "null_space",
    "pivot_norm",
    "product",
    "residual",
    "wide_solve",
]

_MARGIN = 1e3  # safety factor of the full-rank certificates (round-off)
_EPS = 2.220446049250313e-16


# ---------------------------------------------------------------------- small helpers
@kernel
def product(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """``out = A B`` (``out`` C-ordered, distinct from A and B), the zero entries of ``A``
    skipped: the rows multiplied here are sparse (a posture task's rows, a hand's Jacobian
    off its arm, unit rows of bounds), so this costs a fraction of a dense product."""
    m, p = A.shape
    n = B.shape[1]
    for i in range(m):
        for j in range(n):
            out[i, j] = 0.0
        for k in range(p):
            a = A[i, k]
            if a != 0.0:
                for j in range(n):
                    out[i, j] += a * B[k, j]


@kernel
def residual(M: np.ndarray, y: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``c - M y`` (a new vector; the zero entries of ``M`` skipped)."""
    out = np.empty(c.shape[0])
    for i in range(c.shape[0]):
        s = 0.0
        for k in range(y.shape[0]):
            a = M[i, k]
            if a != 0.0:
                s += a * y[k]
        out[i] = c[i] - s
    return out


@kernel
def gradient(A: np.ndarray, x: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A^T (A x - b)``: the gradient of ``1/2 ||A x - b||^2``."""
    return mtv(A, combine(mv(A, x), -1.0, b))


@kernel
def in_box(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether ``lo <= x <= hi`` (False for NaN)."""
    for j in range(x.shape[0]):
        if not (x[j] >= lo[j] and x[j] <= hi[j]):
            return False
    return True


@kernel
def columns_of(A: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The columns ``idx`` of ``A`` (a new array)."""
    out = np.empty((A.shape[0], idx.shape[0]))
    for i in range(A.shape[0]):
        for q in range(idx.shape[0]):
            out[i, q] = A[i, idx[q]]
    return out


@kernel
def _transposed(M: np.ndarray) -> np.ndarray:
    """``M^T`` as a new Fortran-ordered array (its memory: M's rows)."""
    m, r = M.shape
    out = np.empty((m, r))  # C-ordered (m, r): the Fortran-ordered (r, m) transpose
    for i in range(m):
        for j in range(r):
            out[i, j] = M[i, j]
    return out.T


# ---------------------------------------------------------------------- the COD
@kernel
def _rank_certificate(M: np.ndarray, Rinv: np.ndarray, rtol: float, floor: float) -> float:
    """``kappa_F^2 = ||R^-1||_F^2 ||M||_F^2`` (``R``: the triangular factor of a tall M, or of
    ``M M^T`` for a wide one) when the rank rule is certain to find full rank, else -1."""
    inv2 = frobenius2(Rinv)
    k2 = inv2 * frobenius2(M)
    m = max(M.shape[0], M.shape[1])  # (the longer side: the rows of a tall M)
    margin = _MARGIN * rtol
    if k2 * m * margin * margin < 1.0 and inv2 * m * floor * floor < 1.0:
        return k2
    return -1.0


@kernel
def _gram_inverse(M: np.ndarray) -> tuple[bool, np.ndarray]:
    """``(ok, L^-1)`` for the Cholesky factor ``M^T M = L L^T`` of a tall ``M`` (m x r)
    (:func:`~wholebody.kernels.linalg.cholesky_inverse` of its lower triangle, built with the
    zero entries of ``M`` skipped: bound rows are unit rows)."""
    m, r = M.shape
    G = np.zeros((r, r))
    for q in range(m):
        for i in range(r):
            a = M[q, i]
            if a != 0.0:
                for j in range(i + 1):
                    G[i, j] += a * M[q, j]
    return cholesky_inverse(G)


@kernel
def _normal_step(M: np.ndarray, X: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``X^T X M^T c`` (``X`` lower triangular): the least squares of ``M`` where
    ``(M^T M)^-1 = X^T X``."""
    m, r = M.shape
    g = np.zeros(r)
    for q in range(m):  # M^T c
        a = c[q]
        if a != 0.0:
            for j in range(r):
                g[j] += M[q, j] * a
    return gram_solve(X, g)


@kernel
def _tall_solve(M: np.ndarray, c: np.ndarray, rtol: float, floor: float):
    """The least squares of a tall ``M`` (m > r) where full column rank is certain:
    ``(done, y, have_qr)``. By the normal equations where the certificate shows them accurate
    (condition at most ``NORMAL_KAPPA``; refined once above ``REFINE_KAPPA``, as
    :func:`wholebody._numeric.normal_solve`), by LAPACK's QR (``gels``) where it is certain
    but larger; not done where it is not certain (the pivoted QR of :func:`cod` decides
    the rank: a QR here could not certify what the Cholesky factor did not). ``have_qr``:
    the QR's solution ``y`` exists."""
    r = M.shape[1]
    ok, X = _gram_inverse(M)
    k2 = _rank_certificate(M, X, rtol, floor) if ok else -1.0
    if k2 < 0:
        return False, c[:r].copy(), False
    if k2 <= NORMAL_KAPPA * NORMAL_KAPPA:
        y = _normal_step(M, X, c)
        if k2 > REFINE_KAPPA * REFINE_KAPPA:
            dy = _normal_step(M, X, residual(M, y, c))
            for j in range(r):
                y[j] += dy[j]
        return True, y, False
    lqr = fortran(M)
    z = c.copy()
    if gels(lqr, z) != 0:
        return False, c[:r].copy(), False
    R = np.zeros((r, r)).T  # the QR's triangular factor, Fortran-ordered
    for j in range(r):
        for i in range(j + 1):
            R[i, j] = lqr[i, j]
    done = trtri(R, False) == 0 and _rank_certificate(M, R, rtol, floor) >= 0
    return done, z[:r].copy(), True


@kernel
def wide_solve(M: np.ndarray, c: np.ndarray, t: np.ndarray, rtol: float, floor: float):
    """``min ||M y - c||`` for a wide ``M`` (m < r) at minimum distance to ``-t``, where full
    row rank is certain: ``(done, y, L^-1)``, ``y = M^T (M M^T)^-1 (c + M t) - t`` by the
    Cholesky factor ``M M^T = L L^T`` where the certificate shows it accurate (as
    :func:`_tall_solve`: condition at most ``NORMAL_KAPPA``, refined once above
    ``REFINE_KAPPA``); not done where it is not (:func:`cod` then decides the rank)."""
    ok, X = cholesky_inverse(gram_rows(M))
    k2 = _rank_certificate(M, X, rtol, floor) if ok else -1.0
    if not 0.0 <= k2 <= NORMAL_KAPPA * NORMAL_KAPPA:
        return False, t.copy(), X
    y = combine(mtv(M, gram_solve(X, combine(c, 1.0, mv(M, t)))), -1.0, t)
    if k2 > REFINE_KAPPA * REFINE_KAPPA:
        y = combine(y, 1.0, mtv(M, gram_solve(X, residual(M, y, c))))
    return True, y, X


@kernel
def cod(M: np.ndarray, c: np.ndarray, t: np.ndarray, rtol: float, floor: float):
    """``min ||M y - c||`` (M: m x r) at minimum distance to ``-t`` by a complete orthogonal
    decomposition, singular values at most ``max(rtol s_max, floor)`` counted as zero:
    ``(info, rank, y, Q2, smax, known)`` with ``y = Q_1 a - Q_2 Q_2^T t`` (``Q_1 a``: the
    minimum-norm solution), ``Q2`` an orthonormal basis of the null space (r x (r - rank); 0
    columns at full rank), ``smax = |R_00|`` of the pivoted QR where ``known`` (not computed
    where full rank was certified without it); ``info`` nonzero where LAPACK failed."""
    m, r = M.shape
    none = np.zeros((r, 0))
    have_qr = False
    tall = np.zeros(r)
    if m > r > 0:
        done, tall, have_qr = _tall_solve(M, c, rtol, floor)
        if done:
            return 0, r, tall, none, 0.0, False
    k = min(m, r)
    qr = _transposed(M)  # Fortran-ordered M^T (r x m)
    jpvt = np.zeros(max(m, 1), np.int32)
    tau = np.zeros(max(k, 1))
    info = geqp3(qr, jpvt[:m], tau[:k])
    if info != 0:
        return info, 0, np.zeros(r), none, 0.0, True
    smax, rank = 0.0, 0  # the diagonal entries above max(rtol |R_00|, floor)
    if k:
        smax = abs(qr[0, 0])
        if smax > floor:
            thr = max(rtol * smax, floor)
            for j in range(k):
                if abs(qr[j, j]) > thr:
                    rank += 1
    if rank == r and have_qr:  # full column rank, more rows: the unique solution
        return 0, rank, tall, none, smax, True
    info, y, Q2 = _cod_solution(qr, tau, jpvt, c, t, k, rank)
    if info != 0:
        return info, 0, np.zeros(r), none, 0.0, True
    return 0, rank, y, Q2, smax, True


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
def _cod_solution(qr, tau, jpvt, c, t, k: int, rank: int):
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
def pivot_norm(M: np.ndarray) -> float:
    """``|R_00|`` of the pivoted QR of ``M^T``, the scale of ``M``'s largest singular value:
    the norm of its first pivot, the largest column of ``M^T`` (row of ``M``); no
    factorisation needed."""
    top = 0.0
    for i in range(M.shape[0]):
        t = 0.0
        for j in range(M.shape[1]):
            t += M[i, j] * M[i, j]
        top = max(top, t)
    return math.sqrt(top)


@kernel
def _inverse_norm2(R: np.ndarray) -> float:
    """``||R^-1||_F^2`` of the upper triangular ``R`` (inf where a diagonal entry is 0)."""
    q = R.shape[0]
    X = np.zeros((q, q))
    for j in range(q):  # column j of R^-1: R x = e_j, by back substitution
        if R[j, j] == 0.0:
            return np.inf
        X[j, j] = 1.0 / R[j, j]
        for i in range(j - 1, -1, -1):
            t = 0.0
            for k in range(i + 1, j + 1):
                t += R[i, k] * X[k, j]
            X[i, j] = -t / R[i, i]
    return frobenius2(X)


@kernel
def null_space(Nz: np.ndarray, rtol: float, floor: float) -> np.ndarray:
    """An orthonormal basis (r x (r - rank)) of the null space of ``Nz`` (q x r), singular
    values at most ``max(rtol s_max, floor)`` counted as zero: the last columns of the
    complete Q of ``Nz^T = Q R`` where ``Nz`` certainly has q such singular values (``R``
    certifies it, as the Cholesky factor of ``Nz Nz^T = R^T R`` would), else by the SVD."""
    q, r = Nz.shape
    if 0 < q <= r:
        a = np.zeros((r, r)).T  # Fortran-ordered: Nz^T in the first q columns, then Q
        for k in range(q):
            for j in range(r):
                a[j, k] = Nz[k, j]
        tau = np.zeros(q)
        if geqrf(a[:, :q], tau) == 0:
            inv2 = _inverse_norm2(a[:q, :q])
            margin = _MARGIN * rtol
            if (
                inv2 * frobenius2(Nz) * margin * margin < 1.0
                and inv2 * (_MARGIN * floor) ** 2 < 1.0
                and orgqr(a, tau, q, 8 * r) == 0
            ):
                out = np.empty((r, r - q))
                for j in range(r):
                    for k in range(r - q):
                        out[j, k] = a[j, q + k]
                return out
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
    return V2


# ---------------------------------------------------------------------- BVLS
@kernel
def lstsq(A: np.ndarray, b: np.ndarray, rcond: float) -> np.ndarray:
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
def _count_free(state: np.ndarray) -> int:
    """The number of free variables (``state == 0``)."""
    count = 0
    for j in range(state.shape[0]):
        count += state[j] == 0
    return count


@kernel
def _free_lstsq(A: np.ndarray, b: np.ndarray, x: np.ndarray, state: np.ndarray, rcond: float):
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
    return idx, lstsq(columns_of(A, idx), combine(b, -1.0, mv(A, fixed)), rcond)


@kernel
def _kkt(g: np.ndarray, state: np.ndarray) -> tuple[float, int]:
    """The largest violation of the bounded least squares' optimality conditions at the
    gradient ``g``, and the variable whose gradient points inwards most, ``argmax(g * state)``
    (the first of equals; numpy's argmax: the first NaN)."""
    worst = -np.inf
    for j in range(g.shape[0]):
        v = abs(g[j]) if state[j] == 0 else g[j] * state[j]
        worst = max(worst, v)
    best, at = -np.inf, 0
    for j in range(g.shape[0]):
        v = g[j] * state[j]
        if v != v:
            return worst, j
        if v > best:
            best, at = v, j
    return worst, at


@kernel
def bvls(A, b, lb, ub, max_iter: int, tol: float) -> np.ndarray:
    """Bounded-variable least squares ``min ||A x - b||`` over ``lb <= x <= ub`` (Stark and
    Parker 1995, as ``scipy.optimize.lsq_linear(method="bvls")``): from the unconstrained
    solution, variables outside the box set on their bounds until the free ones' least
    squares is inside; then, while the optimality conditions fail by ``tol``, the variable
    whose gradient points inwards most is freed and the free ones move towards their least
    squares, stopping at the first bound reached."""
    m, n = A.shape
    x = lstsq(A, b, -1.0)
    if in_box(x, lb, ub):
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
        worst, inward = _kkt(g, state)
        if worst < tol:
            break
        state[inward] = 0.0
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
def _bvls_free(A, b, lb, ub, x, state, rcond: float) -> None:
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
