"""``wholebody warmup``: compile every kernel now, once per machine, instead of at first use.

The kernels (:mod:`wholebody.kernels`) compile on their first call and are cached on disk
(see there for where); the first control step of a process otherwise pays the compilation
(2.5 to 5.5 minutes measured on a 2-core machine, once) and later processes only load the cache
(about a second). Warming up runs, on the bundled humanoid, a few steps of each solver on a
stack that reaches every compiled path (frame, relative and posture tasks, limits, the arm
energy with the shipped stiffness network, h1, manipulability, bounds active), the collision
kernels (the humanoid's own pairs) and the DMP kernels.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from wholebody.robot import Robot

__all__ = ["Warmup", "warmup"]

DT = 0.01


@dataclass(frozen=True)
class Warmup:
    """What :func:`warmup` did: seconds taken and where the kernels are cached."""

    seconds: float
    cache: Path | None
    compiled: bool  # False under NUMBA_DISABLE_JIT=1 (nothing to compile)


def _steps(robot: Robot, solver: object, tight: bool) -> None:
    """Three closed-loop steps of ``solver``, the hands moving: the paper's stack (h2 on) with
    the closed chain above it, or (``tight``) a hierarchy whose velocity box binds."""
    from wholebody.presets import PaperWeights, paper_stack
    from wholebody.solvers import Level, Stack
    from wholebody.tasks import (
        FrameTask,
        JointPositionLimits,
        PostureTask,
        RelativeFrameTask,
        VelocityLimits,
    )

    hands = [FrameTask(robot, "left_tool", kp=20.0), FrameTask(robot, "right_tool", kp=20.0)]
    if tight:  # a box that binds on every step: the saturation and pinning paths
        stack = Stack(robot, [Level(hands), Level([PostureTask(robot)])],
                      [JointPositionLimits(robot), VelocityLimits(robot, scale=0.05)])  # fmt: skip
    else:
        chain = RelativeFrameTask(robot, "left_tool", "right_tool", kp=20.0, name="chain")
        stack = paper_stack(robot, hands, weights=PaperWeights(manipulability=0.05),
                            first=[chain])  # fmt: skip
    q = robot.home()
    for k in range(3):
        for hand in hands:
            target = robot.frame_pose(q, hand.frame).copy()
            target[:3, 3] += (0.05 * k, 0.0, 0.05)
            hand.set_target(target)
        state = robot.update(q)
        result = solver.solve(stack, state, DT)  # type: ignore[attr-defined]
        stack.advance(state, DT, result=result)
        q = robot.integrate(q, result.u, DT)


def warmup() -> Warmup:
    """Compile (or load from the cache) every kernel of the package; safe to call again."""
    import wholebody
    from wholebody import kernels
    from wholebody.collision import CollisionModel
    from wholebody.planning import dmp
    from wholebody.solvers import ProjectionSolver
    from wholebody.solvers.hqp import HierarchicalQPSolver

    start = time.perf_counter()
    robot = wholebody.load_robot("mobile_humanoid")
    for tight in (False, True):
        _steps(robot, ProjectionSolver(), tight)
        _steps(robot, HierarchicalQPSolver("daqp"), tight)
    CollisionModel(robot).distances(robot.update(robot.home()), 0.05)
    dmp.warmup()
    return Warmup(time.perf_counter() - start, kernels.cache_directory(), not kernels.DISABLED)
