#!/usr/bin/env python3
"""Convergence to random reachable targets from the singular neutral posture, against pink.

From ``mobile_humanoid``'s neutral posture (arms hanging straight: singular), each case
sets both hands' targets to their tool poses at a random configuration inside the joint
limits (``random_configuration(margin=0.05, base_range=0.5)``: reachable by construction,
the base within 0.5 m with any heading) and runs ``--duration`` seconds at 100 Hz. A run
**converges** when both hands end within 1 mm and 1e-2 rad of their targets.

Stacks, each on both wholebody backends:

* ``paper``: the paper's stack (hands, PI law kp = 20 1/s, ki = 5 1/s^2; then ``H``),
  position and velocity limits (:func:`wholebody.presets.paper_stack`);
* ``paper + recovery``: the same with :class:`~wholebody.control.StallRecovery` at its
  defaults (retreat to the middle of the joint ranges when the hands stall, then retry);
* ``hierarchy``: hands strictly above a posture task towards the neutral posture,
  dead-beat gains (``kp = 1/dt``), the problem of ``benchmarks/peers.py``;

and pink (hands and posture as weighted costs, ``single`` of ``peers.py``, daqp; pink's
hierarchy, the hands as equality constraints, has no solution on most of these targets
while they are out of reach of one step), its posture and base costs 100 times weaker than
in ``peers.py`` (with those, the weighted compromise alone leaves the hands millimetres off
their targets). See ``peers.py`` for how the base is matched.

    python benchmarks/convergence.py [--n N] [--seed S] [--duration T] [--acceleration]
                                     [--engine daqp|proxsuite|osqp|qpsolvers:NAME]

Prints per case the success rate, the final position and orientation error percentiles (the
worse hand), the share of steps whose solve FAILED (pink: found no solution), the retreats,
and the targets where each wholebody case and pink disagree.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pinocchio as pin

import wholebody
from wholebody.control.recovery import StallRecovery
from wholebody.presets import paper_stack
from wholebody.solvers import Level, ProjectionSolver, SolverStatus, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import (
    AccelerationLimits,
    FrameTask,
    JointPositionLimits,
    PostureTask,
    VelocityLimits,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers

DT = peers.DT
POSITION_TOL, ANGLE_TOL = 1e-3, 1e-2  # m, rad
PINK_REGULARISATION = 1e-2  # pink's posture and base costs, times those of peers.py


def targets(robot: wholebody.Robot, rng: np.random.Generator) -> list[np.ndarray]:
    """Both tool poses (4x4, world) at a random configuration inside the limits."""
    q = robot.random_configuration(rng, margin=0.05, base_range=0.5)
    return [robot.frame_pose(q, f) for f in peers.HANDS]


def errors(poses: list[np.ndarray], goal: list[np.ndarray]) -> tuple[float, float]:
    """The worse hand's position (m) and orientation (rad) error."""
    p = max(float(np.linalg.norm(a[:3, 3] - b[:3, 3])) for a, b in zip(poses, goal, strict=True))
    r = max(float(np.linalg.norm(pin.log3(a[:3, :3].T @ b[:3, :3])))
            for a, b in zip(poses, goal, strict=True))  # fmt: skip
    return p, r


def wholebody_case(
    robot: wholebody.Robot,
    stack_kind: str,
    backend: str,
    acceleration: bool,
    recovery: bool,
    engine: str = "daqp",
) -> Callable:
    """A run function ``goal -> (final hand poses, failed steps, retreats)`` for one wholebody
    stack and backend (with ``acceleration``: the robot's acceleration limits too; with
    ``recovery``: :class:`~wholebody.control.recovery.StallRecovery` at its defaults)."""
    solver = ProjectionSolver() if backend == "projection" else HierarchicalQPSolver(engine=engine)

    def run(goal: list[np.ndarray], steps: int) -> tuple[list[np.ndarray], int, int]:
        if stack_kind == "paper":
            hands = [FrameTask(robot, f, kp=20.0, ki=5.0) for f in peers.HANDS]
            stack = paper_stack(robot, hands, acceleration=acceleration)
        else:
            hands = [FrameTask(robot, f, kp=1.0 / DT) for f in peers.HANDS]
            posture = PostureTask(robot, kp=1.0 / DT, weight=peers.W_POSTURE)
            posture.set_target(robot.joint_positions(robot.neutral()))
            limits = [JointPositionLimits(robot, gain=peers.LIMIT_GAIN), VelocityLimits(robot)]
            limits += [AccelerationLimits(robot)] if acceleration else []
            stack = Stack(robot, [Level(hands), Level([posture])], limits)
        for hand, T in zip(hands, goal, strict=True):
            hand.set_target(T)
        watch = StallRecovery(robot, stack) if recovery else None
        q, failed = robot.neutral(), 0
        for _ in range(steps):
            state = robot.update(q)
            result = solver.solve(stack if watch is None else watch.stack, state, DT)
            failed += result.status == SolverStatus.FAILED
            if watch is None:
                stack.advance(state, DT, result=result)
            else:
                watch.advance(state, DT, result)
            q = robot.integrate(q, result.u, DT)
        state = robot.update(q)
        poses = [state.pose(robot.frame(f)) for f in peers.HANDS]
        return poses, failed, 0 if watch is None else len(watch.retreats)

    return run


