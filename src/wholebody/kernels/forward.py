"""Forward kinematics and configuration integration in kernels: what Pinocchio's
``computeJointJacobians`` + ``updateFramePlacements`` and ``integrate`` compute, from a packed
description of the model, so that a kernel can move a robot without calling Pinocchio (many
states solved in one ``prange`` loop, many control steps inside one kernel call).

The model is packed once by :func:`wholebody.robot.compiled.pack_model` (a robot's:
``robot.kinematics.model_tables()``) into two tables, one row per joint (Pinocchio's order,
row 0 the universe) then one row per frame::

    model_i (njoints + nframes, 4) int64:   kind, parent joint, idx_q, idx_v
    model_f (njoints + nframes, 15) float64: placement in the parent joint (rotation in
        column-major order, translation in m: the model's ``jointPlacements``, or the frame's
        ``placement``), then the joint's unit axis in its own frame

The kinds, with each joint's ``q`` and ``v`` (``v`` in the joint's own frame, as Pinocchio's):

==============  ==========================================  ====================
kind            q                                           v
==============  ==========================================  ====================
``REVOLUTE``    angle (rad) about the axis                  rad/s
``UNBOUNDED``   (cos, sin) of the angle about the axis      rad/s
``PRISMATIC``   displacement (m) along the axis             m/s
``PLANAR``      (x, y, cos, sin) in the parent's xy-plane   (vx, vy, wz)
``FREE_FLYER``  (x, y, z, qx, qy, qz, qw)                   (linear, angular)
==============  ==========================================  ====================

``ROOT`` is the universe (row 0) and ``FRAME`` a frame's row. The outputs have the layouts
of :meth:`wholebody.robot.compiled.RobotKinematics.views`, so that the kernels of
:mod:`wholebody.kernels.kinematics` read either Pinocchio's data or these::

    oMi (njoints, 12)  joint placements in the world, rotation column-major then translation (m)
    oMf (nframes, 12)  frame placements, the same layout (Pinocchio's data.oMf)
    J (6, nv)          joint Jacobians (Pinocchio's data.J, WORLD convention): column j is the
                       spatial velocity at the world origin of the joint moved by v_j = 1,
                       linear rows (m/s) first, then angular (rad/s)

The kernels allocate nothing and keep no state: several threads may call them at once on
different outputs. The formulas are Pinocchio's (``multibody/joint/*.hpp``,
``multibody/liegroup/special-*.hpp``, ``spatial/explog-quaternion.hpp``) with their branches
(the Taylor expansions of exp6 and exp3, the planar exponential's threshold at 1e-14 rad,
the first-order renormalisation of unit complex numbers and quaternions, a quaternion's sign
kept on the side of the start), so the results agree with Pinocchio's to rounding.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel

__all__ = [
    "FRAME",
    "FREE_FLYER",
    "PLANAR",
    "PRISMATIC",
    "REVOLUTE",
    "ROOT",
    "UNBOUNDED",
    "forward_kinematics",
    "integrate",
    "model_velocity",
]

# ------------------------------------------------------------------ kinds (model_i[:, 0])
ROOT = 0  # the universe: the world frame
REVOLUTE = 1  # RX, RY, RZ, RevoluteUnaligned
UNBOUNDED = 2  # RUBX, RUBY, RUBZ, RevoluteUnboundedUnaligned (continuous joints, wheels)
PRISMATIC = 3  # PX, PY, PZ, PrismaticUnaligned
PLANAR = 4  # Planar (a mobile base)
FREE_FLYER = 5  # FreeFlyer (a floating base)
FRAME = 6  # a frame: its parent joint and placement

# ------------------------------------------------------------------ columns
KIND, PARENT, IDX_Q, IDX_V = 0, 1, 2, 3  # of model_i
AXIS = 12  # model_f[:, 12:15]: the joint's axis

_EPS = 2.220446049250313e-16  # double precision's machine epsilon
_PREC3 = _EPS**0.25  # Pinocchio's TaylorSeriesExpansion<double>::precision<3>()
_PLANAR_SMALL = 1e-14  # rad: below, Pinocchio's planar exponential takes t = (vx, vy)


@kernel
def _motion(kind: int, model_f: np.ndarray, j: int, q: np.ndarray, iq: int) -> tuple:
    """The joint ``j``'s own transform ``M(q)`` (rotation column-major, translation in m),
    as Pinocchio's joint models compute it."""
    if kind == PLANAR:
        c, s = q[iq + 2], q[iq + 3]
        return (c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0, q[iq], q[iq + 1], 0.0)
    if kind == FREE_FLYER:  # Eigen's Quaternion::toRotationMatrix (not normalised first)
        x, y, z, w = q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]
        tx, ty, tz = 2.0 * x, 2.0 * y, 2.0 * z
        twx, twy, twz = tx * w, ty * w, tz * w
        txx, txy, txz = tx * x, ty * x, tz * x
        tyy, tyz, tzz = ty * y, tz * y, tz * z
        r00, r10, r20 = 1.0 - (tyy + tzz), txy + twz, txz - twy
        r01, r11, r21 = txy - twz, 1.0 - (txx + tzz), tyz + twx
        r02, r12, r22 = txz + twy, tyz - twx, 1.0 - (txx + tyy)
        return (r00, r10, r20, r01, r11, r21, r02, r12, r22, q[iq], q[iq + 1], q[iq + 2])
    x, y, z = model_f[j, AXIS], model_f[j, AXIS + 1], model_f[j, AXIS + 2]
    if kind == PRISMATIC:
        d = q[iq]
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, x * d, y * d, z * d)
    if kind == REVOLUTE:
        c, s = math.cos(q[iq]), math.sin(q[iq])
    else:  # UNBOUNDED: (cos, sin) as stored, as Pinocchio reads them
        c, s = q[iq], q[iq + 1]
    # Pinocchio's toRotationMatrix(axis, cos, sin) (Eigen's AngleAxis::toRotationMatrix)
    sx, sy, sz = s * x, s * y, s * z
    cx, cy, cz = (1.0 - c) * x, (1.0 - c) * y, (1.0 - c) * z
    xy, xz, yz = cx * y, cx * z, cy * z
    r00, r10, r20 = cx * x + c, xy + sz, xz - sy
    r01, r11, r21 = xy - sz, cy * y + c, yz + sx
    r02, r12, r22 = xz + sy, yz - sx, cz * z + c
    return (r00, r10, r20, r01, r11, r21, r02, r12, r22, 0.0, 0.0, 0.0)


