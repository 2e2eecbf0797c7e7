"""Tasks written by a user, as the README's "Write your own task" shows them: the contract
checks them (name, weight, row shapes), both backends run them, a Controller follows a
reference with one, and monitors log any objective."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import wholebody as wb
from wholebody.errors import DimensionError, WholebodyError
from wholebody.planning import MinimumJerkTrajectory
from wholebody.testing import assert_objective_gradient, assert_task_jacobian

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "guides" / "tasks.md"
DT = 0.01


def readme_tasks() -> dict:
    """The guide's CoMTask and UprightTask classes (``docs/guides/tasks.md``), as written there."""
    code = next(
        b
        for b in re.findall(r"```python\n(.*?)```", GUIDE.read_text(), flags=re.S)
        if "class CoMTask" in b
    )
    code = code[: code.index("robot = wb.load_robot")]
    namespace: dict = {"__name__": "readme_tasks"}
    exec(compile(code, str(GUIDE), "exec"), namespace)
    return namespace


@pytest.fixture(scope="module")
def tasks():
    return readme_tasks()


@pytest.mark.parametrize("backend", [wb.ProjectionSolver, wb.HierarchicalQPSolver])
def test_the_readme_tasks_reach_their_goals_on_both_backends(humanoid, tasks, backend, rng):
    q = humanoid.home()
    com = tasks["CoMTask"](np.add(humanoid.update(q).com_position(), (0.03, 0, -0.02)))
    upright = tasks["UprightTask"](humanoid, "right_tool")
    for x in (q, humanoid.random_configuration(rng, margin=0.1)):  # exact Jacobians
        assert_task_jacobian(com, humanoid, x, com.compute_error)
        assert_task_jacobian(upright, humanoid, x, upright.error)
    stack = wb.Stack(
        humanoid,
        [[com, upright], [wb.PostureTask(humanoid)]],
        [wb.JointPositionLimits(humanoid), wb.VelocityLimits(humanoid)],
    )
    solver = backend()
    tilt0 = np.linalg.norm(upright.error(humanoid.update(q)))
    for _ in range(300):
        state = humanoid.update(q)
        result = solver.solve(stack, state, DT)
        stack.advance(state, DT, result=result)
        q = humanoid.integrate(q, result.u, DT)
    state = humanoid.update(q)
    assert np.linalg.norm(com.error(state)) < 1e-5
    assert tilt0 > 0.1 and np.linalg.norm(upright.error(state)) < 1e-5


class Bare(wb.Task):
    def __init__(self, name="bare", weight=1.0, rows=(1, 23)):
        super().__init__(name, weight)
        self.shape = rows

    @property
    def dim(self):
        return 3

    def compute(self, state):
        return wb.TaskRows(np.zeros(self.shape), np.zeros(self.shape[0]), self.weights)


def test_the_task_contract_checks_names_weights_and_row_shapes(humanoid):
    for name in ("", None, 3):
        with pytest.raises(DimensionError, match="name must be a non-empty string"):
            Bare(name=name)
    for weight in (-1.0, float("nan"), "x", [[1.0]]):
        with pytest.raises(DimensionError, match="bare: weight"):
            Bare(weight=weight)
    task = Bare(weight=[1.0, 2.0, 3.0])
    np.testing.assert_array_equal(task.weights, [1.0, 2.0, 3.0])
    with pytest.raises(DimensionError, match="2 weights for 3 rows"):
        _ = Bare(weight=[1.0, 2.0]).weights
    state = humanoid.update(humanoid.home())
    stack = wb.Stack(humanoid, [[Bare()]])  # one row for three: numpy would broadcast it
    with pytest.raises(DimensionError, match=r"task 'bare': compute\(\) returned J \(1, 23\)"):
        stack.evaluate(state, DT)
    assert np.isnan(Bare(rows=(3, 23)).error(state)).all()  # not a zero that reads as "met"


class Height(wb.Objective):
    """The right hand's height (m): a user's objective, monitored."""

    def __init__(self, robot):
        super().__init__("hand_height", 1.0)
        self.frame = robot.frame("right_tool")

    def evaluate(self, state):
        return wb.ObjectiveValue(state.position(self.frame)[2], state.jacobian(self.frame)[2])


