"""A whole stack's rows in one kernel, from Pinocchio's data: what every solver kernel starts
with.

In order: the frames' Jacobians and placements and the joint positions; every entry of the
entry table by its kind (a pose or posture task's rows, a half-space's row, an objective's
value and gradient, a limit's box; entries written in Python are already in place); each
level's objectives summed into its descent rows ``I u~ = -k D grad H / (1 + k dt D^2 diag(hess
H))``; the rows scaled by ``sqrt(w) D`` into the coordinates ``u~ = W^(1/2) u`` the solvers
work in (:mod:`wholebody.solvers.stack`); the intersection of the limits' boxes; the anchor
(the acceleration limits' last velocity, which the projection's saturation scales around).
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.collision import collision_entry
from wholebody.kernels.kinematics import frame_kinematics, joint_positions
from wholebody.kernels.layout import fmat, ften, fvec, imat, ivec
from wholebody.kernels.limits import acceleration_box, position_box, velocity_box
from wholebody.kernels.objectives import (
    AE_WIDTH,
    arm_energy,
    joint_limit_avoidance,
    manipulability,
)
from wholebody.kernels.rows import (
    POSE_FA,
    POSE_FB,
    POSE_HAS,
    POSE_NROWS,
    POSE_SEL,
    POSE_STAMP,
    POSE_TARGET,
    TARGET_SET,
    com_rows,
    half_space_row,
    pose_rows,
    posture_rows,
    relative_pose,
)

__all__ = ["evaluate"]

REF_WIDTH = 22  # a reference sample: target pose (4x4, row-major), then twist (6), laid out as
# a pose task's target and twist


@kernel
def evaluate(
    f: np.ndarray,
    i: np.ndarray,
    h: np.ndarray,
    J: np.ndarray,
    oMf: np.ndarray,
    q: np.ndarray,
    refs: np.ndarray,
) -> None:
    """Fill the stack's scaled rows ``F_A, F_B, F_C, F_CB``, box ``F_BOX`` and anchor (and
    the kinematics, errors, objective values on the way) from ``data.J``, ``data.oMf``, ``q``
    and the references' samples ``refs`` (one row of ``REF_WIDTH`` per reference)."""
    dt = fvec(f, h, lay.F_SCALARS)[0]
    act = imat(i, h, lay.I_ACT)
    pos = imat(i, h, lay.I_POS)
    frame_kinematics(
        J,
        oMf,
        ivec(i, h, lay.I_FRAME),
        imat(i, h, lay.I_SUPPORT),
        act[0],
        act[1],
        fvec(f, h, lay.F_ACT_A),
        ften(f, h, lay.F_KIN_J),
        fmat(f, h, lay.F_KIN_P),
        ften(f, h, lay.F_KIN_R),
    )
    joint_positions(q, pos[0], pos[1], fvec(f, h, lay.F_JP))
    entries = imat(i, h, lay.I_ENTRY)
    for e in range(entries.shape[0]):
        cat = entries[e, lay.E_CAT]
        if entries[e, lay.E_KIND] == lay.KIND_PYTHON:
            continue
        if cat == lay.CAT_TASK:
            _task(f, i, h, entries[e], refs, J, oMf)
        elif cat == lay.CAT_INEQUALITY:
            _inequality(f, i, h, entries[e], dt, J, oMf)
        elif cat == lay.CAT_OBJECTIVE:
            _objective(f, i, h, entries[e])
        else:
            _limit(f, i, h, entries[e], dt)
    _objective_rows(f, i, h, dt)
    _scale_rows(f, i, h)
    _box(f, i, h)


