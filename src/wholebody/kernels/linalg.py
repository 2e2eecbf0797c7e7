"""Small dense linear algebra shared by the solver kernels: products, the certified Cholesky
route of a level's Gram matrix, its normal-equations solve, and the residual report.

The products and the Cholesky factor's inverse are plain loops, summed in index order: on
matrices of a few dozen entries they cost less than a BLAS or LAPACK call, compile to a tenth
of the machine code numpy's implementations generate, and give the same answer compiled and
uncompiled. The maths and the thresholds of
the rest are those of the reference solvers (:mod:`wholebody.solvers.projection`,
:mod:`wholebody._numeric`, :class:`wholebody.solvers.stack.LevelProblem`), documented there.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.lapack import geqrf, orgqr

__all__ = [
    "NORMAL_KAPPA",
    "REFINE_KAPPA",
    "cholesky_inverse",
    "combine",
    "complement_solve",
    "diagonal",
    "dot",
    "finite1",
    "fortran",
    "frobenius2",
    "gather_rows",
    "gram_cols",
    "gram_rows",
    "gram_solve",
    "level_report",
    "mm",
    "mmt",
    "mtm",
    "mtv",
    "mv",
    "normal_solve",
    "null_basis",
    "scatter_rows",
    "trace",
]

NORMAL_KAPPA = 1e4  # as wholebody._numeric
REFINE_KAPPA = 1e3


@kernel
def dot(x: np.ndarray, y: np.ndarray) -> float:
    """``x . y``."""
    s = 0.0
    for k in range(x.shape[0]):
        s += x[k] * y[k]
    return s


@kernel
def finite1(a: np.ndarray) -> bool:
    """Whether every entry of the vector ``a`` is finite."""
    for j in range(a.shape[0]):
        if not math.isfinite(a[j]):
            return False
    return True


@kernel
def combine(x: np.ndarray, a: float, y: np.ndarray) -> np.ndarray:
    """``x + a y`` (a new vector)."""
    out = np.empty(x.shape[0])
    for k in range(x.shape[0]):
        out[k] = x[k] + a * y[k]
    return out


@kernel
def mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A x``, each entry summed in index order, four rows at a time: four sums that do
    not wait for each other's additions (a single row's sum is a chain of dependent
    additions)."""
    m, n = A.shape
    out = np.empty(m)
    i = 0
    while i + 4 <= m:
        s0 = s1 = s2 = s3 = 0.0
        for k in range(n):
            a = x[k]
            s0 += A[i, k] * a
            s1 += A[i + 1, k] * a
            s2 += A[i + 2, k] * a
            s3 += A[i + 3, k] * a
        out[i], out[i + 1], out[i + 2], out[i + 3] = s0, s1, s2, s3
        i += 4
    for r in range(i, m):
        s = 0.0
        for k in range(n):
            s += A[r, k] * x[k]
        out[r] = s
    return out


@kernel
def mtv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A^T x``."""
    m, n = A.shape
    out = np.zeros(n)
    for k in range(m):
        a = x[k]
        for j in range(n):
            out[j] += A[k, j] * a
    return out


@kernel
def mm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A B`` (C-ordered)."""
    m, p = A.shape
    n = B.shape[1]
    out = np.zeros((m, n))
    for i in range(m):
        for k in range(p):
            a = A[i, k]
            for j in range(n):
                out[i, j] += a * B[k, j]
    return out


@kernel
def mtm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A^T B`` (C-ordered)."""
    p, m = A.shape
    n = B.shape[1]
    out = np.zeros((m, n))
    for k in range(p):
        for i in range(m):
            a = A[k, i]
            for j in range(n):
                out[i, j] += a * B[k, j]
    return out


@kernel
def mmt(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A B^T`` (C-ordered)."""
    m, p = A.shape
    n = B.shape[0]
    out = np.zeros((m, n))
    for i in range(m):
        for j in range(n):
            s = 0.0
            for k in range(p):
                s += A[i, k] * B[j, k]
            out[i, j] = s
    return out


@kernel
def gram_rows(M: np.ndarray) -> np.ndarray:
    """``M M^T`` (C-ordered), as :func:`mmt` gives it: its lower triangle, mirrored."""
    m, p = M.shape
    out = np.empty((m, m))
    for i in range(m):
        for j in range(i + 1):
            s = 0.0
            for k in range(p):
                s += M[i, k] * M[j, k]
            out[i, j] = s
            out[j, i] = s
    return out


