"""Configuration objectives of the paper: joint-limit avoidance ``h1`` and manipulability ``h2``.

Both return a value and its analytic gradient in actuated coordinates (see
:class:`~wholebody.tasks.base.Objective`); the paper's ``H = w1 f_p + w2 h1 - w3 h2`` is the
weighted sum a stack level forms from its objectives (manipulability with a negative weight).
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence

import numpy as np

from wholebody.errors import DimensionError, WholebodyError
from wholebody.kernels.layout import KIND_H1, KIND_H2
from wholebody.kernels.objectives import joint_limit_avoidance, manipulability
from wholebody.robot import Frame, Robot, RobotState
from wholebody.robot.hessian import actuated_support_mask, check_off_wheels
from wholebody.tasks.base import Objective, ObjectiveValue, Packed, Packer

__all__ = ["JointLimitAvoidance", "Manipulability"]


class JointLimitAvoidance(Objective):
    """The paper's ``h1 = sum_i (qmax_i - qmin_i)^2 / (4 (qmax_i - q_i)(q_i - qmin_i))``.

    Summed over the joints with finite limits (by default all of them: the 19 revolute joints
    of the paper's robot; wheels have none). It is 1 per joint at mid-range and grows without
    bound at a limit. Gradient, with ``a = qmax - q``, ``b = q - qmin``, ``c = range^2 / 4``:
    ``d h1 / d q = c (b - a) / (a b)^2``; the Hessian is diagonal,
    ``d2 h1 / d q2 = 2 c (a b + (b - a)^2) / (a b)^3``, and is reported as ``curvature`` so the
    descent step stays stable however steep h1 gets near a limit. A joint at or beyond a limit
    is evaluated at ``range * 1e-6`` inside it, so value and gradient stay finite and point
    inwards.

    Parameters
    ----------
    joints
        Group names, joint names and/or indices into ``u`` to include (default: every joint
        with finite limits); a name is a group's before a joint's.
    """

    def __init__(
        self,
        robot: Robot,
        joints: Sequence[str | int] | None = None,
        *,
        weight: float = 1.0,
        name: str = "joint_limit_avoidance",
    ) -> None:
        lower, upper = robot.position_limits
        limited = np.isfinite(lower) & np.isfinite(upper)
        if isinstance(joints, str):  # one group or joint name
            joints = [joints]
        if joints is None:
            idx = np.flatnonzero(limited)
        else:
            for j in joints:
                if isinstance(j, (int, np.integer)):
                    if not 0 <= j < robot.nu:
                        raise WholebodyError(f"{name}: index {j} is not in [0, {robot.nu})")
                    continue
                if j not in robot.groups and j not in robot.actuated_joints:
                    close = difflib.get_close_matches(j, [*robot.groups, *robot.actuated_joints])
                    raise WholebodyError(
                        f"{name}: {j!r} is neither a joint group ({', '.join(robot.groups)}) nor "
                        "an actuated joint"
                        + (f" (did you mean {', '.join(map(repr, close))}?)" if close else "")
                    )
            parts = [
                [int(j)]
                if isinstance(j, (int, np.integer))
                else robot.groups[j].indices
                if j in robot.groups
                else [robot.index(j)]
                for j in joints
            ]
            idx = np.unique(np.concatenate(parts)).astype(int)
            if not np.all(limited[idx]):
                bad = [robot.actuated_joints[i] for i in idx if not limited[i]]
                raise WholebodyError(f"{name}: joints without position limits: {bad}")
        if idx.size == 0:
            raise WholebodyError(f"{name}: no joint with finite limits to act on")
        super().__init__(name, weight)
        self.robot = robot
        self.indices = idx
        # Evaluated over all nu entries at once (no gather/scatter): every joint with finite
        # limits over its range, the others over the dummy range [-1, 1]; the joints left out
        # get c = 0, so they contribute exact zeros.
        nu = robot.nu
        lo, hi, c = np.full(nu, -1.0), np.full(nu, 1.0), np.zeros(nu)
        lo[limited], hi[limited] = lower[limited], upper[limited]
        c[idx] = (upper[idx] - lower[idx]) ** 2 / 4
        self._params = np.concatenate([lo, hi, c])  # the kernel's block

    @property
    def ranges(self) -> np.ndarray:
        """(3, nu): the range ``[lo, hi]`` and coefficient ``c = range^2 / 4`` per actuated
        velocity (read-only; ``c = 0`` for the joints left out)."""
        out = self._params.reshape(3, -1)
        out.setflags(write=False)
        return out

    def evaluate(self, state: RobotState) -> ObjectiveValue:
        nu = self.robot.nu
        grad, curv = np.empty(nu), np.empty(nu)
        lo, hi, c = self.ranges
        value = joint_limit_avoidance(state.joint_positions(), lo, hi, c, grad, curv)
        return ObjectiveValue(float(value), grad, curv)

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(JointLimitAvoidance, "evaluate"):
            return None
        return Packed(KIND_H1, self._params, curvature=True)


class Manipulability(Objective):
    """Yoshikawa's manipulability ``h2 = sqrt(det(J J^T))`` of the frames' stacked Jacobian.

    ``J`` is the 6F x nu actuated Jacobian of the frames (for the paper: both hands, 12 x 23,
    wheel columns through the Mecanum matrix). Gradient, exact:
    ``d h2 / d u_l = h2 <(J J^T)^-1 J, d J / d u_l>_F``, the Jacobian derivatives from the
    kinematic-Hessian identity (:mod:`wholebody.robot.hessian`), never finite differences.
    Where ``J J^T`` is singular (h2 = 0) the gradient is taken as zero.

    To maximise manipulability give it a **negative** weight (the paper's ``-w3 h2``).
    """

    def __init__(
        self,
        robot: Robot,
        frames: Sequence[str | Frame],
        *,
        weight: float = -1.0,
        name: str = "manipulability",
    ) -> None:
        if isinstance(frames, (str, Frame)):  # one frame, not its characters
            frames = [frames]
        if not frames:
            raise DimensionError(f"{name}: needs at least one frame")
        super().__init__(name, weight)
        self.robot = robot
        self.frames = [robot.frame(f) for f in frames]
        if 6 * len(self.frames) > robot.nu:
            raise DimensionError(
                f"{name}: {6 * len(self.frames)} rows exceed nu = {robot.nu}; "
                "J J^T is always singular"
            )
        check_off_wheels(robot, self.frames)
        self.support = actuated_support_mask(robot)
        """(nu, nu): ``support[l, k]``, column l supports column k (read-only)."""
        self.support.setflags(write=False)

    def jacobian(self, state: RobotState) -> np.ndarray:
        """The stacked 6F x nu Jacobian."""
        return state.jacobians(self.frames).reshape(6 * len(self.frames), -1).copy()

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return tuple(self.frames)

    def evaluate(self, state: RobotState) -> ObjectiveValue:
        J = state.jacobians(self.frames)
        grad = np.empty(self.robot.nu)
        h2 = manipulability(J, self.support, grad)
        return ObjectiveValue(float(h2), grad)

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(Manipulability, "evaluate"):
            return None
        frames = [packer.frame(f) for f in self.frames]
        ints = np.concatenate([[len(frames)], frames, self.support.ravel()]).astype(np.int64)
        return Packed(KIND_H2, np.zeros(0), ints)
