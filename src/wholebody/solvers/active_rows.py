"""Inequality rows in the projection backend: violated rows held as a level above every level.

The pseudo-inverse with null-space projection has no inequality rows of its own. The
projection backend takes them by an active set: solve the stack without them; every row the
solution violates (``C u~ < lower`` or ``> upper`` beyond the tolerance) is held at its bound
as an equality row of a new first level, above every task; solve again; repeat until no row
is violated (at most once per row: a held row stays held for the step). Every level is then
solved in the null space of the held rows, so the hands yield to a collision row, never the
reverse; rows the first solution respects cost nothing.

What the rows limited is reported: the result's ``message`` names the held rows (task and
row index, e.g. ``collision[2]``, followed by the pair when the solver has the stack:
:meth:`wholebody.tasks.CollisionAvoidance.row_names`) and the tasks whose residual they
raised above the tolerance; ``infeasible`` lists
those tasks, and held rows the box kept from their bound under the level ``HELD``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import LevelProblem, StackProblem

__all__ = ["HELD", "solve_with_inequalities"]

HELD = "inequality rows (held)"
"""The name of the first level the held rows form."""


def solve_with_inequalities(problem: StackProblem, solve: Callable[[StackProblem], SolverResult],
                            tol: float) -> SolverResult:  # fmt: skip
    """``solve`` (a solver of equality levels) with ``problem``'s inequality rows held by the
    active set of the module docstring; the result describes ``problem``'s own levels."""
    C, lower, upper, names = _rows(problem)
    nu = problem.lower.size
    empty = {"C": np.zeros((0, nu)), "lower": np.zeros(0), "upper": np.zeros(0)}
    plain = [replace(lp, inequality_rows={}, **empty) for lp in problem.levels]
    held: dict[int, float] = {}
    first = result = solve(replace(problem, levels=plain))
    for _ in range(len(names)):
        Cu = C @ (result.u / problem.scale)
        newly = [i for i in range(len(names)) if i not in held
                 and not lower[i] - tol * (1 + abs(lower[i])) <= Cu[i]
                 <= upper[i] + tol * (1 + abs(upper[i]))]  # fmt: skip
        if not newly:
            break
        for i in newly:
            held[i] = lower[i] if Cu[i] < lower[i] else upper[i]
        top = _held_level(C, held, names, nu)
        result = solve(replace(problem, levels=[top, *plain]))
    if not held:
        return result
    return _report(result, first, held, names, problem.levels[0].name)


def _rows(problem: StackProblem) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Every level's inequality rows stacked, rows with no finite bound left out, and a name
    per row: ``task[k]``."""
    blocks, names = [], []
    for lp in problem.levels:
        for task, rows in lp.inequality_rows.items():
            for k, r in enumerate(range(rows.start, rows.stop)):
                if np.isfinite(lp.lower[r]) or np.isfinite(lp.upper[r]):
                    blocks.append((lp.C[r], lp.lower[r], lp.upper[r]))
                    names.append(f"{task}[{k}]")
    nu = problem.lower.size
    if not blocks:
        return np.zeros((0, nu)), np.zeros(0), np.zeros(0), []
    C = np.array([b[0] for b in blocks])
    return C, np.array([b[1] for b in blocks]), np.array([b[2] for b in blocks]), names


def _held_level(C: np.ndarray, held: dict[int, float], names: list[str],
                nu: int) -> LevelProblem:  # fmt: skip
    rows = sorted(held)
    return LevelProblem(
        name=HELD,
        A=C[rows].copy(),
        b=np.array([held[i] for i in rows]),
        C=np.zeros((0, nu)),
        lower=np.zeros(0),
        upper=np.zeros(0),
        task_rows={names[i]: slice(k, k + 1) for k, i in enumerate(rows)},
    )


def _report(result: SolverResult, first: SolverResult, held: dict[int, float],
            names: list[str], top: str) -> SolverResult:  # fmt: skip
    """The result without the held level's residual and scale, its message naming the held
    rows and the tasks they limited (unmet now, met without them). INFEASIBLE when a held row
    (the box kept it from its bound) or a task of the stack's first level is unmet."""
    before = {task for _, task in first.infeasible}
    limited = [task for level, task in result.infeasible if level != HELD and task not in before]
    text = f"held inequality rows: {', '.join(names[i] for i in sorted(held))}"
    if limited:
        text += f"; they limited: {', '.join(limited)}"
    status = result.status
    if any(level in (HELD, top) for level, _ in result.infeasible):
        status = SolverStatus.INFEASIBLE
    elif status == SolverStatus.INFEASIBLE:
        status = SolverStatus.BOUNDS_ACTIVE
    return replace(result, status=status, level_residuals=result.level_residuals[1:],
                   scale=result.scale[1:],
                   message="; ".join(m for m in (result.message, text) if m))  # fmt: skip
