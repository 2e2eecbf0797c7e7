"""Relative pose of two frames (the dual-arm closed chain), and relative position in the
axes of a third frame.

The pose of frame b in frame a, ``T_ab = T_a^-1 T_b``, tracks a target (for a carried object,
the constant ``T_ab = T_a,obj T_b,obj^-1`` of the two grasps). In a's axes, with
``r = p_b - p_a``, the relative twist is::

    v_ab = R_a^T (v_b - v_a + [r]x w_a)          w_ab = R_a^T (w_b - w_a)

so the relative Jacobian is ``R_a^T [J_b,lin - J_a,lin + [r]x J_a,ang ; J_b,ang - J_a,ang]``
(:func:`wholebody.kernels.rows.relative_pose`). The rows and the PI law are those of
:class:`~wholebody.tasks.frame.FrameTask`, in a's axes.

:class:`RelativePositionTask` tracks only ``r = p_b - p_a`` in the axes of a frame c (e.g. the
wrist relative to the shoulder in the base's axes, as a person's wrist is recorded relative to
their shoulder). With ``d/dt R_c^T = -R_c^T [w_c]x``::

    d (R_c^T r) / dt = R_c^T (v_b - v_a + [r]x w_c)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wholebody.kernels.rows import relative_pose
from wholebody.robot import Frame, Robot, RobotState
from wholebody.tasks.base import Packed, Packer
from wholebody.tasks.frame import PoseTask

__all__ = ["RelativeFrameTask", "RelativePositionTask"]


class RelativeFrameTask(PoseTask):
    """Keep frame ``b``'s pose in frame ``a`` at a target (6 rows, or 3 by mask).

    Parameters are those of :class:`~wholebody.tasks.frame.FrameTask`; the target is the pose
    of b in a (4x4) and the target twist is b's relative twist in a's axes (zero for a rigid
    grasp).
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
        lm_damping: float = 0.0,
    ) -> None:
        self.frame_a = robot.frame(frame_a)
        self.frame_b = robot.frame(frame_b)
        super().__init__(
            robot,
            name or f"{self.frame_a.name}->{self.frame_b.name}",
            position=position,
            orientation=orientation,
            kp=kp,
            ki=ki,
            integral_limit=integral_limit,
            weight=weight,
            lm_damping=lm_damping,
        )

    def _measured(self, state: RobotState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Ra, pa = state.rotation_translation(self.frame_a)
        Rb, pb = state.rotation_translation(self.frame_b)
        J = np.empty((6, self.robot.nu))
        p = np.empty(3)
        R = np.empty((3, 3))
        Ja, Jb = state.jacobian(self.frame_a), state.jacobian(self.frame_b)
        relative_pose(Ja, pa, np.ascontiguousarray(Ra), Jb, pb, np.ascontiguousarray(Rb), J, p, R)
        return J, p, R

    def relative_pose(self, state: RobotState) -> np.ndarray:
        """The current pose of b in a (4x4): ``[R_a^T R_b, R_a^T (p_b - p_a)]``."""
        _, p, R = self._measured(state)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = p
        return T

    def relative_jacobian(self, state: RobotState) -> np.ndarray:
        """6 x nu Jacobian of b's twist relative to a, in a's axes."""
        return self._measured(state)[0]

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return (self.frame_a, self.frame_b)

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(RelativeFrameTask, "_measured"):
            return None
        return self._pack(packer, packer.frame(self.frame_a), packer.frame(self.frame_b))

    def __repr__(self) -> str:
        return f"RelativeFrameTask({self.name!r}, rows={self.dim})"


class RelativePositionTask(PoseTask):
    """Keep ``R_c^T (p_b - p_a)``, frame b's position relative to frame a in the axes of frame
    ``axes`` (c; default a), at a target (3 rows, m).

    The target is a 4x4 pose whose translation is that vector (its rotation is ignored) and
    the target twist's linear part is its rate (m/s) in c's axes, so that a position
    trajectory drives it as it drives a :class:`~wholebody.tasks.frame.FrameTask`. Gains and
    the PI law are those of :class:`~wholebody.tasks.frame.FrameTask`.
    """

    def __init__(
        self,
        robot: Robot,
        frame_a: str | Frame,
        frame_b: str | Frame,
        *,
        axes: str | Frame | None = None,
        name: str | None = None,
        kp: float | Sequence[float] = 10.0,
        ki: float | Sequence[float] = 0.0,
        integral_limit: float = 0.05,
        weight: float | Sequence[float] = 1.0,
        lm_damping: float = 0.0,
    ) -> None:
        self.frame_a = robot.frame(frame_a)
        self.frame_b = robot.frame(frame_b)
        self.axes = self.frame_a if axes is None else robot.frame(axes)
        super().__init__(
            robot,
            name or f"{self.frame_a.name}->{self.frame_b.name}",
            position=True,
            orientation=False,
            kp=kp,
            ki=ki,
            integral_limit=integral_limit,
            weight=weight,
            lm_damping=lm_damping,
        )

    def _measured(self, state: RobotState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Rc = state.rotation(self.axes)
        r = state.position(self.frame_b) - state.position(self.frame_a)
        skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        J = np.zeros((6, self.robot.nu))
        J[:3] = Rc.T @ (
            state.jacobian(self.frame_b)[:3]
            - state.jacobian(self.frame_a)[:3]
            + skew @ state.jacobian(self.axes)[3:]
        )
        return J, Rc.T @ r, np.eye(3)

    def relative_position(self, state: RobotState) -> np.ndarray:
        """``R_c^T (p_b - p_a)`` (m) at ``state``."""
        return self._measured(state)[1]

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return (self.frame_a, self.frame_b, self.axes)

    def __repr__(self) -> str:
        return f"RelativePositionTask({self.name!r}, rows={self.dim})"
