"""Mobile-base actuation maps: from base actuator speeds to the base twist.

A wheeled base is a planar root joint (x, y, yaw) whose velocity, in Pinocchio, is the twist
``(vx, vy, wz)`` expressed in the **base frame**. The base's actuators (wheel speeds, or the
twist itself for a directly actuated planar base) are the first entries of the actuated
velocity ``u``; a base model is the constant m x n matrix ``B`` with ``twist = B u_base``
(m = 3 for a planar root, 6 for a free-flyer root).

* ``mecanum``: wheels front-left, front-right, rear-left, rear-right, X roller pattern,
  radius r, half wheel base ``lx``, half track ``ly``::

      vx = r/4 ( w1 + w2 + w3 + w4)
      vy = r/4 (-w1 + w2 + w3 - w4)
      wz = r/4 (-w1 + w2 - w3 + w4) / (lx + ly)

  Its null space is the internal mode ``(1, 1, -1, -1)`` (front pair against rear pair),
  which moves nothing: a posture level or a regularisation must pin it.
* ``differential``: wheels left, right: ``vx = r (wl + wr) / 2``, ``wz = r (wr - wl) / track``
  and, with the axle at ``x = x_a`` of the base origin, ``vy = -x_a wz``.

Wheel speeds are positive when a wheel turns about the base's ``+y`` axis (which drives it
forward); :class:`~wholebody.robot.Robot` negates the column of a wheel whose URDF axis is
``-y`` and sets the axle offset from the URDF, so the matrices above are those of wheels whose
joint axes point to the left.
* ``planar``: three virtual actuators ``base_vx, base_vy, base_wz`` equal to the twist.
* ``swerve``: steered wheels (:mod:`wholebody.robot.swerve`), commanded as a real swerve base
  is, by its twist: the three virtual actuators of ``planar``; each module's steering and
  drive joints stay in the model but out of ``u`` (``held``: no velocity moves them), and
  :func:`~wholebody.robot.swerve.module_commands` turns a twist into their commands.
* ``floating``: a free-flyer root (Pinocchio's ``JointModelFreeFlyer``) with six virtual
  actuators ``base_vx, base_vy, base_vz, base_wx, base_wy, base_wz``, its velocity (linear,
  then angular, in the base frame, m/s and rad/s). Nothing drives them on a real robot: a
  controller solves for them like for any joint, and the contacts that carry the robot (the
  soles of a humanoid) must be held by tasks (6-D frame tasks at the top level), or the
  solution floats.
* ``fixed``: no root joint, no base actuator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wholebody.robot.config import BaseConfig

__all__ = ["BaseModel", "base_model"]

PLANAR_ACTUATORS = ("base_vx", "base_vy", "base_wz")
FLOATING_ACTUATORS = ("base_vx", "base_vy", "base_vz", "base_wx", "base_wy", "base_wz")
ANGULAR_ACTUATORS = frozenset({"base_wx", "base_wy", "base_wz"})
"""The virtual base actuators that are angular velocities (rad/s; the others m/s)."""


@dataclass(frozen=True)
class BaseModel:
    """The actuation map of a mobile base.

    Attributes
    ----------
    type
        ``"fixed"``, ``"mecanum"``, ``"differential"``, ``"planar"``, ``"swerve"`` or
        ``"floating"``.
    actuators
        Names of the base's entries of ``u`` (wheel joint names, or the virtual
        ``base_vx, base_vy, base_wz``; six for a floating base), in order.
    matrix
        ``B`` (m x len(actuators)): base twist in the base frame per unit actuator speed
        (rad/s for wheels): ``(vx [m/s], vy [m/s], wz [rad/s])`` of a planar root (m = 3),
        ``(v [m/s], w [rad/s])`` of a free flyer (m = 6).
    wheel_joints
        The actuators that are joints of the URDF (the wheels); empty otherwise.
    held
        Joints of the model that no entry of ``u`` moves (a swerve base's steering and drive
        joints): they stay where the configuration puts them.
    """

    type: str
    actuators: tuple[str, ...]
    matrix: np.ndarray
    wheel_joints: tuple[str, ...]
    held: tuple[str, ...] = ()

    @property
    def mobile(self) -> bool:
        """Whether the robot has a root joint (planar, or a free flyer)."""
        return self.type != "fixed"

    @property
    def floating(self) -> bool:
        """Whether the root joint is a free flyer (x, y, z, quaternion; six velocities)."""
        return self.type == "floating"

    @property
    def root_nv(self) -> int:
        """The root joint's velocities: 0 (fixed), 3 (planar) or 6 (free flyer)."""
        return self.matrix.shape[0] if self.mobile else 0

    def null_space(self) -> np.ndarray:
        """Orthonormal basis (n x k) of the actuator speeds that move nothing."""
        if self.matrix.shape[1] == 0:
            return np.zeros((0, 0))
        _, s, vt = np.linalg.svd(self.matrix)
        rank = int(np.sum(s > 1e-12 * max(1.0, s.max())))
        return vt[rank:].T.copy()


def base_model(config: BaseConfig) -> BaseModel:
    """The actuation map described by a ``[base]`` table."""
    if config.type == "fixed":
        return BaseModel("fixed", (), np.zeros((3, 0)), ())
    if config.type == "planar":
        return BaseModel("planar", PLANAR_ACTUATORS, np.eye(3), ())
    if config.type == "floating":
        return BaseModel("floating", FLOATING_ACTUATORS, np.eye(6), ())
    if config.type == "swerve":
        held = tuple(j for m in config.modules for j in (m.steering, m.drive))
        return BaseModel("swerve", PLANAR_ACTUATORS, np.eye(3), (), held)
    r = config.wheel_radius
    if config.type == "mecanum":
        lx, ly = config.wheel_base / 2, config.track / 2
        B = (r / 4) * np.array(
            [
                [1.0, 1.0, 1.0, 1.0],
                [-1.0, 1.0, 1.0, -1.0],
                [-1.0 / (lx + ly), 1.0 / (lx + ly), -1.0 / (lx + ly), 1.0 / (lx + ly)],
            ]
        )
        return BaseModel("mecanum", config.wheels, B, config.wheels)
    B = r * np.array([[0.5, 0.5], [0.0, 0.0], [-1.0 / config.track, 1.0 / config.track]])
    return BaseModel("differential", config.wheels, B, config.wheels)
