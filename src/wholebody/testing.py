"""Finite-difference checks for tasks and objectives of your own (the ones wholebody's tests
use on its own).

Every derivative in wholebody is analytic; these central differences on the configuration
manifold (through :meth:`Robot.integrate`, so a base's wheels and an endless joint are
differentiated as the controller moves them) are the reference to test one against::

    from wholebody.testing import assert_objective_gradient, jacobian_fd

    J_fd = jacobian_fd(robot, q, lambda state: state.com_position())
    assert_objective_gradient(my_objective, robot, q)

Each column ``k`` is ``(f(integrate(q, e_k, eps)) - f(integrate(q, e_k, -eps))) / (2 eps)``:
the derivative along the actuated velocity ``u = e_k``, the coordinates of every Jacobian a
task returns. The error of central differences is ``O(eps^2)`` plus round-off
``O(|f| 1e-16 / eps)``: with ``eps = 1e-6`` about ``1e-9`` to ``1e-8`` on the robots here.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Objective

__all__ = [
    "assert_objective_gradient",
    "assert_task_jacobian",
    "frame_jacobian_fd",
    "gradient_fd",
    "jacobian_fd",
]


def _directions(robot: Robot, q: np.ndarray, eps: float):
    """``(k, q+, q-)`` for every actuated velocity ``k``."""
    for k in range(robot.nu):
        u = np.zeros(robot.nu)
        u[k] = 1.0
        yield k, robot.integrate(q, u, eps), robot.integrate(q, u, -eps)


def jacobian_fd(
    robot: Robot, q: np.ndarray, f: Callable[[RobotState], np.ndarray], eps: float = 1e-6
) -> np.ndarray:
    """``m x nu`` Jacobian of a vector quantity ``f(state)`` (m,) of the configuration."""
    cols = []
    for _, qp, qm in _directions(robot, q, eps):
        fp = np.array(f(robot.update(qp)), dtype=float)
        fm = np.array(f(robot.update(qm)), dtype=float)
        cols.append((fp - fm) / (2 * eps))
    return np.stack(cols, axis=-1)


def frame_jacobian_fd(robot: Robot, q: np.ndarray, frame: str, eps: float = 1e-6) -> np.ndarray:
    """6 x nu Jacobian of a frame: linear rows from the origin's displacement, angular rows
    from ``log3(R+ R-^T)`` (world axes, as :meth:`Robot.frame_jacobian`)."""
    J = np.zeros((6, robot.nu))
    for k, qp, qm in _directions(robot, q, eps):
        Tp, Tm = robot.frame_pose(qp, frame), robot.frame_pose(qm, frame)
        J[:3, k] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * eps)
        J[3:, k] = pin.log3(Tp[:3, :3] @ Tm[:3, :3].T) / (2 * eps)
    return J


def gradient_fd(
    robot: Robot, q: np.ndarray, f: Callable[[np.ndarray], float], eps: float = 1e-6
) -> np.ndarray:
    """Gradient of a scalar ``f(q)`` in actuated coordinates (the convention of
    :class:`~wholebody.tasks.ObjectiveValue`)."""
    g = np.zeros(robot.nu)
    for k, qp, qm in _directions(robot, q, eps):
        g[k] = (f(qp) - f(qm)) / (2 * eps)
    return g


def assert_objective_gradient(
    objective: Objective, robot: Robot, q: np.ndarray, atol: float = 1e-6, eps: float = 1e-6
) -> None:
    """An objective's analytic gradient at ``q`` equals the central differences of its value
    (AssertionError naming the worst entry otherwise)."""
    analytic = np.asarray(objective.evaluate(robot.update(q)).gradient, dtype=float)
    numeric = gradient_fd(robot, q, lambda x: objective.evaluate(robot.update(x)).value, eps)
    _assert_close(f"objective {objective.name!r}: gradient", analytic, numeric, atol, robot)


def assert_task_jacobian(
    task,
    robot: Robot,
    q: np.ndarray,
    quantity: Callable[[RobotState], np.ndarray],
    atol: float = 1e-6,
    eps: float = 1e-6,
) -> None:
    """A task's rows ``J`` at ``q`` are the Jacobian of ``quantity(state)`` (the vector the
    task moves, e.g. a frame position), by central differences."""
    analytic = np.asarray(task.compute(robot.update(q)).J, dtype=float)
    numeric = jacobian_fd(robot, q, quantity, eps)
    _assert_close(f"task {task.name!r}: rows J", analytic, numeric, atol, robot)


def _assert_close(
    what: str, analytic: np.ndarray, numeric: np.ndarray, atol: float, robot: Robot
) -> None:
    if analytic.shape != numeric.shape:
        raise AssertionError(
            f"{what} has shape {analytic.shape}, finite differences {numeric.shape}"
        )
    err = np.abs(analytic - numeric)
    if err.size and err.max() > atol:
        index = np.unravel_index(int(np.argmax(err)), err.shape)
        joint = robot.actuated_joints[index[-1]]
        raise AssertionError(
            f"{what} differs from finite differences by {err.max():.3g} "
            f"(> {atol:g}) at {index} (u entry {joint!r}): analytic "
            f"{analytic[index]:.6g}, numeric {numeric[index]:.6g}"
        )
