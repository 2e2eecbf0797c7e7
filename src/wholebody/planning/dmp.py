"""Dynamic Movement Primitives in the goal-shift form of Niu et al. 2024, Section 3.

**Equations** (any dimension ``d``; ``K``, ``D`` scalars, the same for every dimension)::

    tau v' = K (g - x) - D v - K (g - x0) s + K f(s) + phi(x, v)
    tau x' = v
    tau_s s' = -alpha_s s,        s(0) = 1
    f(s)   = s sum_i w_i psi_i(s) / sum_i psi_i(s),     psi_i(s) = exp(-h_i (s - c_i)^2)

``x`` is the position (m), ``v = tau x'`` the DMP's velocity state (m), ``x0`` the start, ``g``
the goal, ``phi`` an optional repulsive term (:mod:`wholebody.planning.obstacles`), ``tau = T``
the movement's duration (s). Defaults: ``K = 1050``, ``D = 2 sqrt(K)`` (critically damped),
``alpha_s = 4``, 50 basis functions with centres evenly spaced in time and widths from the
spacing (neighbours cross at 0.9 of their height, see :class:`DMPConfig`).

**Phase and convergence (decision).** With the phase on ``tau = T`` it ends at
``s(T) = exp(-4) = 0.018``, and a moved goal is missed by about 1.8 % of the shift (the
goal-shift term ``K (g - x0) s`` has not died out: 3.6 mm for a 20 cm shift). Here the
phase runs on its own time constant, chosen so that it reaches ``phase_end`` (default
``1e-4``) at ``t = T``::

    tau_s = alpha_s T / ln(1 / phase_end)          (= 0.434 T with the defaults)

``alpha_s`` keeps its value and the transformation system keeps ``tau = T``, so ``K`` means
what it means in the paper (stiffness per movement duration). The residual goal error is
``phase_end`` times the goal shift plus the lag of the critically damped system at the end,
``2 sqrt(K)^-1 ln(1/phase_end) phase_end`` times the shift: 0.03 mm for a 20 cm shift. The
demonstrated goal is reached as well as the demonstration is reproduced (~0.05 mm).

**Fitting** from one demonstration ``x(t)`` (N, d): velocities and accelerations by a
Savitzky-Golay filter (local least-squares polynomials of degree 5 over a window of about
N/8 samples, differentiated analytically), which is exact for polynomial pieces, keeps the
bias on smooth data to a fraction of a millimetre and does not amplify sampling noise the way
a repeated ``np.gradient`` does (the acceleration enters the target scaled by ``tau^2 / K``,
so its noise would become position error). Non-uniform times are first resampled onto a
uniform grid by a cubic spline. ``x0`` and ``g`` are the filtered end points. The forcing
targets ::

    f_target(t) = (tau^2 x'' + D tau x') / K - (g - x) + (g - x0) s(t)

are fitted by ridge-regularised least squares (one solve for all dimensions).

**Rollout.** ``N`` samples on ``[0, T]``, the phase in closed form, the transformation system
by classical RK4 with step ``h = T / (N - 1)``. Without obstacles the system is linear with a
known input, so RK4 is exactly the recurrence ``z_{n+1} = P z_n + m0 b_n + mh b_{n+1/2} +
m1 b_{n+1}`` with ``z = (x, v)``, ``B = h A / tau``, ``A = [[0, 1], [-K, -D]]``,
``P = I + B + B^2/2 + B^3/6 + B^4/24`` and ``b`` the scaled input; it runs as a second-order
IIR filter over all dimensions at once (``scipy.signal.lfilter``). With obstacles (``d = 3``)
the repulsive force varies over millimetres near an obstacle and a fixed step is not
accurate (10 cm off in the paper's two-cylinder scene at 160 samples), so each sample
interval is split into adaptive RK4 substeps with an embedded error estimate
(:class:`_ObstacleIntegrator`). Velocities ``x' = v / tau`` and accelerations
``x'' = v' / tau`` are those of the model at the samples, not finite differences.

**Online stepping.** :class:`DMPStepper` advances a :class:`DMPState` by any ``dt`` with the
same integrators (the phase advanced exactly, ``s <- s exp(-alpha_s dt / tau_s)``);
stepping with ``dt = T / (N - 1)`` reproduces :meth:`DMP.rollout`.

**Compiled kernels (decision).** :meth:`DMP.fit`, :meth:`DMP.rollout` and
:class:`DMPStepper` run in numba kernels (:mod:`wholebody.kernels.dmp`): the same formulas in
the same order, the same adaptive step control, so the compiled path is the reference's to
rounding (1e-13 m in the paper's two-cylinder scene, the same substep count in every
interval) at a fraction of its cost. Profiled, the reference spends an obstacle rollout in
the Python arithmetic of some 1800 force evaluations, and a fit + rollout a third in the
basis functions (``N x 50`` and ``(2N - 1) x 50`` exponentials and their reductions), a sixth
in matrix products (the dense Savitzky-Golay operator, ``Phi^T Phi``), a sixth in the linear
recurrence (``lfilter``) and the rest in numpy's per-call overhead; the kernels evaluate the
exponentials with a vectorised polynomial, the filter as a banded correlation and the
recurrence as a loop.
The potentials of :mod:`~wholebody.planning.obstacles` are computed in the kernels from
their parameters; a rollout with any other :class:`~wholebody.planning.obstacles.Potential`
(a user's ``point_force``) runs the Python integrator below, as does a step of states that
are not float64 arrays. The code of this module is the reference: inside
:func:`reference_implementation` everything runs it (tests and ``benchmarks/dmp.py``
compare the two). The kernels compile on first use, once per machine (:func:`warmup`).

**Orientation.** :class:`DMPTrajectory` adds a slerp from the start to the goal rotation whose
progress is the minimum-jerk polynomial of the normalised phase time
``xi = ln(s) / ln(phase_end) = t / T``: zero angular velocity and acceleration at both ends,
exactly the goal rotation at ``T``, exact angular velocity ``sigma'(t) R0 Log(R0^T R1)``.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Iterator, Sequence
from contextvars import ContextVar
from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.linalg.lapack import dposv as _posv
from scipy.signal import fftconvolve, lfilter

from wholebody.errors import DimensionError, IntegrationError
from wholebody.planning._checks import as_array, as_pose, as_positive, as_vector
from wholebody.planning.obstacles import PointForce, Potential, kernel_rows, make_point_force
from wholebody.planning.rotations import Slerp
from wholebody.planning.trajectory import Trajectory, TrajectoryArrays, minimum_jerk_scaling

__all__ = [
    "DMP",
    "DMPConfig",
    "DMPRollout",
    "DMPState",
    "DMPStepper",
    "DMPTrajectory",
    "reference_implementation",
    "warmup",
]

# ------------------------------------------------------------------ compiled or reference

_REFERENCE: ContextVar[bool] = ContextVar("wholebody_dmp_reference", default=False)
_KERNELS: ModuleType | None = None
_KERNELS_LOCK = threading.Lock()


@contextlib.contextmanager
def reference_implementation(enabled: bool = True) -> Iterator[None]:
    """Inside the block, :meth:`DMP.fit`, :meth:`DMP.rollout` and the :class:`DMPStepper` s
    constructed there run the Python reference implementation of this module instead of the
    compiled kernels (:mod:`wholebody.kernels.dmp`); ``enabled=False`` asks for the kernels
    again. For tests and benchmarks that compare the two (they give the same paths to
    rounding and take the same substep decisions). The switch is a context variable: it holds
    for the current thread or task only."""
    token = _REFERENCE.set(bool(enabled))
    try:
        yield
    finally:
        _REFERENCE.reset(token)


def _kernels() -> ModuleType | None:
    """The compiled kernels, or None inside :func:`reference_implementation`."""
    if _REFERENCE.get():
        return None
    if _KERNELS is None:
        warmup()
    return _KERNELS


def warmup() -> None:
    """Compile the DMP kernels now (once per machine; a notice on stderr says so while it
    takes long) or load them from numba's cache, by running a small fit, rollouts with and
    without obstacles and both steppers. The first compiled call does it anyway."""
    global _KERNELS
    from wholebody.kernels import DISABLED, compile_notice
    from wholebody.kernels import dmp as kernels

    with _KERNELS_LOCK:
        if _KERNELS is not None:
            return
        _KERNELS = kernels
        if DISABLED:  # NUMBA_DISABLE_JIT=1: nothing to compile
            return
        try:
            with compile_notice("the DMP kernels"), reference_implementation(False):
                _exercise()
        except BaseException:
            _KERNELS = None
            raise


def _exercise() -> None:
    """Every kernel once, with the argument types of real use (see :func:`warmup`)."""
    from wholebody.planning.obstacles import DynamicPotential, StaticPotential, sphere

    t = np.linspace(0.0, 1.0, 12)
    dmp = DMP.fit(np.stack([t, t * t, np.sin(t)], axis=1), t, config=DMPConfig(n_basis=4))
    obstacles = (DynamicPotential(sphere([0.5, 0.3, 0.5], 0.1)),
                 StaticPotential(sphere([2.0, 2.0, 2.0], 0.1)))  # fmt: skip
    dmp.rollout(5)
    dmp.rollout(5, obstacles=obstacles)
    for pots in ((), obstacles):
        stepper = dmp.stepper(obstacles=pots)
        state = stepper.initial_state()
        stepper.step(state, 0.1, out=state)


@dataclass(frozen=True)
class DMPConfig:
    """Hyper-parameters of a DMP.

    Attributes
    ----------
    n_basis
        Number of Gaussian basis functions (>= 2).
    stiffness
        ``K`` (dimensionless, per unit ``tau``), > 0.
    damping
        ``D``; ``None`` means ``2 sqrt(K)`` (critical damping).
    alpha_s
        Phase decay rate, > 0.
    phase_end
        Phase value at the end of the movement, in (0, 1): fixes the phase's time constant
        ``tau_s / T`` (module docstring).
    overlap
        Height, in (0, 1), at which neighbouring basis functions cross. Wide, strongly
        overlapping Gaussians (0.9) let the normalised basis follow the steep start of the
        forcing target (where ``(g - x0) s`` falls fastest) without ripple: with 50 functions
        a 1.6 m demonstration is reproduced to about 0.05 mm, against 1.5 mm when they cross
        at half height.
    """

    n_basis: int = 50
    stiffness: float = 1050.0
    damping: float | None = None
    alpha_s: float = 4.0
    phase_end: float = 1e-4
    overlap: float = 0.9

    def __post_init__(self) -> None:
        if int(self.n_basis) != self.n_basis or self.n_basis < 2:
            raise DimensionError(f"DMPConfig: n_basis must be an integer >= 2, got {self.n_basis}")
        as_positive(self.stiffness, "DMPConfig: stiffness")
        if self.damping is not None:
            as_positive(self.damping, "DMPConfig: damping")
        as_positive(self.alpha_s, "DMPConfig: alpha_s")
        if not 0.0 < float(self.phase_end) < 1.0:
            raise DimensionError(f"DMPConfig: phase_end must be in (0, 1), got {self.phase_end}")
        if not 0.0 < float(self.overlap) < 1.0:
            raise DimensionError(f"DMPConfig: overlap must be in (0, 1), got {self.overlap}")

    @property
    def K(self) -> float:
        """Stiffness ``K``."""
        return float(self.stiffness)

    @property
    def D(self) -> float:
        """Damping ``D`` (``2 sqrt(K)`` unless set)."""
        return 2.0 * math.sqrt(self.K) if self.damping is None else float(self.damping)

    @property
    def phase_tau_ratio(self) -> float:
        """``tau_s / T = alpha_s / ln(1 / phase_end)``: the phase's time constant per unit
        duration."""
        return float(self.alpha_s) / math.log(1.0 / float(self.phase_end))

    def centers(self) -> np.ndarray:
        """Basis centres ``c_i = phase_end^(i / (n - 1))``: evenly spaced in time on [0, T]."""
        return self.layout()[0].copy()

    def widths(self) -> np.ndarray:
        """``h_i = 4 ln(1 / overlap) / (c_i - c_{i+1})^2`` (the last reuses the previous gap):
        neighbouring basis functions cross at height ``overlap``."""
        return self.layout()[1].copy()

    def layout(self) -> tuple[np.ndarray, np.ndarray]:
        """``(centers, widths)``, read-only and shared by every DMP of this configuration."""
        return _basis_layout(int(self.n_basis), float(self.phase_end), float(self.overlap))


@lru_cache(maxsize=32)
def _basis_layout(n: int, phase_end: float, overlap: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres and widths of :class:`DMPConfig` (read-only, cached: every DMP built from one
    configuration shares them)."""
    c = phase_end ** np.linspace(0.0, 1.0, n)
    gap = np.abs(np.diff(c))
    gap = np.append(gap, gap[-1])
    h = 4.0 * math.log(1.0 / overlap) / gap**2
    c.setflags(write=False)
    h.setflags(write=False)
    return c, h


