"""The stack: ordered priority levels plus hard constraints, the input of every solver.

A :class:`Stack` holds levels in strict priority (level 0 first) and constraints that hold at
every level. Each :class:`Level` holds equality tasks, inequality tasks and objectives. The
**objectives of a level** are summed into ``H = sum_i w_i f_i`` and enter as the velocity
task ``u = -k W^-1 grad H`` (``k`` = the level's ``gain``): gradient descent on H with step
``k``. Below a level of tasks this gives exactly the paper's projection
``u = J+ v - k (I - J+ J) grad H``, and both backends solve the same rows, so they agree
whenever no bound is active.

Where objectives report the diagonal of their Hessian (``ObjectiveValue.curvature``, e.g.
joint-limit avoidance, whose curvature explodes near a limit), the step is semi-implicit:
``u = -k W^-1 grad H / (1 + k dt W^-1 diag(hess H))``, the backward-Euler step of the gradient
flow for a separable cost. It equals the paper's explicit step where the curvature is small and
never overshoots where it is large (the explicit step oscillates from one control step to the
next once ``k dt h'' > 2``).

``metric`` is an optional diagonal ``W`` (one positive weight per actuated velocity): every
least-squares and minimum-norm choice is made in ``||u||_W``, e.g. cheap wheels make the base
move more. Internally solvers work in ``u~ = W^(1/2) u``; :meth:`Stack.evaluate` returns the
rows already in those coordinates (:class:`StackProblem`) and ``u = D u~`` with
``D = W^(-1/2)``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wholebody.errors import DimensionError, WholebodyError
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Constraint, InequalityTask, Objective, ObjectiveValue, Task

__all__ = ["Level", "LevelProblem", "Stack", "StackProblem"]

Entry = Task | InequalityTask | Objective


@dataclass
class Level:
    """One priority level.

    Parameters
    ----------
    entries
        Tasks (equality rows), inequality tasks and objectives, in any order.
    gain
        ``k`` (1/s per unit of gradient): the objectives' descent step, ``u = -k W^-1 grad H``.
    objective_weight
        Weight of the objectives' rows against the level's equality tasks.
    name
        Shown in results and errors (default ``"level i"``).
    """

    entries: Sequence[Entry] = ()
    gain: float = 1.0
    objective_weight: float = 1.0
    name: str = ""

    @property
    def tasks(self) -> list[Task]:
        return [e for e in self.entries if isinstance(e, Task)]

    @property
    def inequalities(self) -> list[InequalityTask]:
        return [e for e in self.entries if isinstance(e, InequalityTask)]

    @property
    def objectives(self) -> list[Objective]:
        return [e for e in self.entries if isinstance(e, Objective)]


@dataclass
class LevelProblem:
    """A level's rows at one state, in the scaled coordinates ``u~`` (see module docstring).

    ``A u~ = b`` in the least-squares sense (rows pre-multiplied by sqrt of their weights),
    and ``lower <= C u~ <= upper``. ``task_rows`` maps a task name to its row slice of A;
    ``inequality_rows`` likewise for C. The arrays are buffers reused by the next
    :meth:`Stack.evaluate`.
    """

    name: str
    A: np.ndarray
    b: np.ndarray
    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    task_rows: dict[str, slice] = field(default_factory=dict)
    inequality_rows: dict[str, slice] = field(default_factory=dict)
    identity_scale: float = 0.0
    """When the level holds only objectives, its rows are ``identity_scale * I`` (solvers
    may use that shortcut); 0 otherwise."""

    @property
    def has_equalities(self) -> bool:
        return self.A.shape[0] > 0


@dataclass
class StackProblem:
    """All levels at one state, with the box ``lower <= u~ <= upper`` and ``u = scale * u~``."""

    levels: list[LevelProblem]
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    objective_values: dict[str, ObjectiveValue]

    def to_u(self, u_scaled: np.ndarray) -> np.ndarray:
        """Actuated velocity from the scaled one."""
        return self.scale * u_scaled


class Stack:
    """Priority levels and hard constraints over one robot.

    Parameters
    ----------
    robot
        The robot all entries refer to.
    levels
        Highest priority first; each a :class:`Level` or a plain sequence of entries.
    constraints
        Hard boxes (joint position limits, velocity limits) intersected at every level.
    metric
        Optional positive weight per actuated velocity (length nu), the metric ``W``.
    """

    def __init__(
        self,
        robot: Robot,
        levels: Iterable[Level | Sequence[Entry]],
        constraints: Iterable[Constraint] = (),
        metric: np.ndarray | Sequence[float] | None = None,
    ) -> None:
        self.robot = robot
        self.levels: list[Level] = []
        for i, lv in enumerate(levels):
            level = lv if isinstance(lv, Level) else Level(entries=tuple(lv))
            if not level.name:
                level.name = f"level {i}"
            self.levels.append(level)
        self.constraints = list(constraints)
        nu = robot.nu
        if metric is None:
            self.metric = np.ones(nu)
        else:
            self.metric = np.asarray(metric, dtype=float)
            if (
                self.metric.shape != (nu,)
                or not np.all(np.isfinite(self.metric))
                or np.any(self.metric <= 0)
            ):
                raise DimensionError(
                    f"stack metric must be {nu} finite positive weights, got {metric!r}"
                )
        self.scale = 1.0 / np.sqrt(self.metric)
        self._check_entries()
        self._allocate()

    # ------------------------------------------------------------------ checks
    def _check_entries(self) -> None:
        if not self.levels:
            raise WholebodyError("a stack needs at least one level")
        seen: dict[str, str] = {}
        for level in self.levels:
            if not level.entries:
                raise WholebodyError(f"stack {level.name!r} is empty")
            for e in level.entries:
                if not isinstance(e, (Task, InequalityTask, Objective)):
                    raise WholebodyError(
                        f"{level.name}: {e!r} is not a Task, InequalityTask or Objective"
                    )
                if e.name in seen:
                    raise WholebodyError(
                        f"two stack entries are named {e.name!r} ({seen[e.name]} and "
                        f"{level.name}): names must be unique"
                    )
                seen[e.name] = level.name
            if level.objectives and not np.isfinite(level.gain):
                raise WholebodyError(f"{level.name}: gain must be finite, got {level.gain}")
        for c in self.constraints:
            if not isinstance(c, Constraint):
                raise WholebodyError(f"{c!r} is not a Constraint")

    def _allocate(self) -> None:
        nu = self.robot.nu
        self._buffers: list[LevelProblem] = []
        for level in self.levels:
            rows, k = {}, 0
            for t in level.tasks:
                rows[t.name] = slice(k, k + t.dim)
                k += t.dim
            if level.objectives:
                rows["objectives"] = slice(k, k + nu)
                k += nu
            irows, p = {}, 0
            for t in level.inequalities:
                irows[t.name] = slice(p, p + t.dim)
                p += t.dim
            self._buffers.append(
                LevelProblem(level.name, np.zeros((k, nu)), np.zeros(k), np.zeros((p, nu)),
                             np.zeros(p), np.zeros(p), rows, irows)
            )  # fmt: skip
        self._lower = np.empty(nu)
        self._upper = np.empty(nu)

    # ------------------------------------------------------------------ use
    @property
    def tasks(self) -> list[Task]:
        """All equality tasks, highest priority first."""
        return [t for level in self.levels for t in level.tasks]

    @property
    def objectives(self) -> list[Objective]:
        return [o for level in self.levels for o in level.objectives]

    def evaluate(self, state: RobotState, dt: float) -> StackProblem:
        """Rows of every level and the box at ``state`` for a step of ``dt`` s (scaled
        coordinates, see the module docstring)."""
        if not dt > 0:
            raise DimensionError(f"control step dt must be > 0 s, got {dt}")
        D = self.scale
        values: dict[str, ObjectiveValue] = {}
        for level, buf in zip(self.levels, self._buffers, strict=True):
            for t in level.tasks:
                r = t.compute(state)
                sl = buf.task_rows[t.name]
                sw = np.sqrt(r.weights)
                np.multiply(r.J * sw[:, None], D, out=buf.A[sl])
                np.multiply(r.v, sw, out=buf.b[sl])
            if level.objectives:
                grad = np.zeros(self.robot.nu)
                curv = None
                for o in level.objectives:
                    val = o.evaluate(state)
                    values[o.name] = val
                    grad += o.weight * val.gradient
                    if val.curvature is not None and o.weight > 0:
                        curv = o.weight * val.curvature + (0.0 if curv is None else curv)
                sl = buf.task_rows["objectives"]
                sw = np.sqrt(level.objective_weight)
                np.fill_diagonal(buf.A[sl], sw)
                if not level.tasks:
                    buf.identity_scale = float(sw)
                # u0 = -k W^-1 grad / (1 + k dt W^-1 curv); rows in u~: D^-1 u0 = -k D grad / ...
                step = -level.gain * sw * D * grad
                if curv is not None:
                    step /= 1.0 + level.gain * dt * (D * D) * curv
                buf.b[sl] = step
            for t in level.inequalities:
                r = t.compute(state, dt)
                sl = buf.inequality_rows[t.name]
                np.multiply(r.C, D, out=buf.C[sl])
                buf.lower[sl] = r.lower
                buf.upper[sl] = r.upper
        self._lower.fill(-np.inf)
        self._upper.fill(np.inf)
        for c in self.constraints:
            b = c.bounds(state, dt)
            np.maximum(self._lower, b.lower, out=self._lower)
            np.minimum(self._upper, b.upper, out=self._upper)
        # Where position recovery and velocity limits disagree (a state outside its limits
        # asks for more than the joint's speed), the velocity limit wins: move back at full
        # speed rather than declare the box empty.
        crossed = self._lower > self._upper
        if np.any(crossed):
            mid = np.where(self._lower[crossed] > 0, self._upper[crossed], self._lower[crossed])
            self._lower[crossed] = mid
            self._upper[crossed] = mid
        return StackProblem(self._buffers, self._lower / D, self._upper / D, D, values)

    def advance(self, state: RobotState, dt: float, saturated: bool = False) -> None:
        """Advance every task's internal state (PI integrals) by one step."""
        for t in self.tasks:
            t.advance(state, dt, saturated)

    def reset(self) -> None:
        """Reset every task's internal state."""
        for t in self.tasks:
            t.reset()

    def __repr__(self) -> str:
        parts = [f"{lv.name}: [{', '.join(e.name for e in lv.entries)}]" for lv in self.levels]
        return f"Stack({'; '.join(parts)}; constraints: {[c.name for c in self.constraints]})"
