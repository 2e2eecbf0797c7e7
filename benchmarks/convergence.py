#!/usr/bin/env python3
"""Convergence to random reachable targets with the defaults a user gets, against pink.

Each target sets both hands of ``mobile_humanoid`` to their tool poses at a random
configuration inside the joint limits (``random_configuration(margin=0.05, base_range=0.5)``:
reachable by construction, the base within 0.5 m with any heading). A run starts from the
neutral posture (arms hanging straight: singular) or from home, and lasts ``--duration`` s at
100 Hz. The hands get their targets as a **step** (the target from the first step) or as a
**minimum-jerk** reference from their start poses, ``--reference`` s long, then held. A run
**converges** when both hands end within 1 mm and 1e-2 rad of their targets.

wholebody, as a user writes it: ``paper_stack(robot, hands, acceleration=...)`` with
``FrameTask(robot, frame)`` hands and ``Controller(robot, stack, solver, dt=...)``, every other
argument at its default (which includes the stall recovery), on both backends (the HQP on
``--engine``), with the robot's acceleration limits off and on. ``--plain`` adds the same runs
with ``recovery=False``.

pink: hands and posture as weighted costs (``single`` of ``peers.py``, daqp), its posture and
base costs 100 times weaker than in ``peers.py`` (with those, the weighted compromise alone
leaves the hands millimetres off their targets), fed the same steps or references. pink has
no acceleration limits: its row is under "off" only. See ``peers.py`` for how its base is
matched.

    python benchmarks/convergence.py [--n N] [--seed S] [--duration T] [--reference T]
                                     [--engine daqp|proxsuite|osqp|qpsolvers:NAME] [--plain]

Prints the matrix of convergence rates (backend x start x reference x acceleration limits),
then per case the final position error percentiles (the worse hand), the runs that oscillate
at the end (a joint velocity, above 1e-3 rad/s or m/s, changing sign on more than 10 of the
last 100 steps) and the retreats.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import itertools
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pinocchio as pin

import wholebody
from wholebody.control import Controller
from wholebody.planning import MinimumJerkTrajectory
from wholebody.presets import paper_stack
from wholebody.solvers import ProjectionSolver
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import FrameTask

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers

DT = peers.DT
POSITION_TOL, ANGLE_TOL = 1e-3, 1e-2  # m, rad
TAIL, REVERSALS, SLOW = 100, 10, 1e-3  # oscillating: > 10 reversals in the last 100 steps
PINK_REGULARISATION = 1e-2  # pink's posture and base costs, times those of peers.py

Goal = list[np.ndarray]
Outcome = tuple[list[np.ndarray], bool, int]  # final hand poses, still moving, retreats


@dataclasses.dataclass(frozen=True)
class Run:
    """How a run starts and what it follows."""

    start: str  # "neutral" or "home"
    reference: str  # "step" or "min-jerk"
    steps: int
    reference_steps: int


def targets(robot: wholebody.Robot, rng: np.random.Generator) -> Goal:
    """Both tool poses (4x4, world) at a random configuration inside the limits."""
    q = robot.random_configuration(rng, margin=0.05, base_range=0.5)
    return [robot.frame_pose(q, f) for f in peers.HANDS]


def errors(poses: list[np.ndarray], goal: Goal) -> tuple[float, float]:
    """The worse hand's position (m) and orientation (rad) error."""
    p = max(float(np.linalg.norm(a[:3, 3] - b[:3, 3])) for a, b in zip(poses, goal, strict=True))
    r = max(
        float(np.linalg.norm(pin.log3(a[:3, :3].T @ b[:3, :3])))
        for a, b in zip(poses, goal, strict=True)
    )
    return p, r


def oscillates(u: np.ndarray) -> bool:
    """Whether some joint's velocity reversed (``u_k u_{k-1} < 0``, both above ``SLOW``) on
    more than ``REVERSALS`` of the last ``TAIL`` steps."""
    a, b = u[-TAIL - 1 : -1], u[-TAIL:]
    flips = (a * b < 0) & (np.abs(a) > SLOW) & (np.abs(b) > SLOW)
    return bool(flips.sum(axis=0).max() > REVERSALS)


def start_configuration(robot: wholebody.Robot, start: str) -> np.ndarray:
    return robot.neutral() if start == "neutral" else robot.home()


def references(robot: wholebody.Robot, q0: np.ndarray, goal: Goal, run: Run) -> list:
    """Per hand, a minimum-jerk trajectory from its pose at ``q0`` to its target."""
    return [
        MinimumJerkTrajectory(robot.frame_pose(q0, f), T, run.reference_steps * DT)
        for f, T in zip(peers.HANDS, goal, strict=True)
    ]


def wholebody_case(
    robot: wholebody.Robot, backend: str, acceleration: bool, recovery: bool, engine: str
) -> Callable[[Goal, Run], Outcome]:
    """A run of the defaults: the paper's stack, a plain Controller (``recovery`` False only
    for ``--plain``)."""

    def run_one(goal: Goal, run: Run) -> Outcome:
        solver = ProjectionSolver() if backend == "projection" else HierarchicalQPSolver(engine)
        hands = [FrameTask(robot, f) for f in peers.HANDS]
        stack = paper_stack(robot, hands, acceleration=acceleration)
        q = start_configuration(robot, run.start)
        refs = None
        if run.reference == "step":
            for hand, T in zip(hands, goal, strict=True):
                hand.set_target(T)
        else:
            refs = dict(zip(hands, references(robot, q, goal, run), strict=True))
        ctrl = Controller(robot, stack, solver, dt=DT, references=refs, recovery=recovery)
        u = np.zeros((run.steps, robot.nu))
        for k in range(run.steps):
            u[k] = ctrl.step(q)
            q = ctrl.q_next.copy()
        poses = [robot.frame_pose(q, f) for f in peers.HANDS]
        retreats = 0 if ctrl.recovery is None else len(ctrl.recovery.retreats)
        return poses, oscillates(u), retreats

    return run_one


