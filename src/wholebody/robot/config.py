"""``robot.toml``: what a URDF does not say about a robot.

A robot directory holds ``robot.urdf`` and ``robot.toml``. The TOML names the joint groups,
the arm chains (the frames and bodies of the arm energy and arm angle), the base type and
its parameters, and a home posture. Nothing in wholebody's code names a joint or frame of a
particular robot: another robot is another ``robot.toml``.

Schema (every key is checked; unknown keys are errors, to catch typos)::

    format = 1                   # required, first: the format this file is written for
                                 # (wholebody.formats)

    [robot]
    name = "my_robot"            # required
    urdf = "robot.urdf"          # required, relative to this file, or a ROS package path
                                 # "package://PKG/..." (see wholebody.robot.urdf)
    description = "..."          # optional
    package_dirs = ["..."]       # optional: directories holding ROS packages (relative to
                                 # this file), searched first for package:// paths

    [base]                       # optional; default type = "fixed"; wheels are URDF
                                 # joints of the root link turning about its +y or -y
                                 # axis (x forward, z up); a differential base's two
                                 # wheels share one axle, anywhere along x
    type = "fixed" | "mecanum" | "differential" | "planar" | "swerve" | "floating"
    height = 0.0                 # m, any type but floating: the root link's origin above the
                                 # floor (z); the root (a pelvis, a base's centre) is placed
                                 # there for kinematics, collision, drawing and physics
                                 # (default 0; a floating base stands on its lowest frame)
    wheels = [...]               # mecanum: 4 joints FL, FR, RL, RR; differential: left, right
    wheel_radius = 0.08          # m, mecanum and differential (checked to 1 % against the
                                 # wheels' cylinder, sphere or mesh in the URDF)
    wheel_base = 0.50            # m, front-rear axle distance, mecanum
    track = 0.44                 # m, left-right wheel distance, mecanum and differential
    max_linear_velocity = 1.0    # m/s, planar, swerve, floating (default 1.0)
    max_angular_velocity = 1.0   # rad/s, planar, swerve, floating (default 1.0)
    modules = [                  # swerve: one table per steered wheel (wholebody.robot.swerve)
      { steering = "<joint>", drive = "<joint>", wheel_radius = 0.124 },
    ]

    [groups]                     # optional; a joint belongs to at most one group
    name = ["joint", ...]

    [arms.<name>]                # optional, any number
    side = "left" | "right"      # mirrors the arm angle (a single arm: either)
    group = "<group name>"       # optional
    shoulder = elbow = wrist = tool = "<frame>"   # the first three at joint centres
                                 # (checked; `wholebody info DIR --suggest-frames` prints
                                 # [frames] entries placing them there)
    upper_arm = forearm = "<link>"   # or a list of links: a segment whose mass is split
                                     # over several links (the arm energy adds them all)

    [locked]                     # optional: joints removed from the model, held at a
                                 # position (Pinocchio's reduced model): casters, fingers,
                                 # suspensions, legs. Key: a joint name, a glob pattern
    "caster_*" = 0.0             # (fnmatch) or a [groups] name (the group goes with it);
    "arm_left_4_joint" = 0.5     # value: the position (rad, m). A mimic joint whose leader
                                 # is locked is locked with it.

    [joints.<name>]              # optional: the URDF's data of a moving joint overridden
    type = "continuous"          # (a joint name or a glob pattern), so that a URDF fault
    lower = -1.0                 # needs no edit of the URDF: type "revolute", "continuous"
    upper = 1.0                  # (no position limits) or "prismatic"; position limits
    velocity = 2.0               # lower < upper (rad, m), velocity (rad/s, m/s) and effort
    effort = 30.0                # (N m, N) > 0. E.g. a wheel declared revolute without
                                 # limits (read as [0, 0]): type = "continuous"

    [frames.<name>]              # optional: a frame of your own, usable wherever a frame
    parent = "<link or joint>"   # name is (arm chains, tasks)
    xyz = [0.0, 0.0, 0.0]        # m, in the parent's frame (default 0)
    rpy = [0.0, 0.0, 0.0]        # rad, roll-pitch-yaw as in URDF (default 0)

    [home]                       # optional; joint = angle (rad), others at 0 (or at
                                 # the nearer limit when 0 is outside their range)

    [sim]                        # optional: physics runs (wholebody.sim); any of the
    servo_hz = 25.0              # fields of wholebody.robot.sim.SimSettings (timestep s,
    armature = 0.01              # servo_hz Hz, damping_ratio, armature kg m^2, damping
                                 # N m s/rad, effort_scale, gravity_compensation,
                                 # stall_time s, base_force N, base_torque N m)

    [acceleration]               # optional; the hard bound |u - u_prev| <= a dt of
                                 # wholebody.tasks.AccelerationLimits
    joints = 20.0                # rad/s^2 (m/s^2 prismatic), default 20
    wheels = 40.0                # rad/s^2, the base's wheels, default 40
    base_linear = 2.0            # m/s^2, planar, swerve, floating base, default 2
    base_angular = 4.0           # rad/s^2, planar, swerve, floating base, default 4
    waist = 5.0                  # any group or joint name: its own (a joint's wins)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from wholebody.errors import ConfigError, ModelError
from wholebody.formats import FORMAT_KEY, ROBOT, check_format
from wholebody.robot.sim import SimSettings
from wholebody.robot.urdf import PACKAGE, resolve_package
from wholebody.tomlreader import TomlReader as _Reader
from wholebody.tomlreader import config_error, load_toml

__all__ = [
    "ACCELERATION_DEFAULTS",
    "ArmConfig",
    "BaseConfig",
    "FrameConfig",
    "JointOverride",
    "RobotConfig",
    "SwerveModuleConfig",
    "read_robot_config",
]

ACCELERATION_DEFAULTS: Mapping[str, float] = {
    "joints": 20.0,  # rad/s^2 (m/s^2 prismatic): inside the 15-40 of common cobots
    "wheels": 40.0,  # rad/s^2: 3.2 m/s^2 at the rim of the humanoid's 0.08 m wheels
    "base_linear": 2.0,  # m/s^2
    "base_angular": 4.0,  # rad/s^2
}
"""The acceleration limits of the classes of ``u`` that ``[acceleration]`` does not set."""

BaseType = Literal["fixed", "mecanum", "differential", "planar", "swerve", "floating"]
BASE_TYPES: tuple[str, ...] = ("fixed", "mecanum", "differential", "planar", "swerve", "floating")
ARM_FRAME_KEYS = ("shoulder", "elbow", "wrist", "tool")
ARM_BODY_KEYS = ("upper_arm", "forearm")


@dataclass(frozen=True)
class BaseConfig:
    """The mobile base: its type and parameters (SI units)."""

    type: BaseType = "fixed"
    wheels: tuple[str, ...] = ()
    wheel_radius: float = 0.0
    wheel_base: float = 0.0
    track: float = 0.0
    max_linear_velocity: float = 1.0
    max_angular_velocity: float = 1.0
    height: float = 0.0
    """The root link's origin above the floor (m)."""
    modules: tuple[SwerveModuleConfig, ...] = ()
    """A swerve base's steered wheels."""


