"""The rollout with obstacles: adaptive RK4 substeps with an embedded error estimate.

With a repulsive term ``phi(x, v)`` (:mod:`wholebody.planning.obstacles`) the 3-D system ::

    tau x' = v,    tau v' = b(t) - K x - D v + phi(x, v),    b = K (g - (g - x0) s + f(s))

is no longer linear, and near an obstacle the force switches on and grows steeply within a
few millimetres: one RK4 step per sample interval misses the converged path by centimetres.
So each interval ``[t, t + h]`` (a rollout's sample interval or an online step) is split into
``m`` equal RK4 substeps of ``hs = h / m``.

**Error estimate.** The embedded third-order FSAL solution
``y* = y + hs (k1/6 + k2/3 + k3/3 + k5/6)``, ``k5 = F(t + hs, y+)``, differs from the RK4
solution ``y+`` by ``|y+ - y*| = hs/6 |k4 - k5|`` (max over the six components of
``y = (x, v)``, m). ``k5`` is the next substep's ``k1``, so the estimate costs nothing.

**Step control.** The estimate is O(hs^4), so the substep that would just meet the tolerance
is ``hs (tol / err)^(1/4)``: an interval whose estimate exceeds ``tol`` is redone with that
many substeps over 0.8 (at least one more, at most ``max_substeps``), and the next interval
starts from the count the last estimate asks for (at least half the last one). Far from
obstacles one substep per interval suffices, so the cost is that of plain RK4; near an
obstacle the steps shrink. An interval that still misses the tolerance with
``max_substeps`` substeps is accepted within :data:`ACCEPT_AT_LIMIT` times the tolerance and
raises :class:`~wholebody.errors.IntegrationError` beyond, or as soon as the state is NaN or
inf after ``max_substeps`` tries.

The compiled integrator (:func:`wholebody.kernels.dmp.rollout_obstacles`) follows
:class:`ObstacleIntegrator` decision by decision.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from wholebody.errors import DimensionError, IntegrationError
from wholebody.planning._checks import as_positive
from wholebody.planning.dmp.compiled import as_buffer
from wholebody.planning.dmp.config import DMPConfig
from wholebody.planning.dmp.rollout import DMPRollout, rollout_result
from wholebody.planning.obstacles import PointForce, Potential, kernel_rows, make_point_force

if TYPE_CHECKING:
    from wholebody.planning.dmp.model import DMP

__all__ = [
    "ACCEPT_AT_LIMIT",
    "ObstacleIntegrator",
    "check_max_substeps",
    "check_tolerance",
    "failure",
    "obstacle_model",
    "rollout_obstacles",
    "substep_state",
]

ACCEPT_AT_LIMIT = 10.0
"""At ``max_substeps`` an interval whose error estimate is within this factor of the tolerance
is accepted: a force that jumps (``beta = 1``) makes the estimate fall only in proportion to
the substep while the path stays close; beyond, the path is not resolved (a step that jumped
a steep obstacle's shell gives estimates of metres)."""


def check_tolerance(value: float) -> float:
    """A positive tolerance (m); ``inf`` turns the error control off (fixed substeps)."""
    if value == math.inf:
        return math.inf
    return as_positive(value, "DMP: tolerance")


def check_max_substeps(value: int) -> int:
    """The most substeps per interval, an integer >= 1."""
    m = int(value)
    if m != value or m < 1:
        raise DimensionError(f"DMP: max_substeps must be an integer >= 1, got {value}")
    return m


def obstacle_model(cfg: DMPConfig, tau: float) -> np.ndarray:
    """``(K, D, tau, rate)`` for the obstacle kernels; ``rate = alpha_s / tau_s`` (1/s)."""
    return np.array([cfg.K, cfg.D, tau, float(cfg.alpha_s) / (cfg.phase_tau_ratio * tau)])


def substep_state(tol: float, top: int) -> np.ndarray:
    """The obstacle kernels' step-control state (:mod:`wholebody.kernels.dmp`): one substep
    per interval to start with, ``top`` fixed ones without error control (``tol = inf``)."""
    return np.array([top if tol == math.inf else 1, 0, 0], dtype=np.int64)


def failure(
    kernels: ModuleType, status: int, err: float, m: int, s0: float, rate: float, tol: float
) -> ArithmeticError:
    """The error the reference raises where an obstacle kernel returned ``status``: an
    :class:`IntegrationError` (:func:`unresolved`) or, for a force that overflows at the
    start, Python's own ``OverflowError``."""
    if status == kernels.OVERFLOW:
        return OverflowError(34, "Numerical result out of range")
    return unresolved(err, m, s0, rate, tol)


def unresolved(err: float, m: int, s0: float, rate: float, tol: float) -> IntegrationError:
    """The error of an interval from the phase ``s0`` that ``m`` substeps did not resolve
    (its estimate ``err`` m, inf for a non-finite state); ``rate = alpha_s / tau_s``."""
    t0 = max(0.0, math.log(s0) / -rate) if s0 > 0.0 else math.inf
    what = (f"local error {err:.3g} m, above {ACCEPT_AT_LIMIT:g} x the tolerance "
            f"{tol:g} m," if err < math.inf else "a non-finite state")  # fmt: skip
    return IntegrationError(
        f"DMP obstacle rollout: {what} with {m} substeps in the interval from "
        f"t = {t0:.4g} s: the path is not resolved there; raise max_substeps (a "
        "force that jumps, beta = 1, needs many), or tighten the tolerance so that "
        "the steps shrink before a steep obstacle is reached"
    )


class ObstacleIntegrator:
    """Adaptive RK4 of the 3-D DMP with a repulsive force (module docstring), in scalar
    Python floats: the reference of the compiled integrator (:mod:`wholebody.kernels.dmp`).

    Scalar floats because with three components numpy's per-call overhead would cost more
    than the arithmetic.

    Attributes
    ----------
    m
        The substep count the next interval starts from.
    last
        The substeps of the last accepted interval.
    evaluations
        Force evaluations so far.
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
            if err < math.inf and (err <= tol or (m >= top and err <= ACCEPT_AT_LIMIT * tol)):
                if tol < math.inf:
                    self.m = min(top, max(1, m // 2, math.ceil(m * scale)))
                self.last = m
                return y1, k1
            if m >= top:
                raise unresolved(err, m, s0, self.rate, tol)
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


def rollout_obstacles(
    dmp: DMP,
    N: int,
    x0: np.ndarray,
    g: np.ndarray,
    T: float,
    obstacles: Sequence[Potential],
    tolerance: float,
    max_substeps: int,
    kernels: ModuleType | None,
) -> tuple[DMPRollout, np.ndarray, int]:
    """:meth:`DMP.rollout <wholebody.planning.dmp.DMP.rollout>` with obstacles: ``N`` samples
    from rest at ``x0`` (m) to ``g`` over ``T`` s, by
    :func:`wholebody.kernels.dmp.rollout_obstacles` when ``kernels`` is given and computes
    every potential, else by the reference :class:`ObstacleIntegrator`. Also returns the
    substep count of each sample interval (N - 1,) and the number of force evaluations: the
    step control's decisions, which the two implementations share."""
    obstacles = tuple(obstacles)
    rows = None if kernels is None else kernel_rows(obstacles)
    force = make_point_force(obstacles) if rows is None else None
    if dmp.dim != 3:
        raise DimensionError(f"DMP.rollout: obstacles need a 3-D DMP, this one is {dmp.dim}-D")
    tol, top = check_tolerance(tolerance), check_max_substeps(max_substeps)
    if force is not None:
        return _rollout_reference(dmp, N, x0, g, T, force, tol, top)
    assert kernels is not None and rows is not None
    return _rollout_compiled(dmp, N, x0, g, T, rows, tol, top, kernels)


def _rollout_reference(
    dmp: DMP,
    N: int,
    x0: np.ndarray,
    g: np.ndarray,
    T: float,
    force: PointForce,
    tol: float,
    top: int,
) -> tuple[DMPRollout, np.ndarray, int]:
    """:func:`rollout_obstacles` by :class:`ObstacleIntegrator`."""
    cfg = dmp.config
    t_half = np.linspace(0.0, T, 2 * (N - 1) + 1)  # steps and midpoints
    s_half = np.exp(-cfg.alpha_s * t_half / (cfg.phase_tau_ratio * T))
    b = cfg.K * (g - np.outer(s_half, g - x0) + dmp.forcing(s_half))  # (2N - 1, 3)
    integrator = ObstacleIntegrator(dmp, x0, g, T, force, tol, top)
    x, v, vdot, counts = integrator.rollout(b, T / (N - 1), s_half[::2])
    return (rollout_result(t_half[::2].copy(), s_half[::2].copy(), x, v / T, vdot / T, x0, g, T),
            counts, integrator.evaluations)  # fmt: skip


def _rollout_compiled(
    dmp: DMP,
    N: int,
    x0: np.ndarray,
    g: np.ndarray,
    T: float,
    rows: np.ndarray,
    tol: float,
    top: int,
    kernels: ModuleType,
) -> tuple[DMPRollout, np.ndarray, int]:
    """:func:`rollout_obstacles` by :func:`wholebody.kernels.dmp.rollout_obstacles`, the
    potentials given as their kernel ``rows``."""
    cfg = dmp.config
    model = obstacle_model(cfg, T)
    state = substep_state(tol, top)
    times, phase, counts = np.empty(N), np.empty(N), np.zeros(N - 1, dtype=np.int64)
    X, V, A = np.empty((N, 3)), np.empty((N, 3)), np.empty((N, 3))
    status, err, m, n = kernels.rollout_obstacles(
        x0, g, model, -float(cfg.alpha_s), cfg.phase_tau_ratio * T, dmp._c, dmp._h,
        as_buffer(dmp.weights), rows, tol, top, state, times, phase, X, V, A, counts
    )  # fmt: skip
    if status != 0:
        raise failure(kernels, status, err, m, float(phase[n]), float(model[3]), tol)
    return rollout_result(times, phase, X, V, A, x0, g, T), counts, int(state[1])
