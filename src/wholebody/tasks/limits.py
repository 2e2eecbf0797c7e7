"""Hard limits as boxes on the actuated velocity for one control step of ``dt`` seconds."""

from __future__ import annotations

import numpy as np

from wholebody.errors import DimensionError
from wholebody.kernels.layout import KIND_ACCELERATION, KIND_POSITION, KIND_VELOCITY
from wholebody.kernels.limits import acceleration_box, position_box, velocity_box
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import Bounds, Limit, Packed, Packer

__all__ = ["AccelerationLimits", "JointPositionLimits", "VelocityLimits"]


class JointPositionLimits(Limit):
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

    def __init__(
        self,
        robot: Robot,
        *,
        gain: float = 0.5,
        margin: float = 0.0,
        name: str = "joint_position_limits",
    ) -> None:
        if not 0 < gain <= 1:
            raise DimensionError(f"{name}: gain must be in (0, 1], got {gain}")
        lower, upper = robot.position_limits
        if not margin >= 0 or np.any(upper - lower <= 2 * margin):
            raise DimensionError(
                f"{name}: margin {margin} must be >= 0 and smaller than half of every joint range"
            )
        self.robot, self.name = robot, name
        self._margin = float(margin)
        # the kernel's block: lower + margin, upper - margin, gain
        self._params = np.concatenate([lower + margin, upper - margin, [float(gain)]])

    @property
    def gain(self) -> float:
        """Fraction of the remaining distance one step may cover, fixed at construction."""
        return float(self._params[-1])

    @property
    def margin(self) -> float:
        """Distance (rad, m) kept from each limit, fixed at construction."""
        return self._margin

    @property
    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """``(q_min + margin, q_max - margin)`` per actuated velocity (copies)."""
        nu = self.robot.nu
        return self._params[:nu].copy(), self._params[nu : 2 * nu].copy()

    def bounds(self, state: RobotState, dt: float) -> Bounds:
        lower, upper = np.empty(self.robot.nu), np.empty(self.robot.nu)
        position_box(state.joint_positions(), self._params, dt, lower, upper)
        return Bounds(lower, upper)

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(JointPositionLimits, "bounds"):
            return None
        return Packed(KIND_POSITION, self._params)


class VelocityLimits(Limit):
    """``|u| <= scale * v_max`` (URDF velocity limits; base limits from robot.toml)."""

    def __init__(self, robot: Robot, *, scale: float = 1.0, name: str = "velocity_limits") -> None:
        if not scale > 0:
            raise DimensionError(f"{name}: scale must be > 0, got {scale}")
        self.name = name
        self._params = scale * robot.velocity_limits  # the kernel's block: the upper bound

    @property
    def upper(self) -> np.ndarray:
        """``scale * v_max`` per actuated velocity (rad/s, m/s; a copy)."""
        return self._params.copy()

    def bounds(self, state: RobotState, dt: float) -> Bounds:
        lower, upper = np.empty(self._params.size), np.empty(self._params.size)
        velocity_box(self._params, lower, upper)
        return Bounds(lower, upper)

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(VelocityLimits, "bounds"):
            return None
        return Packed(KIND_VELOCITY, self._params)


class AccelerationLimits(Limit):
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

    def __init__(
        self, robot: Robot, *, scale: float = 1.0, name: str = "acceleration_limits"
    ) -> None:
        if not (isinstance(scale, (int, float)) and 0 < scale < np.inf):
            raise DimensionError(f"{name}: scale must be a finite number > 0, got {scale!r}")
        self.name = name
        lower, upper = robot.position_limits
        self._limited = (np.isfinite(lower) & np.isfinite(upper)).astype(np.int64)
        # the kernel's block: a_max, the position range, the last step's velocity
        nu = robot.nu
        self._params = np.zeros(4 * nu)
        self._params[:nu] = scale * robot.acceleration_limits
        self._params[nu : 3 * nu] = np.concatenate([lower, upper])

    @property
    def upper(self) -> np.ndarray:
        """``scale * a_max`` per actuated velocity (rad/s^2, m/s^2; a copy)."""
        return self._params[: self._limited.size].copy()

    @property
    def previous(self) -> np.ndarray:
        """The velocity of the last step (a copy)."""
        return self._params[3 * self._limited.size :].copy()

    def bounds(self, state: RobotState, dt: float) -> Bounds:
        lower, upper = np.empty(self._limited.size), np.empty(self._limited.size)
        acceleration_box(state.joint_positions(), self._params, self._limited, dt, lower, upper)
        return Bounds(lower, upper)

    def advance(self, u: np.ndarray, dt: float) -> None:
        self._params[3 * self._limited.size :] = u

    def reset(self) -> None:
        self._params[3 * self._limited.size :] = 0.0

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(AccelerationLimits, "bounds", "advance", "reset"):
            return None
        return Packed(KIND_ACCELERATION, self._params, self._limited)
