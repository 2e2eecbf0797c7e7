"""Swerve (steered-wheel) bases: each module a wheel on a vertical steering joint.

A swerve base is driven, on a real robot, by a body twist ``(vx, vy, wz)`` (base frame, m/s
and rad/s) that a module controller turns into a steering angle and a wheel speed per module:
wholebody controls it as a ``planar`` base (three virtual actuators equal to the twist,
:mod:`wholebody.robot.base`) and :func:`module_commands` is that module controller. The
steering and drive joints stay in the model, out of ``u``.

Module ``i``, its steering axis at ``(x_i, y_i)`` of the base frame and its wheel of radius
``r_i`` on that axis (no caster offset), moves at::

    v_i = (vx - wz y_i, vy + wz x_i)

so its heading is ``atan2(v_i)`` and its wheel speed ``|v_i| / r_i``. The steering angle that
gives a heading ``psi`` is ``theta = s (psi - phi_0)``, with ``s = +-1`` the steering axis's
sign along the base's z and ``phi_0`` the heading at ``theta = 0`` (the drive joint's axis
``a`` gives it: a wheel spinning at ``w`` about ``a`` rolls its centre at ``w r (a x z)``).
Of the two angles ``theta`` and ``theta + pi`` (wheel speed negated) the one nearer to the
module's present angle is taken, each wrapped into the steering joint's limits: a module
never turns more than 90 degrees for a reversal of the twist. :func:`module_twist` is the
inverse (odometry): the twist that fits the modules' states best, by least squares.

The geometry is read from the URDF at the model's neutral configuration (the locked joints
at their ``[locked]`` positions): the steering axis must be the base's vertical there, the
wheel axis horizontal and its centre on the steering axis.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wholebody.errors import DimensionError
from wholebody.robot.base import BaseModel
from wholebody.robot.config import RobotConfig
from wholebody.robot.urdf import UrdfInfo
from wholebody.robot.wheels import WHEEL_PLACEMENT_TOLERANCE

__all__ = ["SwerveModule", "module_commands", "module_twist", "swerve_modules"]

_AXIS_TOLERANCE = 1e-6  # of a unit axis's components: vertical, horizontal


@dataclass(frozen=True)
class SwerveModule:
    """One steered wheel, in the base frame.

    Attributes
    ----------
    steering, drive
        The steering and drive joints' names.
    x, y
        Where the steering axis meets the base's xy-plane (m).
    radius
        Wheel radius (m).
    sign
        ``+1`` if the steering joint turns about the base's ``+z``, ``-1`` about ``-z``.
    heading
        ``phi_0``: the direction the wheel rolls at steering angle 0 with a positive drive
        speed (rad, from the base's x towards its y).
    lower, upper
        The steering joint's limits (rad; infinite for a continuous joint).
    """

    steering: str
    drive: str
    x: float
    y: float
    radius: float
    sign: float
    heading: float
    lower: float
    upper: float


def swerve_modules(
    model: pin.Model,
    base: BaseModel,
    joint_ids: Mapping[str, int],
    config: RobotConfig,
    urdf: UrdfInfo,
) -> tuple[SwerveModule, ...]:
    """The modules of a ``swerve`` base read from the model (module docstring); ``()`` for
    another base. A ``robot.toml`` error for a module whose axes are not those of a steered
    wheel or whose radius is not the URDF's."""
    if base.type != "swerve":
        return ()
    data = model.createData()
    q = pin.neutral(model)
    pin.computeJointJacobians(model, data, q)
    root = data.oMi[1]
    out = []
    for k, m in enumerate(config.base.modules):
        where = f"base.modules[{k}]"
        js, jd = joint_ids[m.steering], joint_ids[m.drive]
        if js not in model.supports[jd]:
            raise config.error(
                where,
                f"the drive joint {m.drive!r} must be below the steering "
                f"joint {m.steering!r} in the URDF",
            )
        s_axis, s_point = _axis(model, data, root, js)
        d_axis, d_point = _axis(model, data, root, jd)
        if abs(abs(s_axis[2]) - 1.0) > _AXIS_TOLERANCE:
            raise config.error(
                where,
                f"the steering joint {m.steering!r} turns about "
                f"{np.round(s_axis, 4).tolist()} in the base frame: a steering "
                "axis must be vertical (+z or -z)",
            )
        if abs(d_axis[2]) > _AXIS_TOLERANCE:
            raise config.error(
                where,
                f"the drive joint {m.drive!r} turns about "
                f"{np.round(d_axis, 4).tolist()}: a wheel's axis must be "
                "horizontal",
            )
        offset = float(np.linalg.norm(d_point[:2] - s_point[:2]))
        if offset > WHEEL_PLACEMENT_TOLERANCE:
            raise config.error(
                where,
                f"the wheel of {m.drive!r} is {offset:.4f} m off its "
                "steering axis: wholebody's swerve modules have the wheel "
                "centred under the steering axis (no caster offset)",
            )
        _check_radius(config, urdf, where, m.drive, m.wheel_radius)
        roll = np.cross(d_axis, [0.0, 0.0, 1.0])  # a x z: the rolling direction at angle 0
        iq = model.joints[js].idx_q
        lower, upper = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
        if model.joints[js].nq == 2:  # a continuous steering joint
            lower, upper = -math.inf, math.inf
        out.append(
            SwerveModule(
                m.steering,
                m.drive,
                float(s_point[0]),
                float(s_point[1]),
                m.wheel_radius,
                math.copysign(1.0, s_axis[2]),
                math.atan2(roll[1], roll[0]),
                float(lower),
                float(upper),
            )
        )
    return tuple(out)


def _axis(
    model: pin.Model, data: pin.Data, root: pin.SE3, joint: int
) -> tuple[np.ndarray, np.ndarray]:
    """A one-velocity revolute joint's unit axis and origin in the base (root joint) frame."""
    J = pin.getJointJacobian(model, data, joint, pin.WORLD)[3:, model.joints[joint].idx_v]
    axis = root.rotation.T @ (J / np.linalg.norm(J))
    return axis, root.actInv(data.oMi[joint].translation)


def _check_radius(
    config: RobotConfig, urdf: UrdfInfo, where: str, drive: str, radius: float
) -> None:
    """The module's radius equals the URDF's wheel (a cylinder or sphere) to 1 mm."""
    r = urdf.radii.get(urdf.children.get(drive, ""))
    if r is not None and abs(r - radius) > WHEEL_PLACEMENT_TOLERANCE:
        raise config.error(
            f"{where}.wheel_radius",
            f"{radius:g} m, but the URDF's wheel of "
            f"{drive!r} has a radius of {r:g} m (its geometry)",
        )


def module_commands(
    modules: Sequence[SwerveModule], twist: Sequence[float], steering: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Each module's steering angle (rad) and wheel speed (rad/s) for the base twist
    ``(vx m/s, vy m/s, wz rad/s)`` (base frame), from the present steering angles
    ``steering`` (rad; one per module): the angle nearer to the present one of the two that
    give the module's heading, inside the joint's limits (module docstring). A module at
    rest (speed below 1e-12 m/s) keeps its angle. A :class:`DimensionError` for a heading
    that no angle inside a steering joint's limits gives."""
    vx, vy, wz = (float(c) for c in twist)
    if len(steering) != len(modules):
        raise DimensionError(
            f"module_commands: {len(steering)} steering angles for {len(modules)} modules"
        )
    angles, speeds = np.empty(len(modules)), np.empty(len(modules))
    for i, (m, now) in enumerate(zip(modules, steering, strict=True)):
        mx, my = vx - wz * m.y, vy + wz * m.x
        speed = math.hypot(mx, my)
        if speed < 1e-12:
            angles[i], speeds[i] = now, 0.0
            continue
        theta = m.sign * (math.atan2(my, mx) - m.heading)
        angles[i], flip = _nearest(theta, float(now), m)
        speeds[i] = flip * speed / m.radius
    return angles, speeds


def _nearest(theta: float, now: float, m: SwerveModule) -> tuple[float, float]:
    """Of ``theta + k pi`` (k integer; the wheel speed's sign ``(-1)^k``) inside the
    module's steering limits, the one nearest to ``now``; with that sign."""
    k0 = round((now - theta) / math.pi)
    best: tuple[float, float] | None = None
    for k in range(k0 - 2, k0 + 3):
        angle = theta + k * math.pi
        if m.lower - 1e-12 <= angle <= m.upper + 1e-12 and (
            best is None or abs(angle - now) < abs(best[0] - now)
        ):
            best = (angle, -1.0 if k % 2 else 1.0)
    if best is None:
        raise DimensionError(
            f"swerve module {m.steering!r}: no steering angle inside its "
            f"limits [{m.lower:g}, {m.upper:g}] rad gives the heading "
            f"{theta:g} rad (or its reverse) near {now:g} rad"
        )
    return best


def module_twist(
    modules: Sequence[SwerveModule], steering: Sequence[float], speeds: Sequence[float]
) -> np.ndarray:
    """The base twist ``(vx, vy, wz)`` (base frame) that the modules at the steering angles
    ``steering`` (rad) and wheel speeds ``speeds`` (rad/s) give, by least squares over the
    modules' velocities ``v_i = w_i r_i (cos, sin)(phi_0 + s theta_i)`` (exact when they
    agree, as :func:`module_commands` makes them)."""
    rows, v = [], []
    for m, theta, w in zip(modules, steering, speeds, strict=True):
        phi = m.heading + m.sign * float(theta)
        rows += [[1.0, 0.0, -m.y], [0.0, 1.0, m.x]]
        v += [w * m.radius * math.cos(phi), w * m.radius * math.sin(phi)]
    return np.linalg.lstsq(np.array(rows), np.array(v), rcond=None)[0]
