"""Task rows in kernels: pose tracking (a frame, or one frame relative to another) with its
PI integral, posture, the whole-body centre of mass, half-spaces.

The maths is documented where the tasks are (:mod:`wholebody.tasks.frame`,
:mod:`wholebody.tasks.relative`, :mod:`wholebody.tasks.posture`,
:mod:`wholebody.tasks.com`, :mod:`wholebody.tasks.inequality`). Each task keeps its numbers
in a parameter block laid out here (``POSE_*``, ``COM_*``); the task classes call these
kernels on it for their own rows, and the compiled stack calls them on the same block,
adopted into its arena, for every task at once.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.so3 import jlog3, log3

__all__ = [
    "POSE_FINE",
    "POSE_LAST_ROW",
    "POSE_NON_FINITE",
    "POSE_NOT_ROTATION",
    "POSE_WIDTH",
    "advance_integral",
    "com_rows",
    "half_space_row",
    "pose_defect",
    "pose_rows",
    "posture_rows",
    "relative_pose",
    "set_target",
]


POSE_FINE, POSE_NON_FINITE, POSE_LAST_ROW, POSE_NOT_ROTATION, TWIST_NON_FINITE = 0, 1, 2, 3, 4


@kernel
def pose_defect(T: np.ndarray) -> int:
    """What is wrong with the 4x4 homogeneous transform ``T``: POSE_FINE, a NaN or inf
    (POSE_NON_FINITE), a last row other than ``[0, 0, 0, 1]`` within 1e-9 (POSE_LAST_ROW), or
    a rotation part with ``det < 0`` or ``|R^T R - I| > 1e-6`` (POSE_NOT_ROTATION)."""
    for i in range(4):
        for j in range(4):
            if not math.isfinite(T[i, j]):
                return POSE_NON_FINITE
    if abs(T[3, 0]) + abs(T[3, 1]) + abs(T[3, 2]) + abs(T[3, 3] - 1.0) > 1e-9:
        return POSE_LAST_ROW
    det = (
        T[0, 0] * (T[1, 1] * T[2, 2] - T[1, 2] * T[2, 1])
        - T[0, 1] * (T[1, 0] * T[2, 2] - T[1, 2] * T[2, 0])
        + T[0, 2] * (T[1, 0] * T[2, 1] - T[1, 1] * T[2, 0])
    )
    if det < 0:
        return POSE_NOT_ROTATION
    for a in range(3):
        for b in range(a, 3):
            g = T[0, a] * T[0, b] + T[1, a] * T[1, b] + T[2, a] * T[2, b]
            if abs(g - (1.0 if a == b else 0.0)) > 1e-6:
                return POSE_NOT_ROTATION
    return POSE_FINE


@kernel
def set_target(par: np.ndarray, T: np.ndarray, twist: np.ndarray) -> int:
    """A pose task's target ``T`` (4x4) and twist (6,) into its parameter block ``par`` when
    :func:`pose_defect` finds the pose fine and the twist is finite (then POSE_FINE);
    otherwise nothing is written and the defect is returned (TWIST_NON_FINITE for the
    twist). Setting a target forgets the last error (it was for another target)."""
    defect = pose_defect(T)
    if defect != POSE_FINE:
        return defect
    for k in range(6):
        if not math.isfinite(twist[k]):
            return TWIST_NON_FINITE
    for i in range(4):
        for j in range(4):
            par[POSE_TARGET + 4 * i + j] = T[i, j]
    for k in range(6):
        par[POSE_TWIST + k] = twist[k]
    par[POSE_HAS] = TARGET_SET
    par[POSE_STAMP] = -1.0
    return POSE_FINE


# pose tasks' parameter block (floats): gains (1/s, 1/s^2), target (4x4, row-major), target
# twist, integral of the error (m s, rad s), error of the last rows (m, rad), the integral's
# clamp, whether a target is set (TARGET_NONE, _SET, or _HELD: captured at first use), and the
# stamp of the state the last rows were computed at
POSE_KP, POSE_KI, POSE_TARGET, POSE_TWIST, POSE_INTEGRAL, POSE_ERROR = 0, 6, 12, 28, 34, 40
POSE_LIMIT, POSE_HAS, POSE_STAMP = 46, 47, 48
POSE_WIDTH = 49
TARGET_NONE, TARGET_SET, TARGET_HELD = 0.0, 1.0, 2.0
# pose tasks' integer parameters: frame a (-1: the world) and b, rows, the rows kept (<= 6)
POSE_FA, POSE_FB, POSE_NROWS, POSE_SEL = 0, 1, 2, 3
POSE_INTS = 9


@kernel
def pose_rows(
    par: np.ndarray,
    J: np.ndarray,
    p: np.ndarray,
    R: np.ndarray,
    rows: np.ndarray,
    A: np.ndarray,
    v: np.ndarray,
) -> None:
    """The rows of a pose task at its current pose ``(p, R)`` (with Jacobian ``J``, 6 x nu),
    all in one frame's axes, from its parameter block ``par`` (``POSE_*``):
    ``A = (K J)[rows]`` and ``v = (K [v_d; E^T w_d] + kp e + ki I)[rows]`` with
    ``E = R_d R^T``, ``K = diag(I, Jlog3(E))``, ``e = [p_d - p; log3(E)]`` (written into
    the block, all 6). Without a target the current pose is captured and held."""
    target = par[POSE_TARGET : POSE_TARGET + 16].reshape((4, 4))
    if par[POSE_HAS] == TARGET_NONE:
        target[:, :] = 0.0
        target[:3, :3] = R
        target[:3, 3] = p
        target[3, 3] = 1.0
        par[POSE_HAS] = TARGET_HELD
    twist = par[POSE_TWIST : POSE_TWIST + 6]
    e = par[POSE_ERROR : POSE_ERROR + 6]
    E = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            E[i, j] = target[i, 0] * R[j, 0] + target[i, 1] * R[j, 1] + target[i, 2] * R[j, 2]
    eo = np.empty(3)
    theta = log3(E, eo)
    Jl = np.empty((3, 3))
    jlog3(theta, eo, Jl)
    full = np.empty(6)
    for i in range(3):
        e[i] = target[i, 3] - p[i]
        e[3 + i] = eo[i]
        full[i] = twist[i]
    for i in range(3):  # Jlog3 E^T w_d
        t = 0.0
        for k in range(3):
            t += Jl[i, k] * (twist[3] * E[0, k] + twist[4] * E[1, k] + twist[5] * E[2, k])
        full[3 + i] = t
    nu = J.shape[1]
    for r in range(rows.shape[0]):
        i = rows[r]
        v[r] = full[i] + par[POSE_KP + i] * e[i] + par[POSE_KI + i] * par[POSE_INTEGRAL + i]
        if i < 3:
            for c in range(nu):
                A[r, c] = J[i, c]
        else:
            a, b, d = Jl[i - 3, 0], Jl[i - 3, 1], Jl[i - 3, 2]
            for c in range(nu):
                A[r, c] = a * J[3, c] + b * J[4, c] + d * J[5, c]


@kernel
def advance_integral(par: np.ndarray, saturated: bool, dt: float) -> None:
    """One step of a pose task's integral from the error of its last rows: ``I += e dt``
    clamped to ``+-limit``; while ``saturated`` (the bounds limited the task) it may only
    shrink towards 0 (a step against it stops at 0, a step along it is dropped)."""
    some = False
    for i in range(6):
        some = some or par[POSE_KI + i] != 0.0
    if not some:  # no integral action: the integral stays 0
        return
    limit = par[POSE_LIMIT]
    for i in range(6):
        integral = par[POSE_INTEGRAL + i]
        step = par[POSE_ERROR + i] * dt
        if saturated:
            size = abs(integral)
            step = min(max(step, -size), size) if step * integral < 0 else 0.0
        par[POSE_INTEGRAL + i] = min(max(integral + step, -limit), limit)


@kernel
def relative_pose(
    Ja: np.ndarray,
    pa: np.ndarray,
    Ra: np.ndarray,
    Jb: np.ndarray,
    pb: np.ndarray,
    Rb: np.ndarray,
    J: np.ndarray,
    p: np.ndarray,
    R: np.ndarray,
) -> None:
    """The pose of frame b in frame a (``p = R_a^T (p_b - p_a)``, ``R = R_a^T R_b``) and the
    Jacobian of b's twist relative to a in a's axes,
    ``J = R_a^T [J_b,lin - J_a,lin + [p_b - p_a]x J_a,ang ; J_b,ang - J_a,ang]``."""
    rx, ry, rz = pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]
    for i in range(3):
        p[i] = Ra[0, i] * rx + Ra[1, i] * ry + Ra[2, i] * rz
        for j in range(3):
            R[i, j] = Ra[0, i] * Rb[0, j] + Ra[1, i] * Rb[1, j] + Ra[2, i] * Rb[2, j]
    d = np.empty(6)
    for c in range(J.shape[1]):
        wx, wy, wz = Ja[3, c], Ja[4, c], Ja[5, c]
        d[0] = Jb[0, c] - Ja[0, c] + (ry * wz - rz * wy)
        d[1] = Jb[1, c] - Ja[1, c] + (rz * wx - rx * wz)
        d[2] = Jb[2, c] - Ja[2, c] + (rx * wy - ry * wx)
        d[3] = Jb[3, c] - wx
        d[4] = Jb[4, c] - wy
        d[5] = Jb[5, c] - wz
        for i in range(3):
            J[i, c] = Ra[0, i] * d[0] + Ra[1, i] * d[1] + Ra[2, i] * d[2]
            J[3 + i, c] = Ra[0, i] * d[3] + Ra[1, i] * d[4] + Ra[2, i] * d[5]


@kernel
def posture_rows(
    positions: np.ndarray, par: np.ndarray, ints: np.ndarray, A: np.ndarray, v: np.ndarray
) -> None:
    """Posture rows of ``n`` joints from the parameter blocks (floats: target (rad, m), gain
    (1/s), error (out), n each; ints: index into ``u``, tracked, wrapped): ``A`` the unit rows
    of the indices and ``v = kp e`` with ``e = target - positions[index]`` wrapped into
    ``[-pi, pi)`` where ``wrapped`` and 0 where not ``tracked`` (wheels and a planar base's
    actuators)."""
    n = A.shape[0]
    A[:, :] = 0.0
    for r in range(n):
        k = ints[r]
        A[r, k] = 1.0
        err = par[r] - positions[k]
        if ints[2 * n + r]:
            err = (err + math.pi) % (2.0 * math.pi) - math.pi
        if not ints[n + r]:
            err = 0.0
        par[2 * n + r] = err
        v[r] = par[n + r] * err


# a centre-of-mass task's block: target (m), its velocity (m/s), gain (1/s), total mass (kg),
# the centre of mass (m, out), the welded mass's moment (kg m, world), then per moving body its
# mass (kg) and centre of mass in its frame (m); ints: the row count, the rows (3 slots), the
# body and joint counts, then per body its frame and joint, then per joint (Pinocchio's order,
# the universe first) its parent, first velocity and velocity count
COM_TARGET, COM_VELOCITY, COM_KP, COM_MASS, COM_C, COM_FIXED, COM_BODIES = 0, 3, 6, 7, 8, 11, 14
COM_BODY = 4
COM_NROWS, COM_SEL, COM_NB, COM_NJ, COM_TABLE = 0, 1, 4, 5, 6


@kernel
def com_rows(
    J: np.ndarray,
    oMf: np.ndarray,
    act_k: np.ndarray,
    act_j: np.ndarray,
    act_a: np.ndarray,
    par: np.ndarray,
    ints: np.ndarray,
    A: np.ndarray,
    v: np.ndarray,
) -> None:
    """Centre-of-mass rows ``A = J_c[rows]``, ``v = (v_ref + kp (c_ref - c))[rows]``, the
    blocks laid out by ``COM_*``, from the joint Jacobians ``J`` (6 x nv, Pinocchio's
    ``data.J``: column ``j`` the spatial velocity at the world origin, linear rows first) and
    the frame placements ``oMf`` (nframes, 12: rotation column-major, then translation):

        c = (m_0 c_0 + sum_k m_k c_k) / M,     c_k = p_k + R_k l_k
        J_c[:, j] = (m_j v_j + w_j x s_j) / M,  then times A (columns over u)

    over the bodies ``k`` (mass ``m_k``, centre of mass ``l_k`` in its frame), ``m_0 c_0``
    the mass welded to the world, ``M`` the total; ``m_j`` and ``s_j`` the mass and moment
    ``sum m_k c_k`` of the bodies that column ``j`` moves (its joint's subtree, summed from
    the leaves up), ``v_j`` and ``w_j`` its linear and angular rows (the velocity of a point
    ``c`` is ``v + w x c``). ``act_k, act_j, act_a``: the non-zero entries of ``A``. ``c``
    is written to the block."""
    nb, nj = ints[COM_NB], ints[COM_NJ]
    bodies, joints = ints[COM_TABLE : COM_TABLE + 2 * nb], ints[COM_TABLE + 2 * nb :]
    mass, moment = np.zeros(nj), np.zeros((nj, 3))
    for k in range(nb):
        m, j, o = oMf[bodies[2 * k]], bodies[2 * k + 1], COM_BODIES + COM_BODY * k
        mass[j] += par[o]
        for i in range(3):
            ci = m[9 + i] + m[i] * par[o + 1] + m[3 + i] * par[o + 2] + m[6 + i] * par[o + 3]
            moment[j, i] += par[o] * ci
    scale = 1.0 / par[COM_MASS]
    for i in range(3):
        par[COM_C + i] = (moment[1:, i].sum() + par[COM_FIXED + i]) * scale
    Jm = np.zeros((3, J.shape[1]))
    for j in range(nj - 1, 0, -1):  # the subtrees' sums, leaves first
        mj, sx, sy, sz = mass[j], moment[j, 0], moment[j, 1], moment[j, 2]
        for col in range(joints[3 * j + 1], joints[3 * j + 1] + joints[3 * j + 2]):
            wx, wy, wz = J[3, col], J[4, col], J[5, col]
            Jm[0, col] = mj * J[0, col] + (wy * sz - wz * sy)
            Jm[1, col] = mj * J[1, col] + (wz * sx - wx * sz)
            Jm[2, col] = mj * J[2, col] + (wx * sy - wy * sx)
        parent = joints[3 * j]
        mass[parent] += mj
        for i in range(3):
            moment[parent, i] += moment[j, i]
    for n in range(ints[COM_NROWS]):
        i = ints[COM_SEL + n]
        A[n, :] = 0.0
        for e in range(act_k.shape[0]):
            A[n, act_k[e]] += act_a[e] * Jm[i, act_j[e]] * scale
        v[n] = par[COM_VELOCITY + i] + par[COM_KP] * (par[COM_TARGET + i] - par[COM_C + i])


@kernel
def half_space_row(
    J: np.ndarray,
    p: np.ndarray,
    normal: np.ndarray,
    offset: float,
    gain: float,
    dt: float,
    C: np.ndarray,
) -> float:
    """The row ``n^T J_lin`` (into ``C``, nu) of a half-space ``n . p >= d`` and its lower
    bound ``-gain (n . p - d) / dt`` (returned)."""
    for c in range(J.shape[1]):
        C[c] = normal[0] * J[0, c] + normal[1] * J[1, c] + normal[2] * J[2, c]
    distance = normal[0] * p[0] + normal[1] * p[1] + normal[2] * p[2] - offset
    return -gain * distance / dt
