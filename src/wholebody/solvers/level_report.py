"""What the hierarchical QP did at one level of its last solve (for logs, tests and benchmarks).

:attr:`HierarchicalQPSolver.levels <wholebody.solvers.hqp.HierarchicalQPSolver.levels>`
holds one per level, read from the cascade's report rows (:mod:`wholebody.solvers.compiled_hqp`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from wholebody.solvers.qp import QPStatus

__all__ = ["LevelReport"]


@dataclass(slots=True)
class LevelReport:
    """What happened at one level of the last solve (for logs, tests and benchmarks).

    Attributes
    ----------
    name
        The level's name.
    free
        Directions left free by the higher levels when this level was solved (``Z``'s columns).
    rank
        Rank of the level's equality rows in those directions.
    qp
        Whether a QP was solved (False: the unconstrained candidate was feasible, or no freedom).
    engine_status
        The engine's status when a QP was solved.
    iterations
        Engine iterations.
    retries
        QP solves repeated with 100 and 10000 times the Tikhonov term after an engine failure
        (a nearly singular level with degenerate bounds).
    residual
        Weighted residual ``||A x - b||`` of the level's equality rows at the final answer.
    limited
        Names of the tasks (and inequality tasks) that the hard constraints kept from their
        best residual given the higher levels: the box cost this level something.
    failed
        The level was skipped (engine failure or non-finite rows).
    damped
        The level was unmet and solved again with the stall damping
        (:attr:`HierarchicalQPSolver.stall_damping
        <wholebody.solvers.hqp.HierarchicalQPSolver.stall_damping>`): its answer is the
        damped least squares', ``residual`` that answer's.
    """

    name: str
    free: int = 0
    rank: int = 0
    qp: bool = False
    engine_status: QPStatus | None = None
    iterations: int = 0
    residual: float = 0.0
    retries: int = 0
    limited: list[str] = field(default_factory=list)
    failed: bool = False
    damped: bool = False
