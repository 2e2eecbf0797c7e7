"""wholebody: whole-body control of highly redundant robots.

What a user composes is here, as ``import wholebody as wb``::

    robot = wb.load_robot("mobile_humanoid")
    hand = wb.FrameTask(robot, "right_tool", kp=10.0)
    stack = wb.Stack(robot, [[hand], [wb.PostureTask(robot)]],
                     [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)])
    u = wb.ProjectionSolver().solve(stack, robot.update(q), dt=0.01).u

Names are imported on first use (PEP 562), so ``import wholebody`` and the command line stay
fast; the modules (``wholebody.tasks``, ``wholebody.solvers``, ``wholebody.control``,
``wholebody.planning``, ...) hold the rest.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

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

__version__ = "0.1.0"

_LAZY: dict[str, str] = {
    # the robot
    "Frame": "wholebody.robot",
    "Robot": "wholebody.robot",
    "RobotState": "wholebody.robot",
    "available_robots": "wholebody.robot",
    "load_robot": "wholebody.robot",
    # tasks, objectives, limits
    "Task": "wholebody.tasks",
    "TaskRows": "wholebody.tasks",
    "Objective": "wholebody.tasks",
    "ObjectiveValue": "wholebody.tasks",
    "Limit": "wholebody.tasks",
    "Bounds": "wholebody.tasks",
    "FrameTask": "wholebody.tasks",
    "RelativeFrameTask": "wholebody.tasks",
    "RelativePositionTask": "wholebody.tasks",
    "PostureTask": "wholebody.tasks",
    "FrameHalfSpace": "wholebody.tasks",
    "ArmPotentialEnergy": "wholebody.tasks",
    "HumanArmAngle": "wholebody.tasks",
    "CollisionAvoidance": "wholebody.tasks",
    "ComTask": "wholebody.tasks",
    "CollisionModel": "wholebody.collision",
    "Obstacle": "wholebody.collision",
    "HumanArmAngleTask": "wholebody.tasks",
    "ArmAngleSpring": "wholebody.tasks",
    "JointLimitAvoidance": "wholebody.tasks",
    "Manipulability": "wholebody.tasks",
    "JointPositionLimits": "wholebody.tasks",
    "VelocityLimits": "wholebody.tasks",
    "AccelerationLimits": "wholebody.tasks",
    # stacks and solvers
    "Level": "wholebody.solvers",
    "Stack": "wholebody.solvers",
    "ProjectionSolver": "wholebody.solvers",
    "HierarchicalQPSolver": "wholebody.solvers",
    "SolverResult": "wholebody.solvers",
    "SolverStatus": "wholebody.solvers",
    # the control loop
    "Controller": "wholebody.control",
    "RunLog": "wholebody.control",
    "StallRecovery": "wholebody.control",
    # trajectories and planning
    "Trajectory": "wholebody.planning",
    "MinimumJerkTrajectory": "wholebody.planning",
    "HoldTrajectory": "wholebody.planning",
    "DMP": "wholebody.planning",
    # the paper's stack
    "paper_stack": "wholebody.presets",
    "PaperWeights": "wholebody.presets",
}

__all__ = [
    "DMP",
    "AccelerationLimits",
    "ArmAngleSpring",
    "ArmPotentialEnergy",
    "Bounds",
    "CollisionAvoidance",
    "CollisionModel",
    "ComTask",
    "ConfigError",
    "Controller",
    "DataError",
    "DimensionError",
    "Frame",
    "FrameError",
    "FrameHalfSpace",
    "FrameTask",
    "HierarchicalQPSolver",
    "HoldTrajectory",
    "HumanArmAngle",
    "HumanArmAngleTask",
    "IntegrationError",
    "JointLimitAvoidance",
    "JointPositionLimits",
    "Level",
    "Limit",
    "Manipulability",
    "MinimumJerkTrajectory",
    "ModelError",
    "Objective",
    "ObjectiveValue",
    "Obstacle",
    "PaperWeights",
    "PostureTask",
    "ProjectionSolver",
    "RelativeFrameTask",
    "RelativePositionTask",
    "Robot",
    "RobotState",
    "RunLog",
    "SolverError",
    "SolverResult",
    "SolverStatus",
    "Stack",
    "StallRecovery",
    "Task",
    "TaskRows",
    "Trajectory",
    "VelocityLimits",
    "WholebodyError",
    "__version__",
    "available_robots",
    "load_robot",
    "paper_stack",
]


def __getattr__(name: str) -> Any:
    """Import a public name on first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'wholebody' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


if TYPE_CHECKING:  # the names as a type checker and an IDE see them
    from wholebody.collision import CollisionModel, Obstacle
    from wholebody.control import Controller, RunLog, StallRecovery
    from wholebody.planning import DMP, HoldTrajectory, MinimumJerkTrajectory, Trajectory
    from wholebody.presets import PaperWeights, paper_stack
    from wholebody.robot import Frame, Robot, RobotState, available_robots, load_robot
    from wholebody.solvers import (
        HierarchicalQPSolver,
        Level,
        ProjectionSolver,
        SolverResult,
        SolverStatus,
        Stack,
    )
    from wholebody.tasks import (
        AccelerationLimits,
        ArmAngleSpring,
        ArmPotentialEnergy,
        Bounds,
        CollisionAvoidance,
        ComTask,
        FrameHalfSpace,
        FrameTask,
        HumanArmAngle,
        HumanArmAngleTask,
        JointLimitAvoidance,
        JointPositionLimits,
        Limit,
        Manipulability,
        Objective,
        ObjectiveValue,
        PostureTask,
        RelativeFrameTask,
        RelativePositionTask,
        Task,
        TaskRows,
        VelocityLimits,
    )
