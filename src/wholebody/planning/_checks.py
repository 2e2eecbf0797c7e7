"""Argument checks shared by the planning modules.

Every check converts its argument to a float ``numpy`` array and raises a
:class:`~wholebody.errors.DimensionError` (shape, non-finite values, not a rotation) or a
:class:`~wholebody.errors.WholebodyError` subclass whose message names the argument and what
was expected.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody._numeric import count_nonzero as _count_nonzero
from wholebody._poses import ROTATION_TOL, check_pose
from wholebody.errors import DimensionError

__all__ = [
    "ROTATION_TOL",
    "as_array",
    "as_pose",
    "as_positive",
    "as_rotation",
    "as_times",
    "as_vector",
]


def as_array(value: object, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """``value`` as a finite float array of ``shape`` (``None`` entries match any size)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{name}: expected a numeric array of shape {shape}") from exc
    if arr.ndim != len(shape) or any(
        want is not None and have != want for have, want in zip(arr.shape, shape, strict=True)
    ):
        names = iter("NMLPQR")  # one letter per free dimension
        spec = "(" + ", ".join(next(names) if s is None else str(s) for s in shape) + ")"
        raise DimensionError(f"{name}: expected shape {spec}, got {arr.shape}")
    if _count_nonzero(np.isfinite(arr)) != arr.size:
        raise DimensionError(f"{name}: contains NaN or infinite values")
    return arr


def as_vector(value: object, size: int | None, name: str) -> np.ndarray:
    """``value`` as a finite 1-D float array of length ``size`` (any length if ``None``)."""
    return as_array(value, (size,), name)


def as_rotation(value: object, name: str) -> np.ndarray:
    """``value`` as a 3x3 rotation matrix (orthonormal to ``ROTATION_TOL``, det +1)."""
    R = as_array(value, (3, 3), name)
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > ROTATION_TOL:
        raise DimensionError(
            f"{name}: not a rotation matrix (max |R^T R - I| = {err:.2e} > {ROTATION_TOL:g})"
        )
    if np.linalg.det(R) < 0.0:
        raise DimensionError(f"{name}: a reflection (det = -1), expected a rotation (det = +1)")
    return R


def as_pose(value: object, name: str) -> np.ndarray:
    """``value`` as a 4x4 homogeneous transform with a rotation block and last row 0 0 0 1
    (the one pose validator, :func:`wholebody._poses.check_pose`, which tasks use too)."""
    return check_pose(value, name)


def as_positive(value: object, name: str) -> float:
    """``value`` as a finite float > 0."""
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{name}: expected a positive number, got {value!r}") from exc
    if not math.isfinite(x) or x <= 0.0:
        raise DimensionError(f"{name}: expected a finite number > 0, got {x}")
    return x


def as_times(value: object, name: str) -> np.ndarray:
    """``value`` as a finite 1-D float array of times (s); a scalar becomes length 1."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{name}: expected a 1-D array of times in s") from exc
    if arr.ndim == 0:
        arr = arr.reshape(1)
    return as_array(arr, (None,), name)