@kernel
def _columns(
    kind: int, model_f: np.ndarray, oMi: np.ndarray, j: int, J: np.ndarray, iv: int
) -> None:
    """The joint ``j``'s columns ``iv, iv + 1, ...`` of ``J`` from its placement ``oMi[j]``
    (Pinocchio's ``oMi.act(S)``): per velocity, the spatial velocity at the world origin of a
    unit translation along, or rotation about, a direction ``d`` of the joint frame: its axis
    (one-velocity joints), else its x, y, z axes (planar: vx, vy, then wz; free flyer: the
    three translations, then the three rotations)."""
    px, py, pz = oMi[j, 9], oMi[j, 10], oMi[j, 11]
    n = 3 if kind == PLANAR else 6 if kind == FREE_FLYER else 1
    for m in range(n):
        if n == 1:  # d = R axis
            x, y, z = model_f[j, AXIS], model_f[j, AXIS + 1], model_f[j, AXIS + 2]
            dx = oMi[j, 0] * x + oMi[j, 3] * y + oMi[j, 6] * z
            dy = oMi[j, 1] * x + oMi[j, 4] * y + oMi[j, 7] * z
            dz = oMi[j, 2] * x + oMi[j, 5] * y + oMi[j, 8] * z
        else:  # d = R e_k
            k = m % 3
            dx, dy, dz = oMi[j, 3 * k], oMi[j, 3 * k + 1], oMi[j, 3 * k + 2]
        c = iv + m
        if kind in (REVOLUTE, UNBOUNDED) or (kind == PLANAR and m == 2) or m >= 3:
            # a rotation about d: (p x d, d)
            J[0, c] = py * dz - pz * dy
            J[1, c] = pz * dx - px * dz
            J[2, c] = px * dy - py * dx
            J[3, c] = dx
            J[4, c] = dy
            J[5, c] = dz
        else:  # a translation along d: (d, 0)
            J[0, c] = dx
            J[1, c] = dy
            J[2, c] = dz
            J[3, c] = 0.0
            J[4, c] = 0.0
            J[5, c] = 0.0


