"""The robot model: one Pinocchio model and data, the actuated velocity space, joint groups,
limits and arm chains.

Actuated velocities
-------------------
Tasks and solvers work in the **actuated velocity** space ``u`` (size ``nu``): first the base
actuators (wheel speeds in rad/s, or the twist of a directly actuated planar base), then one
speed per remaining 1-DOF joint in model order. The model velocity is ``v = A u`` with the
constant actuation matrix ``A`` (nv x nu): the planar root joint's rows are the base model's
``B`` (see :mod:`wholebody.robot.base`), every other joint's row is a unit row. Every
Jacobian this module returns is ``J_model A``: its wheel columns go through the base's
actuation map.

Frames
------
Poses are 4x4 homogeneous transforms in the world frame (z up). Jacobians are 6 x nu with
world-aligned axes at the frame origin (Pinocchio's ``LOCAL_WORLD_ALIGNED``), linear rows
first: ``[v; w] = J u``.
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np
import pinocchio as pin

from wholebody._numeric import float_array
from wholebody.errors import DimensionError, FrameError, ModelError, WholebodyError
from wholebody.robot.base import BaseModel, base_model
from wholebody.robot.building import build_model, geometry_model
from wholebody.robot.compiled import RobotKinematics
from wholebody.robot.config import ACCELERATION_DEFAULTS, ArmConfig, RobotConfig
from wholebody.robot.urdf import UrdfInfo, read_urdf

__all__ = ["ArmChain", "Body", "Frame", "JointGroup", "Robot", "RobotState"]

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
WORLD = pin.ReferenceFrame.WORLD
WHEEL_PLACEMENT_TOLERANCE = 1e-3  # m, between robot.toml's base geometry and the URDF
_FLOAT = np.dtype(float)
T = TypeVar("T")


@dataclass(frozen=True)
class Frame:
    """A frame of the robot model, resolved once by name (see :meth:`Robot.frame`)."""

    name: str
    index: int
    joint: int

    def __str__(self) -> str:
        return self.name


@dataclass(frozen=True)
class Body:
    """A rigid link with mass: its frame, mass (kg) and centre of mass in the link frame (m)."""

    name: str
    frame: Frame
    mass: float
    com: np.ndarray


@dataclass(frozen=True)
class JointGroup:
    """Named joints and their indices into the actuated velocity ``u``."""

    name: str
    joints: tuple[str, ...]
    indices: np.ndarray

    def __len__(self) -> int:
        return len(self.joints)


@dataclass(frozen=True)
class ArmChain:
    """An arm: frames at the shoulder, elbow and wrist centres and the tool, the upper-arm
    and forearm bodies, its side (``"left"``/``"right"``, used to mirror the arm angle) and
    its joint group if one is named in ``robot.toml``."""

    name: str
    side: str
    shoulder: Frame
    elbow: Frame
    wrist: Frame
    tool: Frame
    upper_arm: Body
    forearm: Body
    group: JointGroup | None

    upper_arm_bodies: tuple[Body, ...] = ()
    """Every link of the upper-arm segment (``upper_arm`` is the first): a segment's mass may
    be split over several links; the arm energy adds them all."""
    forearm_bodies: tuple[Body, ...] = ()
    """Every link of the forearm segment (``forearm`` is the first)."""

    @property
    def upper_arm_length(self) -> float:
        """Shoulder-to-elbow distance (m), the same at every posture (checked on loading)."""
        return float(self._lengths[0])

    @property
    def forearm_length(self) -> float:
        """Elbow-to-wrist distance (m)."""
        return float(self._lengths[1])

    _lengths: tuple[float, float] = (0.0, 0.0)


_FRAME_PREFERENCE = (
    pin.FrameType.BODY,
    pin.FrameType.OP_FRAME,
    pin.FrameType.FIXED_JOINT,
    pin.FrameType.JOINT,
    pin.FrameType.SENSOR,
)
"""The frame kinds :meth:`Robot.frame` looks a name up in, in this order."""


class Robot:
    """A robot: Pinocchio model and data, actuation map, groups, limits and arm chains.

    Build it with :func:`wholebody.load_robot`. One ``Robot`` owns one ``pinocchio.Data``:
    :meth:`update` fills it and returns a :class:`RobotState` view, which stays valid until
    the next :meth:`update` (a stale view raises instead of returning wrong numbers). The
    convenience methods that take ``q`` (:meth:`frame_pose`, :meth:`frame_jacobian`, ...)
    call :meth:`update` themselves.
    """

    def __init__(self, config: RobotConfig) -> None:
        self.config = config
        self.name = config.name
        self.base: BaseModel = base_model(config.base)
        self.urdf: UrdfInfo = read_urdf(config.urdf)
        """What the URDF says besides the kinematics (link masses, mimic joints)."""
        self._links, root_link = self.urdf.links, self.urdf.root
        self._built = build_model(config, self.urdf, self.base.mobile)
        self.model: pin.Model = self._built.model
        self.locked: Mapping[str, float] = dict(self._built.locked)
        """The joints ``[locked]`` removed from the model, and their positions (rad, m)."""
        self.data: pin.Data = self.model.createData()
        self._version = 0
        self._layouts: dict[tuple[int, ...], dict[int, int]] = {}  # see RobotState.prefetch
        self.base_frame: Frame = self.frame(root_link)
        """The URDF's root link (the moving base of a mobile robot)."""
        self._build_actuation()
        kept = {g: j for g, j in config.groups.items() if g not in self._built.locked_groups}
        self.groups: dict[str, JointGroup] = _Named(
            "joint group", {g: self._group(g, joints) for g, joints in kept.items()}
        )
        self._check_base_geometry()
        self.arms: dict[str, ArmChain] = _Named(
            "arm", {a: self._arm(c) for a, c in config.arms.items()}
        )
        self._home = self._configuration_from(config.home, "home")
        self.acceleration_limits: np.ndarray = self._acceleration_limits()
        """Per actuated velocity, the largest change of ``u`` per second (rad/s^2, m/s^2;
        ``[acceleration]`` of robot.toml over :data:`ACCELERATION_DEFAULTS`; read-only)."""
        self.kinematics = RobotKinematics(self)
        """What the compiled core reads (views of Pinocchio's data, actuation entries)."""

    # ------------------------------------------------------------------ construction
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
            elif name not in self._joint_ids:  # a planar base's x, y, yaw
                a[k] = angular if k == 2 else linear
        for name in sorted(given, key=lambda n: n not in self.groups):  # groups, then joints
            if name in self.groups:
                a[self.groups[name].indices] = given[name]
            elif name in self._u_index:
                a[self._u_index[name]] = given[name]
            else:
                known = [*ACCELERATION_DEFAULTS, *self.groups, *self.actuated_joints]
                raise self.config.error(f"acceleration.{name}", "not a group or joint of the "
                                        "robot" + _suggest(name, known))  # fmt: skip
        a.setflags(write=False)
        return a

    def _build_actuation(self) -> None:
        model, base = self.model, self.base
        first = 2 if base.mobile else 1  # joint 0 = universe, 1 = planar root if mobile
        joint_ids = {model.names[j]: j for j in range(first, model.njoints)}
        for name, j in joint_ids.items():
            if model.joints[j].nv != 1:
                raise ModelError(
                    f"{self.config.urdf}: joint {name!r} has {model.joints[j].nv} DOF; "
                    "wholebody supports 1-DOF joints (revolute, continuous, prismatic) "
                    "below the root"
                )
        for w in base.wheel_joints:
            if w not in joint_ids:
                raise self.config.error(
                    "base.wheels",
                    f"wheel joint {w!r} is not a joint of {self.config.urdf.name}"
                    + _suggest(w, joint_ids),
                )
        if base.wheel_joints:
            base = self.base = self._wheel_geometry(joint_ids)
        # a mimic joint (not locked) is no velocity of u: its leader's moves it (below)
        self._followers = {f: m for f, m in self.urdf.mimic.items() if f in joint_ids}
        moved = set(base.wheel_joints) | set(self._followers)
        names = list(base.actuators) + [n for n in joint_ids if n not in moved]
        self.actuated_joints: tuple[str, ...] = tuple(names)
        self.nu = len(names)
        self.nq, self.nv = model.nq, model.nv
        self._q_shape = (model.nq,)
        A = np.zeros((model.nv, self.nu))
        lower = np.full(self.nu, -np.inf)
        upper = np.full(self.nu, np.inf)
        vmax = np.full(self.nu, np.inf)
        kinds = np.zeros(self.nu, dtype=int)  # 0 scalar q, 1 continuous (cos, sin), 2 base
        qidx = np.zeros(self.nu, dtype=int)
        nb = len(base.actuators)
        if base.mobile:
            A[0:3, 0:nb] = base.matrix
        for k, name in enumerate(names):
            if name not in joint_ids:  # virtual planar actuator
                kinds[k] = 2
                qidx[k] = k
                vmax[k] = (
                    self.config.base.max_linear_velocity
                    if k < 2
                    else self.config.base.max_angular_velocity
                )
                continue
            j = joint_ids[name]
            iv, iq = model.joints[j].idx_v, model.joints[j].idx_q
            A[iv, k] = 1.0
            qidx[k] = iq
            vmax[k] = model.velocityLimit[iv]
            if model.joints[j].nq == 2:
                kinds[k] = 1
            else:
                lower[k] = model.lowerPositionLimit[iq]
                upper[k] = model.upperPositionLimit[iq]
        self._mimic_q = self._couple_mimics(joint_ids, names, A, lower, upper, vmax)
        lower[~np.isfinite(lower) | (lower < -1e300)] = -np.inf
        upper[~np.isfinite(upper) | (upper > 1e300)] = np.inf
        for k in np.flatnonzero(~(lower < upper) & (kinds == 0)).tolist():
            raise ModelError(
                f"{self.config.urdf}: joint {names[k]!r} cannot move: its limits are "
                f"[{lower[k]:g}, {upper[k]:g}] (a URDF <limit> without lower and upper means "
                "0 and 0); give it its range, or make it a fixed joint"
            )
        vmax[vmax <= 0] = np.inf  # URDF velocity 0 means "not given"
        self.actuation = A
        self.position_limits: tuple[np.ndarray, np.ndarray] = (lower, upper)
        self.velocity_limits: np.ndarray = vmax
        for arr in (A, lower, upper, vmax):
            arr.setflags(write=False)
        self.positional: np.ndarray = kinds == 0
        """Per actuated velocity: whether it has a bounded-or-not scalar joint position
        (revolute, prismatic); False for wheels and planar-base actuators."""
        self.positional.setflags(write=False)
        self._scalar = np.flatnonzero(kinds == 0)
        self._scalar_q = qidx[self._scalar]
        self._cont = np.flatnonzero(kinds == 1)
        self._cont_q = qidx[self._cont]
        self._virtual = np.flatnonzero(kinds == 2)
        # joint_positions()'s gathers: slices where the indices are runs (cheaper than fancy
        # indexing), the same entries
        self._scalar_ix = _as_slice(self._scalar)
        self._scalar_qix = _as_slice(self._scalar_q)
        self._cont_ix = _as_slice(self._cont)
        self._cont_cos = _as_slice(self._cont_q)
        self._cont_sin = _as_slice(self._cont_q + 1)
        self._joint_ids = joint_ids
        self._u_index = {n: k for k, n in enumerate(names)}
        # the zero configuration, every joint whose range excludes 0 at its nearer limit
        # where q holds (cos, sin) pairs: the planar root's yaw, every continuous joint
        self._pairs = np.concatenate(([2] if base.mobile else [], self._cont_q)).astype(int)
        self._pair_list: list[int] = self._pairs.tolist()
        self._neutral = pin.neutral(model)
        self._neutral[self._scalar_q] = np.clip(0.0, lower[self._scalar], upper[self._scalar])
        self._couple(self._neutral)
        self._neutral.setflags(write=False)

    def _couple_mimics(self, joint_ids: Mapping[str, int], names: Sequence[str], A: np.ndarray,
                       lower: np.ndarray, upper: np.ndarray,
                       vmax: np.ndarray) -> list[tuple[int, int, float, float]]:  # fmt: skip
        """Each mimic joint moves with its leader: its row of ``A`` is ``multiplier`` in the
        leader's column, and its position and velocity limits narrow the leader's (in the
        leader's coordinate). Returns ``(q index, leader's q index, multiplier, offset)``."""
        model, index = self.model, {n: k for k, n in enumerate(names)}
        out = []
        for name, m in self._followers.items():
            jf, jl = model.joints[joint_ids[name]], model.joints[joint_ids[m.leader]]
            if jf.nq != 1 or jl.nq != 1:
                raise ModelError(f"{self.config.urdf}: mimic joint {name!r}: wholebody "
                                 "couples revolute and prismatic joints only")  # fmt: skip
            k = index[m.leader]
            A[jf.idx_v, k] = m.multiplier
            lo, hi = model.lowerPositionLimit[jf.idx_q], model.upperPositionLimit[jf.idx_q]
            if abs(lo) < 1e300 and abs(hi) < 1e300:
                a, b = sorted(((lo - m.offset) / m.multiplier, (hi - m.offset) / m.multiplier))
                lower[k], upper[k] = max(lower[k], a), min(upper[k], b)
            if model.velocityLimit[jf.idx_v] > 0:
                vmax[k] = min(vmax[k], model.velocityLimit[jf.idx_v] / abs(m.multiplier))
            out.append((jf.idx_q, jl.idx_q, m.multiplier, m.offset))
        return out

    def _couple(self, q: np.ndarray) -> np.ndarray:
        """``q`` with every mimic joint at ``multiplier q_leader + offset`` (in place)."""
        for i, leader, multiplier, offset in self._mimic_q:
            q[i] = multiplier * q[leader] + offset
        return q

    def _group(self, gname: str, joints: tuple[str, ...]) -> JointGroup:
        for j in joints:
            if j in self.locked or j in self._followers:
                why = "locked ([locked])" if j in self.locked else "a mimic joint"
                raise self.config.error(f"groups.{gname}", f"joint {j!r} is {why}: it is no "
                                        "velocity of u; leave it out of the group")  # fmt: skip
            if j not in self._u_index:
                raise self.config.error(
                    f"groups.{gname}",
                    f"{j!r} is not an actuated joint of {self.config.urdf.name}"
                    + _suggest(j, self._u_index),
                )
        idx = np.array([self._u_index[j] for j in joints], dtype=int)
        idx.setflags(write=False)
        return JointGroup(gname, joints, idx)

    def _wheel_geometry(self, joint_ids: Mapping[str, int]) -> BaseModel:
        """The base model with the URDF's wheel axes and axle: a wheel turning positively
        about ``+y`` of the base drives it forward, so a wheel whose joint axis is ``-y``
        gets its column of ``B`` negated; a differential axle at ``x = x_a`` of the base
        origin gives the origin the lateral speed ``vy = -x_a wz`` (the axle midpoint, not
        the origin, cannot slide sideways)."""
        model, base = self.model, self.base
        data = model.createData()
        pin.computeJointJacobians(model, data, pin.neutral(model))
        B = base.matrix.copy()
        xs = []
        for k, w in enumerate(base.wheel_joints):
            j = joint_ids[w]
            if model.parents[j] != 1:
                raise self.config.error(
                    "base.wheels",
                    f"wheel {w!r} must be attached to the base link (the root link of the URDF), "
                    f"not below joint {model.names[model.parents[j]]!r}",
                )
            local = pin.getJointJacobian(model, data, j, pin.LOCAL)[3:, model.joints[j].idx_v]
            axis = model.jointPlacements[j].rotation @ local  # in the base (root) frame
            if abs(axis[1]) < 1.0 - 1e-6:
                raise self.config.error(
                    "base.wheels",
                    f"wheel {w!r} turns about ({axis[0]:.3g}, {axis[1]:.3g}, {axis[2]:.3g}) in "
                    "the base frame: a wheel's joint axis must be the base's lateral axis, "
                    "+y or -y (x forward, z up)",
                )
            B[:, k] *= math.copysign(1.0, axis[1])
            xs.append(float(model.jointPlacements[j].translation[0]))
        if base.type == "differential":
            if abs(xs[0] - xs[1]) > WHEEL_PLACEMENT_TOLERANCE:
                raise self.config.error(
                    "base.wheels",
                    f"the wheels of a differential base share one axle: {base.wheel_joints[0]!r} "
                    f"is at x={xs[0]:.4f} m, {base.wheel_joints[1]!r} at x={xs[1]:.4f} m",
                )
            B[1] = -0.5 * (xs[0] + xs[1]) * B[2]
        B.setflags(write=False)
        return replace(base, matrix=B)

    def _check_base_geometry(self) -> None:
        """Check the base parameters of robot.toml against the URDF's wheel placements and,
        where the wheels' geometry is a cylinder or sphere, their radius (within 5 %)."""
        base, cfg = self.base, self.config.base
        if not base.wheel_joints:
            return
        for w in base.wheel_joints:
            r = self.urdf.radii.get(self.urdf.children.get(w, ""))
            if r is not None and abs(r - cfg.wheel_radius) > 0.05 * r:
                raise self.config.error(
                    "base.wheel_radius", f"{cfg.wheel_radius:g} m, but the URDF's wheel "
                    f"{w!r} has a radius of {r:g} m (its geometry)",
                )  # fmt: skip
        placements = []
        for w in base.wheel_joints:  # (attached to the base: see _wheel_geometry)
            placements.append(self.model.jointPlacements[self._joint_ids[w]].translation[:2])
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
            raise self.config.error(
                "base",
                f"{keys} do not match the URDF: wheel "
                f"{base.wheel_joints[bad]!r} is at x={xy[bad, 0]:.4f}, y={xy[bad, 1]:.4f} m but "
                f"the [base] table puts it at x={expected[bad, 0]:.4f}, y={expected[bad, 1]:.4f}"
                f" m (expected wheels {what})",
            )

    def _arm(self, cfg: ArmConfig) -> ArmChain:
        where = f"arms.{cfg.name}"
        frames = {}
        for key in ("shoulder", "elbow", "wrist", "tool"):
            try:
                frames[key] = self.frame(getattr(cfg, key))
            except FrameError as exc:
                raise self.config.error(f"{where}.{key}", str(exc)) from None
        segments = {key: self._segment(f"{where}.{key}", getattr(cfg, key))
                    for key in ("upper_arm", "forearm")}  # fmt: skip
        group = self.groups[cfg.group] if cfg.group else None
        self._check_chain(cfg, frames, segments, group)
        lengths = self._arm_lengths(cfg, frames)
        return ArmChain(
            cfg.name,
            cfg.side,
            frames["shoulder"],
            frames["elbow"],
            frames["wrist"],
            frames["tool"],
            segments["upper_arm"][0],
            segments["forearm"][0],
            group,
            upper_arm_bodies=segments["upper_arm"],
            forearm_bodies=segments["forearm"],
            _lengths=lengths,
        )

    def _segment(self, key: str, links: tuple[str, ...]) -> tuple[Body, ...]:
        """The bodies of an arm segment: links of the URDF with a mass; the first one the
        arm energy's kernel reads, the others added to it (see ArmPotentialEnergy)."""
        out = []
        for name in links:
            if name not in self._links:
                raise self.config.error(
                    key, f"{name!r} is not a link of {self.config.urdf.name}"
                    + _suggest(name, self._links),
                )  # fmt: skip
            mass, com = self._links[name]
            if mass <= 0:
                raise self.config.error(
                    key, f"link {name!r} has no mass in the URDF: expected an <inertial> "
                    "with mass > 0 (the arm energy needs it)",
                )  # fmt: skip
            out.append(Body(name, self.frame(name), mass, com))
        return tuple(out)

    def _check_chain(self, cfg: ArmConfig, frames: dict[str, Frame],
                     segments: dict[str, tuple[Body, ...]],
                     group: JointGroup | None) -> None:  # fmt: skip
        """Shoulder, elbow, wrist and tool one below the other on one kinematic chain, the
        upper arm between shoulder and elbow, the forearm between elbow and wrist, and the
        arm's group made of joints of that chain."""
        supports = self.model.supports
        where = f"arms.{cfg.name}"

        def below(upper: Frame, lower: Frame) -> bool:  # every joint moving upper moves lower
            return upper.joint in supports[lower.joint]

        order = (("shoulder", "elbow"), ("elbow", "wrist"), ("wrist", "tool"))
        for a, b in order:
            if not below(frames[a], frames[b]):
                raise self.config.error(
                    f"{where}.{b}",
                    f"{frames[b].name!r} is not below the {a} {frames[a].name!r} on one "
                    "kinematic chain: expected shoulder, elbow, wrist and tool in that order "
                    "along the arm",
                )
        for key, (a, b) in (("upper_arm", ("shoulder", "elbow")),
                            ("forearm", ("elbow", "wrist"))):  # fmt: skip
            for body in (s.frame for s in segments[key]):
                if not (below(frames[a], body) and below(body, frames[b])):
                    raise self.config.error(
                        f"{where}.{key}",
                        f"link {body.name!r} is not on the chain between the {a} "
                        f"{frames[a].name!r} and the {b} {frames[b].name!r}",
                    )
        if group is not None:
            chain = set(supports[frames["tool"].joint])
            # the base's actuators (wheels, a planar base's virtual joints) move every frame
            base = set(self.base.wheel_joints)
            off = [j for j in group.joints if j not in base and self.model.existJointName(j)
                   and self.model.getJointId(j) not in chain]  # fmt: skip
            if off:
                raise self.config.error(
                    f"{where}.group",
                    f"group {group.name!r} has joints that do not move the tool "
                    f"{frames['tool'].name!r}: {', '.join(map(repr, off))}",
                )

    def _arm_lengths(self, cfg: ArmConfig, frames: dict[str, Frame]) -> tuple[float, float]:
        """Shoulder-elbow and elbow-wrist distances (m), checked to be the same (to 0.1 mm) at
        the neutral posture and with the arm's joints (those between shoulder and wrist) at 20
        random positions: the arm geometry (arm angle, posture mapping) takes the three
        frames as joint centres."""
        # only the joints between shoulder and wrist move, the others stay at neutral
        supports, neutral = self.model.supports, self.neutral()
        above = set(supports[frames["shoulder"].joint])
        moving = [self.model.joints[j] for j in supports[frames["wrist"].joint]
                  if j not in above]  # fmt: skip
        idx = np.concatenate([np.arange(jm.idx_q, jm.idx_q + jm.nq) for jm in moving]
                             or [np.zeros(0, dtype=int)])  # fmt: skip
        rng = np.random.default_rng(0)
        configurations = [neutral]
        for _ in range(20):
            q = neutral.copy()
            q[idx] = self.random_configuration(rng)[idx]
            configurations.append(q)
        pairs = (("shoulder", "elbow"), ("elbow", "wrist"))
        d = np.empty((len(configurations), 2))
        for i, q in enumerate(configurations):
            state = self.update(q)
            for k, (a, b) in enumerate(pairs):
                d[i, k] = np.linalg.norm(state.position(frames[b]) - state.position(frames[a]))
        where = f"arms.{cfg.name}"
        if d[0].min() < 1e-3:
            raise self.config.error(
                where,
                f"upper-arm/forearm lengths {tuple(d[0].tolist())} m: the shoulder, elbow and "
                "wrist frames must be distinct points",
            )
        spread = d.max(axis=0) - d.min(axis=0)
        for k, (a, b) in enumerate(pairs):
            if spread[k] > 1e-4:
                raise self.config.error(
                    f"{where}.{b}",
                    f"the {a}-{b} distance changes with the posture ({d[:, k].min():.4f} to "
                    f"{d[:, k].max():.4f} m): the shoulder, elbow and wrist frames must be joint "
                    "centres (on the axes of the joints between them)",
                )
        return float(d[0, 0]), float(d[0, 1])

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
        raise FrameError(f"robot {self.name!r} has no frame {name!r}" + _suggest(name, names))

    def body(self, name: str) -> Body:
        """The link ``name`` with its mass and centre of mass (from the URDF)."""
        if name not in self._links:
            raise FrameError(
                f"robot {self.name!r} has no link {name!r}" + _suggest(name, self._links)
            )
        mass, com = self._links[name]
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
                f"robot {self.name!r} has no {what} {name!r}" + _suggest(name, table)
            ) from None

    # ------------------------------------------------------------------ configurations
    def neutral(self) -> np.ndarray:
        """The zero configuration: base at the world origin facing +x, all joints at 0 (a
        joint whose range excludes 0 at its nearer limit, so that it is a valid state)."""
        return self._neutral.copy()

    def home(self) -> np.ndarray:
        """The home posture of ``robot.toml`` (base at the origin)."""
        return self._home.copy()

    def configuration(
        self,
        joints: Mapping[str, float] | None = None,
        base_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> np.ndarray:
        """A configuration from joint values (rad, m) by name and a base pose (x, y, yaw)."""
        q = self._configuration_from(joints or {}, "joints")
        self._set_base(q, base_pose)
        return q

    def _configuration_from(self, joints: Mapping[str, float], where: str) -> np.ndarray:
        q = self.neutral()
        lower, upper = self.position_limits
        for name, value in joints.items():
            if name not in self._u_index:
                msg = _not_actuated(name, self.locked, self._followers, self._u_index)
                if where == "home":
                    raise self.config.error(f"home.{name}", msg)
                raise FrameError(msg)
            k = self._u_index[name]
            if not isinstance(value, numbers.Real) or isinstance(value, bool):
                msg = f"expected a number (rad or m), got {value!r}"
                if where == "home":
                    raise self.config.error(f"home.{name}", msg)
                raise DimensionError(f"joint {name!r}: {msg}")
            if not lower[k] <= value <= upper[k]:
                msg = f"{value} rad is outside the joint's limits [{lower[k]}, {upper[k]}]"
                if where == "home":
                    raise self.config.error(f"home.{name}", msg)
                raise DimensionError(f"joint {name!r}: {msg}")
            j = self.model.joints[self._joint_ids[name]]
            if j.nq == 2:
                q[j.idx_q : j.idx_q + 2] = math.cos(value), math.sin(value)
            else:
                q[j.idx_q] = value
        return self._couple(q)

    def _set_base(self, q: np.ndarray, pose: tuple[float, float, float]) -> None:
        if not self.base.mobile:
            if any(pose):
                raise DimensionError(
                    f"robot {self.name!r} has a fixed base: base_pose must be (0, 0, 0)"
                )
            return
        values = tuple(pose) if isinstance(pose, (tuple, list, np.ndarray)) else ()
        if len(values) != 3 or not all(isinstance(v, numbers.Real) and math.isfinite(v)
                                       for v in values):  # fmt: skip
            raise DimensionError(f"base_pose must be three finite numbers (x m, y m, yaw rad), "
                                 f"got {pose!r}")  # fmt: skip
        x, y, yaw = map(float, values)
        q[0:4] = x, y, math.cos(yaw), math.sin(yaw)

    def random_configuration(
        self, rng: np.random.Generator, margin: float = 0.0, base_range: float = 1.0
    ) -> np.ndarray:
        """A configuration drawn uniformly inside the joint limits shrunk by ``margin``
        (fraction of each range on each side; a joint without a limit on one side within 2 pi
        (rad or m) of the other, without any in [-pi, pi]), wheels at random angles, base
        uniform in ``[-base_range, base_range]^2`` with any heading."""
        if not (isinstance(margin, numbers.Real) and 0.0 <= margin < 0.5):
            raise DimensionError("random_configuration: margin is the fraction of each range kept "
                                 f"clear on each side, in [0, 0.5); got {margin!r}")  # fmt: skip
        if not (isinstance(base_range, numbers.Real) and 0.0 <= base_range < math.inf):
            raise DimensionError(f"random_configuration: base_range must be a finite distance "
                                 f">= 0 (m), got {base_range!r}")  # fmt: skip
        lower, upper = self.position_limits
        q = self.neutral()
        s = self._scalar
        lo, hi = lower[s], upper[s]
        # a side without a limit: 2 pi (rad or m) from the other, or [-pi, pi] with neither
        has_lo, has_hi = np.isfinite(lo), np.isfinite(hi)
        lo, hi = (np.where(has_lo, lo, np.where(has_hi, hi - 2 * np.pi, -np.pi)),
                  np.where(has_hi, hi, np.where(has_lo, lo + 2 * np.pi, np.pi)))  # fmt: skip
        span = hi - lo
        q[self._scalar_q] = rng.uniform(lo + margin * span, hi - margin * span)
        ang = rng.uniform(-np.pi, np.pi, self._cont.size)
        q[self._cont_q], q[self._cont_q + 1] = np.cos(ang), np.sin(ang)
        if self.base.mobile:
            x, y = rng.uniform(-base_range, base_range, 2)
            self._set_base(q, (x, y, rng.uniform(-np.pi, np.pi)))
        return self._couple(q)

    def joint_positions(self, q: np.ndarray) -> np.ndarray:
        """One scalar position per entry of ``u`` (rad or m): joint angles, wheel angles in
        (-pi, pi], and for a directly actuated planar base its pose (x, y, yaw)."""
        out = np.empty(self.nu)
        out[self._scalar_ix] = q[self._scalar_qix]
        out[self._cont_ix] = np.arctan2(q[self._cont_sin], q[self._cont_cos])
        if self._virtual.size:
            out[self._virtual] = self.base_pose(q)
        return out

    def base_pose(self, q: np.ndarray) -> np.ndarray:
        """Base pose ``(x [m], y [m], yaw [rad])`` in the world (zeros for a fixed base)."""
        if not self.base.mobile:
            return np.zeros(3)
        return np.array([q[0], q[1], math.atan2(q[3], q[2])])

    # ------------------------------------------------------------------ kinematics
    def check_configuration(self, q: np.ndarray) -> np.ndarray:
        """``q`` as a float array of shape (nq,), or a :class:`DimensionError`."""
        q = float_array(q, f"configuration of robot {self.name!r}")
        if q.shape != (self.nq,):
            raise DimensionError(
                f"configuration of robot {self.name!r} has shape {q.shape}; expected ({self.nq},)"
            )
        if not np.all(np.isfinite(q)):
            raise DimensionError(f"configuration of robot {self.name!r} is not finite: {q}")
        c, s = q[self._pairs], q[self._pairs + 1]
        bad = np.flatnonzero(np.abs(c * c + s * s - 1.0) > 1e-6)
        if bad.size:
            i = int(self._pairs[bad[0]])
            raise DimensionError(
                f"configuration of robot {self.name!r}: (q[{i}], q[{i + 1}]) = ({q[i]:g}, "
                f"{q[i + 1]:g}) is not a (cos, sin) pair: q stores the base's yaw and every "
                f"continuous joint's angle as cos and sin (nq = {self.nq} for nu = {self.nu}); "
                "build q with robot.neutral(), robot.home() or robot.configuration()"
            )
        return q

    def _accept(self, q: np.ndarray) -> np.ndarray:
        """``q`` checked: the common case (a finite float vector of the right shape with unit
        (cos, sin) pairs) accepted fast, anything else through :meth:`check_configuration`.
        A NaN or inf makes ``q.q`` non-finite; an overflow of it only sends q to the full
        check."""
        if (
            q.__class__ is np.ndarray
            and q.dtype == _FLOAT
            and q.shape == self._q_shape
            and math.isfinite(q.dot(q))
            and self._unit_pairs(q)
        ):
            return q
        return self.check_configuration(q)

    def _unit_pairs(self, q: np.ndarray) -> bool:
        """Whether every (cos, sin) pair of ``q`` is a unit vector (to 1e-6; about 0.2 us a
        pair, cheaper than :meth:`check_configuration`'s arrays)."""
        for i in self._pair_list:
            c, s = q.item(i), q.item(i + 1)
            if abs(c * c + s * s - 1.0) > 1e-6:
                return False
        return True

    def update(self, q: np.ndarray) -> RobotState:
        """Forward kinematics and all joint Jacobians at ``q``; a view valid until the next
        call."""
        q = self._accept(q)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        self._version += 1
        return RobotState(self, q, self._version)

    def frame_pose(self, q: np.ndarray, frame: str | Frame) -> np.ndarray:
        """4x4 pose of ``frame`` in the world at ``q``."""
        return self.update(self.check_configuration(q)).pose(self.frame(frame))

    def frame_jacobian(self, q: np.ndarray, frame: str | Frame) -> np.ndarray:
        """6 x nu Jacobian of ``frame`` at ``q``: world-aligned axes at the frame origin,
        linear rows first, wheel columns through the base actuation map."""
        return self.update(self.check_configuration(q)).jacobian(self.frame(frame)).copy()

    def com_position(self, q: np.ndarray, body: str | Body) -> np.ndarray:
        """World position (m) of a body's centre of mass at ``q``."""
        body = body if isinstance(body, Body) else self.body(body)
        return self.update(self.check_configuration(q)).com_position(body)

    def integrate(self, q: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """Configuration reached from ``q`` by applying ``u`` for ``dt`` seconds (exact on
        the configuration manifold: the planar base follows the SE(2) exponential)."""
        q = self._accept(q)
        u = float_array(u, f"actuated velocity of robot {self.name!r}")
        if u.shape != (self.nu,):
            raise DimensionError(
                f"actuated velocity of robot {self.name!r} has shape "
                f"{u.shape}; expected ({self.nu},)"
            )
        if not math.isfinite(u.dot(u)):
            raise DimensionError(f"actuated velocity of robot {self.name!r} is not finite: {u}")
        if not (isinstance(dt, numbers.Real) and math.isfinite(dt)):
            raise DimensionError(f"integrate: dt must be a finite number of seconds, got {dt!r}")
        return pin.integrate(self.model, q, self.actuation.dot(u * dt))

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
            f"  base: {self.base.type}; nq = {self.nq}, nv = {self.nv}, nu = {self.nu} "
            "actuated velocities",
        ]
        if self.locked:
            lines.append(f"  locked: {len(self.locked)} joints ({_abridged(list(self.locked))})")
        if self._followers:
            lines.append("  mimic: " + ", ".join(f"{f} follows {m.leader}"
                                                 for f, m in self._followers.items()))  # fmt: skip
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


class RobotState:
    """Kinematics of a robot at one configuration (a view of the robot's Pinocchio data).

    Returned by :meth:`Robot.update`. Jacobians are computed once per frame and cached;
    the arrays returned are read-only views of that cache (fresh arrays per state: a
    Jacobian read from an older state keeps its values). The view is invalidated by the
    next :meth:`Robot.update`; using it afterwards raises :class:`WholebodyError`.

    :meth:`prefetch` (or :meth:`jacobians`) computes the Jacobians of many frames at once,
    with one product with the actuation matrix instead of one per frame; a
    :class:`~wholebody.solvers.Stack` prefetches the frames its entries declare before
    evaluating them.
    """

    __slots__ = ("_block", "_cache", "_order", "_rows", "_version", "q", "robot")

    def __init__(self, robot: Robot, q: np.ndarray, version: int) -> None:
        self.robot = robot
        self.q = q.copy()
        self.q.setflags(write=False)
        self._version = version
        self._cache: dict[object, np.ndarray] = {}
        self._block: np.ndarray | None = None  # the (F, 6, nu) Jacobians of prefetch()
        self._rows: dict[int, int] = {}  # frame index -> its first position in _block
        self._order: list[int] = []  # the frame index at each position of _block

    def _data(self) -> pin.Data:
        if self._version != self.robot._version:
            raise WholebodyError(
                "this RobotState is stale: Robot.update() was called again since it was "
                "made; keep using the newest state"
            )
        return self.robot.data

    def placement(self, frame: Frame) -> pin.SE3:
        """The frame's world placement as a ``pinocchio.SE3`` (a copy)."""
        return pin.SE3(self._data().oMf[frame.index])

    def pose(self, frame: Frame) -> np.ndarray:
        """4x4 world pose of ``frame``."""
        return self._data().oMf[frame.index].homogeneous

    def position(self, frame: Frame) -> np.ndarray:
        """World position (m) of the frame origin."""
        return self._data().oMf[frame.index].translation.copy()

    def rotation(self, frame: Frame) -> np.ndarray:
        """3x3 world orientation of the frame."""
        return self._data().oMf[frame.index].rotation.copy()

    def rotation_translation(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """The frame's world rotation (3x3) and position (3,) **without a copy**: views of the
        robot's data, overwritten by the next :meth:`Robot.update`; read, never write, them
        (for the control loop; :meth:`rotation` and :meth:`position` return copies)."""
        M = self._data().oMf[frame.index]
        return M.rotation, M.translation

    def jacobian(self, frame: Frame) -> np.ndarray:
        """6 x nu Jacobian (world-aligned axes at the frame origin, linear rows first)."""
        J = self._cache.get(frame.index)
        if J is None:
            k = self._rows.get(frame.index)
            if k is not None:  # in prefetch()'s block
                return self._block[k]
            robot = self.robot
            Jm = pin.getFrameJacobian(robot.model, self._data(), frame.index, LWA)
            J = Jm.dot(robot.actuation)
            J.setflags(write=False)
            self._cache[frame.index] = J
        return J

    def prefetch(self, frames: Sequence[Frame]) -> None:
        """Compute and cache the Jacobians of ``frames`` not cached yet, in one batch.

        The same numbers as :meth:`jacobian` frame by frame: Pinocchio's frame Jacobians
        stacked into one (6F x nv) array and multiplied by the actuation matrix once. On a
        fresh state the batch is kept as one (F, 6, nu) block in the order of ``frames``
        (repeats allowed), so that :meth:`jacobians` of a run of consecutive frames of it is
        a view, not a copy.
        """
        cache, rows = self._cache, self._rows
        missing = [f.index for f in frames if f.index not in cache and f.index not in rows]
        if not missing:
            return
        robot = self.robot
        model, data = robot.model, self._data()
        if len(missing) == 1:
            J = pin.getFrameJacobian(model, data, missing[0], LWA).dot(robot.actuation)
            J.setflags(write=False)
            cache[missing[0]] = J
            return
        get = pin.getFrameJacobian
        Jm = np.concatenate([get(model, data, i, LWA) for i in missing])
        J = Jm.dot(robot.actuation).reshape(len(missing), 6, robot.nu)
        J.setflags(write=False)
        if self._block is None:  # jacobian() reads the block (no per-frame cache entries)
            key = tuple(missing)
            rows = robot._layouts.get(key)
            if rows is None:  # first position of each frame, per layout (few per robot)
                rows = robot._layouts[key] = {i: k for k, i in reversed(list(enumerate(key)))}
            self._block, self._order, self._rows = J, missing, rows
            return
        for k, i in enumerate(missing):
            cache.setdefault(i, J[k])

    def jacobians(self, frames: Sequence[Frame]) -> np.ndarray:
        """(F, 6, nu) Jacobians of ``frames`` stacked (see :meth:`jacobian`), read-only.

        A view of :meth:`prefetch`'s block when the frames are consecutive in it; otherwise
        cached per tuple of frames, the frames not cached yet computed in one batch.
        """
        block = self._run(frames)
        if block is not None:
            return block
        key = ("stack", *(f.index for f in frames))
        block = self._cache.get(key)
        if block is None:
            self.prefetch(frames)
            block = self._run(frames)  # a fresh state: prefetch() made them one block
            if block is not None:
                return block
            block = np.stack([self.jacobian(f) for f in frames])
            block.setflags(write=False)
            self._cache[key] = block
        return block

    def _run(self, frames: Sequence[Frame]) -> np.ndarray | None:
        """The frames' Jacobians as a view of prefetch()'s block if they are consecutive
        in it, else None."""
        if self._block is None or not frames:
            return None
        ids = [f.index for f in frames]
        k0 = self._rows.get(ids[0], -1)
        if k0 >= 0 and self._order[k0 : k0 + len(ids)] == ids:
            return self._block[k0 : k0 + len(ids)]
        return None

    def world_jacobian(self, frame: Frame) -> np.ndarray:
        """6 x nv model Jacobian in Pinocchio's ``WORLD`` convention (spatial velocity at
        the world origin), model velocity columns (not actuated)."""
        key = ("world", frame.index)
        J = self._cache.get(key)
        if J is None:
            J = pin.getFrameJacobian(self.robot.model, self._data(), frame.index, WORLD)
            J.setflags(write=False)
            self._cache[key] = J
        return J

    def com_position(self, body: Body) -> np.ndarray:
        """World position (m) of the body's centre of mass."""
        M = self._data().oMf[body.frame.index]
        return M.translation + M.rotation @ body.com

    def com_jacobian(self, body: Body) -> np.ndarray:
        """3 x nu Jacobian of the body's centre of mass (world axes)."""
        J = self.jacobian(body.frame)
        rx, ry, rz = self._data().oMf[body.frame.index].rotation @ body.com
        # v_com = v_o + w x r = v_o - [r]x w
        return J[:3] - np.array([[0.0, -rz, ry], [rz, 0.0, -rx], [-ry, rx, 0.0]]) @ J[3:]

    def memo(self, key: str, compute: Callable[[RobotState], T]) -> T:
        """``compute(self)``, computed once per state and cached under ``key`` (for values
        that several tasks derive from the same state; ``key`` must name what ``compute``
        returns, and the result must not be modified)."""
        value = self._cache.get(key)
        if value is None:
            value = self._cache[key] = compute(self)
        return value

    def joint_positions(self) -> np.ndarray:
        """Scalar position per actuated velocity (see :meth:`Robot.joint_positions`)."""
        jp = self._cache.get("joint_positions")
        if jp is None:
            jp = self.robot.joint_positions(self.q)
            jp.setflags(write=False)
            self._cache["joint_positions"] = jp
        return jp


# ---------------------------------------------------------------------- helpers
def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """``idx`` as an equivalent slice when it is an arithmetic run (step >= 1), else itself."""
    k = idx.tolist()
    if not k:
        return slice(0, 0)
    step = k[1] - k[0] if len(k) > 1 else 1
    if step >= 1 and k == list(range(k[0], k[-1] + 1, step)):
        return slice(k[0], k[-1] + 1, step)
    return idx


class _Named(dict):
    """A dict of named parts (arms, groups) whose missing key says what there is."""

    def __init__(self, kind: str, items: Mapping[str, object]) -> None:
        super().__init__(items)
        self.kind = kind

    def __missing__(self, key: object) -> object:
        raise KeyError(f"no {self.kind} {key!r}" + _suggest(key, self))


def _abridged(names: list[str], most: int = 6) -> str:
    """At most ``most`` names, then how many more."""
    more = len(names) - most
    return ", ".join(names[:most]) + (f" and {more} more" if more > 0 else "")


def _not_actuated(name: str, locked: Mapping[str, float], followers: Mapping[str, object],
                  known: Mapping[str, int]) -> str:  # fmt: skip
    """Why ``name`` cannot be given a position: locked, a mimic joint, or unknown."""
    if name in locked:
        return f"{name!r} is locked at {locked[name]:g} ([locked] of robot.toml)"
    if name in followers:
        return f"{name!r} is a mimic joint: give its leader {followers[name].leader!r}"  # type: ignore[attr-defined]
    return f"{name!r} is not a joint of the robot" + _suggest(name, known)


def _suggest(name: object, candidates) -> str:
    """Up to three close matches, or the candidates themselves when none is close."""
    names = [str(c) for c in candidates]
    close = difflib.get_close_matches(str(name), names, n=3)
    if close:
        return f" (did you mean {', '.join(repr(c) for c in close)}?)"
    return f"; known: {', '.join(names)}" if names else ""
