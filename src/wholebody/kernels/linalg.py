"""Small dense linear algebra shared by the solver kernels: the certified Cholesky route of a
level's Gram matrix, its normal-equations solve, and the residual report.

The maths and the thresholds are those of the reference solvers
(:mod:`wholebody.solvers.projection`, :mod:`wholebody._numeric`,
:class:`wholebody.solvers.stack.LevelProblem`), documented there.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.lapack import potrf, trtri

__all__ = ["NORMAL_KAPPA", "REFINE_KAPPA", "cholesky_inverse", "normal_solve"]

NORMAL_KAPPA = 1e4  # as wholebody._numeric
REFINE_KAPPA = 1e3


@kernel
def cholesky_inverse(G: np.ndarray) -> tuple[bool, np.ndarray]:
    """``(ok, L^-1)`` for the Cholesky factor ``G = L L^T`` of the symmetric ``G`` (n x n):
    ``L^-1`` lower triangular, Fortran-ordered; ok False where ``G`` is not positive
    definite to working precision."""
    L = np.asfortranarray(G)
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
    Ht, Mt = H.T, M.T
    y = Ht.dot(H.dot(Mt.dot(c)))
    if kappa2 > REFINE_KAPPA * REFINE_KAPPA:
        y += Ht.dot(H.dot(Mt.dot(c - M.dot(y))))
    return y


@kernel
def frobenius2(a: np.ndarray) -> float:
    """``||a||_F^2``."""
    total = 0.0
    for x in a.ravel():
        total += x * x
    return total


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
    r = A.dot(x) - b
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
