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
import pinocchio as pin

from wholebody.robot.robot import LWA, Frame, Robot, RobotState

__all__ = ["JacobianDerivativeContraction", "actuated_support_mask", "frame_hessian"]


def actuated_support_mask(robot: Robot) -> np.ndarray:
    """(nu, nu) boolean ``M[l, k]``: actuated column l's joints support column k's joints.

    A column's joints are those its actuation column ``A[:, k]`` drives; a wheel drives the
    planar root (which supports every joint) and its own joint (which moves no frame).
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


def frame_hessian(state: RobotState, frame: Frame, mask: np.ndarray) -> np.ndarray:
    """(6, nu, nu): ``H[:, k, l] = d J[:, k] / d u_l`` of the frame's actuated Jacobian.

    Dense; for tests and analysis (:class:`JacobianDerivativeContraction` is the fast path).
    """
    J = state.jacobian(frame)
    v, w = J[:3].T, J[3:].T  # (nu, 3)
    m = mask.T[:, :, None]  # [k, l] -> M[l, k]
    lin = np.where(m, np.cross(w[None, :, :], v[:, None, :]),
                   np.cross(w[:, None, :], v[None, :, :]))  # fmt: skip
    ang = np.where(m, np.cross(w[None, :, :], w[:, None, :]), 0.0)
    return np.transpose(np.concatenate([lin, ang], axis=2), (2, 0, 1))


def _cross(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Column-wise cross product of (3, n) arrays (much faster than np.cross at this size)."""
    return np.array(
        [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
    )


class JacobianDerivativeContraction:
    """``c_l = sum_f <P_f, d J_f / d u_l>_F`` for a fixed list of frames, without forming any
    Hessian: the gradient of functions of stacked Jacobians such as manipulability.

    ``P`` stacks one 6 x nu weight block per frame (6F x nu). With ``a_k, b_k`` the linear
    and angular parts of column k of a block, the identity in the module docstring gives::

        c_l = w_l . sum_{k: M[l,k]} (v_k x a_k + w_k x b_k) + v_l . sum_{k: not M[l,k]} (a_k x w_k)

    Only each frame's support columns are visited, all frames side by side in one pass (at
    this size the cost is numpy's per-call overhead: fewer, larger calls win).
    """

    def __init__(self, robot: Robot, frames: list[Frame]) -> None:
        self.frames = list(frames)
        mask = actuated_support_mask(robot)
        q = robot.random_configuration(np.random.default_rng(0))
        data = robot.model.createData()  # a private probe: the robot's data stays untouched
        # The columns that move a frame (non-zero Jacobian columns: a revolute column always
        # has w != 0, a prismatic one v != 0); the others contribute nothing to c.
        cols = []
        for f in self.frames:
            J = pin.computeFrameJacobian(robot.model, data, q, f.index, LWA) @ robot.actuation
            cols.append(np.flatnonzero(np.any(J != 0, axis=0)))
        self._cols = cols
        n = sum(c.size for c in cols)
        self._same_t = np.zeros((n, n))  # M^T within each frame's block
        self._other_t = np.zeros((n, n))  # (1 - M)^T within each frame's block
        self._scatter = np.zeros((n, robot.nu))
        s = 0
        for c in cols:
            e = s + c.size
            block = mask[np.ix_(c, c)]
            self._same_t[s:e, s:e] = block.T
            self._other_t[s:e, s:e] = ~block.T
            self._scatter[np.arange(s, e), c] = 1.0
            s = e
        self._rows = [slice(6 * i, 6 * i + 6) for i in range(len(cols))]

    def __call__(self, state: RobotState, P: np.ndarray) -> np.ndarray:
        """(nu,) contraction for the 6F x nu weights ``P``."""
        J = np.hstack([state.jacobian(f)[:, c] for f, c in zip(self.frames, self._cols,
                                                                 strict=True)])  # fmt: skip
        Pc = np.hstack([P[r, c] for r, c in zip(self._rows, self._cols, strict=True)])
        v, w, a, b = J[:3], J[3:], Pc[:3], Pc[3:]
        n = v.shape[1]
        c = _cross(np.concatenate([v, w, a], axis=1), np.concatenate([a, b, w], axis=1))
        alpha = c[:, :n] + c[:, n : 2 * n]
        gamma = c[:, 2 * n :]
        term = (w * (alpha @ self._same_t)).sum(0) + (v * (gamma @ self._other_t)).sum(0)
        return term @ self._scatter
