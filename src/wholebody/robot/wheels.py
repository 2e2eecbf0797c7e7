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
from pathlib import Path

import numpy as np
import pinocchio as pin

from wholebody.robot.base import BaseModel
from wholebody.robot.config import RobotConfig
from wholebody.robot.urdf import PACKAGE, MeshRef, UrdfInfo, resolve_package

__all__ = [
    "WHEEL_PLACEMENT_TOLERANCE",
    "WHEEL_RADIUS_TOLERANCE",
    "check_base_geometry",
    "check_wheel_radius",
    "wheel_geometry",
]

WHEEL_PLACEMENT_TOLERANCE = 1e-3  # m, between robot.toml's base geometry and the URDF
WHEEL_RADIUS_TOLERANCE = 0.01
"""Relative difference allowed between ``[base] wheel_radius`` and a wheel's geometry. The
base's speed and odometry are off by as much: 1 % is 1 cm per metre driven, about what a
hard (polyurethane, rubber-coated) robot wheel's rolling radius differs from its nominal one
under load; a typo or a wrong wheel (5 mm on an 8 cm wheel is 6 %) is well beyond it."""


def wheel_geometry(
    model: pin.Model, base: BaseModel, joint_ids: Mapping[str, int], config: RobotConfig
) -> BaseModel:
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


def check_base_geometry(
    model: pin.Model,
    base: BaseModel,
    joint_ids: Mapping[str, int],
    config: RobotConfig,
    urdf: UrdfInfo,
) -> None:
    """Check the base parameters of robot.toml against the URDF's wheel placements and the
    wheels' radius (:func:`check_wheel_radius`)."""
    cfg = config.base
    if not base.wheel_joints:
        return
    check_wheel_radius(model, base, joint_ids, config, urdf)
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


def check_wheel_radius(
    model: pin.Model,
    base: BaseModel,
    joint_ids: Mapping[str, int],
    config: RobotConfig,
    urdf: UrdfInfo,
) -> None:
    """``[base] wheel_radius`` against each wheel's geometry in the URDF, to
    :data:`WHEEL_RADIUS_TOLERANCE`: a cylinder's or sphere's radius, or a mesh's extent
    ``max_i |p_i - (p_i . a) a|`` about the wheel's axis ``a`` (vertices ``p_i`` in the
    wheel's frame, whose origin is on the axis). The base's speed is proportional to the
    radius (:mod:`wholebody.robot.base`), so a radius off by ``e`` drives it ``e`` too fast
    or too slow. A mesh file that cannot be found or read is not checked (drawing the robot
    reports it)."""
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    for w in base.wheel_joints:
        link = urdf.children.get(w, "")
        r, what = urdf.radii.get(link), "radius of its cylinder or sphere"
        if r is None and link in urdf.meshes:
            j = joint_ids[w]
            axis = pin.getJointJacobian(model, data, j, pin.LOCAL)[3:, model.joints[j].idx_v]
            r, what = _mesh_radius(config, urdf.meshes[link], axis), "extent of its mesh"
        if r is None or abs(r - config.base.wheel_radius) <= WHEEL_RADIUS_TOLERANCE * r:
            continue
        raise config.error(
            "base.wheel_radius",
            f"{config.base.wheel_radius:g} m, but the URDF's wheel {w!r} has a radius of "
            f"{r:.4g} m (the {what} about the wheel's axis): the base would drive "
            f"{abs(config.base.wheel_radius / r - 1):.1%} off the commanded speed (the check "
            f"allows {WHEEL_RADIUS_TOLERANCE:.0%}); give the geometry's radius",
        )


def _mesh_radius(
    config: RobotConfig, meshes: tuple[MeshRef, ...], axis: np.ndarray
) -> float | None:
    """The largest distance (m) of the meshes' vertices (scaled, placed in the link frame)
    from the line through the link origin along ``axis``; None if a file cannot be read."""
    import coal  # Pinocchio's collision library: it reads the meshes Pinocchio draws

    a = axis / np.linalg.norm(axis)
    radius = 0.0
    for m in meshes:
        try:
            path = _mesh_path(config, m.filename)
            bvh = coal.MeshLoader().load(str(path), np.array(m.scale))
        except (FileNotFoundError, RuntimeError, ValueError):
            return None
        placement = pin.SE3(pin.rpy.rpyToMatrix(np.array(m.rpy)), np.array(m.xyz))
        p = np.asarray(bvh.vertices()) @ placement.rotation.T + placement.translation
        radial = p - np.outer(p @ a, a)
        radius = max(radius, float(np.sqrt((radial**2).sum(axis=1)).max(initial=0.0)))
    return radius if radius > 0 else None


def _mesh_path(config: RobotConfig, filename: str) -> Path:
    """A ``<mesh filename>``: a ``package://`` path, a ``file://`` URI, or a path relative
    to the URDF's directory."""
    if filename.startswith(PACKAGE):
        return resolve_package(filename, config.package_dirs)
    path = Path(filename.removeprefix("file://"))
    path = path if path.is_absolute() else config.urdf.parent / path
    if not path.is_file():
        raise FileNotFoundError(path)
    return path