@dataclass(frozen=True)
class DMPRollout:
    """A rolled-out DMP: ``N`` samples on ``[0, duration]``.

    Attributes
    ----------
    times
        (N,) s, from 0 to ``duration``.
    positions, velocities, accelerations
        (N, d) in m, m/s, m/s^2 (``x``, ``x'``, ``x''``).
    phase
        (N,) the phase ``s(t)``.
    start, goal
        (d,) ``x0`` and ``g`` used.
    duration
        ``T``, s.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    phase: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    duration: float


@dataclass(eq=False)
class DMPState:
    """State of an online DMP.

    Attributes
    ----------
    x
        Position (d,), m.
    v
        Velocity ``x'`` (d,), m/s (the paper's ``v`` is ``tau x'``).
    s
        Phase.
    t
        Time since the start, s.
    """

    x: np.ndarray
    v: np.ndarray
    s: float = 1.0
    t: float = 0.0

    def copy(self) -> DMPState:
        """An independent copy."""
        return DMPState(self.x.copy(), self.v.copy(), self.s, self.t)


class DMP:
    """A learned DMP: weights of the forcing term plus the demonstration's start, goal and
    duration (the defaults of :meth:`rollout`). See the module docstring for the maths.

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
        polyorder = int(polyorder)
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
        if (times is None) == (dt is None):
            raise DimensionError("DMP.fit: give exactly one of times (N,) and dt")
        if times is None:
            h = as_positive(dt, "DMP.fit: dt")
            T = h * (N - 1)
        else:
            t = as_vector(times, N, "DMP.fit: times (one per row of positions)")
            steps = t[1:] - t[:-1]
            shortest, longest = float(steps.min()), float(steps.max())
            if not shortest > 0.0:
                raise DimensionError("DMP.fit: times must be strictly increasing")
            T = float(t[-1] - t[0])
            h = T / (N - 1)
            if longest - shortest > 1e-9 * h:  # non-uniform: resample onto a uniform grid
                X = CubicSpline(t - t[0], X, axis=0)(np.linspace(0.0, T, N))
        if window is None:
            window = max(polyorder + 2, round(N / 8))
        window = int(window) | 1  # odd
        if window > N:
            window = N if N % 2 else N - 1
        if window <= polyorder:
            raise DimensionError(
                f"DMP.fit: window ({window}) must exceed polyorder ({polyorder}) and fit in "
                f"{N} samples"
            )
        kernels = _kernels()
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
        """:meth:`fit` from the uniformly resampled ``X`` (N, d) by :func:`kernels.fit`: the
        Savitzky-Golay filter there too up to 400 samples, beyond by FFT convolutions here."""
        ridge = _ridge(regularization)
        N, d = X.shape
        nb = cfg.n_basis
        filtered = np.empty((3, N, d))
        if N <= _DENSE_SAVGOL:
            E = _savgol_windows(window, polyorder)
        else:
            filtered[:] = savitzky_golay(X, window, polyorder, h)
            E = _NO_WINDOWS
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
            third-order estimate, on ``x`` and on ``v = tau x'``; conservative: the default
            gives a global error near 1e-5 m in the paper's two-cylinder scene). ``inf``
            turns the error control off: fixed-step RK4 with ``max_substeps`` substeps.
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
        kernels = _kernels()
        if obstacles:
            return self._rollout_obstacles(N, x0, g, T, obstacles, tolerance, max_substeps,
                                           kernels)[0]  # fmt: skip
        if kernels is not None:
            return self._rollout_linear_compiled(kernels, N, x0, g, T)
        cfg = self.config
        K, D = cfg.K, cfg.D
        tau = T
        h = T / (N - 1)
        # m RK4 steps per sample interval, enough for stability and accuracy however coarse
        # the sampling (m = 1 unless N is small)
        m = _linear_substeps(cfg, h / tau)
        t_half = np.linspace(0.0, T, 2 * m * (N - 1) + 1)  # steps and midpoints
        s_half = np.exp(-cfg.alpha_s * t_half / (cfg.phase_tau_ratio * T))
        b = K * (g - np.outer(s_half, g - x0) + self.forcing(s_half))  # (2m(N-1)+1, d)
        x, v = _rk4_linear(b, x0, K, D, tau, h / m)
        if m > 1:
            x, v = x[::m].copy(), v[::m].copy()
        vdot = (b[:: 2 * m] - K * x - D * v) / tau
        return _result(t_half[:: 2 * m].copy(), s_half[:: 2 * m].copy(), x, v / tau, vdot / tau,
                       x0, g, T)  # fmt: skip

    def _rollout_linear_compiled(
        self, kernels: ModuleType, N: int, x0: np.ndarray, g: np.ndarray, T: float
    ) -> DMPRollout:
        """:meth:`rollout` without obstacles by :func:`kernels.rollout_linear`."""
        cfg = self.config
        h = T / (N - 1)
        m = _linear_substeps(cfg, h / T)
        P, m0, mh, m1 = _rk4_matrices(cfg.K, cfg.D, h / m / T)
        times, phase = np.empty(N), np.empty(N)
        X, V, A = np.empty((N, self.dim)), np.empty((N, self.dim)), np.empty((N, self.dim))
        kernels.rollout_linear(x0, g, cfg.K, cfg.D, T, -float(cfg.alpha_s),
                               cfg.phase_tau_ratio * T, m, P, m0, mh, m1, self._c, self._h,
                               _buffer(self.weights), times, phase, X, V, A)  # fmt: skip
        return _result(times, phase, X, V, A, x0, g, T)

    def _rollout_obstacles(
        self,
        N: int,
        x0: np.ndarray,
        g: np.ndarray,
        T: float,
        obstacles: tuple[Potential, ...],
        tolerance: float,
        max_substeps: int,
        kernels: ModuleType | None,
    ) -> tuple[DMPRollout, np.ndarray, int]:
        """:meth:`rollout` with obstacles, by :func:`kernels.rollout_obstacles` when
        ``kernels`` is given and computes every potential, else by the reference
        :class:`_ObstacleIntegrator`. Also returns the substep count of each sample
        interval (N - 1,) and the number of force evaluations: the step control's
        decisions, which the two implementations share."""
        rows = None if kernels is None else kernel_rows(obstacles)
        force = make_point_force(obstacles) if rows is None else None
        if self.dim != 3:
            raise DimensionError(f"DMP.rollout: obstacles need a 3-D DMP, this one is {self.dim}-D")
        tol, top = _tolerance(tolerance), _max_substeps(max_substeps)
        cfg = self.config
        if force is not None:
            t_half = np.linspace(0.0, T, 2 * (N - 1) + 1)  # steps and midpoints
            s_half = np.exp(-cfg.alpha_s * t_half / (cfg.phase_tau_ratio * T))
            b = cfg.K * (g - np.outer(s_half, g - x0) + self.forcing(s_half))  # (2N - 1, 3)
            integrator = _ObstacleIntegrator(self, x0, g, T, force, tol, top)
            x, v, vdot, counts = integrator.rollout(b, T / (N - 1), s_half[::2])
            return (_result(t_half[::2].copy(), s_half[::2].copy(), x, v / T, vdot / T, x0, g, T),
                    counts, integrator.evaluations)  # fmt: skip
        assert kernels is not None and rows is not None
        model = _obstacle_model(cfg, T)
        state = _substep_state(tol, top)
        times, phase, counts = np.empty(N), np.empty(N), np.zeros(N - 1, dtype=np.int64)
        X, V, A = np.empty((N, 3)), np.empty((N, 3)), np.empty((N, 3))
        status, err, m, n = kernels.rollout_obstacles(
            x0, g, model, -float(cfg.alpha_s), cfg.phase_tau_ratio * T, self._c, self._h,
            _buffer(self.weights), rows, tol, top, state, times, phase, X, V, A, counts
        )  # fmt: skip
        if status != 0:
            raise _failure(kernels, status, err, m, float(phase[n]), float(model[3]), tol)
        return _result(times, phase, X, V, A, x0, g, T), counts, int(state[1])

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


