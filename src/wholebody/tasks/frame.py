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

from wholebody._numeric import float_array
from wholebody._poses import check_pose
from wholebody.errors import DimensionError
from wholebody.kernels.layout import KIND_POSE
from wholebody.kernels.rows import (
    POSE_ERROR,
    POSE_FA,
    POSE_FB,
    POSE_FINE,
    POSE_HAS,
    POSE_INTEGRAL,
    POSE_INTS,
    POSE_KI,
    POSE_KP,
    POSE_LIMIT,
    POSE_NROWS,
    POSE_SEL,
    POSE_STAMP,
    POSE_TARGET,
    POSE_TWIST,
    POSE_WIDTH,
    TARGET_HELD,
    TARGET_NONE,
    TARGET_SET,
    advance_integral,
    pose_rows,
    set_target,
)
from wholebody.robot import Frame, Robot, RobotState
from wholebody.tasks.base import Packed, Packer, Task, TaskRows

__all__ = [
    "FrameTask",
    "PoseTask",
    "check_pose",
    "check_twist",
    "pose_error",
]


_NO_TWIST = np.zeros(6)
_NO_TWIST.setflags(write=False)
_ZERO_TWIST = np.zeros(6)  # (writable: the kernels' array type; never written)
_F64 = np.dtype(np.float64)


def _plain(a: np.ndarray) -> bool:
    """Whether ``a`` is of the array type the kernels are compiled for (C-contiguous and
    writable; another would compile them again)."""
    flags = a.flags
    return flags.c_contiguous and flags.writeable


def check_twist(twist: np.ndarray | None, what: str) -> np.ndarray:
    """A finite 6-vector [linear (m/s), angular (rad/s)] (read-only zeros when None)."""
    if twist is None:
        return _NO_TWIST
    t = float_array(twist, what).copy()
    if t.shape != (6,) or (not math.isfinite(t @ t) and not np.isfinite(t).all()):
        raise DimensionError(f"{what}: expected a finite twist of shape (6,), got {t.shape}")
    return t


def _gain(value: float | Sequence[float], what: str) -> np.ndarray:
    """A (6,) gain from a number or 6 numbers, finite and >= 0."""
    try:
        g = np.broadcast_to(np.asarray(value, dtype=float), (6,)).copy()
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{what} must be a number or 6 numbers, got {value!r}") from exc
    if not np.all(np.isfinite(g)) or np.any(g < 0):
        raise DimensionError(f"{what} must be finite and >= 0, got {value!r}")
    return g


