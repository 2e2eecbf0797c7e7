"""The paper's controller as a ready-made stack.

``H = w1 f_p + w2 h1 - w3 h2`` (NOTES §2) with:

* ``f_p`` the arm potential energy of each arm (:class:`ArmPotentialEnergy`), weight ``w1``;
* ``h1`` joint-limit avoidance with a per-group weight (the paper's ``w2`` "is a coefficient
  matrix"): heavy on the waist, light on the arms. That is what turns the paper's principle
  "more arm, less waist" into numbers: ``h1`` pulls joints to mid-range, and a heavy waist
  weight makes the null-space motion straighten the trunk and let the base and arms work;
* ``h2`` manipulability of both hands (:class:`Manipulability`), weight ``w3`` (0 by default:
  ``h2`` is left out unless ``PaperWeights.manipulability`` is set);
* descent gain ``k`` (``u = J+ v - k (I - J+ J) grad H``).

The velocity metric makes one wheel radian per second as cheap as 0.01 of a joint's, so the
minimum-norm choices let the base drive (a wheel speed of 1 rad/s moves the base only
2 cm/s). The same metric is used for the plain pseudo-inverse baseline, so a comparison
isolates the effect of the objectives.

The default numbers were tuned on the paper's single-arm reach (right hand to
(1.701, -0.45675, 0.46133) m in 5 s at 100 Hz): ``tests/test_controller.py`` holds the
comparison with the plain pseudo-inverse. The energy weight keeps an arm that has no task
hanging relaxed (``h1`` alone would lift it to mid-range), and the waist weight keeps the
trunk upright while the base and the arm reach.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wholebody.arm.network import default_stiffness as network_stiffness
from wholebody.arm.network import stiffness_path
from wholebody.arm.stiffness import ConstantStiffness, StiffnessModel
from wholebody.errors import DimensionError
from wholebody.robot import Robot
from wholebody.solvers.stack import Level, Stack
from wholebody.tasks import (
    AccelerationLimits,
    ArmAngleSpring,
    ArmPotentialEnergy,
    CollisionAvoidance,
    HumanArmAngle,
    HumanArmAngleTask,
    JointLimitAvoidance,
    JointPositionLimits,
    Manipulability,
    Objective,
    Task,
    VelocityLimits,
)
from wholebody.tasks.arm_angle import ArmAngleModel

__all__ = [
    "HUMAN_LIKE",
    "SPRINGS",
    "PaperWeights",
    "paper_metric",
    "paper_objectives",
    "paper_stack",
]


SPRINGS = ("paper", "signed", "none")
"""The arm energy's spring: the paper's ``1/2 k (pi - |alpha|)^2``, the signed
``1/2 k (pi - alpha)^2`` (:class:`~wholebody.tasks.ArmAngleSpring`), or none (gravity only)."""


@dataclass(frozen=True)
class PaperWeights:
    """Weights of ``H`` and the descent gain (see the module docstring); beyond the paper,
    the spring's form (:data:`SPRINGS`), the weight of the pull towards the human arm angle
    in ``H`` (:class:`~wholebody.tasks.HumanArmAngle`, 0: off), the rate (1/s) of the arm
    angle as a task level between the tasks and ``H``
    (:class:`~wholebody.tasks.HumanArmAngleTask`, 0: no such level), and the velocity
    metric's weight on the waist's joints (:func:`paper_metric`)."""

    energy: float = 0.5
    limits_arms: float = 0.05
    limits_waist: float = 30.0
    manipulability: float = 0.0
    gain: float = 1.0
    wheel_metric: float = 0.01
    spring: str = "paper"
    human_arm_angle: float = 0.0
    human_arm_angle_kp: float = 0.0
    waist_metric: float = 1.0


HUMAN_LIKE = PaperWeights(spring="none", human_arm_angle_kp=10.0, waist_metric=100.0)
"""The human-like preset: the paper's stack with its spring replaced by the human arm angle
as a task level (rate 10 1/s), and the waist a hundred times dearer than an arm joint in the
velocity metric. Why the metric: the arm-angle level moves the elbow in the null space of the
hands, which without it the waist pays for (twice the paper's waist travel on people's
trials); with it the arms do, "more arm, less waist", at a cost of a fraction of a degree of
arm angle (benchmarks/README.md, "Human motion")."""


def default_stiffness(robot: Robot) -> StiffnessModel:
    """The robot's learned stiffness network if it has one (``stiffness.npz`` beside its
    ``robot.toml``, see :func:`wholebody.humanlike.default_stiffness`), else a constant
    0.1 N m/rad."""
    if stiffness_path(robot).is_file():
        return network_stiffness(robot)
    return ConstantStiffness(0.1)


def paper_metric(robot: Robot, weights: PaperWeights = PaperWeights()) -> np.ndarray:
    """Velocity metric ``W`` (:class:`~wholebody.solvers.Stack`'s: every minimum-norm choice
    in ``||u||_W``): ``weights.wheel_metric`` on the base actuators, ``weights.waist_metric``
    on the joints of the robot's ``waist`` group (if it has one), 1 elsewhere."""
    for name in ("wheel_metric", "waist_metric"):
        value = getattr(weights, name)
        if not (math.isfinite(value) and value > 0):
            raise DimensionError(f"PaperWeights.{name} must be a finite weight > 0, got {value}")
    metric = np.ones(robot.nu)
    metric[: len(robot.base.actuators)] = weights.wheel_metric
    if "waist" in robot.groups:
        metric[robot.groups["waist"].indices] = weights.waist_metric
    return metric


