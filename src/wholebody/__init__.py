"""wholebody: whole-body control of highly redundant mobile humanoids."""

from __future__ import annotations

from wholebody.errors import (
    ConfigError,
    DataError,
    DimensionError,
    FrameError,
    IntegrationError,
    ModelError,
    SolverError,
    WholebodyError,
)
from wholebody.robot import Frame, Robot, RobotState, available_robots, load_robot

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "DataError",
    "DimensionError",
    "Frame",
    "FrameError",
    "IntegrationError",
    "ModelError",
    "Robot",
    "RobotState",
    "SolverError",
    "WholebodyError",
    "__version__",
    "available_robots",
    "load_robot",
]