def pose_error(p: np.ndarray, R: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(6,) error ``[p_d - p; log3(E)]`` and ``E = R_d R^T`` (all in one frame's axes)."""
    E = target[:3, :3] @ R.T
    return np.concatenate([target[:3, 3] - p, pin.log3(E)]), E


class PoseTask(Task):
    """What :class:`FrameTask` and :class:`~wholebody.tasks.relative.RelativeFrameTask` share:
    a pose tracked with the PI law, its target, gains, integral and the error of its last rows.

    Subclasses say what is tracked (:meth:`_measured`: the Jacobian, position and rotation in
    the task's axes; :meth:`pack`: the frames the kernels read). The rows come from the
    kernel :func:`wholebody.kernels.rows.pose_rows`, the same one the compiled stack runs, on
    the task's parameter block (``POSE_*`` of :mod:`wholebody.kernels.rows`): gains, target,
    twist, integral and error live there, shared with the stack that runs the task.

    Gains and targets are read-only arrays: change them by assignment or :meth:`set_target`;
    the integral is updated in place.
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
        lm_damping: float = 0.0,
    ) -> None:
        if not (position or orientation):
            raise DimensionError(
                f"{type(self).__name__}: track the position, the orientation or both"
            )
        self.robot = robot
        self.rows = np.flatnonzero([position] * 3 + [orientation] * 3)
        self.rows.setflags(write=False)
        super().__init__(name, weight, lm_damping=lm_damping)
        self._params = np.zeros(POSE_WIDTH)
        self._params[POSE_STAMP] = -1.0
        self.kp = kp
        self.ki = ki
        self.integral_limit = integral_limit

    def _view(self, start: int, size: int) -> np.ndarray:
        """A read-only view of the parameter block."""
        out = self._params[start : start + size]
        out.setflags(write=False)
        return out

    @property
    def kp(self) -> np.ndarray:
        """Proportional gain (1/s) per component [x, y, z, rx, ry, rz] (read-only)."""
        return self._view(POSE_KP, 6)

    @kp.setter
    def kp(self, value: float | Sequence[float]) -> None:
        self._params[POSE_KP : POSE_KP + 6] = _gain(value, f"{self.name}: kp")

    @property
    def ki(self) -> np.ndarray:
        """Integral gain (1/s^2) per component (read-only)."""
        return self._view(POSE_KI, 6)

    @ki.setter
    def ki(self, value: float | Sequence[float]) -> None:
        self._params[POSE_KI : POSE_KI + 6] = _gain(value, f"{self.name}: ki")

    @property
    def integral_limit(self) -> float:
        """Anti-windup clamp of each integral component (m s, rad s)."""
        return float(self._params[POSE_LIMIT])

    @integral_limit.setter
    def integral_limit(self, value: float) -> None:
        if not (isinstance(value, (int, float, np.floating)) and value >= 0):
            raise DimensionError(f"{self.name}: integral_limit must be >= 0, got {value!r}")
        self._params[POSE_LIMIT] = float(value)

    @property
    def integral(self) -> np.ndarray:
        """The integral of the error (m s, rad s), advanced in place each step."""
        return self._params[POSE_INTEGRAL : POSE_INTEGRAL + 6]

    @property
    def last_error(self) -> np.ndarray:
        """The (6,) error ``[p_d - p; log3(E)]`` (m, rad) the last rows were computed with,
        by this task or by the kernel of a stack that runs it (read-only; zeros before)."""
        return self._view(POSE_ERROR, 6)

    @property
    def target(self) -> np.ndarray | None:
        """The target pose (4x4, read-only), or None before it is set or captured."""
        if self._params[POSE_HAS] == TARGET_NONE:
            return None
        return self._view(POSE_TARGET, 16).reshape(4, 4)

    @property
    def target_twist(self) -> np.ndarray:
        """The target twist ``[v (m/s), w (rad/s)]`` (read-only)."""
        return self._view(POSE_TWIST, 6)

    @property
    def dim(self) -> int:
        return self.rows.size

    def set_target(self, pose: np.ndarray | pin.SE3, twist: np.ndarray | None = None) -> None:
        """Target pose (4x4 or SE3) and twist ``[v (m/s), w (rad/s)]`` (zero when omitted), in
        the task's axes (see the subclass)."""
        try:  # (a plain float array, as a control loop passes, is taken as it is)
            T = (
                pose
                if pose.__class__ is np.ndarray and pose.dtype is _F64  # type: ignore[union-attr]
                else float_array(pose.homogeneous if isinstance(pose, pin.SE3) else pose, "pose")
            )
            t = _ZERO_TWIST if twist is None else float_array(twist, "twist")
        except DimensionError:
            T = t = _NO_TWIST  # (the checks below raise with the task's name)
        if (
            T.shape == (4, 4)  # type: ignore[union-attr]
            and t.shape == (6,)
            and _plain(T)  # type: ignore[arg-type]
            and (t is _ZERO_TWIST or _plain(t))
            and set_target(self._params, T, t) == POSE_FINE
        ):  # checked and written by one kernel call
            return
        T = check_pose(pose, f"{self.name}: target pose")
        t = check_twist(twist, f"{self.name}: target twist")
        par = self._params
        par[POSE_TARGET : POSE_TARGET + 16] = T.ravel()
        par[POSE_TWIST : POSE_TWIST + 6] = t
        par[POSE_HAS] = TARGET_SET
        par[POSE_STAMP] = -1.0  # the last error was for another target

    def current_target(self, state: RobotState) -> np.ndarray:
        """The target, capturing the current pose when none is set (held until
        :meth:`reset`)."""
        if self._params[POSE_HAS] == TARGET_NONE:
            self._full_error(state)
        return self.target  # type: ignore[return-value]

    def _measured(self, state: RobotState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The tracked pose's Jacobian (6 x nu), position and rotation at ``state``."""
        raise NotImplementedError

    def compute(self, state: RobotState) -> TaskRows:
        A = np.empty((self.rows.size, self.robot.nu))
        v = np.empty(self.rows.size)
        self.write_rows(state, A, v)
        return TaskRows(A, v, self.weights)

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        Jm, p, R = self._measured(state)
        pose_rows(self._params, Jm, p, R, self.rows, J, v)
        self._params[POSE_STAMP] = state.stamp
        return self.weight

    def _full_error(self, state: RobotState) -> np.ndarray:
        """The (6,) error at ``state`` and the current target: that of the last rows when
        they were computed there (by a stack's kernel or by this task), else computed."""
        if self._params[POSE_STAMP] != state.stamp or not state.valid:
            self.write_rows(
                state, np.empty((self.rows.size, self.robot.nu)), np.empty(self.rows.size)
            )
        return self._params[POSE_ERROR : POSE_ERROR + 6]

    def error(self, state: RobotState) -> np.ndarray:
        """(dim,) error: position error (m) and/or orientation error (rad)."""
        return self._full_error(state)[self.rows]

    def advance(self, state: RobotState, dt: float, saturated: bool = False) -> None:
        self._full_error(state)
        advance_integral(self._params, bool(saturated), float(dt))

    def reset(self) -> None:
        """Zero the integral; a target captured at first use (none was set) is forgotten."""
        self._params[POSE_INTEGRAL : POSE_INTEGRAL + 6] = 0.0
        if self._params[POSE_HAS] == TARGET_HELD:
            self._params[POSE_HAS] = TARGET_NONE
            self._params[POSE_STAMP] = -1.0  # the last error was for the forgotten target

    def _pack(self, packer: Packer, fa: int, fb: int) -> Packed | None:
        """The kernel's view of this task tracking frame ``fb`` (relative to ``fa``, -1: the
        world), unless a subclass changed what it computes."""
        if not self.compiled_as(
            PoseTask, "compute", "write_rows", "error", "advance", "_full_error"
        ):
            return None
        ints = np.zeros(POSE_INTS, dtype=np.int64)
        ints[POSE_FA], ints[POSE_FB], ints[POSE_NROWS] = fa, fb, self.rows.size
        ints[POSE_SEL : POSE_SEL + self.rows.size] = self.rows
        return Packed(KIND_POSE, self._params, ints)


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
    lm_damping
        Levenberg-Marquardt damping (:class:`~wholebody.tasks.Task`; 0: none).

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
        lm_damping: float = 0.0,
    ) -> None:
        self.frame = robot.frame(frame)
        super().__init__(
            robot,
            name or self.frame.name,
            position=position,
            orientation=orientation,
            kp=kp,
            ki=ki,
            integral_limit=integral_limit,
            weight=weight,
            lm_damping=lm_damping,
        )

    def _measured(self, state: RobotState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        R, p = state.rotation_translation(self.frame)
        return state.jacobian(self.frame), p, np.ascontiguousarray(R)

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return (self.frame,)

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(FrameTask, "_measured"):
            return None
        return self._pack(packer, -1, packer.frame(self.frame))

    def __repr__(self) -> str:
        return f"FrameTask({self.name!r}, frame={self.frame.name!r}, rows={self.dim})"
