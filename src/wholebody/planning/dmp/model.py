"""The learned DMP: the forcing term's weights, fitted from one demonstration.

**Forcing term.** ``f(s) = s sum_i w_i psi_i(s) / sum_i psi_i(s)`` with the Gaussian basis
``psi_i(s) = exp(-h_i (s - c_i)^2)`` of :class:`~wholebody.planning.dmp.DMPConfig`: zero at
the end of the movement (``s -> 0``), so the transformation system converges to the goal
whatever the weights.

**Fitting** from one demonstration ``x(t)`` (N, d): non-uniform times are first resampled
onto a uniform grid by a cubic spline; velocities and accelerations come from a
Savitzky-Golay filter (:mod:`~wholebody.planning.dmp.savgol`: local least-squares
polynomials of degree 5 over a window of about N/8 samples, differentiated analytically).
``x0`` and ``g`` are the filtered end points. The forcing targets ::

    f_target(t) = (tau^2 x'' + D tau x') / K - (g - x) + (g - x0) s(t)

are what makes the transformation system reproduce the demonstration; they are fitted by
ridge-regularised least squares, ``(Phi^T Phi + lambda I) W = Phi^T F`` with ``Phi`` the
(N, n_basis) phase-scaled normalised basis at the samples (one Cholesky solve for all
dimensions).

**Rollout** is :mod:`~wholebody.planning.dmp.linear` without obstacles and
:mod:`~wholebody.planning.dmp.adaptive` with them; :meth:`DMP.stepper` integrates online
(:mod:`~wholebody.planning.dmp.stepper`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import ModuleType

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.linalg.lapack import dposv as _posv

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_array, as_positive, as_vector
from wholebody.planning.dmp import compiled
from wholebody.planning.dmp.adaptive import rollout_obstacles
from wholebody.planning.dmp.config import DMPConfig
from wholebody.planning.dmp.linear import rollout_linear
from wholebody.planning.dmp.rollout import DMPRollout
from wholebody.planning.dmp.savgol import fit_windows, savitzky_golay
from wholebody.planning.dmp.stepper import DMPStepper
from wholebody.planning.obstacles import Potential

__all__ = ["DMP"]


class DMP:
    """A learned DMP: weights of the forcing term plus the demonstration's start, goal and
    duration (the defaults of :meth:`rollout`). See :mod:`wholebody.planning.dmp` for the
    equations.

    Parameters
    ----------
    weights
        ``w`` (n_basis, d).
    start, goal
        Demonstrated ``x0`` and ``g`` (d,), m.
    duration
        Demonstrated ``T``, s.
    config
        Hyper-parameters; ``n_basis`` must match ``weights``.
    """

    def __init__(
        self,
        weights: np.ndarray,
        start: np.ndarray,
        goal: np.ndarray,
        duration: float,
        config: DMPConfig | None = None,
    ) -> None:
        self.config = DMPConfig() if config is None else config
        W = as_array(weights, (self.config.n_basis, None), "DMP: weights")
        self.dim = int(W.shape[1])
        if self.dim < 1:
            raise DimensionError("DMP: weights must have at least one column (dimension)")
        self.weights = W.copy()
        self.start = as_vector(start, self.dim, "DMP: start").copy()
        self.goal = as_vector(goal, self.dim, "DMP: goal").copy()
        self.duration = as_positive(duration, "DMP: duration")
        self._c, self._h = self.config.layout()

    # ------------------------------------------------------------------ basis functions

    def basis(self, s: np.ndarray) -> np.ndarray:
        """Normalised, phase-scaled basis ``s psi_i(s) / sum_j psi_j(s)`` (N, n_basis)."""
        s = np.asarray(s, dtype=float)
        psi = np.subtract(s[:, None], self._c)  # one (N, n_basis) array, worked in place
        psi *= psi
        psi *= -self._h
        psi -= psi.max(axis=1)[:, None]  # the ratio is unchanged; no 0/0 once every psi underflows
        np.exp(psi, out=psi)
        psi *= (s / psi.sum(axis=1))[:, None]
        return psi

    def forcing(self, s: np.ndarray) -> np.ndarray:
        """``f(s)`` (N, d) at phases ``s`` (N,)."""
        return self.basis(s) @ self.weights

    # ------------------------------------------------------------------ fitting

    @classmethod
    def fit(
        cls,
        positions: np.ndarray,
        times: np.ndarray | None = None,
        *,
        dt: float | None = None,
        config: DMPConfig | None = None,
        regularization: float = 1e-10,
        window: int | None = None,
        polyorder: int = 5,
    ) -> DMP:
        """Learn a DMP from one demonstration.

        Parameters
        ----------
        positions
            ``x(t_k)`` (N, d), m; N >= ``polyorder + 2`` and N >= ``config.n_basis``.
        times
            ``t_k`` (N,) s, strictly increasing; or give ``dt`` (s) for uniform sampling.
        config
            Hyper-parameters (default :class:`DMPConfig`).
        regularization
            Ridge weight relative to the mean diagonal of the normal matrix.
        window
            Savitzky-Golay window (odd, samples); default about N/8, at least
            ``polyorder + 2``.
        polyorder
            Savitzky-Golay polynomial degree.

        Returns
        -------
        DMP
            With ``start`` and ``goal`` the filtered first and last positions and
            ``duration = t_N - t_0``.
        """
        cfg = DMPConfig() if config is None else config
        X = as_array(positions, (None, None), "DMP.fit: positions")
        N, d = X.shape
        if d < 1:
            raise DimensionError("DMP.fit: positions must have at least one column")
        polyorder = _check_samples(N, int(polyorder), cfg)
        X, h, T = _uniform(X, times, dt)
        window = _window(window, polyorder, N)
        kernels = compiled.kernels()
        if kernels is not None:
            return cls._fit_compiled(kernels, X, h, T, cfg, window, polyorder, regularization)
        xs, xd, xdd = savitzky_golay(X, window, polyorder, h)
        x0, g = xs[0].copy(), xs[-1].copy()
        K, D = cfg.K, cfg.D
        tau = T
        s = np.exp(np.arange(N) * (-cfg.alpha_s * h / (cfg.phase_tau_ratio * T)))
        target = (tau * tau * xdd + D * tau * xd) / K - (g - xs) + np.outer(s, g - x0)
        dmp = cls(np.zeros((cfg.n_basis, d)), x0, g, T, cfg)
        Phi = dmp.basis(s)
        A = Phi.T.dot(Phi)
        nb = cfg.n_basis
        ridge = _ridge(regularization)
        A.flat[:: nb + 1] += ridge * A.trace() / nb
        rhs = Phi.T.dot(target)
        _, w, info = _posv(A, rhs)  # the ridge makes A positive definite: Cholesky
        dmp.weights = w if info == 0 else np.linalg.solve(A, rhs)
        return dmp

    @classmethod
    def _fit_compiled(
        cls,
        kernels: ModuleType,
        X: np.ndarray,
        h: float,
        T: float,
        cfg: DMPConfig,
        window: int,
        polyorder: int,
        regularization: float,
    ) -> DMP:
        """:meth:`fit` from the uniformly resampled ``X`` (N, d) by
        :func:`wholebody.kernels.dmp.fit`: the Savitzky-Golay filter there too up to 400
        samples, beyond by FFT convolutions here (:func:`~.savgol.fit_windows`)."""
        ridge = _ridge(regularization)
        N, d = X.shape
        nb = cfg.n_basis
        filtered = np.empty((3, N, d))
        E = fit_windows(X, window, polyorder, h, filtered)
        c, hw = cfg.layout()
        A, rhs, W = np.empty((nb, nb)), np.empty((nb, d)), np.empty((nb, d))
        rate_h = -float(cfg.alpha_s) * h / (cfg.phase_tau_ratio * T)
        info = kernels.fit(np.ascontiguousarray(X, dtype=float), E, filtered, float(h), float(T),
                           cfg.K, cfg.D, rate_h, c, hw, ridge, A, rhs, W)  # fmt: skip
        dmp = cls(np.zeros((nb, d)), filtered[0, 0].copy(), filtered[0, -1].copy(), T, cfg)
        dmp.weights = W if info == 0 else np.linalg.solve(A, rhs)
        return dmp

    # ------------------------------------------------------------------ rollout

    def _targets(
        self, start: np.ndarray | None, goal: np.ndarray | None, duration: float | None
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """``x0``, ``g`` (d,) m and ``T`` s: those given, else the demonstration's."""
        x0 = self.start if start is None else as_vector(start, self.dim, "DMP: start")
        g = self.goal if goal is None else as_vector(goal, self.dim, "DMP: goal")
        T = self.duration if duration is None else as_positive(duration, "DMP: duration")
        return x0.astype(float), g.astype(float), T

    def rollout(
        self,
        samples: int = 160,
        *,
        duration: float | None = None,
        start: np.ndarray | None = None,
        goal: np.ndarray | None = None,
        obstacles: Sequence[Potential] = (),
        tolerance: float = 1e-3,
        max_substeps: int = 256,
    ) -> DMPRollout:
        """Integrate the DMP from rest at ``start`` to ``goal`` over ``duration``.

        Parameters
        ----------
        samples
            ``N`` >= 2 samples, at ``t_k = k T / (N - 1)``.
        duration, start, goal
            ``T`` (s), ``x0`` and ``g`` (d,) (m); default the demonstration's.
        obstacles
            Repulsive potentials (3-D DMPs only); their forces add.
        tolerance
            With obstacles: tolerance (m) on the substeps' local error estimate (the embedded
            third-order estimate, on ``x`` and on ``v = tau x'``; conservative: the global
            error is well below it). ``inf`` turns the error control off: fixed-step RK4
            with ``max_substeps`` substeps.
        max_substeps
            With obstacles: most substeps per sample interval.

        Raises
        ------
        IntegrationError
            With obstacles, when an interval's error estimate stays above 10 x ``tolerance``
            with ``max_substeps`` substeps, or the state becomes NaN or inf (the path is not
            resolved there: a step may have crossed a steep obstacle's surface); more
            substeps, or a tighter tolerance, resolve it.
        """
        N = int(samples)
        if samples != N or N < 2:
            raise DimensionError(f"DMP.rollout: samples must be an integer >= 2, got {samples}")
        x0, g, T = self._targets(start, goal, duration)
        obstacles = tuple(obstacles)
        kernels = compiled.kernels()
        if obstacles:
            return rollout_obstacles(self, N, x0, g, T, obstacles, tolerance, max_substeps,
                                     kernels)[0]  # fmt: skip
        return rollout_linear(self, N, x0, g, T, kernels)

    def stepper(
        self,
        *,
        duration: float | None = None,
        start: np.ndarray | None = None,
        goal: np.ndarray | None = None,
        obstacles: Sequence[Potential] = (),
        tolerance: float = 1e-3,
        max_substeps: int = 256,
    ) -> DMPStepper:
        """An online integrator of this DMP (see :class:`DMPStepper`)."""
        return DMPStepper(self, duration=duration, start=start, goal=goal, obstacles=obstacles,
                          tolerance=tolerance, max_substeps=max_substeps)  # fmt: skip


