"""The rollout without obstacles: classical RK4 of a linear system, as a linear recurrence.

Without a repulsive term the transformation system is linear with a known input,
``z' = (A z + b(t)) / tau`` with ``z = (x, v)``, ``A = [[0, 1], [-K, -D]]`` and
``b = (0, K (g - (g - x0) s + f(s)))``. Classical RK4 with step ``h`` is then exactly the
recurrence ::

    z_{n+1} = P z_n + m0 b_n + mh b_{n+1/2} + m1 b_{n+1}
    B = h A / tau,   P = I + B + B^2/2 + B^3/6 + B^4/24

(``m0``, ``mh``, ``m1`` below), which runs as a second-order IIR filter over all dimensions
at once (``scipy.signal.lfilter``) instead of one Python step per sample: the same numbers as
stepping RK4, at the cost of one filter call. A sampling too coarse for one stable, accurate
step per interval takes ``m`` steps per interval (:func:`linear_substeps`).
"""

from __future__ import annotations

import math
from functools import lru_cache
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
from scipy.signal import lfilter

from wholebody.planning.dmp.compiled import as_buffer
from wholebody.planning.dmp.config import DMPConfig
from wholebody.planning.dmp.rollout import DMPRollout, rollout_result

if TYPE_CHECKING:
    from wholebody.planning.dmp.model import DMP

__all__ = ["linear_substeps", "rk4_linear", "rk4_matrices", "rollout_linear"]

_LINEAR_STEP = 0.25  # largest |lambda| h of a linear RK4 step (stable below 2.78)


def linear_substeps(cfg: DMPConfig, r: float) -> int:
    """RK4 steps per interval of ``r = h / tau`` for the linear DMP ``z' = A z / tau``:
    ``|lambda_max(A)| h / tau <= 0.25`` (1 for the paper's 160 samples: 0.2)."""
    K, D = cfg.K, cfg.D
    rho = 0.5 * (D + math.sqrt(D * D - 4.0 * K)) if D * D >= 4.0 * K else math.sqrt(K)
    return max(1, math.ceil(rho * r / _LINEAR_STEP - 1e-12))


@lru_cache(maxsize=64)
def rk4_matrices(K: float, D: float, r: float) -> tuple[np.ndarray, ...]:
    """RK4 of ``z' = (A z + b(t)) / tau`` with ``r = h / tau`` as ``z+ = P z + m0 b0 + mh bh +
    m1 b1`` (``b`` entering the second row only, so the ``m`` are 2-vectors). Read-only and
    cached (one set per DMP configuration and sampling)."""
    B = r * np.array([[0.0, 1.0], [-K, -D]])
    I2 = np.eye(2)
    B2 = B @ B
    B3 = B2 @ B
    P = I2 + B + B2 / 2.0 + B3 / 6.0 + B2 @ B2 / 24.0
    e2 = np.array([0.0, r])
    m0 = (I2 + B + B2 / 2.0 + B3 / 4.0) @ e2 / 6.0
    mh = (4.0 * I2 + 2.0 * B + B2 / 2.0) @ e2 / 6.0
    m1 = e2 / 6.0
    for a in (P, m0, mh, m1):
        a.setflags(write=False)
    return P, m0, mh, m1


