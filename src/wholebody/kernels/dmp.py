"""The DMP in kernels: the fit, the linear rollout, the obstacle rollout and the online steps.

These are the compiled twins of the reference implementation in
:mod:`wholebody.planning.dmp` and :mod:`wholebody.planning.obstacles` (see their docstrings
for the maths): the same formulas, evaluated in the same order, with the same branches and
the same adaptive-RK4 step control, so that a compiled rollout takes the same substep
decisions as the reference and its path agrees to rounding (1e-13 m in the paper's
two-cylinder scene). Where the reference calls numpy's vectorised ``exp`` (the basis
functions), a kernel evaluates its own (:func:`_exp`, within an ulp, vectorised by LLVM where
``math.exp`` would be one libm call per value); where it uses a dense matrix (the
Savitzky-Golay operator) or ``lfilter`` (the linear recurrence), a kernel sums the same terms
in loops: results differ in the last bits, not in kind. Powers, ``sqrt`` and the phases'
``exp`` are the C library's, as Python's.

**Obstacles** are rows of a float array (:func:`obstacle_row`, one per potential): the
superquadric's centre ``c`` (m), rotation ``R`` (row-major), inverse semi-axes ``1/f``
(1/m) and exponents ``n, m``, then the potential's ``lambda`` (or ``A``), ``beta``, ``eta``
and floor ``C_min``, and two flags (``R = I``; ``n = 1``) for the reference's shortcuts. A
potential of another kind has no row: the planner then runs the Python reference.

**States.** The obstacle integrator keeps an int64 array ``state``: ``state[0]`` the substep
count the next interval starts from, ``state[1]`` the force evaluations so far,
``state[2]`` the substep count of the last accepted interval. A kernel that cannot resolve an
interval returns a non-zero status with the error estimate (m, ``inf`` for a non-finite
state) and the substep count; the caller raises
:class:`~wholebody.errors.IntegrationError`.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.lapack import potrf, trtrs

__all__ = [
    "OBSTACLE_ROW",
    "OVERFLOW",
    "UNRESOLVED",
    "fit",
    "obstacle_row",
    "rollout_linear",
    "rollout_obstacles",
    "step_linear",
    "step_obstacles",
]

OBSTACLE_ROW = 24
"""Entries of one obstacle's row (:func:`obstacle_row`)."""

_STATIC = 1.0  # row[0]: 0 the dynamic potential, 1 the static one
_ACCEPT_AT_LIMIT = 10.0  # as wholebody.planning.dmp._ACCEPT_AT_LIMIT
_Q_FLOOR = 1e-150  # as wholebody.planning.obstacles._Q_FLOOR
UNRESOLVED = 1
"""Status of an interval that misses the tolerance at ``max_substeps``."""
OVERFLOW = 2
"""Status of a start whose force overflowed (where the reference raised ``OverflowError``)."""


def obstacle_row(
    static: bool,
    params: tuple[float, ...],
    gain: float,
    beta: float,
    eta: float,
    floor: float,
) -> np.ndarray:
    """One obstacle's row (``OBSTACLE_ROW`` floats) from the superquadric's flat parameters
    ``params`` (``c`` (3), ``R`` row-major (9), ``1/f`` (3), ``n``, ``m``: 17 floats, as
    :meth:`~wholebody.planning.obstacles.Superquadric._params`) and the potential's. Not a
    kernel: the planner calls it."""
    row = np.zeros(OBSTACLE_ROW)
    row[0] = _STATIC if static else 0.0
    row[1:18] = params
    row[18:22] = (gain, beta, eta, floor)
    aligned = all(params[3 + i] == (1.0 if i % 4 == 0 else 0.0) for i in range(9))
    row[22] = 1.0 if aligned else 0.0
    row[23] = 1.0 if params[15] == 1.0 else 0.0
    return row


# --------------------------------------------------------------------------------------
# Basis functions and inputs

_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # ln 2 in two parts (fdlibm): k _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10
_EXP_MIN = -708.0  # exp below is subnormal (< 3.3e-308): taken as 0
_POW2 = np.ldexp(1.0, -np.arange(1023))  # 2^-k, k = 0..1022 (normal numbers)


@kernel
def _exp(x: float) -> float:
    """``exp(x)`` for ``x <= 0`` to 1 ulp, in arithmetic that LLVM vectorises (``math.exp``
    is one libm call per value, four times slower here; numpy's ``exp`` is vectorised).

    ``x = k ln 2 + r`` with ``k = round(x / ln 2)``, ``|r| <= ln(2) / 2`` (Cody-Waite: ``ln 2``
    in two parts, ``k`` times the first exact), ``exp(r)`` by its Taylor polynomial of
    degree 13 (remainder ``|r|^14 / 14! < 4.2e-18`` relative), times ``2^k`` from a table.
    Below ``_EXP_MIN`` (and for NaN) 0: the basis functions' ratio to the largest, the only
    use, is then below 1e-307."""
    xc = x if x > _EXP_MIN else _EXP_MIN
    k = math.floor(xc * _LOG2E + 0.5)
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = 1.6059043836821613e-10  # 1 / 13!
    p = p * r + 2.08767569878681e-09
    p = p * r + 2.505210838544172e-08
    p = p * r + 2.755731922398589e-07
    p = p * r + 2.7557319223985893e-06
    p = p * r + 2.48015873015873e-05
    p = p * r + 0.0001984126984126984
    p = p * r + 0.001388888888888889
    p = p * r + 0.008333333333333333
    p = p * r + 0.041666666666666664
    p = p * r + 0.16666666666666666
    p = p * r + 0.5
    p = p * r + 1.0
    p = p * r + 1.0
    e = p * _POW2[min(max(-k, 0), 1022)]
    return e if x > _EXP_MIN else 0.0