def _arm_angle_model(model: ArmAngleModel | None) -> ArmAngleModel:
    """``model``, or the shipped model of the human arm angle."""
    if model is not None:
        return model
    from wholebody.arm import default_arm_angle_model

    return default_arm_angle_model()


def paper_objectives(
    robot: Robot,
    weights: PaperWeights = PaperWeights(),
    stiffness: float | StiffnessModel | None = None,
    arm_angle_model: ArmAngleModel | None = None,
) -> list[Objective]:
    """``f_p`` of every arm (with the spring ``weights.spring`` says), the pull towards the
    human arm angle if weighted, ``h1`` (per group) and, if weighted, ``h2`` of the arms'
    tools. ``arm_angle_model``: the human arm angle the pull aims at (default: the shipped
    model, :func:`wholebody.arm.default_arm_angle_model`)."""
    if weights.spring not in SPRINGS:
        raise DimensionError(
            f"PaperWeights.spring must be one of {', '.join(SPRINGS)}, got {weights.spring!r}"
        )
    k = default_stiffness(robot) if stiffness is None else stiffness
    objectives: list[Objective] = []
    for arm in robot.arms:
        paper = weights.spring == "paper"
        objectives.append(
            ArmPotentialEnergy(robot, arm, k if paper else 0.0, weight=weights.energy)
        )
        if weights.spring == "signed":
            objectives.append(ArmAngleSpring(robot, arm, k, signed=True, weight=weights.energy))
    if not (math.isfinite(weights.human_arm_angle) and weights.human_arm_angle >= 0):
        raise DimensionError(
            f"PaperWeights.human_arm_angle must be a weight >= 0, got {weights.human_arm_angle}"
        )
    if weights.human_arm_angle:
        model = _arm_angle_model(arm_angle_model)
        objectives += [
            HumanArmAngle(robot, arm, model, weight=weights.human_arm_angle) for arm in robot.arms
        ]
    # h1 acts on the joints with position limits: continuous joints (wheels, an endless
    # wrist) have no range to stay inside
    arm_groups = [a.group.name for a in robot.arms.values() if a.group is not None]
    arm_joints = _limited(robot, arm_groups)
    others = _limited(robot, [g for g in robot.groups if g not in arm_groups])
    others = [j for j in others if j not in arm_joints]
    if arm_joints:
        objectives.append(
            JointLimitAvoidance(
                robot, arm_joints, weight=weights.limits_arms, name="joint_limits_arms"
            )
        )
    if others:
        objectives.append(
            JointLimitAvoidance(
                robot, others, weight=weights.limits_waist, name="joint_limits_body"
            )
        )
    if weights.manipulability:
        objectives.append(
            Manipulability(
                robot, [a.tool for a in robot.arms.values()], weight=-weights.manipulability
            )
        )
    return objectives


def _limited(robot: Robot, groups: Sequence[str]) -> list[int]:
    """The entries of ``u`` of the joints of ``groups`` with finite position limits, in order,
    without repeats (indices: a joint may be named like a group)."""
    lower, upper = robot.position_limits
    joints: list[int] = []
    for g in groups:
        for i in robot.group(g).indices.tolist():
            if np.isfinite(lower[i]) and np.isfinite(upper[i]) and i not in joints:
                joints.append(i)
    return joints


def paper_stack(
    robot: Robot,
    tasks: Sequence[Task],
    *,
    objectives: bool = True,
    weights: PaperWeights = PaperWeights(),
    stiffness: float | StiffnessModel | None = None,
    first: Sequence[Task] = (),
    acceleration: bool = False,
    arm_angle_model: ArmAngleModel | None = None,
    collision: CollisionAvoidance | None = None,
) -> Stack:
    """The paper's stack: ``tasks`` on top, then ``H`` (omitted with ``objectives=False``:
    the plain pseudo-inverse baseline), joint position and velocity limits (and with
    ``acceleration`` the robot's acceleration limits), the metric.

    With ``weights.human_arm_angle_kp > 0`` (and ``objectives``) a level of
    :class:`~wholebody.tasks.HumanArmAngleTask` (one per arm, ``arm_angle_model`` or the
    shipped model) sits between ``tasks`` and ``H``: the arm angles follow the human one
    wherever the tasks leave the arms' self-motion free.

    ``collision`` (:class:`~wholebody.tasks.CollisionAvoidance`) goes in a level above
    all: every task is met inside its rows.

    ``first`` puts tasks in a level above ``tasks``: for a carried object, the closed chain
    (the hands' relative pose) above the hands' absolute poses, the usual cooperative
    task-space priority. The relative rows are then met exactly and the hands'
    rows, redundant with them, in the least-squares sense below."""
    levels: list[Level] = [Level((collision,), name="collision")] if collision else []
    if first:
        levels.append(Level(tuple(first), name="closed chain"))
    levels.append(Level(tuple(tasks), name="tasks"))
    kp = weights.human_arm_angle_kp
    if not (math.isfinite(kp) and kp >= 0):
        raise DimensionError(f"PaperWeights.human_arm_angle_kp must be >= 0 (1/s), got {kp}")
    if kp > 0 and objectives:
        model = _arm_angle_model(arm_angle_model)
        pulls = [HumanArmAngleTask(robot, arm, model, kp=kp) for arm in robot.arms]
        levels.append(Level(tuple(pulls), name="arm angle"))
    if objectives:
        levels.append(
            Level(
                tuple(paper_objectives(robot, weights, stiffness, arm_angle_model)),
                gain=weights.gain,
                name="objectives",
            )
        )
    return Stack(
        robot,
        levels,
        [JointPositionLimits(robot), VelocityLimits(robot)]
        + ([AccelerationLimits(robot)] if acceleration else []),
        metric=paper_metric(robot, weights),
    )
