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

Evaluation: the stack is compiled for the kernels (:mod:`wholebody.solvers.plan`): every
entry packs itself into one arena, and one kernel call computes every row, gradient and box.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wholebody.errors import DimensionError, WholebodyError
from wholebody.kernels import layout as lay
from wholebody.kernels.advance import ADVANCE_FLAGS, ADVANCE_MEMORY, ADVANCE_TASKS, advance
from wholebody.kernels.evaluate import evaluate
from wholebody.robot import Robot, RobotState
from wholebody.solvers.plan import LEVEL_SETTINGS, NO_REFERENCES, Plan, first_call
from wholebody.solvers.result import SolverResult
from wholebody.tasks.base import InequalityTask, Limit, Objective, ObjectiveValue, Task

__all__ = ["OBJECTIVES", "Level", "LevelProblem", "Stack", "StackProblem"]

Entry = Task | InequalityTask | Objective

OBJECTIVES = "objectives"
"""The name of a level's objective rows in :attr:`LevelProblem.task_rows`."""


_ENTRIES = operator.attrgetter("entries")


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

    def __setattr__(self, name: str, value: object) -> None:
        # entries are kept as a tuple: a new set of entries is a new object, which the stack
        # notices (it lays its buffers out again), and cannot change behind its back
        if name == "entries":
            value = tuple(value)  # type: ignore[arg-type]
        elif name in ("gain", "objective_weight"):
            LEVEL_SETTINGS[0] += 1  # (a plan rewrites its levels' numbers when this moves)
        object.__setattr__(self, name, value)

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
    unweight: np.ndarray | None = None
    """Per row of ``A``, ``1 / sqrt(w)`` of its task's weight (0 where ``w = 0``), to report
    unweighted task residuals; None: the rows are not weighted."""
    reference_scale: float = 1.0
    """``sqrt(w_min)``, the smallest positive weight of the level's task rows (1 without
    any): a scale-dependent decision (the projection's damping threshold) is taken on
    ``A / reference_scale``, so that a weight common to the level's tasks changes nothing and
    a task is never judged in the units of a heavier one."""
    _names: list[str] = field(init=False, repr=False)
    _sums: np.ndarray = field(init=False, repr=False)
    _starts: np.ndarray = field(init=False, repr=False)
    _work: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        # The tasks' rows tile the top of A (the objectives' rows, if any, come last).
        rows = sorted(
            (sl.start, sl.stop, nm)
            for nm, sl in self.task_rows.items()
            if nm != OBJECTIVES and sl.stop > sl.start
        )
        self._names = [nm for _, _, nm in rows]
        ends = [0, *(stop for _, stop, _ in rows)][: len(rows)]
        if any(start != end for (start, _, _), end in zip(rows, ends, strict=True)):
            raise WholebodyError(f"{self.name}: the tasks' rows must tile the top of A")
        k = self.A.shape[0]
        # column i sums the rows of task i, the last column every row
        self._sums = np.zeros((k, len(rows) + 1))
        for i, (start, stop, _) in enumerate(rows):
            self._sums[start:stop, i] = 1.0
        self._sums[:, -1] = 1.0
        self._starts = np.array([start for start, _, _ in rows], dtype=np.intp)
        self._work = np.empty((3, k))

    @property
    def has_equalities(self) -> bool:
        return self.A.shape[0] > 0

    def task_residuals(self, r: np.ndarray) -> list[tuple[str, float, float, float]]:
        """``(task, ||r_t||, ||r_t|| unweighted, ||b_t||)`` of each equality task (the
        objectives' rows left out) for the residual ``r = A u~ - b`` of this level."""
        self._work[0] = r
        return self._report()[1]

    def residual_report(self, x: np.ndarray) -> tuple[float, list[tuple[str, float, float, float]]]:
        """``||A x - b||`` and :meth:`task_residuals` of ``r = A x - b``."""
        r = self._work[0]
        np.dot(self.A, x, out=r)
        r -= self.b
        return self._report()

    def _report(self) -> tuple[float, list[tuple[str, float, float, float]]]:
        """From ``r`` in the first row of the work array: the norms of ``r`` over all rows and,
        per task, of ``r``, of the unweighted ``r`` and of ``b`` (their squares summed in one
        product with the task-sum matrix)."""
        work = self._work
        if self.unweight is None:
            work[1] = work[0]
        else:
            np.multiply(work[0], self.unweight, out=work[1])
        work[2] = self.b
        work *= work
        weighted, plain, b = work.dot(self._sums).tolist()
        if not math.isfinite(weighted[-1] + plain[-1] + b[-1]) and self._names:
            # a NaN or inf row: 0 * inf in the product would spill it into every task; sum
            # each task's own rows instead
            n = int(self._sums[:, :-1].sum())  # the task rows (the objectives' come last)
            totals = (weighted[-1], plain[-1], b[-1])
            parts = np.add.reduceat(work[:, :n], self._starts, axis=1).tolist()
            weighted, plain, b = ([*row, t] for row, t in zip(parts, totals, strict=True))
        sqrt = math.sqrt
        return sqrt(weighted[-1]), [
            (name, sqrt(w), sqrt(p), sqrt(bb))
            for name, w, p, bb in zip(self._names, weighted, plain, b)  # noqa: B905 (sums: +1)
        ]


