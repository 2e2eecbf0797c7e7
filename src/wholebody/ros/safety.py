"""What keeps the published commands safe: the command limiter and the input checks.

* :class:`CommandLimiter`: every command inside the velocity limits ``|u| <= v_max`` and the
  acceleration limits ``|u - u_prev| <= a_max dt`` (rad/s, m/s; ``u_prev`` the last command
  published). The stack enforces both already; the limiter is the last word, after the
  solver, so that no solver corner case (a box the stack had to cross, a non-finite
  solution) reaches the robot. A non-finite command is replaced by a stop.
* :func:`check_pose` and :func:`check_twist`: a target or feed-forward is refused, never
  passed on, when it is not finite, in a frame other than the controller's world, with a
  quaternion that is not a rotation, or out of the robot's reach.

A stop (:meth:`CommandLimiter.stop`) is the one command not bound by the acceleration
limits: it is sent when the controller cannot see the robot (a stale state, a bad
solution), and a ramp down would move the robot blind; the drives brake at their own
limits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wholebody.errors import DimensionError

__all__ = [
    "WORLD_FRAMES",
    "CommandLimiter",
    "Reach",
    "check_pose",
    "check_twist",
    "pose_matrix",
]

WORLD_FRAMES = ("world", "odom")
"""The frame ids a target may be given in: the controller's world, which for a mobile base
is the odometry frame its base pose is measured in."""


class CommandLimiter:
    """Clips commands to the velocity and acceleration limits (module docstring).

    Parameters
    ----------
    velocity, acceleration
        ``v_max`` (rad/s, m/s) and ``a_max`` (rad/s^2, m/s^2) per actuated velocity
        (``inf`` where there is none).
    dt
        The control period (s).
    """

    def __init__(self, velocity: np.ndarray, acceleration: np.ndarray, dt: float) -> None:
        self.velocity = np.asarray(velocity, dtype=float).copy()
        self.acceleration = np.asarray(acceleration, dtype=float).copy()
        if self.velocity.shape != self.acceleration.shape or self.velocity.ndim != 1:
            raise DimensionError(
                "velocity and acceleration limits must be two vectors of the same length"
            )
        if np.any(self.velocity <= 0) or np.any(self.acceleration <= 0):
            raise DimensionError("velocity and acceleration limits must be > 0")
        if not (math.isfinite(dt) and dt > 0):
            raise DimensionError(f"the control period must be > 0 s, got {dt!r}")
        self.dt = float(dt)
        self.last = np.zeros(self.velocity.size)
        """The last command published (rad/s, m/s)."""

    def limit(self, u: np.ndarray) -> tuple[np.ndarray, bool]:
        """``u`` clipped into ``[max(-v_max, u_prev - a_max dt), min(v_max, u_prev + a_max
        dt)]``, and whether anything was clipped; a non-finite ``u`` becomes a stop (then
        True). The result becomes ``u_prev``."""
        u = np.asarray(u, dtype=float)
        if u.shape != self.last.shape or not np.all(np.isfinite(u)):
            return self.stop(), True
        step = self.acceleration * self.dt
        lower = np.maximum(-self.velocity, self.last - step)
        upper = np.minimum(self.velocity, self.last + step)
        out = np.minimum(np.maximum(u, lower), upper)
        clipped = bool(np.any(out != u))
        self.last = out
        return out.copy(), clipped

    def stop(self) -> np.ndarray:
        """A zero command (module docstring: not bound by the acceleration limits)."""
        self.last = np.zeros(self.last.size)
        return self.last.copy()


@dataclass(frozen=True)
class Reach:
    """How far a frame can be from the robot: ``radius`` (m) from the root's origin (the
    base's for a mobile robot), plus ``travel`` (m) the base may drive in the plane."""

    radius: float
    travel: float = 0.0

    def distance_beyond(self, position: np.ndarray, root: np.ndarray) -> float:
        """How far (m) ``position`` is outside the reach around ``root`` (<= 0: inside)."""
        d = np.asarray(position, dtype=float) - np.asarray(root, dtype=float)
        horizontal = max(0.0, math.hypot(d[0], d[1]) - self.travel)
        return math.hypot(horizontal, d[2]) - self.radius


def pose_matrix(position: Sequence[float], quaternion: Sequence[float]) -> np.ndarray:
    """The 4x4 pose of a position (m) and a unit quaternion ``(x, y, z, w)``."""
    x, y, z, w = quaternion
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = position
    return T


def check_pose(
    frame_id: str,
    position: Sequence[float],
    quaternion: Sequence[float],
    reach: Reach,
    root: np.ndarray,
) -> tuple[np.ndarray | None, str]:
    """A target pose (4x4, world) from a ``PoseStamped``'s fields, or None and why it was
    refused: a frame id not in :data:`WORLD_FRAMES`, a non-finite number, a quaternion
    whose norm is off 1 by more than 1 % (one within is normalised), or a position beyond
    ``reach`` of ``root`` (the robot's root origin, world, m)."""
    values = [*position, *quaternion]
    if frame_id not in WORLD_FRAMES:
        return None, (f"frame_id {frame_id!r}: targets are taken in {' or '.join(WORLD_FRAMES)}")
    if not all(math.isfinite(v) for v in values):
        return None, (
            f"not finite: position {[float(v) for v in position]}, orientation "
            f"{[float(v) for v in quaternion]}"
        )
    norm = math.sqrt(sum(v * v for v in quaternion))
    if abs(norm - 1.0) > 0.01:
        return None, f"the orientation quaternion has norm {norm:.4f}, not 1"
    beyond = reach.distance_beyond(np.asarray(position, dtype=float), root)
    if beyond > 0:
        return None, (
            f"out of reach: {beyond:.3f} m beyond the {reach.radius:.3f} m the "
            f"frame can reach"
            + (f" after {reach.travel:g} m of base travel" if reach.travel else "")
        )
    return pose_matrix(position, [v / norm for v in quaternion]), ""


def check_twist(
    frame_id: str,
    linear: Sequence[float],
    angular: Sequence[float],
    max_linear: float,
    max_angular: float,
) -> tuple[np.ndarray | None, str]:
    """A feed-forward twist ``[v (m/s), w (rad/s)]`` (world axes) from a ``TwistStamped``'s
    fields, or None and why it was refused: a frame id not in :data:`WORLD_FRAMES`, a
    non-finite number, or a speed above ``max_linear`` (m/s) or ``max_angular`` (rad/s)."""
    if frame_id not in WORLD_FRAMES:
        return None, (
            f"frame_id {frame_id!r}: twists are taken in {' or '.join(WORLD_FRAMES)} axes"
        )
    twist = np.array([*linear, *angular], dtype=float)
    if not np.all(np.isfinite(twist)):
        return None, f"not finite: {twist.tolist()}"
    v, w = float(np.linalg.norm(twist[:3])), float(np.linalg.norm(twist[3:]))
    if v > max_linear or w > max_angular:
        return None, (
            f"too fast: {v:.3f} m/s, {w:.3f} rad/s (at most {max_linear:g} m/s, "
            f"{max_angular:g} rad/s)"
        )
    return twist, ""
