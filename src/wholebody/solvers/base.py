"""The solver contract."""

from __future__ import annotations

from abc import ABC, abstractmethod

from wholebody.robot import RobotState
from wholebody.solvers.result import SolverResult
from wholebody.solvers.stack import Stack

__all__ = ["Solver"]


class Solver(ABC):
    """A solver backend: turns a :class:`Stack` at a state into an actuated velocity."""

    name: str

    @abstractmethod
    def solve(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        """The actuated velocity ``u`` for one control step of ``dt`` seconds at ``state``.

        Never returns NaN; ``u`` always respects the stack's constraints (box).
        """
