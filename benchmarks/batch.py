#!/usr/bin/env python3
"""Many independent states of one stack: ``Controller.step_many`` against the same states
solved one after another with ``Controller.step``.

The paper's robot, both hands above a weak posture task, joint position, velocity and
acceleration limits; ``N`` random configurations, each hand given a target 10 cm from where it
is. Sequential: for each state its targets set (``set_target``), then ``steps`` calls of
``Controller.step`` (the one-call step) from its configuration. Batched: one
``Controller.step_many(Q, targets, steps=steps)`` on every core. The two are interleaved
(``--repeat`` rounds, median kept), the answers compared, and the throughput (states a
second) printed for each backend.

    python benchmarks/batch.py [--n 1000] [--steps 1] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import wholebody as wb
from wholebody.control import Controller
from wholebody.solvers.hqp import HierarchicalQPSolver

DT = 0.01


def setup(robot: wb.Robot, solver: object, n: int, seed: int = 0):
    """The controller, the states and the targets."""
    rng = np.random.default_rng(seed)
    hands = [wb.FrameTask(robot, f, kp=20.0) for f in ("left_tool", "right_tool")]
    limits = [wb.JointPositionLimits(robot), wb.VelocityLimits(robot), wb.AccelerationLimits(robot)]
    stack = wb.Stack(robot, [hands, [wb.PostureTask(robot, weight=1e-3)]], limits)
    Q = np.array([robot.random_configuration(rng, margin=0.05, base_range=0.5) for _ in range(n)])
    targets = {}
    for hand in hands:
        poses = []
        for q in Q:
            T = robot.frame_pose(q, hand.frame).copy()
            T[:3, 3] += rng.normal(size=3) * (0.1 / np.sqrt(3))
            poses.append(T)
        targets[hand] = np.array(poses)
    return Controller(robot, stack, solver, dt=DT), Q, targets


def sequential(controller: Controller, Q: np.ndarray, targets: dict, steps: int) -> np.ndarray:
    """Each state on its own: its targets set, ``steps`` one-call steps."""
    out = np.empty((Q.shape[0], controller.robot.nq))
    for s in range(Q.shape[0]):
        controller.reset()
        for task, poses in targets.items():
            task.set_target(poses[s])
        q = Q[s]
        for _ in range(steps):
            controller.step(q)
            q = controller.q_next
        out[s] = q
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="states")
    parser.add_argument("--steps", type=int, default=1, help="control steps per state")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    robot = wb.load_robot("mobile_humanoid")
    print(
        f"{args.n} states of mobile_humanoid (nu = {robot.nu}), {args.steps} step(s) each; "
        f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}"
    )
    print(
        f"{'backend':12s} {'sequential s':>13s} {'batched s':>10s} {'states/s seq':>13s} "
        f"{'states/s batch':>15s} {'ratio':>6s} {'max |dq|':>9s}"
    )
    for name, solver in (("projection", wb.ProjectionSolver()), ("hqp", HierarchicalQPSolver())):
        controller, Q, targets = setup(robot, solver, args.n)
        sequential(controller, Q[:2], {t: p[:2] for t, p in targets.items()}, 1)  # warm
        controller.step_many(Q[:4], {t: p[:4] for t, p in targets.items()}, steps=1)
        seq, bat = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            q_seq = sequential(controller, Q, targets, args.steps)
            t1 = time.perf_counter()
            controller.reset()
            batch = controller.step_many(Q, targets, steps=args.steps)
            t2 = time.perf_counter()
            seq.append(t1 - t0)
            bat.append(t2 - t1)
        controller.close()
        s, b = float(np.median(seq)), float(np.median(bat))
        gap = float(np.abs(batch.q - q_seq).max())
        print(
            f"{name:12s} {s:13.3f} {b:10.3f} {args.n / s:13.0f} {args.n / b:15.0f} "
            f"{s / b:6.2f} {gap:9.1e}"
        )


if __name__ == "__main__":
    main()
