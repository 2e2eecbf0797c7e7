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
each component is clamped to ``+-integral_limit``, and while the solver reports saturation the
integral may only shrink (conditional integration).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from wholebody._numeric import count_nonzero as _count_nonzero
from wholebody.errors import DimensionError
from wholebody.robot import Frame, Robot, RobotState
from wholebody.tasks.base import Task, TaskRows

__all__ = [
    "FrameTask",
    "PoseRows",
    "check_pose",
    "check_twist",
    "integrate_error",
    "pose_error",
    "pose_rows",
]


def check_pose(pose: np.ndarray, what: str) -> np.ndarray:
    """A 4x4 homogeneous transform with an orthonormal rotation, or DimensionError."""
    T = np.array(pose.homogeneous if isinstance(pose, pin.SE3) else pose, dtype=float)
    if T.shape != (4, 4):
        raise DimensionError(f"{what}: expected a finite 4x4 pose, got shape {T.shape}")
    (a0, a1, a2, p0), (b0, b1, b2, p1), (c0, c1, c2, p2), (d0, d1, d2, d3) = T.tolist()
    # A NaN or inf anywhere makes the sum non-finite (an overflow of it: the exact test).
    total = a0 + a1 + a2 + p0 + b0 + b1 + b2 + p1 + c0 + c1 + c2 + p2 + d0 + d1 + d2 + d3
    if not math.isfinite(total) and not np.isfinite(T).all():
        raise DimensionError(f"{what}: expected a finite 4x4 pose, got shape {T.shape}")
    if abs(d0) + abs(d1) + abs(d2) + abs(d3 - 1.0) > 1e-9:
        raise DimensionError(f"{what}: the last row of a 4x4 pose must be [0, 0, 0, 1], got "
                             f"{T[3].tolist()} (a transposed matrix?)")  # fmt: skip
    det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
    # R^T R - I, entry by entry (its six distinct entries)
    gram = (
        a0 * a0 + b0 * b0 + c0 * c0 - 1.0,
        a1 * a1 + b1 * b1 + c1 * c1 - 1.0,
        a2 * a2 + b2 * b2 + c2 * c2 - 1.0,
        a0 * a1 + b0 * b1 + c0 * c1,
        a0 * a2 + b0 * b2 + c0 * c2,
        a1 * a2 + b1 * b2 + c1 * c2,
    )
    if det < 0 or max(map(abs, gram)) > 1e-6:
        raise DimensionError(f"{what}: the rotation part is not a rotation matrix")
    return T


def check_twist(twist: np.ndarray | None, what: str) -> np.ndarray:
    """A finite 6-vector [linear (m/s), angular (rad/s)] (zeros when None)."""
    if twist is None:
        return np.zeros(6)
    t = np.array(twist, dtype=float)
    if t.shape != (6,) or (not math.isfinite(t @ t) and not np.isfinite(t).all()):
        raise DimensionError(f"{what}: expected a finite twist of shape (6,), got {t.shape}")
    return t


def _gain(value: float | Sequence[float], what: str) -> np.ndarray:
    g = np.broadcast_to(np.asarray(value, dtype=float), (6,)).copy()
    if not np.all(np.isfinite(g)) or np.any(g < 0):
        raise DimensionError(f"{what} must be finite and >= 0, got {value!r}")
    return g