def _ridge(value: float) -> float:
    """The fit's regularisation, a finite number >= 0."""
    ridge = float(value)
    if not (math.isfinite(ridge) and ridge >= 0.0):
        raise DimensionError(f"DMP.fit: regularization must be a finite number >= 0, got {value!r}")
    return ridge


_LINEAR_STEP = 0.25  # largest |lambda| h of a linear RK4 step (stable below 2.78)


def _linear_substeps(cfg: DMPConfig, r: float) -> int:
    """RK4 steps per interval of ``r = h / tau`` for the linear DMP ``z' = A z / tau``:
    ``|lambda_max(A)| h / tau <= 0.25`` (1 for the paper's 160 samples: 0.2)."""
    K, D = cfg.K, cfg.D
    rho = 0.5 * (D + math.sqrt(D * D - 4.0 * K)) if D * D >= 4.0 * K else math.sqrt(K)
    return max(1, math.ceil(rho * r / _LINEAR_STEP - 1e-12))


_ACCEPT_AT_LIMIT = 10.0
"""At ``max_substeps`` an interval whose error estimate is within this factor of the tolerance
is accepted: a force that jumps (``beta = 1``) makes the estimate fall only in proportion to
the substep, while the path stays close (0.25 mm in the paper's scene); beyond, the path is not
resolved (a step that jumped a steep obstacle's shell gave estimates of 1e5 m)."""


