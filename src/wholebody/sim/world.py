"""A MuJoCo model of a robot and a scenario's objects, built from the controller's own model.

The robot is compiled from the same Pinocchio model the controller uses (the URDF with
``robot.toml``'s locked joints welded and its frames), so that the simulated and the
controlled kinematics are one: every Pinocchio joint becomes a MuJoCo body with the joint's
placement, the URDF's mass and inertia (about the centre of mass, in the joint frame) and one
MuJoCo joint of the same name and axis (MuJoCo's own URDF importer welds the root link to the
world and reads no Collada meshes, which the example-robot-data robots use). What a URDF lacks
is added here, from :class:`SimSettings`:

* a planar root joint becomes three MuJoCo joints of the root body (slide x, slide y, hinge z
  about the world's z): **a planar base driven by velocity servos**, whose force limit is
  what the wheels' torque limits give through the base matrix; wheels spin on their own
  joints but do not touch the ground (no rolling contact, no slip);
* a free-flyer root (a floating base) becomes MuJoCo's free joint, **not driven**: the robot
  stands on its collision shapes, which then touch the floor (a humanoid's soles), and falls
  if its joints do not hold it there;
* every joint gets a torque motor (limit: the URDF's effort limit times
  ``effort_scale``), rotor inertia (``armature``) and viscous friction (``damping``);
* the collision shapes of the URDF (meshes as their convex hulls) touch the scenario's
  fixed objects but not each other (the controller keeps links apart where a scenario asks);
  every contact has the friction and softness of ``friction`` and ``contact_time``;
* objects with a mass are free bodies of uniform density resting on what is under them (a
  floor at z = 0 catches anything dropped), objects without one are fixed; neither touches
  the robot: a grasp is a **weld** between the hand's body and the object, off until a
  phase carries the object.

Contact bits (``contype``/``conaffinity``): robot 1/0, fixed objects and the floor 2/3 and
2/2 (the floor 2/3 under a floating base), free objects 2/2: the robot touches fixed objects
(and the floor if its base floats), free objects touch fixed objects and the floor.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import pinocchio as pin

from wholebody.errors import ModelError
from wholebody.robot import Robot
from wholebody.robot.sim import SimSettings, effort_limits, joint_kind, wheel_dofs

if TYPE_CHECKING:
    from wholebody.scenarios.spec import ObjectSpec

__all__ = ["World", "build_world"]

_SCALAR = {"RX": (1, 0, 0), "RY": (0, 1, 0), "RZ": (0, 0, 1)}
_SLIDE = {"PX": (1, 0, 0), "PY": (0, 1, 0), "PZ": (0, 0, 1)}
_CONTINUOUS = {"RUBX": (1, 0, 0), "RUBY": (0, 1, 0), "RUBZ": (0, 0, 1)}
_MIN_MASS, _MIN_INERTIA = 1e-4, 1e-7  # kg, kg m^2: MuJoCo needs moving bodies to have some


@dataclass
class World:
    """A compiled MuJoCo model of a robot and objects, with the maps between the two models.

    Attributes
    ----------
    model
        The ``mujoco.MjModel``.
    joints
        Per Pinocchio joint (index from 1): its MuJoCo joint names (three for a planar root,
        one free joint of six dofs for a free-flyer root).
    effort
        Torque (N m) or force (N) limit per MuJoCo degree of freedom of the robot, in
        :attr:`dofs` order.
    dofs
        MuJoCo dof index of each Pinocchio velocity (``nv``): the planar root's three are the
        world x, y and yaw slides, a free flyer's six its free joint's (MuJoCo's linear
        velocity is in the world, Pinocchio's in the base frame; no servo drives them).
    objects
        Name of each free object -> its MuJoCo body id.
    welds
        ``(object, hand frame)`` -> the weld's equality id.
    hand_bodies
        Hand frame name -> MuJoCo body id of the link that carries it.
    """

    model: mujoco.MjModel
    robot: Robot
    joints: dict[int, tuple[str, ...]]
    effort: np.ndarray
    dofs: np.ndarray
    objects: dict[str, int] = field(default_factory=dict)
    welds: dict[tuple[str, str], int] = field(default_factory=dict)
    hand_bodies: dict[str, int] = field(default_factory=dict)
    wheel_limit: float = math.inf
    """The smallest wheel torque limit (N m) of a wheeled base (inf without wheels)."""


def _quat(R: np.ndarray) -> list[float]:
    x, y, z, w = pin.Quaternion(R).coeffs()
    return [w, x, y, z]


def _add_joint(body, robot: Robot, index: int, settings: SimSettings) -> tuple[str, ...]:
    """The MuJoCo joint(s) of Pinocchio joint ``index`` in ``body``; their names."""
    model = robot.model
    joint, name = model.joints[index], model.names[index]
    kind = joint_kind(joint)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    if kind == "Planar":
        names = (f"{name}_x", f"{name}_y", f"{name}_yaw")
        for n, jt, axis in zip(
            names, ("slide", "slide", "hinge"), ((1, 0, 0), (0, 1, 0), (0, 0, 1)), strict=True
        ):
            body.add_joint(
                name=n,
                type=getattr(mujoco.mjtJoint, f"mjJNT_{jt.upper()}"),
                axis=axis,
                damping=settings.damping,
                armature=settings.armature,
            )
        return names
    if kind == "FreeFlyer":
        body.add_freejoint(name=name)
        return (name,)
    if kind in _SCALAR or kind == "RevoluteUnaligned":
        axis, jtype = _SCALAR.get(kind) or tuple(joint.extract().axis), mujoco.mjtJoint.mjJNT_HINGE
    elif kind in _SLIDE or kind == "PrismaticUnaligned":
        axis, jtype = _SLIDE.get(kind) or tuple(joint.extract().axis), mujoco.mjtJoint.mjJNT_SLIDE
    elif kind in _CONTINUOUS or kind == "RevoluteUnboundedUnaligned":
        axis = _CONTINUOUS.get(kind) or tuple(joint.extract().axis)
        body.add_joint(
            name=name,
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=axis,
            armature=settings.armature,
            damping=settings.damping,
        )
        return (name,)
    else:
        raise ModelError(
            f"joint {name!r} of robot {robot.name!r} is a {kind} joint, which the "
            "MuJoCo model does not support (revolute, prismatic, continuous, a "
            "planar or free-flyer root)"
        )
    k = joint.idx_q
    if not lo[k] < hi[k]:  # no range: a joint no velocity of u moves (a swerve module's)
        body.add_joint(
            name=name, type=jtype, axis=axis, armature=settings.armature, damping=settings.damping
        )
        return (name,)
    body.add_joint(
        name=name,
        type=jtype,
        axis=axis,
        armature=settings.armature,
        damping=settings.damping,
        limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        range=[float(lo[k]), float(hi[k])],
    )
    return (name,)


def _set_inertia(body, inertia: pin.Inertia) -> None:
    body.explicitinertial = True
    body.mass = max(float(inertia.mass), _MIN_MASS)
    body.ipos = inertia.lever.copy()
    eigen, axes = np.linalg.eigh(inertia.inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 0] *= -1
    body.inertia = np.maximum(eigen, _MIN_INERTIA)
    body.iquat = _quat(axes)


def _add_geom(body, spec: mujoco.MjSpec, obj: pin.GeometryObject, contact: tuple[int, int]):
    """A collision shape of the robot in ``body`` (placement in the joint frame)."""
    g = obj.geometry
    kind = type(g).__name__
    geom = body.add_geom(
        name=obj.name,
        pos=obj.placement.translation,
        quat=_quat(obj.placement.rotation),
        contype=contact[0],
        conaffinity=contact[1],
        group=3,
    )
    if kind == "Box":
        geom.type, geom.size = mujoco.mjtGeom.mjGEOM_BOX, list(g.halfSide)
    elif kind == "Sphere":
        geom.type, geom.size = mujoco.mjtGeom.mjGEOM_SPHERE, [g.radius, 0, 0]
    elif kind == "Cylinder":
        geom.type, geom.size = mujoco.mjtGeom.mjGEOM_CYLINDER, [g.radius, g.halfLength, 0]
    elif kind == "Capsule":
        geom.type, geom.size = mujoco.mjtGeom.mjGEOM_CAPSULE, [g.radius, g.halfLength, 0]
    elif hasattr(g, "vertices") and g.num_vertices >= 4:
        mesh = spec.add_mesh(name=f"{obj.name}_hull", maxhullvert=64)
        mesh.uservert = np.asarray(g.vertices(), dtype=np.float32).ravel()
        geom.type, geom.meshname = mujoco.mjtGeom.mjGEOM_MESH, mesh.name
    else:  # a shape MuJoCo has no counterpart for: a point that touches nothing
        geom.type, geom.size, geom.contype, geom.conaffinity = (
            mujoco.mjtGeom.mjGEOM_SPHERE,
            [1e-3, 0, 0],
            0,
            0,
        )


def _box_inertia(obj: ObjectSpec, mass: float) -> list[float]:
    """Principal moments (kg m^2) of a uniform solid object about its centre."""
    if obj.kind == "box":
        a, b, c = obj.size
        return [
            mass * (b * b + c * c) / 12,
            mass * (a * a + c * c) / 12,
            mass * (a * a + b * b) / 12,
        ]
    if obj.kind == "cylinder":
        r, h = obj.radius, obj.height
        side = mass * (3 * r * r + h * h) / 12
        return [side, side, mass * r * r / 2]
    return [0.4 * mass * obj.radius**2] * 3


def _object_geom(parent, obj: ObjectSpec, contact: tuple[int, int], pos) -> None:
    if obj.kind == "box":
        gtype, size = mujoco.mjtGeom.mjGEOM_BOX, [s / 2 for s in obj.size]
    elif obj.kind == "cylinder":
        gtype, size = mujoco.mjtGeom.mjGEOM_CYLINDER, [obj.radius, obj.height / 2, 0]
    else:
        gtype, size = mujoco.mjtGeom.mjGEOM_SPHERE, [obj.radius, 0, 0]
    parent.add_geom(
        name=obj.name, type=gtype, size=size, pos=pos, contype=contact[0], conaffinity=contact[1]
    )


def _hand_body(robot: Robot, frame: str) -> str:
    """The MuJoCo body (named after its Pinocchio joint) that carries ``frame``."""
    return robot.model.names[robot.frame(frame).joint]


def build_world(
    robot: Robot,
    objects: Iterable[ObjectSpec] = (),
    grasps: Iterable[tuple[str, str]] = (),
    settings: SimSettings | None = None,
) -> World:
    """Compile the MuJoCo model of ``robot`` and ``objects`` (those with a ``mass`` free,
    the others fixed), with an inactive weld for each ``(object, hand frame)`` of
    ``grasps``. A :class:`ModelError` for a joint MuJoCo cannot represent, a joint without
    an effort limit and a carried object without a mass."""
    settings = settings or SimSettings()
    spec = mujoco.MjSpec()
    spec.compiler.degree = False  # angles in rad, as in the URDF
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.timestep = settings.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_OVERRIDE  # every contact alike:
    spec.option.o_friction = [settings.friction, settings.friction, 0.005, 1e-4, 1e-4]
    spec.option.o_solref = [settings.contact_time, 1.0]
    spec.option.o_margin = 0.0
    effort = effort_limits(robot, settings)
    joints = _add_robot(spec, robot, settings, effort)
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 1],
        contype=2,
        conaffinity=3 if robot.base.floating else 2,
    )
    free = [obj.name for obj in objects if _add_object(spec, obj)]
    welds = list(dict.fromkeys(grasps))
    for name, frame in welds:
        if name not in free:
            raise ModelError(
                f"object {name!r} is carried, so it needs a mass (kg) under "
                "physics: add mass = ... to its [[objects]] entry"
            )
        spec.add_equality(
            name=f"grasp_{name}_{frame}",
            type=mujoco.mjtEq.mjEQ_WELD,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            name1=_hand_body(robot, frame),
            name2=name,
            active=False,
            solref=[2 * settings.timestep, 1.0],
        )
    model = spec.compile()
    dofs = np.empty(robot.nv, dtype=int)
    for i, names in joints.items():
        jm = robot.model.joints[i]
        adr = [model.jnt_dofadr[model.joint(n).id] for n in names]
        if jm.nv == 6 and len(names) == 1:  # the free joint: its six dofs in a row
            adr = list(range(adr[0], adr[0] + 6))
        dofs[jm.idx_v : jm.idx_v + jm.nv] = adr
    wheels = wheel_dofs(robot)
    return World(
        model,
        robot,
        joints,
        effort,
        dofs,
        objects={name: model.body(name).id for name in free},
        welds={w: model.equality(f"grasp_{w[0]}_{w[1]}").id for w in welds},
        hand_bodies={f: model.body(_hand_body(robot, f)).id for _, f in welds},
        wheel_limit=float(effort[wheels].min()) if wheels else math.inf,
    )


def _add_robot(
    spec: mujoco.MjSpec, robot: Robot, settings: SimSettings, effort: np.ndarray
) -> dict[int, tuple[str, ...]]:
    """The robot's bodies, joints, collision shapes and torque motors (limit ``effort`` per
    velocity); the MuJoCo joint names of each Pinocchio joint."""
    model = robot.model
    bodies = {0: spec.worldbody}
    joints: dict[int, tuple[str, ...]] = {}
    for i in range(1, model.njoints):
        M = model.jointPlacements[i]
        body = bodies[model.parents[i]].add_body(
            name=model.names[i], pos=M.translation, quat=_quat(M.rotation)
        )
        _set_inertia(body, model.inertias[i])
        joints[i] = _add_joint(body, robot, i, settings)
        bodies[i] = body
        if joint_kind(model.joints[i]) == "FreeFlyer":
            continue  # a floating base: nothing drives it
        for k, name in enumerate(joints[i]):
            limit = float(effort[model.joints[i].idx_v + k])
            spec.add_actuator(
                name=name,
                target=name,
                trntype=mujoco.mjtTrn.mjTRN_JOINT,
                ctrllimited=True,
                ctrlrange=[-limit, limit],
            )
    geometry, _ = robot.geometry("collision")
    for obj in geometry.geometryObjects:
        _add_geom(bodies[obj.parentJoint], spec, obj, (1, 0))
    return joints


def _add_object(spec: mujoco.MjSpec, obj: ObjectSpec) -> bool:
    """A scenario object: fixed in the world, or (with a mass) a free body of uniform
    density; whether it is free."""
    if obj.mass is None:
        _object_geom(spec.worldbody, obj, (2, 3), obj.position)
        return False
    body = spec.worldbody.add_body(name=obj.name, pos=obj.position)
    body.add_freejoint(name=f"{obj.name}_free")
    body.explicitinertial, body.mass = True, obj.mass
    body.ipos, body.iquat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]  # the centre
    body.inertia = _box_inertia(obj, obj.mass)
    _object_geom(body, obj, (2, 2), [0, 0, 0])
    return True
