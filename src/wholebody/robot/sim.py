"""``robot.toml [sim]``: what a physics run adds to a robot's URDF (:mod:`wholebody.sim`).

Kept apart from the simulator so that reading a robot needs no MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from wholebody.errors import ModelError

if TYPE_CHECKING:
    from wholebody.robot.robot import Robot

__all__ = ["SimSettings", "effort_limits", "joint_kind", "wheel_dofs"]


@dataclass(frozen=True)
class SimSettings:
    """What the physics run adds to a robot's URDF (``robot.toml [sim]``).

    Attributes
    ----------
    timestep
        Physics step (s); the control period must be a whole number of them.
    servo_hz
        Bandwidth (Hz) of each joint's velocity servo: ``kp = w^2``, ``kv = 2 zeta w`` with
        ``w = 2 pi servo_hz``, through the robot's inertia ``M(q)``
        (:class:`wholebody.sim.MujocoPlant`).
    damping_ratio
        ``zeta`` of the servos.
    armature
        Rotor inertia reflected at each joint (kg m^2, kg for a prismatic joint).
    damping
        Viscous friction of each joint (N m s/rad, N s/m), not compensated by the servo.
    effort_scale
        Factor on every effort limit (1: the URDF's).
    gravity_compensation
        The servos add the model's gravity and Coriolis torques of the robot (not of a
        carried object, which the servo does not know).
    stall_time
        A joint held at its torque limit this long (s) stops the run, reported.
    friction
        Sliding friction coefficient of every contact (robot shapes, objects, floor).
    contact_time
        Time constant (s) of the contacts' softness (MuJoCo's ``solref``, critically
        damped): how fast a penetration is pushed out; at least two physics steps.
    base_force, base_torque
        Limits (N, N m) of a planar base without wheels (a directly actuated base), and
        of a wheeled base along a direction its wheels do not drive (a differential base's
        sideways force: the wheels' grip).
    """

    timestep: float = 0.001
    servo_hz: float = 25.0
    damping_ratio: float = 1.0
    armature: float = 0.01
    damping: float = 0.1
    effort_scale: float = 1.0
    gravity_compensation: bool = True
    stall_time: float = 0.25
    friction: float = 1.0
    contact_time: float = 0.005
    base_force: float = 1000.0
    base_torque: float = 300.0

    def __post_init__(self) -> None:
        for name in (
            "timestep",
            "servo_hz",
            "damping_ratio",
            "effort_scale",
            "stall_time",
            "friction",
            "contact_time",
            "base_force",
            "base_torque",
        ):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise ModelError(f"sim setting {name} must be a finite number > 0, got {value!r}")
        if self.contact_time < 2 * self.timestep:
            raise ModelError(
                f"sim setting contact_time ({self.contact_time} s) must be at "
                f"least two physics steps ({2 * self.timestep} s)"
            )
        for name in ("armature", "damping"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value >= 0):
                raise ModelError(f"sim setting {name} must be a number >= 0, got {value!r}")

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The setting names (``robot.toml [sim]``'s keys)."""
        return tuple(f.name for f in fields(cls))


def joint_kind(joint: pin.JointModel) -> str:
    """A Pinocchio joint's kind: ``"FreeFlyer"``, ``"Planar"``, ``"RZ"``, ..."""
    return joint.shortname().removeprefix("JointModel")


def wheel_dofs(robot: Robot) -> list[int]:
    """The velocity index of each wheel joint of the robot's base."""
    return [robot.model.joints[robot.model.getJointId(w)].idx_v for w in robot.base.wheel_joints]


def effort_limits(robot: Robot, settings: SimSettings) -> np.ndarray:
    """The limit of each Pinocchio velocity (N m, N): the URDF's effort times
    ``effort_scale``; a planar root's from its wheels through the base matrix (``tau = B^T
    W``, so ``|W_i| <= tau_max / max_j |B_ij|``) or, without wheels, ``base_force`` and
    ``base_torque``; a free flyer's infinite (it has no motor: nothing is applied there)."""
    raw = np.array(robot.model.effortLimit, dtype=float)
    limit = np.where(np.isfinite(raw) & (raw < 1e30), raw, np.nan) * settings.effort_scale
    root = robot.model.joints[1] if robot.model.njoints > 1 else None
    free = np.zeros(limit.size, dtype=bool)
    if root is not None and joint_kind(root) == "FreeFlyer":
        free[:6] = True
    if root is not None and joint_kind(root) == "Planar":
        base = robot.base
        wheels = wheel_dofs(robot)
        if wheels:
            gain = np.abs(base.matrix).max(axis=1)  # 0: a direction no wheel drives
            fallback = [settings.base_force, settings.base_force, settings.base_torque]
            limit[:3] = np.where(gain > 0, limit[wheels].min() / np.maximum(gain, 1e-300), fallback)
        else:
            limit[:3] = [settings.base_force, settings.base_force, settings.base_torque]
    bad = (~np.isfinite(limit) | (limit <= 0)) & ~free
    if bad.any():
        names = [
            robot.model.names[j]
            for j in range(1, robot.model.njoints)
            if bad[robot.model.joints[j].idx_v]
        ]
        raise ModelError(
            f"robot {robot.name!r}: joints without an effort limit in the URDF "
            f"({', '.join(names)}); a physics run needs one per joint"
        )
    limit[free] = np.inf
    return limit