def pose_error(p: np.ndarray, R: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(6,) error ``[p_d - p; log3(E)]`` and ``E = R_d R^T`` (all in one frame's axes)."""
    E = target[:3, :3] @ R.T
    return np.concatenate([target[:3, 3] - p, pin.log3(E)]), E


def pose_rows(
    J: np.ndarray,
    p: np.ndarray,
    R: np.ndarray,
    target: np.ndarray,
    twist: np.ndarray,
    kp: np.ndarray,
    ki: np.ndarray,
    integral: np.ndarray,
    rows: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Task Jacobian, right-hand side and error of a pose task (see the module docstring).

    ``J`` is the frame's 6 x nu Jacobian in the axes in which ``p, R, target, twist`` are
    expressed; ``rows`` selects among the 6 rows.
    """
    A = np.empty((6, J.shape[1]))
    v = np.empty(6)
    e = PoseRows()(J, p, R, target, twist, kp, ki, integral, A, v).copy()
    if rows.size == 6:
        return A, v, e
    return A[rows], v[rows], e


class PoseRows:
    """The 6 rows of a pose task with preallocated work arrays (one per task).

    With ``K = diag(I, Jlog3(E))`` the rows are ``K J`` and the right-hand side is
    ``K [v_d; E^T w_d] + Kp e + Ki I``: two products instead of a product per part.
    """

    __slots__ = ("K", "_Ko", "_Rd", "_eo", "_ep", "_pd", "_target", "_written", "e", "ff")

    def __init__(self) -> None:
        self.K = np.eye(6)
        self.ff = np.empty(6)
        self.e = np.empty(6)
        # views made once: K's Jlog3 block, the error's parts, the last target's parts
        self._Ko = self.K[3:, 3:]
        self._ep = self.e[:3]
        self._eo = self.e[3:]
        self._target: np.ndarray | None = None
        self._Rd = self._pd = None
        self._written: tuple[object, np.ndarray] | None = None  # (state, target) of self.e

    def __call__(
        self,
        J: np.ndarray,
        p: np.ndarray,
        R: np.ndarray,
        target: np.ndarray,
        twist: np.ndarray,
        kp: np.ndarray,
        ki: np.ndarray,
        integral: np.ndarray,
        A: np.ndarray,
        v: np.ndarray,
    ) -> np.ndarray:
        """Write the rows into ``A`` and ``v``; return the error (a work array: copy it to
        keep it)."""
        if target is not self._target:
            self._target, self._Rd, self._pd = target, target[:3, :3], target[:3, 3]
        E = self._Rd.dot(R.T)
        K, ff, e = self.K, self.ff, self.e
        self._Ko[...] = pin.Jlog3(E)
        np.dot(K, J, out=A)
        np.subtract(self._pd, p, out=self._ep)
        self._eo[...] = pin.log3(E)
        if _count_nonzero(twist):
            ff[:3] = twist[:3]
            np.dot(twist[3:], E, out=ff[3:])  # E^T w_d
            np.dot(K, ff, out=v)
            v += kp * e
        else:  # no feed-forward: K 0 = 0
            np.multiply(kp, e, out=v)
        if _count_nonzero(integral):  # integral.any(), without its Python wrapper
            v += ki * integral
        return e

    def error_at(self, state: object, target: np.ndarray | None) -> np.ndarray | None:
        """The full (6,) error of the last :meth:`write` if it was at ``state`` and
        ``target`` (a task's advance after its solve), else None."""
        w = self._written
        return self.e if w is not None and w[0] is state and w[1] is target else None

    def write(
        self,
        state: object,
        rows: np.ndarray,
        J: np.ndarray,
        p: np.ndarray,
        R: np.ndarray,
        target: np.ndarray,
        twist: np.ndarray,
        kp: np.ndarray,
        ki: np.ndarray,
        integral: np.ndarray,
        A: np.ndarray,
        v: np.ndarray,
    ) -> None:
        """:meth:`__call__` at ``state`` keeping only the rows ``rows`` (indices among the 6),
        written into ``A`` (len(rows) x nu) and ``v``: straight into them when all 6 are
        kept. The full error stays available to :meth:`error_at`."""
        self._written = (state, target)
        if rows.size == 6:
            self(J, p, R, target, twist, kp, ki, integral, A, v)
            return
        A6, v6 = np.empty((6, A.shape[1])), np.empty(6)
        self(J, p, R, target, twist, kp, ki, integral, A6, v6)
        A[...] = A6[rows]
        v[...] = v6[rows]


class FrameTask(Task):
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
        if not (position or orientation):
            raise DimensionError("FrameTask: track the position, the orientation or both")
        self.robot = robot
        self.frame = robot.frame(frame)
        self.name = name or self.frame.name
        self.rows = np.flatnonzero([position] * 3 + [orientation] * 3)
        self.kp = _gain(kp, f"{self.name}: kp")
        self.ki = _gain(ki, f"{self.name}: ki")
        if not integral_limit >= 0:
            raise DimensionError(f"{self.name}: integral_limit must be >= 0")
        self.integral_limit = float(integral_limit)
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
        """Target pose (4x4 or SE3, world) and twist ``[v (m/s), w (rad/s)]`` (world axes,
        linear velocity of the target frame's origin; zero when omitted)."""
        self.target = check_pose(pose, f"{self.name}: target pose")
        self.target_twist = check_twist(twist, f"{self.name}: target twist")
        self._held = False

    def _target(self, state: RobotState) -> np.ndarray:
        if self.target is None:  # hold the current pose until told otherwise
            self.target = state.pose(self.frame)
            self._held = True
        return self.target

    def compute(self, state: RobotState) -> TaskRows:
        A = np.empty((self.rows.size, self.robot.nu))
        v = np.empty(self.rows.size)
        self.write_rows(state, A, v)
        return TaskRows(A, v, self._weights())

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        R, p = state.rotation_translation(self.frame)
        target = self.target if self.target is not None else self._target(state)
        self._rows.write(state, self.rows, state.jacobian(self.frame), p, R, target,
                         self.target_twist, self.kp, self.ki, self.integral, J, v)  # fmt: skip
        return self.weight

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return (self.frame,)

    def error(self, state: RobotState) -> np.ndarray:
        """(dim,) error: position error (m) and/or orientation error (rad), world axes."""
        e, _ = pose_error(state.position(self.frame), state.rotation(self.frame),
                                   self._target(state))  # fmt: skip
        return e[self.rows]

    def advance(self, state: RobotState, dt: float, saturated: bool = False) -> None:
        ki = self.ki
        if not (_count_nonzero(ki) if isinstance(ki, np.ndarray) else np.any(ki)):
            return
        e = self._rows.error_at(state, self.target)  # the rows' own, after the usual solve
        if e is None:
            e, _ = pose_error(state.position(self.frame), state.rotation(self.frame),
                              self._target(state))  # fmt: skip
        integrate_error(self.integral, e, dt, saturated, self.integral_limit)

    def reset(self) -> None:
        """Zero the integral; a target captured at first use (none was set) is forgotten."""
        self.integral[:] = 0.0
        if self._held:
            self.target, self._held = None, False

    def __repr__(self) -> str:
        return f"FrameTask({self.name!r}, frame={self.frame.name!r}, rows={self.dim})"


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
