#!/usr/bin/env python3
"""Cost of one compiled control step as the robot and the task count grow.

For each bundled robot (``dual_arm_torso``, nu = 15; ``mobile_humanoid``, nu = 23) and 2, 4
and 8 frame tasks (6-D each): the two tool frames track small circles on the top level; the
extra frames (elbow centres, wrist centres, upper arms) hold their home poses on a second
level; a posture level below; joint position and velocity limits. One step = set the
targets, update the kinematics, solve, advance the integrators, integrate. The cases take
turns step by step (the cold schedule of ``control_step.py``) over ``--steps`` steps and
``--repeat`` repeats; medians in microseconds.

    python benchmarks/scaling.py [--steps N] [--repeat R]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import wholebody
from wholebody.solvers import Level, ProjectionSolver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import FrameTask, JointPositionLimits, PostureTask, VelocityLimits

DT = 0.01
ROBOTS = ("dual_arm_torso", "mobile_humanoid")
COUNTS = (2, 4, 8)
EXTRA = ("elbow_centre", "wrist_centre", "upper_arm")  # per side, after the tool


def build(robot: wholebody.Robot, count: int, backend: str) -> dict:
    sides = ("left", "right")
    tools = [FrameTask(robot, f"{s}_tool", kp=20.0) for s in sides]
    extras = [FrameTask(robot, f"{s}_{e}", kp=5.0, weight=0.1) for e in EXTRA for s in sides][
        : count - 2
    ]
    q0 = robot.home()
    for task in extras:
        task.set_target(robot.frame_pose(q0, task.frame))
    levels = [Level(tools, name="tools")]
    if extras:
        levels.append(Level(extras, name="frames"))
    levels.append(Level([PostureTask(robot, kp=1.0)], name="posture"))
    stack = Stack(robot, levels, [JointPositionLimits(robot), VelocityLimits(robot)])
    solver = ProjectionSolver() if backend == "projection" else HierarchicalQPSolver(backend)
    homes = [robot.frame_pose(q0, t.frame) for t in tools]
    return {
        "robot": robot,
        "stack": stack,
        "solver": solver,
        "tools": tools,
        "homes": homes,
        "q": q0,
        "q0": q0,
        "times": [],
        "bounds": 0,
    }


def step(case: dict, k: int) -> None:
    robot, stack = case["robot"], case["stack"]
    start = time.perf_counter()
    phase = 2 * np.pi * k / 200
    for task, home in zip(case["tools"], case["homes"], strict=True):
        target = home.copy()
        target[:3, 3] += 0.05 * np.array([np.cos(phase) - 1.0, np.sin(phase), 0.0])
        task.set_target(target)
    state = robot.update(case["q"])
    result = case["solver"].solve(stack, state, DT)
    stack.advance(state, DT, result=result)
    case["q"] = robot.integrate(case["q"], result.u, DT)
    case["times"].append(time.perf_counter() - start)
    case["bounds"] = case.get("bounds", 0) + result.limit_hit


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    cases = {}
    for name in ROBOTS:
        robot = wholebody.load_robot(name)
        for count in COUNTS:
            for backend in ("projection", "daqp"):
                cases[(name, robot.nu, count, backend)] = build(robot, count, backend)
    for case in cases.values():  # compile / load the kernels outside the timing
        step(case, 0)
        case["times"].clear()
        case["bounds"] = 0
    for _ in range(args.repeat):
        for case in cases.values():
            case["q"] = case["q0"].copy()
            case["stack"].reset()
        for k in range(args.steps):
            for case in cases.values():
                step(case, k)
    print(
        f"one control step, step-interleaved, {args.steps} steps x {args.repeat}; "
        f"{platform.machine()}, Python {platform.python_version()}"
    )
    print(
        f"{'robot':16s} {'nu':>3s} {'frame tasks':>11s} {'projection us':>14s} "
        f"{'hqp daqp us':>12s} {'x 2 tasks (proj, hqp)':>22s} "
        f"{'bounds % (proj, hqp)':>21s}"
    )
    med = {key: float(np.median(c["times"])) * 1e6 for key, c in cases.items()}
    for name in ROBOTS:
        for count in COUNTS:
            (nu,) = {k[1] for k in cases if k[0] == name}
            p, h = med[(name, nu, count, "projection")], med[(name, nu, count, "daqp")]
            p2, h2 = med[(name, nu, 2, "projection")], med[(name, nu, 2, "daqp")]
            bp, bh = (
                100 * cases[(name, nu, count, b)]["bounds"] / (args.steps * args.repeat)
                for b in ("projection", "daqp")
            )
            print(
                f"{name:16s} {nu:3d} {count:11d} {p:14.1f} {h:12.1f} "
                f"{p / p2:11.2f} {h / h2:10.2f} {bp:10.0f} {bh:10.0f}"
            )


if __name__ == "__main__":
    main()