def _tolerance(value: float) -> float:
    """A positive tolerance (m); ``inf`` turns the error control off (fixed substeps)."""
    if value == math.inf:
        return math.inf
    return as_positive(value, "DMP: tolerance")


def _max_substeps(value: int) -> int:
    m = int(value)
    if m != value or m < 1:
        raise DimensionError(f"DMP: max_substeps must be an integer >= 1, got {value}")
    return m


def _is_buffer(a: object) -> bool:
    """Whether ``a`` is an array the kernels can write into as it is."""
    return (
        isinstance(a, np.ndarray)
        and a.dtype == np.float64
        and a.flags.c_contiguous
        and a.flags.writeable
    )


def _buffer(a: object) -> np.ndarray:
    """``a`` as a C-ordered float64 array for the kernels (a copy only if it is not)."""
    return np.ascontiguousarray(a, dtype=np.float64)


def _result(
    times: np.ndarray,
    phase: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    x0: np.ndarray,
    g: np.ndarray,
    T: float,
) -> DMPRollout:
    """A :class:`DMPRollout` (``v``, ``a``: the velocities and accelerations x', x'')."""
    return DMPRollout(times=times, positions=x, velocities=v, accelerations=a, phase=phase,
                      start=x0.copy(), goal=g.copy(), duration=T)  # fmt: skip


def _obstacle_model(cfg: DMPConfig, tau: float) -> np.ndarray:
    """``(K, D, tau, rate)`` for the obstacle kernels; ``rate = alpha_s / tau_s`` (1/s)."""
    return np.array([cfg.K, cfg.D, tau, float(cfg.alpha_s) / (cfg.phase_tau_ratio * tau)])


def _substep_state(tol: float, top: int) -> np.ndarray:
    """The obstacle kernels' step-control state (:mod:`wholebody.kernels.dmp`): one substep
    per interval to start with, ``top`` fixed ones without error control (``tol = inf``)."""
    return np.array([top if tol == math.inf else 1, 0, 0], dtype=np.int64)


def _failure(
    kernels: ModuleType, status: int, err: float, m: int, s0: float, rate: float, tol: float
) -> ArithmeticError:
    """The error the reference raises where an obstacle kernel returned ``status``: an
    :class:`IntegrationError` (:func:`_unresolved`) or, for a force that overflows at the
    start, Python's own ``OverflowError``."""
    if status == kernels.OVERFLOW:
        return OverflowError(34, "Numerical result out of range")
    return _unresolved(err, m, s0, rate, tol)


def _unresolved(err: float, m: int, s0: float, rate: float, tol: float) -> IntegrationError:
    """The error of an interval from the phase ``s0`` that ``m`` substeps did not resolve
    (its estimate ``err`` m, inf for a non-finite state); ``rate = alpha_s / tau_s``."""
    t0 = max(0.0, math.log(s0) / -rate) if s0 > 0.0 else math.inf
    what = (f"local error {err:.3g} m, above {_ACCEPT_AT_LIMIT:g} x the tolerance "
            f"{tol:g} m," if err < math.inf else "a non-finite state")  # fmt: skip
    return IntegrationError(
        f"DMP obstacle rollout: {what} with {m} substeps in the interval from "
        f"t = {t0:.4g} s: the path is not resolved there; raise max_substeps (a "
        "force that jumps, beta = 1, needs many), or tighten the tolerance so that "
        "the steps shrink before a steep obstacle is reached"
    )


@lru_cache(maxsize=64)
def _rk4_matrices(K: float, D: float, r: float) -> tuple[np.ndarray, ...]:
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


