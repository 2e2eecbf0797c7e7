r"""The contacts' rows at the torque level in kernels (:mod:`wholebody.dynamics.contacts`
states them): each contact's Jacobian, the acceleration that holds it and its map to the
world, from the joint Jacobians and frame placements that every kernel reads.

A contact is a row of ``table`` (ints, ``CT_*``): its kind (``PATCH``: a frame held, its
wrench in the frame, ``LOCAL``; ``POINT``: a point held, its force in the world's axes) and
frame, and a row of ``par`` (floats, ``CP_*``): its gains ``kp`` (1/s^2) and ``kd`` (1/s)
and where it was made (a patch's 4x4 pose, row-major; a point's position, m). ``support[c,
j]`` says whether the model velocity ``j`` moves contact ``c``'s frame. ``J`` is Pinocchio's
``data.J`` (6 x nv: column ``j`` the spatial velocity at the world's origin, linear rows
first) and ``oMf`` the frame placements (nframes, 12: rotation column-major, translation).

Each contact's velocity ``V = J_c v`` (:func:`twists`), its Jacobian ``J_c`` (a patch's
``LOCAL``: ``[R^T (v_j + w_j x p); R^T w_j]`` per column; a point's ``[v_j + w_j x p]``) and
the acceleration it asks for, ``J_c dv = -kp e - kd V - Jdot_c v``, with ``e`` the drift
from where it was made (a patch's ``log6(M_ref^-1 M)``, Pinocchio's; a point's ``p -
p_ref``) and ``Jdot_c v`` the forward difference ``(V(q (+) eps v) - V(q)) / eps`` of the
velocities at the two configurations the stack's rows are evaluated at (``eps = 0``: at rest,
none). ``to_world`` maps the wrench to the world's origin: a patch's ``[[R, 0], [p^ R, R]]``
(Pinocchio's dual action matrix), a point's ``[I; p^]``.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.kinematics import frame_kinematics
from wholebody.kernels.so3 import log3

__all__ = ["CP_WIDTH", "CT_WIDTH", "PATCH", "POINT", "contact_rows", "log6", "twists"]

PATCH, POINT = 6, 3  # the kinds: the wrench's size
CT_KIND, CT_FRAME = 0, 1
CT_WIDTH = 2
CP_KP, CP_KD, CP_REF = 0, 1, 2  # the reference: 16 (a pose, row-major) or 3 (a point)
CP_WIDTH = 18
_PREC3 = 2.220446049250313e-16**0.25  # Pinocchio's TaylorSeriesExpansion precision<3>


@kernel
def _jacobian(
    J: np.ndarray, oMf: np.ndarray, kind: int, frame: int, support: np.ndarray, out: np.ndarray
) -> None:
    """The contact's Jacobian (``kind`` rows x nv) into ``out`` (module docstring): the
    frame's world-aligned Jacobian over the model's velocities
    (:func:`~wholebody.kernels.kinematics.frame_kinematics` with the identity for ``A``;
    ``support``: its row, 1 x nv), rotated into the frame for a patch."""
    nv = J.shape[1]
    columns = np.arange(nv)
    Jf, p, R = np.empty((1, 6, nv)), np.empty((1, 3)), np.empty((1, 3, 3))
    frames = np.full(1, frame)
    frame_kinematics(J, oMf, frames, support, columns, columns, np.ones(nv), Jf, p, R)
    if kind == POINT:
        out[:, :] = Jf[0, :3]
        return
    for i in range(3):  # R^T: row i of R^T is column i of R
        for j in range(nv):
            out[i, j] = (
                R[0, 0, i] * Jf[0, 0, j] + R[0, 1, i] * Jf[0, 1, j] + R[0, 2, i] * Jf[0, 2, j]
            )
            out[3 + i, j] = (
                R[0, 0, i] * Jf[0, 3, j] + R[0, 1, i] * Jf[0, 4, j] + R[0, 2, i] * Jf[0, 5, j]
            )


@kernel
def twists(
    J: np.ndarray,
    oMf: np.ndarray,
    table: np.ndarray,
    support: np.ndarray,
    v: np.ndarray,
    out: np.ndarray,
) -> None:
    """Each contact's velocity ``J_c v`` (its kind's entries; a patch's ``LOCAL`` twist, a
    point's velocity in the world's axes) into ``out`` (contacts x 6), ``v`` the model
    velocity (nv)."""
    Jc = np.empty((6, J.shape[1]))
    for c in range(table.shape[0]):
        kind = table[c, CT_KIND]
        _jacobian(J, oMf, kind, table[c, CT_FRAME], support[c : c + 1], Jc[:kind])
        for i in range(kind):
            out[c, i] = Jc[i] @ v


@kernel
def log6(R: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
    """``out`` (6) = Pinocchio's ``log6`` of the placement ``(R, p)``: ``[V^-1 p; w]`` with
    ``w = log3(R)`` and ``V^-1 p = alpha p - w x p / 2 + beta (w . p) w``."""
    w = np.empty(3)
    theta = log3(R, w)
    t2 = theta * theta
    if theta < _PREC3:  # (Pinocchio's Taylor expansion)
        alpha = 1.0 - t2 / 12.0 - t2 * t2 / 720.0
        beta = 1.0 / 12.0 + t2 / 720.0
    else:
        st, ct = math.sin(theta), math.cos(theta)
        alpha = theta * st / (2.0 * (1.0 - ct))
        beta = 1.0 / t2 - st / (2.0 * theta * (1.0 - ct))
    wp = w[0] * p[0] + w[1] * p[1] + w[2] * p[2]
    out[0] = alpha * p[0] - 0.5 * (w[1] * p[2] - w[2] * p[1]) + beta * wp * w[0]
    out[1] = alpha * p[1] - 0.5 * (w[2] * p[0] - w[0] * p[2]) + beta * wp * w[1]
    out[2] = alpha * p[2] - 0.5 * (w[0] * p[1] - w[1] * p[0]) + beta * wp * w[2]
    out[3], out[4], out[5] = w[0], w[1], w[2]


@kernel
def _error(kind: int, m: np.ndarray, ref: np.ndarray, out: np.ndarray) -> None:
    """The drift ``e`` of a contact at the placement ``m`` (12) from ``ref`` (module
    docstring) into ``out`` (``kind`` entries)."""
    if kind == POINT:
        for i in range(3):
            out[i] = m[9 + i] - ref[i]
        return
    R, p = np.empty((3, 3)), np.empty(3)
    d0, d1, d2 = m[9] - ref[3], m[10] - ref[7], m[11] - ref[11]
    for i in range(3):  # M_ref^-1 M = (R_ref^T R, R_ref^T (p - p_ref))
        p[i] = ref[i] * d0 + ref[4 + i] * d1 + ref[8 + i] * d2
        for k in range(3):
            R[i, k] = ref[i] * m[3 * k] + ref[4 + i] * m[3 * k + 1] + ref[8 + i] * m[3 * k + 2]
    log6(R, p, out)


@kernel
def _to_world(kind: int, m: np.ndarray, G: np.ndarray) -> None:
    """The contact's map of its wrench to the world's origin (6 x kind) into ``G``."""
    G[:, :] = 0.0
    p = m[9:12]
    for i in range(3):
        for k in range(3):
            r = m[3 * k + i] if kind == PATCH else (1.0 if i == k else 0.0)  # R[i, k], or I
            G[i, k] = r
            if kind == PATCH:
                G[3 + i, 3 + k] = r
    for k in range(3):  # the torque rows: p x (force column k)
        G[3, k] = p[1] * G[2, k] - p[2] * G[1, k]
        G[4, k] = p[2] * G[0, k] - p[0] * G[2, k]
        G[5, k] = p[0] * G[1, k] - p[1] * G[0, k]


@kernel
def contact_rows(
    J: np.ndarray,
    oMf: np.ndarray,
    table: np.ndarray,
    support: np.ndarray,
    par: np.ndarray,
    v: np.ndarray,
    ahead: np.ndarray,
    eps: float,
    out: tuple,
) -> None:
    """Every contact's rows at the state of ``J`` and ``oMf``, one after the other (a
    contact's rows and wrench columns start where the last one's end), into ``out = (Jw,
    eq_dv, eq_b, G)``: its Jacobian into ``Jw`` and ``eq_dv`` (rows), ``-kp e - kd V -
    Jdot v`` into ``eq_b`` and ``to_world`` into ``G`` (columns). ``ahead`` (contacts x 6):
    the velocities at ``q (+) eps v`` (:func:`twists`; unread where ``eps = 0``)."""
    Jw, eq_dv, eq_b, G = out
    e, r = np.empty(6), 0
    for c in range(table.shape[0]):
        kind, m = table[c, CT_KIND], oMf[table[c, CT_FRAME]]
        Jc = Jw[r : r + kind]
        _jacobian(J, oMf, kind, table[c, CT_FRAME], support[c : c + 1], Jc)
        eq_dv[r : r + kind] = Jc
        _error(kind, m, par[c, CP_REF:], e)
        for i in range(kind):
            V = Jc[i] @ v
            drift = (ahead[c, i] - V) / eps if eps > 0.0 else 0.0
            eq_b[r + i] = -par[c, CP_KP] * e[i] - par[c, CP_KD] * V - drift
        _to_world(kind, m, G[:, r : r + kind])
        r += kind
