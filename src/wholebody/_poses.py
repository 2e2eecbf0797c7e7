"""One validator of homogeneous transforms for every module that takes a pose (tasks, the
planner, the trajectories): the same tolerances and messages everywhere."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from wholebody._numeric import float_array
from wholebody.errors import DimensionError
from wholebody.kernels.rows import POSE_LAST_ROW, POSE_NON_FINITE, pose_defect

__all__ = ["ROTATION_TOL", "check_pose"]

ROTATION_TOL = 1e-6
"""Largest entry of ``|R^T R - I|`` accepted for a rotation matrix (and ``det R > 0``); the
last row must be ``[0, 0, 0, 1]`` within 1e-9 (:func:`wholebody.kernels.rows.pose_defect`)."""


def check_pose(pose: object, what: str) -> np.ndarray:
    """A 4x4 homogeneous transform (or ``pinocchio.SE3``) with an orthonormal rotation, as a
    new float array, or DimensionError naming ``what``."""
    value = pose.homogeneous if isinstance(pose, pin.SE3) else pose
    T = float_array(value, what).copy()
    if T.shape != (4, 4):
        raise DimensionError(f"{what}: expected a finite 4x4 pose, got shape {T.shape}")
    defect = pose_defect(T)
    if defect == POSE_NON_FINITE:
        raise DimensionError(f"{what}: expected a finite 4x4 pose (it holds NaN or inf)")
    if defect == POSE_LAST_ROW:
        raise DimensionError(
            f"{what}: the last row of a 4x4 pose must be [0, 0, 0, 1], got "
            f"{T[3].tolist()} (a transposed matrix?)"
        )
    if defect:
        raise DimensionError(
            f"{what}: the rotation part is not a rotation matrix "
            f"(|R^T R - I| > {ROTATION_TOL:g} or det < 0)"
        )
    return T
