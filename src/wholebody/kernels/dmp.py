"""The DMP in kernels: the basis functions, the fit and the integrator (rollouts and online
steps, with and without obstacles). The maths are in :mod:`wholebody.planning.dmp` (the
equations), :mod:`~wholebody.planning.dmp.model` (the fit) and
:mod:`~wholebody.planning.dmp.integrator` (the integrator); this is their one
implementation, which the Python side lays out and calls.

**The arena.** A DMP's numbers travel as one float64 array ``p`` (numba's call overhead
grows with every array argument): a header of ``HEADER`` scalars, then the regions of
:func:`regions`::

    H_DIM, H_NB        d, the number of basis functions nb (integers, stored as floats)
    H_K, H_D           stiffness K, damping D
    H_TAU, H_RATE      tau = T (s); the phase's rate alpha_s / tau_s (1/s)
    H_TOL              local error tolerance (m); inf: fixed substeps, no error control
    H_SPAN             the time a run covers (s): the rollout's T, an online step's dt
    H_ERR              out: the error estimate (m) of an interval that was not resolved
    g, x0              goal and start (d,) m
    c, h               basis centres and widths (nb,)
    W                  weights (nb, d), row-major
    work               scratch: WORK d + nb floats

**The control array** ``ctl`` (int64): ``C_NEXT`` the substeps the next interval starts
with, ``C_TOP`` the most per interval, ``C_EVALS`` the derivative evaluations so far,
``C_LAST`` the substeps of the last interval (accepted, or the one that failed),
``C_FAILED`` the failed interval, then the substeps of each interval of a rollout.

**Samples** are evenly spaced in time: ``clock`` (2, N) their times (s) and phases, ``Y``
(3, N, d) their positions ``x`` (m), velocities ``x'`` (m/s) and accelerations ``x''``
(m/s^2). The first is the start (time, phase, position, velocity); :func:`integrate` fills
in its acceleration and the samples after it.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel, potentials
from wholebody.kernels.lapack import potrf, trtrs

__all__ = [
    "ACCEPT_AT_LIMIT",
    "HEADER",
    "UNRESOLVED",
    "basis",
    "fit",
    "integrate",
    "regions",
    "savgol",
]

H_DIM, H_NB, H_K, H_D, H_TAU, H_RATE, H_TOL, H_SPAN, H_ERR = range(9)
HEADER = 9
"""Scalars before the arena's regions (module docstring)."""
WORK = 18
"""Scratch floats per dimension: the state ``(x, v)`` and its slope, both again at the
interval's start, a stage's state and four stages' slopes."""
C_NEXT, C_TOP, C_EVALS, C_LAST, C_FAILED = range(5)
CONTROL = 5
"""Entries of ``ctl`` before the substep counts of a rollout's intervals."""
UNRESOLVED = 1
""":func:`integrate`'s status for an interval that misses the tolerance at ``ctl[C_TOP]``
substeps or whose state is not finite."""
ACCEPT_AT_LIMIT = 10.0
"""At the most substeps an interval whose estimate is within this factor of the tolerance
is accepted (:mod:`~wholebody.planning.dmp.integrator`)."""


@kernel
def regions(d: int, nb: int) -> tuple[int, int, int, int, int, int]:
    """Offsets in the arena of ``g``, ``x0``, ``c``, ``h``, ``W`` and the scratch; the arena
    holds ``scratch + WORK d + nb`` floats."""
    og = HEADER
    oc = og + 2 * d
    return og, og + d, oc, oc + nb, oc + 2 * nb, oc + 2 * nb + nb * d


# --------------------------------------------------------------------------------------
# Basis functions

_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # ln 2 in two parts (fdlibm): k _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10
_EXP_MIN = -708.0  # exp below is subnormal (< 3.3e-308): taken as 0
_POW2 = np.ldexp(1.0, -np.arange(1023))  # 2^-k, k = 0..1022 (normal numbers)


