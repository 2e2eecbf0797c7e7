"""A task's Levenberg-Marquardt damping (pink's ``lm_damping``, ``wb.Task(lm_damping=...)``):
the damped rows against the closed form, a damped task alone in its level moving as pink's
damped QP on both backends, the levels below it keeping their priority, and the checks."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import wholebody as wb
from wholebody.errors import DimensionError
from wholebody.tasks import damp_rows

DT = 0.01


@pytest.fixture(scope="module")
def panda() -> wb.Robot:
    return wb.load_robot("panda")


def lm_step(J: np.ndarray, v: np.ndarray, w: np.ndarray, mu: float) -> np.ndarray:
    """pink's damped QP's answer: ``(J^T W J + mu I)^-1 J^T W v``."""
    return np.linalg.solve(J.T @ (w[:, None] * J) + mu * np.eye(J.shape[1]), J.T @ (w * v))


@pytest.mark.parametrize("rank", [4, 2])
def test_the_damped_rows_give_the_levenberg_marquardt_step(rng, rank):
    J = rng.standard_normal((4, rank)) @ rng.standard_normal((rank, 7))  # rank 2: singular
    v, w, mu = rng.standard_normal(4), rng.uniform(0.5, 2.0, 4), 0.3
    s = np.sqrt(w)
    u = np.linalg.pinv(s[:, None] * J) @ (s * damp_rows(J, v, w, mu))  # the minimum norm
    np.testing.assert_allclose(u, lm_step(J, v, w, mu), atol=1e-12)
    np.testing.assert_array_equal(damp_rows(J, v, w, 0.0), v)
    w[1] = 0.0  # a row of weight 0 keeps its right-hand side (it weighs nothing)
    assert damp_rows(J, v, w, mu)[1] == v[1]


class Reach(wb.Task):
    """The short way, damped: the hand's position to a target (m)."""

    dim = 3

    def __init__(self, robot: wb.Robot, target: np.ndarray, lm_damping: float) -> None:
        super().__init__("reach", 2.0, gain=5.0, lm_damping=lm_damping)
        self.frame, self.target = robot.frame("panda_hand"), target

    def compute_error(self, state: wb.RobotState) -> np.ndarray:
        return state.position(self.frame) - self.target

    def compute_jacobian(self, state: wb.RobotState) -> np.ndarray:
        return state.jacobian(self.frame)[:3]


@pytest.mark.parametrize("solver", [wb.ProjectionSolver, wb.HierarchicalQPSolver])
def test_a_damped_task_alone_moves_as_pinks_damped_qp(panda, solver):
    q = panda.home()
    state = panda.update(q)
    target = state.position(panda.frame("panda_hand")) + np.array([0.3, -0.2, 0.25])
    task = Reach(panda, target, lm_damping=4.0)
    stack = wb.Stack(panda, [[task]])
    u = solver().solve(stack, state, DT).u
    e, J = task.compute_error(state), task.compute_jacobian(state)
    w = np.full(3, 2.0)
    expected = lm_step(J, -5.0 * e, w, 4.0 * float(w @ (e * e)))
    np.testing.assert_allclose(u, expected, atol=1e-9)
    undamped = np.linalg.pinv(J) @ (-5.0 * e)
    assert np.linalg.norm(expected) < 0.9 * np.linalg.norm(undamped)  # it did damp


@pytest.mark.parametrize("solver", [wb.ProjectionSolver, wb.HierarchicalQPSolver])
def test_a_damped_built_in_task_leaves_the_levels_below_their_priority(panda, solver, rng):
    """A FrameTask with damping: its rows are its own, damped; the posture below is then the
    best it can be among the motions that realise them (KKT of the equality-constrained least
    squares), the damping taking none of its freedom."""
    q = panda.random_configuration(rng, margin=0.3)
    state = panda.update(q)
    hand = wb.FrameTask(panda, "panda_hand", position=True, orientation=False, kp=5.0)
    target = state.pose(panda.frame("panda_hand")).copy()
    target[:3, 3] += (0.2, 0.1, -0.15)
    hand.set_target(target)
    posture = wb.PostureTask(panda, kp=1.0)
    stack = wb.Stack(panda, [[hand], [posture]])
    plain = stack.evaluate(state, DT).levels[0].b.copy()
    hand.lm_damping = 2.0  # after the stack was laid out: from now on evaluated in Python
    problem = stack.evaluate(state, DT)
    J1, b1 = problem.levels[0].A, problem.levels[0].b
    e = hand.error(state)
    np.testing.assert_allclose(b1, damp_rows(J1, plain, np.ones(3), 2.0 * float(e @ e)), atol=1e-12)
    assert np.linalg.norm(b1) < np.linalg.norm(plain)
    u = solver().solve(stack, state, DT).u
    np.testing.assert_allclose(J1 @ u, b1, atol=1e-9)  # the damped rows are met
    J2, b2 = problem.levels[1].A, problem.levels[1].b
    n = panda.nu  # the posture's optimum under J1 u = b1: [J2^T J2, J1^T; J1, 0] [u; y] = ...
    kkt = np.block([[J2.T @ J2 + 1e-12 * np.eye(n), J1.T], [J1, np.zeros((3, 3))]])
    best = scipy.linalg.solve(kkt, np.r_[J2.T @ b2, b1])[:n]
    np.testing.assert_allclose(J2 @ u - b2, J2 @ best - b2, atol=1e-7)


class Rowsonly(wb.Task):
    """Rows without an error: damping cannot be computed."""

    dim = 1

    def compute(self, state: wb.RobotState) -> wb.TaskRows:
        return wb.TaskRows(np.ones((1, state.robot.nu)), np.ones(1), np.ones(1))


def test_the_damping_is_checked_and_needs_an_error(panda):
    with pytest.raises(DimensionError, match="reach: lm_damping must be a finite number >= 0"):
        Reach(panda, np.zeros(3), lm_damping=-1.0)
    task = wb.PostureTask(panda)
    with pytest.raises(DimensionError, match="posture: lm_damping must be"):
        task.lm_damping = float("nan")
    rows = Rowsonly("rows", lm_damping=1.0)
    stack = wb.Stack(panda, [[rows]])
    with pytest.raises(DimensionError, match="rows: lm_damping needs the task's error"):
        stack.evaluate(panda.update(panda.home()), DT)


def test_damping_set_during_a_run_takes_effect_in_the_controllers_loop(panda):
    """The one-kernel loop (every task compiled) leaves it when a task is damped: the next
    step is that of a controller damped from the start."""

    def controller(lm_damping: float) -> tuple[wb.FrameTask, wb.Controller]:
        hand = wb.FrameTask(panda, "panda_hand", kp=5.0, lm_damping=lm_damping)
        target = panda.frame_pose(panda.home(), "panda_hand").copy()
        target[:3, 3] += (0.3, -0.2, 0.25)
        hand.set_target(target)
        stack = wb.Stack(panda, [[hand], [wb.PostureTask(panda)]], [wb.VelocityLimits(panda)])
        return hand, wb.Controller(panda, stack, wb.HierarchicalQPSolver(), dt=DT)

    q = panda.home()
    (hand, late), (_, damped), (_, plain) = controller(0.0), controller(3.0), controller(0.0)
    late.step(q)
    hand.lm_damping = 3.0
    late.step(q)
    damped.step(q)
    plain.step(q)
    np.testing.assert_allclose(late.q_next, damped.q_next, atol=1e-12)
    assert np.abs(late.q_next - plain.q_next).max() > 1e-4
