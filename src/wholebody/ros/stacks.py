"""The stack a node runs: the default one, or a scenario file's ``[stack]`` and hands.

* **Default** (:func:`default_stack`): one :class:`~wholebody.tasks.FrameTask` per frame
  (``kp`` 1/s, position and orientation), a level below it a
  :class:`~wholebody.tasks.PostureTask` on every joint towards the posture the robot has
  when it is first commanded (so that the redundancy does not drift), and the joint
  position, velocity and acceleration limits. A mobile base's actuators cost
  ``wheel_metric`` of a joint's in the velocity metric, so that the base drives rather than
  the arms stretch (:func:`~wholebody.presets.paper_metric`).
* **Scenario** (:func:`scenario_stack`): the file's hands as frame tasks (their gains),
  :func:`~wholebody.presets.paper_stack` with its ``[stack]`` weights, the acceleration
  limits always on, and its ``[collision]`` avoidance when enforced. Its phases and
  planners are not used: the targets come from the topics.

Either way, the node runs without the stall recovery (:class:`~wholebody.control.
recovery.StallRecovery`): a robot next to people should not start a retreat of its own
when a target is out of reach; it stays where the limits hold it and the status says
which task is unmet.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wholebody.collision import CollisionModel
from wholebody.errors import ConfigError
from wholebody.presets import PaperWeights, default_stiffness, paper_metric, paper_stack
from wholebody.robot import Robot
from wholebody.solvers import Level, Stack
from wholebody.solvers.base import Solver
from wholebody.tasks import (
    AccelerationLimits,
    CollisionAvoidance,
    FrameTask,
    JointPositionLimits,
    PostureTask,
    VelocityLimits,
)

__all__ = ["NodeStack", "default_stack", "scenario_stack"]

_TOPIC_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


@dataclass
class NodeStack:
    """What a node runs: the stack, its frame tasks by frame name (the topics' ``<FRAME>``),
    the posture task whose target is the posture held (None in a scenario's stack), the
    solver and the collision model whose closest pairs the markers show (None without)."""

    stack: Stack
    tasks: dict[str, FrameTask]
    posture: PostureTask | None
    solver: Solver
    collision: CollisionModel | None = None


def _frame_tasks(robot: Robot, frames: Sequence[str], kp: float, ki: float) -> dict[str, FrameTask]:
    """A frame task per frame, keyed by the frame's name (checked: a topic name part)."""
    tasks: dict[str, FrameTask] = {}
    for frame in frames:
        name = robot.frame(frame).name
        if not _TOPIC_NAME.match(name):
            raise ConfigError(
                f"frame {name!r} cannot be part of a ROS topic name (letters, "
                f"digits and _, starting with a letter)"
            )
        if name in tasks:
            raise ConfigError(f"frame {name!r} given twice")
        tasks[name] = FrameTask(robot, name, kp=kp, ki=ki)
    return tasks


def default_stack(
    robot: Robot, frames: Sequence[str] | None, solver: Solver, *, kp: float = 10.0, ki: float = 0.0
) -> NodeStack:
    """The default stack (module docstring) for ``frames`` (None: the arms' tool
    frames)."""
    if frames is None:
        frames = [arm.tool.name for arm in robot.arms.values()]
        if not frames:
            raise ConfigError(
                f"robot {robot.name!r} has no [arms]: name the frames to control with --task FRAME"
            )
    tasks = _frame_tasks(robot, frames, kp, ki)
    posture = PostureTask(robot, kp=1.0, weight=1.0)
    metric = paper_metric(robot) if robot.base.mobile else np.ones(robot.nu)
    stack = Stack(
        robot,
        [Level(tuple(tasks.values()), name="tasks"), Level((posture,), name="posture")],
        [JointPositionLimits(robot), VelocityLimits(robot), AccelerationLimits(robot)],
        metric=metric,
    )
    return NodeStack(stack, tasks, posture, solver)


def scenario_stack(robot: Robot, path: str | Path, solver: Solver, backend: str) -> NodeStack:
    """A scenario file's stack and hands on ``robot`` (module docstring); ``backend``
    ``"pinv"`` leaves the objectives out."""
    from wholebody.scenarios import load_scenario
    from wholebody.scenarios.runner import collision_model, scenario_robot

    spec = load_scenario(path)
    if scenario_robot(spec).name != robot.name:
        raise ConfigError(
            f"{path}: the scenario is for robot {spec.robot!r}, the node runs {robot.name!r}"
        )
    tasks: dict[str, FrameTask] = {}
    for hand in spec.hands.values():
        tasks.update(_frame_tasks(robot, [hand.frame], hand.kp, hand.ki))
    weights: PaperWeights = spec.stack
    stiffness = (
        default_stiffness(robot) if spec.stack.stiffness == "learned" else spec.stack.stiffness
    )
    model = collision_model(spec, robot)
    cs = spec.collision
    avoid = None
    if model is not None and cs is not None and cs.enforce:
        avoid = CollisionAvoidance(
            robot, model, safety=cs.safety, influence=cs.influence, speed=cs.speed
        )
    stack = paper_stack(
        robot,
        list(tasks.values()),
        objectives=backend != "pinv",
        weights=weights,
        stiffness=stiffness,
        acceleration=True,
        collision=avoid,
    )
    return NodeStack(stack, tasks, None, solver, model)