@kernel
def _exp(x: float) -> float:
    """``exp(x)`` for ``x <= 0`` to 1 ulp, in arithmetic that LLVM vectorises (``math.exp``
    is one libm call per value, four times slower here).

    ``x = k ln 2 + r`` with ``k = round(x / ln 2)``, ``|r| <= ln(2) / 2`` (Cody-Waite: ``ln 2``
    in two parts, ``k`` times the first exact), ``exp(r)`` by its Taylor polynomial of
    degree 13 (remainder ``|r|^14 / 14! < 4.2e-18`` relative), times ``2^k`` from a table.
    Below ``_EXP_MIN`` (and for NaN) 0: the basis functions' ratio to the largest, the only
    use, is then below 1e-307."""
    xc = x if x > _EXP_MIN else _EXP_MIN
    k = math.floor(xc * _LOG2E + 0.5)
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    e = 1.6059043836821613e-10  # 1 / 13!
    e = e * r + 2.08767569878681e-09
    e = e * r + 2.505210838544172e-08
    e = e * r + 2.755731922398589e-07
    e = e * r + 2.7557319223985893e-06
    e = e * r + 2.48015873015873e-05
    e = e * r + 0.0001984126984126984
    e = e * r + 0.001388888888888889
    e = e * r + 0.008333333333333333
    e = e * r + 0.041666666666666664
    e = e * r + 0.16666666666666666
    e = e * r + 0.5
    e = e * r + 1.0
    e = e * r + 1.0
    e = e * _POW2[min(max(-k, 0), 1022)]
    return e if x > _EXP_MIN else 0.0


@kernel
def _psi(p: np.ndarray, s: float, psi: np.ndarray) -> float:
    """The normalised, phase-scaled basis at the phase ``s`` into ``psi`` (nb,):
    ``s psi_i(s) / sum_k psi_k(s)``, ``psi_i = exp(-h_i (s - c_i)^2)``, with ``c``, ``h``
    from the arena ``p``. The exponents are shifted by the largest (the ratio is unchanged,
    and no 0/0 arises once every ``psi`` underflows); returns ``s / sum`` (NaN for a NaN
    ``s``)."""
    nb = psi.shape[0]
    oc = regions(int(p[H_DIM]), nb)[2]
    c, h = p[oc : oc + nb], p[oc + nb : oc + 2 * nb]
    top = -math.inf
    for i in range(nb):
        e = s - c[i]
        e = e * e * -h[i]
        psi[i] = e
        top = e if e > top else top
    for i in range(nb):  # vectorised: no reduction in this loop
        psi[i] = _exp(psi[i] - top)
    total = 0.0
    for i in range(nb):
        total += psi[i]
    ratio = s / total if total > 0.0 else math.nan
    for i in range(nb):
        psi[i] *= ratio
    return ratio


