"""The torque-level control loop: references -> tasks -> :class:`DynamicsSolver` -> torques
-> a plant (MuJoCo) or exact integration -> log.

One step at ``t_k = k dt``: every referenced task gets its target (the reference's pose and
twist at ``t_k``); the solver turns the stack at the measured ``(q, u)`` into accelerations,
torques and wrenches; the tasks' integrators advance with the velocity ``u + a dt`` the step
leads to. Without a plant the state is integrated semi-implicitly
(``u' = u + a dt``, ``q' = integrate(q, u', dt)``), the contacts then holding by
construction; with a plant (:class:`wholebody.sim.MujocoPlant`) the generalised force ``Q``
is applied for the period and the state is read back from the simulator, its velocity
mapped to ``u`` by least squares on ``v = A u``.

Units: s, rad, m; torques N m and N; wrenches as their contacts state them
(:mod:`wholebody.dynamics.contacts`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from wholebody.dynamics.solver import DynamicsResult, DynamicsSolver
from wholebody.errors import DimensionError
from wholebody.planning.trajectory import Trajectory
from wholebody.robot import Robot
from wholebody.solvers.stack import Stack

__all__ = ["TorqueController", "TorqueLog", "TorquePlant"]


class TorquePlant(Protocol):
    """What the loop needs of a simulator (:class:`wholebody.sim.MujocoPlant` is one)."""

    stop_reason: str | None

    def torque_step(self, q: np.ndarray, force: np.ndarray, dt: float) -> np.ndarray: ...

    def velocity(self) -> np.ndarray: ...


class Target(Protocol):
    name: str

    def set_target(self, pose: np.ndarray, twist: np.ndarray | None = None) -> None: ...


@dataclass
class TorqueLog:
    """One row per control step (arrays of length N)."""

    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    tau: np.ndarray
    """(N, nu) the torque of each entry of ``u`` (N m, N)."""
    wrenches: dict[str, np.ndarray]
    """Contact frame -> (N, 6 or 3)."""
    status: np.ndarray
    violation: np.ndarray
    """(N,) the largest excess over a bound (N m, N): 0 while every bound holds."""
    squeeze: dict[str, np.ndarray]
    """Carried object -> (N,) the squeeze its hands' wrenches make (N; NaN while not held)."""
    step_time: np.ndarray
    """(N,) wall time of the solve (s)."""
    meta: dict = field(default_factory=dict)


class TorqueController:
    """Runs a stack at the torque level (module docstring).

    Parameters
    ----------
    robot, stack, solver
        The stack's tasks, and the solver with its contacts.
    dt
        Control period (s); with a MuJoCo plant a whole number of its physics steps (1 kHz:
        the physics rate).
    references
        Task -> the trajectory its target follows (time from the run's start).
    plant
        A simulator with ``torque_step`` and ``velocity``; None integrates exactly.
    """

    def __init__(
        self,
        robot: Robot,
        stack: Stack,
        solver: DynamicsSolver,
        *,
        dt: float,
        references: Mapping[Target, Trajectory] | None = None,
        plant: TorquePlant | None = None,
    ) -> None:
        if not (math.isfinite(dt) and dt > 0.0):
            raise DimensionError(f"dt must be a positive number of seconds, got {dt}")
        self.robot, self.stack, self.solver, self.dt = robot, stack, solver, float(dt)
        self.references = dict(references or {})
        self.plant = plant
        self._pinv = np.linalg.pinv(np.asarray(robot.actuation))
        self.t = 0.0
        self.result: DynamicsResult | None = None

    def step(self, q: np.ndarray, u: np.ndarray) -> DynamicsResult:
        """One step at the measured ``(q, u)``: targets at :attr:`t`, the solve, the tasks'
        integrators advanced; returns the step's :class:`DynamicsResult`."""
        for task, ref in self.references.items():
            sample = ref.sample(min(self.t, ref.duration))
            twist = sample.twist if self.t < ref.duration else np.zeros(6)
            task.set_target(sample.pose, twist)
        result = self.solver.solve(self.stack, q, u, self.dt)
        self.stack.advance(self.solver.state, self.dt, u=u + result.a * self.dt)
        self.t += self.dt
        self.result = result
        return result

    def advance(self, q: np.ndarray, u: np.ndarray, result: DynamicsResult) -> tuple:
        """The state ``(q, u)`` after the step: the plant's, or integrated."""
        if self.plant is None:
            u = u + result.a * self.dt
            return self.robot.integrate(q, u, self.dt), u
        q = self.plant.torque_step(q, result.force, self.dt)
        return q, self._pinv @ self.plant.velocity()

    def run(
        self,
        q0: np.ndarray,
        duration: float,
        *,
        u0: np.ndarray | None = None,
        callback: Callable[[int, float, np.ndarray, DynamicsResult], None] | None = None,
    ) -> TorqueLog:
        """Run for ``duration`` s from ``(q0, u0)`` (default at rest); ``callback(k, t, q,
        result)`` after every step. A plant's ``stop_reason`` ends the run (in ``meta``)."""
        n = round(duration / self.dt)
        if n < 1:
            raise DimensionError(f"duration {duration} s is shorter than one step")
        robot = self.robot
        q = robot.check_configuration(q0).copy()
        u = np.zeros(robot.nu) if u0 is None else np.asarray(u0, dtype=float).copy()
        rows = _Rows(robot, self.solver, n)
        for k in range(n):
            start = time.perf_counter()
            result = self.step(q, u)
            rows.record(k, self.t - self.dt, q, u, result, time.perf_counter() - start)
            q, u = self.advance(q, u, result)
            if callback is not None:
                callback(k, self.t, q, result)
            if self.plant is not None and self.plant.stop_reason:
                return rows.finish(k + 1, {"stopped": self.plant.stop_reason, "final_q": q})
        return rows.finish(n, {"final_q": q, "final_u": u})


class _Rows:
    """Preallocated log arrays."""

    def __init__(self, robot: Robot, solver: DynamicsSolver, n: int) -> None:
        self.t, self.status = np.zeros(n), np.zeros(n, dtype=np.int8)
        self.q, self.u = np.zeros((n, robot.nq)), np.zeros((n, robot.nu))
        self.tau = np.zeros((n, robot.nu))
        self.violation, self.step_time = np.zeros(n), np.zeros(n)
        self.wrenches = {c.frame: np.zeros((n, c.size)) for c in solver.contacts}
        self.squeeze = {o.name: np.full(n, np.nan) for o in solver.objects}

    def record(
        self, k: int, t: float, q: np.ndarray, u: np.ndarray, r: DynamicsResult, wall: float
    ) -> None:
        self.t[k], self.q[k], self.u[k], self.tau[k] = t, q, u, r.tau
        self.status[k], self.step_time[k] = int(r.status), wall
        self.violation[k] = max(r.violations.values(), default=0.0)
        for frame, w in r.wrenches.items():
            if frame in self.wrenches:
                self.wrenches[frame][k] = w
        for name, value in r.squeeze.items():
            self.squeeze[name][k] = value

    def finish(self, n: int, meta: dict) -> TorqueLog:
        return TorqueLog(
            self.t[:n],
            self.q[:n],
            self.u[:n],
            self.tau[:n],
            {f: w[:n] for f, w in self.wrenches.items()},
            self.status[:n],
            self.violation[:n],
            {o: v[:n] for o, v in self.squeeze.items()},
            self.step_time[:n],
            meta,
        )