def _rk4_linear(
    b: np.ndarray, x0: np.ndarray, K: float, D: float, tau: float, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """RK4 without obstacles as a linear recurrence; returns ``x`` and ``v`` (N, d)."""
    N = (b.shape[0] + 1) // 2
    d = b.shape[1]
    P, m0, mh, m1 = _rk4_matrices(K, D, h / tau)
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


class _ObstacleIntegrator:
    """Adaptive RK4 of the 3-D DMP with a repulsive force, in scalar Python floats: the
    reference of the compiled integrator (:mod:`wholebody.kernels.dmp`), which follows it
    decision by decision.

    Without the substeps, 160-sample RK4 misses the converged path by up to 10 cm in the
    paper's two-cylinder scene: the force switches on and grows steeply within a few
    millimetres of the obstacle.

    Each interval ``[t, t + h]`` (a rollout sample interval or an online step) is split into
    ``m`` equal RK4 substeps. The local error of a substep is estimated by the embedded
    third-order FSAL solution ``y* = y + hs (k1/6 + k2/3 + k3/3 + k5/6)``,
    ``k5 = F(t + hs, y+)``: ``|y+ - y*| = hs/6 |k4 - k5|`` (max over the six components, m;
    ``k5`` is the next substep's ``k1``, so the estimate costs nothing). It is O(hs^4), so
    the substep that would just meet ``tol`` is ``hs (tol / err)^(1/4)``: an interval whose
    estimate exceeds ``tol`` is redone with that many substeps over 0.8 (at least one more,
    at most ``max_substeps``), and the next interval starts from the count the last estimate
    asks for (at least half the last one). Against doubling and halving, this takes 16 %
    fewer force evaluations in the paper's two-cylinder scene (1677 against 1993). Far from
    obstacles one substep per interval suffices, so the cost is that of plain RK4; near an
    obstacle, where the force changes over millimetres, the steps shrink. An interval that
    still misses the tolerance with ``max_substeps`` substeps is accepted within 10 x the
    tolerance (:data:`_ACCEPT_AT_LIMIT`) and raises :class:`~wholebody.errors.IntegrationError`
    beyond, or as soon as the state is NaN or inf after ``max_substeps`` tries.

    Scalar floats because with three components numpy's per-call overhead would cost more
    than the arithmetic.
    """

    def __init__(
        self,
        dmp: DMP,
        x0: np.ndarray,
        g: np.ndarray,
        tau: float,
        kernel: PointForce,
        tol: float,
        max_substeps: int,
    ) -> None:
        self.dmp, self.x0, self.g, self.tau = dmp, x0, g, tau
        self.K, self.D = dmp.config.K, dmp.config.D
        self.rate = float(dmp.config.alpha_s) / (dmp.config.phase_tau_ratio * tau)
        self.kernel = kernel
        self.tol, self.max_substeps = tol, max_substeps
        self.m = max_substeps if tol == math.inf else 1  # inf: a fixed count, no control
        self.evaluations = 0
        self.last = 0  # the substeps of the last accepted interval

    def inputs(self, s0: float, h: float, m: int) -> list[list[float]]:
        """``b = K (g - (g - x0) s + f(s))`` at ``t0 + j h / (2m)``, j = 0..2m, from the phase
        ``s0`` at ``t0``."""
        s = s0 * np.exp(-self.rate * h / (2 * m) * np.arange(2 * m + 1))
        return (self.K * (self.g - np.outer(s, self.g - self.x0) + self.dmp.forcing(s))).tolist()

    def deriv(self, b: list[float], y: tuple[float, ...]) -> tuple[float, ...]:
        """``(x', v')`` at state ``y = (x, v)`` (v in DMP units) with input ``b``."""
        x1, x2, x3, v1, v2, v3 = y
        p1, p2, p3 = self.kernel(x1, x2, x3, v1, v2, v3)
        self.evaluations += 1
        K, D, it = self.K, self.D, 1.0 / self.tau
        return (
            v1 * it,
            v2 * it,
            v3 * it,
            (b[0] - K * x1 - D * v1 + p1) * it,
            (b[1] - K * x2 - D * v2 + p2) * it,
            (b[2] - K * x3 - D * v3 + p3) * it,
        )

    def interval(
        self,
        y: tuple[float, ...],
        k: tuple[float, ...],
        s0: float,
        h: float,
        b: list[list[float]] | None = None,
    ) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Integrate ``[t0, t0 + h]`` from ``y`` with ``k = F(t0, y)``; ``b``: the inputs at
        ``t0, t0 + h/2, t0 + h`` if known. Returns the end state and ``F`` there."""
        m, tol, top = self.m, self.tol, self.max_substeps
        while True:
            bb = b if (m == 1 and b is not None) else self.inputs(s0, h, m)
            try:
                y1, k1, err = self._substeps(y, k, h / m, m, bb)
            except OverflowError:  # a force's float power overflowed
                y1 = k1 = y
                err = math.inf
            if not math.isfinite(err + sum(y1)):  # NaN or inf (max() in the estimate drops NaN)
                err = math.inf
            # the estimate is the error of the embedded third-order solution, O(hs^4): the
            # substep that would just meet the tolerance, with a safety factor of 0.8
            scale = (err / tol) ** 0.25 / 0.8 if 0.0 < err < math.inf else 0.0
            if err < math.inf and (err <= tol or (m >= top and err <= _ACCEPT_AT_LIMIT * tol)):
                if tol < math.inf:
                    self.m = min(top, max(1, m // 2, math.ceil(m * scale)))
                self.last = m
                return y1, k1
            if m >= top:
                raise _unresolved(err, m, s0, self.rate, tol)
            m = min(top, 4 * m if err == math.inf else max(m + 1, math.ceil(m * scale)))

    def _substeps(
        self, y: tuple[float, ...], k: tuple[float, ...], hs: float, m: int, b: list[list[float]]
    ) -> tuple[tuple[float, ...], tuple[float, ...], float]:
        """``m`` RK4 substeps of ``hs`` from ``y`` (``k = F(y)``); the derivative is written out
        inline (same formula as :meth:`deriv`) because this loop is the hot path."""
        kern, K, D, it = self.kernel, self.K, self.D, 1.0 / self.tau
        hh, h6 = 0.5 * hs, hs / 6.0
        worst = 0.0
        for j in range(m):
            y1, y2, y3, y4, y5, y6 = y
            a1, a2, a3, a4, a5, a6 = k
            bm, be = b[2 * j + 1], b[2 * j + 2]
            # stage 2
            x1, x2, x3 = y1 + hh * a1, y2 + hh * a2, y3 + hh * a3
            w1, w2, w3 = y4 + hh * a4, y5 + hh * a5, y6 + hh * a6
            p1, p2, p3 = kern(x1, x2, x3, w1, w2, w3)
            c1, c2, c3 = w1 * it, w2 * it, w3 * it
            c4 = (bm[0] - K * x1 - D * w1 + p1) * it
            c5 = (bm[1] - K * x2 - D * w2 + p2) * it
            c6 = (bm[2] - K * x3 - D * w3 + p3) * it
            # stage 3
            x1, x2, x3 = y1 + hh * c1, y2 + hh * c2, y3 + hh * c3
            w1, w2, w3 = y4 + hh * c4, y5 + hh * c5, y6 + hh * c6
            p1, p2, p3 = kern(x1, x2, x3, w1, w2, w3)
            d1, d2, d3 = w1 * it, w2 * it, w3 * it
            d4 = (bm[0] - K * x1 - D * w1 + p1) * it
            d5 = (bm[1] - K * x2 - D * w2 + p2) * it
            d6 = (bm[2] - K * x3 - D * w3 + p3) * it
            # stage 4
            x1, x2, x3 = y1 + hs * d1, y2 + hs * d2, y3 + hs * d3
            w1, w2, w3 = y4 + hs * d4, y5 + hs * d5, y6 + hs * d6
            p1, p2, p3 = kern(x1, x2, x3, w1, w2, w3)
            e1, e2, e3 = w1 * it, w2 * it, w3 * it
            e4 = (be[0] - K * x1 - D * w1 + p1) * it
            e5 = (be[1] - K * x2 - D * w2 + p2) * it
            e6 = (be[2] - K * x3 - D * w3 + p3) * it
            # new state and its derivative (FSAL: the next substep's k1)
            x1 = y1 + h6 * (a1 + 2.0 * (c1 + d1) + e1)
            x2 = y2 + h6 * (a2 + 2.0 * (c2 + d2) + e2)
            x3 = y3 + h6 * (a3 + 2.0 * (c3 + d3) + e3)
            w1 = y4 + h6 * (a4 + 2.0 * (c4 + d4) + e4)
            w2 = y5 + h6 * (a5 + 2.0 * (c5 + d5) + e5)
            w3 = y6 + h6 * (a6 + 2.0 * (c6 + d6) + e6)
            p1, p2, p3 = kern(x1, x2, x3, w1, w2, w3)
            f1, f2, f3 = w1 * it, w2 * it, w3 * it
            f4 = (be[0] - K * x1 - D * w1 + p1) * it
            f5 = (be[1] - K * x2 - D * w2 + p2) * it
            f6 = (be[2] - K * x3 - D * w3 + p3) * it
            y = (x1, x2, x3, w1, w2, w3)
            k = (f1, f2, f3, f4, f5, f6)
            err = h6 * max(abs(e1 - f1), abs(e2 - f2), abs(e3 - f3),
                           abs(e4 - f4), abs(e5 - f5), abs(e6 - f6))  # fmt: skip
            if err > worst:
                worst = err
                if worst > self.tol and m < self.max_substeps:
                    break
        self.evaluations += 4 * m
        return y, k, worst

    def rollout(
        self, b: np.ndarray, h: float, phase: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """All ``N`` samples from rest at ``x0``; ``b`` (2N-1, 3) on the half-step grid.
        Returns ``x``, ``v`` (DMP units), ``v'`` (N, 3) and the substeps of each interval
        (N - 1,)."""
        N = (b.shape[0] + 1) // 2
        bl = b.tolist()
        y = (*self.x0.tolist(), 0.0, 0.0, 0.0)
        k = self.deriv(bl[0], y)
        Y, Kd, counts = [y], [k], []
        for n in range(N - 1):
            y, k = self.interval(y, k, float(phase[n]), h, bl[2 * n : 2 * n + 3])
            Y.append(y)
            Kd.append(k)
            counts.append(self.last)
        Ya, Ka = np.array(Y), np.array(Kd)
        return Ya[:, :3], Ya[:, 3:], Ka[:, 3:], np.array(counts, dtype=np.int64)


class DMPStepper:
    """Online integration of a DMP, one ``dt`` at a time.

    Without obstacles one RK4 step per call (several for a ``dt`` too coarse for one, as in
    :meth:`DMP.rollout`), into preallocated buffers: stepping with ``dt = T / (N - 1)``
    reproduces :meth:`DMP.rollout` to rounding. With obstacles (3-D) each
    call runs the rollout's adaptive substeps over ``[t, t + dt]``.

    Parameters
    ----------
    dmp
        The learned primitive.
    duration, start, goal
        ``T`` (s), ``x0``, ``g`` (d,) (m); default the demonstration's.
    obstacles
        Repulsive potentials (3-D only).
    tolerance, max_substeps
        As in :meth:`DMP.rollout` (obstacles only).

    Notes
    -----
    ``step(state, dt, out=state)`` updates in place and, without obstacles, allocates no
    arrays; without ``out`` it returns a new :class:`DMPState`. The goal may be moved between
    steps with :meth:`set_goal`. A stepper runs compiled unless it is constructed inside
    :func:`reference_implementation` or its obstacles include a potential the kernels do not
    compute; states whose arrays are not float64 take the reference's code (module
    docstring).
    """

    def __init__(
        self,
        dmp: DMP,
        *,
        duration: float | None = None,
        start: np.ndarray | None = None,
        goal: np.ndarray | None = None,
        obstacles: Sequence[Potential] = (),
        tolerance: float = 1e-3,
        max_substeps: int = 256,
    ) -> None:
        self.dmp = dmp
        x0, g, T = dmp._targets(start, goal, duration)
        self.start, self.goal, self.duration = x0.copy(), g.copy(), T
        cfg = dmp.config
        self.K, self.D, self.alpha_s = cfg.K, cfg.D, float(cfg.alpha_s)
        self.tau = T
        self.tau_s = cfg.phase_tau_ratio * T
        obstacles = tuple(obstacles)
        kernel = make_point_force(obstacles)
        self._integrator: _ObstacleIntegrator | None = None
        self._kernels = _kernels()  # None: the reference implementation
        d, nb = dmp.dim, cfg.n_basis
        if kernel is not None:
            if dmp.dim != 3:
                raise DimensionError(
                    f"DMPStepper: obstacles need a 3-D DMP, this one is {dmp.dim}-D"
                )
            self._integrator = _ObstacleIntegrator(dmp, self.start, self.goal, self.tau, kernel,
                                                   _tolerance(tolerance),
                                                   _max_substeps(max_substeps))  # fmt: skip
            self._rows = None if self._kernels is None else kernel_rows(obstacles)
            if self._rows is None:
                self._kernels = None  # a potential the kernels do not compute
            else:
                self._model = _obstacle_model(cfg, T)
                self._state = _substep_state(self._integrator.tol, self._integrator.max_substeps)
        elif self._kernels is not None:
            self._work = np.empty(13 * d + nb)
        self._c, self._negh, self._W = dmp._c, -dmp._h, dmp.weights
        if self._kernels is not None:
            self._W = _buffer(dmp.weights)
        self._S = np.empty((3, 1))  # phases at t, t + dt/2, t + dt
        self._psi = np.empty((3, nb))
        self._den = np.empty(3)
        self._ratio = np.empty(3)
        self._f = np.empty((3, d))
        self._b = np.empty((3, d))  # K g - K (g - x0) s + K f(s) at the three phases
        self._Kgx0 = np.empty(d)
        self._Kg = np.empty(d)
        self.set_goal(g)
        self._x, self._v = np.empty(d), np.empty(d)  # stage inputs (v in DMP units)
        self._kx = np.empty((4, d))
        self._kv = np.empty((4, d))
        self._tmp = np.empty(d)
        self._x0, self._v0 = np.empty(d), np.empty(d)
        self._last_dt = math.nan  # the dt the next three are for
        self._m = 1  # RK4 steps per call without obstacles (see DMP.rollout)
        self._eh = self._e1 = 1.0  # phase decay over half and one of those steps

    def set_goal(self, goal: np.ndarray) -> None:
        """Move the goal ``g`` (d,) m for the following steps."""
        g = as_vector(goal, self.dmp.dim, "DMPStepper: goal")
        self.goal[:] = g  # shared with the obstacle integrator
        np.multiply(self.K, g, out=self._Kg)
        np.subtract(g, self.start, out=self._Kgx0)
        self._Kgx0 *= -self.K

    def initial_state(self) -> DMPState:
        """At rest at the start, ``s = 1``, ``t = 0``."""
        return DMPState(self.start.copy(), np.zeros(self.dmp.dim), 1.0, 0.0)

    def _inputs(self, s: float) -> None:
        """Fill ``_b`` with the input at the phases ``s``, ``s e_h``, ``s e_1``."""
        S = self._S
        S[0, 0], S[1, 0], S[2, 0] = s, s * self._eh, s * self._e1
        psi = self._psi
        np.subtract(S, self._c, out=psi)
        np.square(psi, out=psi)
        np.multiply(psi, self._negh, out=psi)
        np.max(psi, axis=1, out=self._den)  # as DMP.basis: scaled by the largest term
        psi -= self._den[:, None]
        np.exp(psi, out=psi)
        np.sum(psi, axis=1, out=self._den)
        np.divide(S[:, 0], self._den, out=self._ratio)
        np.matmul(psi, self._W, out=self._f)
        self._f *= self._ratio[:, None]
        # b = K g - K (g - x0) s + K f
        np.multiply(S, self._Kgx0, out=self._b)
        self._b += self._Kg
        self._f *= self.K
        self._b += self._f

    def _deriv(self, x: np.ndarray, v: np.ndarray, j: int, stage: int) -> None:
        """``kx = v / tau``, ``kv = (b_j - K x - D v) / tau`` into row ``stage``."""
        it = 1.0 / self.tau
        np.multiply(v, it, out=self._kx[stage])
        kv = self._kv[stage]
        np.multiply(x, -self.K, out=kv)
        kv += self._b[j]
        np.multiply(v, self.D, out=self._tmp)
        kv -= self._tmp
        kv *= it

    def step(self, state: DMPState, dt: float, out: DMPState | None = None) -> DMPState:
        """Advance ``state`` by ``dt`` s (> 0); into ``out`` if given (may be ``state``)."""
        if not dt > 0.0:
            raise DimensionError(f"DMPStepper.step: dt must be > 0 s, got {dt}")
        d = self.dmp.dim
        for what, st in (("state", state), ("out", out)):
            if st is not None and not (np.shape(st.x) == np.shape(st.v) == (d,)):
                raise DimensionError(
                    f"DMPStepper.step: {what} must hold x and v of shape ({d},), got "
                    f"{np.shape(st.x)} and {np.shape(st.v)}"
                )
        if out is None:
            out = DMPState(np.empty(self.dmp.dim), np.empty(self.dmp.dim))
        if dt != self._last_dt:
            self._m = (
                1
                if self._integrator is not None
                else _linear_substeps(self.dmp.config, dt / self.tau)
            )
            self._eh = math.exp(-0.5 * self.alpha_s * dt / self._m / self.tau_s)
            self._e1 = self._eh * self._eh
            self._last_dt = dt
        s, t = state.s, state.t
        if self._kernels is not None and all(map(_is_buffer, (state.x, state.v, out.x, out.v))):
            self._step_compiled(state, dt, out)
        elif self._integrator is not None:
            self._step_obstacles(state, dt, out)
            out.s = s * self._e1
        else:  # m RK4 steps of dt / m
            hs = dt / self._m
            src = state
            for _ in range(self._m):
                s_j = src.s
                self._step_linear(src, hs, out)
                out.s = s_j * self._e1
                src = out
        out.t = t + dt
        return out

    def _step_compiled(self, state: DMPState, dt: float, out: DMPState) -> None:
        """:meth:`step` by :func:`kernels.step_obstacles` or :func:`kernels.step_linear`, for
        states of C-ordered float64 arrays (others take the reference's numpy code, which
        rounds to their type where it stores: slower, the same answers)."""
        kernels = self._kernels
        assert kernels is not None
        s = float(state.s)
        if self._integrator is not None:
            integ = self._integrator
            status, err, m = kernels.step_obstacles(
                state.x, state.v, s, float(dt), self._model, self.goal, self.start, self._c,
                self.dmp._h, self._W, self._rows, integ.tol, integ.max_substeps, self._state,
                out.x, out.v,
            )  # fmt: skip
            if status != 0:
                raise _failure(kernels, status, err, m, s, integ.rate, integ.tol)
            out.s = s * self._e1
        else:
            out.s = kernels.step_linear(state.x, state.v, s, dt / self._m, self._m, self._eh,
                                        self._e1, self.K, self.D, self.tau, self._Kg,
                                        self._Kgx0, self._c, self.dmp._h, self._W, self._work,
                                        out.x, out.v)  # fmt: skip

    def _step_obstacles(self, state: DMPState, dt: float, out: DMPState) -> None:
        integ = self._integrator
        assert integ is not None
        evaluations = integ.evaluations
        if self._kernels is not None:  # a compiled stepper's: share its step control
            integ.m = int(self._state[0])
        b = integ.inputs(state.s, dt, 1)
        y = (*state.x.tolist(), *(state.v * self.tau).tolist())
        y1, _ = integ.interval(y, integ.deriv(b[0], y), state.s, dt, b)
        out.x[:] = y1[:3]
        out.v[:] = y1[3:]
        out.v *= 1.0 / self.tau
        if self._kernels is not None:
            self._state[0], self._state[2] = integ.m, integ.last
            self._state[1] += integ.evaluations - evaluations

    def _step_linear(self, state: DMPState, dt: float, out: DMPState) -> None:
        self._inputs(state.s)
        x0, v0, x, v, kx, kv = self._x0, self._v0, self._x, self._v, self._kx, self._kv
        np.copyto(x0, state.x)
        np.multiply(state.v, self.tau, out=v0)  # DMP units
        self._deriv(x0, v0, 0, 0)
        for stage, (j, c) in enumerate(((1, 0.5 * dt), (1, 0.5 * dt), (2, dt)), start=1):
            np.multiply(kx[stage - 1], c, out=x)
            x += x0
            np.multiply(kv[stage - 1], c, out=v)
            v += v0
            self._deriv(x, v, j, stage)
        # z+ = z + dt/6 (k1 + 2 k2 + 2 k3 + k4)
        for k in (kx, kv):
            k[1] += k[2]
            k[1] *= 2.0
            k[0] += k[1]
            k[0] += k[3]
            k[0] *= dt / 6.0
        np.add(x0, kx[0], out=out.x)
        np.add(v0, kv[0], out=out.v)
        out.v *= 1.0 / self.tau

    def acceleration(self, state: DMPState) -> np.ndarray:
        """``x''`` (d,) m/s^2 of the model at ``state``."""
        s = state.s
        f = self.dmp.forcing(np.array([s]))[0]
        vp = state.v * self.tau
        b = self.K * (self.goal - (self.goal - self.start) * s + f)
        if self._integrator is not None:
            return np.array(self._integrator.deriv(b.tolist(), (*state.x, *vp))[3:]) / self.tau
        return (b - self.K * state.x - self.D * vp) / self.tau**2


class DMPTrajectory(Trajectory):
    """A hand trajectory: a 3-D position DMP plus a slerp of the orientation.

    The position DMP is rolled out densely (``samples``) and sampled in between by quintic
    Hermite interpolation of the rollout's positions, velocities and accelerations (C2, exact
    at the samples). The orientation goes from the start to the goal rotation with the
    minimum-jerk progress of the normalised phase time (module docstring).

    Parameters
    ----------
    dmp
        A 3-D :class:`DMP`.
    start_pose, goal_pose
        4x4 world poses; their positions are the DMP's ``x0`` and ``g``.
    duration
        ``T`` s; default the demonstration's.
    obstacles
        Repulsive potentials for the position DMP.
    samples
        Rollout samples; default one per 10 ms, at least 160.

    Notes
    -----
    ``end_pose`` is the rollout's final position (a small fraction of a millimetre from the
    goal, see the module docstring) with the goal rotation: chain a
    :class:`~wholebody.planning.trajectory.HoldTrajectory` at ``end_pose``, not at the goal.
    """

    def __init__(
        self,
        dmp: DMP,
        start_pose: np.ndarray,
        goal_pose: np.ndarray,
        duration: float | None = None,
        *,
        obstacles: Sequence[Potential] = (),
        samples: int | None = None,
    ) -> None:
        if dmp.dim != 3:
            raise DimensionError(f"DMPTrajectory: needs a 3-D position DMP, got {dmp.dim}-D")
        T0 = as_pose(start_pose, "DMPTrajectory: start_pose")
        T1 = as_pose(goal_pose, "DMPTrajectory: goal_pose")
        T = dmp.duration if duration is None else as_positive(duration, "DMPTrajectory: duration")
        n = max(160, math.ceil(T / 0.01) + 1) if samples is None else int(samples)
        self.rollout = dmp.rollout(n, duration=T, start=T0[:3, 3], goal=T1[:3, 3],
                                   obstacles=obstacles)  # fmt: skip
        self._duration = T
        self._R0, self._R1 = T0[:3, :3].copy(), T1[:3, :3].copy()
        self._slerp = Slerp(self._R0, self._R1)
        # Quintic Hermite coefficients per interval, in u = (t - t_k) / h.
        r = self.rollout
        h = T / (n - 1)
        self._h = h
        p0, p1 = r.positions[:-1], r.positions[1:]
        v0, v1 = h * r.velocities[:-1], h * r.velocities[1:]
        a0, a1 = h * h * r.accelerations[:-1], h * h * r.accelerations[1:]
        dp = p1 - p0
        self._coef = np.stack(
            [
                p0,
                v0,
                0.5 * a0,
                10.0 * dp - 6.0 * v0 - 4.0 * v1 - 1.5 * a0 + 0.5 * a1,
                -15.0 * dp + 8.0 * v0 + 7.0 * v1 + 1.5 * a0 - a1,
                6.0 * dp - 3.0 * v0 - 3.0 * v1 - 0.5 * a0 + 0.5 * a1,
            ],
            axis=1,
        )  # (n-1, 6, 3)
        # (6, 18): [u^j] -> [u^j | d/dt | d2/dt2] of the polynomial's basis, t = t_k + u h
        self._shift = np.zeros((6, 18))
        for j in range(6):
            self._shift[j, j] = 1.0
            if j + 1 < 6:
                self._shift[j, 6 + j + 1] = (j + 1) / h
            if j + 2 < 6:
                self._shift[j, 12 + j + 2] = (j + 2) * (j + 1) / (h * h)

    @property
    def duration(self) -> float:
        return self._duration

    @property
    def start_pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self._R0, self.rollout.positions[0]
        return T

    @property
    def end_pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self._R1, self.rollout.positions[-1]
        return T

    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        h, T = self._h, self._duration
        x = times / h
        k = x.astype(np.intp)  # the interval (times are in [0, T])
        np.minimum(k, self._coef.shape[0] - 1, out=k)
        u = x - k
        # rows [u^j], [j u^(j-1) / h], [j (j-1) u^(j-2) / h^2] in one product with the constant
        # shift-and-scale matrix, then all three against the interval's coefficients
        weights = (u[:, None] ** _POWERS).dot(self._shift).reshape(-1, 3, 6)
        pva = np.matmul(weights, self._coef[k])  # (N, 3, 3): position, velocity, acceleration
        sig, dsig, ddsig = minimum_jerk_scaling(times / T)
        R, axis = self._slerp(sig)
        return TrajectoryArrays(
            times=times,
            positions=pva[:, 0],
            rotations=R,
            linear_velocities=pva[:, 1],
            angular_velocities=(dsig / T)[:, None] * axis,
            linear_accelerations=pva[:, 2],
            angular_accelerations=(ddsig / T**2)[:, None] * axis,
        )


_POWERS = np.arange(6.0)


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


_DENSE_SAVGOL = 400  # up to this many samples, the filter is one cached (3n, n) matrix


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
    ``mode="interp"``). For ``n <= 400`` only (at most 3.8 MB each)."""
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
    if N <= _DENSE_SAVGOL:
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
