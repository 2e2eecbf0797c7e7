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

from wholebody.errors import DimensionError
from wholebody.robot.robot import LWA, Frame, Robot, RobotState

__all__ = [
    "JacobianDerivativeContraction",
    "actuated_support_mask",
    "check_off_wheels",
    "frame_hessian",
]


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

    Dense; for tests and analysis (:class:`JacobianDerivativeContraction` is the fast path).
    Not for a frame on a wheel (:func:`check_off_wheels`).
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
    this size the cost is numpy's per-call overhead: fewer, larger calls win). With ``n`` such
    columns, one gather from ``[J; P]`` gives the rotated components of ``[v w a]`` and
    ``[a b w]``, so the three cross products are ``X' Y'' - X'' Y'`` (3 x 3n); one product
    with the block matrix ``K = [[M^T, 0], [M^T, 0], [0, (1 - M)^T]]`` sums them over k, and
    one product with a 0/1 matrix multiplies by ``[w v]``, sums the components and scatters
    the columns back to the nu actuated velocities.
    """

    def __init__(self, robot: Robot, frames: list[Frame]) -> None:
        check_off_wheels(robot, frames)
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
        nu, F = robot.nu, len(cols)
        n = sum(c.size for c in cols)
        same_t = np.zeros((n, n))  # M^T within each frame's block
        other_t = np.zeros((n, n))  # (1 - M)^T within each frame's block
        col = np.concatenate(cols).astype(int)  # actuated column of each of the n entries
        frame = np.repeat(np.arange(F), [c.size for c in cols])
        s = 0
        for c in cols:
            e = s + c.size
            block = mask[np.ix_(c, c)]
            same_t[s:e, s:e] = block.T
            other_t[s:e, s:e] = ~block.T
            s = e
        self._K = np.zeros((3 * n, 2 * n))
        self._K[:n, :n] = same_t
        self._K[n : 2 * n, :n] = same_t
        self._K[2 * n :, n:] = other_t

        # Flat indices into [J.ravel(), P.ravel()] (J, P: 6F x nu) of component r of the
        # linear (part 0) or angular (part 1) rows of J (src 0) or P (src 1), per entry.
        def flat(src: int, part: int, r: np.ndarray) -> np.ndarray:
            return src * 6 * F * nu + ((6 * frame + 3 * part + r) * nu + col)

        rot1, rot2 = np.array([1, 2, 0])[:, None], np.array([2, 0, 1])[:, None]

        def xyz(rot: np.ndarray, parts: list[tuple[int, int]]) -> np.ndarray:
            return np.concatenate([flat(src, part, rot) for src, part in parts], axis=1)

        X, Y = [(0, 0), (0, 1), (1, 0)], [(1, 0), (1, 1), (0, 1)]  # [v w a], [a b w]
        ident = np.arange(3)[:, None]
        self._gather = np.stack([xyz(rot1, X), xyz(rot2, Y), xyz(rot2, X), xyz(rot1, Y),
                                 xyz(ident, [(0, 1), (0, 0), (0, 0)])])  # fmt: skip
        self._two_n = 2 * n
        # sum over components and scatter of the 2n entries ([w.(..) | v.(..)]) to nu columns
        scatter = np.zeros((3, 2 * n, nu))
        scatter[:, np.arange(2 * n), np.concatenate([col, col])] = 1.0
        self._scatter = scatter.reshape(6 * n, nu)
        self._rows = [slice(6 * i, 6 * i + 6) for i in range(F)]

    def __call__(self, state: RobotState, P: np.ndarray, J: np.ndarray | None = None) -> np.ndarray:
        """(nu,) contraction for the 6F x nu weights ``P``. ``J``, the frames' stacked
        Jacobians (6F x nu, or (F, 6, nu)), is read from ``state`` when not given."""
        if J is None:
            J = state.jacobians(self.frames)
        T = np.concatenate((J.ravel(), P.ravel()))[self._gather]
        c = T[0] * T[1]
        c -= T[2] * T[3]  # [v x a | w x b | a x w], 3 x 3n
        R = c.dot(self._K)  # [sum_M (v x a + w x b) | sum_(1-M) (a x w)], 3 x 2n
        R *= T[4, :, : self._two_n]  # times [w | v]
        return R.ravel().dot(self._scatter)
