"""The stack's contract with its users and with both solvers: layout changes, validation,
degenerate boxes and rows, and the reports (status, infeasible tasks) of both backends."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wholebody.errors import DimensionError, WholebodyError
from wholebody.solvers import Level, ProjectionSolver, SolverStatus, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.stack import LevelProblem, StackProblem
from wholebody.tasks import (
    ArmPotentialEnergy,
    Bounds,
    FrameTask,
    JointPositionLimits,
    Limit,
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


class NaNBox(Limit):
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


def test_hqp_reports_a_violated_inequality_below_a_level_that_used_all_freedom(humanoid):
    """The energy level (rows s I) leaves no freedom: the half-space below it cannot be met
    and must be reported, not dropped."""
    state = humanoid.update(humanoid.home())
    left, right = holding(humanoid, state, "left_tool"), holding(humanoid, state, "right_tool")
    above = FrameHalfSpace(
        humanoid, "left_tool", [0.0, 0.0, 1.0], state.position(left.frame)[2] + 0.2
    )
    energy = Level([ArmPotentialEnergy(humanoid, "left", 0.1)])
    stack = Stack(humanoid, [[left, right], energy, [above]], limits(humanoid))
    solver = HierarchicalQPSolver()
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
    assert [lv.name for lv in stack.evaluate(state, DT).levels] == ["level 0", "level 1", "level 2"]
    assert set(solver().solve(stack, state, DT).task_residuals) == {
        left.name,
        "p2",
        "right_tool_task",
    }


def test_objective_weight_and_task_weights_are_checked(humanoid):
    energy = ArmPotentialEnergy(humanoid, "left", 0.1)
    with pytest.raises(WholebodyError, match="objective_weight"):
        Stack(humanoid, [Level([energy], objective_weight=-1.0)])
    state = humanoid.update(humanoid.home())
    for bad in (-1.0, np.nan, "heavy", True, [[1.0]]):  # refused when the task is made
        with pytest.raises(DimensionError, match="posture: weight"):
            PostureTask(humanoid, weight=bad)
    stack = Stack(humanoid, [[PostureTask(humanoid, weight=[1.0, 2.0])]])  # 2 of 19 rows
    with pytest.raises(DimensionError, match="posture: weight"):
        stack.evaluate(state, DT)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e300])
def test_a_non_finite_task_leaves_the_other_tasks_residuals_alone(bad):
    # one product sums every task's squares: a NaN or inf row must not spill into the others
    A = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    b = np.array([1.0, 1.0, bad])
    level = LevelProblem(
        "level",
        A,
        b,
        np.zeros((0, 2)),
        np.zeros(0),
        np.zeros(0),
        {"good": slice(0, 2), "bad": slice(2, 3)},
    )
    x = np.array([0.5, -0.5])
    problem = StackProblem([level], -np.ones(2), np.ones(2), np.ones(2), {})
    with np.errstate(over="ignore", invalid="ignore"):
        _, residuals, _ = problem.residuals(x, 1e-6)
    assert residuals["good"] == pytest.approx(np.linalg.norm(A[:2] @ x - b[:2]), rel=1e-15)
    assert not np.isfinite(residuals["bad"])


class PinnedJoint(Limit):
    """A joint held at rest (a locked motor): its velocity bounds are both 0."""

    name = "pinned_joint"

    def __init__(self, robot, joint: str) -> None:
        self.lower, self.upper = np.full(robot.nu, -np.inf), np.full(robot.nu, np.inf)
        self.lower[robot.index(joint)] = self.upper[robot.index(joint)] = 0.0

    def bounds(self, state, dt):
        return Bounds(self.lower, self.upper)


def two_hands(robot, q, ki=5.0):
    """Right hand above left hand, each with a PI integral and a target 2 cm off."""
    state = robot.update(q)
    right = FrameTask(robot, "right_tool", kp=5.0, ki=ki)
    left = FrameTask(robot, "left_tool", kp=5.0, ki=ki)
    for task, offset in ((right, (0.02, 0.0, 0.0)), (left, (0.0, 0.0, 0.02))):
        T = state.pose(task.frame).copy()
        T[:3, 3] += offset
        task.set_target(T)
    return right, left


@pytest.mark.parametrize("solver", SOLVERS)
def test_anti_windup_stops_only_the_integrals_of_the_tasks_a_bound_limits(humanoid, solver):
    """The left elbow is pinned at rest: a bound is active at every step. The right hand's
    rows do not move that joint, so its integral keeps integrating; the left hand's do, so
    its integral stays frozen at 0. (One flag for all, ``result.limit_hit``, froze both.)"""
    q = humanoid.home()
    right, left = two_hands(humanoid, q)
    stack = Stack(
        humanoid,
        [Level([right], name="right"), Level([left], name="left")],
        [PinnedJoint(humanoid, "left_elbow_flexion"), *limits(humanoid)],
    )
    elbow = humanoid.index("left_elbow_flexion")
    s = solver()
    for _ in range(20):
        state = humanoid.update(q)
        result = s.solve(stack, state, DT)
        assert elbow in result.active_bounds and result.limit_hit
        assert stack.saturated_tasks(state, result) == {"right_tool": False, "left_tool": True}
        stack.advance(state, DT, result=result)
        q = humanoid.integrate(q, result.u, DT)
    assert np.abs(right.integral[:3]).max() > 1e-4  # 20 steps of a ~1 cm error
    assert not np.any(left.integral)


def test_advance_keeps_the_single_flag_and_refuses_both_forms(humanoid):
    q = humanoid.home()
    right, left = two_hands(humanoid, q)
    stack = Stack(humanoid, [[right], [left]], [PinnedJoint(humanoid, "left_elbow_flexion")])
    state = humanoid.update(q)
    result = ProjectionSolver().solve(stack, state, DT)
    with pytest.raises(WholebodyError, match="not both"):
        stack.advance(state, DT, saturated=True, result=result)
    stack.advance(state, DT, result.limit_hit)  # the older form: every integral frozen
    assert not np.any(right.integral) and not np.any(left.integral)
    stack.advance(state, DT, False)
    assert np.any(right.integral) and np.any(left.integral)


def test_a_task_is_saturated_when_its_level_is_scaled_or_it_is_unmet(humanoid):
    """Without an active bound on its joints a task still counts as limited when the
    projection scaled its level or the solve left it unmet; the rows are the tasks' own
    when the stack was not evaluated at that state."""
    q = humanoid.home()
    right, left = two_hands(humanoid, q)
    stack = Stack(humanoid, [Level([right], name="right"), Level([left], name="left")])
    state = humanoid.update(q)
    result = ProjectionSolver().solve(stack, state, DT)
    assert stack.saturated_tasks(state, result) == {"right_tool": False, "left_tool": False}
    scaled = dataclasses.replace(result, scale=np.array([1.0, 0.5]))
    assert stack.saturated_tasks(state, scaled) == {"right_tool": False, "left_tool": True}
    unmet = dataclasses.replace(result, infeasible=[("right", "right_tool")])
    assert stack.saturated_tasks(state, unmet) == {"right_tool": True, "left_tool": False}
    other = humanoid.update(q)  # not evaluated: the rows are computed
    for joint, expected in (("waist_yaw", True), ("left_wrist_rotation", False)):
        active = dataclasses.replace(result, active_bounds=np.array([humanoid.index(joint)]))
        assert stack.saturated_tasks(other, active) == {"right_tool": expected, "left_tool": True}


def test_the_status_has_one_meaning_for_both_backends(humanoid):
    """The left elbow rests on its upper limit and the posture level under the hands asks
    it to go 0.3 rad further: the box, not the hands, keeps that level from its optimum,
    and both backends say INFEASIBLE (the projection, which re-solves the level around the
    saturated joint without scaling it, said BOUNDS_ACTIVE). Without the box the hands
    alone keep the posture from its target: OK for both. With a bound active that costs no
    level anything: BOUNDS_ACTIVE for both."""
    elbow = humanoid.index("left_elbow_flexion")
    home = dict(
        zip(
            humanoid.actuated_joints[4:], humanoid.joint_positions(humanoid.home())[4:], strict=True
        )
    )
    q = humanoid.configuration({**home, "left_elbow_flexion": humanoid.position_limits[1][elbow]})
    state = humanoid.update(q)
    hands = [holding(humanoid, state, frame) for frame in ("left_tool", "right_tool")]
    posture = PostureTask(humanoid, humanoid.actuated_joints[4:], kp=1.0)
    beyond = humanoid.joint_positions(q)[4:]
    beyond[elbow - 4] += 0.3

    def statuses(target, constraints):
        posture.set_target(target)
        stack = Stack(
            humanoid, [Level(hands, name="hands"), Level([posture], name="posture")], constraints
        )
        results = [solver().solve(stack, state, DT) for solver in SOLVERS]
        for r in results:
            assert not any(level == "hands" for level, _ in r.infeasible)  # the hands are met
        return [r.status for r in results], results

    limited, (projection, _) = statuses(beyond, limits(humanoid))
    assert limited == [SolverStatus.INFEASIBLE] * 2
    assert np.all(projection.scale == 1.0) and elbow in projection.active_bounds
    assert ("posture", "posture") in projection.infeasible
    free, results = statuses(beyond, [])
    assert free == [SolverStatus.OK] * 2
    assert all(("posture", "posture") in r.infeasible for r in results)
    resting, results = statuses(humanoid.joint_positions(q)[4:], limits(humanoid))
    assert resting == [SolverStatus.BOUNDS_ACTIVE] * 2
    assert all(elbow in r.active_bounds for r in results)
