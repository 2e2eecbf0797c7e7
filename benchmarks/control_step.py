#!/usr/bin/env python3
"""Time one full control step of the paper's robot, per backend, in one interleaved run.

A step is: kinematics at q, the hand targets, the stack (both hand tasks, both arm energies,
h1, h2 where the stack has them), the solve and the integration: what a real controller
does every period. Every case follows the same target sequence (both hands on
minimum-jerk reaches, repeated), its own state evolving. Two schedules, both in the same run
(as in ``benchmarks/peers.py``):

* **step-interleaved** (cold): the cases take turns step by step, so every step starts after
  six other stacks have run, with cold caches, as in a controller that shares its machine
  with a simulator or other processes between two periods;
* **block-interleaved** (warm): the cases take turns every ``BLOCK`` (50) steps, so a step
  follows steps of its own stack, as in a tight simulation loop.

Each repeat runs both schedules, one after the other, so that machine noise (which drifts
over seconds on this shared host) hits all the cases and both schedules alike. Printed:
median and p90 per case (us) and the ratio of medians to the plain pseudo-inverse measured
in the same schedule and run.

    python benchmarks/control_step.py [--steps N] [--repeat R]

Add a case by appending to ``CASES``: ``(name, factory)``, the factory building
``(stack, solver)`` from the robot and the two hand tasks.
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Callable

import numpy as np
import pinocchio as pin

import wholebody
from wholebody.planning.dual_arm import CoordinatedTrajectory
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.presets import PaperWeights, paper_metric, paper_stack
from wholebody.solvers import Level, ProjectionSolver, Solver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import (
    ArmPotentialEnergy,
    FrameTask,
    JointLimitAvoidance,
    JointPositionLimits,
    PostureTask,
    RelativeFrameTask,
    VelocityLimits,
)

DT = 0.01
BLOCK = 50  # steps of one case in a row in the warm schedule
PAPER = PaperWeights(manipulability=0.05)  # the full H = w1 f_p + w2 h1 - w3 h2

Factory = Callable[[wholebody.Robot, list[FrameTask]], tuple[Stack, Solver]]


def pinv(robot, hands):
    return paper_stack(robot, hands, objectives=False), ProjectionSolver()


def projection(robot, hands):
    return paper_stack(robot, hands, weights=PAPER, stiffness=0.1), ProjectionSolver()


def hqp_paper(robot, hands):
    return paper_stack(robot, hands, weights=PAPER, stiffness=0.1), HierarchicalQPSolver("daqp")


def closed_chain(robot, hands):
    """The closed chain between the hands, its target their relative pose at home: the hand
    references carry a rigid object (see :func:`hand_references`), so the three tasks of the
    first level agree exactly."""
    chain = RelativeFrameTask(robot, hands[0].frame, hands[1].frame, kp=20.0, name="closed_chain")
    q0 = robot.home()
    chain.set_target(np.linalg.solve(robot.frame_pose(q0, hands[0].frame),
                                     robot.frame_pose(q0, hands[1].frame)))  # fmt: skip
    return chain


def three_levels(robot, hands):
    """Hands and the closed chain; arm energy; posture and joint-limit avoidance.

    The first level is redundant (12 independent rows of 18): the hands' and the chain's
    feedback agree only to second order in the tracking error, so its least-squares residual
    is ~1e-5 and the solvers report INFEASIBLE (tolerance 1e-6) on most steps while both
    hands track to 0.07 mm. The scenarios put the chain in a level above the hands instead."""
    energy = [ArmPotentialEnergy(robot, arm, 0.1, weight=0.5) for arm in robot.arms]
    return Stack(
        robot,
        [
            Level((*hands, closed_chain(robot, hands)), name="hands"),
            Level(energy, gain=1.0, name="energy"),
            Level((PostureTask(robot, kp=1.0), JointLimitAvoidance(robot, weight=0.05)),
                  gain=1.0, name="posture"),
        ],
        [JointPositionLimits(robot), VelocityLimits(robot)],
        metric=paper_metric(robot),
    )  # fmt: skip


def hqp_three_levels(engine):
    def factory(robot, hands):
        return three_levels(robot, hands), HierarchicalQPSolver(engine)

    return factory


def hierarchy(backend: str, scale: float) -> Factory:
    """Hands above posture, velocity limits scaled by ``scale``: 0.05 makes a bound active on
    almost every step (the tight case: saturation in the projection, pins in the HQP)."""

    def factory(robot, hands):
        limits = [JointPositionLimits(robot), VelocityLimits(robot, scale=scale)]
        stack = Stack(robot, [Level(hands, name="hands"), Level([PostureTask(robot, kp=1.0)])],
                      limits)  # fmt: skip
        solver = ProjectionSolver() if backend == "projection" else HierarchicalQPSolver(backend)
        return stack, solver

    return factory


CASES: list[tuple[str, Factory]] = [
    ("pinv (plain pseudo-inverse)", pinv),
    ("projection (paper's stack)", projection),
    ("hqp daqp (paper's stack)", hqp_paper),
    (
        "projection (3 levels)",
        lambda robot, hands: (three_levels(robot, hands), ProjectionSolver()),
    ),
    ("hqp daqp (3 levels)", hqp_three_levels("daqp")),
    ("hqp proxsuite (3 levels)", hqp_three_levels("proxsuite")),
    ("hqp osqp (3 levels)", hqp_three_levels("osqp")),
    ("projection (hierarchy, free)", hierarchy("projection", 1.0)),
    ("projection (hierarchy, tight)", hierarchy("projection", 0.05)),
    ("hqp daqp (hierarchy, free)", hierarchy("daqp", 1.0)),
    ("hqp daqp (hierarchy, tight)", hierarchy("daqp", 0.05)),
]


def hand_references(robot):
    """The right hand on a minimum-jerk reach (up, forward, turned), the left hand carried
    rigidly with it (both hands hold one object: a consistent closed chain)."""
    q0 = robot.home()
    left, right = robot.frame_pose(q0, "left_tool"), robot.frame_pose(q0, "right_tool")
    end = right.copy()
    end[:3, 3] += (0.15, 0.05, 0.2)
    end[:3, :3] = pin.exp3(np.array([0.0, -0.3, 0.2])) @ right[:3, :3]
    primary = MinimumJerkTrajectory(right, end, 2.0)
    secondary = CoordinatedTrajectory(primary, np.eye(4), np.linalg.solve(left, right))
    return q0, [secondary, primary]


def forth_and_back(refs, t: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pose and twist of each reference at ``t``, played forth and back (continuous)."""
    period = refs[0].duration
    phase = t % (2 * period)
    back = phase > period
    samples = [ref.sample(2 * period - phase if back else phase) for ref in refs]
    return [(s.pose, -s.twist if back else s.twist) for s in samples]


