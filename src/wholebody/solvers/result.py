"""What a solver returns: the actuated velocity and what happened."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["SolverResult", "SolverStatus"]


class SolverStatus(enum.IntEnum):
    """Outcome of one solve, from best to worst; the same meaning for every backend.

    A task is *limited* when the hard constraints (the box, inequality rows) raised its
    weighted residual above the best that the higher levels leave it (its box-free
    optimum) by more than the solver's tolerance ``tol (1 + ||v||)``. A task that the
    higher levels alone keep from its target (a posture under the hands) is not limited:
    it is listed in :attr:`SolverResult.infeasible`, and the status does not change."""

    OK = 0
    """Every level solved; no bound active."""
    BOUNDS_ACTIVE = 1
    """Every level solved as well as the higher levels allow, with some bounds active."""
    SCALED = 2
    """As BOUNDS_ACTIVE, and the projection backend scaled a level's motion down to respect
    the bounds without limiting a task (an objectives' level: its descent step shortened;
    the HQP reports BOUNDS_ACTIVE there)."""
    INFEASIBLE = 3
    """A level could not be met within tolerance: a task of the first level is unmet, or a
    task of any level is limited by the hard constraints (see ``infeasible``); ``u`` is the
    best feasible answer. Not a failure in itself: a posture level under the hands that the
    velocity limits hold back reads INFEASIBLE on every step of a reach that succeeds.
    :func:`wholebody.solvers.unmet.classify` tells why each task was unmet, and whether it
    could have been met (the run logs record it: ``RunLog.unmet``, ``unmet_steps``)."""
    FAILED = 4
    """A numerical failure; ``u`` is a safe fallback that respects the bounds."""


@dataclass
class SolverResult:
    """The result of :meth:`Solver.solve`.

    Attributes
    ----------
    u
        Actuated velocity (nu,), never NaN; always inside the box of the stack's constraints.
    status
        See :class:`SolverStatus`.
    level_residuals
        Per level, the weighted residual norm ``||A u~ - b||`` of its equality rows.
    task_residuals
        Per equality task, the residual norm of its rows ``||J u - v||`` (unweighted; rows
        of weight 0 take no part in the problem and count as 0).
    active_bounds
        Indices of the entries of ``u`` at a bound of the box.
    scale
        Per level, the factor its motion was scaled by (1 = not scaled; projection only).
    infeasible
        ``(level name, task name)`` of the tasks a level could not meet.
    solve_time
        Wall time of the solve, seconds.
    message
        Free text (engine status, fallback taken).
    source
        The arena (a stack's plan) of the solve, for :meth:`report` and :meth:`causes`
        while the stack has not been solved again; None for a result made by hand.
    """

    u: np.ndarray
    status: SolverStatus
    level_residuals: np.ndarray
    task_residuals: dict[str, float] = field(default_factory=dict)
    active_bounds: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    scale: np.ndarray = field(default_factory=lambda: np.ones(0))
    infeasible: list[tuple[str, str]] = field(default_factory=list)
    solve_time: float = 0.0
    message: str = ""
    source: Any = field(default=None, repr=False, compare=False)

    def report(self) -> str:
        """The solve in words, per level and task: its error with its units, its weight,
        met or not and why (:func:`wholebody.solvers.unmet.classify`), then the active limits
        (joint, which bound, which limit) and the inequality rows at their bound (a collision
        pair and its distance). Complete until the stack is solved again; after that, only
        what the result holds (:mod:`wholebody.solvers.status`)."""
        from wholebody.solvers.status import status_report

        return status_report(self)

    def causes(self) -> dict[str, Any]:
        """Per equality task, its :class:`~wholebody.solvers.unmet.UnmetCause` in this solve
        (MET when met); ValueError once the stack was solved again."""
        from wholebody.solvers.status import causes

        return causes(self)

    def __str__(self) -> str:
        return self.report()

    @property
    def limit_hit(self) -> bool:
        """Whether any bound was active or any motion scaled down (whichever task it
        concerns: :meth:`Stack.saturated_tasks <wholebody.solvers.Stack.saturated_tasks>`
        tells which tasks a bound limited)."""
        return (
            self.status in (SolverStatus.BOUNDS_ACTIVE, SolverStatus.SCALED)
            or bool(self.active_bounds.size)
            or bool(np.any(self.scale < 1.0))
        )

    @property
    def ok(self) -> bool:
        """Whether every level was solved (possibly with bounds active)."""
        return self.status <= SolverStatus.SCALED
