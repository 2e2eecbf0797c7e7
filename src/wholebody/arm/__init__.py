"""The arm as the controller sees it: the arm angle (the elbow's rotation about the
shoulder-wrist line), the stiffness models ``k(wrist)`` of the paper's spring, constant or
a network shipped as ``.npz`` and evaluated in numpy, and the models of the arm angle people
choose, ``alpha_h(p)`` of the normalised wrist (:mod:`wholebody.arm.human_arm_angle`). Below
the tasks, and importing nothing of the offline human-data pipeline
(:mod:`wholebody.humanlike`), which learns them."""

from __future__ import annotations

from wholebody.arm.angle import ArmAngle, arm_angle, arm_angle_with_gradient
from wholebody.arm.human_arm_angle import (
    ConstantArmAngle,
    HumanArmAngleModel,
    NetworkArmAngle,
    default_arm_angle_model,
    normalised_wrist,
)
from wholebody.arm.network import NetworkStiffness, default_stiffness, stiffness_path
from wholebody.arm.stiffness import ConstantStiffness, StiffnessModel

__all__ = [
    "ArmAngle",
    "ConstantArmAngle",
    "ConstantStiffness",
    "HumanArmAngleModel",
    "NetworkArmAngle",
    "NetworkStiffness",
    "StiffnessModel",
    "arm_angle",
    "arm_angle_with_gradient",
    "default_arm_angle_model",
    "default_stiffness",
    "normalised_wrist",
    "stiffness_path",
]
