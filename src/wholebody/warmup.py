"""``wholebody warmup``: compile every kernel now, once per machine, instead of at first use.

The kernels (:mod:`wholebody.kernels`) compile on their first call and are cached on disk
(see there for where); a later process only loads them (about a second). Warming up runs, on
the bundled humanoid, a stack that reaches every compiled entry (frame, relative and posture
tasks, a half-space, collision avoidance, the arm energy with the shipped stiffness network,
h1, manipulability, position, velocity and acceleration limits) through both backends'
control steps, the evaluation, the stack's advance, the collision distances, a torque-level
step (:mod:`wholebody.kernels.torque`) and the DMP kernels.

The work is split in two halves that compile in two processes at once (the machine's cores):
the evaluation, the projection's step and the torque level in one, the hierarchical QP's
cascade, then its step (which finds the evaluation in the cache by then) and the DMP kernels
in the other. The
evaluation and the cascade are compiled as parts of the steps (:func:`wholebody.kernels.
as_callees`), optimised once, in the steps. This process then loads everything from the
cache.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from wholebody.robot import Robot
    from wholebody.solvers import Stack

__all__ = ["Warmup", "warmup"]

DT = 0.01
HALVES = ("projection", "hqp")


@dataclass(frozen=True)
class Warmup:
    """What :func:`warmup` did: seconds taken and where the kernels are cached."""

    seconds: float
    cache: Path | None
    compiled: bool  # False under NUMBA_DISABLE_JIT=1 (nothing to compile)


def _stack(robot: Robot) -> Stack:
    """A stack with every compiled kind of entry (module docstring)."""
    import numpy as np

    from wholebody.collision import Obstacle
    from wholebody.presets import PaperWeights, paper_stack
    from wholebody.tasks import CollisionAvoidance, FrameHalfSpace, FrameTask, RelativeFrameTask

    hands = [FrameTask(robot, "left_tool", kp=20.0), FrameTask(robot, "right_tool", kp=20.0)]
    chain = RelativeFrameTask(robot, "left_tool", "right_tool", kp=20.0, name="chain")
    pose = np.eye(4)
    pose[:3, 3] = (0.6, 0.0, 0.3)
    board = Obstacle("warmup_board", "box", (0.3, 0.3, 0.02), pose)
    above = FrameHalfSpace(robot, "right_tool", (0.0, 0.0, 1.0), 0.0)
    stack = paper_stack(
        robot, hands, weights=PaperWeights(manipulability=0.05), first=[chain], acceleration=True
    )
    stack.levels[0].entries = (
        *stack.levels[0].entries,
        above,
        CollisionAvoidance(robot, obstacles=[board]),
    )
    return stack


def _steps(robot: Robot, solver: object) -> None:
    """A few steps of ``solver``: one-call steps, the loop of four calls and a logged run."""
    from wholebody.control import Controller

    stack = _stack(robot)
    controller = Controller(robot, stack, solver, dt=DT)
    q = robot.home()
    for _ in range(2):
        controller.step(q)
        q = controller.q_next.copy()
    controller.close()
    state = robot.update(q)
    result = solver.solve(stack, state, DT)  # type: ignore[attr-defined]
    stack.advance(state, DT, result=result)
    stack.evaluate(state, DT)
    controller.run(q, 2 * DT)


def _half(name: str) -> None:
    """One half of the work (module docstring)."""
    import wholebody
    from wholebody.kernels import as_callees
    from wholebody.planning import dmp
    from wholebody.solvers import ProjectionSolver
    from wholebody.solvers.hqp import HierarchicalQPSolver

    robot = wholebody.load_robot("mobile_humanoid")
    if name == "projection":
        stack = _stack(robot)
        with as_callees():  # the evaluation first, for both steps (the HQP's half loads it)
            stack.evaluate(robot.update(robot.home()), DT)
        _steps(robot, ProjectionSolver())
        stack.levels[0].entries[-1].model.distances(robot.update(robot.home()), 0.05)
        _torque(robot)
    else:
        with as_callees():  # the cascade first, for the HQP's step
            _cascade()
        _steps(robot, HierarchicalQPSolver("daqp"))
        dmp.warmup()


def _torque(robot: Robot) -> None:
    """A weighted torque-level step (the torque level's kernels)."""
    import numpy as np

    from wholebody.dynamics import DynamicsSolver
    from wholebody.solvers import Stack
    from wholebody.tasks import PostureTask, VelocityLimits

    stack = Stack(robot, [[PostureTask(robot)]], [VelocityLimits(robot)])
    u = np.full(robot.nu, 0.1)
    DynamicsSolver(robot, mode="weighted").solve(stack, robot.home(), u, 1e-3)


def _cascade() -> None:
    """The cascade alone, on a small synthetic problem with its box active."""
    import numpy as np

    from wholebody.solvers.hqp import HierarchicalQPSolver
    from wholebody.solvers.stack import LevelProblem, StackProblem

    n = 4
    rows = {"t": slice(0, 2)}
    none = (np.zeros((0, n)), np.zeros(0), np.zeros(0))
    level = LevelProblem("level", np.eye(n)[:2], np.array([3.0, -3.0]), *none, rows)
    box = np.ones(n)
    HierarchicalQPSolver().solve_problem(StackProblem([level], -box, box, np.ones(n), {}))


def _cached() -> bool:
    """Whether both steps are in the cache, up to date (numba's index of each is for the
    kernels' current sources); False where numba's cache internals are not the known ones."""
    from wholebody.kernels import control

    for run in (control.projection_run, control.hqp_run):
        index = getattr(getattr(run._cache, "_cache_file", None), "_load_index", None)
        if index is None or not index():
            return False
    return True


def warmup(parallel: bool = True) -> Warmup:
    """Compile (or load from the cache) every kernel of the package; safe to call again.
    ``parallel``: the two halves in two processes at once (module docstring), unless both
    steps are in the cache already (then this process only loads everything)."""
    from wholebody import kernels

    start = time.perf_counter()
    if parallel and not _cached() and not kernels.DISABLED and (os.cpu_count() or 1) > 1:
        code = "import sys; from wholebody.warmup import _half; _half(sys.argv[1])"
        procs = [subprocess.Popen([sys.executable, "-c", code, half]) for half in HALVES]
        for proc in procs:
            proc.wait()  # (a half that failed is compiled here below, with its error)
    for half in HALVES:
        _half(half)
    return Warmup(time.perf_counter() - start, kernels.cache_directory(), not kernels.DISABLED)
