"""Kinematic Hessians: derivatives of frame Jacobians with respect to the configuration.

Pinocchio computes them in C++ (``computeJointKinematicHessians``), but its Python bindings up
to 3.8 do not expose that function, so this module evaluates the same identity from the
frame Jacobians Pinocchio returns. For the Jacobian with world-aligned axes at the frame
origin, columns ``J_k = [v_k; w_k]`` (linear, angular), the derivative of column k along
column l's direction is::

    d v_k / d q_l = w_l x v_k,   d w_k / d q_l = w_l x w_k     if l supports k,
    d v_k / d q_l = w_k x v_l,   d w_k / d q_l = 0             otherwise,

where "l supports k" means column l's joint is column k's joint or one of its ancestors. (It
is the Lie bracket ``ad(J_l) J_k`` of the spatial Jacobian, moved to the frame origin, which
itself moves with ``v_l``.) The identity is linear in the columns, so it holds column-wise
for the actuated Jacobian ``J_u = J A`` too: a base actuator (wheel) column is a
combination of the planar root joint's columns, and the root supports every joint.
Derivatives are along the actuated directions, ``q(t) = integrate(q, e_l, t)``.
"""

from __future__ import annotations

import numpy as np

from wholebody.errors import DimensionError
from wholebody.robot.parts import Frame
from wholebody.robot.robot import Robot
from wholebody.robot.state import RobotState

__all__ = ["actuated_support_mask", "check_off_wheels", "frame_hessian"]


def actuated_support_mask(robot: Robot) -> np.ndarray:
    """(nu, nu) boolean ``M[l, k]``: actuated column l's joints support column k's joints.

    A column's joints are those its actuation column ``A[:, k]`` drives; a wheel drives the
    planar root (which supports every joint) and its own joint, which moves only the frames
    on its wheel: the mask is exact for every other frame (see :func:`check_off_wheels`).
    """
    model = robot.model
    joint_of = np.empty(model.nv, dtype=int)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        joint_of[jm.idx_v : jm.idx_v + jm.nv] = j
    supports = [set(model.supports[j]) for j in range(model.njoints)]
    drives = [set(joint_of[np.flatnonzero(robot.actuation[:, k])]) for k in range(robot.nu)]
    M = np.zeros((robot.nu, robot.nu), dtype=bool)
    for k in range(robot.nu):
        below = set().union(*(supports[j] for j in drives[k]))
        for i in range(robot.nu):
            M[i, k] = bool(drives[i] & below)
    return M


def check_off_wheels(robot: Robot, frames: list[Frame]) -> None:
    """Raise :class:`~wholebody.errors.DimensionError` for a frame on a wheel (moved by a
    wheel's own joint): one boolean per pair of columns cannot say that a wheel column
    supports such a frame through the root but not through the wheel's spin."""
    model = robot.model
    wheels = {model.getJointId(j): j for j in robot.base.wheel_joints}
    for f in frames:
        on = [name for jid, name in wheels.items() if jid in model.supports[f.joint]]
        if on:
            raise DimensionError(
                f"frame {f.name!r} is on the wheel {on[0]!r}: its Jacobian derivatives are not "
                "supported (choose a frame of the body or the arms)"
            )


def frame_hessian(state: RobotState, frame: Frame, mask: np.ndarray) -> np.ndarray:
    """(6, nu, nu): ``H[:, k, l] = d J[:, k] / d u_l`` of the frame's actuated Jacobian.

    Dense; for tests and analysis (the gradients contract the identity without forming it:
    :func:`wholebody.kernels.objectives.manipulability`).
    Not for a frame on a wheel (:func:`check_off_wheels`).
    """
    J = state.jacobian(frame)
    v, w = J[:3].T, J[3:].T  # (nu, 3)
    m = mask.T[:, :, None]  # [k, l] -> M[l, k]
    lin = np.where(
        m, np.cross(w[None, :, :], v[:, None, :]), np.cross(w[:, None, :], v[None, :, :])
    )
    ang = np.where(m, np.cross(w[None, :, :], w[:, None, :]), 0.0)
    return np.transpose(np.concatenate([lin, ang], axis=2), (2, 0, 1))
