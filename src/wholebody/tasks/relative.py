"""Relative pose of two frames: the dual-arm closed chain.

The pose of frame b in frame a, ``T_ab = T_a^-1 T_b``, tracks a target (for a carried object,
the constant ``T_ab = T_a,obj T_b,obj^-1`` of the two grasps). In a's axes, with
``r = p_b - p_a``, the relative twist is::

    v_ab = R_a^T (v_b - v_a + [r]x w_a)          w_ab = R_a^T (w_b - w_a)

so the relative Jacobian is ``R_a^T [J_b,lin - J_a,lin + [r]x J_a,ang ; J_b,ang - J_a,ang]``.
The rows and the PI law are those of :class:`~wholebody.tasks.frame.FrameTask`, in a's axes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from wholebody._numeric import count_nonzero as _count_nonzero
from wholebody.robot import Frame, Robot, RobotState
from wholebody.tasks.base import Task, TaskRows
from wholebody.tasks.frame import (
    FrameTask,
    PoseRows,
    check_pose,
    check_twist,
    integrate_error,
    pose_error,
    pose_rows,
)

__all__ = ["RelativeFrameTask"]


class RelativeFrameTask(Task):
    """Keep frame ``b``'s pose in frame ``a`` at a target (6 rows, or 3 by mask).

    Parameters are those of :class:`FrameTask`; the target is the pose of b in a (4x4) and the
    target twist is b's relative twist in a's axes (zero for a rigid grasp).
    """

    def __init__(
        self,
        robot: Robot,
        frame_a: str | Frame,
        frame_b: str | Frame,
        *,
        name: str | None = None,
        position: bool = True,
        orientation: bool = True,
        kp: float | Sequence[float] = 10.0,
        ki: float | Sequence[float] = 0.0,
        integral_limit: float = 0.05,
        weight: float | Sequence[float] = 1.0,
    ) -> None:
        # Reuse FrameTask's argument checks and gain handling.
        proto = FrameTask(robot, frame_b, name=name, position=position, orientation=orientation,
                          kp=kp, ki=ki, integral_limit=integral_limit, weight=weight)  # fmt: skip
        self.robot = robot
        self.frame_a = robot.frame(frame_a)
        self.frame_b = proto.frame
        self.name = name or f"{self.frame_a.name}->{self.frame_b.name}"
        self.rows, self.kp, self.ki = proto.rows, proto.kp, proto.ki
        self.integral_limit = proto.integral_limit
        self.weight = weight
        self.target: np.ndarray | None = None
        self.target_twist = np.zeros(6)
        self.integral = np.zeros(6)
        self._held = False  # the target is the pose captured at first use (reset forgets it)
        self._rows = PoseRows()

    @property
    def dim(self) -> int:
        return self.rows.size

    def set_target(self, pose: np.ndarray | pin.SE3, twist: np.ndarray | None = None) -> None:
        """Target pose of b in a (4x4 or SE3) and relative twist (a's axes; zero if omitted)."""
        self.target = check_pose(pose, f"{self.name}: target pose")
        self.target_twist = check_twist(twist, f"{self.name}: target twist")
        self._held = False

    def relative_pose(self, state: RobotState) -> np.ndarray:
        """The current pose of b in a (4x4): ``[R_a^T R_b, R_a^T (p_b - p_a)]``."""
        Ra, pa = state.rotation_translation(self.frame_a)
        Rb, pb = state.rotation_translation(self.frame_b)
        T = np.eye(4)
        T[:3, :3] = Ra.T.dot(Rb)
        T[:3, 3] = Ra.T.dot(pb - pa)
        return T

    def relative_jacobian(self, state: RobotState) -> np.ndarray:
        """6 x nu Jacobian of b's twist relative to a, in a's axes."""
        Ja, Jb = state.jacobian(self.frame_a), state.jacobian(self.frame_b)
        Ra, pa = state.rotation_translation(self.frame_a)
        rx, ry, rz = (state.rotation_translation(self.frame_b)[1] - pa).tolist()
        J = Jb - Ja
        J[:3] += np.array([[0.0, -rz, ry], [rz, 0.0, -rx], [-ry, rx, 0.0]]).dot(Ja[3:])  # r x w_a
        out = np.empty_like(J)
        np.dot(Ra.T, J[:3], out=out[:3])
        np.dot(Ra.T, J[3:], out=out[3:])
        return out

    def _relative(self, state: RobotState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        T = self.relative_pose(state)
        if self.target is None:  # hold the current relative pose
            self.target, self._held = T.copy(), True
        return T[:3, 3], T[:3, :3], self.target

    def compute(self, state: RobotState) -> TaskRows:
        p, R, target = self._relative(state)
        A, v, _ = pose_rows(self.relative_jacobian(state), p, R, target, self.target_twist,
                            self.kp, self.ki, self.integral, self.rows)  # fmt: skip
        return TaskRows(A, v, self._weights())

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        p, R, target = self._relative(state)
        self._rows.write(state, self.rows, self.relative_jacobian(state), p, R, target,
                         self.target_twist, self.kp, self.ki, self.integral, J, v)  # fmt: skip
        return self.weight

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return (self.frame_a, self.frame_b)

    def error(self, state: RobotState) -> np.ndarray:
        """(dim,) relative pose error in a's axes: position (m) and/or orientation (rad)."""
        e, _ = pose_error(*self._relative(state))
        return e[self.rows]

    def advance(self, state: RobotState, dt: float, saturated: bool = False) -> None:
        if not _count_nonzero(self.ki):
            return
        e = self._rows.error_at(state, self.target)  # the rows' own, after the usual solve
        if e is None:
            e, _ = pose_error(*self._relative(state))
        integrate_error(self.integral, e, dt, saturated, self.integral_limit)

    def reset(self) -> None:
        """Zero the integral; a target captured at first use (none was set) is forgotten."""
        self.integral[:] = 0.0
        if self._held:
            self.target, self._held = None, False

    def __repr__(self) -> str:
        return f"RelativeFrameTask({self.name!r}, rows={self.dim})"
