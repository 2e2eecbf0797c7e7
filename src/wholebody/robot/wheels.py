"""A wheeled base read against its URDF: wheel axes, the differential axle, placements and
radii.

``robot.toml``'s ``[base]`` gives the base model's parameters (:mod:`wholebody.robot.base`);
the URDF has the wheels' joints. :func:`wheel_geometry` takes from the URDF what the matrix
``B`` (twist = ``B u_wheels``) depends on besides those parameters, and
:func:`check_base_geometry` checks the parameters against the URDF, so that a typo in the
wheel base or the wheel order is an error on loading, not a base that drives askew.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import pinocchio as pin

from wholebody.robot.base import BaseModel
from wholebody.robot.config import RobotConfig
from wholebody.robot.urdf import UrdfInfo

__all__ = ["WHEEL_PLACEMENT_TOLERANCE", "check_base_geometry", "wheel_geometry"]

WHEEL_PLACEMENT_TOLERANCE = 1e-3  # m, between robot.toml's base geometry and the URDF


def wheel_geometry(model: pin.Model, base: BaseModel, joint_ids: Mapping[str, int],
                   config: RobotConfig) -> BaseModel:  # fmt: skip
    """The base model with the URDF's wheel axes and axle: a wheel turning positively
    about ``+y`` of the base drives it forward, so a wheel whose joint axis is ``-y``
    gets its column of ``B`` negated; a differential axle at ``x = x_a`` of the base
    origin gives the origin the lateral speed ``vy = -x_a wz`` (the axle midpoint, not
    the origin, cannot slide sideways)."""
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    B = base.matrix.copy()
    xs = []
    for k, w in enumerate(base.wheel_joints):
        j = joint_ids[w]
        if model.parents[j] != 1:
            raise config.error(
                "base.wheels",
                f"wheel {w!r} must be attached to the base link (the root link of the URDF), "
                f"not below joint {model.names[model.parents[j]]!r}",
            )
        local = pin.getJointJacobian(model, data, j, pin.LOCAL)[3:, model.joints[j].idx_v]
        axis = model.jointPlacements[j].rotation @ local  # in the base (root) frame
        if abs(axis[1]) < 1.0 - 1e-6:
            raise config.error(
                "base.wheels",
                f"wheel {w!r} turns about ({axis[0]:.3g}, {axis[1]:.3g}, {axis[2]:.3g}) in "
                "the base frame: a wheel's joint axis must be the base's lateral axis, "
                "+y or -y (x forward, z up)",
            )
        B[:, k] *= math.copysign(1.0, axis[1])
        xs.append(float(model.jointPlacements[j].translation[0]))
    if base.type == "differential":
        if abs(xs[0] - xs[1]) > WHEEL_PLACEMENT_TOLERANCE:
            raise config.error(
                "base.wheels",
                f"the wheels of a differential base share one axle: {base.wheel_joints[0]!r} "
                f"is at x={xs[0]:.4f} m, {base.wheel_joints[1]!r} at x={xs[1]:.4f} m",
            )
        B[1] = -0.5 * (xs[0] + xs[1]) * B[2]
    B.setflags(write=False)
    return replace(base, matrix=B)


def check_base_geometry(model: pin.Model, base: BaseModel, joint_ids: Mapping[str, int],
                        config: RobotConfig, urdf: UrdfInfo) -> None:  # fmt: skip
    """Check the base parameters of robot.toml against the URDF's wheel placements and,
    where the wheels' geometry is a cylinder or sphere, their radius (within 5 %)."""
    cfg = config.base
    if not base.wheel_joints:
        return
    for w in base.wheel_joints:
        r = urdf.radii.get(urdf.children.get(w, ""))
        if r is not None and abs(r - cfg.wheel_radius) > 0.05 * r:
            raise config.error(
                "base.wheel_radius", f"{cfg.wheel_radius:g} m, but the URDF's wheel "
                f"{w!r} has a radius of {r:g} m (its geometry)",
            )  # fmt: skip
    placements = []
    for w in base.wheel_joints:  # (attached to the base: see wheel_geometry)
        placements.append(model.jointPlacements[joint_ids[w]].translation[:2])
    xy = np.array(placements)
    if base.type == "mecanum":
        expected = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]]) * [
            cfg.wheel_base / 2,
            cfg.track / 2,
        ]
        what = "front-left, front-right, rear-left, rear-right at (+-wheel_base/2, +-track/2)"
        keys = "wheel_base/track/wheel order"
    else:
        expected = np.array([[np.nan, 1], [np.nan, -1]]) * [1.0, cfg.track / 2]
        expected[:, 0] = xy[:, 0]
        what = "left, right at y = +-track/2"
        keys = "track/wheel order"
    err = np.abs(xy - expected)
    if np.any(err > WHEEL_PLACEMENT_TOLERANCE):
        bad = int(np.argmax(err.max(axis=1)))
        raise config.error(
            "base",
            f"{keys} do not match the URDF: wheel "
            f"{base.wheel_joints[bad]!r} is at x={xy[bad, 0]:.4f}, y={xy[bad, 1]:.4f} m but "
            f"the [base] table puts it at x={expected[bad, 0]:.4f}, y={expected[bad, 1]:.4f}"
            f" m (expected wheels {what})",
        )
