"""Mobile-base actuation maps: from base actuator speeds to the base twist.

A mobile base is a planar root joint (x, y, yaw) whose velocity, in Pinocchio, is the twist
``(vx, vy, wz)`` expressed in the **base frame**. The base's actuators (wheel speeds, or the
twist itself for a directly actuated planar base) are the first entries of the actuated
velocity ``u``; a base model is the constant 3 x n matrix ``B`` with ``twist = B u_base``.

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
* ``fixed``: no root joint, no base actuator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wholebody.robot.config import BaseConfig

__all__ = ["BaseModel", "base_model"]

PLANAR_ACTUATORS = ("base_vx", "base_vy", "base_wz")


@dataclass(frozen=True)
class BaseModel:
    """The actuation map of a mobile base.

    Attributes
    ----------
    type
        ``"fixed"``, ``"mecanum"``, ``"differential"`` or ``"planar"``.
    actuators
        Names of the base's entries of ``u`` (wheel joint names, or the virtual
        ``base_vx, base_vy, base_wz``), in order.
    matrix
        ``B`` (3 x len(actuators)): base twist ``(vx [m/s], vy [m/s], wz [rad/s])`` in the
        base frame per unit actuator speed (rad/s for wheels).
    wheel_joints
        The actuators that are joints of the URDF (the wheels); empty otherwise.
    """

    type: str
    actuators: tuple[str, ...]
    matrix: np.ndarray
    wheel_joints: tuple[str, ...]

    @property
    def mobile(self) -> bool:
        """Whether the robot has a planar root joint."""
        return self.type != "fixed"

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