@kernel
def _psi_row(s: float, c: np.ndarray, h: np.ndarray, out: np.ndarray) -> float:
    """``out_i = exp(-h_i (s - c_i)^2 - e_max)`` (each exponent shifted by the largest, as
    ``DMP.basis``: the normalised basis is unchanged and no 0/0 arises once every ``psi``
    underflows); returns ``sum_i out_i`` (>= 1 unless ``s`` is NaN)."""
    nb = c.shape[0]
    top = -math.inf
    for i in range(nb):
        e = s - c[i]
        e = e * e * -h[i]
        out[i] = e
        top = e if e > top else top
    for i in range(nb):  # vectorised: no reduction in this loop
        out[i] = _exp(out[i] - top)
    total = 0.0
    for i in range(nb):
        total += out[i]
    return total


@kernel
def _basis(S: np.ndarray, c: np.ndarray, h: np.ndarray, out: np.ndarray) -> None:
    """``DMP.basis``: ``out[j, i] = s_j psi_i(s_j) / sum_k psi_k(s_j)``,
    ``psi_i = exp(-h_i (s - c_i)^2)``, at the phases ``S`` (J,) into ``out`` (J, nb)."""
    for j in range(S.shape[0]):
        row = out[j]
        s = S[j]
        total = _psi_row(s, c, h, row)
        ratio = s / total if total > 0.0 else math.nan
        for i in range(c.shape[0]):
            row[i] *= ratio


@kernel
def _inputs_at(
    S: np.ndarray,
    K: float,
    g: np.ndarray,
    x0: np.ndarray,
    c: np.ndarray,
    h: np.ndarray,
    W: np.ndarray,
    b: np.ndarray,
) -> None:
    """``b[j] = K (g - (g - x0) s_j + f(s_j))`` (J, d), ``f = basis(s) W``, at the phases
    ``S`` (J,): the transformation system's input without the state."""
    J, d = S.shape[0], g.shape[0]
    Phi = np.empty((J, c.shape[0]))
    _basis(S, c, h, Phi)
    F = np.dot(Phi, W)
    for j in range(J):
        for q in range(d):
            b[j, q] = K * (g[q] - S[j] * (g[q] - x0[q]) + F[j, q])


@kernel
def _half_grid(
    T: float,
    neg_alpha: float,
    tau_s: float,
    K: float,
    g: np.ndarray,
    x0: np.ndarray,
    c: np.ndarray,
    h: np.ndarray,
    W: np.ndarray,
    t: np.ndarray,
    s: np.ndarray,
    b: np.ndarray,
) -> None:
    """Times ``t`` (J,) s evenly on ``[0, T]`` (as ``np.linspace``), the phases
    ``s = exp(-alpha_s t / tau_s)`` there (``neg_alpha = -alpha_s``, ``tau_s`` s) and the
    inputs ``b`` (J, d)."""
    J = t.shape[0]
    step = T / (J - 1) if J > 1 else 0.0
    for j in range(J):
        t[j] = j * step + 0.0 if j < J - 1 else T
        s[j] = math.exp(neg_alpha * t[j] / tau_s)
    _inputs_at(s, K, g, x0, c, h, W, b)


@kernel
def _inputs(
    s0: float,
    dt: float,
    m: int,
    rate: float,
    K: float,
    g: np.ndarray,
    x0: np.ndarray,
    c: np.ndarray,
    h: np.ndarray,
    W: np.ndarray,
) -> np.ndarray:
    """The inputs (2m + 1, d) at ``t0 + j dt / (2m)``, j = 0..2m, from the phase ``s0`` at
    ``t0``: ``s_j = s0 exp(-rate dt / (2m) j)``, ``rate = alpha_s / tau_s`` (1/s)."""
    a = -rate * dt / (2 * m)
    S = np.empty(2 * m + 1)
    for j in range(2 * m + 1):
        S[j] = s0 * math.exp(a * j)
    b = np.empty((2 * m + 1, g.shape[0]))
    _inputs_at(S, K, g, x0, c, h, W, b)
    return b


# --------------------------------------------------------------------------------------
# Fit