def _check_samples(N: int, polyorder: int, cfg: DMPConfig) -> int:
    """``polyorder``, checked against the demonstration's ``N`` samples: enough for the
    Savitzky-Golay polynomial and for the basis weights."""
    if polyorder < 2:
        raise DimensionError(f"DMP.fit: polyorder must be >= 2, got {polyorder}")
    if polyorder + 2 > N:
        raise DimensionError(
            f"DMP.fit: need at least {polyorder + 2} samples for polyorder {polyorder}, got {N}"
        )
    if cfg.n_basis > N:
        raise DimensionError(
            f"DMP.fit: {N} samples cannot determine {cfg.n_basis} basis weights (the fit "
            "would swing between the samples): resample the demonstration to at least "
            "n_basis samples or use fewer basis functions (DMPConfig(n_basis=...))"
        )
    return polyorder


def _uniform(
    X: np.ndarray, times: np.ndarray | None, dt: float | None
) -> tuple[np.ndarray, float, float]:
    """The demonstration ``X`` (N, d) on a uniform grid, its step ``h`` and duration ``T``
    (s): given ``dt``, or ``times`` (resampled by a cubic spline where they are not
    uniform)."""
    N = X.shape[0]
    if (times is None) == (dt is None):
        raise DimensionError("DMP.fit: give exactly one of times (N,) and dt")
    if times is None:
        h = as_positive(dt, "DMP.fit: dt")
        return X, h, h * (N - 1)
    t = as_vector(times, N, "DMP.fit: times (one per row of positions)")
    steps = t[1:] - t[:-1]
    shortest, longest = float(steps.min()), float(steps.max())
    if not shortest > 0.0:
        raise DimensionError("DMP.fit: times must be strictly increasing")
    T = float(t[-1] - t[0])
    h = T / (N - 1)
    if longest - shortest > 1e-9 * h:  # non-uniform: resample onto a uniform grid
        X = CubicSpline(t - t[0], X, axis=0)(np.linspace(0.0, T, N))
    return X, h, T


def _window(window: int | None, polyorder: int, N: int) -> int:
    """The Savitzky-Golay window (odd, samples): the one given or about ``N / 8``, at least
    ``polyorder + 2``, at most ``N``."""
    if window is None:
        window = max(polyorder + 2, round(N / 8))
    window = int(window) | 1  # odd
    if window > N:
        window = N if N % 2 else N - 1
    if window <= polyorder:
        raise DimensionError(
            f"DMP.fit: window ({window}) must exceed polyorder ({polyorder}) and fit in {N} samples"
        )
    return window


def _ridge(value: float) -> float:
    """The fit's regularisation, a finite number >= 0."""
    ridge = float(value)
    if not (math.isfinite(ridge) and ridge >= 0.0):
        raise DimensionError(f"DMP.fit: regularization must be a finite number >= 0, got {value!r}")
    return ridge
