"""The whole-body centre of mass held at a point: what keeps a floating-base robot balanced.

With ``c`` the centre of mass of every link (:meth:`RobotState.com_position
<wholebody.robot.RobotState.com_position>`, world, m) and ``J_c`` its 3 x nu Jacobian, the rows
of the chosen axes are::

    J_c[axes] u = kp (c_ref - c)[axes]        (m/s)

A standing humanoid stays up under physics when its centre of mass stays over its support
polygon (the soles): hold it in ``"xy"`` at the level below the soles' frame tasks. Compiled:
the kernel :func:`~wholebody.kernels.rows.com_rows` sums the bodies' masses
(:func:`wholebody.robot.com.mass_table`) over the joints' subtrees as Pinocchio's
``jacobianCenterOfMass`` does, so a stack with it runs in one kernel call like the pose and
posture tasks; its centre of mass and Jacobian agree with Pinocchio's
(:meth:`RobotState.com_position <wholebody.robot.RobotState.com_position>`) to rounding.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from wholebody.errors import DimensionError
from wholebody.kernels.layout import KIND_COM
from wholebody.kernels.rows import (
    COM_BODIES,
    COM_BODY,
    COM_FIXED,
    COM_KP,
    COM_MASS,
    COM_TARGET,
    COM_VELOCITY,
    com_rows,
)
from wholebody.robot import Robot, RobotState
from wholebody.robot.com import MassTable, mass_table
from wholebody.tasks.base import Packed, Packer, Task, TaskRows

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
        super().__init__(name, weight, lm_damping=lm_damping)
        self.robot = robot
        self.rows = np.array([_AXES[a] for a in axes], dtype=int)
        self.rows.setflags(write=False)
        table = mass_table(robot.model)
        self._params = _block(table)
        self._ints = _tables(robot.model, table, self.rows)
        self.kp = kp
        self.set_target(robot.update(robot.home()).com_position() if target is None else target)

    @property
    def dim(self) -> int:
        return self.rows.size

    @property
    def kp(self) -> float:
        """Gain (1/s)."""
        return float(self._params[COM_KP])

    @kp.setter
    def kp(self, value: float) -> None:
        if not (np.isfinite(value) and value >= 0):
            raise DimensionError(f"{self.name}: kp must be a finite number >= 0, got {value!r}")
        self._params[COM_KP] = value

    @property
    def target(self) -> np.ndarray:
        """The point held (m, world; a copy)."""
        return self._params[COM_TARGET : COM_TARGET + 3].copy()

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
        self._params[COM_TARGET : COM_TARGET + 3] = t
        self._params[COM_VELOCITY : COM_VELOCITY + 3] = v

    def error(self, state: RobotState) -> np.ndarray:
        return (self.target - state.com_position())[self.rows]

    def compute(self, state: RobotState) -> TaskRows:
        J = np.empty((self.dim, state.robot.nu))
        v = np.empty(self.dim)
        ComTask.write_rows(self, state, J, v)
        return TaskRows(J, v, self.weights)

    def write_rows(self, state: RobotState, J_out: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        if type(self).compute is not ComTask.compute:  # (a subclass's own rows)
            return super().write_rows(state, J_out, v)
        state.require_valid()
        J, oMf = state.robot.kinematics.views()
        kin = state.robot.kinematics
        com_rows(J, oMf, kin.act_k, kin.act_j, kin.act_a, self._params, self._ints, J_out, v)
        return self.weight

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(ComTask, "compute", "write_rows", "error"):
            return None
        return Packed(KIND_COM, self._params, self._ints)

    def __repr__(self) -> str:
        return f"ComTask({self.name!r}, rows={self.dim})"


def _block(table: MassTable) -> np.ndarray:
    """The kernel's float block (``COM_*``) of the masses; target, velocity and gain zero."""
    n = len(table.frames)
    par = np.zeros(COM_BODIES + COM_BODY * n)
    par[COM_MASS] = table.total
    par[COM_FIXED : COM_FIXED + 3] = table.fixed_mass * table.fixed_centre
    bodies = par[COM_BODIES:].reshape(n, COM_BODY)
    bodies[:, 0], bodies[:, 1:] = table.masses, table.centres
    return par


def _tables(model: pin.Model, table: MassTable, rows: np.ndarray) -> np.ndarray:
    """The kernel's ints (``COM_*``): the rows, each body's frame and joint, each joint's
    parent and velocity columns (read-only)."""
    ints = [rows.size, *rows, *[0] * (3 - rows.size), len(table.frames), model.njoints]
    for f in table.frames:
        ints += [f.index, f.joint]
    for j in range(model.njoints):
        ints += [model.parents[j], model.joints[j].idx_v, model.joints[j].nv]
    out = np.array(ints, dtype=np.int64)
    out.setflags(write=False)
    return out
