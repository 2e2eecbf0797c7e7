"""The robot: one Pinocchio model and data, the actuated velocity space, joint groups, limits
and arm chains, loaded from a ``robot.toml`` and its URDF.

Loading (:class:`Robot`'s constructor) goes

1. from the URDF to the model: locked joints welded, declared frames added
   (:mod:`wholebody.robot.building`, :mod:`wholebody.robot.urdf`);
2. to the actuated velocity space ``u`` and the actuation matrix ``A``, ``v = A u``: base
   actuators first, mimic joints coupled to their leaders, position and velocity limits
   per entry of ``u`` (:mod:`wholebody.robot.actuation`, :mod:`wholebody.robot.wheels`);
3. to the named parts: joint groups, arm chains (:mod:`wholebody.robot.arms`), the home
   posture and the acceleration limits.

Configurations are made and read by :class:`~wholebody.robot.configurations.Configurations`
(a base class of :class:`Robot`); the kinematics at one configuration are a
:class:`~wholebody.robot.state.RobotState`, returned by :meth:`Robot.update`. Every Jacobian
is ``J_model A``: its wheel columns go through the base's actuation map.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from typing import TypeVar

import numpy as np
import pinocchio as pin

from wholebody.errors import FrameError, WholebodyError
from wholebody.robot._names import Named, suggest
from wholebody.robot.actuation import Actuation, build_actuation
from wholebody.robot.arms import arm_chain
from wholebody.robot.base import ANGULAR_ACTUATORS, BaseModel, base_model
from wholebody.robot.building import build_model, geometry_model
from wholebody.robot.com import total_mass
from wholebody.robot.compiled import RobotKinematics
from wholebody.robot.config import ACCELERATION_DEFAULTS, RobotConfig
from wholebody.robot.configurations import Configurations
from wholebody.robot.overrides import urdf_text
from wholebody.robot.parts import ArmChain, Body, Frame, JointGroup
from wholebody.robot.sim import SimSettings
from wholebody.robot.state import RobotState
from wholebody.robot.swerve import SwerveModule, swerve_modules
from wholebody.robot.urdf import UrdfInfo, read_urdf
from wholebody.robot.wheels import check_base_geometry

__all__ = ["ArmChain", "Body", "Frame", "JointGroup", "Robot", "RobotState"]

T = TypeVar("T")
_STAMPS = itertools.count(1)  # state versions, unique over every robot of the process

_FRAME_PREFERENCE = (
    pin.FrameType.BODY,
    pin.FrameType.OP_FRAME,
    pin.FrameType.FIXED_JOINT,
    pin.FrameType.JOINT,
    pin.FrameType.SENSOR,
)
"""The frame kinds :meth:`Robot.frame` looks a name up in, in this order."""


class Robot(Configurations):
    """A robot: Pinocchio model and data, actuation map, groups, limits and arm chains.

    Build it with :func:`wholebody.load_robot`. One ``Robot`` owns one ``pinocchio.Data``:
    :meth:`update` fills it and returns a :class:`RobotState` view, which stays valid until
    the next :meth:`update` (a stale view raises instead of returning wrong numbers). The
    convenience methods that take ``q`` (:meth:`frame_pose`, :meth:`frame_jacobian`, ...)
    call :meth:`update` themselves. The configuration helpers (:meth:`neutral`,
    :meth:`home`, :meth:`configuration`, :meth:`random_configuration`,
    :meth:`joint_positions`, :meth:`integrate`, ...) are those of
    :class:`~wholebody.robot.configurations.Configurations`.
    """

    def __init__(self, config: RobotConfig) -> None:
        self.config = config
        self.name = config.name
        base = base_model(config.base)
        text = urdf_text(config)  # the URDF with [joints] applied; None: the file as it is
        self.urdf: UrdfInfo = read_urdf(config.urdf, text)
        """What the URDF says besides the kinematics (link masses, mimic joints)."""
        self._built = build_model(config, self.urdf, base.mobile, text)
        self.model: pin.Model = self._built.model
        self.locked: Mapping[str, float] = dict(self._built.locked)
        """The joints ``[locked]`` removed from the model, and their positions (rad, m)."""
        self.data: pin.Data = self.model.createData()
        self._version = 0
        self._layouts: dict[tuple[int, ...], dict[int, int]] = {}  # see RobotState.prefetch
        self.base_frame: Frame = self.frame(self.urdf.root)
        """The URDF's root link (the moving base of a mobile robot)."""
        self._init_actuation(
            build_actuation(config, self.model, self.urdf, base, self._built.locked)
        )
        self.swerve: tuple[SwerveModule, ...] = swerve_modules(
            self.model, self.base, self._joint_ids, config, self.urdf
        )
        """A swerve base's modules (:func:`wholebody.robot.swerve.module_commands` turns
        the base twist into their commands); empty for another base."""
        kept = {g: j for g, j in config.groups.items() if g not in self._built.locked_groups}
        self.groups: dict[str, JointGroup] = Named(
            "joint group", {g: self._group(g, joints) for g, joints in kept.items()}
        )
        check_base_geometry(self.model, self.base, self._joint_ids, config, self.urdf)
        self.arms: dict[str, ArmChain] = Named(
            "arm", {a: arm_chain(self, c) for a, c in config.arms.items()}
        )
        self._home = self._configuration_from(config.home, "home")
        self.acceleration_limits: np.ndarray = self._acceleration_limits()
        """Per actuated velocity, the largest change of ``u`` per second (rad/s^2, m/s^2;
        ``[acceleration]`` of robot.toml over :data:`ACCELERATION_DEFAULTS`; read-only)."""
        self.mass: float = total_mass(self.model)
        """Total mass (kg): every link of the URDF, locked and fixed ones included."""
        self.kinematics = RobotKinematics(self)
        """What the compiled core reads (views of Pinocchio's data, actuation entries)."""

    # ------------------------------------------------------------------ construction
    def _init_actuation(self, act: Actuation) -> None:
        """The actuated velocity space's attributes, and the configuration layout."""
        self.base: BaseModel = act.base
        self.actuated_joints: tuple[str, ...] = act.joints
        self.nu = len(act.joints)
        self.nq, self.nv = self.model.nq, self.model.nv
        self.actuation: np.ndarray = act.matrix
        """``A`` (nv x nu): the model velocity is ``v = A u`` (read-only)."""
        self.position_limits: tuple[np.ndarray, np.ndarray] = (act.lower, act.upper)
        self.velocity_limits: np.ndarray = act.velocity
        self._joint_ids = act.joint_ids
        self._followers = act.followers
        self._u_index = {n: k for k, n in enumerate(act.joints)}
        self._init_configurations(act)

    def _acceleration_limits(self) -> np.ndarray:
        """``[acceleration]`` resolved per entry of ``u``: the class defaults, then groups,
        then joints."""
        given = dict(self.config.acceleration)
        a = np.full(self.nu, given.pop("joints", ACCELERATION_DEFAULTS["joints"]))
        wheels = given.pop("wheels", ACCELERATION_DEFAULTS["wheels"])
        linear = given.pop("base_linear", ACCELERATION_DEFAULTS["base_linear"])
        angular = given.pop("base_angular", ACCELERATION_DEFAULTS["base_angular"])
        for k, name in enumerate(self.actuated_joints):
            if name in self.base.wheel_joints:
                a[k] = wheels
            elif name not in self._joint_ids:  # a planar or floating base's virtual actuator
                a[k] = angular if name in ANGULAR_ACTUATORS else linear
        for name in sorted(given, key=lambda n: n not in self.groups):  # groups, then joints
            if name in self.groups:
                a[self.groups[name].indices] = given[name]
            elif name in self._u_index:
                a[self._u_index[name]] = given[name]
            else:
                known = [*ACCELERATION_DEFAULTS, *self.groups, *self.actuated_joints]
                raise self.config.error(
                    f"acceleration.{name}",
                    "not a group or joint of the robot" + suggest(name, known),
                )
        a.setflags(write=False)
        return a

    def _group(self, gname: str, joints: tuple[str, ...]) -> JointGroup:
        """The group ``gname`` of ``robot.toml``: actuated joints, by their index in ``u``."""
        for j in joints:
            if j in self.locked or j in self._followers:
                why = "locked ([locked])" if j in self.locked else "a mimic joint"
                raise self.config.error(
                    f"groups.{gname}",
                    f"joint {j!r} is {why}: it is no velocity of u; leave it out of the group",
                )
            if j not in self._u_index:
                raise self.config.error(
                    f"groups.{gname}",
                    f"{j!r} is not an actuated joint of {self.config.urdf.name}"
                    + suggest(j, self._u_index),
                )
        idx = np.array([self._u_index[j] for j in joints], dtype=int)
        idx.setflags(write=False)
        return JointGroup(gname, joints, idx)

    # ------------------------------------------------------------------ names
    def frame(self, name: str | Frame) -> Frame:
        """The frame called ``name`` (link, joint or fixed frame of the URDF).

        URDF lets a link and a joint share a name (the bundled ``mobile_humanoid`` has a link
        and a joint ``left_clavicle``): the link's frame is taken, then an operational frame,
        a fixed joint's, a joint's.
        """
        if isinstance(name, Frame):
            return name
        if isinstance(name, str):
            for kind in _FRAME_PREFERENCE:
                if self.model.existFrame(name, kind):
                    fid = self.model.getFrameId(name, kind)
                    return Frame(name, fid, int(self.model.frames[fid].parentJoint))
        names = list(dict.fromkeys(f.name for f in self.model.frames))
        raise FrameError(f"robot {self.name!r} has no frame {name!r}" + suggest(name, names))

    def body(self, name: str) -> Body:
        """The link ``name`` with its mass and centre of mass (from the URDF)."""
        links = self.urdf.links
        if name not in links:
            raise FrameError(f"robot {self.name!r} has no link {name!r}" + suggest(name, links))
        mass, com = links[name]
        return Body(name, self.frame(name), mass, com)

    def arm(self, name: str) -> ArmChain:
        """The arm ``name`` of ``robot.toml``."""
        return self._named(self.arms, name, "arm")

    def group(self, name: str) -> JointGroup:
        """The joint group ``name`` of ``robot.toml``."""
        return self._named(self.groups, name, "joint group")

    def index(self, joint: str) -> int:
        """Index of an actuated joint (or base actuator) in ``u``."""
        return self._named(self._u_index, joint, "actuated joint")

    def _named(self, table: Mapping[str, T], name: str, what: str) -> T:
        """``table[name]``, or a FrameError with the closest names."""
        try:
            return table[name]
        except KeyError:
            raise FrameError(
                f"robot {self.name!r} has no {what} {name!r}" + suggest(name, table)
            ) from None

    # ------------------------------------------------------------------ kinematics
    def update(self, q: np.ndarray) -> RobotState:
        """Forward kinematics and all joint Jacobians at ``q``; a view valid until the next
        call."""
        q = self._accept(q)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        self._version = next(_STAMPS)
        return RobotState(self, q, self._version)

    def frame_pose(self, q: np.ndarray, frame: str | Frame) -> np.ndarray:
        """4x4 pose of ``frame`` in the world at ``q``."""
        return self.update(self.check_configuration(q)).pose(self.frame(frame))

    def frame_jacobian(self, q: np.ndarray, frame: str | Frame) -> np.ndarray:
        """6 x nu Jacobian of ``frame`` at ``q``: world-aligned axes at the frame origin,
        linear rows first, wheel columns through the base actuation map."""
        return self.update(self.check_configuration(q)).jacobian(self.frame(frame)).copy()

    def com_position(self, q: np.ndarray, body: str | Body | None = None) -> np.ndarray:
        """World position (m) of a body's centre of mass at ``q``; without a body, of the
        whole robot's (see :meth:`RobotState.com_position`)."""
        if body is None:
            return self.update(self.check_configuration(q)).com_position().copy()
        body = body if isinstance(body, Body) else self.body(body)
        return self.update(self.check_configuration(q)).com_position(body)

    @property
    def sim_settings(self) -> SimSettings:
        """What a physics run adds to the URDF: ``robot.toml [sim]`` over the defaults."""
        return SimSettings(**self.config.sim)  # type: ignore[arg-type]

    def geometry(self, kind: str = "visual") -> tuple[pin.GeometryModel, str]:
        """The URDF's ``"visual"`` or ``"collision"`` geometry for :attr:`model` (locked
        joints welded as in the model; ``package://`` meshes found through ``[robot]
        package_dirs``, ``$ROS_PACKAGE_PATH`` and the installed example-robot-data), and a
        one-line note when meshes could not be found (they are then left out)."""
        kinds = {"visual": pin.GeometryType.VISUAL, "collision": pin.GeometryType.COLLISION}
        if kind not in kinds:
            raise WholebodyError(f"geometry kind must be 'visual' or 'collision', got {kind!r}")
        return geometry_model(self.config, self._built, kinds[kind])

    # ------------------------------------------------------------------ presentation
    def summary(self) -> str:
        """A human-readable description of the robot."""
        state = self.update(self.home())
        lines = [
            f"robot {self.name}: {self.config.description}".rstrip(": "),
            f"  files: {self.config.path} ({self.config.urdf})",
            f"  base: {self.base.type}{_height(self.config.base.height)}; nq = {self.nq}, "
            f"nv = {self.nv}, nu = {self.nu} "
            f"actuated velocities; mass {self.mass:g} kg",
        ]
        if self.swerve:
            modules = (f"{m.steering}/{m.drive} at ({m.x:.4f}, {m.y:.4f}) m" for m in self.swerve)
            lines.append("  swerve modules: " + ", ".join(modules))
        if self.locked:
            lines.append(f"  locked: {len(self.locked)} joints ({_abridged(list(self.locked))})")
        if self._followers:
            lines.append(
                "  mimic: "
                + ", ".join(f"{f} follows {m.leader}" for f, m in self._followers.items())
            )
        for g in self.groups.values():
            lines.append(f"  group {g.name} ({len(g)}): {', '.join(g.joints)}")
        for arm in self.arms.values():
            p = state.position(arm.tool)
            lines.append(
                f"  arm {arm.name} ({arm.side}): upper arm {arm.upper_arm_length:.4f} m, "
                f"forearm {arm.forearm_length:.4f} m, masses "
                f"{sum(b.mass for b in arm.upper_arm_bodies):g} / "
                f"{sum(b.mass for b in arm.forearm_bodies):g} kg; tool at the home posture: "
                f"({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}) m"
            )
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, nu={self.nu}, base={self.base.type!r})"


def _height(height: float) -> str:
    """``[base] height`` in the summary: nothing at the default 0."""
    return f", root link {height:g} m above the floor" if height else ""


def _abridged(names: list[str], most: int = 6) -> str:
    """At most ``most`` names, then how many more."""
    more = len(names) - most
    return ", ".join(names[:most]) + (f" and {more} more" if more > 0 else "")