@dataclass(frozen=True)
class SwerveModuleConfig:
    """One steered wheel of a swerve base: its steering joint (about the base's z), its
    drive joint (the wheel's spin) and the wheel radius (m)."""

    steering: str
    drive: str
    wheel_radius: float


JOINT_TYPES = ("revolute", "continuous", "prismatic")
"""The types ``[joints]`` may give a moving joint."""


@dataclass(frozen=True)
class JointOverride:
    """``[joints.<key>]``: what replaces the URDF's data of the joints ``key`` names (a name
    or a glob pattern); None where the URDF's stays. SI units: rad or m, rad/s or m/s,
    N m or N."""

    key: str
    type: str | None = None
    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    effort: float | None = None


@dataclass(frozen=True)
class ArmConfig:
    """One arm chain: frame names at the joint centres and tool, and the links of its two
    segments (one or more each)."""

    name: str
    side: Literal["left", "right"]
    shoulder: str
    elbow: str
    wrist: str
    tool: str
    upper_arm: tuple[str, ...]
    forearm: tuple[str, ...]
    group: str | None = None


@dataclass(frozen=True)
class FrameConfig:
    """A frame declared in ``[frames]``: its parent link or joint and its placement there
    (m; roll-pitch-yaw, rad)."""

    name: str
    parent: str
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class CollisionConfig:
    """``[collision]``: links whose collision shapes are replaced by one bounding
    ``"capsule"`` or ``"sphere"`` (``shapes``; the key ``"*"`` for every other link,
    ``"urdf"`` to keep a link's own), and pairs of links or shapes never checked
    (``exclude``); see :mod:`wholebody.collision`."""

    shapes: Mapping[str, str] = field(default_factory=dict)
    exclude: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class RobotConfig:
    """The parsed, schema-checked content of a ``robot.toml`` (not yet checked against
    the URDF; :class:`wholebody.Robot` does that)."""

    path: Path
    name: str
    urdf: Path
    description: str = ""
    base: BaseConfig = field(default_factory=BaseConfig)
    groups: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    arms: Mapping[str, ArmConfig] = field(default_factory=dict)
    home: Mapping[str, float] = field(default_factory=dict)
    acceleration: Mapping[str, float] = field(default_factory=dict)
    """``[acceleration]`` as written (rad/s^2, m/s^2); :attr:`Robot.acceleration_limits`
    resolves it with the defaults :data:`ACCELERATION_DEFAULTS`."""
    package_dirs: tuple[Path, ...] = ()
    """``[robot] package_dirs``, absolute."""
    locked: Mapping[str, float] = field(default_factory=dict)
    """``[locked]`` as written: joint name, glob pattern or group -> position (rad, m)."""
    frames: Mapping[str, FrameConfig] = field(default_factory=dict)
    """``[frames]``."""
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    """``[collision]``."""
    sim: Mapping[str, float | bool] = field(default_factory=dict)
    """``[sim]`` as written: :class:`~wholebody.robot.sim.SimSettings` by name."""
    joints: tuple[JointOverride, ...] = ()
    """``[joints]``, in the file's order (:mod:`wholebody.robot.overrides`)."""

    def error(self, key: str, message: str) -> ConfigError:
        """A :class:`ConfigError` naming this file and ``key``."""
        return config_error(self.path, key, message)


