#!/usr/bin/env python3
"""A long kinematic run: does the controller's memory grow, or its step time drift?

The paper's stack on the humanoid (both hands on a minimum-jerk reach played forth and back,
``benchmarks/control_step.py``'s references, the closed chain held by construction), closed
loop (each step from the configuration the last one reached), ``--steps`` control steps per
backend: ``set_target`` on the hands, then ``Controller.step``. Every ``--block`` steps it
records the process's resident memory (``/proc/self/statm``), the median step time of the
block and the hands' largest distance to their references. Printed per backend: the blocks
(first, last and a few between), the memory's growth from the end of the first block to the
end of the last, the ratio of the last block's median step to the first's, and the slope of
the block medians (a least-squares line, us per 100 000 steps).

    python benchmarks/soak.py [--steps 300000] [--block 10000] [--backends projection,hqp]

Its physics half, the carry under MuJoCo read with sensor noise and delay, is
``benchmarks/soak_physics.py``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from control_step import DT, PAPER, forth_and_back, hand_references

import wholebody
from wholebody.control import Controller
from wholebody.presets import paper_stack
from wholebody.solvers import ProjectionSolver
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import FrameTask


def resident_mb() -> float:
    """This process's resident memory now (MB; Linux's ``/proc/self/statm``)."""
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def soak(backend: str, steps: int, block: int) -> list[tuple[int, float, float, float]]:
    """``(steps done, resident MB, median step us, largest hand error mm)`` per block."""
    robot = wholebody.load_robot("mobile_humanoid")
    q, refs = hand_references(robot)
    hands = [FrameTask(robot, "left_tool", kp=20.0), FrameTask(robot, "right_tool", kp=20.0)]
    stack = paper_stack(robot, hands, weights=PAPER, stiffness=0.1)
    solver = ProjectionSolver() if backend == "projection" else HierarchicalQPSolver("daqp")
    controller = Controller(robot, stack, solver, dt=DT)
    period = round(2 * refs[0].duration / DT)
    samples = [forth_and_back(refs, k * DT) for k in range(period)]
    times = np.empty(block)
    rows = []
    for done in range(0, steps, block):
        error = 0.0
        for k in range(block):
            start = time.perf_counter()
            for hand, (pose, twist) in zip(hands, samples[(done + k) % period], strict=True):
                hand.set_target(pose, twist)
            controller.step(q)
            q = controller.q_next.copy()
            times[k] = time.perf_counter() - start
        for hand, (pose, _) in zip(hands, samples[(done + block) % period], strict=True):
            error = max(
                error, float(np.linalg.norm(robot.frame_pose(q, hand.frame)[:3, 3] - pose[:3, 3]))
            )
        rows.append((done + block, resident_mb(), float(np.median(times)) * 1e6, error * 1e3))
    controller.close()
    return rows


def report(backend: str, rows: list[tuple[int, float, float, float]]) -> None:
    """The blocks and the soak's three figures (module docstring)."""
    print(f"{backend}:")
    print(f"  {'steps':>8s} {'resident MB':>12s} {'median us':>10s} {'hand error mm':>14s}")
    shown = sorted({0, len(rows) - 1, *range(0, len(rows), max(1, len(rows) // 6))})
    for i in shown:
        n, mb, us, mm = rows[i]
        print(f"  {n:8d} {mb:12.1f} {us:10.1f} {mm:14.3f}")
    steps = np.array([r[0] for r in rows], dtype=float)
    medians = np.array([r[2] for r in rows])
    slope = np.polyfit(steps, medians, 1)[0] * 1e5 if len(rows) > 1 else 0.0
    print(
        f"  resident memory {rows[-1][1] - rows[0][1]:+.2f} MB from step {rows[0][0]} to "
        f"{rows[-1][0]}; last block's median step {medians[-1] / medians[0]:.3f}x the "
        f"first's; trend {slope:+.3f} us per 100 000 steps"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300_000)
    parser.add_argument("--block", type=int, default=10_000)
    parser.add_argument("--backends", default="projection,hqp")
    args = parser.parse_args()
    print(
        f"soak, mobile_humanoid, the paper's stack, {args.steps} steps per backend in blocks "
        f"of {args.block}, dt = {DT} s; {platform.machine()}, Python "
        f"{platform.python_version()}"
    )
    for backend in args.backends.split(","):
        report(backend, soak(backend, args.steps, args.block))


if __name__ == "__main__":
    main()