def rk4_linear(
    b: np.ndarray, x0: np.ndarray, K: float, D: float, tau: float, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """RK4 from rest at ``x0`` as the linear recurrence, with the input ``b`` (2N - 1, d) on
    the grid of steps and midpoints; returns ``x`` and ``v`` (N, d)."""
    N = (b.shape[0] + 1) // 2
    d = b.shape[1]
    P, m0, mh, m1 = rk4_matrices(K, D, h / tau)
    # c_n = m0 b_n + mh b_{n+1/2} + m1 b_{n+1}: (N-1, 2, d)
    c = np.multiply.outer(b[0:-1:2], m0)  # (N-1, d, 2), transposed below
    c += np.multiply.outer(b[1::2], mh)
    c += np.multiply.outer(b[2::2], m1)
    c = c.transpose(0, 2, 1)
    z = np.empty((N, 2, d))
    z[0, 0], z[0, 1] = x0, 0.0
    z[1] = P.dot(z[0]) + c[0]
    if N > 2:
        # Cayley-Hamilton: z_{n+2} - tr(P) z_{n+1} + det(P) z_n = c_{n+1} + (P - tr(P) I) c_n
        (p00, p01), (p10, p11) = P.tolist()
        tr, det = p00 + p11, p00 * p11 - p01 * p10
        e = np.empty((N - 2, 2, d))
        np.multiply(c[:-1, 0], p00 - tr, out=e[:, 0])
        e[:, 0] += p01 * c[:-1, 1]
        np.multiply(c[:-1, 0], p10, out=e[:, 1])
        e[:, 1] += (p11 - tr) * c[:-1, 1]
        e += c[1:]
        y0, y1 = z[0].reshape(-1), z[1].reshape(-1)
        zi = np.empty((2, 2 * d))  # direct form II transposed state
        np.subtract(tr * y1, det * y0, out=zi[0])
        np.multiply(y1, -det, out=zi[1])
        z[2:] = lfilter((1.0,), (1.0, -tr, det), e.reshape(N - 2, 2 * d), axis=0,
                        zi=zi)[0].reshape(N - 2, 2, d)  # fmt: skip
    return z[:, 0, :], z[:, 1, :]


def rollout_linear(
    dmp: DMP, N: int, x0: np.ndarray, g: np.ndarray, T: float, kernels: ModuleType | None
) -> DMPRollout:
    """:meth:`DMP.rollout <wholebody.planning.dmp.DMP.rollout>` without obstacles: ``N``
    samples from rest at ``x0`` (m) to ``g`` over ``T`` s, by
    :func:`wholebody.kernels.dmp.rollout_linear` when ``kernels`` is given, else by the
    recurrence here."""
    if kernels is not None:
        return _rollout_compiled(dmp, kernels, N, x0, g, T)
    cfg = dmp.config
    K, D = cfg.K, cfg.D
    tau = T
    h = T / (N - 1)
    # m RK4 steps per sample interval, enough for stability and accuracy however coarse
    # the sampling (m = 1 unless N is small)
    m = linear_substeps(cfg, h / tau)
    t_half = np.linspace(0.0, T, 2 * m * (N - 1) + 1)  # steps and midpoints
    s_half = np.exp(-cfg.alpha_s * t_half / (cfg.phase_tau_ratio * T))
    b = K * (g - np.outer(s_half, g - x0) + dmp.forcing(s_half))  # (2m(N-1)+1, d)
    x, v = rk4_linear(b, x0, K, D, tau, h / m)
    if m > 1:
        x, v = x[::m].copy(), v[::m].copy()
    vdot = (b[:: 2 * m] - K * x - D * v) / tau
    return rollout_result(t_half[:: 2 * m].copy(), s_half[:: 2 * m].copy(), x, v / tau,
                          vdot / tau, x0, g, T)  # fmt: skip


def _rollout_compiled(
    dmp: DMP, kernels: ModuleType, N: int, x0: np.ndarray, g: np.ndarray, T: float
) -> DMPRollout:
    """:func:`rollout_linear` by :func:`wholebody.kernels.dmp.rollout_linear`."""
    cfg = dmp.config
    h = T / (N - 1)
    m = linear_substeps(cfg, h / T)
    P, m0, mh, m1 = rk4_matrices(cfg.K, cfg.D, h / m / T)
    times, phase = np.empty(N), np.empty(N)
    X, V, A = np.empty((N, dmp.dim)), np.empty((N, dmp.dim)), np.empty((N, dmp.dim))
    kernels.rollout_linear(x0, g, cfg.K, cfg.D, T, -float(cfg.alpha_s),
                           cfg.phase_tau_ratio * T, m, P, m0, mh, m1, dmp._c, dmp._h,
                           as_buffer(dmp.weights), times, phase, X, V, A)  # fmt: skip
    return rollout_result(times, phase, X, V, A, x0, g, T)
