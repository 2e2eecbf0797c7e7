"""The Savitzky-Golay filter: a demonstration's smoothed positions, velocities and
accelerations.

Each sample's values are those of the least-squares polynomial of degree ``p`` fitted to the
``w`` samples around it (``w = 2m + 1``, odd), differentiated analytically; the first and
last ``m`` samples use the polynomial of the first and last window (scipy's
``savgol_filter(..., mode="interp")``). With the window's offsets normalised to
``x = (i - m) / m`` in [-1, 1] and ``V[i, j] = x_i^j``, the polynomial's coefficients are
``C y`` with ``C = V^+`` ((p + 1) x w), and its k-th derivative per sample is the k-th
derivative in ``x`` divided by ``m^k``. Up to :data:`LONG` samples the kernel
:func:`wholebody.kernels.dmp.savgol` applies these window operators; beyond, FFT
convolutions here (:func:`fit_windows`).

Why this filter for the fit (:meth:`~wholebody.planning.dmp.DMP.fit`): it is exact for
polynomial pieces, keeps the bias on smooth data to a fraction of a millimetre and does not
amplify sampling noise the way a repeated ``np.gradient`` does; the acceleration enters the
forcing target scaled by ``tau^2 / K``, so its noise would become position error.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

__all__ = ["fit_windows", "savitzky_golay"]

LONG = 400
"""Beyond this many samples the filter runs as FFT convolutions (the window, about N/8
samples, grows with N: a direct correlation would cost O(N^2))."""


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


def savitzky_golay(
    X: np.ndarray, window: int, polyorder: int, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed positions, velocities and accelerations of ``X`` (N, d) sampled every ``h``
    seconds: the Savitzky-Golay filter (local least-squares polynomial of degree
    ``polyorder`` over ``window`` samples, odd, ``<= N``), the first and last ``window // 2``
    samples from the polynomial fitted to the first and last window. It equals scipy's
    ``savgol_filter(..., mode="interp")`` to round-off; it is what :meth:`DMP.fit
    <wholebody.planning.dmp.DMP.fit>` differentiates the demonstration with."""
    N, d = X.shape
    out = np.empty((3, N, d))
    E = fit_windows(X, window, polyorder, h, out)
    if E.shape[1] > 0:
        from wholebody.planning.dmp.compiled import as_buffer, kernels

        kernels().savgol(as_buffer(X), E, float(h), out)
    return out[0], out[1], out[2]


def fit_windows(
    X: np.ndarray, window: int, polyorder: int, h: float, filtered: np.ndarray
) -> np.ndarray:
    """What the fit's filter (:func:`wholebody.kernels.dmp.savgol`) needs for ``X`` (N, d):
    up to :data:`LONG` samples the (3, w, w) window operators, which it applies itself as a
    correlation over the window; beyond, ``filtered`` (3, N, d) is filled here by FFT
    convolutions (their cost does not grow with the window) and an empty (3, 0, 0) array is
    returned."""
    N = X.shape[0]
    if N <= LONG:
        return _savgol_windows(window, polyorder)
    m = window // 2
    x, C = _savgol_fit(window, polyorder)
    centre = _savgol_rows(x[m : m + 1], polyorder, m)[:, 0].dot(C)  # (3, w)
    for k in range(3):  # sample i: centre[k] . X[i - m : i + m + 1], a correlation
        from scipy.signal import fftconvolve  # (imported when used: 0.4 s)

        filtered[k, m : N - m] = fftconvolve(X, centre[k, ::-1, None], mode="valid", axes=0)
    filtered[:, :m] = _savgol_rows(x[:m], polyorder, m).dot(C.dot(X[:window]))
    filtered[:, N - m :] = _savgol_rows(x[m + 1 :], polyorder, m).dot(C.dot(X[N - window :]))
    filtered[1] /= h
    filtered[2] /= h * h
    return _NO_WINDOWS
