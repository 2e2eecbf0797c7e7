"""The stack's contract with its users and with both solvers: layout changes, validation,
degenerate boxes and rows, and the reports (status, infeasible tasks) of both backends."""

from __future__ import annotations

import numpy as np
import pytest

from wholebody.errors import DimensionError, WholebodyError
from wholebody.solvers import Level, ProjectionSolver, SolverStatus, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.stack import LevelProblem, StackProblem
from wholebody.tasks import (
    ArmPotentialEnergy,
    Bounds,
    Constraint,
    FrameTask,
    JointPositionLimits,
    PostureTask,
    TaskRows,
    VelocityLimits,
)
from wholebody.tasks.base import Task
from wholebody.tasks.inequality import FrameHalfSpace

DT = 0.01
SOLVERS = [ProjectionSolver, HierarchicalQPSolver]


def limits(robot):
    return [JointPositionLimits(robot), VelocityLimits(robot)]


def holding(robot, state, frame, lift=0.0):
    task = FrameTask(robot, frame, name=f"{frame}_task")
    T = state.pose(task.frame).copy()
    T[2, 3] += lift
    task.set_target(T)
    return task


class NaNBox(Constraint):
    """A user constraint whose box has a NaN bound."""

    name = "nan_box"

    def __init__(self, nu: int) -> None:
        self.nu = nu

    def bounds(self, state, dt):
        lower = -np.ones(self.nu)
        lower[3] = np.nan
        return Bounds(lower, np.ones(self.nu))


class NaNTask(Task):
    """Rows with a NaN target (a broken user task)."""

    name, weight = "nan_task", 1.0

    def __init__(self, nu: int) -> None:
        self.nu = nu

    @property
    def dim(self) -> int:
        return 2

    def compute(self, state):
        J = np.zeros((2, self.nu))
        J[0, 5] = J[1, 6] = 1.0
        return TaskRows(J, np.array([np.nan, 0.0]), 1.0)


@pytest.mark.parametrize("solver", SOLVERS)
def test_a_nan_box_gives_u_zero_and_failed(humanoid, solver):
    state = humanoid.update(humanoid.home())
    stack = Stack(humanoid, [[PostureTask(humanoid)]], [NaNBox(humanoid.nu)])
    result = solver().solve(stack, state, DT)
    assert result.status == SolverStatus.FAILED
    assert np.array_equal(result.u, np.zeros(humanoid.nu))
    assert "NaN" in result.message


def test_projection_fallback_after_non_finite_rows_is_failed(humanoid):
    state = humanoid.update(humanoid.home())
    stack = Stack(humanoid, [[NaNTask(humanoid.nu)]], limits(humanoid))
    result = ProjectionSolver().solve(stack, state, DT)
    assert result.status == SolverStatus.FAILED and np.all(np.isfinite(result.u))
    assert "non-finite" in result.message


@pytest.mark.parametrize("method", ["native", "cascade"])
def test_hqp_reports_a_violated_inequality_below_a_level_that_used_all_freedom(humanoid, method):
    """The energy level (rows s I) leaves no freedom: the half-space below it cannot be met
    and must be reported, not dropped."""
    state = humanoid.update(humanoid.home())
    left, right = holding(humanoid, state, "left_tool"), holding(humanoid, state, "right_tool")
    above = FrameHalfSpace(humanoid, "left_tool", [0.0, 0.0, 1.0],
                           state.position(left.frame)[2] + 0.2)  # fmt: skip
    energy = Level([ArmPotentialEnergy(humanoid, "left", 0.1)])
    stack = Stack(humanoid, [[left, right], energy, [above]], limits(humanoid))
    solver = HierarchicalQPSolver(method=method)
    result = solver.solve(stack, state, DT)
    assert solver.levels[2].free == 0
    assert result.status == SolverStatus.INFEASIBLE
    assert ("level 2", above.name) in result.infeasible


