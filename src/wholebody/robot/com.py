"""The whole-body centre of mass and its Jacobian in actuated coordinates.

Over every body ``i`` with mass ``m_i`` (kg) and centre of mass ``c_i`` (m, world)::

    c = sum_i m_i c_i / M,        M = sum_i m_i
    J_c = sum_i m_i J_i / M       (3 x nu: c' = J_c u)

with ``J_i`` the linear Jacobian of ``c_i``. Pinocchio computes both over the model's joints
(``jacobianCenterOfMass`` on the kinematics :meth:`Robot.update
<wholebody.robot.Robot.update>` computed; ``3 x nv``, times the actuation matrix ``A`` like
every Jacobian, so wheel columns go through the base's map and a mimic joint moves with its
leader). Two kinds of mass are welded rather than jointed, and both count:

* locked joints (``[locked]``): Pinocchio's reduced model merges each welded link's inertia
  into its parent joint's, so it is in the sum above;
* the mass on the universe joint -- a fixed base's root link and what is locked onto it --
  which Pinocchio leaves out. It does not move: it shifts ``c`` and scales ``J_c`` by
  ``M_moving / M``, and is added here, so that ``c`` is the mass-weighted mean of every
  link of the URDF.

:func:`mass_table` gives the same sums per body for the kernels (each joint's inertia on one
of its frames, :func:`wholebody.kernels.rows.com_rows`), which compute ``c`` and ``J_c`` from
the frames' kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wholebody.errors import ModelError
from wholebody.robot.parts import Frame

__all__ = ["MassTable", "center_of_mass", "mass_table", "total_mass"]


def total_mass(model: pin.Model) -> float:
    """``M`` (kg): every inertia of the model, the universe's (a fixed base's) included."""
    return float(sum(inertia.mass for inertia in model.inertias))


@dataclass(frozen=True)
class MassTable:
    """The model's masses as :func:`~wholebody.kernels.rows.com_rows` sums them: per moving
    body (a joint's inertia, locked links merged in), a frame it moves with, its mass (kg)
    and its centre of mass in that frame (m); the mass welded to the world and its centre
    (kg, m world); the total (kg)."""

    frames: tuple[Frame, ...]
    masses: np.ndarray
    centres: np.ndarray
    fixed_mass: float
    fixed_centre: np.ndarray
    total: float


def mass_table(model: pin.Model) -> MassTable:
    """The :class:`MassTable` of ``model``: each joint with mass is carried by the first of
    its frames whose placement is the identity (its JOINT frame), else by its first frame;
    :class:`ModelError` for a massless model or a massive joint without a frame."""
    total = total_mass(model)
    if not total > 0.0:
        raise ModelError(
            "the robot has no mass: its URDF has no <inertial> with a mass > 0, "
            "so it has no centre of mass"
        )
    carriers: dict[int, int] = {}
    for fid, frame in enumerate(model.frames):
        j, best = int(frame.parentJoint), carriers.get(int(frame.parentJoint))
        if best is None or (
            frame.placement.isIdentity() and not model.frames[best].placement.isIdentity()
        ):
            carriers[j] = fid
    frames, masses, centres = [], [], []
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        if inertia.mass <= 0.0:
            continue
        if j not in carriers:
            raise ModelError(f"joint {model.names[j]!r} has mass but no frame to carry it")
        fid = carriers[j]
        frame = model.frames[fid]
        frames.append(Frame(frame.name, fid, j))
        masses.append(inertia.mass)
        centres.append(frame.placement.actInv(inertia.lever))
    fixed = model.inertias[0]
    return MassTable(
        tuple(frames),
        np.array(masses),
        np.array(centres).reshape(-1, 3),
        float(fixed.mass),
        np.array(fixed.lever),
        total,
    )


def center_of_mass(
    model: pin.Model, data: pin.Data, actuation: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(c, J_c)``: the whole-body centre of mass (3,) m in the world and its Jacobian
    (3 x nu) in actuated coordinates, read-only, from ``data`` after
    ``computeJointJacobians`` (module docstring). ``data``'s ``com``, ``mass`` and ``Jcom``
    are overwritten; its joint Jacobians are recomputed to the same values."""
    Jm = pin.jacobianCenterOfMass(model, data, False)  # the moving mass's, 3 x nv
    moving, fixed = float(data.mass[0]), model.inertias[0]
    mass = moving + fixed.mass
    if not mass > 0.0:
        raise ModelError(
            "the robot has no mass: its URDF has no <inertial> with a mass > 0, "
            "so it has no centre of mass"
        )
    if not moving > 0.0:  # everything welded to the world (Pinocchio divides by zero)
        c, Jm = np.zeros(3), np.zeros_like(Jm)
    else:
        c = np.array(data.com[0])
    if fixed.mass > 0.0:
        c = (moving * c + fixed.mass * fixed.lever) / mass
        Jm = Jm * (moving / mass)
    J = Jm.dot(actuation)
    c.setflags(write=False)
    J.setflags(write=False)
    return c, J