def read_robot_config(path: str | Path) -> RobotConfig:
    """Read and schema-check a ``robot.toml``.

    Raises
    ------
    ConfigError
        If the file is missing, not valid TOML, or breaks the schema; the message names
        the file, the key and what was expected.
    """
    path = Path(path)
    r = _Reader(path)
    data = load_toml(path, "robot configuration")
    check_format(r, data, ROBOT)

    r.only(
        data,
        "",
        (
            FORMAT_KEY,
            "robot",
            "base",
            "groups",
            "arms",
            "home",
            "acceleration",
            "locked",
            "frames",
            "collision",
            "sim",
            "joints",
        ),
    )
    robot = r.table(data, "robot", "", required=True)
    r.only(robot, "robot", ("name", "urdf", "description", "package_dirs"))
    name = r.string(robot, "name", "robot")
    package_dirs = (
        tuple(path.parent / d for d in r.names(robot, "package_dirs", "robot"))
        if "package_dirs" in robot
        else ()
    )
    urdf = _urdf_path(r, path, r.string(robot, "urdf", "robot"), package_dirs)
    description = r.string(robot, "description", "robot", default="")

    base = _read_base(r, r.table(data, "base", "", required=False))

    groups: dict[str, tuple[str, ...]] = {}
    owner: dict[str, str] = {}
    for gname in r.table(data, "groups", "", required=False):
        joints = r.names(data["groups"], gname, "groups")
        for j in joints:
            if j in owner:
                raise r.fail(
                    f"groups.{gname}",
                    f"joint {j!r} is already in group "
                    f"{owner[j]!r}: a joint belongs to at most one group",
                )
            owner[j] = gname
        groups[gname] = joints

    arms: dict[str, ArmConfig] = {}
    for aname, table in r.table(data, "arms", "", required=False).items():
        where = f"arms.{aname}"
        if not isinstance(table, dict):
            raise r.fail(where, f"expected a table, got {type(table).__name__}")
        r.only(table, where, ("side", "group", *ARM_FRAME_KEYS, *ARM_BODY_KEYS))
        group = r.string(table, "group", where) if "group" in table else None
        if group is not None and group not in groups:
            raise r.fail(
                f"{where}.group",
                f"unknown group {group!r}; defined groups: {', '.join(groups) or '(none)'}",
            )
        arms[aname] = ArmConfig(
            name=aname,
            side=r.string(table, "side", where, choices=("left", "right")),  # type: ignore[arg-type]
            group=group,
            **{k: r.string(table, k, where) for k in ARM_FRAME_KEYS},
            **{k: _links(r, table, k, where) for k in ARM_BODY_KEYS},
        )

    home: dict[str, float] = {}
    for joint in r.table(data, "home", "", required=False):
        home[joint] = r.number(data["home"], joint, "home")
    acceleration = {
        key: r.number(data["acceleration"], key, "acceleration", positive=True)
        for key in r.table(data, "acceleration", "", required=False)
    }
    locked = {
        key: r.number(data["locked"], key, "locked")
        for key in r.table(data, "locked", "", required=False)
    }
    frames = {
        fname: _frame(r, fname, table)
        for fname, table in r.table(data, "frames", "", required=False).items()
    }

    collision = _read_collision(r, r.table(data, "collision", "", required=False))
    overrides = r.table(data, "joints", "", required=False)
    joints = tuple(_joint_override(r, key, table) for key, table in overrides.items())
    return RobotConfig(
        joints=joints,
        collision=collision,
        sim=_read_sim(r, r.table(data, "sim", "", required=False)),
        path=path,
        name=name,
        urdf=urdf,
        description=description,
        base=base,
        groups=groups,
        arms=arms,
        home=home,
        acceleration=acceleration,
        package_dirs=package_dirs,
        locked=locked,
        frames=frames,
    )