def run(steps: int, repeat: int) -> None:
    robot = wholebody.load_robot("mobile_humanoid")
    q0, refs = hand_references(robot)
    runs = []
    for name, factory in CASES:
        hands = [FrameTask(robot, "left_tool", kp=20.0), FrameTask(robot, "right_tool", kp=20.0)]
        stack, solver = factory(robot, hands)
        runs.append({"name": name, "stack": stack, "solver": solver, "hands": hands,
                     "cold": [], "warm": []})  # fmt: skip
    samples = [forth_and_back(refs, k * DT) for k in range(steps)]

    placo = placo_case()
    if placo is not None:
        case, targets = placo
        runs.append({"name": "placo (peers.py hierarchy)", "peer": case, "targets": targets,
                     "cold": [], "warm": []})  # fmt: skip

    def steps_of(r: dict, ks: range, out: list[float]) -> None:
        """Steps ``ks`` of case ``r`` from its current state (``r["q"]``)."""
        if "peer" in r:
            return peer_steps(r["peer"], r["targets"], ks, out)
        hands, stack, solver = r["hands"], r["stack"], r["solver"]
        q = r["q"]
        for k in ks:
            start = time.perf_counter()
            for hand, (pose, twist) in zip(hands, samples[k], strict=True):
                hand.set_target(pose, twist)
            state = robot.update(q)
            result = solver.solve(stack, state, DT)
            stack.advance(state, DT, result=result)
            q = robot.integrate(q, result.u, DT)
            out.append(time.perf_counter() - start)
            r["bounds"] = r.get("bounds", 0) + result.limit_hit
        r["q"] = q

    for _ in range(repeat):
        for schedule in ("cold", "warm"):
            for r in runs:
                r["q"] = q0.copy()
                if "peer" in r:
                    r["peer"].reset()
                else:
                    r["stack"].reset()
            size = 1 if schedule == "cold" else BLOCK
            for k in range(0, steps, size):
                for r in runs:
                    steps_of(r, range(k, min(k + size, steps)), r[schedule])
    print(
        f"control step, mobile_humanoid (nu = {robot.nu}), dt = {DT} s, "
        f"{steps} steps x {repeat}, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}"
    )
    cols = f"{'median us':>10s} {'p90 us':>9s} {'x pinv':>7s} {'Hz':>7s} {'x placo':>8s}"
    print(f"{'':42s} {'step-interleaved (cold)':^36s}  {'block-interleaved (warm)':^36s}".rstrip())
    print(f"{'case':42s} {cols}  {cols}")
    base = {sch: float(np.median(runs[0][sch])) * 1e6 for sch in ("cold", "warm")}
    ref = {sch: float(np.median(runs[-1][sch])) * 1e6 if placo else np.nan
           for sch in ("cold", "warm")}  # fmt: skip
    for r in runs:
        line = f"{r['name']:42s}"
        for sch in ("cold", "warm"):
            t = np.asarray(r[sch]) * 1e6
            med = float(np.median(t))
            line += (f" {med:10.1f} {np.percentile(t, 90):9.1f} {med / base[sch]:7.2f} "
                     f"{1e6 / med:7.0f} {med / ref[sch]:8.2f} ")  # fmt: skip
        if "bounds" in r:
            line += f" bounds on {100 * r['bounds'] / (2 * steps * repeat):.0f} % of steps"
        print(line.rstrip())
    if placo is None:
        print("placo not installed (pip install '.[bench]'): no x placo column")
    print("paper (Table 2 / Sec. 5.2): pseudo-inverse 343.46 Hz, paper's method 40.55 Hz")


def placo_case():
    """placo on peers.py's 2-level hierarchy (hands strictly above posture, same robot) and
    its reference's targets (one reach forth and back), or None when placo is not installed:
    the yardstick of the "x placo" column."""
    import peers

    if peers.peer_available("placo") is not None:
        return None
    setup = peers.make_setup()
    case = peers.build_case(setup, "placo", "eiquadprog", peers.HIERARCHY)
    return case, [setup.targets(k) for k in range(2 * peers.PERIOD)]


def peer_steps(case, targets: list, ks: range, out: list[float]) -> None:
    """Steps ``ks`` of a peers.py case along ``targets`` (repeated)."""
    for k in ks:
        target = targets[k % len(targets)]
        start = time.perf_counter()
        case.step(target)
        out.append(time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    run(args.steps, args.repeat)


if __name__ == "__main__":
    main()
