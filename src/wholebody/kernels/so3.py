"""SO(3) in kernels: the logarithm ``log3`` and its right Jacobian ``Jlog3``.

The formulas and branch thresholds are Pinocchio's (``spatial/log.hxx``), so the kernels'
orientation errors and task rows agree with ``pinocchio.log3`` and ``pinocchio.Jlog3`` to
rounding: the rotation is re-orthonormalised first, the angle comes from the trace (with
Taylor expansions within ``eps^(1/3)`` of 0 and of pi), and near pi the axis comes from the
diagonal entry that determines it best.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel

__all__ = ["jlog3", "log3"]

_EPS = 2.220446049250313e-16
_PREC2 = _EPS ** (1.0 / 3.0)  # Pinocchio's TaylorSeriesExpansion precision<2>
_PREC3 = _EPS ** (1.0 / 4.0)  # precision<3>


@kernel
def _renormalised(R: np.ndarray) -> np.ndarray:
    """Columns 0 and 1 normalised, column 2 their cross product, column 0 recomputed."""
    out = np.empty((3, 3))
    n0 = math.sqrt(R[0, 0] ** 2 + R[1, 0] ** 2 + R[2, 0] ** 2)
    n1 = math.sqrt(R[0, 1] ** 2 + R[1, 1] ** 2 + R[2, 1] ** 2)
    for i in range(3):
        out[i, 0] = R[i, 0] / n0
        out[i, 1] = R[i, 1] / n1
    out[0, 2] = out[1, 0] * out[2, 1] - out[2, 0] * out[1, 1]
    out[1, 2] = out[2, 0] * out[0, 1] - out[0, 0] * out[2, 1]
    out[2, 2] = out[0, 0] * out[1, 1] - out[1, 0] * out[0, 1]
    out[0, 0] = out[1, 1] * out[2, 2] - out[2, 1] * out[1, 2]
    out[1, 0] = out[2, 1] * out[0, 2] - out[0, 1] * out[2, 2]
    out[2, 0] = out[0, 1] * out[1, 2] - out[1, 1] * out[0, 2]
    return out


@kernel
def _theta_axis(i0: int, val: float, R: np.ndarray, axis: np.ndarray) -> float:
    """Angle and unit axis (into ``axis``) near pi from the diagonal entry ``i0``."""
    i1 = (i0 + 1) % 3
    i2 = (i0 + 2) % 3
    sign = 1.0 if R[i2, i1] >= R[i1, i2] else -1.0
    s = math.sqrt(val + _EPS + _EPS * _EPS) * sign
    axis[i0] = s / 2.0
    axis[i1] = 1.0 / (2.0 * s) * (R[i1, i0] + R[i0, i1])
    axis[i2] = 1.0 / (2.0 * s) * (R[i2, i0] + R[i0, i2])
    w = 1.0 / (2.0 * s) * (R[i2, i1] - R[i1, i2])
    norm = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    for k in range(3):
        axis[k] /= norm
    return 2.0 * math.atan2(norm, w)


@kernel
def log3(R: np.ndarray, out: np.ndarray) -> float:
    """``out = log3(R)`` (rad, the rotation vector of the 3x3 rotation ``R``); returns the
    angle ``theta`` in [0, pi]."""
    Rn = _renormalised(R)
    tr = Rn[0, 0] + Rn[1, 1] + Rn[2, 2]
    cos_value = (tr - 1.0) / 2.0
    acos_expansion = math.sqrt(2.0 * (1.0 - cos_value) + _EPS * _EPS)
    if tr > 3.0 - _PREC2:
        theta_nominal = acos_expansion
    elif tr >= -1.0 + _PREC2:
        theta_nominal = math.acos(cos_value)
    else:
        theta_nominal = math.pi - acos_expansion
    if cos_value >= -1.0 + _PREC2:
        a0 = 0.5 * (Rn[2, 1] - Rn[1, 2])
        a1 = 0.5 * (Rn[0, 2] - Rn[2, 0])
        a2 = 0.5 * (Rn[1, 0] - Rn[0, 1])
        sq = a0 * a0 + a1 * a1 + a2 * a2
        if theta_nominal >= _PREC2:
            t = theta_nominal / math.sin(theta_nominal)
        else:
            t = 1.0 + sq / 6.0 + sq * sq * 3.0 / 40.0
        out[0] = t * a0
        out[1] = t * a1
        out[2] = t * a2
        return theta_nominal
    # near pi: the axis from the largest of 2 R_ii - tr + 1
    v0 = 2.0 * Rn[0, 0] - tr + 1.0
    v1 = 2.0 * Rn[1, 1] - tr + 1.0
    v2 = 2.0 * Rn[2, 2] - tr + 1.0
    if v0 >= v1:
        i0, val = (0, v0) if v0 >= v2 else (2, v2)
    else:
        i0, val = (1, v1) if v1 >= v2 else (2, v2)
    theta = _theta_axis(i0, val, Rn, out)
    for k in range(3):
        out[k] *= theta
    return theta


@kernel
def jlog3(theta: float, w: np.ndarray, J: np.ndarray) -> None:
    """``J = Jlog3`` (3x3, into ``J``) at the rotation vector ``w`` of angle ``theta``."""
    st = math.sin(theta)
    ct = math.cos(theta)
    if theta < _PREC3:
        alpha = 1.0 / 12.0 + theta * theta / 720.0
        diag = 0.5 * (2.0 - theta * theta / 6.0)
    else:
        st_1mct = st / (1.0 - ct)
        alpha = 1.0 / (theta * theta) - st_1mct / (2.0 * theta)
        diag = 0.5 * (theta * st_1mct)
    for i in range(3):
        for j in range(3):
            J[i, j] = alpha * w[i] * w[j]
        J[i, i] += diag
    J[0, 1] -= 0.5 * w[2]
    J[0, 2] += 0.5 * w[1]
    J[1, 0] += 0.5 * w[2]
    J[1, 2] -= 0.5 * w[0]
    J[2, 0] -= 0.5 * w[1]
    J[2, 1] += 0.5 * w[0]
