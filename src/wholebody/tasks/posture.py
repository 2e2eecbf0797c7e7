"""Joint posture regulation: ``u_j = kp (q_ref,j - q_j)`` for a set of actuated joints.

For joints with a position (revolute, prismatic) the error is ``q_ref - q``; for continuous
joints other than wheels (an endless wrist) it is that difference wrapped into ``[-pi, pi)``,
the shorter way round; for wheels and the virtual actuators of a planar base it is zero, so
their rows damp the speed to zero (at a low priority this pins, e.g., the Mecanum base's
internal wheel mode).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from wholebody.errors import DimensionError
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Task, TaskRows

__all__ = ["PostureTask"]


class PostureTask(Task):
    """Drive joints towards reference positions.

    Parameters
    ----------
    robot
        The robot.
    joints
        A group name, a list of joint names, or None for every actuated velocity.
    target
        Reference positions (rad, m), one per joint; defaults to the home posture.
    kp
        Gain (1/s), scalar or per joint.
    weight
        Weight in its level, scalar or per joint.
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
    ) -> None:
        self.robot = robot
        if joints is None:
            idx = np.arange(robot.nu)
            label = "posture"
        elif isinstance(joints, str):
            idx = robot.group(joints).indices
            label = f"posture[{joints}]"
        else:
            idx = np.array([robot.index(j) for j in joints], dtype=int)
            label = "posture"
        self.indices = idx
        self._all = idx.size == robot.nu and bool(np.all(idx == np.arange(robot.nu)))
        self.name = name or label
        base = np.arange(robot.nu) < len(robot.base.actuators)  # wheels, planar actuators
        self._tracked = (~base)[idx].astype(float)  # 0: no position error
        self._wrapped = np.flatnonzero(~robot.positional[idx] & ~base[idx])  # endless joints
        self.kp = np.broadcast_to(np.asarray(kp, float), idx.shape).copy()
        if not np.all(np.isfinite(self.kp)) or np.any(self.kp < 0):
            raise DimensionError(f"{self.name}: kp must be finite and >= 0")
        self.weight = weight
        self._J = np.zeros((idx.size, robot.nu))
        self._J[np.arange(idx.size), idx] = 1.0
        self._J.setflags(write=False)
        self.set_target(robot.joint_positions(robot.home())[idx] if target is None else target)

    @property
    def dim(self) -> int:
        return self.indices.size

    def set_target(self, target: np.ndarray | Sequence[float]) -> None:
        """Reference positions, one per joint of the task (rad, m)."""
        t = np.asarray(target, dtype=float)
        if t.shape != self.indices.shape or not np.all(np.isfinite(t)):
            raise DimensionError(f"{self.name}: target must be {self.indices.size} finite "
                                 f"values, got shape {t.shape}")  # fmt: skip
        self.target = t.copy()

    def error(self, state: RobotState) -> np.ndarray:
        e = self.target - state.joint_positions()[self.indices]
        self._finish(e)
        return e

    def _finish(self, e: np.ndarray) -> None:
        """``target - q`` into the error: wrapped for endless joints, 0 for the base."""
        w = self._wrapped
        if w.size:
            e[w] = np.remainder(e[w] + math.pi, 2.0 * math.pi) - math.pi
        e *= self._tracked

    def compute(self, state: RobotState) -> TaskRows:
        return TaskRows(self._J, self.kp * self.error(state), self._weights())

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        jp = state.joint_positions()
        np.subtract(self.target, jp if self._all else jp[self.indices], out=v)
        self._finish(v)
        v *= self.kp
        J[...] = self._J
        return self.weight

    def __repr__(self) -> str:
        return f"PostureTask({self.name!r}, joints={self.dim})"
