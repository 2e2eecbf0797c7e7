"""Solver backends over the same stack: projection (the paper's) and hierarchical QP."""

from __future__ import annotations

from wholebody.solvers.base import Solver
from wholebody.solvers.projection import ProjectionSolver
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import Level, LevelProblem, Stack, StackProblem

__all__ = [
    "Level",
    "LevelProblem",
    "ProjectionSolver",
    "Solver",
    "SolverResult",
    "SolverStatus",
    "Stack",
    "StackProblem",
]