@kernel
def gram_cols(M: np.ndarray) -> np.ndarray:
    """``M^T M`` (C-ordered), as :func:`mtm` gives it: its lower triangle, mirrored."""
    p, m = M.shape
    out = np.zeros((m, m))
    for k in range(p):
        for i in range(m):
            a = M[k, i]
            for j in range(i + 1):
                out[i, j] += a * M[k, j]
    for i in range(m):
        for j in range(i):
            out[j, i] = out[i, j]
    return out


@kernel
def fortran(A: np.ndarray) -> np.ndarray:
    """A Fortran-ordered copy of ``A`` (for LAPACK)."""
    m, n = A.shape
    out = np.zeros((n, m)).T
    for j in range(n):
        for i in range(m):
            out[i, j] = A[i, j]
    return out


@kernel
def diagonal(A: np.ndarray) -> tuple[bool, np.ndarray]:
    """``(ok, a)``: whether the square ``A`` is diagonal (no entry off its diagonal other
    than 0; NaN is other), and its diagonal ``a``."""
    n = A.shape[0]
    a = np.empty(n)
    for i in range(n):
        for j in range(n):
            if i != j and A[i, j] != 0.0:
                return False, a
        a[i] = A[i, i]
    return True, a


@kernel
def trace(G: np.ndarray) -> float:
    """``tr G``, the sum of the square ``G``'s diagonal."""
    t = 0.0
    for k in range(G.shape[0]):
        t += G[k, k]
    return t


@kernel
def frobenius2(A: np.ndarray) -> float:
    """``||A||_F^2`` of a matrix."""
    total = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            total += A[i, j] * A[i, j]
    return total


