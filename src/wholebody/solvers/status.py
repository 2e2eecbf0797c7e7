"""A solve's outcome in words: per level and task, the error, the weight, met or not and why,
the active limits and the inequality rows that held a task back (as placo's ``dump_status``).

:func:`status_report` reads the :class:`~wholebody.solvers.result.SolverResult` and, while
the stack has not been solved again since, the arena of the solve it came from: the rows
(scaled coordinates ``u~ = u / D``), the box, the inequality rows and the causes of the unmet
tasks (:func:`wholebody.solvers.unmet.classify`). An older result is reported from its own
fields only.

Errors are the tasks' own (:meth:`Task.error <wholebody.tasks.Task.error>`): a pose task's
position error in m and orientation error in rad (read from its parameter block, where the
solve computed it), a posture's in rad (m for a prismatic joint); a task of another kind
reports the norm of its rows' demand ``||v||`` and residual ``||J u - v||`` instead.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from wholebody.kernels import layout as lay
from wholebody.solvers.unmet import CAUSE_WORDS, UnmetCause, classify

if TYPE_CHECKING:
    from wholebody.solvers.plan import Arena
    from wholebody.solvers.result import SolverResult

__all__ = ["causes", "fresh_source", "status_report"]

_BOUND = 1e-6  # a limit's bound within this (relative) of u is the one u rests on
_ROW = 1e-6  # an inequality row within this (relative) of its bound is at it


def fresh_source(result: SolverResult) -> Arena | None:
    """The arena of the solve ``result`` came from, while it still holds that solve (no
    other solve of the stack since); else None."""
    arena = result.source
    if arena is None:
        return None
    last = getattr(arena, "last_result", result)
    return arena if last is result else None


def causes(result: SolverResult) -> dict[str, UnmetCause]:
    """Per equality task (by name), why it was unmet in the solve (MET if met); only while
    the stack has not been solved again (else :class:`ValueError`)."""
    arena = fresh_source(result)
    if arena is None:
        raise ValueError(
            "the stack was solved again since this result: ask for its causes (or its "
            "report) before the next solve"
        )
    found, _ = classify(arena)
    return {name: UnmetCause(int(c)) for name, c in zip(arena.task_names, found, strict=True)}


def status_report(result: SolverResult) -> str:
    """``result`` as text (module docstring)."""
    head = (
        f"{result.status.name}: max |u| {np.abs(result.u).max(initial=0.0):.3g} (rad/s, m/s), "
        f"solved in {result.solve_time * 1e6:.0f} us"
    )
    lines = [head]
    arena = fresh_source(result)
    if arena is None:
        lines += _plain(result)
        lines.append("  (details gone: the stack was solved again since this result)")
    else:
        lines += _levels(result, arena)
        lines += _limits(result, arena)
        lines += _held(arena)
    if result.message:
        lines.append(f"message: {result.message}")
    return "\n".join(lines)


def _plain(result: SolverResult) -> list[str]:
    """What the result holds itself: residuals by task, the unmet tasks, the active entries."""
    unmet = {name for _, name in result.infeasible}
    out = [
        f"  {name}: residual {r:.3g}, {'UNMET' if name in unmet else 'met'}"
        for name, r in result.task_residuals.items()
    ]
    if result.active_bounds.size:
        out.append(f"  active bounds on u[{', '.join(map(str, result.active_bounds))}]")
    return out


def _levels(result: SolverResult, arena: Arena) -> list[str]:
    """Per level, its residual (and scale), then its tasks, inequality tasks and objectives."""
    found, _ = classify(arena)
    out = []
    for k, level in enumerate(arena.level_names):
        title = f"level {k}" + ("" if level == f"level {k}" else f" {level!r}")
        scale = result.scale[k] if k < result.scale.size else 1.0
        scaled = f", its motion scaled by {scale:.3g}" if scale < 1.0 else ""
        out.append(f"{title}: residual {result.level_residuals[k]:.3g}{scaled}")
        out += _task_lines(arena, k, found)
        out += _other_lines(arena, k)
    return out


def _task_lines(arena: Arena, k: int, found: np.ndarray) -> list[str]:
    """The equality tasks of level ``k``: weight, error, met or not and why."""
    tasks = arena.view(lay.I_TASK)
    entries = _entries(arena)
    unmet = arena.view(lay.I_INFEASIBLE)
    out = []
    for t in np.flatnonzero(tasks[:, 0] == k).tolist():
        name = arena.task_names[t]
        task = entries.get(name)
        verdict = "met"
        if unmet[t]:
            cause = UnmetCause(int(found[t]))
            verdict = f"UNMET: {CAUSE_WORDS.get(cause, cause.name)}"
            if cause == UnmetCause.INEQUALITY:
                verdict += f" ({', '.join(_active_rows(arena, k)) or 'rows not named'})"
        out.append(f"  {name}: weight {_weight(task)}, {_error(task, arena, t)}; {verdict}")
    return out


def _other_lines(arena: Arena, k: int) -> list[str]:
    """The inequality tasks (rows at their bound) and objectives (weight) of level ``k``."""
    stack = getattr(arena, "stack", None)
    entries = {} if stack is None else {t.name: t for t in stack.levels[k].inequalities}
    out = []
    for level, first, last, name in arena.inequality_rows:
        if level == k:
            at = [r for r in _active_rows(arena, k, only=k) if r.startswith(f"{name}[")]
            used = len(getattr(entries.get(name), "pairs", range(last - first)))
            out.append(
                f"  {name}: inequality, {used} of {last - first} rows in use, "
                f"{len(at)} at their bound"
            )
    if stack is not None:
        gain = stack.levels[k].gain  # 1/s: the descent's step, u = -gain W^-1 grad H
        out += [
            f"  {o.name}: objective, weight {o.weight:g}, level gain {gain:g}"
            for o in stack.levels[k].objectives
        ]
    return out


def _entries(arena: Arena) -> dict[str, object]:
    """The stack's equality tasks by name (none for an arena no stack made)."""
    stack = getattr(arena, "stack", None)
    return {} if stack is None else {t.name: t for t in stack.tasks}


