"""Pose tracking of a frame with the paper's PI law.

Error (world-aligned axes), position and orientation decoupled (R^3 x SO(3)):

* position ``e_p = p_d - p`` (m),
* orientation ``e_o = log3(E)`` with ``E = R_d R^T`` (rad): the rotation vector that takes the
  frame's orientation to the target's.

Its exact rate, with ``v, w = J u`` the frame's velocity and ``v_d, w_d`` the target's::

    d e_p / dt = v_d - v
    d e_o / dt = Jlog3(E) (E^T w_d - w)

(``Jlog3`` is Pinocchio's right Jacobian of log3). The task asks for the paper's law
``d e / dt = -Kp e - Ki int(e)``, i.e. the rows::

    J_lin u              = v_d + Kp e_p + Ki I_p
    Jlog3(E) J_ang u     = Jlog3(E) E^T w_d + Kp e_o + Ki I_o

At ``e_o = 0`` they reduce to ``J u = x'_d + Kp e + Ki int(e)``, the paper's law verbatim. The
integral ``I`` advances once per control step (:meth:`FrameTask.advance`) with anti-windup:
each component is clamped to ``+-integral_limit``, and while the hard constraints limit this
task (its ``saturated`` flag: see :meth:`~wholebody.solvers.Stack.saturated_tasks`) the
integral may only shrink (conditional integration).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from wholebody._numeric import count_nonzero as _count_nonzero
from wholebody._numeric import float_array
from wholebody._poses import check_pose
from wholebody.errors import DimensionError
from wholebody.kernels.rows import pose_rows
from wholebody.robot import Frame, Robot, RobotState
from wholebody.tasks.base import Task, TaskRows

__all__ = [
    "FrameTask",
    "PoseTask",
    "check_pose",
    "check_twist",
    "integrate_error",
    "pose_error",
]


_NO_TWIST = np.zeros(6)
_NO_TWIST.setflags(write=False)


def check_twist(twist: np.ndarray | None, what: str) -> np.ndarray:
    """A finite 6-vector [linear (m/s), angular (rad/s)] (read-only zeros when None)."""
    if twist is None:
        return _NO_TWIST
    t = float_array(twist, what).copy()
    if t.shape != (6,) or (not math.isfinite(t @ t) and not np.isfinite(t).all()):
        raise DimensionError(f"{what}: expected a finite twist of shape (6,), got {t.shape}")
    return t


def _gain(value: float | Sequence[float], what: str) -> np.ndarray:
    """A read-only (6,) gain from a number or 6 numbers, finite and >= 0."""
    try:
        g = np.broadcast_to(np.asarray(value, dtype=float), (6,)).copy()
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{what} must be a number or 6 numbers, got {value!r}") from exc
    if not np.all(np.isfinite(g)) or np.any(g < 0):
        raise DimensionError(f"{what} must be finite and >= 0, got {value!r}")
    return _readonly(g)


def pose_error(p: np.ndarray, R: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(6,) error ``[p_d - p; log3(E)]`` and ``E = R_d R^T`` (all in one frame's axes)."""
    E = target[:3, :3] @ R.T
    return np.concatenate([target[:3, 3] - p, pin.log3(E)]), E