@kernel
def _task(
    f: np.ndarray,
    i: np.ndarray,
    h: np.ndarray,
    entry: np.ndarray,
    refs: np.ndarray,
    J: np.ndarray,
    oMf: np.ndarray,
) -> None:
    """A compiled task's rows: a pose task (a frame, or a frame relative to another; its
    target and twist from its reference if it follows one), a posture task or a
    centre-of-mass task."""
    par = fvec(f, h, lay.F_PAR)[entry[lay.E_F0] : entry[lay.E_F0] + entry[lay.E_FN]]
    ints = ivec(i, h, lay.I_PAR)[entry[lay.E_I0] : entry[lay.E_I0] + entry[lay.E_IN]]
    r0, n = entry[lay.E_ROW], entry[lay.E_ROWS]
    A, b = fmat(f, h, lay.F_A)[r0 : r0 + n], fvec(f, h, lay.F_B)[r0 : r0 + n]
    if entry[lay.E_KIND] == lay.KIND_POSTURE:
        posture_rows(fvec(f, h, lay.F_JP), par, ints, A, b)
        return
    if entry[lay.E_KIND] == lay.KIND_COM:
        act = imat(i, h, lay.I_ACT)
        com_rows(J, oMf, act[0], act[1], fvec(f, h, lay.F_ACT_A), par, ints, A, b)
        return
    ref = entry[lay.E_REF]
    if ref >= 0:
        for k in range(REF_WIDTH):
            par[POSE_TARGET + k] = refs[ref, k]
        par[POSE_HAS] = TARGET_SET
    KJ, KP, KR = ften(f, h, lay.F_KIN_J), fmat(f, h, lay.F_KIN_P), ften(f, h, lay.F_KIN_R)
    fa, fb = ints[POSE_FA], ints[POSE_FB]
    rows = ints[POSE_SEL : POSE_SEL + ints[POSE_NROWS]]
    if fa < 0:
        pose_rows(par, KJ[fb], KP[fb], KR[fb], rows, A, b)
    else:
        nu = A.shape[1]
        Jr, pr, Rr = np.empty((6, nu)), np.empty(3), np.empty((3, 3))
        relative_pose(KJ[fa], KP[fa], KR[fa], KJ[fb], KP[fb], KR[fb], Jr, pr, Rr)
        pose_rows(par, Jr, pr, Rr, rows, A, b)
    par[POSE_STAMP] = fvec(f, h, lay.F_SCALARS)[2]


@kernel
def _inequality(
    f: np.ndarray,
    i: np.ndarray,
    h: np.ndarray,
    entry: np.ndarray,
    dt: float,
    J: np.ndarray,
    oMf: np.ndarray,
) -> None:
    """A compiled inequality task's rows and bounds (unscaled): a half-space, or collision
    avoidance (from Pinocchio's ``data.J`` and ``data.oMf``)."""
    par = fvec(f, h, lay.F_PAR)[entry[lay.E_F0] : entry[lay.E_F0] + entry[lay.E_FN]]
    ints = ivec(i, h, lay.I_PAR)[entry[lay.E_I0] : entry[lay.E_I0] + entry[lay.E_IN]]
    row = entry[lay.E_ROW]
    cb = fmat(f, h, lay.F_CB)
    if entry[lay.E_KIND] == lay.KIND_COLLISION:
        rows = row + entry[lay.E_ROWS]
        act = imat(i, h, lay.I_ACT)
        collision_entry(
            J,
            oMf,
            par,
            ints,
            act,
            fvec(f, h, lay.F_ACT_A),
            fmat(f, h, lay.F_C)[row:rows],
            cb[:, row:rows],
        )
        return
    frame = ints[0]
    cb[0, row] = half_space_row(
        ften(f, h, lay.F_KIN_J)[frame],
        fmat(f, h, lay.F_KIN_P)[frame],
        par[0:3],
        par[3],
        par[4],
        dt,
        fmat(f, h, lay.F_C)[row],
    )
    cb[1, row] = np.inf


@kernel
def _objective(f: np.ndarray, i: np.ndarray, h: np.ndarray, entry: np.ndarray) -> None:
    """A compiled objective's value, gradient and curvature (unweighted) into its slot."""
    par = fvec(f, h, lay.F_PAR)[entry[lay.E_F0] : entry[lay.E_F0] + entry[lay.E_FN]]
    ints = ivec(i, h, lay.I_PAR)[entry[lay.E_I0] : entry[lay.E_I0] + entry[lay.E_IN]]
    slot, kind = entry[lay.E_SLOT], entry[lay.E_KIND]
    out, grad = fmat(f, h, lay.F_OBJ)[slot], fmat(f, h, lay.F_OBJ_GRAD)[slot]
    KJ, KP, KR = ften(f, h, lay.F_KIN_J), fmat(f, h, lay.F_KIN_P), ften(f, h, lay.F_KIN_R)
    nu = grad.shape[0]
    if kind == lay.KIND_ARM:  # ints: the frames' rows (AF_*), par: the block (AE_*)
        arm_energy(KP, KR, KJ, ints, par, grad)
        out[1] = par[AE_WIDTH]  # the first of its parts, the value
    elif kind == lay.KIND_H1:
        out[1] = joint_limit_avoidance(
            fvec(f, h, lay.F_JP),
            par[:nu],
            par[nu : 2 * nu],
            par[2 * nu :],
            grad,
            fmat(f, h, lay.F_OBJ_CURV)[slot],
        )
    else:  # KIND_H2: ints = frame count, frames, then the (nu, nu) support mask
        n = ints[0]
        Js = np.empty((n, 6, nu))
        for j in range(n):
            Js[j] = KJ[ints[1 + j]]
        mask = ints[1 + n : 1 + n + nu * nu].reshape((nu, nu))
        out[1] = manipulability(Js, mask, grad)


