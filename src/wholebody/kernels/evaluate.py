"""A whole stack's rows in one kernel: what :meth:`wholebody.solvers.Stack.evaluate` computes
entry by entry, for every built-in entry at once, from Pinocchio's data.

In order: the frames' Jacobians and placements and the joint positions; every pose and
posture task's rows, every half-space's row; every objective's value and gradient, summed per
level into its descent rows ``I u~ = -k D grad H / (1 + k dt D^2 diag(hess H))``; the box
of the position, velocity and Python-written limits; the rows scaled by ``sqrt(w) D`` into the
coordinates ``u~ = W^(1/2) u`` the solvers work in (:mod:`wholebody.solvers.stack`). Rows and
bounds of entries written in Python are already in the arena when it runs.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.kinematics import frame_kinematics, joint_positions
from wholebody.kernels.layout import fmat, ften, fvec, imat, ivec
from wholebody.kernels.objectives import arm_energy, joint_limit_avoidance, manipulability
from wholebody.kernels.rows import (
    half_space_row,
    pose_rows,
    position_box,
    posture_rows,
    relative_pose,
)

__all__ = ["evaluate"]


@kernel
def evaluate(
    f: np.ndarray, i: np.ndarray, h: np.ndarray, J: np.ndarray, oMf: np.ndarray, q: np.ndarray
) -> None:
    """Fill the stack's scaled rows ``F_A, F_B, F_C, F_CB`` and box ``F_BOX`` (and the
    kinematics, errors, objective values on the way) from ``data.J``, ``data.oMf`` and
    ``q`` (see the module docstring)."""
    dt = fvec(f, h, lay.F_SCALARS)[0]
    act = imat(i, h, lay.I_ACT)
    pos = imat(i, h, lay.I_POS)
    frame_kinematics(J, oMf, ivec(i, h, lay.I_FRAME), imat(i, h, lay.I_SUPPORT), act[0],
                     act[1], fvec(f, h, lay.F_ACT_A), ften(f, h, lay.F_KIN_J),
                     fmat(f, h, lay.F_KIN_P), ften(f, h, lay.F_KIN_R))  # fmt: skip
    joint_positions(q, pos[0], pos[1], fvec(f, h, lay.F_JP))
    _pose_tasks(f, i, h)
    _posture_tasks(f, i, h)
    _half_spaces(f, i, h, dt)
    _objectives(f, i, h)
    _objective_rows(f, i, h, dt)
    _scale_rows(f, i, h)
    _box(f, i, h, dt)


@kernel
def _pose_tasks(f: np.ndarray, i: np.ndarray, h: np.ndarray) -> None:
    """Rows of every pose task (a frame, or a frame relative to another)."""
    tasks = imat(i, h, lay.I_POSE)
    par = fmat(f, h, lay.F_POSE)
    KJ, KP, KR = ften(f, h, lay.F_KIN_J), fmat(f, h, lay.F_KIN_P), ften(f, h, lay.F_KIN_R)
    A, b = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B)
    nu = A.shape[1]
    Jr = np.empty((6, nu))
    pr = np.empty(3)
    Rr = np.empty((3, 3))
    for t in range(tasks.shape[0]):
        fa, fb = tasks[t, lay.POSE_FA], tasks[t, lay.POSE_FB]
        r0, n = tasks[t, lay.POSE_ROW], tasks[t, lay.POSE_NROWS]
        rows = tasks[t, lay.POSE_SEL : lay.POSE_SEL + n]
        if fa < 0:
            Jt, pt, Rt = KJ[fb], KP[fb], KR[fb]
        else:
            relative_pose(KJ[fa], KP[fa], KR[fa], KJ[fb], KP[fb], KR[fb], Jr, pr, Rr)
            Jt, pt, Rt = Jr, pr, Rr
        p = par[t]
        target = p[lay.POSE_TARGET : lay.POSE_TARGET + 16].reshape((4, 4))
        pose_rows(Jt, pt, Rt, target, p[lay.POSE_TWIST : lay.POSE_TWIST + 6],
                  p[lay.POSE_KP : lay.POSE_KP + 6], p[lay.POSE_KI : lay.POSE_KI + 6],
                  p[lay.POSE_INTEGRAL : lay.POSE_INTEGRAL + 6], rows, A[r0 : r0 + n],
                  b[r0 : r0 + n], p[lay.POSE_ERROR : lay.POSE_ERROR + 6])  # fmt: skip


@kernel
def _posture_tasks(f: np.ndarray, i: np.ndarray, h: np.ndarray) -> None:
    """Rows of every posture task."""
    tasks = imat(i, h, lay.I_POSTURE)
    entry = imat(i, h, lay.I_POSTURE_ENTRY)
    par = fmat(f, h, lay.F_POSTURE)
    A, b = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B)
    jp = fvec(f, h, lay.F_JP)
    for t in range(tasks.shape[0]):
        r0, e0, n = tasks[t, 0], tasks[t, 1], tasks[t, 2]
        posture_rows(jp, entry[0, e0 : e0 + n], par[0, e0 : e0 + n], par[1, e0 : e0 + n],
                     entry[1, e0 : e0 + n], entry[2, e0 : e0 + n], A[r0 : r0 + n],
                     b[r0 : r0 + n], par[2, e0 : e0 + n])  # fmt: skip


@kernel
def _half_spaces(f: np.ndarray, i: np.ndarray, h: np.ndarray, dt: float) -> None:
    """The row and lower bound of every half-space (unscaled)."""
    spaces = imat(i, h, lay.I_HALF)
    par = fmat(f, h, lay.F_HALF)
    KJ, KP = ften(f, h, lay.F_KIN_J), fmat(f, h, lay.F_KIN_P)
    C, cb = fmat(f, h, lay.F_C), fmat(f, h, lay.F_CB)
    for s in range(spaces.shape[0]):
        fr, row = spaces[s, 0], spaces[s, 1]
        cb[0, row] = half_space_row(KJ[fr], KP[fr], par[s, 0:3], par[s, 3], par[s, 4], dt,
                                    C[row])  # fmt: skip
        cb[1, row] = np.inf


@kernel
def _objectives(f: np.ndarray, i: np.ndarray, h: np.ndarray) -> None:
    """Value, gradient and curvature of every built-in objective (unweighted)."""
    objs = imat(i, h, lay.I_OBJ)
    out = fmat(f, h, lay.F_OBJ)
    grads, curvs = fmat(f, h, lay.F_OBJ_GRAD), fmat(f, h, lay.F_OBJ_CURV)
    KJ, KP, KR = ften(f, h, lay.F_KIN_J), fmat(f, h, lay.F_KIN_P), ften(f, h, lay.F_KIN_R)
    arms, arm_par, parts = imat(i, h, lay.I_ARM), fmat(f, h, lay.F_ARM), fmat(f, h, lay.F_ARM_PARTS)
    h1, h2, mask = ften(f, h, lay.F_H1), imat(i, h, lay.I_H2), imat(i, h, lay.I_H2_MASK)
    nets, jp = fvec(f, h, lay.F_NETS), fvec(f, h, lay.F_JP)
    nu = jp.shape[0]
    P6 = np.zeros((6, 3))
    R6 = np.zeros((6, 3, 3))
    J6 = np.zeros((6, 6, nu))
    for o in range(objs.shape[0]):
        kind, k = objs[o, lay.OBJ_KIND], objs[o, lay.OBJ_INDEX]
        if kind == lay.KIND_ARM:
            for j in range(6):
                fr = arms[k, j]
                if fr >= 0:
                    P6[j], R6[j], J6[j] = KP[fr], KR[fr], KJ[fr]
            arm_energy(P6, R6, J6, arm_par[k], nets, grads[o], parts[k])
            out[o, 1] = parts[k, 0]
        elif kind == lay.KIND_H1:
            out[o, 1] = joint_limit_avoidance(jp, h1[k, 0], h1[k, 1], h1[k, 2], grads[o],
                                              curvs[o])  # fmt: skip
        elif kind == lay.KIND_H2:
            n = h2[k, 0]
            Js = np.empty((n, 6, nu))
            for j in range(n):
                Js[j] = KJ[h2[k, 1 + j]]
            out[o, 1] = manipulability(Js, mask, grads[o])


@kernel
def _objective_rows(f: np.ndarray, i: np.ndarray, h: np.ndarray, dt: float) -> None:
    """Each level's objective rows: ``sw I`` and ``b = -k sw D grad / (1 + k dt D^2 curv)``,
    ``sw = sqrt(objective weight)``, ``grad`` and ``curv`` the weighted sums over the level's
    objectives (curvatures of objectives with a positive weight only)."""
    levels, lf = imat(i, h, lay.I_LEVEL), fmat(f, h, lay.F_LEVEL)
    objs, out = imat(i, h, lay.I_OBJ), fmat(f, h, lay.F_OBJ)
    grads, curvs = fmat(f, h, lay.F_OBJ_GRAD), fmat(f, h, lay.F_OBJ_CURV)
    metric = fmat(f, h, lay.F_METRIC)
    A, b = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B)
    nu = A.shape[1]
    grad = np.empty(nu)
    curv = np.empty(nu)
    for k in range(levels.shape[0]):
        r0, r1 = levels[k, lay.LEVEL_TASKS_END], levels[k, lay.LEVEL_ROW_END]
        if r1 == r0:
            continue
        grad[:] = 0.0
        have_curv = False
        for o in range(objs.shape[0]):
            if objs[o, lay.OBJ_LEVEL] != k:
                continue
            w = out[o, 0]
            for j in range(nu):
                grad[j] += w * grads[o, j]
            if objs[o, lay.OBJ_HAS_CURV] and w > 0:
                for j in range(nu):
                    curv[j] = w * curvs[o, j] + curv[j] if have_curv else w * curvs[o, j]
                have_curv = True
        gain = lf[k, lay.LEVEL_GAIN]
        sw = math.sqrt(lf[k, lay.LEVEL_OBJECTIVE_WEIGHT])
        lf[k, lay.LEVEL_IDENTITY] = 0.0 if levels[k, lay.LEVEL_HAS_TASKS] else sw
        block = A[r0:r1]
        block[:, :] = 0.0
        for j in range(nu):
            block[j, j] = sw
            step = (-gain * sw * metric[0, j]) * grad[j]
            if have_curv:
                step /= curv[j] * (gain * dt * metric[1, j]) + 1.0
            b[r0 + j] = step


@kernel
def _scale_rows(f: np.ndarray, i: np.ndarray, h: np.ndarray) -> None:
    """Task rows times ``sqrt(w_i) D_j`` (their right-hand sides times ``sqrt(w_i)``) and
    inequality rows times ``D_j``: the scaled coordinates ``u~``."""
    levels = imat(i, h, lay.I_LEVEL)
    rows, D = fmat(f, h, lay.F_ROW), fmat(f, h, lay.F_METRIC)[0]
    A, b, C = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B), fmat(f, h, lay.F_C)
    nu = A.shape[1]
    for k in range(levels.shape[0]):
        for r in range(levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_TASKS_END]):
            sw = rows[0, r]
            for j in range(nu):
                A[r, j] *= sw * D[j]
            b[r] *= sw
    for r in range(C.shape[0]):
        for j in range(nu):
            C[r, j] *= D[j]


@kernel
def _nan_max(a: float, b: float) -> float:
    """``np.maximum``: NaN if either is."""
    return a if (a >= b or a != a) else b


@kernel
def _nan_min(a: float, b: float) -> float:
    """``np.minimum``: NaN if either is."""
    return a if (a <= b or a != a) else b


@kernel
def _box(f: np.ndarray, i: np.ndarray, h: np.ndarray, dt: float) -> None:
    """The intersection of every constraint's box, a crossed entry set to the bound that
    moves the joint back (the velocity limit wins over position recovery), in scaled
    coordinates."""
    counts = ivec(i, h, lay.I_BOX)
    pos, vel, py = ften(f, h, lay.F_POS_BOX), fmat(f, h, lay.F_VEL_BOX), ften(f, h, lay.F_PY_BOX)
    jp, D = fvec(f, h, lay.F_JP), fmat(f, h, lay.F_METRIC)[0]
    box = fmat(f, h, lay.F_BOX)
    nu = jp.shape[0]
    lo, hi = box[0], box[1]
    lo[:] = -np.inf
    hi[:] = np.inf
    first = True
    blo = np.empty(nu)
    bhi = np.empty(nu)
    for c in range(counts[0] + counts[1] + counts[2]):
        if c < counts[0]:
            position_box(jp, pos[c, 0], pos[c, 1], pos[c, 2, 0], dt, blo, bhi)
        elif c < counts[0] + counts[1]:
            for j in range(nu):
                bhi[j] = vel[c - counts[0], j]
                blo[j] = -bhi[j]
        else:
            for j in range(nu):
                blo[j] = py[c - counts[0] - counts[1], 0, j]
                bhi[j] = py[c - counts[0] - counts[1], 1, j]
        for j in range(nu):
            lo[j] = blo[j] if first else _nan_max(lo[j], blo[j])
            hi[j] = bhi[j] if first else _nan_min(hi[j], bhi[j])
        first = False
    for j in range(nu):
        if lo[j] > hi[j]:
            mid = hi[j] if lo[j] > 0 else lo[j]
            lo[j] = mid
            hi[j] = mid
        lo[j] /= D[j]
        hi[j] /= D[j]
