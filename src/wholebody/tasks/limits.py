"""Hard limits as boxes on the actuated velocity for one control step of ``dt`` seconds."""

from __future__ import annotations

import numpy as np

from wholebody.errors import DimensionError
from wholebody.kernels.rows import position_box
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Bounds, Constraint

__all__ = ["AccelerationLimits", "JointPositionLimits", "VelocityLimits"]


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


class AccelerationLimits(Constraint):
    """``|u - u_prev| <= scale * a_max * dt``: no step changes a velocity by more than the
    robot's acceleration limits allow (``a_max``: :attr:`Robot.acceleration_limits`, rad/s^2
    and m/s^2, from ``[acceleration]`` of robot.toml), so that the command never jumps.

    ``u_prev`` is the velocity of the last step, given by :meth:`advance` (the controller
    and :meth:`Stack.advance` call it); after :meth:`reset` the robot is at rest (0).

    A joint with position limits also gets the braking bound: towards a limit at distance
    ``d`` it may move at most ``v_b(d) = a dt (sqrt(1 + 2 d / (a dt^2)) - 1)``, the speed from
    which braking at ``a`` per step stops it at the limit (``v dt + v^2 / (2 a) = d``). The
    bound is invariant: after a step at ``v_b(d)``, ``v_b`` of the new distance is at least
    ``v_b(d) - a dt``, so braking never needs more than ``a``.

    Where this box and another one still cross (a velocity limit lowered below ``u_prev``,
    a start too fast for the braking bound, the position limits' own ``gain``), the stack
    keeps the bound that moves the joint back: position and velocity limits win over
    smoothness, and that step exceeds ``a_max`` on that joint.
    """

    def __init__(self, robot: Robot, *, scale: float = 1.0,
                 name: str = "acceleration_limits") -> None:  # fmt: skip
        if not (isinstance(scale, (int, float)) and 0 < scale < np.inf):
            raise DimensionError(f"{name}: scale must be a finite number > 0, got {scale!r}")
        self.name = name
        self._amax = scale * robot.acceleration_limits
        self._amax.setflags(write=False)
        self._previous = np.zeros(robot.nu)
        lower, upper = robot.position_limits
        self._limited = np.flatnonzero(np.isfinite(lower) & np.isfinite(upper))
        self._range = lower[self._limited], upper[self._limited]

    @property
    def upper(self) -> np.ndarray:
        """``scale * a_max`` per actuated velocity (rad/s^2, m/s^2; read-only)."""
        return self._amax

    @property
    def previous(self) -> np.ndarray:
        """The velocity of the last step (a copy)."""
        return self._previous.copy()

    def bounds(self, state: RobotState, dt: float) -> Bounds:
        step = self._amax * dt
        lower, upper = self._previous - step, self._previous + step
        k = self._limited
        if k.size:
            q = state.joint_positions()[k]
            a, lo, hi = self._amax[k], *self._range
            to_hi, to_lo = np.maximum(hi - q, 0.0), np.maximum(q - lo, 0.0)
            upper[k] = np.minimum(upper[k], _braking(to_hi, a, dt))
            lower[k] = np.maximum(lower[k], -_braking(to_lo, a, dt))
        return Bounds(lower, upper)

    def advance(self, u: np.ndarray, dt: float) -> None:
        self._previous[:] = u

    def reset(self) -> None:
        self._previous[:] = 0.0


def _braking(d: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
    """The speed from which braking at ``a`` per step stops within ``d``:
    ``a dt (sqrt(1 + 2 d / (a dt^2)) - 1)`` (rad/s, m/s)."""
    adt = a * dt
    return adt * (np.sqrt(1.0 + 2.0 * d / (adt * dt)) - 1.0)
