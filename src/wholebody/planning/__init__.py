"""Task-space planning: reference trajectories, DMPs, volumetric obstacles, dual-arm chains.

* :mod:`~wholebody.planning.trajectory` -- the :class:`Trajectory` contract the controller
  samples, minimum-jerk, hold and sequence trajectories.
* :mod:`~wholebody.planning.dmp` -- goal-shift DMPs (fit, rollout, online stepping) and
  :class:`DMPTrajectory` (DMP position + slerp orientation).
* :mod:`~wholebody.planning.obstacles` -- superquadric isopotentials and the dynamic and
  static repulsive potentials with exact gradients.
* :mod:`~wholebody.planning.dual_arm` -- the secondary hand's trajectory from the primary's.
* :mod:`~wholebody.planning.demonstration` -- a demonstration carried onto a new chord.
* :mod:`~wholebody.planning.rotations` -- SO(3) exponential, logarithm and slerp.
"""

from __future__ import annotations

from wholebody.planning.demonstration import align_to_chord, chord_frame
from wholebody.planning.dmp import (
    DMP,
    DMPConfig,
    DMPRollout,
    DMPState,
    DMPStepper,
    DMPTrajectory,
)
from wholebody.planning.dual_arm import CoordinatedTrajectory, secondary_pose
from wholebody.planning.obstacles import (
    DynamicPotential,
    Potential,
    StaticPotential,
    Superquadric,
    box,
    box_distance,
    cylinder,
    cylinder_distance,
    sphere,
    sphere_distance,
    total_force,
)
from wholebody.planning.rotations import exp_so3, log_so3, slerp
from wholebody.planning.trajectory import (
    HoldTrajectory,
    MinimumJerkTrajectory,
    Trajectory,
    TrajectoryArrays,
    TrajectoryError,
    TrajectorySample,
    TrajectorySequence,
    minimum_jerk_scaling,
)

__all__ = [
    "DMP",
    "CoordinatedTrajectory",
    "DMPConfig",
    "DMPRollout",
    "DMPState",
    "DMPStepper",
    "DMPTrajectory",
    "DynamicPotential",
    "HoldTrajectory",
    "MinimumJerkTrajectory",
    "Potential",
    "StaticPotential",
    "Superquadric",
    "Trajectory",
    "TrajectoryArrays",
    "TrajectoryError",
    "TrajectorySample",
    "TrajectorySequence",
    "align_to_chord",
    "box",
    "box_distance",
    "chord_frame",
    "cylinder",
    "cylinder_distance",
    "exp_so3",
    "log_so3",
    "minimum_jerk_scaling",
    "secondary_pose",
    "slerp",
    "sphere",
    "sphere_distance",
    "total_force",
]