@kernel
def forward_kinematics(
    model_i: np.ndarray,
    model_f: np.ndarray,
    q: np.ndarray,
    oMi: np.ndarray,
    oMf: np.ndarray,
    J: np.ndarray,
) -> None:
    """Joint placements ``oMi`` (njoints, 12), frame placements ``oMf`` (nframes, 12) and
    joint Jacobians ``J`` (6 x nv, WORLD convention) at the configuration ``q`` (module
    docstring): Pinocchio's ``computeJointJacobians`` then ``updateFramePlacements``.

    ``model_i, model_f`` are the packed model (:func:`wholebody.robot.compiled.pack_model`);
    every entry of the outputs is written. ``J`` may be a (6, nv) Fortran-ordered array (the
    memory of ``data.J``) or any other 6 x nv array."""
    nj = oMi.shape[0]
    for c in range(12):
        oMi[0, c] = 1.0 if c == 0 or c == 4 or c == 8 else 0.0
    for r in range(1, model_i.shape[0]):  # the joints, then the frames
        out, o = (oMi, r) if r < nj else (oMf, r - nj)
        p = model_i[r, PARENT]
        for i in range(3):  # out[o] = oMi[p] placement: the joint at q = 0, or the frame
            a0, a1, a2 = oMi[p, i], oMi[p, 3 + i], oMi[p, 6 + i]  # row i of the rotation
            for c in range(3):
                b0, b1, b2 = model_f[r, 3 * c], model_f[r, 3 * c + 1], model_f[r, 3 * c + 2]
                out[o, 3 * c + i] = a0 * b0 + a1 * b1 + a2 * b2
            b0, b1, b2 = model_f[r, 9], model_f[r, 10], model_f[r, 11]
            out[o, 9 + i] = a0 * b0 + a1 * b1 + a2 * b2 + oMi[p, 9 + i]
        if r >= nj:
            continue
        kind = model_i[r, KIND]
        M = _motion(kind, model_f, r, q, model_i[r, IDX_Q])
        for i in range(3):  # oMi[r] = oMi[r] M(q)
            a0, a1, a2 = oMi[r, i], oMi[r, 3 + i], oMi[r, 6 + i]
            oMi[r, i] = a0 * M[0] + a1 * M[1] + a2 * M[2]
            oMi[r, 3 + i] = a0 * M[3] + a1 * M[4] + a2 * M[5]
            oMi[r, 6 + i] = a0 * M[6] + a1 * M[7] + a2 * M[8]
            oMi[r, 9 + i] += a0 * M[9] + a1 * M[10] + a2 * M[11]
        _columns(kind, model_f, oMi, r, J, model_i[r, IDX_V])


@kernel
def model_velocity(
    act_k: np.ndarray, act_j: np.ndarray, act_a: np.ndarray, u: np.ndarray, v: np.ndarray
) -> None:
    """``v = A u`` (nv): the model velocity of the actuated velocity ``u`` (nu), with the
    actuation matrix ``A`` given by its non-zero entries ``A[act_j[e], act_k[e]] = act_a[e]``
    (:class:`wholebody.robot.compiled.RobotKinematics`)."""
    v[:] = 0.0
    for e in range(act_k.shape[0]):
        v[act_j[e]] += act_a[e] * u[act_k[e]]


@kernel
def _integrate_planar(
    q: np.ndarray, v: np.ndarray, dt: float, iq: int, iv: int, out: np.ndarray
) -> None:
    """A planar joint moved by ``v dt`` along SE(2)'s exponential (Pinocchio's)."""
    x0, y0, c0, s0 = q[iq], q[iq + 1], q[iq + 2], q[iq + 3]
    vx, vy, w = v[iv] * dt, v[iv + 1] * dt, v[iv + 2] * dt
    cv, sv = math.cos(w), math.sin(w)
    tx, ty = vx, vy
    if abs(w) > _PLANAR_SMALL:
        tx = (-vy - (-vy * cv + vx * -sv)) / w
        ty = (vx - (-vy * sv + vx * cv)) / w
    out[iq] = c0 * tx - s0 * ty + x0
    out[iq + 1] = s0 * tx + c0 * ty + y0
    out[iq + 2] = c0 * cv - s0 * sv
    out[iq + 3] = s0 * cv + c0 * sv