@pytest.mark.parametrize("weight", [1.0, 1e-4])
def test_an_objectives_only_level_does_not_depend_on_its_weight_under_bounds(humanoid, weight):
    """Rows ``s I``: the move is ``b / s`` with or without saturation (no damping of s)."""
    state = humanoid.update(humanoid.random_configuration(np.random.default_rng(0), margin=0.1))

    def solve(w):
        level = Level([ArmPotentialEnergy(humanoid, "left", 1.0)], gain=0.5, objective_weight=w)
        return ProjectionSolver().solve(Stack(humanoid, [level], limits(humanoid)), state, DT)

    reference, result = solve(1.0), solve(weight)
    assert reference.status == SolverStatus.SCALED  # the bounds bite
    np.testing.assert_allclose(result.u, reference.u, atol=1e-12)
    assert result.status == reference.status


def test_entries_are_a_tuple_and_a_replacement_is_laid_out_again(humanoid):
    state = humanoid.update(humanoid.home())
    left = holding(humanoid, state, "left_tool")
    right = holding(humanoid, state, "right_tool", lift=0.05)
    level = Level([left])
    stack = Stack(humanoid, [level], limits(humanoid))
    assert ProjectionSolver().solve(stack, state, DT).task_residuals.keys() == {left.name}
    assert isinstance(level.entries, tuple)
    with pytest.raises(AttributeError):
        level.entries.append(right)  # type: ignore[attr-defined]
    level.entries = [left, right]
    result = ProjectionSolver().solve(stack, state, DT)
    assert result.task_residuals.keys() == {left.name, right.name}
    assert np.abs(result.u).max() > 1e-3  # the right hand is asked to rise


@pytest.mark.parametrize("solver", SOLVERS)
def test_added_and_replaced_levels_are_laid_out_and_named(humanoid, solver):
    state = humanoid.update(humanoid.home())
    left = holding(humanoid, state, "left_tool")
    stack = Stack(humanoid, [[left], [PostureTask(humanoid)]], limits(humanoid))
    solver().solve(stack, state, DT)
    stack.levels[1] = Level([PostureTask(humanoid, name="p2")])
    stack.levels.append(Level([holding(humanoid, state, "right_tool")]))
    assert [lv.name for lv in stack.evaluate(state, DT).levels] == ["level 0", "level 1",
                                                                    "level 2"]  # fmt: skip
    assert set(solver().solve(stack, state, DT).task_residuals) == {left.name, "p2",
                                                                   "right_tool_task"}  # fmt: skip


def test_objective_weight_and_task_weights_are_checked(humanoid):
    energy = ArmPotentialEnergy(humanoid, "left", 0.1)
    with pytest.raises(WholebodyError, match="objective_weight"):
        Stack(humanoid, [Level([energy], objective_weight=-1.0)])
    state = humanoid.update(humanoid.home())
    for bad in (-1.0, np.nan, [1.0, 2.0]):
        stack = Stack(humanoid, [[PostureTask(humanoid, weight=bad)]])
        with pytest.raises(DimensionError, match="posture: weight"):
            stack.evaluate(state, DT)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e300])
def test_a_non_finite_task_leaves_the_other_tasks_residuals_alone(bad):
    # one product sums every task's squares: a NaN or inf row must not spill into the others
    A = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    b = np.array([1.0, 1.0, bad])
    level = LevelProblem("level", A, b, np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                         {"good": slice(0, 2), "bad": slice(2, 3)})  # fmt: skip
    x = np.array([0.5, -0.5])
    problem = StackProblem([level], -np.ones(2), np.ones(2), np.ones(2), {})
    with np.errstate(over="ignore", invalid="ignore"):
        _, residuals, _ = problem.residuals(x, 1e-6)
    assert residuals["good"] == pytest.approx(np.linalg.norm(A[:2] @ x - b[:2]), rel=1e-15)
    assert not np.isfinite(residuals["bad"])
