"""Online integration of a DMP: a :class:`DMPState` advanced by any ``dt``, one call at a time.

Each call is one sample interval ``[t, t + dt]`` of the rollout's integrator
(:mod:`~wholebody.planning.dmp.integrator`, the same kernel): without obstacles RK4 substeps
as many as the ``dt`` needs, with obstacles the adaptive substeps, whose count carries over
from one call to the next. The phase is advanced exactly, ``s <- s exp(-alpha_s dt /
tau_s)``. Stepping with ``dt = T / (N - 1)`` therefore reproduces :meth:`DMP.rollout
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
from wholebody.planning.dmp.compiled import kernels
from wholebody.planning.dmp.integrator import (
    check_max_substeps,
    check_tolerance,
    control,
    linear_substeps,
    run,
)
from wholebody.planning.obstacles import Potential, potential_rows

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
    """Online integration of a DMP, one ``dt`` at a time (module docstring).

    Parameters
    ----------
    dmp
        The learned primitive.
    duration, start, goal
        ``T`` (s), ``x0``, ``g`` (d,) (m); default the demonstration's.
    obstacles
        Repulsive potentials (3-D only; those :meth:`DMP.rollout` takes).
    tolerance, max_substeps
        As in :meth:`DMP.rollout` (obstacles only).

    Notes
    -----
    ``step(state, dt, out=state)`` updates ``state``'s arrays in place, through buffers the
    stepper keeps; without ``out`` it returns a new :class:`DMPState`. States of other types
    (float32 arrays, lists) are read as float64 and written back in their own type. The
    goal may be moved between steps with :meth:`set_goal`.
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
        self.start, self.duration = x0.copy(), T
        self._obs = potential_rows(obstacles, "DMPStepper")
        d = dmp.dim
        if len(self._obs) and d != 3:
            raise DimensionError(f"DMPStepper: obstacles need a 3-D DMP, this one is {d}-D")
        if len(self._obs):
            tol, top = check_tolerance(tolerance), check_max_substeps(max_substeps)
            first = top if tol == math.inf else 1
        else:
            tol, top = math.inf, 1
            first = 1
        self._p = dmp._run(x0, g, T, tol, math.nan)
        self._ctl = control(top, first, 1)
        k = kernels()
        og = k.regions(d, dmp.config.n_basis)[0]
        self.goal = self._p[og : og + d]  # the arena's goal: set_goal moves it
        self._clock, self._Y = np.zeros((2, 2)), np.zeros((3, 2, d))
        self._span, self._next, self._top = k.H_SPAN, k.C_NEXT, k.C_TOP

    def set_goal(self, goal: np.ndarray) -> None:
        """Move the goal ``g`` (d,) m for the following steps."""
        self.goal[:] = as_vector(goal, self.dmp.dim, "DMPStepper: goal")

    def initial_state(self) -> DMPState:
        """At rest at the start, ``s = 1``, ``t = 0``."""
        return DMPState(self.start.copy(), np.zeros(self.dmp.dim), 1.0, 0.0)

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
            out = DMPState(np.empty(d), np.empty(d))
        p = self._p
        if dt != p[self._span]:
            p[self._span] = dt
            if not len(self._obs):  # the substeps a linear step of dt needs
                m = linear_substeps(self.dmp.config, dt / self.duration)
                self._ctl[self._next] = self._ctl[self._top] = m
        self._load(state, self._clock, self._Y)
        run(p, self._obs, self._ctl, self._clock, self._Y, "DMPStepper.step")
        out.x[:] = self._Y[0, 1]
        out.v[:] = self._Y[1, 1]
        out.t, out.s = float(self._clock[0, 1]), float(self._clock[1, 1])
        return out

    def acceleration(self, state: DMPState) -> np.ndarray:
        """``x''`` (d,) m/s^2 of the model at ``state`` (with the obstacles' force)."""
        clock, Y = np.empty((2, 1)), np.empty((3, 1, self.dmp.dim))
        self._load(state, clock, Y)
        run(self._p, self._obs, self._ctl, clock, Y, "DMPStepper.acceleration")
        return Y[2, 0]

    @staticmethod
    def _load(state: DMPState, clock: np.ndarray, Y: np.ndarray) -> None:
        """``state`` into the integrator's first sample."""
        clock[0, 0], clock[1, 0] = state.t, state.s
        Y[0, 0] = state.x
        Y[1, 0] = state.v