@kernel
def gather_rows(A: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The rows of ``A`` where ``keep``, in order (a new array)."""
    count = 0
    for q in range(keep.shape[0]):
        count += keep[q]
    out = np.empty((count, A.shape[1]))
    c = 0
    for q in range(keep.shape[0]):
        if keep[q]:
            out[c, :] = A[q, :]
            c += 1
    return out


@kernel
def scatter_rows(Y: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The inverse of :func:`gather_rows` with zeros elsewhere: row ``q`` of the result is
    the next row of ``Y`` where ``keep[q]``, else 0."""
    out = np.zeros((keep.shape[0], Y.shape[1]))
    c = 0
    for q in range(keep.shape[0]):
        if keep[q]:
            out[q, :] = Y[c, :]
            c += 1
    return out


@kernel
def cholesky_inverse(G: np.ndarray) -> tuple[bool, np.ndarray]:
    """``(ok, L^-1)`` for the Cholesky factor ``G = L L^T`` of the symmetric ``G`` (n x n,
    its lower triangle read): ``L^-1`` lower triangular, Fortran-ordered; ok False where
    ``G`` is not positive definite to working precision (a pivot not above 0, or NaN).

    Plain loops, the matrices being a few dozen rows at most: LAPACK's unblocked routines
    make a BLAS call per column, which costs more than the arithmetic. Row by row (the
    Cholesky-Crout order), ``L_ij = (G_ij - sum_k<j L_ik L_jk) / L_jj``; then column by
    column, ``L^-1`` from ``L X = I`` by forward substitution."""
    n = G.shape[0]
    L = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1):
            s = G[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i > j:
                L[i, j] = s / L[j, j]
            elif s > 0.0:
                L[i, i] = math.sqrt(s)
            else:
                return False, L.T
    X = np.zeros((n, n)).T
    for j in range(n):
        X[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * X[k, j]
            X[i, j] = s / L[i, i]
    return True, X


@kernel
def normal_solve(M: np.ndarray, H: np.ndarray, c: np.ndarray, kappa2: float) -> np.ndarray:
    """The least-squares solution of a tall ``M`` from ``H`` with ``(M^T M)^-1 = H^T H``:
    ``y = H^T H M^T c`` (``c``: (m, k)), refined once where ``kappa2 > REFINE_KAPPA^2``
    (see :func:`wholebody._numeric.normal_solve`)."""
    y = mtm(H, mm(H, mtm(M, c)))
    if kappa2 > REFINE_KAPPA * REFINE_KAPPA:
        y += mtm(H, mm(H, mtm(M, c - mm(M, y))))
    return y


@kernel
def gram_solve(X: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``X^T X v`` for the lower-triangular ``X = L^-1`` of :func:`cholesky_inverse`: ``G^-1
    v`` where ``G = L L^T`` (only X's lower triangle read)."""
    m = v.shape[0]
    y = np.zeros(m)
    for i in range(m):
        t = 0.0
        for k in range(i + 1):
            t += X[i, k] * v[k]
        for j in range(i + 1):
            y[j] += X[i, j] * t
    return y


@kernel
def complement_solve(M: np.ndarray, a: np.ndarray, c: np.ndarray) -> tuple[bool, np.ndarray]:
    """``(ok, dx)``: ``dx = argmin ||diag(a) dx - c||`` subject to ``M dx = 0`` (M: m x r of
    full row rank, ``a``: r nonzero entries), without a basis of M's null space: with ``D =
    diag(a)^2``, ``dx = D^-1 (a c - M^T l)`` where ``M D^-1 M^T l = M (c / a)``, by the
    Cholesky factor of ``S = M D^-1 M^T``, the constraint's round-off projected out once more
    above ``REFINE_KAPPA``. Not ok where ``S`` has no factor or its Frobenius condition
    exceeds ``NORMAL_KAPPA``. A diagonal level (a posture in its metric) below a level of full
    row rank, in both backends."""
    m, r = M.shape
    dinv, dx = np.empty(r), np.empty(r)
    for k in range(r):
        dinv[k] = 1.0 / (a[k] * a[k])
        dx[k] = c[k] / a[k]
    S = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            t = 0.0
            for k in range(r):
                t += M[i, k] * M[j, k] * dinv[k]
            S[i, j] = t
    ok, X = cholesky_inverse(S)
    k2 = frobenius2(X) * trace(S) if ok else math.inf
    if not k2 <= NORMAL_KAPPA * NORMAL_KAPPA:
        return False, dx
    for _ in range(2 if k2 > REFINE_KAPPA * REFINE_KAPPA else 1):
        g = mtv(M, gram_solve(X, mv(M, dx)))  # M^T S^-1 M dx: dx's part off M's null space
        for k in range(r):
            dx[k] -= g[k] * dinv[k]
    return True, dx


@kernel
def null_basis(M: np.ndarray) -> np.ndarray:
    """An orthonormal basis (r x (r - m)) of the null space of ``M`` (m x r) of full row rank
    m <= r: the last columns of the complete Q of ``M^T = Q R``."""
    m, r = M.shape
    a = np.zeros((r, r)).T  # Fortran-ordered: M^T in the first m columns, then Q
    for k in range(m):
        for j in range(r):
            a[j, k] = M[k, j]
    tau = np.zeros(max(m, 1))
    if m:
        geqrf(a[:, :m], tau[:m])
    orgqr(a, tau, m, 8 * r)
    out = np.empty((r, r - m))
    for j in range(r):
        for k in range(r - m):
            out[j, k] = a[j, m + k]
    return out


@kernel
def level_report(
    A: np.ndarray,
    b: np.ndarray,
    unweight: np.ndarray,
    x: np.ndarray,
    tasks: np.ndarray,
    row0: int,
    out: np.ndarray,
) -> float:
    """``||A x - b||`` of a level (returned) and, per task ``t`` of ``tasks`` (rows
    ``[tasks[t, 1], tasks[t, 2])`` of the whole stack, the level starting at ``row0``), into
    ``out[t]``: ``||r_t||``, ``||r_t||`` unweighted (times ``unweight``) and ``||b_t||``."""
    r = mv(A, x) - b
    total = 0.0
    for k in range(r.shape[0]):
        total += r[k] * r[k]
    for t in range(tasks.shape[0]):
        w = p = bb = 0.0
        for k in range(tasks[t, 1] - row0, tasks[t, 2] - row0):
            w += r[k] * r[k]
            ru = r[k] * unweight[k]
            p += ru * ru
            bb += b[k] * b[k]
        out[t, 0] = math.sqrt(w)
        out[t, 1] = math.sqrt(p)
        out[t, 2] = math.sqrt(bb)
    return math.sqrt(total)