class PoseTask(Task):
    """What :class:`FrameTask` and :class:`~wholebody.tasks.relative.RelativeFrameTask` share:
    a pose tracked with the PI law, its target, gains, integral and the error of its last rows.

    Subclasses say what is tracked (:meth:`_measured`: the Jacobian, position and rotation in
    the task's axes) and what a held target is (:meth:`_hold`). The rows come from the kernel
    :func:`wholebody.kernels.rows.pose_rows`, the same one the compiled stack runs.

    Gains and targets are read-only arrays: change them by assignment or :meth:`set_target`
    (so that a compiled stack sees every change); the integral is updated in place.
    """

    def __init__(
        self,
        robot: Robot,
        name: str,
        *,
        position: bool,
        orientation: bool,
        kp: float | Sequence[float],
        ki: float | Sequence[float],
        integral_limit: float,
        weight: float | Sequence[float],
    ) -> None:
        if not (position or orientation):
            raise DimensionError(f"{type(self).__name__}: track the position, the orientation "
                                 "or both")  # fmt: skip
        self.robot = robot
        self.rows = np.flatnonzero([position] * 3 + [orientation] * 3)
        self.rows.setflags(write=False)
        super().__init__(name, weight)
        self.kp = kp
        self.ki = ki
        if not integral_limit >= 0:
            raise DimensionError(f"{self.name}: integral_limit must be >= 0")
        self.integral_limit = float(integral_limit)
        self._target: np.ndarray | None = None
        self._twist = _readonly(np.zeros(6))
        self.integral = np.zeros(6)
        """The integral of the error (m s, rad s), advanced in place by :meth:`advance`."""
        self._held = False  # the target is the pose captured at first use (reset forgets it)
        self._error = np.zeros(6)  # the full error of the last rows, at _error_key
        self._error_key: tuple[object, object] | None = None  # (state, target) of _error

    @property
    def kp(self) -> np.ndarray:
        """Proportional gain (1/s) per component [x, y, z, rx, ry, rz] (read-only)."""
        return self._kp

    @kp.setter
    def kp(self, value: float | Sequence[float]) -> None:
        self._kp = _gain(value, f"{self.name}: kp")

    @property
    def ki(self) -> np.ndarray:
        """Integral gain (1/s^2) per component (read-only)."""
        return self._ki

    @ki.setter
    def ki(self, value: float | Sequence[float]) -> None:
        self._ki = _gain(value, f"{self.name}: ki")

    @property
    def target(self) -> np.ndarray | None:
        """The target pose (4x4, read-only), or None before it is set or captured."""
        return self._target

    @property
    def target_twist(self) -> np.ndarray:
        """The target twist ``[v (m/s), w (rad/s)]`` (read-only)."""
        return self._twist

    @property
    def dim(self) -> int:
        return self.rows.size

    def set_target(self, pose: np.ndarray | pin.SE3, twist: np.ndarray | None = None) -> None:
        """Target pose (4x4 or SE3) and twist ``[v (m/s), w (rad/s)]`` (zero when omitted), in
        the task's axes (see the subclass)."""
        self._target = _readonly(check_pose(pose, f"{self.name}: target pose"))
        self._twist = _readonly(check_twist(twist, f"{self.name}: target twist"))
        self._held = False

    def current_target(self, state: RobotState) -> np.ndarray:
        """The target, capturing the current pose when none is set (held until
        :meth:`reset`)."""
        if self._target is None:
            self._target = _readonly(self._hold(state))
            self._held = True
        return self._target

    def _measured(self, state: RobotState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The tracked pose's Jacobian (6 x nu), position and rotation at ``state``."""
        raise NotImplementedError

    def _hold(self, state: RobotState) -> np.ndarray:
        """The pose (4x4) to hold when no target is set."""
        raise NotImplementedError

    def compute(self, state: RobotState) -> TaskRows:
        A = np.empty((self.rows.size, self.robot.nu))
        v = np.empty(self.rows.size)
        self.write_rows(state, A, v)
        return TaskRows(A, v, self.weights)

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        Jm, p, R = self._measured(state)
        target = self.current_target(state)
        pose_rows(Jm, p, R, target, self._twist, self._kp, self._ki, self.integral, self.rows,
                  J, v, self._error)  # fmt: skip
        self._error_key = (state, target)
        return self.weight

    def _full_error(self, state: RobotState) -> np.ndarray:
        """The (6,) error at ``state`` and the current target: that of the last rows when
        they were written there (a task's advance after its solve), else computed."""
        key = self._error_key
        if key is None or key[0] is not state or key[1] is not self._target:
            self.write_rows(state, np.empty((self.rows.size, self.robot.nu)),
                            np.empty(self.rows.size))  # fmt: skip
        return self._error

    def error(self, state: RobotState) -> np.ndarray:
        """(dim,) error: position error (m) and/or orientation error (rad)."""
        return self._full_error(state)[self.rows]

    def advance(self, state: RobotState, dt: float, saturated: bool = False) -> None:
        if not _count_nonzero(self._ki):
            return
        integrate_error(self.integral, self._full_error(state), dt, saturated,
                        self.integral_limit)  # fmt: skip

    def reset(self) -> None:
        """Zero the integral; a target captured at first use (none was set) is forgotten."""
        self.integral[:] = 0.0
        if self._held:
            self._target, self._held = None, False


class FrameTask(PoseTask):
    """Track a target pose (and twist) of a frame: 6 rows, or 3 with position/orientation only.

    Parameters
    ----------
    robot, frame
        The robot and the frame to move (name or :class:`Frame`).
    position, orientation
        Which parts to track (at least one).
    kp
        Proportional gain (1/s), scalar or per [x, y, z, rx, ry, rz].
    ki
        Integral gain (1/s^2), scalar or per component; 0 disables the integral.
    integral_limit
        Anti-windup clamp of each integral component (m s, rad s).
    weight
        Weight in its level, scalar or per row.

    The target pose and twist are in the world (world axes, linear velocity of the target
    frame's origin).
    """

    def __init__(
        self,
        robot: Robot,
        frame: str | Frame,
        *,
        name: str | None = None,
        position: bool = True,
        orientation: bool = True,
        kp: float | Sequence[float] = 10.0,
        ki: float | Sequence[float] = 0.0,
        integral_limit: float = 0.05,
        weight: float | Sequence[float] = 1.0,
    ) -> None:
        self.frame = robot.frame(frame)
        super().__init__(robot, name or self.frame.name, position=position,
                         orientation=orientation, kp=kp, ki=ki, integral_limit=integral_limit,
                         weight=weight)  # fmt: skip

    def _measured(self, state: RobotState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        R, p = state.rotation_translation(self.frame)
        return state.jacobian(self.frame), p, np.ascontiguousarray(R)

    def _hold(self, state: RobotState) -> np.ndarray:
        return state.pose(self.frame)

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return (self.frame,)

    def __repr__(self) -> str:
        return f"FrameTask({self.name!r}, frame={self.frame.name!r}, rows={self.dim})"


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def integrate_error(integral: np.ndarray, e: np.ndarray, dt: float, saturated: bool,
                    limit: float) -> None:  # fmt: skip
    """``I += e dt`` clamped to ``+-limit``; while saturated the integral may only shrink
    towards 0 (a step against it stops at 0, a step along it is dropped)."""
    step = e * dt
    if saturated:
        size = np.abs(integral)
        step = np.where(step * integral < 0, np.clip(step, -size, size), 0.0)
    integral += step
    np.minimum(integral, limit, out=integral)  # np.clip without its Python wrapper
    np.maximum(integral, -limit, out=integral)