def _read_sim(r: _Reader, table: Mapping[str, Any]) -> dict[str, float | bool]:
    """``[sim]``: :class:`wholebody.robot.sim.SimSettings` by name (each checked there)."""
    r.only(table, "sim", SimSettings.keys())
    out: dict[str, float | bool] = {}
    for key in table:
        if key == "gravity_compensation":
            out[key] = r.boolean(table, key, "sim", default=True)
        else:
            out[key] = r.number(table, key, "sim")
    try:
        SimSettings(**out)  # type: ignore[arg-type]
    except ModelError as exc:
        raise r.fail("sim", str(exc)) from None
    return out


def _read_collision(r: _Reader, table: Mapping[str, Any]) -> CollisionConfig:
    r.only(table, "collision", ("shapes", "exclude"))
    shapes = {
        link: r.string(
            table["shapes"], link, "collision.shapes", choices=("capsule", "sphere", "urdf")
        )
        for link in r.table(table, "shapes", "collision", required=False)
    }
    pairs = table.get("exclude", [])
    ok = isinstance(pairs, list) and all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(n, str) for n in p) for p in pairs
    )
    if not ok:
        raise r.fail(
            "collision.exclude",
            'expected a list of pairs of link or shape names, e.g. [["torso", "left_forearm"]]',
        )
    return CollisionConfig(shapes, tuple((a, b) for a, b in pairs))


def _urdf_path(r: _Reader, path: Path, value: str, package_dirs: tuple[Path, ...]) -> Path:
    """The URDF file: relative to the robot.toml, or a ``package://`` path resolved."""
    if value.startswith(PACKAGE):
        try:
            return resolve_package(value, package_dirs)
        except FileNotFoundError as exc:
            raise r.fail("robot.urdf", str(exc)) from None
    urdf = path.parent / value
    if not urdf.is_file():
        raise r.fail(
            "robot.urdf",
            f"file {urdf} does not exist: expected a URDF path relative "
            "to the robot.toml or a package:// path",
        )
    return urdf


def _links(r: _Reader, table: Mapping[str, Any], key: str, where: str) -> tuple[str, ...]:
    """A segment's link: a name, or a non-empty list of names."""
    if isinstance(table.get(key), list):
        names = r.names(table, key, where)
        if not names:
            raise r.fail(f"{where}.{key}", "expected a link name or a non-empty list of them")
        return names
    return (r.string(table, key, where),)


def _frame(r: _Reader, name: str, table: Any) -> FrameConfig:
    where = f"frames.{name}"
    if not isinstance(table, dict):
        raise r.fail(where, f"expected a table (parent, xyz, rpy), got {type(table).__name__}")
    r.only(table, where, ("parent", "xyz", "rpy"))
    xyz = r.vector(table, "xyz", where, 3, default=(0.0, 0.0, 0.0))
    rpy = r.vector(table, "rpy", where, 3, default=(0.0, 0.0, 0.0))
    return FrameConfig(name, r.string(table, "parent", where), xyz, rpy)  # type: ignore[arg-type]