def _weight(task: object) -> str:
    """A task's weight as text (a number, or one per row; "?" without the task)."""
    w = getattr(task, "weight", None)
    if w is None:
        return "?"
    return f"{w:g}" if isinstance(w, float) else np.array2string(np.asarray(w), precision=3)


def _error(task: object, arena: Arena, t: int) -> str:
    """The task's error with its units (module docstring)."""
    from wholebody.tasks.frame import PoseTask
    from wholebody.tasks.posture import PostureTask

    params = getattr(task, "_params", np.zeros(0))
    if isinstance(task, PoseTask) and params.size:
        from wholebody.kernels.rows import POSE_ERROR

        e = params[POSE_ERROR : POSE_ERROR + 6]
        parts = []
        if (task.rows < 3).any():
            parts.append(f"{np.linalg.norm(e[:3]) * 1e3:.3f} mm")
        if (task.rows >= 3).any():
            parts.append(f"{np.linalg.norm(e[3:]):.4f} rad")
        return "error " + ", ".join(parts)
    if isinstance(task, PostureTask) and params.size:
        e = params[2 * task.dim :]
        return f"error {np.linalg.norm(e):.4f} rad (largest {np.abs(e).max(initial=0):.4f})"
    tasks = arena.view(lay.I_TASK)
    b = arena.view(lay.F_B)[tasks[t, 1] : tasks[t, 2]]
    unweight = arena.view(lay.F_ROW)[1, tasks[t, 1] : tasks[t, 2]]
    residual = arena.view(lay.F_TASK_RES)[t, 1]
    return f"demand {np.linalg.norm(b * unweight):.3g}/s, residual {residual:.3g}/s"


def _limits(result: SolverResult, arena: Arena) -> list[str]:
    """The active entries of ``u``: joint, which bound, and which limit sets it."""
    if not result.active_bounds.size:
        return ["active limits: none"]
    stack = getattr(arena, "stack", None)
    names = stack.robot.actuated_joints if stack is not None else None
    boxes = arena.view(lay.F_BOXES)
    limits = getattr(arena, "constraints", [])
    box, x = arena.view(lay.F_BOX), arena.view(lay.F_U)[0]  # scaled
    out = [f"active limits ({result.active_bounds.size}):"]
    for j in result.active_bounds.tolist():
        u = float(result.u[j])
        side = int(abs(x[j] - box[1, j]) <= abs(x[j] - box[0, j]))
        which = [
            getattr(c, "name", type(c).__name__)
            for c, b in zip(limits, boxes, strict=False)
            if abs(b[side, j] - u) <= _BOUND * (1.0 + abs(u))
        ]
        joint = names[j] if names is not None else f"u[{j}]"
        bound = "upper" if side else "lower"
        by = f" ({', '.join(which)})" if which else ""
        out.append(f"  {joint}: at its {bound} bound{by}, u = {u:.4g}")
    return out


def _active_rows(arena: Arena, k: int, only: int | None = None) -> list[str]:
    """The inequality rows of level ``k`` and above (``only``: of that level alone) at their
    bound at the solution: their names, with the pair and its distance for a collision
    task."""
    C, CB = arena.view(lay.F_C), arena.view(lay.F_CB)
    x = arena.view(lay.F_U)[0]
    entries = {}
    stack = getattr(arena, "stack", None)
    if stack is not None:
        entries = {t.name: t for lv in stack.levels for t in lv.inequalities}
    out = []
    for level, first, last, name in arena.inequality_rows:
        if level > k or (only is not None and level != only):
            continue
        pairs = getattr(entries.get(name), "pairs", None)  # a collision task's rows' pairs
        used = last if pairs is None else min(last, first + len(pairs))
        for r in range(first, used):
            value = float(C[r] @ x)
            lo, hi = CB[0, r], CB[1, r]
            if min(abs(value - lo), abs(value - hi)) > _ROW * (1.0 + abs(value)):
                continue
            label = f"{name}[{r - first}]"
            if pairs is not None:
                p = pairs[r - first]
                label += f" {p.name} at {p.distance * 1e3:.2f} mm"
            out.append(label)
    return out


def _held(arena: Arena) -> list[str]:
    """Every inequality row at its bound (whichever task it held back)."""
    if not arena.inequality_rows:
        return []
    rows = _active_rows(arena, len(arena.level_names))
    return [f"inequality rows at their bound: {', '.join(rows) if rows else 'none'}"]
