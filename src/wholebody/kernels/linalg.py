"""Small dense linear algebra shared by the solver kernels: products, the certified Cholesky
route of a level's Gram matrix, its normal-equations solve, and the residual report.

The products are plain loops, summed in index order: on matrices of a few dozen entries they
cost less than a BLAS call, compile to a tenth of the machine code numpy's implementations
generate, and give the same answer compiled and uncompiled. The maths and the thresholds of
the rest are those of the reference solvers (:mod:`wholebody.solvers.projection`,
:mod:`wholebody._numeric`, :class:`wholebody.solvers.stack.LevelProblem`), documented there.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.lapack import geqrf, orgqr, potrf, trtri

__all__ = [
    "NORMAL_KAPPA",
    "REFINE_KAPPA",
    "cholesky_inverse",
    "combine",
    "dot",
    "fortran",
    "frobenius2",
    "gather_rows",
    "gram_cols",
    "gram_rows",
    "level_report",
    "mm",
    "mmt",
    "mtm",
    "mtv",
    "mv",
    "normal_solve",
    "null_basis",
    "scatter_rows",
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
def combine(x: np.ndarray, a: float, y: np.ndarray) -> np.ndarray:
    """``x + a y`` (a new vector)."""
    out = np.empty(x.shape[0])
    for k in range(x.shape[0]):
        out[k] = x[k] + a * y[k]
    return out


@kernel
def mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A x`` (each entry summed in index order, the rows at once: no chain of dependent
    additions)."""
    m, n = A.shape
    out = np.zeros(m)
    for k in range(n):
        a = x[k]
        for i in range(m):
            out[i] += A[i, k] * a
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
    """``(ok, L^-1)`` for the Cholesky factor ``G = L L^T`` of the symmetric ``G`` (n x n):
    ``L^-1`` lower triangular, Fortran-ordered; ok False where ``G`` is not positive
    definite to working precision."""
    L = fortran(G)
    if potrf(L, True) != 0:
        return False, L
    if trtri(L, True) != 0:
        return False, L
    return True, L


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
