"""Finite-difference references shared by the tests (central differences on the manifold)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from wholebody import Robot


def frame_jacobian_fd(robot: Robot, q: np.ndarray, frame: str, eps: float = 1e-6) -> np.ndarray:
    """6 x nu Jacobian of a frame by central differences through ``Robot.integrate``:
    linear rows from the origin's displacement, angular rows from ``log3(R+ R-^T)``."""
    J = np.zeros((6, robot.nu))
    for k in range(robot.nu):
        u = np.zeros(robot.nu)
        u[k] = 1.0
        Tp = robot.frame_pose(robot.integrate(q, u, eps), frame)
        Tm = robot.frame_pose(robot.integrate(q, u, -eps), frame)
        J[:3, k] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * eps)
        J[3:, k] = pin.log3(Tp[:3, :3] @ Tm[:3, :3].T) / (2 * eps)
    return J


def gradient_fd(
    robot: Robot, q: np.ndarray, f: Callable[[np.ndarray], float], eps: float = 1e-6
) -> np.ndarray:
    """Gradient in actuated coordinates: ``g_k = d f(integrate(q, e_k, t)) / dt`` at t = 0."""
    g = np.zeros(robot.nu)
    for k in range(robot.nu):
        u = np.zeros(robot.nu)
        u[k] = 1.0
        g[k] = (f(robot.integrate(q, u, eps)) - f(robot.integrate(q, u, -eps))) / (2 * eps)
    return g
