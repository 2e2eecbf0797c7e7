"""The outcome of one torque-level step (:class:`DynamicsResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from wholebody.errors import SolverError
from wholebody.solvers.result import SolverResult, SolverStatus

if TYPE_CHECKING:
    from wholebody.dynamics.solver import DynamicsSolver

__all__ = ["DynamicsResult"]


@dataclass
class DynamicsResult:
    """One torque-level step. Units: rad/s^2 and m/s^2 (accelerations), N m and N (torques,
    generalised forces), wrenches as their contact states (:mod:`~wholebody.dynamics.contacts`).

    Attributes
    ----------
    a
        Actuated acceleration (nu).
    dv
        Model acceleration ``A a`` (nv).
    force
        ``Q``, the actuators' generalised force on the model's velocities (nv; zero on a
        floating base's six, up to the solver's tolerance).
    tau
        ``A^T Q`` per entry of ``u``: the torque of each actuated joint, a wheel's torque.
    wrenches
        Contact frame -> its wrench (6: force then torque, in the contact frame; 3: a point
        contact's force, world axes); ``"object/hand"`` -> the carried object's wrench on
        that hand (hand frame).
    violations
        Kind of bound -> the largest excess over it (0 where every bound holds).
    status
        INFEASIBLE where a bound is exceeded by more than the solver's tolerance, FAILED
        where the cascade failed, BOUNDS_ACTIVE where a task gave way to a bound, else OK.
    """

    a: np.ndarray
    dv: np.ndarray
    force: np.ndarray
    tau: np.ndarray
    wrenches: dict[str, np.ndarray]
    violations: dict[str, float]
    status: SolverStatus
    solver: DynamicsSolver = field(repr=False)
    solve: int = 0
    """Which solve of ``solver`` this is (:attr:`solution` needs it to be the last)."""
    squeeze: dict[str, float] = field(default_factory=dict)
    """Carried object -> the squeeze between its two hands (N, :mod:`~wholebody.dynamics.carry`)."""
    solve_time: float = 0.0
    """The whole step (s)."""
    qp_time: float = 0.0
    """Of :attr:`solve_time`, the QP's solve (s): the weighted QP's kernel or the cascade's."""

    @property
    def solution(self) -> SolverResult:
        """The cascade's full outcome (levels, each task's residual in m/s^2 or rad/s^2,
        unmet tasks): readable until the solver solves again."""
        if self.solve != self.solver._solves:
            raise SolverError("DynamicsResult.solution: the solver has solved again since")
        return self.solver.solution()

    def report(self) -> str:
        """Per task its acceleration residual ``||J a + Jdot u - a*||`` (m/s^2, rad/s^2) and
        whether it was met, the contacts' wrenches, and the bounds' excesses."""
        unmet = {name for _, name in self.solution.infeasible}
        lines = [f"{self.status.name}: solved in {self.solve_time * 1e6:.0f} us"]
        lines += [
            f"  {name}: residual {r:.3g}, {'UNMET' if name in unmet else 'met'}"
            for name, r in self.solution.task_residuals.items()
        ]
        for frame, w in self.wrenches.items():
            lines.append(f"  contact {frame}: wrench " + " ".join(f"{x:+.2f}" for x in w))
        bad = {k: v for k, v in self.violations.items() if v > 0.0}
        excess = ", ".join(f"{k} by {v:.3g}" for k, v in bad.items())
        lines.append("  exceeded: " + (excess or "none"))
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()
