"""Robot models: Pinocchio kinematics in the actuated velocity space, groups, limits, arms.

* :mod:`~wholebody.robot.robot` -- :class:`Robot`: loading, names, :meth:`Robot.update`.
* :mod:`~wholebody.robot.state` -- :class:`RobotState`: poses, Jacobians and centres of mass
  at one configuration.
* :mod:`~wholebody.robot.configurations` -- making, checking and reading configurations ``q``.
* :mod:`~wholebody.robot.actuation` -- the actuated velocity space ``u`` and ``v = A u``.
* :mod:`~wholebody.robot.com` -- the whole-body centre of mass and its Jacobian.
* :mod:`~wholebody.robot.parts` -- :class:`Frame`, :class:`Body`, :class:`JointGroup`,
  :class:`ArmChain`.
* :mod:`~wholebody.robot.arms` -- arm chains from ``[arms]``, their geometry checked;
  :mod:`~wholebody.robot.centres` -- joint centres for arm frames that are not.
* :mod:`~wholebody.robot.base`, :mod:`~wholebody.robot.wheels` -- mobile bases and their
  wheels.
* :mod:`~wholebody.robot.config`, :mod:`~wholebody.robot.urdf`,
  :mod:`~wholebody.robot.building` -- ``robot.toml``, the URDF and the model built from them;
  :mod:`~wholebody.robot.overrides` -- ``[joints]``, the URDF's joint data overridden.
* :mod:`~wholebody.robot.compiled`, :mod:`~wholebody.robot.hessian` -- what the compiled core
  reads; kinematic Hessians.
"""

from __future__ import annotations

from pathlib import Path

from wholebody.errors import ConfigError
from wholebody.resources import robots_dir
from wholebody.robot.base import BaseModel
from wholebody.robot.config import ArmConfig, BaseConfig, RobotConfig, read_robot_config
from wholebody.robot.parts import ArmChain, Body, Frame, JointGroup
from wholebody.robot.robot import Robot
from wholebody.robot.state import RobotState

__all__ = [
    "ArmChain",
    "ArmConfig",
    "BaseConfig",
    "BaseModel",
    "Body",
    "Frame",
    "JointGroup",
    "Robot",
    "RobotConfig",
    "RobotState",
    "available_robots",
    "load_robot",
    "read_robot_config",
    "robot_catalogue",
    "robot_toml",
]


def available_robots() -> list[str]:
    """Names of the robots that ship with wholebody (some need an extra: see
    :func:`robot_catalogue`)."""
    root = robots_dir()
    return sorted(p.parent.name for p in root.glob("*/robot.toml"))


def robot_catalogue() -> list[tuple[str, str, bool]]:
    """Every bundled robot as ``(name, description, available)``: unavailable ones (their
    URDF is in a package that is not installed) have the reason and the install command as
    description."""
    out = []
    for name in available_robots():
        try:
            config = read_robot_config(robots_dir() / name / "robot.toml")
        except ConfigError as exc:
            out.append((name, str(exc).split(": ", 1)[-1], False))
        else:
            out.append((name, config.description, True))
    return out


def load_robot(name_or_path: str | Path) -> Robot:
    """Load a robot by bundled name (``"mobile_humanoid"``), robot directory or ``robot.toml``.

    A directory holding a ``robot.toml`` is loaded even where a bundled robot has its name;
    a bare name whose directory has none (or does not exist) is the bundled robot.

    Raises
    ------
    ConfigError
        Unknown name, missing files, or a malformed/inconsistent ``robot.toml``.
    ModelError
        A URDF that cannot be loaded.
    """
    return Robot(read_robot_config(robot_toml(name_or_path)))


def robot_toml(name_or_path: str | Path) -> Path:
    """The ``robot.toml`` that :func:`load_robot` reads for ``name_or_path`` (a
    :class:`ConfigError` as it raises)."""
    if not isinstance(name_or_path, (str, Path)) or not str(name_or_path):
        raise ConfigError(
            f"load_robot: expected a bundled robot name "
            f"({', '.join(available_robots()) or 'none installed'}), a robot "
            f"directory or a robot.toml path, got {name_or_path!r}"
        )
    path = Path(name_or_path)
    if path.suffix == ".toml":
        return path
    toml = path / "robot.toml"
    if toml.is_file():
        return toml
    bundled = robots_dir() / path.name / "robot.toml"
    if len(path.parts) == 1 and bundled.is_file():  # a name, as a str or a one-part Path
        # (a directory of that name without a robot.toml, e.g. a scenario's output, does not
        # hide the bundled robot)
        return bundled
    if path.is_dir():
        raise ConfigError(f"{path}: robot directory has no robot.toml")
    raise ConfigError(
        f"no robot {str(name_or_path)!r}: expected a bundled robot name "
        f"({', '.join(available_robots()) or 'none installed'}), a robot directory or a "
        "robot.toml path"
    )
