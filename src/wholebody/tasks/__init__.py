"""Composable tasks, objectives and limits (velocity level, actuated coordinates)."""

from __future__ import annotations

from wholebody.tasks.arm_angle import ArmAngleSpring, HumanArmAngle, HumanArmAngleTask
from wholebody.tasks.arm_energy import ArmEnergyValue, ArmPotentialEnergy
from wholebody.tasks.base import (
    Bounds,
    InequalityRows,
    InequalityTask,
    Limit,
    Objective,
    ObjectiveValue,
    Task,
    TaskRows,
    damp_rows,
)
from wholebody.tasks.collision import CollisionAvoidance
from wholebody.tasks.com import ComTask
from wholebody.tasks.frame import FrameTask
from wholebody.tasks.inequality import FrameHalfSpace
from wholebody.tasks.limits import AccelerationLimits, JointPositionLimits, VelocityLimits
from wholebody.tasks.objectives import JointLimitAvoidance, Manipulability
from wholebody.tasks.posture import PostureTask
from wholebody.tasks.relative import RelativeFrameTask, RelativePositionTask

__all__ = [
    "AccelerationLimits",
    "ArmAngleSpring",
    "ArmEnergyValue",
    "ArmPotentialEnergy",
    "Bounds",
    "CollisionAvoidance",
    "ComTask",
    "FrameHalfSpace",
    "FrameTask",
    "HumanArmAngle",
    "HumanArmAngleTask",
    "InequalityRows",
    "InequalityTask",
    "JointLimitAvoidance",
    "JointPositionLimits",
    "Limit",
    "Manipulability",
    "Objective",
    "ObjectiveValue",
    "PostureTask",
    "RelativeFrameTask",
    "RelativePositionTask",
    "Task",
    "TaskRows",
    "VelocityLimits",
    "damp_rows",
]
