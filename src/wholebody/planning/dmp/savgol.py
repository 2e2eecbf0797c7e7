"""The Savitzky-Golay filter: a demonstration's smoothed positions, velocities and
accelerations.

Each sample's values are those of the least-squares polynomial of degree ``p`` fitted to the
``w`` samples around it (``w = 2m + 1``, odd), differentiated analytically; the first and
last ``m`` samples use the polynomial of the first and last window (scipy's
``savgol_filter(..., mode="interp")``). With the window's offsets normalised to
``x = (i - m) / m`` in [-1, 1] and ``V[i, j] = x_i^j``, the polynomial's coefficients are
``C y`` with ``C = V^+`` ((p + 1) x w), and its k-th derivative per sample is the k-th
derivative in ``x`` divided by ``m^k``.

Why this filter for the fit (:meth:`~wholebody.planning.dmp.DMP.fit`): it is exact for
polynomial pieces, keeps the bias on smooth data to a fraction of a millimetre and does not
amplify sampling noise the way a repeated ``np.gradient`` does; the acceleration enters the
forcing target scaled by ``tau^2 / K``, so its noise would become position error.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.signal import fftconvolve

__all__ = ["fit_windows", "savitzky_golay"]

DENSE_SAVGOL = 400
"""Up to this many samples the filter is one cached (3n, n) matrix (at most 3.8 MB)."""


@lru_cache(maxsize=32)
def _savgol_fit(window: int, polyorder: int) -> tuple[np.ndarray, np.ndarray]:
    """``x`` (w,), the window's offsets normalised to [-1, 1] (``x = (i - m) / m``,
    ``window = 2m + 1``: ``V[i, j] = x_i^j`` stays well conditioned for wide windows), and
    ``C = V^+`` (p + 1, w), which maps a window's samples to the coefficients of their
    least-squares polynomial of degree ``polyorder`` in ``x``. Read-only, cached."""
    m = window // 2
    x = (np.arange(window, dtype=float) - m) / max(m, 1)
    C = np.linalg.pinv(x[:, None] ** np.arange(polyorder + 1))
    for a in (x, C):
        a.setflags(write=False)
    return x, C


def _savgol_rows(x: np.ndarray, polyorder: int, m: int) -> np.ndarray:
    """(3, len(x), p + 1): the value and the first and second derivatives per sample
    (unit spacing, ``d/di = d/dx / m``) of the polynomial with given coefficients, at ``x``."""
    powers = np.arange(polyorder + 1)
    D = np.empty((3, x.size, polyorder + 1))
    for k in range(3):
        coef = np.array([math.perm(j, k) if j >= k else 0.0 for j in powers]) / max(m, 1) ** k
        D[k] = coef * x[:, None] ** np.maximum(powers - k, 0)
    return D


@lru_cache(maxsize=16)
def _savgol_windows(window: int, polyorder: int) -> np.ndarray:
    """(3, w, w): row ``i`` of ``[k]`` maps a window's samples to the k-th derivative (unit
    spacing) of their least-squares polynomial at the window's sample ``i``. Read-only,
    cached."""
    x, C = _savgol_fit(window, polyorder)
    E = _savgol_rows(x, polyorder, window // 2).dot(C)
    E.setflags(write=False)
    return E


_NO_WINDOWS = np.empty((3, 0, 0))  # kernels.fit: the filtered demonstration is given
_NO_WINDOWS.setflags(write=False)


@lru_cache(maxsize=16)
def _savgol_operator(n: int, window: int, polyorder: int) -> np.ndarray:
    """The Savitzky-Golay filter of an ``n``-sample signal as one (3n, n) matrix (unit
    spacing): rows ``k n .. (k + 1) n`` give the value (k = 0) and the first and second
    derivatives; interior samples use the centre of their own window, the first and last
    ``m`` samples the polynomial fitted to the first and last window (scipy's
    ``mode="interp"``). For ``n <= 400`` only (:data:`DENSE_SAVGOL`)."""
    m = window // 2
    E = _savgol_windows(window, polyorder)  # (3, w, w): sample i of a window, from it
    S = np.zeros((3, n, n))
    for k in range(3):
        for i in range(m, n - m):
            S[k, i, i - m : i + m + 1] = E[k, m]
        S[k, :m, :window] = E[k, :m]
        S[k, n - m :, n - window :] = E[k, m + 1 :]
    S = S.reshape(3 * n, n)
    S.setflags(write=False)
    return S


def savitzky_golay(
    X: np.ndarray, window: int, polyorder: int, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed positions, velocities and accelerations of ``X`` (N, d) sampled every ``h``
    seconds: the Savitzky-Golay filter (local least-squares polynomial of degree
    ``polyorder`` over ``window`` samples, odd, ``<= N``), the first and last ``window // 2``
    samples from the polynomial fitted to the first and last window. It equals scipy's
    ``savgol_filter(..., mode="interp")`` to round-off: up to 400 samples as one cached
    matrix product (no per-call overhead), beyond as FFT convolutions (memory proportional
    to ``N``, not to ``N window``)."""
    N, d = X.shape
    if N <= DENSE_SAVGOL:
        out = _savgol_operator(N, window, polyorder).dot(X).reshape(3, N, d)
    else:
        m = window // 2
        x, C = _savgol_fit(window, polyorder)
        out = np.empty((3, N, d))
        centre = _savgol_rows(x[m : m + 1], polyorder, m)[:, 0].dot(C)  # (3, w)
        for k in range(3):  # sample i: centre[k] . X[i - m : i + m + 1], a correlation
            out[k, m : N - m] = fftconvolve(X, centre[k, ::-1, None], mode="valid", axes=0)
        out[:, :m] = _savgol_rows(x[:m], polyorder, m).dot(C.dot(X[:window]))
        out[:, N - m :] = _savgol_rows(x[m + 1 :], polyorder, m).dot(C.dot(X[N - window :]))
    return out[0], out[1] / h, out[2] / (h * h)


def fit_windows(
    X: np.ndarray, window: int, polyorder: int, h: float, filtered: np.ndarray
) -> np.ndarray:
    """What the compiled fit (:func:`wholebody.kernels.dmp.fit`) needs of the filter for ``X``
    (N, d): up to :data:`DENSE_SAVGOL` samples the (3, w, w) window operators, which it
    applies itself; beyond, ``filtered`` (3, N, d) is filled here by FFT convolutions and an
    empty (3, 0, 0) array is returned."""
    if X.shape[0] <= DENSE_SAVGOL:
        return _savgol_windows(window, polyorder)
    filtered[:] = savitzky_golay(X, window, polyorder, h)
    return _NO_WINDOWS