def _joint_override(r: _Reader, key: str, table: Any) -> JointOverride:
    """``[joints.<key>]``, each value checked; ``lower < upper`` when both are given, and no
    position limit for a continuous joint."""
    where = f"joints.{key}"
    if not isinstance(table, dict) or not table:
        raise r.fail(
            where,
            "expected a table of type, lower, upper, velocity, effort, e.g. "
            f'[joints.{key}] type = "continuous"',
        )
    r.only(table, where, ("type", "lower", "upper", "velocity", "effort"))
    kind = r.string(table, "type", where, choices=JOINT_TYPES) if "type" in table else None
    lower, upper, velocity, effort = (
        r.number(table, k, where, positive=k in ("velocity", "effort")) if k in table else None
        for k in ("lower", "upper", "velocity", "effort")
    )
    if kind == "continuous" and (lower is not None or upper is not None):
        raise r.fail(
            where,
            "a continuous joint turns without position limits: give lower "
            'and upper with type = "revolute"',
        )
    if lower is not None and upper is not None and not lower < upper:
        raise r.fail(where, f"lower = {lower:g} must be below upper = {upper:g}")
    return JointOverride(key, kind, lower, upper, velocity, effort)


def _read_base(r: _Reader, table: Mapping[str, Any]) -> BaseConfig:
    if not table:
        return BaseConfig()
    kind = r.string(table, "type", "base", choices=BASE_TYPES)
    height = r.number(table, "height", "base", default=0.0)
    base = _base_of_type(r, table, kind)
    return replace(base, height=height) if height else base


def _base_of_type(r: _Reader, table: Mapping[str, Any], kind: str) -> BaseConfig:
    """``[base]``'s keys of a base type (and ``height``, read by :func:`_read_base`)."""
    if kind == "fixed":
        r.only(table, "base", ("type", "height"))
        return BaseConfig()
    if kind in ("planar", "floating"):
        keys = ("type", "max_linear_velocity", "max_angular_velocity")
        r.only(table, "base", keys if kind == "floating" else (*keys, "height"))
        return BaseConfig(
            type=kind,  # type: ignore[arg-type]
            max_linear_velocity=r.number(table, "max_linear_velocity", "base", 1.0, True),
            max_angular_velocity=r.number(table, "max_angular_velocity", "base", 1.0, True),
        )
    if kind == "swerve":
        return _read_swerve(r, table)
    if kind == "mecanum":
        r.only(table, "base", ("type", "height", "wheels", "wheel_radius", "wheel_base", "track"))
        return BaseConfig(
            type="mecanum",
            wheels=r.names(table, "wheels", "base", count=4),
            wheel_radius=r.number(table, "wheel_radius", "base", positive=True),
            wheel_base=r.number(table, "wheel_base", "base", positive=True),
            track=r.number(table, "track", "base", positive=True),
        )
    r.only(table, "base", ("type", "height", "wheels", "wheel_radius", "track"))
    return BaseConfig(
        type="differential",
        wheels=r.names(table, "wheels", "base", count=2),
        wheel_radius=r.number(table, "wheel_radius", "base", positive=True),
        track=r.number(table, "track", "base", positive=True),
    )


def _read_swerve(r: _Reader, table: Mapping[str, Any]) -> BaseConfig:
    """``[base] type = "swerve"``: the twist limits and at least two modules."""
    r.only(
        table, "base", ("type", "height", "modules", "max_linear_velocity", "max_angular_velocity")
    )
    modules = table.get("modules")
    if not isinstance(modules, list) or len(modules) < 2:
        raise r.fail(
            "base.modules",
            "expected a list of at least two tables "
            '{ steering = "<joint>", drive = "<joint>", wheel_radius = <m> }',
        )
    out = []
    for k, m in enumerate(modules):
        where = f"base.modules[{k}]"
        if not isinstance(m, dict):
            raise r.fail(where, f"expected a table, got {type(m).__name__}")
        r.only(m, where, ("steering", "drive", "wheel_radius"))
        out.append(
            SwerveModuleConfig(
                r.string(m, "steering", where),
                r.string(m, "drive", where),
                r.number(m, "wheel_radius", where, positive=True),
            )
        )
    joints = [j for m in out for j in (m.steering, m.drive)]
    if len(set(joints)) != len(joints):
        raise r.fail("base.modules", "a joint appears twice among the modules' joints")
    return BaseConfig(
        type="swerve",
        modules=tuple(out),
        max_linear_velocity=r.number(table, "max_linear_velocity", "base", 1.0, True),
        max_angular_velocity=r.number(table, "max_angular_velocity", "base", 1.0, True),
    )
