"""The paper's motion principle: arm angle, arm energy, stiffness models, human data."""

from __future__ import annotations

from wholebody.humanlike.arm_geometry import ArmAngle, arm_angle, arm_angle_with_gradient
from wholebody.humanlike.stiffness import ConstantStiffness, StiffnessModel

__all__ = [
    "ArmAngle",
    "ConstantStiffness",
    "StiffnessModel",
    "arm_angle",
    "arm_angle_with_gradient",
]
