"""Small-array helpers for the control loop's hot paths (tasks and solvers).

On arrays of a few dozen entries numpy's Python-level wrappers (``ndarray.all()``,
``np.count_nonzero``) cost more than the work; ``count_nonzero`` here is numpy's C function
without its wrapper (numpy >= 2), or the public one on older numpy.
"""

from __future__ import annotations

import numpy as np

try:
    from numpy._core.multiarray import count_nonzero
except ImportError:  # pragma: no cover - numpy < 2
    count_nonzero = np.count_nonzero

__all__ = ["count_nonzero"]
