"""The whole-body centre of mass held at a point: what keeps a floating-base robot balanced.

With ``c`` the centre of mass of every link (:meth:`RobotState.com_position
<wholebody.robot.RobotState.com_position>`, world, m) and ``J_c`` its 3 x nu Jacobian, the rows
of the chosen axes are::

    J_c[axes] u = kp (c_ref - c)[axes]        (m/s)

A standing humanoid stays up under physics when its centre of mass stays over its support
polygon (the soles): hold it in ``"xy"`` at the level below the soles' frame tasks. A Python
task (no compiled kernel): the compiled stack has it write its rows into the stack's arena
each step (:meth:`ComTask.write_rows`, from Pinocchio's centre of mass and its Jacobian).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wholebody.errors import DimensionError
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Task, TaskRows

__all__ = ["ComTask"]

_AXES = {"x": 0, "y": 1, "z": 2}


class ComTask(Task):
    """Hold the whole-body centre of mass at a point, along some world axes.

    Parameters
    ----------
    robot
        The robot.
    axes
        The world axes held: ``"xy"`` (default: over the feet), ``"xyz"``, ``"z"``, ...
    target
        The point (m, world; all three coordinates, the unheld ones ignored); default the
        centre of mass at the home posture.
    kp
        Gain (1/s).
    weight
        Weight in its level, scalar or per row.
    lm_damping
        Levenberg-Marquardt damping (:class:`~wholebody.tasks.Task`; 0: none).
    """

    def __init__(
        self,
        robot: Robot,
        axes: str = "xy",
        *,
        name: str = "com",
        target: Sequence[float] | np.ndarray | None = None,
        kp: float = 5.0,
        weight: float | Sequence[float] = 1.0,
        lm_damping: float = 0.0,
    ) -> None:
        if not axes or len(set(axes)) != len(axes) or not set(axes) <= set(_AXES):
            raise DimensionError(f"{name}: axes must be distinct letters of 'xyz', got {axes!r}")
        if not (np.isfinite(kp) and kp >= 0):
            raise DimensionError(f"{name}: kp must be a finite number >= 0, got {kp!r}")
        super().__init__(name, weight, lm_damping=lm_damping)
        self.robot = robot
        self.rows = np.array([_AXES[a] for a in axes], dtype=int)
        self.rows.setflags(write=False)
        self.kp = float(kp)
        self._target, self._velocity = np.zeros(3), np.zeros(3)
        self.set_target(robot.update(robot.home()).com_position() if target is None else target)

    @property
    def dim(self) -> int:
        return self.rows.size

    @property
    def target(self) -> np.ndarray:
        """The point held (m, world; a copy)."""
        return self._target.copy()

    def set_target(
        self,
        target: Sequence[float] | np.ndarray,
        velocity: Sequence[float] | np.ndarray | None = None,
    ) -> None:
        """The point to hold (m, world, three coordinates) and, for a moving one, its
        velocity (m/s, world; default at rest) as feed-forward: the rows ask
        ``J u = velocity + kp (target - com)``."""
        t = np.asarray(target, dtype=float)
        v = np.zeros(3) if velocity is None else np.asarray(velocity, dtype=float)
        for name, x in (("target", t), ("velocity", v)):
            if x.shape != (3,) or not np.all(np.isfinite(x)):
                raise DimensionError(f"{self.name}: {name} must be 3 finite numbers, got {x!r}")
        self._target[:] = t
        self._velocity[:] = v

    def error(self, state: RobotState) -> np.ndarray:
        return (self._target - state.com_position())[self.rows]

    def compute(self, state: RobotState) -> TaskRows:
        J = np.empty((self.dim, state.robot.nu))
        v = np.empty(self.dim)
        ComTask.write_rows(self, state, J, v)
        return TaskRows(J, v, self.weights)

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        if type(self).compute is not ComTask.compute:  # (a subclass's own rows)
            return super().write_rows(state, J, v)
        np.take(state.com_jacobian(), self.rows, axis=0, out=J)
        np.take(self._velocity + self.kp * (self._target - state.com_position()), self.rows, out=v)
        return self.weight

    def __repr__(self) -> str:
        return f"ComTask({self.name!r}, rows={self.dim})"
