"""Solver backends over the same stack: projection (the paper's) and hierarchical QP."""

from __future__ import annotations

from wholebody.solvers.base import Solver
from wholebody.solvers.hqp import HierarchicalQPSolver, LevelReport
from wholebody.solvers.projection import ProjectionSolver
from wholebody.solvers.qp import ENGINES, QPEngine, QPSolution, QPStatus, make_engine
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import Level, LevelProblem, Stack, StackProblem

__all__ = [
    "ENGINES",
    "HierarchicalQPSolver",
    "Level",
    "LevelProblem",
    "LevelReport",
    "ProjectionSolver",
    "QPEngine",
    "QPSolution",
    "QPStatus",
    "Solver",
    "SolverResult",
    "SolverStatus",
    "Stack",
    "StackProblem",
    "make_engine",
]