def pink_case(robot: wholebody.Robot, start: str) -> Callable[[Goal, Run], Outcome] | None:
    """pink's weighted problem from ``start``, or None without pink."""
    try:
        setup = peers.make_setup(robot)
    except ImportError:
        return None
    q0 = start_configuration(robot, start)
    jp = robot.joint_positions(q0)
    home = {j: float(jp[robot.index(j)]) for j in setup.joints}
    try:
        case = peers.PinkCase(dataclasses.replace(setup, q0=q0, home=home), "daqp", peers.SINGLE)
    except ImportError:
        return None
    for task in case.tasks[len(peers.HANDS) :]:  # posture and base: a weaker pull than the
        task.cost = task.cost * PINK_REGULARISATION  # hands', not a compromise with them

    def run_one(goal: Goal, run: Run) -> Outcome:
        case.reset()
        refs = references(robot, q0, goal, run) if run.reference == "min-jerk" else None
        v = []
        for k in range(run.steps):
            now = goal if refs is None else [r.sample(k * DT).pose for r in refs]
            with contextlib.suppress(case._pink.exceptions.NoSolutionFound):
                case.step(now)  # (no step found: the robot stays; the final error counts it)
            v.append(case.velocity())
        poses = [case.conf.get_transform_frame_to_world(f).homogeneous for f in peers.HANDS]
        return poses, oscillates(np.array(v)), 0

    return run_one


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=50, help="number of random targets")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=6.0, help="s per run")
    parser.add_argument(
        "--reference", type=float, default=3.0, help="s of the minimum-jerk references"
    )
    parser.add_argument(
        "--engine", default="daqp", help="the HQP's QP engine (daqp, proxsuite, osqp, ...)"
    )
    parser.add_argument("--plain", action="store_true", help="also the runs with recovery=False")
    args = parser.parse_args()
    robot = wholebody.load_robot("mobile_humanoid")
    rng = np.random.default_rng(args.seed)
    goals = [targets(robot, rng) for _ in range(args.n)]
    steps, ref_steps = round(args.duration / DT), round(args.reference / DT)
    recoveries = (True, False) if args.plain else (True,)
    rates: dict[tuple[str, str, str, bool], float] = {}
    rows = []
    for start, reference in itertools.product(("neutral", "home"), ("step", "min-jerk")):
        run = Run(start, reference, steps, ref_steps)
        cases: dict[tuple[str, bool], Callable[[Goal, Run], Outcome] | None] = {}
        for backend, recovery, acc in itertools.product(
            ("projection", "hqp"), recoveries, (False, True)
        ):
            name = backend + ("" if recovery else ", recovery=False")
            cases[(name, acc)] = wholebody_case(robot, backend, acc, recovery, args.engine)
        cases[("pink", False)] = pink_case(robot, start)
        for (name, acc), case in cases.items():
            if case is None:
                continue
            out = [case(g, run) for g in goals]
            e = np.array([errors(o[0], g) for o, g in zip(out, goals, strict=True)])
            ok = (e[:, 0] <= POSITION_TOL) & (e[:, 1] <= ANGLE_TOL)
            rates[(name, start, reference, acc)] = ok.mean()
            rows.append(
                (
                    name,
                    start,
                    reference,
                    acc,
                    ok.mean(),
                    e,
                    sum(o[1] for o in out),
                    sum(o[2] for o in out),
                )
            )
    print(
        f"{args.n} random reachable targets (seed {args.seed}), {args.duration:g} s runs, "
        f"minimum-jerk references of {args.reference:g} s; converged: both hands within "
        f"{POSITION_TOL * 1e3:g} mm and {ANGLE_TOL:g} rad"
    )
    print(
        f"\n{'case':<32} {'start':<8} {'reference':<9} {'acc. limits off':>15} "
        f"{'acc. limits on':>15}"
    )
    for name, start, reference in dict.fromkeys((r[0], r[1], r[2]) for r in rows):
        cells = [rates.get((name, start, reference, acc)) for acc in (False, True)]
        text = [f"{c:>15.0%}" if c is not None else f"{'n/a':>15}" for c in cells]
        print(f"{name:<32} {start:<8} {reference:<9} {text[0]} {text[1]}")
    print(
        f"\n{'case':<32} {'start':<8} {'reference':<9} {'acc':<4} {'converged':>9}   "
        f"position error mm p50 / p90 / max   oscillating   retreats"
    )
    for name, start, reference, acc, rate, e, oscillating, retreats in rows:
        p = np.percentile(e[:, 0] * 1e3, [50, 90, 100])
        print(
            f"{name:<32} {start:<8} {reference:<9} {'on' if acc else 'off':<4} {rate:>9.0%}"
            f"   {p[0]:8.2f} / {p[1]:8.2f} / {p[2]:8.1f}   {oscillating:>11}"
            f"   {retreats:>8}"
        )


if __name__ == "__main__":
    main()