@kernel
def _integrate_free_flyer(
    q: np.ndarray, v: np.ndarray, dt: float, iq: int, iv: int, out: np.ndarray
) -> None:
    """A free flyer moved by ``v dt`` along SE(3)'s exponential (Pinocchio's, with the
    quaternion kept on the start's side and renormalised to first order)."""
    px, py, pz = q[iq], q[iq + 1], q[iq + 2]
    ax, ay, az, aw = q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]
    lx, ly, lz = v[iv] * dt, v[iv + 1] * dt, v[iv + 2] * dt
    wx, wy, wz = v[iv + 3] * dt, v[iv + 4] * dt, v[iv + 5] * dt
    n2 = wx * wx + wy * wy + wz * wz
    # exp6's translation: l + a1 w x l + a2 w x (w x l)
    t2 = n2 + _EPS * _EPS
    t = math.sqrt(t2)
    if t < _PREC3:
        a1, a2 = 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0
    else:
        a1, a2 = (1.0 - math.cos(t)) / t2, (t - math.sin(t)) / t2 / t
    cx, cy, cz = wy * lz - wz * ly, wz * lx - wx * lz, wx * ly - wy * lx
    dx, dy, dz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
    ex, ey, ez = lx + a1 * cx + a2 * dx, ly + a1 * cy + a2 * dy, lz + a1 * cz + a2 * dz
    # exp3: the rotation's quaternion b
    if n2 > _PREC3:
        angle = math.sqrt(n2 + _EPS * _EPS)
        h = math.sin(0.5 * angle)
        bx, by, bz = h * (wx / angle), h * (wy / angle), h * (wz / angle)
        bw = math.cos(0.5 * angle)
    else:
        s2 = n2 / 4.0
        f = 0.5 * (1.0 - s2 / 6.0 + s2 * s2 / 120.0)
        bx, by, bz, bw = f * wx, f * wy, f * wz, 1.0 - s2 / 2.0 + s2 * s2 / 24.0
    # the translation: p + a e (Eigen's Quaternion * vector)
    ux, uy, uz = 2.0 * (ay * ez - az * ey), 2.0 * (az * ex - ax * ez), 2.0 * (ax * ey - ay * ex)
    out[iq] = ex + aw * ux + (ay * uz - az * uy) + px
    out[iq + 1] = ey + aw * uy + (az * ux - ax * uz) + py
    out[iq + 2] = ez + aw * uz + (ax * uy - ay * ux) + pz
    # the rotation: a b, on the side of a, renormalised to first order
    rw = aw * bw - ax * bx - ay * by - az * bz
    rx = aw * bx + ax * bw + ay * bz - az * by
    ry = aw * by + ay * bw + az * bx - ax * bz
    rz = aw * bz + az * bw + ax * by - ay * bx
    if rx * ax + ry * ay + rz * az + rw * aw < 0.0:
        rx, ry, rz, rw = -rx, -ry, -rz, -rw
    g = (3.0 - (rx * rx + ry * ry + rz * rz + rw * rw)) / 2.0
    out[iq + 3] = rx * g
    out[iq + 4] = ry * g
    out[iq + 5] = rz * g
    out[iq + 6] = rw * g


@kernel
def integrate(
    model_i: np.ndarray, q: np.ndarray, v: np.ndarray, dt: float, out: np.ndarray
) -> None:
    """``out = integrate(q, v dt)`` on the configuration manifold: Pinocchio's
    ``pinocchio.integrate(model, q, v * dt)``, with ``v`` the model velocity (nv; rad/s, m/s,
    :func:`model_velocity` makes it from ``u``) and ``dt`` in s.

    ``out`` may be ``q`` itself (each joint reads its entries before writing them)."""
    for i in range(model_i.shape[0]):
        kind = model_i[i, KIND]
        iq, iv = model_i[i, IDX_Q], model_i[i, IDX_V]
        if kind == FRAME:
            break  # the frames' rows, after every joint's
        if kind in (REVOLUTE, PRISMATIC):
            out[iq] = q[iq] + v[iv] * dt
        elif kind == UNBOUNDED:  # SO(2), renormalised to first order
            w = v[iv] * dt
            cw, sw = math.cos(w), math.sin(w)
            c, s = q[iq], q[iq + 1]
            c, s = cw * c - sw * s, sw * c + cw * s
            g = (3.0 - (c * c + s * s)) / 2.0
            out[iq] = c * g
            out[iq + 1] = s * g
        elif kind == PLANAR:
            _integrate_planar(q, v, dt, iq, iv, out)
        elif kind == FREE_FLYER:
            _integrate_free_flyer(q, v, dt, iq, iv, out)
