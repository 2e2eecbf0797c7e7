"""Hard limits as boxes on the actuated velocity for one control step of ``dt`` seconds."""

from __future__ import annotations

import numpy as np

from wholebody.errors import DimensionError
from wholebody.kernels.rows import position_box
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Bounds, Constraint

__all__ = ["JointPositionLimits", "VelocityLimits"]


class JointPositionLimits(Constraint):
    """Joint position limits as velocity bounds for the next step.

    ``gain (q_min + margin - q) / dt <= u <= gain (q_max - margin - q) / dt`` for every joint
    with finite limits (wheels and planar-base actuators are unbounded here). With
    ``gain <= 1`` a step never crosses a limit (the joint coordinates integrate exactly).
    A joint outside its limits gets a bound that pushes it back inside (the stack resolves a
    conflict with the velocity limit by moving back at full speed).

    Parameters
    ----------
    gain
        Fraction of the remaining distance that one step may cover (0, 1].
    margin
        Distance (rad, m) kept from each limit.
    """

    def __init__(self, robot: Robot, *, gain: float = 0.5, margin: float = 0.0,
                 name: str = "joint_position_limits") -> None:  # fmt: skip
        if not 0 < gain <= 1:
            raise DimensionError(f"{name}: gain must be in (0, 1], got {gain}")
        lower, upper = robot.position_limits
        if not margin >= 0 or np.any(upper - lower <= 2 * margin):
            raise DimensionError(f"{name}: margin {margin} must be >= 0 and smaller than half "
                                 "of every joint range")  # fmt: skip
        self.robot, self.name = robot, name
        self._gain, self._margin = float(gain), float(margin)
        self._lower = lower + margin
        self._upper = upper - margin
        for a in (self._lower, self._upper):
            a.setflags(write=False)

    @property
    def gain(self) -> float:
        """Fraction of the remaining distance one step may cover, fixed at construction."""
        return self._gain

    @property
    def margin(self) -> float:
        """Distance (rad, m) kept from each limit, fixed at construction."""
        return self._margin

    @property
    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """``(q_min + margin, q_max - margin)`` per actuated velocity (read-only)."""
        return self._lower, self._upper

    def bounds(self, state: RobotState, dt: float) -> Bounds:
        lower, upper = np.empty(self.robot.nu), np.empty(self.robot.nu)
        position_box(state.joint_positions(), self._lower, self._upper, self.gain, dt, lower,
                     upper)  # fmt: skip
        return Bounds(lower, upper)


class VelocityLimits(Constraint):
    """``|u| <= scale * v_max`` (URDF velocity limits; base limits from robot.toml)."""

    def __init__(self, robot: Robot, *, scale: float = 1.0,
                 name: str = "velocity_limits") -> None:  # fmt: skip
        if not scale > 0:
            raise DimensionError(f"{name}: scale must be > 0, got {scale}")
        self.name = name
        self._upper = scale * robot.velocity_limits
        self._upper.setflags(write=False)
        self._bounds = Bounds(-self._upper, self._upper)

    @property
    def upper(self) -> np.ndarray:
        """``scale * v_max`` per actuated velocity (rad/s, m/s; read-only)."""
        return self._upper

    def bounds(self, state: RobotState, dt: float) -> Bounds:
        return self._bounds
