"""Kinematics in kernels: frame Jacobians in actuated coordinates, frame placements, joint
positions, read from Pinocchio's data after ``computeJointJacobians`` and
``updateFramePlacements`` (see :meth:`wholebody.Robot.kinematics_views`).

Frame Jacobian (world-aligned axes at the frame origin ``p``, linear rows first), from the
joint Jacobians ``data.J`` (6 x nv, Pinocchio's WORLD convention: spatial velocity at the
world origin)::

    J_f[:, j] = [v_j + w_j x p ; w_j]   for the columns j of the joints that support the frame
    J_f[:, j] = 0                         otherwise

and in actuated coordinates ``J_f A``, with the constant actuation matrix ``A`` (nv x nu)
given by its non-zero entries ``(k, j, a)``: column k of ``A`` has ``a`` in row j. This is what
``pinocchio.getFrameJacobian(..., LOCAL_WORLD_ALIGNED) @ A`` computes, column by column.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel

__all__ = ["frame_kinematics", "joint_positions"]


@kernel
def frame_kinematics(
    J: np.ndarray,
    oMf: np.ndarray,
    frames: np.ndarray,
    support: np.ndarray,
    act_k: np.ndarray,
    act_j: np.ndarray,
    act_a: np.ndarray,
    Jout: np.ndarray,
    pout: np.ndarray,
    Rout: np.ndarray,
) -> None:
    """The Jacobians (F, 6, nu), positions (F, 3) and rotations (F, 3, 3) of ``frames``.

    ``J`` is ``data.J`` (6 x nv); ``oMf`` the frame placements (nframes, 12), each a rotation
    in column-major order then the translation; ``support[f, j]`` whether column j moves
    frame ``frames[f]``; ``act_k, act_j, act_a`` the non-zero entries of ``A``."""
    for f in range(frames.shape[0]):
        m = oMf[frames[f]]
        px, py, pz = m[9], m[10], m[11]
        pout[f, 0] = px
        pout[f, 1] = py
        pout[f, 2] = pz
        for i in range(3):
            for c in range(3):
                Rout[f, i, c] = m[3 * c + i]
        Jf = Jout[f]
        Jf[:, :] = 0.0
        for e in range(act_k.shape[0]):
            j = act_j[e]
            if not support[f, j]:
                continue
            k = act_k[e]
            a = act_a[e]
            wx, wy, wz = J[3, j], J[4, j], J[5, j]
            Jf[0, k] += a * (J[0, j] + (wy * pz - wz * py))
            Jf[1, k] += a * (J[1, j] + (wz * px - wx * pz))
            Jf[2, k] += a * (J[2, j] + (wx * py - wy * px))
            Jf[3, k] += a * wx
            Jf[4, k] += a * wy
            Jf[5, k] += a * wz


SCALAR_POSITION, ANGLE_PAIR, ROLL, PITCH, YAW = 0, 1, 2, 3, 4
"""How :func:`joint_positions` reads a position from ``q``: a scalar, a (cos, sin) pair, or
the roll, pitch or yaw of a unit quaternion ``(x, y, z, w)`` (a free flyer's orientation)."""


@kernel
def _rpy(q: np.ndarray, i: int, which: int) -> float:
    """Roll, pitch or yaw (rad; ``R = Rz(yaw) Ry(pitch) Rx(roll)``, pitch in [-pi/2, pi/2])
    of the unit quaternion ``q[i:i + 4] = (x, y, z, w)``, as Pinocchio's ``rpy.matrixToRpy``
    of its rotation matrix; at pitch +-pi/2 exactly (roll and yaw then turn about one axis)
    roll 0 and the whole heading in yaw."""
    x, y, z, w = q[i], q[i + 1], q[i + 2], q[i + 3]
    r20, r21, r22 = 2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)
    c2 = r21 * r21 + r22 * r22  # cos(pitch)^2
    if which == PITCH:
        return math.atan2(-r20, math.sqrt(c2))
    if c2 < 1e-24:
        if which == ROLL:
            return 0.0
        return math.atan2(-2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z))
    if which == ROLL:
        return math.atan2(r21, r22)
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


@kernel
def joint_positions(q: np.ndarray, index: np.ndarray, pair: np.ndarray, out: np.ndarray) -> None:
    """One scalar position per actuated velocity from ``q[index[k]]``, read as ``pair[k]``
    says: the scalar itself (:data:`SCALAR_POSITION`), the angle ``atan2(q[i + 1], q[i])`` in
    (-pi, pi] of a (cos, sin) pair (:data:`ANGLE_PAIR`), or the :data:`ROLL`, :data:`PITCH`
    or :data:`YAW` (rad) of a free flyer's quaternion ``q[i:i + 4]``."""
    for k in range(out.shape[0]):
        i = index[k]
        how = pair[k]
        if how == ANGLE_PAIR:
            out[k] = math.atan2(q[i + 1], q[i])
        elif how >= ROLL:
            out[k] = _rpy(q, i, how)
        else:
            out[k] = q[i]
