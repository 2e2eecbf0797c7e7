"""``SolverResult.report()``: the solve in words, checked on real solves."""

from __future__ import annotations

import numpy as np
import pytest

import wholebody as wb
from wholebody.solvers.unmet import UnmetCause

ROBOT = wb.load_robot("mobile_humanoid")
LIMITS = (wb.JointPositionLimits, wb.VelocityLimits)


def _limits() -> list:
    return [c(ROBOT) for c in LIMITS]


@pytest.mark.parametrize("solver", [wb.ProjectionSolver(), wb.HierarchicalQPSolver()])
def test_a_met_solve_reads_met_with_its_errors_and_no_active_limit(solver):
    hand = wb.FrameTask(ROBOT, "right_tool", kp=1.0)
    stack = wb.Stack(ROBOT, [[hand], [wb.PostureTask(ROBOT)]], _limits())
    q = ROBOT.home()
    goal = ROBOT.frame_pose(q, "right_tool")
    goal[:3, 3] += (0.01, 0.0, 0.0)
    hand.set_target(goal)
    result = solver.solve(stack, ROBOT.update(q), 0.01)
    text = result.report()
    assert str(result) == text
    line = next(x for x in text.splitlines() if x.strip().startswith("right_tool:"))
    assert "met" in line and "UNMET" not in line and "10.000 mm" in line, text
    assert "active limits: none" in text
    assert result.causes()["right_tool"] == UnmetCause.MET


@pytest.mark.parametrize("solver", [wb.ProjectionSolver(), wb.HierarchicalQPSolver()])
def test_a_joint_at_its_limit_is_named_with_its_bound_and_the_cause(solver):
    joint = "right_elbow_flexion"
    j = ROBOT.actuated_joints.index(joint)
    upper = ROBOT.position_limits[1][j]
    elbow = wb.PostureTask(ROBOT, [joint], name="elbow", target=[upper + 0.3], kp=2.0)
    stack = wb.Stack(ROBOT, [[elbow], [wb.PostureTask(ROBOT)]], _limits())
    controller = wb.Controller(ROBOT, stack, solver, dt=0.01)
    q = ROBOT.home()
    for _ in range(150):
        controller.step(q)
        q = controller.q_next.copy()
    assert abs(ROBOT.joint_positions(q)[j] - upper) < 1e-6
    result = controller.result
    text = result.report()
    line = next(x for x in text.splitlines() if x.strip().startswith("elbow:"))
    assert "UNMET: at a joint position limit" in line, text
    assert f"{joint}: at its upper bound (joint_position_limits)" in text, text
    assert result.causes()["elbow"] == UnmetCause.JOINT_LIMIT
    controller.step(q)  # solved again: the old result keeps only its own fields
    assert "details gone" in result.report()
    with pytest.raises(ValueError, match="solved again"):
        result.causes()


@pytest.mark.parametrize("solver", [wb.ProjectionSolver(), wb.HierarchicalQPSolver()])
def test_a_hand_held_by_a_collision_pair_names_the_pair(solver):
    q = ROBOT.home()
    start = ROBOT.frame_pose(q, "right_tool")
    ball = np.eye(4)
    ball[:3, 3] = start[:3, 3] + (0.0, 0.2, 0.0)  # around the hand's goal
    collision = wb.CollisionAvoidance(
        ROBOT, obstacles=[wb.Obstacle("ball", "sphere", (0.05,), ball)]
    )
    hand = wb.FrameTask(ROBOT, "right_tool", kp=5.0, orientation=False)
    stack = wb.Stack(ROBOT, [[collision], [hand]], _limits())
    hand.set_target(ball)  # inside the ball: the pair holds the hand 1 cm off it
    controller = wb.Controller(ROBOT, stack, solver, dt=0.01)
    for _ in range(200):
        controller.step(q)
        q = controller.q_next.copy()
    result = controller.result
    text = result.report()
    line = next(x for x in text.splitlines() if x.strip().startswith("right_tool:"))
    assert result.causes()["right_tool"] == UnmetCause.INEQUALITY, text
    assert "held back by an inequality task" in line and "|ball at 10.0" in line, text
    assert "inequality rows at their bound: collision[0]" in text, text
    line = next(x for x in text.splitlines() if x.strip().startswith("collision:"))
    assert "rows in use" in line and "0 at their bound" not in line, text


def test_a_result_without_its_solve_reports_its_own_fields():
    result = wb.SolverResult(
        u=np.array([0.5, -1.0]),
        status=wb.SolverStatus.INFEASIBLE,
        level_residuals=np.array([0.2]),
        task_residuals={"hand": 0.2, "posture": 0.0},
        active_bounds=np.array([1]),
        infeasible=[("level 0", "hand")],
    )
    text = str(result)
    assert text.splitlines()[0].startswith("INFEASIBLE: max |u| 1 ")
    assert "hand: residual 0.2, UNMET" in text and "posture: residual 0, met" in text
    assert "active bounds on u[1]" in text


def test_a_problem_solved_without_a_stack_is_reported_from_its_rows():
    stack = wb.Stack(ROBOT, [[wb.FrameTask(ROBOT, "right_tool")]], _limits())
    problem = stack.evaluate(ROBOT.update(ROBOT.home()), 0.01)
    text = wb.HierarchicalQPSolver().solve_problem(problem).report()
    assert "right_tool: weight ?, demand" in text and "; met" in text, text
