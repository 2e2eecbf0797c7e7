"""Small-array helpers for the control loop's hot paths (tasks and solvers).

On arrays of a few dozen entries numpy's Python-level wrappers (``ndarray.all()``,
``np.count_nonzero``) cost more than the work; ``count_nonzero`` here is numpy's C function
without its wrapper (numpy >= 2), or the public one on older numpy.
"""

from __future__ import annotations

import numpy as np

from wholebody.errors import DimensionError

try:
    from numpy._core.multiarray import count_nonzero
except ImportError:  # pragma: no cover - numpy < 2
    count_nonzero = np.count_nonzero

__all__ = ["NORMAL_KAPPA", "REFINE_KAPPA", "count_nonzero", "float_array", "normal_solve"]

NORMAL_KAPPA = 1e4
"""Largest condition bound ``kappa_F`` for which a solver may use a tall level's normal
equations (:func:`normal_solve`) instead of a QR or an SVD."""
REFINE_KAPPA = 1e3
"""Above this ``kappa_F``, :func:`normal_solve` refines its answer once."""


def float_array(value: object, what: str) -> np.ndarray:
    """``value`` as a float array (itself when it already is one); strings and other
    non-numbers give a :class:`DimensionError` naming ``what`` (numpy would parse ``"1.5"``
    silently, or raise a bare ``ValueError``)."""
    if value.__class__ is np.ndarray and value.dtype == np.float64:  # type: ignore[union-attr]
        return value  # type: ignore[return-value]
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise DimensionError(f"{what} must be numbers, got {arr.dtype} values: {value!r}")
    return arr.astype(float)


def normal_solve(M: np.ndarray, H: np.ndarray, c: np.ndarray, kappa2: float) -> np.ndarray:
    """The least-squares solution of a tall ``M`` (m x n, full column rank) from ``H`` with
    ``(M^T M)^-1 = H^T H`` (``H = L^-1`` for the Cholesky factor ``M^T M = L L^T``):
    ``y = H^T H M^T c`` (``c``: (m,) or (m, k)), refined once where ``kappa2``, the squared
    condition bound ``kappa_F^2`` of ``M``, exceeds ``REFINE_KAPPA^2``.

    Relative error: up to about ``kappa_F^2 eps`` unrefined, below 2.2e-10 for
    ``kappa_F <= 1e3`` (1.2e-10 measured at kappa 900 with one small singular value); refined,
    a few 1e-11 at worst (3e-11 measured at kappa 3000 with a large residual; a QR reaches
    1e-13). A handful of small products, where LAPACK's QR routines spend their time in
    per-column BLAS calls."""
    Ht, Mt = H.T, M.T
    y = Ht.dot(H.dot(Mt.dot(c)))
    if kappa2 > REFINE_KAPPA * REFINE_KAPPA:
        y += Ht.dot(H.dot(Mt.dot(c - M.dot(y))))
    return y