@kernel
def _limit(f: np.ndarray, i: np.ndarray, h: np.ndarray, entry: np.ndarray, dt: float) -> None:
    """A compiled limit's box (rad/s, m/s) into its slot."""
    par = fvec(f, h, lay.F_PAR)[entry[lay.E_F0] : entry[lay.E_F0] + entry[lay.E_FN]]
    box = ften(f, h, lay.F_BOXES)[entry[lay.E_SLOT]]
    kind = entry[lay.E_KIND]
    if kind == lay.KIND_POSITION:
        position_box(fvec(f, h, lay.F_JP), par, dt, box[0], box[1])
    elif kind == lay.KIND_VELOCITY:
        velocity_box(par, box[0], box[1])
    else:
        ints = ivec(i, h, lay.I_PAR)[entry[lay.E_I0] : entry[lay.E_I0] + entry[lay.E_IN]]
        acceleration_box(fvec(f, h, lay.F_JP), par, ints, dt, box[0], box[1])


@kernel
def _objective_rows(f: np.ndarray, i: np.ndarray, h: np.ndarray, dt: float) -> None:
    """Each level's objective rows: ``sw I`` and ``b = -k sw D grad / (1 + k dt D^2 curv)``,
    ``sw = sqrt(objective weight)``, ``grad`` and ``curv`` the weighted sums over the level's
    objectives (curvatures of objectives with a positive weight only)."""
    levels, lf = imat(i, h, lay.I_LEVEL), fmat(f, h, lay.F_LEVEL)
    entries = imat(i, h, lay.I_ENTRY)
    out = fmat(f, h, lay.F_OBJ)
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
        for e in range(entries.shape[0]):
            if entries[e, lay.E_CAT] != lay.CAT_OBJECTIVE or entries[e, lay.E_LEVEL] != k:
                continue
            o = entries[e, lay.E_SLOT]
            w = out[o, 0]
            for j in range(nu):
                grad[j] += w * grads[o, j]
            if entries[e, lay.E_FLAG] and w > 0:  # E_FLAG: it reports a curvature
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
def _box(f: np.ndarray, i: np.ndarray, h: np.ndarray) -> None:
    """The box of every limit (rows 0 and 1 of ``F_BOX``) and of every limit but the
    acceleration limits (rows 2 and 3), in scaled coordinates (:func:`_intersect`); and the
    anchor: the acceleration limits' last velocity (scaled; 0 without them)."""
    boxes, D = ften(f, h, lay.F_BOXES), fmat(f, h, lay.F_METRIC)[0]
    box, anchor = fmat(f, h, lay.F_BOX), fvec(f, h, lay.F_ANCHOR)
    entries = imat(i, h, lay.I_ENTRY)
    nu = D.shape[0]
    anchor[:] = 0.0
    par = fvec(f, h, lay.F_PAR)
    skip = np.zeros(boxes.shape[0], np.bool_)
    for e in range(entries.shape[0]):
        if entries[e, lay.E_KIND] == lay.KIND_ACCELERATION:
            skip[entries[e, lay.E_SLOT]] = True
            previous = par[entries[e, lay.E_F0] + 3 * nu : entries[e, lay.E_F0] + 4 * nu]
            for j in range(nu):
                anchor[j] = previous[j] / D[j]
    _intersect(boxes, np.zeros(boxes.shape[0], np.bool_), D, box[0], box[1])
    _intersect(boxes, skip, D, box[2], box[3])


@kernel
def _intersect(
    boxes: np.ndarray, skip: np.ndarray, D: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> None:
    """Into ``lo, hi``: the intersection of the boxes not in ``skip``, a crossed entry set to
    the bound that moves the joint back (the velocity limit wins over position recovery),
    scaled by ``D``."""
    lo[:] = -np.inf
    hi[:] = np.inf
    for c in range(boxes.shape[0]):
        if skip[c]:
            continue
        for j in range(D.shape[0]):
            lo[j] = _nan_max(lo[j], boxes[c, 0, j])
            hi[j] = _nan_min(hi[j], boxes[c, 1, j])
    for j in range(D.shape[0]):
        if lo[j] > hi[j]:
            mid = hi[j] if lo[j] > 0 else lo[j]
            lo[j] = mid
            hi[j] = mid
        lo[j] /= D[j]
        hi[j] /= D[j]
