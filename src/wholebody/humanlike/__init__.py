"""The paper's motion principle: arm angle, arm energy, stiffness models, human data.

Numpy only at import: the training (``training`` and ``arm_angle_fit``, PyTorch), the SVR
baseline (``svr``, scikit-learn), the pipeline, the reports and the command line are imported
on demand.
"""

from __future__ import annotations

from wholebody.arm.angle import ArmAngle, arm_angle, arm_angle_with_gradient
from wholebody.arm.human_arm_angle import (
    ConstantArmAngle,
    HumanArmAngleModel,
    NetworkArmAngle,
    default_arm_angle_model,
    normalised_wrist,
)
from wholebody.arm.network import NetworkStiffness, default_stiffness
from wholebody.arm.stiffness import ConstantStiffness, StiffnessModel
from wholebody.humanlike.arm_angle_data import ArmAngleRecords, arm_angle_records
from wholebody.humanlike.arm_angle_model import (
    CALIBRATED,
    ArmAngleModel,
    calibrate,
    elbow_on_circle,
    kim_arm_angle,
)
from wholebody.humanlike.dataset import (
    DEFAULT_TEST_PARTICIPANTS,
    StiffnessDataset,
    build_dataset,
)
from wholebody.humanlike.evaluation import regression_scores
from wholebody.humanlike.labels import (
    StiffnessLabels,
    frame_rules,
    gravity_energy,
    stiffness_labels,
)
from wholebody.humanlike.mapping import (
    ArmParameters,
    canonical_to_lab,
    lab_to_canonical,
    map_to_robot,
)
from wholebody.humanlike.recordings import (
    Recording,
    load_participants,
    load_recording,
    load_recordings,
    save_npz_recording,
)
from wholebody.humanlike.synthetic import (
    DEFAULT_PARTICIPANTS,
    VirtualParticipant,
    generate_synthetic,
)

__all__ = [
    "CALIBRATED",
    "DEFAULT_PARTICIPANTS",
    "DEFAULT_TEST_PARTICIPANTS",
    "ArmAngle",
    "ArmAngleModel",
    "ArmAngleRecords",
    "ArmParameters",
    "ConstantArmAngle",
    "ConstantStiffness",
    "HumanArmAngleModel",
    "NetworkArmAngle",
    "NetworkStiffness",
    "Recording",
    "StiffnessDataset",
    "StiffnessLabels",
    "StiffnessModel",
    "VirtualParticipant",
    "arm_angle",
    "arm_angle_records",
    "arm_angle_with_gradient",
    "build_dataset",
    "calibrate",
    "canonical_to_lab",
    "default_arm_angle_model",
    "default_stiffness",
    "elbow_on_circle",
    "frame_rules",
    "generate_synthetic",
    "gravity_energy",
    "kim_arm_angle",
    "lab_to_canonical",
    "load_participants",
    "load_recording",
    "load_recordings",
    "map_to_robot",
    "normalised_wrist",
    "regression_scores",
    "save_npz_recording",
    "stiffness_labels",
]