def test_a_controller_follows_a_reference_with_a_users_task_and_logs_any_objective(humanoid):
    class PositionTask(wb.Task):  # position only, with a set_target: a ReferenceTask
        def __init__(self, robot, frame):
            super().__init__("grip", 1.0)
            self.frame, self.target = robot.frame(frame), None
            self.twist = np.zeros(6)

        @property
        def dim(self):
            return 3

        def set_target(self, pose, twist=None):
            self.target = np.asarray(pose)[:3, 3]
            self.twist = np.zeros(6) if twist is None else np.asarray(twist)

        def error(self, state):
            return self.target - state.position(self.frame)

        def compute(self, state):
            v = self.twist[:3] + 10.0 * self.error(state)
            return wb.TaskRows(state.jacobian(self.frame)[:3], v, self.weights)

    q = humanoid.home()
    grip = PositionTask(humanoid, "right_tool")
    start = humanoid.frame_pose(q, "right_tool")
    goal = start.copy()
    goal[:3, 3] += (0.1, 0.0, 0.1)
    height = Height(humanoid)
    assert_objective_gradient(height, humanoid, q)
    stack = wb.Stack(
        humanoid,
        [[grip], [wb.PostureTask(humanoid)]],
        [wb.JointPositionLimits(humanoid), wb.VelocityLimits(humanoid)],
    )
    ctrl = wb.Controller(
        humanoid,
        stack,
        wb.ProjectionSolver(),
        dt=DT,
        monitors=[height],
        references={grip: MinimumJerkTrajectory(start, goal, 1.0)},
    )
    log = ctrl.run(q, 1.5)
    final = humanoid.frame_pose(np.array(log.meta["final_q"]), "right_tool")[:3, 3]
    assert np.abs(final - goal[:3, 3]).max() < 1e-4
    assert np.abs(log.task_errors["grip"][-1]).max() < 1e-4
    heights = [humanoid.frame_pose(x, "right_tool")[2, 3] for x in log.q[::25]]
    np.testing.assert_allclose(log.objectives["hand_height"][::25], heights, atol=1e-12)
    with pytest.raises(WholebodyError, match="set_target"):
        wb.Controller(
            humanoid,
            stack,
            wb.ProjectionSolver(),
            dt=DT,
            references={wb.PostureTask(humanoid): None},
        )
    with pytest.raises(WholebodyError, match="monitors are objectives"):
        wb.Controller(humanoid, stack, wb.ProjectionSolver(), dt=DT, monitors=[grip])


class Short(wb.Task):
    """The short way: an error and its Jacobian (the right hand's position, m)."""

    dim = 3

    def __init__(self, robot, target, gain=4.0, shape=None):
        super().__init__("short", gain=gain)
        self.frame, self.target, self.shape = robot.frame("right_tool"), target, shape

    def compute_error(self, state):
        return state.position(self.frame) - self.target

    def compute_jacobian(self, state):
        J = state.jacobian(self.frame)[:3]
        return J if self.shape is None else np.zeros(self.shape)


def test_the_short_way_asks_for_the_errors_decay_and_checks_its_shapes_once(humanoid):
    q = humanoid.home()
    state = humanoid.update(q)
    target = np.add(state.position(humanoid.frame("right_tool")), (0.05, -0.02, 0.04))
    task = Short(humanoid, target)
    rows = task.compute(state)
    e = task.compute_error(state)
    np.testing.assert_array_equal(rows.v, -4.0 * e)  # de/dt = -gain e
    np.testing.assert_array_equal(task.error(state), e)  # what the logs record
    assert_task_jacobian(task, humanoid, q, task.compute_error)
    state = humanoid.update(q)  # (the check moved the robot's state)
    with pytest.raises(DimensionError, match=r"short: compute_jacobian returned shape \(3, 7\)"):
        Short(humanoid, target, shape=(3, 7)).compute(state)
    with pytest.raises(DimensionError, match="short: gain must be"):
        Short(humanoid, target, gain=-1.0)
    with pytest.raises(NotImplementedError, match="define compute_error"):
        Bare.__bases__[0].compute(Bare(), state)  # wb.Task's own: neither way defined
    solver = wb.HierarchicalQPSolver()
    stack = wb.Stack(humanoid, [[task], [wb.PostureTask(humanoid)]], [wb.VelocityLimits(humanoid)])
    for _ in range(300):  # 3 s: the error decays by exp(-4 t), ~6e-6 of 7 cm
        state = humanoid.update(q)
        result = solver.solve(stack, state, DT)
        q = humanoid.integrate(q, result.u, DT)
    assert np.linalg.norm(task.compute_error(humanoid.update(q))) < 1e-5