@kernel
def _savgol(X: np.ndarray, E: np.ndarray, h: float, out: np.ndarray) -> None:
    """Savitzky-Golay values and first and second derivatives (3, N, d) of ``X`` (N, d)
    sampled every ``h`` s: ``E`` (3, w, w) maps a window's samples to the k-th derivative
    (unit spacing) at each of its samples; interior samples use the centre row of their own
    window (a correlation, summed over the window in order and vectorised over the samples),
    the first and last ``w // 2`` the first and last window (scipy's ``mode="interp"``); then
    ``/ h`` and ``/ h^2``."""
    N, d = X.shape
    w = E.shape[1]
    m = w // 2
    col, acc = np.empty(N), np.empty(N)
    for q in range(d):
        for i in range(N):
            col[i] = X[i, q]
        for k in range(3):
            acc[:] = 0.0
            inner = acc[m : N - m]  # slices: no index arithmetic, so that LLVM vectorises
            for j in range(w):
                e, window = E[k, m, j], col[j : j + N - 2 * m]
                for i in range(N - 2 * m):
                    inner[i] += e * window[i]
            for i in range(m):
                first, last = 0.0, 0.0
                for j in range(w):
                    first += E[k, i, j] * col[j]
                    last += E[k, m + 1 + i, j] * col[N - w + j]
                acc[i], acc[N - m + i] = first, last
            scale = 1.0 if k == 0 else (h if k == 1 else h * h)
            for i in range(N):
                out[k, i, q] = acc[i] / scale if k > 0 else acc[i]


@kernel
def fit(
    X: np.ndarray,
    E: np.ndarray,
    filtered: np.ndarray,
    h: float,
    tau: float,
    K: float,
    D: float,
    rate_h: float,
    c: np.ndarray,
    hw: np.ndarray,
    ridge: float,
    A: np.ndarray,
    rhs: np.ndarray,
    W: np.ndarray,
) -> int:
    """``DMP.fit`` from the uniformly sampled demonstration ``X`` (N, d) m, ``h`` s apart.

    ``filtered`` (3, N, d): the Savitzky-Golay positions, velocities (m/s) and accelerations
    (m/s^2); computed here from ``X`` with ``E`` (:func:`_savgol`) unless ``E`` is empty (then
    given). With ``x0``, ``g`` the first and last filtered positions and the phase
    ``s_k = exp(k rate_h)`` (``rate_h = -alpha_s h / tau_s``), the forcing targets
    ``(tau^2 x'' + D tau x') / K - (g - x) + (g - x0) s`` are fitted by the ridge normal
    equations ``(Phi^T Phi + r I) W = Phi^T target`` (``A`` (nb, nb), ``rhs`` (nb, d),
    ``r = ridge tr(Phi^T Phi) / nb``), solved by Cholesky (LAPACK's, as the reference) into
    ``W`` (nb, d). Returns LAPACK's ``info``: non-zero when ``A`` is not positive definite
    (``A`` and ``rhs`` are then left for a general solve)."""
    if E.shape[1] > 0:
        _savgol(X, E, h, filtered)
    N, d = X.shape
    nb = c.shape[0]
    xs, xd, xdd = filtered[0], filtered[1], filtered[2]
    S = np.empty(N)
    target = np.empty((N, d))
    tt, dtau = tau * tau, D * tau
    for k in range(N):
        S[k] = math.exp(k * rate_h)
        for q in range(d):
            g, x0 = xs[N - 1, q], xs[0, q]
            target[k, q] = (tt * xdd[k, q] + dtau * xd[k, q]) / K - (g - xs[k, q]) + S[k] * (g - x0)
    Phi = np.empty((N, nb))
    _basis(S, c, hw, Phi)
    A[:, :] = np.dot(Phi.T, Phi)
    trace = 0.0
    for i in range(nb):
        trace += A[i, i]
    for i in range(nb):
        A[i, i] += ridge * trace / nb
    rhs[:, :] = np.dot(Phi.T, target)
    U = np.empty((nb, nb)).T  # Fortran order, as LAPACK reads it
    U[:, :] = A
    info = potrf(U, False)  # A = U^T U
    if info == 0:
        col = np.empty(nb)
        for q in range(d):
            col[:] = rhs[:, q]
            trtrs(U, col, False, True)  # U^T y = rhs
            trtrs(U, col, False, False)  # U w = y
            W[:, q] = col
    return info


# --------------------------------------------------------------------------------------
# Linear rollout and online step (no obstacles)


