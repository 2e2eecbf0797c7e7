"""Small-array helpers for the control loop's hot paths (tasks and solvers).

On arrays of a few dozen entries numpy's Python-level wrappers (``ndarray.all()``,
``np.count_nonzero``, ``np.ones``) cost more than the work; the helpers here are the C-level
equivalents: ``count_nonzero`` is numpy's C function without its wrapper (numpy >= 2), or
the public one on older numpy, and the others are built on it or on a dot product.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.errors import DimensionError

try:
    from numpy._core.multiarray import count_nonzero
except ImportError:  # pragma: no cover - numpy < 2
    count_nonzero = np.count_nonzero

__all__ = [
    "all_finite",
    "all_true",
    "any_true",
    "count_nonzero",
    "entry_sum",
    "float_array",
    "ones",
]


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


def all_true(mask: np.ndarray) -> bool:
    """``mask.all()``."""
    return count_nonzero(mask) == mask.size


def any_true(mask: np.ndarray) -> bool:
    """``mask.any()``."""
    return count_nonzero(mask) > 0


def all_finite(x: np.ndarray) -> bool:
    """``np.isfinite(x).all()`` for a vector: ``x . x`` is finite iff every entry is, unless
    it overflows (then the entry-wise test decides)."""
    return math.isfinite(x.dot(x)) or all_true(np.isfinite(x))


_ONES: dict[int, np.ndarray] = {}


def entry_sum(a: np.ndarray) -> float:
    """Sum of all entries of ``a``, as a dot product with ones (a BLAS call: cheaper than
    ``np.add.reduce``; a NaN or inf entry makes it non-finite all the same)."""
    f = a.ravel()
    n = f.shape[0]
    ones_n = _ONES.get(n)
    if ones_n is None:
        ones_n = _ONES[n] = np.ones(n)
        ones_n.setflags(write=False)
    return float(f.dot(ones_n))


def ones(n: int) -> np.ndarray:
    """``np.ones(n)`` (a fresh array) without its Python wrapper."""
    out = np.empty(n)
    out.fill(1.0)
    return out