@kernel
def basis(S: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
    """``DMP.basis``: the normalised, phase-scaled basis (:func:`_psi`) at the phases ``S``
    (J,) into ``out`` (J, nb), from the arena ``p``."""
    for j in range(S.shape[0]):
        _psi(p, S[j], out[j])


@kernel
def _inputs(p: np.ndarray, s0: float, step: float, B: np.ndarray) -> None:
    """The transformation system's input ``b = K (g - (g - x0) s + f(s))`` (m),
    ``f = W^T psi(s)``, at the phases ``s_j = s0 exp(-rate step j)`` (``step`` s), into the
    columns of ``B`` (d, J). The basis of all the phases is one matrix, multiplied by ``W``
    in one product (BLAS: a sum per phase and dimension would be a chain of dependent
    additions)."""
    d, nb, J = B.shape[0], int(p[H_NB]), B.shape[1]
    og, ox0, _, _, ow, _ = regions(d, nb)
    Phi, S = np.empty((J, nb)), np.empty(J)
    for j in range(J):
        S[j] = s0 * math.exp(-p[H_RATE] * step * j)
        _psi(p, S[j], Phi[j])
    F = np.dot(Phi, p[ow : ow + nb * d].reshape((nb, d)))
    K = p[H_K]
    for q in range(d):
        g, x0 = p[og + q], p[ox0 + q]
        for j in range(J):
            B[q, j] = K * (g - S[j] * (g - x0) + F[j, q])


# --------------------------------------------------------------------------------------
# Fit


@kernel
def savgol(X: np.ndarray, E: np.ndarray, h: float, out: np.ndarray) -> None:
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
                out[k, i, q] = acc[i] / scale


@kernel
def fit(
    X: np.ndarray,
    E: np.ndarray,
    Y: np.ndarray,
    p: np.ndarray,
    M: np.ndarray,
    h: float,
    ridge: float,
) -> int:
    """``DMP.fit`` from the uniformly sampled demonstration ``X`` (N, d) m, ``h`` s apart,
    into the weights of the arena ``p``.

    ``Y`` (3, N, d): the Savitzky-Golay positions, velocities (m/s) and accelerations
    (m/s^2), computed here from ``X`` with ``E`` (:func:`savgol`) unless ``E`` is empty (then
    given). With ``x0``, ``g`` the first and last filtered positions and the phase
    ``s_k = exp(-rate h k)``, the forcing targets
    ``(tau^2 x'' + D tau x') / K - (g - x) + (g - x0) s`` are fitted by the ridge normal
    equations ``(Phi^T Phi + r I) W = Phi^T target``, ``r = ridge tr(Phi^T Phi) / nb`` (the
    products by BLAS, as in :func:`_inputs`), solved by LAPACK's Cholesky. ``M``
    (2 nb + d, nb) is scratch: the normal matrix in its first ``nb`` rows, its factor in the
    next ``nb``, the right-hand sides (one row per dimension) last. Returns LAPACK's
    ``info``: non-zero when the matrix is not positive definite (the caller then solves
    ``M[:nb] W = M[2 nb:].T`` otherwise)."""
    if E.shape[1] > 0:
        savgol(X, E, h, Y)
    N, d, nb = X.shape[0], X.shape[1], M.shape[1]
    tau, K, D = p[H_TAU], p[H_K], p[H_D]
    Phi, PhiT, target = np.empty((N, nb)), np.empty((nb, N)), np.empty((N, d))
    for k in range(N):
        s = math.exp(-p[H_RATE] * h * k)
        _psi(p, s, Phi[k])
        for i in range(nb):
            PhiT[i, k] = Phi[k, i]
        for q in range(d):
            g, x0 = Y[0, N - 1, q], Y[0, 0, q]
            f = (tau * tau * Y[2, k, q] + D * tau * Y[1, k, q]) / K - (g - Y[0, k, q])
            target[k, q] = f + s * (g - x0)
    A, rhs = np.dot(PhiT, Phi), np.dot(PhiT, target)
    trace = 0.0
    for i in range(nb):
        trace += A[i, i]
    for i in range(nb):
        A[i, i] += ridge * trace / nb
        for j in range(nb):
            M[i, j] = M[nb + i, j] = A[i, j]
        for q in range(d):
            M[2 * nb + q, i] = rhs[i, q]
    ow, osc = regions(d, nb)[4:]
    psi = p[osc : osc + nb]
    U = M[nb : 2 * nb].T  # Fortran order, as LAPACK reads it (the matrix is symmetric)
    info = potrf(U, False)  # A = U^T U
    if info == 0:
        for q in range(d):
            for i in range(nb):
                psi[i] = M[2 * nb + q, i]
            trtrs(U, psi, False, True)  # U^T y = rhs
            trtrs(U, psi, False, False)  # U w = y
            for i in range(nb):
                p[ow + i * d + q] = psi[i]
    return info


# --------------------------------------------------------------------------------------
# The integrator


@kernel
def _substeps(
    p: np.ndarray,
    obs: np.ndarray,
    ctl: np.ndarray,
    B: np.ndarray,
    col: int,
    dt: float,
    m: int,
    stop: bool,
) -> float:
    """``m`` RK4 substeps of ``hs = dt / m`` s from the scratch's state ``y = (x, v)`` (2d,),
    ``v`` the DMP's ``tau x'`` (m), with ``k = F(y)``; ``y`` and ``k`` are updated in place
    (FSAL: ``F`` at a substep's end is the next one's first slope), the evaluations of ``F``
    counted in ``ctl``. The inputs at the substeps' start, middles and ends are the columns
    ``col .. col + 2m`` of ``B`` (d, ...; :func:`_inputs`). ``m = 0``: only ``k = F(y)``.

    ``F(y) = (v, b - K x - D v + phi(x, v)) / tau``, ``phi`` the force of the potentials
    ``obs`` (3-D only). Returns the largest local error estimate ``hs/6 max|k4 - k5|`` (m),
    stopping at the first substep above the tolerance if ``stop`` (the interval will be
    redone), or inf if the state or its slope is not finite."""
    d, nb = int(p[H_DIM]), int(p[H_NB])
    n2 = 2 * d
    oy = regions(d, nb)[5] + nb  # y, k, (the interval's start), z, four stages' slopes
    ok, oz, os = oy + n2, oy + 4 * n2, oy + 5 * n2
    K, D, it = p[H_K], p[H_D], 1.0 / p[H_TAU]
    hs = dt / m if m > 0 else 0.0
    hh, h6 = 0.5 * hs, hs / 6.0
    worst = 0.0
    for j in range(max(m, 1)):
        for st in range(0 if m > 0 else 3, 4):  # stages 2, 3, 4, then F at the new state
            if st < 3:
                c, src = hs if st == 2 else hh, ok if st == 0 else os + (st - 1) * n2
                for i in range(n2):
                    p[oz + i] = p[oy + i] + c * p[src + i]
            else:
                if m > 0:
                    for i in range(n2):
                        a = p[ok + i] + 2.0 * (p[os + i] + p[os + n2 + i]) + p[os + 2 * n2 + i]
                        p[oy + i] += h6 * a
                for i in range(n2):
                    p[oz + i], p[os + 3 * n2 + i] = p[oy + i], p[os + 2 * n2 + i]
            dst = ok if st == 3 else os + st * n2
            e = col if m == 0 else (col + 2 * j + 1 if st < 2 else col + 2 * j + 2)
            for q in range(d):
                x, v = p[oz + q], p[oz + d + q]
                p[dst + q], p[dst + d + q] = v * it, (B[q, e] - K * x - D * v) * it
            if obs.shape[0] > 0:
                f = potentials.force(
                    obs, p[oz], p[oz + 1], p[oz + 2], p[oz + 3], p[oz + 4], p[oz + 5]
                )
                for q in range(3):
                    p[dst + d + q] += f[q] * it
        ctl[C_EVALS] += 4 if m > 0 else 1
        err = 0.0
        for i in range(n2):
            a = abs(p[os + 3 * n2 + i] - p[ok + i])
            err = a if a > err else err
        err *= h6
        if err > worst:
            worst = err
            if stop and worst > p[H_TOL]:
                break
    total = worst
    for i in range(n2):
        total += p[oy + i] + p[ok + i]
    return worst if math.isfinite(total) else math.inf


@kernel
def _count(m: int, scale: float, low: int, top: int) -> int:
    """``min(top, max(low, ceil(m scale)))``, clamped before the conversion to an integer
    (``m scale`` may exceed any integer)."""
    want = m * scale
    return top if not want < top else min(top, max(low, math.ceil(want)))


@kernel
def _linear(p: np.ndarray, B: np.ndarray, m: int, clock: np.ndarray, Y: np.ndarray) -> None:
    """Without obstacles: ``m`` classical RK4 substeps per sample interval, one dimension at
    a time (the system is linear and decoupled), the inputs at the substeps' starts, middles
    and ends in ``B`` (d, 2 m (N - 1) + 1); samples as in :func:`integrate`."""
    N, d = Y.shape[1], Y.shape[2]
    K, D, tau = p[H_K], p[H_D], p[H_TAU]
    dt = p[H_SPAN] / (N - 1) if N > 1 else 0.0
    hs = dt / m
    it, hh, h6 = 1.0 / tau, 0.5 * hs, hs / 6.0
    for n in range(1, N):  # the dimensions inner: independent chains the CPU overlaps
        for q in range(d):
            x, v, row = Y[0, n - 1, q], Y[1, n - 1, q] * tau, B[q]
            for j in range(2 * m * (n - 1), 2 * m * n, 2):  # a substep from input j
                b0, bh, b1 = row[j], row[j + 1], row[j + 2]
                ax, av = v * it, (b0 - K * x - D * v) * it
                x2, v2 = x + hh * ax, v + hh * av
                bx, bv = v2 * it, (bh - K * x2 - D * v2) * it
                x3, v3 = x + hh * bx, v + hh * bv
                cx, cv = v3 * it, (bh - K * x3 - D * v3) * it
                x4, v4 = x + hs * cx, v + hs * cv
                dx, dv = v4 * it, (b1 - K * x4 - D * v4) * it
                x, v = x + h6 * (ax + 2.0 * (bx + cx) + dx), v + h6 * (av + 2.0 * (bv + cv) + dv)
            Y[0, n, q], Y[1, n, q] = x, v * it
    for q in range(d):
        for n in range(N):
            Y[2, n, q] = (B[q, 2 * m * n] - K * Y[0, n, q] - D * tau * Y[1, n, q]) * it * it
    for n in range(1, N):
        clock[0, n] = clock[0, 0] + p[H_SPAN] if n == N - 1 else clock[0, 0] + n * dt
        clock[1, n] = clock[1, 0] * math.exp(-p[H_RATE] * (clock[0, n] - clock[0, 0]))


@kernel
def integrate(
    p: np.ndarray, obs: np.ndarray, ctl: np.ndarray, clock: np.ndarray, Y: np.ndarray
) -> int:
    """Integrate the DMP of the arena ``p`` with the potentials ``obs`` (n, ``ROW``; 3-D
    only) over ``p[H_SPAN]`` s from its start, the first sample, into the samples after it,
    evenly spaced in time: ``clock`` (2, N) their times (s) and phases, ``Y`` (3, N, d) their
    positions (m), velocities (m/s) and accelerations (m/s^2); with one sample, only the
    acceleration at the start.

    Without obstacles every interval is ``ctl[C_TOP]`` RK4 substeps (:func:`_linear`). With
    obstacles an interval is ``m`` substeps (:func:`_substeps`), ``m = ctl[C_NEXT]`` first;
    an interval whose estimate exceeds the tolerance is redone with
    ``ceil(m (err / tol)^(1/4) / 0.8)`` substeps (at least one more; four times as many
    after a non-finite state), up to ``ctl[C_TOP]``, where it is accepted within
    ``ACCEPT_AT_LIMIT`` times the tolerance; the next interval starts from the count the
    accepted estimate asks for (at least half). The inputs on the grid of samples and
    midpoints are computed once; an interval of several substeps computes its own. Returns
    0, or ``UNRESOLVED`` with the estimate in ``p[H_ERR]`` and the interval in ``ctl`` (its
    samples and those after it are not written)."""
    N, d = Y.shape[1], Y.shape[2]
    dt = p[H_SPAN] / (N - 1) if N > 1 else 0.0
    top = ctl[C_TOP]
    linear = obs.shape[0] == 0
    grid = np.empty((d, 2 * (top if linear else 1) * (N - 1) + 1))
    _inputs(p, clock[1, 0], 0.5 * dt / (top if linear else 1), grid)
    if linear:
        _linear(p, grid, top, clock, Y)
        ctl[C_EVALS] += 4 * top * (N - 1) + 1
        return 0
    n2 = 2 * d
    o = regions(d, int(p[H_NB]))[5] + int(p[H_NB])
    y, k, y0, k0 = (
        p[o : o + n2],
        p[o + n2 : o + 2 * n2],
        p[o + 2 * n2 : o + 3 * n2],
        p[o + 3 * n2 : o + 4 * n2],
    )
    tau, tol = p[H_TAU], p[H_TOL]
    for q in range(d):
        y[q], y[d + q] = Y[0, 0, q], Y[1, 0, q] * tau
    for n in range(N):
        m = 0 if n == 0 else ctl[C_NEXT]
        for i in range(n2):
            y0[i], k0[i] = y[i], k[i]
        while True:
            B, col = grid, max(0, 2 * n - 2)
            if m > 1:
                B, col = np.empty((d, 2 * m + 1)), 0
                _inputs(p, clock[1, n - 1], 0.5 * dt / m, B)
            err = _substeps(p, obs, ctl, B, col, dt, m, 0 < m < top)
            scale = (err / tol) ** 0.25 / 0.8 if 0.0 < err < math.inf and tol < math.inf else 0.0
            if n == 0 or (
                err < math.inf and (err <= tol or (m >= top and err <= ACCEPT_AT_LIMIT * tol))
            ):
                if n > 0 and tol < math.inf:
                    ctl[C_NEXT] = _count(m, scale, max(1, m // 2), top)
                break
            if m >= top:
                ctl[C_LAST], ctl[C_FAILED], p[H_ERR] = m, n - 1, err
                return UNRESOLVED
            m = min(top, 4 * m) if err == math.inf else _count(m, scale, m + 1, top)
            for i in range(n2):
                y[i], k[i] = y0[i], k0[i]
        if n > 0:
            ctl[C_LAST] = m
            if CONTROL + n - 1 < ctl.shape[0]:
                ctl[CONTROL + n - 1] = m
            clock[0, n] = clock[0, 0] + p[H_SPAN] if n == N - 1 else clock[0, 0] + n * dt
            clock[1, n] = clock[1, 0] * math.exp(-p[H_RATE] * (clock[0, n] - clock[0, 0]))
        for q in range(d):
            Y[0, n, q], Y[1, n, q], Y[2, n, q] = y[q], y[d + q] / tau, k[d + q] / tau
    return 0
