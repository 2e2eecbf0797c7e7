"""The repulsive forces of the DMP's obstacles, in kernels: the one implementation of
``phi = -grad_x U`` for :class:`~wholebody.planning.obstacles.DynamicPotential` and
:class:`~wholebody.planning.obstacles.StaticPotential` (see :mod:`wholebody.planning.obstacles`
for the maths). The DMP integrator (:mod:`wholebody.kernels.dmp`) evaluates it at every RK4
stage; the potentials' vectorised ``force()`` calls :func:`forces`.

**Rows.** A potential is one row of ``ROW`` floats (:func:`row`): its kind, the
superquadric's centre ``c`` (m), rotation ``R`` (row-major: ``R[i, j]`` at ``4 + 3 i + j``),
inverse semi-axes ``1/f`` (1/m) and exponents ``n, m``, then the potential's gain
(``lambda`` or ``A``), ``beta`` (unused by the static potential), ``eta`` and floor
``C_min``. Several rows add their forces.

**Overflow.** A power that overflows (far beyond the obstacle's reach with an extreme
exponent, or an absurd gain) gives an infinite or NaN force; the integrator then reports a
non-finite state (:class:`~wholebody.errors.IntegrationError`) rather than a wrong path.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel

__all__ = ["ROW", "STATIC", "forces", "row"]

ROW = 22
"""Floats per potential (module docstring)."""

DYNAMIC, STATIC = 0.0, 1.0  # row[0]: the potential's kind
_Q_FLOOR = 1e-150  # floor of q = a^n + b^n on the obstacle's axis, where q^(m/n-2) is infinite


def row(
    static: bool,
    center: np.ndarray,
    rotation: np.ndarray,
    semi_axes: np.ndarray,
    exponents: tuple[float, float],
    gain: float,
    beta: float,
    eta: float,
    floor: float,
) -> np.ndarray:
    """One potential's row (``ROW`` floats, module docstring): centre (3,) m, rotation
    (3, 3), semi-axes (3,) m, ``(n, m)``, then the potential's parameters. Not a kernel: the
    Python side calls it."""
    out = np.empty(ROW)
    out[0] = STATIC if static else DYNAMIC
    out[1:4] = center
    out[4:13] = np.asarray(rotation, dtype=float).ravel()
    out[13:16] = 1.0 / np.asarray(semi_axes, dtype=float)
    out[16:18] = exponents
    out[18:22] = (gain, beta, eta, floor)
    return out


@kernel
def force(
    obs: np.ndarray, x1: float, x2: float, x3: float, v1: float, v2: float, v3: float
) -> tuple[float, float, float]:
    """The summed force ``phi`` (m, world axes) of the potentials ``obs`` (n, ``ROW``) at the
    point ``x`` (m) moving with ``v`` (m: the DMP's ``tau x'``).

    Per row, in the obstacle's frame, ``u = diag(1/f) R^T (x - c)``, ``a, b, c = u^2``,
    ``q = max(a^n + b^n, _Q_FLOOR)``, ``C = q^(m/n) + c^m - 1`` and ``g = grad_p C``; the
    static force is ``A exp(-eta C) (eta / C + 1 / C^2) g`` where ``C > C_min``; the dynamic
    force, where the velocity ``w = R^T v`` approaches (``w.g < 0``), is
    ``lambda C_s^-eta k^(beta-1) [(beta / |g|) H w_perp + eta k |w| g / C_s]`` with
    ``C_s = max(C, C_min)``, ``k = -w.g / (|w| |g|)``, ``H = hess_p C`` and ``w_perp`` the
    part of ``w`` orthogonal to ``g`` (its second term only where ``C > C_min``); then
    ``R`` turns the force into world axes."""
    f1 = f2 = f3 = 0.0
    for j in range(obs.shape[0]):
        p = obs[j]
        i1, i2, i3, n, m = p[13], p[14], p[15], p[16], p[17]
        gain, beta, eta, floor = p[18], p[19], p[20], p[21]
        d1, d2, d3 = x1 - p[1], x2 - p[2], x3 - p[3]
        u1 = (p[4] * d1 + p[7] * d2 + p[10] * d3) * i1
        u2 = (p[5] * d1 + p[8] * d2 + p[11] * d3) * i2
        u3 = (p[6] * d1 + p[9] * d2 + p[12] * d3) * i3
        a, b, c = u1 * u1, u2 * u2, u3 * u3
        cm1 = c ** (m - 1.0)
        if n == 1.0:  # a round cross-section (every cylinder): two powers fewer
            an1 = bn1 = 1.0
        else:
            an1, bn1 = a ** (n - 1.0), b ** (n - 1.0)
        an, bn = an1 * a, bn1 * b
        q = an + bn
        if q < _Q_FLOOR:
            q = _Q_FLOOR
        qm = q ** (m / n)
        iso = qm + c * cm1 - 1.0
        t = 2.0 * m * qm / q  # 2m q^(m/n-1)
        g1, g2, g3 = t * an1 * u1 * i1, t * bn1 * u2 * i2, 2.0 * m * cm1 * u3 * i3
        if p[0] == STATIC:
            if iso <= floor:
                continue
            iso2 = iso * iso  # > 0 unless C_min < 1e-154
            s = gain * math.exp(-eta * iso) * (eta / iso + (1.0 / iso2 if iso2 > 0.0 else math.inf))
            l1, l2, l3 = s * g1, s * g2, s * g3
        else:
            w1 = p[4] * v1 + p[7] * v2 + p[10] * v3
            w2 = p[5] * v1 + p[8] * v2 + p[11] * v3
            w3 = p[6] * v1 + p[9] * v2 + p[12] * v3
            wg = w1 * g1 + w2 * g2 + w3 * g3
            gg = g1 * g1 + g2 * g2 + g3 * g3
            ww = w1 * w1 + w2 * w2 + w3 * w3
            if wg >= 0.0 or gg == 0.0 or ww == 0.0:
                continue
            gn, wn = math.sqrt(gg), math.sqrt(ww)
            k = -wg / (wn * gn) if wn * gn > 0.0 else math.inf
            Cs = iso if iso > floor else floor
            hq, hd = t / q, 2.0 * (m - n)  # 2m q^(m/n-2), 2 (m - n)
            H11 = hq * an1 * (hd * an + (2.0 * n - 1.0) * q) * i1 * i1
            H22 = hq * bn1 * (hd * bn + (2.0 * n - 1.0) * q) * i2 * i2
            H12 = hd * hq * an1 * bn1 * u1 * u2 * i1 * i2
            H33 = 2.0 * m * (2.0 * m - 1.0) * cm1 * i3 * i3
            r = wg / gg
            p1, p2, p3 = w1 - r * g1, w2 - r * g2, w3 - r * g3
            coef = gain * Cs**-eta * k ** (beta - 1.0)
            sa = coef * beta / gn
            sb = coef * eta * k * wn / Cs if iso > floor else 0.0
            l1 = sa * (H11 * p1 + H12 * p2) + sb * g1
            l2 = sa * (H12 * p1 + H22 * p2) + sb * g2
            l3 = sa * H33 * p3 + sb * g3
        f1 += p[4] * l1 + p[5] * l2 + p[6] * l3
        f2 += p[7] * l1 + p[8] * l2 + p[9] * l3
        f3 += p[10] * l1 + p[11] * l2 + p[12] * l3
    return f1, f2, f3


@kernel
def forces(obs: np.ndarray, X: np.ndarray, V: np.ndarray, out: np.ndarray) -> None:
    """:func:`force` at each of the points ``X`` (N, 3) m moving with ``V`` (N, 3) m, into
    ``out`` (N, 3) m."""
    for i in range(X.shape[0]):
        f = force(obs, X[i, 0], X[i, 1], X[i, 2], V[i, 0], V[i, 1], V[i, 2])
        out[i, 0], out[i, 1], out[i, 2] = f
