"""Joint posture regulation: ``u_j = kp (q_ref,j - q_j)`` for a set of actuated joints.

For joints with a position (revolute, prismatic) the error is ``q_ref - q``; for continuous
joints other than wheels (an endless wrist) it is that difference wrapped into ``[-pi, pi)``,
the shorter way round; for wheels and the virtual actuators of a planar base it is zero, so
their rows damp the speed to zero (at a low priority this pins, e.g., the Mecanum base's
internal wheel mode). The rows come from :func:`wholebody.kernels.rows.posture_rows`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wholebody.errors import DimensionError
from wholebody.kernels.layout import KIND_POSTURE
from wholebody.kernels.rows import posture_rows
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Packed, Packer, Task, TaskRows

__all__ = ["PostureTask"]


class PostureTask(Task):
    """Drive joints towards reference positions.

    Parameters
    ----------
    robot
        The robot.
    joints
        A group name, a list of joint names, or None for every actuated velocity (but a
        floating base's six: the base is left free, as the contacts held by tasks decide it).
    target
        Reference positions (rad, m), one per joint; defaults to the home posture.
    kp
        Gain (1/s), scalar or per joint.
    weight
        Weight in its level, scalar or per joint.
    lm_damping
        Levenberg-Marquardt damping (:class:`~wholebody.tasks.Task`; 0: none).

    The target and the gains are read-only arrays: change them with :meth:`set_target` and
    by assigning ``kp``.
    """

    def __init__(
        self,
        robot: Robot,
        joints: str | Sequence[str] | None = None,
        *,
        name: str | None = None,
        target: np.ndarray | Sequence[float] | None = None,
        kp: float | Sequence[float] = 1.0,
        weight: float | Sequence[float] = 1.0,
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = robot
        if joints is None:
            idx = np.arange(len(robot.base.actuators) if robot.base.floating else 0, robot.nu)
            label = "posture"
        elif isinstance(joints, str):
            idx = robot.group(joints).indices
            label = f"posture[{joints}]"
        else:
            idx = np.array([robot.index(j) for j in joints], dtype=int)
            label = "posture"
        self.indices = np.array(idx, dtype=np.int64)
        self.indices.setflags(write=False)
        super().__init__(name or label, weight, lm_damping=lm_damping)
        base = np.arange(robot.nu) < len(robot.base.actuators)  # wheels, virtual actuators
        self.tracked = (~base)[idx]
        """Per joint, whether it has a position error (False: wheels, a base's virtual
        actuators)."""
        self.wrapped = ~robot.positional[idx] & ~base[idx]
        """Per joint, whether its error wraps into [-pi, pi) (endless joints)."""
        for a in (self.tracked, self.wrapped):
            a.setflags(write=False)
        self._params = np.zeros(3 * self.dim)  # target, kp, error (the kernel's layout)
        self._int_params = np.concatenate([self.indices, self.tracked, self.wrapped])
        self._int_params = self._int_params.astype(np.int64)
        self.kp = kp
        self.set_target(robot.joint_positions(robot.home())[idx] if target is None else target)

    @property
    def dim(self) -> int:
        return self.indices.size

    def _view(self, k: int) -> np.ndarray:
        """Part ``k`` of the parameter block (0: target, 1: kp, 2: error), read-only."""
        n = self.dim
        out = self._params[k * n : (k + 1) * n]
        out.setflags(write=False)
        return out

    @property
    def kp(self) -> np.ndarray:
        """Gain (1/s) per joint (read-only)."""
        return self._view(1)

    @kp.setter
    def kp(self, value: float | Sequence[float]) -> None:
        try:
            kp = np.broadcast_to(np.asarray(value, float), self.indices.shape)
        except (TypeError, ValueError) as exc:
            raise DimensionError(
                f"{self.name}: kp must be a number or {self.dim} numbers, got {value!r}"
            ) from exc
        if not np.all(np.isfinite(kp)) or np.any(kp < 0):
            raise DimensionError(f"{self.name}: kp must be finite and >= 0")
        self._params[self.dim : 2 * self.dim] = kp

    @property
    def target(self) -> np.ndarray:
        """Reference positions (rad, m), one per joint (read-only)."""
        return self._view(0)

    def set_target(self, target: np.ndarray | Sequence[float]) -> None:
        """Reference positions, one per joint of the task (rad, m)."""
        t = np.asarray(target, dtype=float)
        if t.shape != self.indices.shape or not np.all(np.isfinite(t)):
            raise DimensionError(
                f"{self.name}: target must be {self.indices.size} finite "
                f"values, got shape {t.shape}"
            )
        self._params[: self.dim] = t

    def error(self, state: RobotState) -> np.ndarray:
        self._rows(state, np.empty((self.dim, self.robot.nu)), np.empty(self.dim))
        return self._params[2 * self.dim :].copy()

    def _rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> None:
        posture_rows(state.joint_positions(), self._params, self._int_params, J, v)

    def compute(self, state: RobotState) -> TaskRows:
        J = np.empty((self.dim, self.robot.nu))
        v = np.empty(self.dim)
        self._rows(state, J, v)
        return TaskRows(J, v, self.weights)

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        self._rows(state, J, v)
        return self.weight

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(PostureTask, "compute", "write_rows", "error"):
            return None
        return Packed(KIND_POSTURE, self._params, self._int_params)

    def __repr__(self) -> str:
        return f"PostureTask({self.name!r}, joints={self.dim})"