@kernel
def rollout_linear(
    x0: np.ndarray,
    g: np.ndarray,
    K: float,
    D: float,
    tau: float,
    neg_alpha: float,
    tau_s: float,
    m: int,
    P: np.ndarray,
    m0: np.ndarray,
    mh: np.ndarray,
    m1: np.ndarray,
    c: np.ndarray,
    hw: np.ndarray,
    W: np.ndarray,
    times: np.ndarray,
    phase: np.ndarray,
    X: np.ndarray,
    V: np.ndarray,
    A: np.ndarray,
) -> None:
    """``DMP.rollout`` without obstacles: ``N`` samples on ``[0, tau]`` (``X`` (N, d) m,
    ``V`` m/s, ``A`` m/s^2, ``times`` s, ``phase``) from rest at ``x0``, ``m`` RK4 steps per
    sample interval.

    RK4 of the linear system is exactly ``z_{n+1} = P z_n + m0 b_n + mh b_{n+1/2} +
    m1 b_{n+1}`` (``z = (x, tau x')``, per dimension; ``P``, ``m0``, ``mh``, ``m1`` from
    ``_rk4_matrices``), with ``b`` the inputs on the grid of steps and midpoints. The
    accelerations are the model's, ``x'' = (b - K x - D tau x') / tau^2``, at the samples."""
    N, d = X.shape
    J = 2 * m * (N - 1) + 1
    t = np.empty(J)
    s = np.empty(J)
    b = np.empty((J, d))
    _half_grid(tau, neg_alpha, tau_s, K, g, x0, c, hw, W, t, s, b)
    p00, p01, p10, p11 = P[0, 0], P[0, 1], P[1, 0], P[1, 1]
    for q in range(d):
        x, v = x0[q], 0.0
        X[0, q], V[0, q] = x, 0.0
        for n in range(m * (N - 1)):
            b0, bh, b1 = b[2 * n, q], b[2 * n + 1, q], b[2 * n + 2, q]
            cx = m0[0] * b0 + mh[0] * bh + m1[0] * b1
            cv = m0[1] * b0 + mh[1] * bh + m1[1] * b1
            x, v = p00 * x + p01 * v + cx, p10 * x + p11 * v + cv
            if (n + 1) % m == 0:
                X[(n + 1) // m, q], V[(n + 1) // m, q] = x, v
    for k in range(N):
        times[k], phase[k] = t[2 * m * k], s[2 * m * k]
        for q in range(d):
            A[k, q] = (b[2 * m * k, q] - K * X[k, q] - D * V[k, q]) / tau / tau
            V[k, q] = V[k, q] / tau


@kernel
def _stepper_inputs(
    s: float,
    eh: float,
    e1: float,
    K: float,
    Kg: np.ndarray,
    Kgx0: np.ndarray,
    c: np.ndarray,
    hw: np.ndarray,
    W: np.ndarray,
    psi: np.ndarray,
    b: np.ndarray,
) -> None:
    """``b[j d : (j + 1) d] = s_j Kgx0 + Kg + K f(s_j)`` at the phases ``s``, ``s eh``,
    ``s e1`` (``Kgx0 = -K (g - x0)``, ``Kg = K g``): the stepper's inputs, in its order of
    operations (``f = (psi W) s / sum psi``)."""
    d, nb = Kg.shape[0], c.shape[0]
    for j in range(3):
        sj = s if j == 0 else (s * eh if j == 1 else s * e1)
        total = _psi_row(sj, c, hw, psi)
        ratio = sj / total if total > 0.0 else math.nan
        for q in range(d):
            f = 0.0
            for i in range(nb):
                f += psi[i] * W[i, q]
            b[j * d + q] = sj * Kgx0[q] + Kg[q] + f * ratio * K


@kernel
def step_linear(
    x: np.ndarray,
    v: np.ndarray,
    s: float,
    dt: float,
    m: int,
    eh: float,
    e1: float,
    K: float,
    D: float,
    tau: float,
    Kg: np.ndarray,
    Kgx0: np.ndarray,
    c: np.ndarray,
    hw: np.ndarray,
    W: np.ndarray,
    work: np.ndarray,
    x_out: np.ndarray,
    v_out: np.ndarray,
) -> float:
    """``DMPStepper.step`` without obstacles: ``m`` RK4 steps of ``dt`` s from ``x`` (m),
    ``v`` (m/s) at the phase ``s`` into ``x_out``, ``v_out`` (which may be ``x``, ``v``); the
    phase decays by ``eh`` over half a step and by ``e1`` over one. ``work``
    (``13 d + nb``,) is scratch, so that a step allocates nothing. Returns the phase after
    the steps.

    Each step: ``k_i = ((v, b_j - K x - D v) / tau)`` at the RK4 stages (``v = tau x'``),
    ``z+ = z + dt/6 (k1 + 2 (k2 + k3) + k4)``, the state handed on as ``(x, x')``."""
    d, nb = x.shape[0], c.shape[0]
    b = work[: 3 * d]
    kx = work[3 * d : 7 * d]  # row-major (4, d): the stages
    kv = work[7 * d : 11 * d]
    z = work[11 * d : 13 * d]  # stage input (x, tau x')
    psi = work[13 * d : 13 * d + nb]
    it = 1.0 / tau
    for q in range(d):
        x_out[q], v_out[q] = x[q], v[q]
    for _ in range(m):
        _stepper_inputs(s, eh, e1, K, Kg, Kgx0, c, hw, W, psi, b)
        for stage in range(4):
            j = 0 if stage == 0 else (1 if stage < 3 else 2)
            cst = 0.5 * dt if stage < 3 else dt
            for q in range(d):
                x0, v0 = x_out[q], v_out[q] * tau
                z[q] = kx[(stage - 1) * d + q] * cst + x0 if stage > 0 else x0
                z[d + q] = kv[(stage - 1) * d + q] * cst + v0 if stage > 0 else v0
            for q in range(d):
                kx[stage * d + q] = z[d + q] * it
                kv[stage * d + q] = (z[q] * -K + b[j * d + q] - z[d + q] * D) * it
        for q in range(d):
            x0, v0 = x_out[q], v_out[q] * tau
            sx = (kx[q] + (kx[d + q] + kx[2 * d + q]) * 2.0 + kx[3 * d + q]) * (dt / 6.0)
            sv = (kv[q] + (kv[d + q] + kv[2 * d + q]) * 2.0 + kv[3 * d + q]) * (dt / 6.0)
            x_out[q], v_out[q] = x0 + sx, (v0 + sv) * it
        s = s * e1
    return s


# --------------------------------------------------------------------------------------
# Repulsive forces


@kernel
def _overflow(base: float, power: float) -> bool:
    """Whether the reference's ``base ** y`` raised ``OverflowError``: Python raises where
    a finite base's power overflows (an infinite one gives inf quietly), numba gives inf."""
    return power == math.inf and base < math.inf


@kernel
def _rotate(
    p: np.ndarray, a1: float, a2: float, a3: float, inverse: bool
) -> tuple[float, float, float]:
    """``R a`` (the obstacle's axes to world axes) or, if ``inverse``, ``R^T a``; ``R`` is
    row-major in ``p[4:13]``, so ``R^T`` steps by 3 along a row where ``R`` steps by 1."""
    term, comp = (3, 1) if inverse else (1, 3)
    return (
        p[4] * a1 + p[4 + term] * a2 + p[4 + 2 * term] * a3,
        p[4 + comp] * a1 + p[4 + comp + term] * a2 + p[4 + comp + 2 * term] * a3,
        p[4 + 2 * comp] * a1 + p[4 + 2 * comp + term] * a2 + p[4 + 2 * comp + 2 * term] * a3,
    )


@kernel
def _local(p: np.ndarray, x1: float, x2: float, x3: float) -> tuple[float, float, float]:
    """``u = diag(1/f) R^T (x - c)``: the point ``x`` (m) in the obstacle's scaled frame."""
    d1, d2, d3 = _rotate(p, x1 - p[1], x2 - p[2], x3 - p[3], True)
    return d1 * p[13], d2 * p[14], d3 * p[15]


@kernel
def _dynamic_force(
    p: np.ndarray, x1: float, x2: float, x3: float, v1: float, v2: float, v3: float
) -> tuple[float, float, float, bool]:
    """``phi = -grad_x U`` (m) of the dynamic potential of row ``p`` at one point ``x`` (m)
    moving with ``v`` (m, the DMP's ``tau x'``), as ``DynamicPotential.point_force`` (its
    shortcuts for ``R = I`` and ``n = 1`` too); the flag: a power overflowed (where the
    reference raised ``OverflowError``; the force is then NaN)."""
    i1, i2, i3, n, m = p[13], p[14], p[15], p[16], p[17]
    lam, beta, eta, floor = p[18], p[19], p[20], p[21]
    aligned = p[22] != 0.0
    if aligned:
        u1, u2, u3 = (x1 - p[1]) * i1, (x2 - p[2]) * i2, (x3 - p[3]) * i3
        w1, w2, w3 = v1, v2, v3
    else:
        u1, u2, u3 = _local(p, x1, x2, x3)
        w1, w2, w3 = _rotate(p, v1, v2, v3, True)
    a, b, c = u1 * u1, u2 * u2, u3 * u3
    cm1 = c ** (m - 1.0)
    over = _overflow(c, cm1)
    if p[23] != 0.0:  # n = 1: a^(n - 1) = 1
        an1 = bn1 = 1.0
        an, bn = a, b
    else:
        an1, bn1 = a ** (n - 1.0), b ** (n - 1.0)
        an, bn = an1 * a, bn1 * b
        over = over or _overflow(a, an1) or _overflow(b, bn1)
    q = an + bn
    if q < _Q_FLOOR:
        q = _Q_FLOOR
    qm = q ** (m / n)
    if over or _overflow(q, qm):
        return math.nan, math.nan, math.nan, True
    t = 2.0 * m * qm / q
    g1, g2, g3 = t * an1 * u1 * i1, t * bn1 * u2 * i2, 2.0 * m * cm1 * u3 * i3
    wg = w1 * g1 + w2 * g2 + w3 * g3
    gg = g1 * g1 + g2 * g2 + g3 * g3
    ww = w1 * w1 + w2 * w2 + w3 * w3
    if wg >= 0.0 or gg == 0.0 or ww == 0.0:
        return 0.0, 0.0, 0.0, False
    gn, wn = math.sqrt(gg), math.sqrt(ww)
    k = -wg / (wn * gn) if wn * gn > 0.0 else math.inf
    iso = qm + c * cm1 - 1.0
    Cs = iso if iso > floor else floor
    hq = t / q
    hd = 2.0 * (m - n)
    H11 = hq * an1 * (hd * an + (2.0 * n - 1.0) * q) * i1 * i1
    H22 = hq * bn1 * (hd * bn + (2.0 * n - 1.0) * q) * i2 * i2
    H12 = hd * hq * an1 * bn1 * u1 * u2 * i1 * i2
    r = wg / gg
    p1, p2, p3 = w1 - r * g1, w2 - r * g2, w3 - r * g3
    ce, kb = Cs**-eta, k ** (beta - 1.0)
    if _overflow(Cs, ce) or _overflow(k, kb):
        return math.nan, math.nan, math.nan, True
    coef = lam * ce * kb
    sa = coef * beta / gn
    sb = coef * eta * k * wn / Cs if iso > floor else 0.0
    f1 = sa * (H11 * p1 + H12 * p2) + sb * g1
    f2 = sa * (H12 * p1 + H22 * p2) + sb * g2
    f3 = sa * (2.0 * m * (2.0 * m - 1.0) * i3 * i3) * cm1 * p3 + sb * g3
    if aligned:
        return f1, f2, f3, False
    f1, f2, f3 = _rotate(p, f1, f2, f3, False)
    return f1, f2, f3, False


@kernel
def _static_force(
    p: np.ndarray, x1: float, x2: float, x3: float
) -> tuple[float, float, float, bool]:
    """``phi`` (m) of the static potential of row ``p`` at one point ``x`` (m), as
    ``StaticPotential.point_force``; the flag as for :func:`_dynamic_force`."""
    n, m, A, eta, floor = p[16], p[17], p[18], p[20], p[21]
    u1, u2, u3 = _local(p, x1, x2, x3)
    a, b, c = u1 * u1, u2 * u2, u3 * u3
    an1, bn1, cm1 = a ** (n - 1.0), b ** (n - 1.0), c ** (m - 1.0)
    q = an1 * a + bn1 * b
    if q < _Q_FLOOR:
        q = _Q_FLOOR
    qm = q ** (m / n)
    if _overflow(a, an1) or _overflow(b, bn1) or _overflow(c, cm1) or _overflow(q, qm):
        return math.nan, math.nan, math.nan, True
    iso = qm + c * cm1 - 1.0
    if iso <= floor:
        return 0.0, 0.0, 0.0, False
    t = 2.0 * m * qm / q
    iso2 = iso * iso  # > 0 unless C_min < 1e-154 (then 1 / 0: inf, as numpy's)
    s = A * math.exp(-eta * iso) * (eta / iso + (1.0 / iso2 if iso2 > 0.0 else math.inf))
    f1 = s * t * an1 * u1 * p[13]
    f2 = s * t * bn1 * u2 * p[14]
    f3 = s * (2.0 * m) * cm1 * u3 * p[15]
    f1, f2, f3 = _rotate(p, f1, f2, f3, False)
    return f1, f2, f3, False


@kernel
def _force(
    obs: np.ndarray, x1: float, x2: float, x3: float, v1: float, v2: float, v3: float
) -> tuple[float, float, float, bool]:
    """The summed force (m) of every obstacle row of ``obs`` (n, ``OBSTACLE_ROW``), in
    order, at ``x`` moving with ``v``; the flag: a power overflowed (the reference stopped
    there with ``OverflowError``)."""
    f1 = f2 = f3 = 0.0
    for j in range(obs.shape[0]):
        p = obs[j]
        if p[0] == _STATIC:
            a1, a2, a3, over = _static_force(p, x1, x2, x3)
        else:
            a1, a2, a3, over = _dynamic_force(p, x1, x2, x3, v1, v2, v3)
        if over:
            return a1, a2, a3, True
        if j == 0:
            f1, f2, f3 = a1, a2, a3
        else:
            f1, f2, f3 = f1 + a1, f2 + a2, f3 + a3
    return f1, f2, f3, False


# --------------------------------------------------------------------------------------
# Adaptive RK4 with obstacles (3-D)


@kernel
def _first_max(a: float, b: float, c: float, d: float, e: float, f: float) -> float:
    """Python's ``max(a, b, c, d, e, f)``: the first of the largest, a NaN kept only in
    first place (a later one never compares greater), as the reference's error estimate."""
    top = a
    for x in (b, c, d, e, f):
        if x > top:
            top = x
    return top


@kernel
def _slope(
    obs: np.ndarray,
    x1: float,
    x2: float,
    x3: float,
    w1: float,
    w2: float,
    w3: float,
    b: np.ndarray,
    K: float,
    D: float,
    it: float,
) -> tuple[float, float, float, float, float, float, bool]:
    """``F(y) = (v, b - K x - D v + phi(x, v)) / tau`` at ``y = (x, v)`` (m; ``v`` the DMP's
    ``tau x'``, ``it = 1 / tau``) with the input ``b`` (3,), and whether a force's power
    overflowed."""
    p1, p2, p3, over = _force(obs, x1, x2, x3, w1, w2, w3)
    return (
        w1 * it,
        w2 * it,
        w3 * it,
        (b[0] - K * x1 - D * w1 + p1) * it,
        (b[1] - K * x2 - D * w2 + p2) * it,
        (b[2] - K * x3 - D * w3 + p3) * it,
        over,
    )


@kernel
def _deriv(
    b: np.ndarray,
    y: np.ndarray,
    obs: np.ndarray,
    K: float,
    D: float,
    tau: float,
    k: np.ndarray,
) -> bool:
    """``k = F(y)`` (:func:`_slope`) for the state array ``y`` (6,); returns whether a force
    overflowed."""
    k[0], k[1], k[2], k[3], k[4], k[5], over = _slope(obs, y[0], y[1], y[2], y[3], y[4], y[5],
                                                      b, K, D, 1.0 / tau)  # fmt: skip
    return over


@kernel
def _substeps(
    y: np.ndarray,
    k: np.ndarray,
    hs: float,
    m: int,
    b: np.ndarray,
    row: int,
    obs: np.ndarray,
    K: float,
    D: float,
    tau: float,
    tol: float,
    top: int,
    y_out: np.ndarray,
    k_out: np.ndarray,
) -> tuple[float, bool]:
    """``m`` RK4 substeps of ``hs`` s from ``y`` (``k = F(y)``) into ``y_out``, ``k_out``,
    the inputs at the substeps' starts, midpoints and ends in ``b[row : row + 2m + 1]``.
    Returns the largest local error estimate ``hs/6 max|k4 - k5|`` (m; ``k5 = F(y+)``, the
    FSAL third-order solution's), stopping early once it exceeds ``tol`` with substeps to
    spare (the interval will be redone), and whether a force overflowed (then at once, with
    an infinite estimate: the reference's ``OverflowError``). Scalar code, as the
    reference's hot loop, with the same arithmetic."""
    it = 1.0 / tau
    hh, h6 = 0.5 * hs, hs / 6.0
    y1, y2, y3, y4, y5, y6 = y[0], y[1], y[2], y[3], y[4], y[5]
    a1, a2, a3, a4, a5, a6 = k[0], k[1], k[2], k[3], k[4], k[5]
    worst = 0.0
    for j in range(m):
        bm, be = b[row + 2 * j + 1], b[row + 2 * j + 2]
        c1, c2, c3, c4, c5, c6, over = _slope(obs, y1 + hh * a1, y2 + hh * a2, y3 + hh * a3,
                                              y4 + hh * a4, y5 + hh * a5, y6 + hh * a6, bm, K,
                                              D, it)  # fmt: skip
        if over:
            return math.inf, True
        d1, d2, d3, d4, d5, d6, over = _slope(obs, y1 + hh * c1, y2 + hh * c2, y3 + hh * c3,
                                              y4 + hh * c4, y5 + hh * c5, y6 + hh * c6, bm, K,
                                              D, it)  # fmt: skip
        if over:
            return math.inf, True
        e1, e2, e3, e4, e5, e6, over = _slope(obs, y1 + hs * d1, y2 + hs * d2, y3 + hs * d3,
                                              y4 + hs * d4, y5 + hs * d5, y6 + hs * d6, be, K,
                                              D, it)  # fmt: skip
        if over:
            return math.inf, True
        # the new state and its derivative (FSAL: the next substep's k1)
        y1 = y1 + h6 * (a1 + 2.0 * (c1 + d1) + e1)
        y2 = y2 + h6 * (a2 + 2.0 * (c2 + d2) + e2)
        y3 = y3 + h6 * (a3 + 2.0 * (c3 + d3) + e3)
        y4 = y4 + h6 * (a4 + 2.0 * (c4 + d4) + e4)
        y5 = y5 + h6 * (a5 + 2.0 * (c5 + d5) + e5)
        y6 = y6 + h6 * (a6 + 2.0 * (c6 + d6) + e6)
        a1, a2, a3, a4, a5, a6, over = _slope(obs, y1, y2, y3, y4, y5, y6, be, K, D, it)
        if over:
            return math.inf, True
        err = h6 * _first_max(abs(e1 - a1), abs(e2 - a2), abs(e3 - a3),
                              abs(e4 - a4), abs(e5 - a5), abs(e6 - a6))  # fmt: skip
        if err > worst:
            worst = err
            if worst > tol and m < top:
                break
    y_out[0], y_out[1], y_out[2], y_out[3], y_out[4], y_out[5] = y1, y2, y3, y4, y5, y6
    k_out[0], k_out[1], k_out[2], k_out[3], k_out[4], k_out[5] = a1, a2, a3, a4, a5, a6
    return worst, False


@kernel
def _substep_count(m: int, scale: float, top: int, floor: int) -> int:
    """``min(top, max(floor, ceil(m scale)))``: the substeps that would just meet the
    tolerance (``scale = (err / tol)^(1/4) / 0.8``), clamped before the conversion to an
    integer (``m scale`` may exceed any integer)."""
    want = m * scale
    if not want < top:
        return top
    return min(top, max(floor, math.ceil(want)))


@kernel
def _interval(
    y: np.ndarray,
    k: np.ndarray,
    s0: float,
    dt: float,
    b: np.ndarray,
    row: int,
    model: np.ndarray,
    g: np.ndarray,
    x0: np.ndarray,
    c: np.ndarray,
    hw: np.ndarray,
    W: np.ndarray,
    obs: np.ndarray,
    tol: float,
    top: int,
    state: np.ndarray,
    y_out: np.ndarray,
    k_out: np.ndarray,
) -> tuple[int, float, int]:
    """Integrate ``[t0, t0 + dt]`` from ``y`` with ``k = F(t0, y)`` into ``y_out``, ``k_out``
    (``_ObstacleIntegrator.interval``): ``m`` equal substeps, ``m = state[0]`` first; an
    interval whose estimate exceeds ``tol`` (m) is redone with ``ceil(m (err/tol)^(1/4) /
    0.8)`` substeps (at least one more; four times as many after a non-finite state), up to
    ``top``; the next interval starts from the count the accepted estimate asks for (at least
    half). ``b[row : row + 3]`` are the inputs at ``t0``, ``t0 + dt/2``, ``t0 + dt`` (one
    substep); for more they are computed from the phase ``s0``. ``model`` = (K, D, tau,
    rate): the DMP's constants, ``rate = alpha_s / tau_s`` (1/s). Returns (status, estimate,
    substeps): status 0 accepted, ``UNRESOLVED`` not resolved at ``top`` substeps."""
    K, D, tau, rate = model[0], model[1], model[2], model[3]
    m = int(state[0])
    while True:
        if m == 1:
            err, over = _substeps(y, k, dt / m, m, b, row, obs, K, D, tau, tol, top, y_out,
                                  k_out)  # fmt: skip
        else:
            bm = _inputs(s0, dt, m, rate, K, g, x0, c, hw, W)
            err, over = _substeps(y, k, dt / m, m, bm, 0, obs, K, D, tau, tol, top, y_out,
                                  k_out)  # fmt: skip
        total = 0.0
        if over:  # the reference's OverflowError: no evaluations counted, the state kept
            y_out[:] = y
            k_out[:] = k
        else:
            state[1] += 4 * m
            for i in range(6):
                total += y_out[i]
        if not math.isfinite(err + total):  # NaN or inf (the estimate's max drops NaN)
            err = math.inf
        scale = (err / tol) ** 0.25 / 0.8 if 0.0 < err < math.inf else 0.0
        if err < math.inf and (err <= tol or (m >= top and err <= _ACCEPT_AT_LIMIT * tol)):
            if tol < math.inf:
                state[0] = _substep_count(m, scale, top, max(1, m // 2))
            state[2] = m
            return 0, err, m
        if m >= top:
            return UNRESOLVED, err, m
        m = min(top, 4 * m) if err == math.inf else _substep_count(m, scale, top, m + 1)


@kernel
def rollout_obstacles(
    x0: np.ndarray,
    g: np.ndarray,
    model: np.ndarray,
    neg_alpha: float,
    tau_s: float,
    c: np.ndarray,
    hw: np.ndarray,
    W: np.ndarray,
    obs: np.ndarray,
    tol: float,
    top: int,
    state: np.ndarray,
    times: np.ndarray,
    phase: np.ndarray,
    X: np.ndarray,
    V: np.ndarray,
    A: np.ndarray,
    counts: np.ndarray,
) -> tuple[int, float, int, int]:
    """``DMP.rollout`` with obstacles (3-D): ``N`` samples on ``[0, tau]`` from rest at
    ``x0`` (``X`` m, ``V`` m/s, ``A`` m/s^2, ``times`` s, ``phase``), each sample interval
    by :func:`_interval` (its substep count into ``counts`` (N - 1,)); ``model`` = (K, D,
    tau, rate) as there, ``state`` as in the module docstring. Returns (status, estimate,
    substeps, interval): status 0 when every interval was resolved, else that of the
    interval that was not (the samples after it are not written)."""
    N = X.shape[0]
    tau = model[2]
    dt = tau / (N - 1)
    t = np.empty(2 * N - 1)
    s = np.empty(2 * N - 1)
    b = np.empty((2 * N - 1, 3))
    _half_grid(tau, neg_alpha, tau_s, model[0], g, x0, c, hw, W, t, s, b)
    for n in range(N):
        times[n], phase[n] = t[2 * n], s[2 * n]
    y, k = np.zeros(6), np.empty(6)
    y1, k1 = np.empty(6), np.empty(6)
    y[:3] = x0
    if _deriv(b[0], y, obs, model[0], model[1], tau, k):
        return OVERFLOW, math.inf, 0, 0
    state[1] += 1
    for n in range(N):
        if n > 0:
            status, err, m = _interval(y, k, phase[n - 1], dt, b, 2 * n - 2, model, g, x0, c,
                                       hw, W, obs, tol, top, state, y1, k1)  # fmt: skip
            if status != 0:
                return status, err, m, n - 1
            counts[n - 1] = m
            y[:] = y1
            k[:] = k1
        for i in range(3):
            X[n, i], V[n, i], A[n, i] = y[i], y[3 + i] / tau, k[3 + i] / tau
    return 0, 0.0, 0, N - 1


@kernel
def step_obstacles(
    x: np.ndarray,
    v: np.ndarray,
    s: float,
    dt: float,
    model: np.ndarray,
    g: np.ndarray,
    x0: np.ndarray,
    c: np.ndarray,
    hw: np.ndarray,
    W: np.ndarray,
    obs: np.ndarray,
    tol: float,
    top: int,
    state: np.ndarray,
    x_out: np.ndarray,
    v_out: np.ndarray,
) -> tuple[int, float, int]:
    """``DMPStepper.step`` with obstacles: ``[t, t + dt]`` from ``x`` (m), ``v`` (m/s) at
    the phase ``s`` by :func:`_interval` into ``x_out``, ``v_out`` (untouched when the
    interval is not resolved); ``model``, ``state`` and the result as there."""
    tau = model[2]
    b = _inputs(s, dt, 1, model[3], model[0], g, x0, c, hw, W)
    y, k = np.empty(6), np.empty(6)
    y1, k1 = np.empty(6), np.empty(6)
    for i in range(3):
        y[i], y[3 + i] = x[i], v[i] * tau
    if _deriv(b[0], y, obs, model[0], model[1], tau, k):
        return OVERFLOW, math.inf, 0
    state[1] += 1
    status, err, m = _interval(y, k, s, dt, b, 0, model, g, x0, c, hw, W, obs, tol, top, state,
                               y1, k1)  # fmt: skip
    if status == 0:
        for i in range(3):
            x_out[i], v_out[i] = y1[i], y1[3 + i] * (1.0 / tau)
    return status, err, m