@dataclass
class StackProblem:
    """All levels at one state, with the box ``lower <= u~ <= upper`` and ``u = scale * u~``."""

    levels: list[LevelProblem]
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    objective_values: dict[str, ObjectiveValue]
    anchor: np.ndarray | None = None
    """Scaled velocity the projection's saturation scales motions around (clipped to the
    box): the last step's velocity when the stack has acceleration limits (whose box is
    centred on it), else None (0, the textbook choice)."""

    def to_u(self, u_scaled: np.ndarray) -> np.ndarray:
        """Actuated velocity from the scaled one."""
        return self.scale * u_scaled

    def residuals(
        self, u_scaled: np.ndarray, tol: float, failed: Sequence[int] = ()
    ) -> tuple[np.ndarray, dict[str, float], list[tuple[str, str]]]:
        """At ``u~``: each level's weighted residual ``||A u~ - b||``, each task's unweighted
        residual ``||J u - v||``, and the ``(level, task)`` pairs whose weighted residual
        exceeds ``tol (1 + ||b_t||)`` (every task of the levels listed in ``failed``)."""
        levels = self.levels
        level_res = np.zeros(len(levels))
        task_res: dict[str, float] = {}
        infeasible: list[tuple[str, str]] = []
        for i, lev in enumerate(levels):
            if not lev.A.shape[0]:
                continue
            level_res[i], tasks = lev.residual_report(u_scaled)
            skipped = i in failed
            for name, weighted, plain, b in tasks:
                task_res[name] = plain
                if skipped or not weighted <= tol * (1.0 + b):  # (a NaN residual too)
                    infeasible.append((lev.name, name))
        return level_res, task_res, infeasible


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
        constraints: Iterable[Limit] = (),
        metric: np.ndarray | Sequence[float] | None = None,
    ) -> None:
        self.robot = robot
        self.levels: list[Level] = [
            lv if isinstance(lv, Level) else Level(entries=lv) for lv in levels
        ]
        self.constraints = list(constraints)
        self._scale_version = 0
        self.metric = np.ones(robot.nu) if metric is None else metric
        self._plan: Plan | None = None
        self._check_entries()

    @property
    def metric(self) -> np.ndarray:
        """The metric ``W`` (read-only; assign a new one to change it)."""
        return self._metric

    @metric.setter
    def metric(self, value: np.ndarray | Sequence[float]) -> None:
        nu = self.robot.nu
        m = np.array(value, dtype=float)
        if m.shape != (nu,) or not np.all(np.isfinite(m)) or np.any(m <= 0):
            raise DimensionError(
                f"stack metric must be {nu} finite positive weights, got {value!r}"
            )
        scale = 1.0 / np.sqrt(m)
        m.setflags(write=False)
        scale.setflags(write=False)
        self._metric, self._scale = m, scale
        self._scale_sq = scale * scale
        self._scale_version += 1

    @property
    def scale(self) -> np.ndarray:
        """``D = W^(-1/2)``, ``u = D u~`` (read-only; follows :attr:`metric`)."""
        return self._scale

    # ------------------------------------------------------------------ checks
    def _check_entries(self) -> None:
        if not self.levels:
            raise WholebodyError("a stack needs at least one level")
        seen: dict[str, str] = {}
        for i, level in enumerate(self.levels):
            if not isinstance(level, Level):
                raise WholebodyError(f"stack level {i} is not a Level: {level!r}")
            if not level.name:
                level.name = f"level {i}"
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
            if level.objectives and not 0.0 <= level.objective_weight < np.inf:
                raise WholebodyError(
                    f"{level.name}: objective_weight must be finite and >= 0, "
                    f"got {level.objective_weight}"
                )
        for c in self.constraints:
            if not isinstance(c, Limit):
                raise WholebodyError(f"{c!r} is not a Limit")

    def _relayout(self) -> None:
        self._check_entries()
        self._plan = None

    def _check_layout(self) -> None:
        """Lay the stack out anew where levels, their entries or the limits were replaced."""
        plan = self._plan
        if plan is None:
            return
        levels, limits = self.levels, self.constraints
        if not (
            len(levels) == len(plan.levels)
            and len(limits) == len(plan.constraints)
            and all(map(operator.is_, levels, plan.levels))
            and all(map(operator.is_, map(_ENTRIES, levels), plan.entries))
            and all(map(operator.is_, limits, plan.constraints))
        ):
            self._relayout()

    @property
    def current_plan(self) -> Plan | None:
        """The plan of the last compiled evaluation, if any (:meth:`plan` lays one out)."""
        return self._plan

    def plan(self) -> Plan:
        """The stack compiled for the kernels (:mod:`wholebody.solvers.plan`), laid out at the
        first use and again whenever levels, entries or limits were replaced."""
        self._check_layout()
        plan = self._plan
        if plan is None or plan.stale:
            plan = self._plan = Plan(self)
        return plan

    def synced_plan(self, state: RobotState, dt: float) -> Plan:
        """The plan with everything Python owns written for a step of ``dt`` s at ``state``
        (laid out anew first where an entry changed shape)."""
        if not dt > 0:
            raise DimensionError(f"control step dt must be > 0 s, got {dt}")
        plan = self.plan()
        plan.sync(state, dt)
        if plan.stale:
            plan = self.plan()
            plan.sync(state, dt)
        return plan

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
        coordinates, see the module docstring), by the compiled plan. The arrays are views of
        the plan's arena that the next evaluation overwrites."""
        plan = self.evaluated_plan(state, dt)
        problem = plan.problem()
        problem.objective_values = plan.objective_values()
        return problem

    def evaluated_plan(self, state: RobotState, dt: float) -> Plan:
        """Evaluate every row and the box at ``state`` as :meth:`evaluate` does, and return
        the plan whose arena holds them (its regions ``F_A``, ``F_B``, ``F_C``, ... of
        :mod:`wholebody.kernels.layout`), without building the :class:`StackProblem`: what a
        kernel that reads the rows takes (the torque level)."""
        plan = self.synced_plan(state, dt)
        first_call(
            "evaluate", "the control kernels", evaluate, *plan.kernel_args(state), NO_REFERENCES
        )
        plan.evaluated = state.stamp
        return plan

    def advance(
        self,
        state: RobotState,
        dt: float,
        saturated: bool | None = None,
        u: np.ndarray | None = None,
        *,
        result: SolverResult | None = None,
    ) -> None:
        """Advance every task's internal state (the PI integrals) by one step of ``dt`` s,
        after the step was solved at ``state``, and tell the constraints the velocity ``u``
        that was applied (when given).

        ``result``: the solve of this step. Each task's anti-windup then follows its own
        saturation (:meth:`saturated_tasks`: a bound that limits that task, not just any
        bound), and ``u`` defaults to ``result.u``. ``saturated``: instead, one flag for every
        task (``result.limit_hit`` freezes every integral whenever any entry of ``u`` sits on
        a bound, e.g. a joint resting at 0 on its limit that no task uses). Give one or the
        other.
        """
        if result is not None and saturated is not None:
            raise WholebodyError(
                "Stack.advance: give result= (per-task anti-windup) or "
                "saturated= (one flag for every task), not both"
            )
        plan = self._evaluated_plan(state, dt)
        what = ADVANCE_TASKS
        if result is not None:
            self._outcome(plan, result)
            what |= ADVANCE_FLAGS
            if u is None:
                u = result.u
        else:
            plan.view(lay.I_SATURATED)[:] = bool(saturated)
        if u is not None:
            plan.view(lay.F_U)[1] = u
            what |= ADVANCE_MEMORY
        first_call(
            "advance", "the control kernels", advance, plan.f, plan.i, plan.h, float(dt), what
        )
        plan.advance_python(state, dt, u)

    def _evaluated_plan(self, state: RobotState, dt: float) -> Plan:
        """The plan, its rows evaluated at ``state`` (evaluated now if they are not)."""
        plan = self._plan
        if plan is None or plan.evaluated != state.stamp:
            self.evaluate(state, dt)
            plan = self._plan
        return plan  # type: ignore[return-value]

    def _last_dt(self) -> float:
        """The step (s) of the last evaluation; 0.01 s before any (what it changes, the
        limits' boxes, does not enter the flags)."""
        plan = self._plan
        dt = 0.0 if plan is None else float(plan.view(lay.F_SCALARS)[0])
        return dt if dt > 0 else 0.01

    @staticmethod
    def _outcome(plan: Plan, result: SolverResult) -> None:
        """``result`` into the plan's outcome regions unless it is the plan's own last."""
        if plan.last_result is not result:
            plan.write_result(result)

    def saturated_tasks(self, state: RobotState, result: SolverResult) -> dict[str, bool]:
        """Per equality task (by name), whether the hard constraints limited it in the solve
        ``result`` at ``state``, which is what its anti-windup needs: its level's motion was
        scaled (``result.scale[level] < 1``, projection), or an active bound
        (``result.active_bounds``) is on an entry of ``u`` that the task's rows move (a
        column of its rows not 0: a joint no task row uses may rest on its limit without
        stopping any integral), or the task is reported unmet (``result.infeasible``)
        (:mod:`wholebody.kernels.advance`)."""
        plan = self._evaluated_plan(state, self._last_dt())
        self._outcome(plan, result)
        first_call(
            "advance", "the control kernels", advance, plan.f, plan.i, plan.h, 1.0, ADVANCE_FLAGS
        )
        flags = plan.view(lay.I_SATURATED).tolist()
        return {r.entry.name: bool(flags[r.slot]) for r in plan.tasks}

    def set_velocity(self, u: np.ndarray, dt: float) -> None:
        """The velocity the robot moves at (applied for the last ``dt`` s): the constraints
        with a memory (acceleration limits) keep it."""
        for c in self.constraints:
            c.advance(u, dt)

    def reset(self) -> None:
        """Reset every task's and constraint's internal state."""
        for t in self.tasks:
            t.reset()
        for c in self.constraints:
            c.reset()

    def __repr__(self) -> str:
        parts = [f"{lv.name}: [{', '.join(e.name for e in lv.entries)}]" for lv in self.levels]
        return f"Stack({'; '.join(parts)}; constraints: {[c.name for c in self.constraints]})"
