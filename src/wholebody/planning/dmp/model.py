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

The fit runs in the kernel :func:`wholebody.kernels.dmp.fit`; where the ridge leaves the
normal matrix numerically indefinite (``regularization=0`` with nearly coincident basis
functions) its Cholesky factorisation fails and the equations are solved by LU
(``np.linalg.solve``) instead.

**Rollout** is the integrator of :mod:`~wholebody.planning.dmp.integrator`;
:meth:`DMP.stepper` integrates online with it (:mod:`~wholebody.planning.dmp.stepper`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_array, as_positive, as_vector
from wholebody.planning.dmp.compiled import arena, as_buffer, for_run, kernels
from wholebody.planning.dmp.config import DMPConfig
from wholebody.planning.dmp.integrator import rollout
from wholebody.planning.dmp.rollout import DMPRollout
from wholebody.planning.dmp.savgol import fit_windows
from wholebody.planning.dmp.stepper import DMPStepper
from wholebody.planning.obstacles import Potential, potential_rows

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
        self._p = arena(self.config, W)  # the kernels' numbers: weights, basis layout
        self.start = as_vector(start, self.dim, "DMP: start").copy()
        self.goal = as_vector(goal, self.dim, "DMP: goal").copy()
        self.duration = as_positive(duration, "DMP: duration")

    @property
    def weights(self) -> np.ndarray:
        """``w`` (n_basis, d): a view of the numbers the kernels read (writing into it
        changes the DMP)."""
        ow = kernels().regions(self.dim, self.config.n_basis)[4]
        return self._p[ow : ow + self.config.n_basis * self.dim].reshape(-1, self.dim)

    @weights.setter
    def weights(self, value: np.ndarray) -> None:
        self.weights[:] = as_array(value, (self.config.n_basis, self.dim), "DMP: weights")

    def _run(self, x0: np.ndarray, g: np.ndarray, T: float, tol: float, span: float) -> np.ndarray:
        """The arena of a run of this DMP (:func:`~.compiled.for_run`)."""
        return for_run(self._p, self.config, x0, g, T, tol, span)

    # ------------------------------------------------------------------ basis functions

    def basis(self, s: np.ndarray) -> np.ndarray:
        """Normalised, phase-scaled basis ``s psi_i(s) / sum_j psi_j(s)`` (N, n_basis) at the
        phases ``s`` (N,), by :func:`wholebody.kernels.dmp.basis` (the integrator's)."""
        S = as_buffer(np.atleast_1d(s))
        out = np.empty((S.shape[0], self.config.n_basis))
        kernels().basis(S, self._p, out)
        return out

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
        ridge = _ridge(regularization)
        nb = cfg.n_basis
        p = for_run(arena(cfg, np.zeros((nb, d))), cfg, np.zeros(d), np.zeros(d), T, 0.0, 0.0)
        Y = np.empty((3, N, d))
        E = fit_windows(X, window, polyorder, h, Y)
        M = np.empty((2 * nb + d, nb))
        k = kernels()
        info = k.fit(as_buffer(X), E, Y, p, M, float(h), ridge)
        if info != 0:  # not positive definite: LU
            ow = k.regions(d, nb)[4]
            p[ow : ow + nb * d] = np.linalg.solve(M[:nb], M[2 * nb :].T).ravel()
        dmp = cls.__new__(cls)  # the fit's arena is the DMP's (DMP.__init__ builds it)
        dmp.config, dmp.dim, dmp._p = cfg, d, p
        dmp.start, dmp.goal, dmp.duration = Y[0, 0].copy(), Y[0, -1].copy(), T
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
            Repulsive potentials (3-D DMPs only): :class:`~wholebody.planning.DynamicPotential`
            or :class:`~wholebody.planning.StaticPotential` of a superquadric (others are
            refused: :mod:`wholebody.planning.obstacles`); their forces add.
        tolerance
            With obstacles: tolerance (m) on the substeps' local error estimate (the embedded
            third-order estimate, on ``x`` and on ``v = tau x'``; conservative: the global
            error is well below it). ``inf`` turns the error control off: fixed-step RK4
            with ``max_substeps`` substeps.
        max_substeps
            With obstacles: most substeps per sample interval.

        Raises
        ------
        DimensionError
            Obstacles that are not such potentials, or obstacles for a DMP that is not 3-D.
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
        obs = potential_rows(obstacles, "DMP.rollout")
        if len(obs) and self.dim != 3:
            raise DimensionError(f"DMP.rollout: obstacles need a 3-D DMP, this one is {self.dim}-D")
        return rollout(self, N, x0, g, T, obs, tolerance, max_substeps)[0]

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
        return DMPStepper(
            self,
            duration=duration,
            start=start,
            goal=goal,
            obstacles=obstacles,
            tolerance=tolerance,
            max_substeps=max_substeps,
        )


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
        from scipy.interpolate import CubicSpline  # (imported when used)

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
