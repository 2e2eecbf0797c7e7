#!/usr/bin/env python3
"""What locking joints saves: one control step of TIAGo++ as configured (casters, suspensions
and fingers locked, u = 19) against the same robot with only its suspensions locked (the
wheels must hang from the base link), so that its 8 casters and 72 finger joints stay in u
(u = 99).

The paper's stack with both hands on small step targets from the home posture, both
backends, step-interleaved (the four cases take turns every step), one BLAS thread; medians
after a warm-up. Needs example-robot-data (``pip install '.[robots]' from the checkout``).

    python benchmarks/locking.py [--steps N]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

import wholebody
from wholebody.presets import paper_stack
from wholebody.resources import robots_dir
from wholebody.solvers import ProjectionSolver
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import FrameTask

WARMUP = 20


def unlocked(tmp: Path) -> wholebody.Robot:
    """TIAGo++ with only the suspensions locked."""
    text = (robots_dir() / "tiago_dual" / "robot.toml").read_text()
    kept = [line for line in text.splitlines() if not line.startswith(('"caster_*"', '"hand_*"'))]
    (tmp / "robot.toml").write_text("\n".join(kept) + "\n")
    return wholebody.load_robot(tmp)


def case(robot: wholebody.Robot, solver) -> dict:
    hands = [FrameTask(robot, robot.arm(a).tool, kp=20.0) for a in ("left", "right")]
    stack = paper_stack(robot, hands, stiffness=0.1)
    q = robot.home()
    for hand in hands:
        T = robot.frame_pose(q, hand.frame).copy()
        T[:3, 3] += [0.05, 0.0, 0.05]
        hand.set_target(T)
    return {"robot": robot, "stack": stack, "solver": solver, "q": q, "times": []}


def step(c: dict) -> None:
    robot, stack, solver = c["robot"], c["stack"], c["solver"]
    start = time.perf_counter()
    state = robot.update(c["q"])
    result = solver.solve(stack, state, 0.01)
    stack.advance(state, 0.01, result=result)
    c["q"] = robot.integrate(c["q"], result.u, 0.01)
    c["times"].append(time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        robots = {"locked": wholebody.load_robot("tiago_dual"), "unlocked": unlocked(Path(tmp))}
        cases = {
            (name, b): case(r, ProjectionSolver() if b == "projection" else HierarchicalQPSolver())
            for name, r in robots.items()
            for b in ("projection", "hqp")
        }
        with threadpool_limits(1):
            for _ in range(args.steps + WARMUP):
                for c in cases.values():
                    step(c)
    print(
        f"one control step of TIAGo++, the paper's stack with both hands, "
        f"{args.steps} steps, step-interleaved"
    )
    print(f"{'robot':<10} {'nu':>4} {'backend':<11} {'median us':>10} {'x locked':>9}")
    for (name, backend), c in cases.items():
        t = np.median(c["times"][WARMUP:]) * 1e6
        ref = np.median(cases[("locked", backend)]["times"][WARMUP:]) * 1e6
        print(f"{name:<10} {c['robot'].nu:>4} {backend:<11} {t:>10.1f} {t / ref:>9.2f}")


if __name__ == "__main__":
    main()
