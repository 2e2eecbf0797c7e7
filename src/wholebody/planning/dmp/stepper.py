"""Online integration of a DMP: a :class:`DMPState` advanced by any ``dt``, one call at a time.

The integrators are the rollout's: without obstacles RK4 of the linear system (several
steps for a ``dt`` too coarse for one, :func:`~wholebody.planning.dmp.linear.linear_substeps`),
with obstacles the adaptive substeps of :mod:`~wholebody.planning.dmp.adaptive` over
``[t, t + dt]``. The phase is advanced exactly, ``s <- s exp(-alpha_s dt / tau_s)``. Stepping
with ``dt = T / (N - 1)`` therefore reproduces :meth:`DMP.rollout
<wholebody.planning.dmp.DMP.rollout>` to rounding: a controller can follow a plan computed
online, step by step, while the goal moves (:meth:`DMPStepper.set_goal`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_vector
from wholebody.planning.dmp import compiled
from wholebody.planning.dmp.adaptive import (
    ObstacleIntegrator,
    check_max_substeps,
    check_tolerance,
    failure,
    obstacle_model,
    substep_state,
)
from wholebody.planning.dmp.compiled import as_buffer
from wholebody.planning.dmp.linear import linear_substeps
from wholebody.planning.obstacles import Potential, kernel_rows, make_point_force

if TYPE_CHECKING:
    from wholebody.planning.dmp.model import DMP

__all__ = ["DMPState", "DMPStepper"]


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
    :func:`~wholebody.planning.dmp.compiled.reference_implementation` or its obstacles
    include a potential the kernels do not compute; states whose arrays are not float64 take
    the reference's code.
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
        self._integrator: ObstacleIntegrator | None = None
        self._kernels = compiled.kernels()  # None: the reference implementation
        d, nb = dmp.dim, cfg.n_basis
        if kernel is not None:
            if dmp.dim != 3:
                raise DimensionError(
                    f"DMPStepper: obstacles need a 3-D DMP, this one is {dmp.dim}-D"
                )
            self._integrator = ObstacleIntegrator(dmp, self.start, self.goal, self.tau, kernel,
                                                  check_tolerance(tolerance),
                                                  check_max_substeps(max_substeps))  # fmt: skip
            self._rows = None if self._kernels is None else kernel_rows(obstacles)
            if self._rows is None:
                self._kernels = None  # a potential the kernels do not compute
            else:
                self._model = obstacle_model(cfg, T)
                self._state = substep_state(self._integrator.tol, self._integrator.max_substeps)
        elif self._kernels is not None:
            self._work = np.empty(13 * d + nb)
        self._c, self._negh, self._W = dmp._c, -dmp._h, dmp.weights
        if self._kernels is not None:
            self._W = as_buffer(dmp.weights)
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
                else linear_substeps(self.dmp.config, dt / self.tau)
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
                raise failure(kernels, status, err, m, s, integ.rate, integ.tol)
            out.s = s * self._e1
        else:
            out.s = kernels.step_linear(state.x, state.v, s, dt / self._m, self._m, self._eh,
                                        self._e1, self.K, self.D, self.tau, self._Kg,
                                        self._Kgx0, self._c, self.dmp._h, self._W, self._work,
                                        out.x, out.v)  # fmt: skip

    def _step_obstacles(self, state: DMPState, dt: float, out: DMPState) -> None:
        """:meth:`step` with obstacles by the reference :class:`ObstacleIntegrator`: one
        interval of ``dt`` (a compiled stepper's step-control state is read and written back,
        so that both paths continue from the same decisions)."""
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
        """One classical RK4 step of ``dt`` without obstacles, in the preallocated buffers."""
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


def _is_buffer(a: object) -> bool:
    """Whether ``a`` is an array the kernels can write into as it is."""
    return (
        isinstance(a, np.ndarray)
        and a.dtype == np.float64
        and a.flags.c_contiguous
        and a.flags.writeable
    )