def pink_case(robot: wholebody.Robot) -> Callable | None:
    """pink's hierarchy from the neutral posture, or None without pink."""
    try:
        setup = peers.make_setup(robot)
    except ImportError:
        return None
    neutral = robot.neutral()
    jp = robot.joint_positions(neutral)
    home = {j: float(jp[robot.index(j)]) for j in setup.joints}
    setup = dataclasses.replace(setup, q0=neutral, home=home)
    try:
        case = peers.PinkCase(setup, "daqp", peers.SINGLE)
    except ImportError:
        return None
    for task in case.tasks[len(peers.HANDS) :]:  # posture and base: a weaker pull than the
        task.cost = task.cost * PINK_REGULARISATION  # hands', not a compromise with them

    def run(goal: list[np.ndarray], steps: int) -> tuple[list[np.ndarray], int, int]:
        case.reset()
        failed = 0
        for _ in range(steps):
            try:
                case.step(goal)
            except case._pink.exceptions.NoSolutionFound:
                failed += 1  # no step found: the robot stays (the final error counts it)
        poses = [case.conf.get_transform_frame_to_world(f).homogeneous for f in peers.HANDS]
        return poses, failed, 0

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=50, help="number of random targets")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=3.0, help="s per run")
    parser.add_argument("--engine", default="daqp",
                        help="the HQP cases' QP engine (daqp, proxsuite, osqp, ...)")  # fmt: skip
    parser.add_argument("--acceleration", action="store_true",
                        help="wholebody's stacks with the robot's acceleration limits")  # fmt: skip
    args = parser.parse_args()
    robot = wholebody.load_robot("mobile_humanoid")
    cases: dict[str, Callable] = {}
    for kind, recovery in (("paper", False), ("paper", True), ("hierarchy", False)):
        for backend in ("projection", "hqp"):
            engine = f" {args.engine}" if backend == "hqp" and args.engine != "daqp" else ""
            name = f"wholebody {kind}{' + recovery' if recovery else ''} {backend}{engine}"
            cases[name] = wholebody_case(robot, kind, backend, args.acceleration, recovery,
                                         args.engine)  # fmt: skip
    pink = pink_case(robot)
    if pink is not None:
        cases["pink single daqp"] = pink
    else:
        print("pink not installed (the bench extra): skipped")
    rng = np.random.default_rng(args.seed)
    steps = round(args.duration / DT)
    goals = [targets(robot, rng) for _ in range(args.n)]
    results, failed, retreats = {}, {}, {}
    for name, run in cases.items():
        runs = [run(g, steps) for g in goals]
        results[name] = np.array([errors(r[0], g) for r, g in zip(runs, goals, strict=True)])
        failed[name] = sum(r[1] for r in runs) / (steps * args.n)
        retreats[name] = sum(r[2] for r in runs)
    print(
        f"{args.n} random reachable targets (seed {args.seed}), {args.duration} s from the "
        f"neutral posture{' with acceleration limits' if args.acceleration else ''}; "
        f"converged: both hands within {POSITION_TOL * 1e3:g} mm and {ANGLE_TOL:g} rad"
    )
    print(f"{'case':<42} {'converged':>9}   position error mm p50 / p90 / max"
          f"   angle rad p50 / p90 / max   failed steps   retreats")  # fmt: skip
    ok = {}
    for name, e in results.items():
        ok[name] = (e[:, 0] <= POSITION_TOL) & (e[:, 1] <= ANGLE_TOL)
        p = np.percentile(e[:, 0] * 1e3, [50, 90, 100])
        r = np.percentile(e[:, 1], [50, 90, 100])
        print(f"{name:<42} {ok[name].mean():>8.0%}   {p[0]:8.2f} / {p[1]:8.2f} / {p[2]:8.1f}"
              f"   {r[0]:6.3f} / {r[1]:6.3f} / {r[2]:6.3f}   {failed[name]:>11.2%}"
              f"   {retreats[name]:>8}")  # fmt: skip
    if pink is not None:
        for name in (n for n in ok if n.startswith("wholebody")):
            only_pink = np.flatnonzero(ok["pink single daqp"] & ~ok[name]).tolist()
            only_wb = np.flatnonzero(ok[name] & ~ok["pink single daqp"]).tolist()
            print(f"{name}: pink only {only_pink}; wholebody only {only_wb}")


if __name__ == "__main__":
    main()
