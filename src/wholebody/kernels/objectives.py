"""Objectives in kernels: the arm potential energy (with a constant or network stiffness),
joint-limit avoidance ``h1`` and manipulability ``h2``, each with its analytic gradient in
actuated coordinates.

The maths is documented with the objectives (:mod:`wholebody.tasks.arm_energy`,
:mod:`wholebody.tasks.objectives`, :mod:`wholebody.arm.network`,
:mod:`wholebody.arm.angle`); the objective classes call these kernels, and the
compiled plan calls them for every built-in objective of a stack in one pass.

Parameters travel as flat float arrays with named entries (``AE_*`` for the arm energy,
followed by its links and its network in the layout of :func:`mlp_stiffness`; its frames are
ints ``AF_*``, rows of a table of frame kinematics), so that many objectives fit in one
table.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.lapack import getrf, getrs, potrf, trtri
from wholebody.kernels.linalg import fortran, mm, mmt, mtm

__all__ = [
    "AE_WIDTH",
    "ARM_PARTS",
    "arm_angle_terms",
    "arm_energy",
    "joint_limit_avoidance",
    "manipulability",
    "mlp_stiffness",
]

# An arm energy's parameter block (floats; one per arm, of variable length):
AE_G, AE_SIDE, AE_FADE, AE_SMOOTH = 0, 1, 2, 3  # m/s^2, +-1 (left/right), m, rad
AE_SHOULDER, AE_LINKS = 4, 5  # 1: heights from the shoulder (0: world); number of links n
AE_K, AE_NET, AE_DK = 6, 7, 8  # stiffness (N m/rad); its source (below); dk/dp (3, N m/rad/m)
AE_WIDTH = 11  # then ARM_PARTS outputs, then n links from AE_LINK0, then the network if any
ARM_PARTS = 6  # value, gravity, spring (J), arm angle (rad), stiffness (N m/rad), rho (m)
AE_LINK0 = AE_WIDTH + ARM_PARTS
LINK_WIDTH = 4  # a link: mass (kg), centre of mass in the link frame (m, 3)
# AE_NET: the offset in the block of the packed stiffness network (:func:`mlp_stiffness`), or
# AE_CONSTANT (k = par[AE_K]) or AE_GIVEN (k = par[AE_K] and dk/dp = par[AE_DK:AE_DK + 3],
# written by the caller at the canonical wrist position before each call)
AE_CONSTANT, AE_GIVEN = -1, -2
# An arm energy's ints: rows of the frame table (positions, rotations and Jacobians) of the
# shoulder, elbow and wrist centres, the base (-1 with a constant stiffness: not read), then
# of the n links' frames from AF_LINK0, upper arm's first, in the order of the block's links
AF_SHOULDER, AF_ELBOW, AF_WRIST, AF_BASE, AF_LINK0 = 0, 1, 2, 3, 4

_PIVOT_FLOOR = 1e-8  # Cholesky pivots^2 below this fraction of max diag(J J^T): LU decides


@kernel
def arm_angle_terms(
    S: np.ndarray, E: np.ndarray, W: np.ndarray, side: float, dx: np.ndarray, dy: np.ndarray
) -> tuple[float, float, float]:
    """``(alpha, x, y)`` of one arm and the gradients of ``x`` and ``y`` with respect to S,
    E and W (rows of 3, flattened into ``dx`` and ``dy``, (9,)); see
    :func:`wholebody.arm.angle.arm_angle_with_gradient`."""
    sx, sy, sz = S[0], S[1], S[2]
    ax, ay, az = E[0] - sx, E[1] - sy, E[2] - sz
    cx, cy, cz = W[0] - sx, W[1] - sy, W[2] - sz
    L = math.sqrt(cx * cx + cy * cy + cz * cz)
    ux, uy, uz = cx / L, cy / L, cz / L
    au = ax * ux + ay * uy + az * uz
    x = -az + au * uz
    y = side * (ux * ay - uy * ax)
    xa0, xa1, xa2 = uz * ux, uz * uy, uz * uz - 1.0  # d/da
    ya0, ya1 = -side * uy, side * ux
    xu0, xu1, xu2 = uz * ax, uz * ay, uz * az + au  # d/du, then d/dW = (v - u (u.v)) / L
    yu0, yu1 = side * ay, -side * ax
    t = ux * xu0 + uy * xu1 + uz * xu2
    xw0, xw1, xw2 = (xu0 - ux * t) / L, (xu1 - uy * t) / L, (xu2 - uz * t) / L
    t = ux * yu0 + uy * yu1
    yw0, yw1, yw2 = (yu0 - ux * t) / L, (yu1 - uy * t) / L, (0.0 - uz * t) / L
    dx[0], dx[1], dx[2] = -xa0 - xw0, -xa1 - xw1, -xa2 - xw2
    dx[3], dx[4], dx[5] = xa0, xa1, xa2
    dx[6], dx[7], dx[8] = xw0, xw1, xw2
    dy[0], dy[1], dy[2] = -ya0 - yw0, -ya1 - yw1, -0.0 - yw2
    dy[3], dy[4], dy[5] = ya0, ya1, 0.0
    dy[6], dy[7], dy[8] = yw0, yw1, yw2
    return math.atan2(y, x), x, y


@kernel
def mlp_stiffness(net: np.ndarray, p: np.ndarray, grad: np.ndarray) -> float:
    """The stiffness network's ``k`` (returned) and ``dk/dp`` (into ``grad``, (3,)) at the
    canonical wrist position ``p`` (see :mod:`wholebody.arm.network`).

    ``net`` layout: ``[L, beta, b_out, H_L]``, then per hidden layer ``[out, in, W (out x
    in, row-major), b (out)]`` (the input normalisation folded into the first), then
    ``w_out`` (H_L) (the output scaling folded in): see ``NetworkStiffness.packed``."""
    n_layers = int(net[0])
    beta, b_out, width = net[1], net[2], int(net[3])
    hs = np.zeros((n_layers, width))
    sizes = np.zeros(n_layers, np.int64)
    starts = np.zeros(n_layers, np.int64)
    h = p.copy()
    o = 4
    for i in range(n_layers):
        n_out, n_in = int(net[o]), int(net[o + 1])
        starts[i], sizes[i] = o + 2, n_out
        Wl = net[o + 2 : o + 2 + n_out * n_in]
        b = net[o + 2 + n_out * n_in : o + 2 + n_out * n_in + n_out]
        nxt = np.empty(n_out)
        for r in range(n_out):
            acc = 0.0
            for c in range(n_in):
                acc += Wl[r * n_in + c] * h[c]
            nxt[r] = math.tanh(acc + b[r])
        hs[i, :n_out] = nxt
        h = nxt
        o += 2 + n_out * n_in + n_out
    w_out = net[o : o + h.shape[0]]
    acc = 0.0
    for c in range(h.shape[0]):
        acc += w_out[c] * h[c]
    r = acc + b_out
    br = beta * r
    if br > 30.0:
        k, s = r, 1.0
    else:
        e = math.exp(br) if br < 0 else math.exp(-br)
        k = (max(br, 0.0) + math.log1p(e)) / beta
        s = 1.0 / (1.0 + e) if br >= 0 else e / (1.0 + e)
    g = np.empty(h.shape[0])
    for c in range(h.shape[0]):
        g[c] = w_out[c] * s
    for i in range(n_layers - 1, -1, -1):
        n_out = sizes[i]
        n_in = 3 if i == 0 else sizes[i - 1]
        Wl = net[starts[i] : starts[i] + n_out * n_in]
        nxt = np.zeros(n_in)
        for r in range(n_out):
            gi = g[r] * (1.0 - hs[i, r] * hs[i, r])
            for c in range(n_in):
                nxt[c] += Wl[r * n_in + c] * gi
        g = nxt
    grad[:] = g
    return k


@kernel
def _gravity(
    P: np.ndarray, R: np.ndarray, frames: np.ndarray, par: np.ndarray, C: np.ndarray
) -> float:
    """``g sum_i m_i h_i`` over the arm's links (``AE_LINKS`` of them: a segment may be split
    over several), heights (m) of their centres of mass from the shoulder centre with
    ``AE_SHOULDER``, else from the world's origin; the coefficients of its gradient
    ``g m_i (J_ci[z] - J_S[z])`` on the frames' Jacobian rows added into ``C`` (rows as
    ``frames``: ``J_ci[z] = J_i[z] + (w_i x R_i c_i)[z]`` reads the link frame's linear z row
    and angular x and y rows)."""
    g = par[AE_G]
    mass = 0.0
    gravity = 0.0
    for link in range(int(par[AE_LINKS])):
        o = AE_LINK0 + LINK_WIDTH * link
        m, c0, c1, c2 = par[o], par[o + 1], par[o + 2], par[o + 3]
        row = AF_LINK0 + link
        f = frames[row]
        Rb = R[f]
        rx = Rb[0, 0] * c0 + Rb[0, 1] * c1 + Rb[0, 2] * c2  # R c: the centre from the origin
        ry = Rb[1, 0] * c0 + Rb[1, 1] * c1 + Rb[1, 2] * c2
        rz = Rb[2, 0] * c0 + Rb[2, 1] * c1 + Rb[2, 2] * c2
        gm = g * m
        gravity += gm * (P[f, 2] + rz)
        C[row, 2] += gm
        C[row, 3] += gm * ry
        C[row, 4] -= gm * rx
        mass += m
    if par[AE_SHOULDER] != 0.0:
        gravity -= g * mass * P[frames[AF_SHOULDER], 2]
        C[AF_SHOULDER, 2] -= g * mass
    return gravity


@kernel
def arm_energy(
    P: np.ndarray,
    R: np.ndarray,
    J: np.ndarray,
    frames: np.ndarray,
    par: np.ndarray,
    grad: np.ndarray,
) -> None:
    """Gravity plus spring energy of one arm and its gradient (into ``grad``, nu).

    ``P`` (F, 3), ``R`` (F, 3, 3) and ``J`` (F, 6, nu): world positions (m), rotations and
    Jacobians (world-aligned axes at the frame origin, linear rows first, actuated columns)
    of a table of frames, of which ``frames`` (ints ``AF_*``) names the arm's rows: the
    shoulder, elbow and wrist centres, the base (read only when the stiffness depends on the
    wrist) and each link. ``par`` the arm's block (``AE_*``, the links, the network); its
    ``ARM_PARTS`` numbers at ``AE_WIDTH`` receive the value and its parts. ``J`` is read only
    for the gradient's columns (none: the value alone)."""
    C = np.zeros((frames.shape[0], 6))  # the gradient's coefficients of each frame's 6 rows
    gravity = _gravity(P, R, frames, par, C)
    S, E, W = P[frames[AF_SHOULDER]], P[frames[AF_ELBOW]], P[frames[AF_WRIST]]
    dx = np.empty(9)
    dy = np.empty(9)
    side = par[AE_SIDE]
    alpha, x, y = arm_angle_terms(S, E, W, side, dx, dy)
    rho2 = x * x + y * y
    eps2 = par[AE_FADE] ** 2
    w = rho2 / (rho2 + eps2)
    delta = par[AE_SMOOTH]
    if abs(alpha) < delta:
        s, ds = alpha * alpha / (2 * delta) + delta / 2, alpha / delta
    else:
        s, ds = abs(alpha), float((alpha > 0) - (alpha < 0))
    rest = math.pi - s
    net = int(par[AE_NET])
    dk = np.zeros(3)
    d = np.empty(3)
    for i in range(3):
        d[i] = W[i] - S[i]
    if net == AE_CONSTANT:
        k = par[AE_K]
    elif net == AE_GIVEN:
        k = par[AE_K]
        dk[:] = par[AE_DK : AE_DK + 3]
    else:
        Rb = R[frames[AF_BASE]]
        wrist = np.empty(3)
        for i in range(3):  # Mirror R_b^T (W - S), the mirror flipping y for a left arm
            wrist[i] = Rb[0, i] * d[0] + Rb[1, i] * d[1] + Rb[2, i] * d[2]
        wrist[1] *= -side
        k = mlp_stiffness(par[net:], wrist, dk)
    spring = 0.5 * k * rest * rest * w
    den = rho2 + eps2
    cw = k * rest * 0.5 * rest * 2 * eps2 / (den * den)
    ca = -k * rest * ds / den
    coef_x = cw * x - ca * y
    coef_y = cw * y + ca * x
    for i in range(9):  # d f_e / d(S, E, W): rows AF_SHOULDER, AF_ELBOW, AF_WRIST
        C[i // 3, i % 3] += coef_x * dx[i] + coef_y * dy[i]
    if net != AE_CONSTANT:
        # dp = Mirror R_b^T (J_W - J_S + [W - S]x J_b,ang): with q = (c dk Mirror) R_b^T,
        # q.dp = q.J_W - q.J_S + (q x (W - S)).J_b,ang
        c = 0.5 * rest * rest * w
        dk[1] *= -side
        Rb = R[frames[AF_BASE]]
        q = np.empty(3)
        for i in range(3):
            q[i] = (c * dk[0]) * Rb[i, 0] + (c * dk[1]) * Rb[i, 1] + (c * dk[2]) * Rb[i, 2]
        for i in range(3):
            C[AF_WRIST, i] += q[i]
            C[AF_SHOULDER, i] -= q[i]
        C[AF_BASE, 3] += q[1] * d[2] - q[2] * d[1]
        C[AF_BASE, 4] += q[2] * d[0] - q[0] * d[2]
        C[AF_BASE, 5] += q[0] * d[1] - q[1] * d[0]
    grad[:] = 0.0
    for row in range(frames.shape[0]):
        f = frames[row]
        for r in range(6):
            cf = C[row, r]
            if cf != 0.0:  # (a frame not read, f < 0, has none)
                for col in range(grad.shape[0]):
                    grad[col] += cf * J[f, r, col]
    parts = par[AE_WIDTH : AE_WIDTH + ARM_PARTS]
    parts[0] = gravity + spring
    parts[1] = gravity
    parts[2] = spring
    parts[3] = alpha
    parts[4] = k
    parts[5] = math.sqrt(rho2)


@kernel
def joint_limit_avoidance(
    positions: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    c: np.ndarray,
    grad: np.ndarray,
    curvature: np.ndarray,
) -> float:
    """The paper's ``h1 = sum_i c_i / (a_i b_i)``, ``a = hi - q``, ``b = q - lo``, with its
    gradient ``c (b - a) / (a b)^2`` and diagonal Hessian
    ``2 c (a b + (b - a)^2) / (a b)^3`` (into ``grad`` and ``curvature``), ``q`` clamped
    ``1e-6`` of the range inside ``[lo, hi]``; entries with ``c = 0`` contribute zeros."""
    value = 0.0
    for i in range(positions.shape[0]):
        eps = 1e-6 * (hi[i] - lo[i])
        q = min(max(positions[i], lo[i] + eps), hi[i] - eps)
        a = hi[i] - q
        b = q - lo[i]
        ab = a * b
        dd = b - a
        ab2 = ab * ab
        grad[i] = c[i] * dd / ab2
        curvature[i] = 2.0 * c[i] * (dd * dd + ab) / (ab2 * ab)
        value += c[i] / ab
    return value


@kernel
def manipulability(J: np.ndarray, mask: np.ndarray, grad: np.ndarray) -> float:
    """Yoshikawa's ``h2 = sqrt(det(J J^T))`` of the stacked Jacobians ``J`` (F, 6, nu) and
    its gradient (into ``grad``): ``h2 <(J J^T)^-1 J, dJ/du_l>_F``, the Jacobian derivatives
    from the kinematic-Hessian identity (:mod:`wholebody.robot.hessian`) with
    ``mask[l, k]``: column l supports column k. Zero where ``J J^T`` is singular."""
    F, _, nu = J.shape
    n = 6 * F
    Js = J.reshape(n, nu)
    G = mmt(Js, Js)
    L = fortran(G)
    info = potrf(L, True)
    top = 0.0
    low = np.inf
    for i in range(n):
        top = max(top, G[i, i])
        low = min(low, L[i, i] * L[i, i])
    grad[:] = 0.0
    if info == 0 and low > _PIVOT_FLOOR * top:
        logdet = 0.0
        for i in range(n):
            logdet += math.log(L[i, i])
        logdet *= 2.0
        if logdet < -200:
            return 0.0
        trtri(L, True)
        Pm = mtm(L, mm(L, Js))
    else:  # LU with partial pivoting, as numpy's slogdet and solve
        LU = fortran(G)
        piv = np.zeros(n, np.int32)
        if getrf(LU, piv) < 0:
            return 0.0
        negative = False
        logdet = 0.0
        for i in range(n):
            d = LU[i, i]
            if d == 0.0:  # singular: numpy.linalg.slogdet says sign 0
                return 0.0
            negative ^= (d < 0.0) ^ (piv[i] != i + 1)
            logdet += math.log(abs(d))
        if negative or logdet < -200:
            return 0.0
        Pm = fortran(Js)
        getrs(LU, piv, Pm)
    h2 = math.exp(0.5 * logdet)
    for f in range(F):
        _contract(J[f], Pm[6 * f : 6 * f + 6], mask, grad)
    for k in range(nu):
        grad[k] *= h2
    return h2


@kernel
def _contract(Jf: np.ndarray, Pf: np.ndarray, mask: np.ndarray, out: np.ndarray) -> None:
    """``out_l += <P_f, dJ_f / du_l>_F`` over the columns that move the frame: with
    ``J_k = [v_k; w_k]`` and ``P_k = [a_k; b_k]``,
    ``w_l . sum_{k: M[l,k]} (v_k x a_k + w_k x b_k) + v_l . sum_{k: not M[l,k]} (a_k x w_k)``."""
    nu = Jf.shape[1]
    cols = np.empty(nu, np.int64)
    n = 0
    for k in range(nu):
        if (
            Jf[0, k] != 0.0
            or Jf[1, k] != 0.0
            or Jf[2, k] != 0.0
            or Jf[3, k] != 0.0
            or Jf[4, k] != 0.0
            or Jf[5, k] != 0.0
        ):
            cols[n] = k
            n += 1
    same = np.empty((n, 3))  # v_k x a_k + w_k x b_k
    other = np.empty((n, 3))  # a_k x w_k
    for i in range(n):
        k = cols[i]
        v0, v1, v2 = Jf[0, k], Jf[1, k], Jf[2, k]
        w0, w1, w2 = Jf[3, k], Jf[4, k], Jf[5, k]
        a0, a1, a2 = Pf[0, k], Pf[1, k], Pf[2, k]
        b0, b1, b2 = Pf[3, k], Pf[4, k], Pf[5, k]
        same[i, 0] = (v1 * a2 - v2 * a1) + (w1 * b2 - w2 * b1)
        same[i, 1] = (v2 * a0 - v0 * a2) + (w2 * b0 - w0 * b2)
        same[i, 2] = (v0 * a1 - v1 * a0) + (w0 * b1 - w1 * b0)
        other[i, 0] = a1 * w2 - a2 * w1
        other[i, 1] = a2 * w0 - a0 * w2
        other[i, 2] = a0 * w1 - a1 * w0
    for i in range(n):
        l = cols[i]  # noqa: E741
        s0 = s1 = s2 = t0 = t1 = t2 = 0.0
        for j in range(n):
            if mask[l, cols[j]]:
                s0 += same[j, 0]
                s1 += same[j, 1]
                s2 += same[j, 2]
            else:
                t0 += other[j, 0]
                t1 += other[j, 1]
                t2 += other[j, 2]
        out[l] += (
            Jf[3, l] * s0
            + Jf[4, l] * s1
            + Jf[5, l] * s2
            + Jf[0, l] * t0
            + Jf[1, l] * t1
            + Jf[2, l] * t2
        )
