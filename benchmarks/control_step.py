#!/usr/bin/env python3
"""Time one full control step of the paper's robot, per backend, in one interleaved run.

A step is: the hand targets (``set_target``), then ``Controller.step``: kinematics at q, the
stack (both hand tasks, both arm energies, h1, h2 where the stack has them), the solve, the
integrals and the integration in one kernel call: what a real controller does every period.
Every case follows the same target sequence (both hands on minimum-jerk reaches, repeated),
its own state evolving. Two schedules, both in the same run
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

Then, in a second interleaved run (the humanoid's table is measured without them), **real
robots against pink**: robots of ``robots/`` whose URDFs ship in example-robot-data
(``--robots``, default TIAGo++ ``tiago_dual`` and the TALOS upper body ``talos_upper``; also
``tiago_dual_fixed``). Per robot, wholebody (projection and HQP daqp) and pink (daqp) solve
``benchmarks/peers.py``'s problem (both hands' 6-D tasks on the arms' tool frames, dead-beat,
a weak posture regularisation, joint position and velocity limits; ``single`` weighted QP and
``hierarchy`` hands above posture) on the same Pinocchio model (``robot.model``), the hands
going forth and back by a few cm from the home posture. Printed per case: median and p90 (us)
in both schedules and the ratios of each wholebody median to pink's on the same robot,
problem and schedule (``wb/pink``, ``pink/wb``); then peers.py's agreement check (every
case's hands against wholebody's HQP, tolerance 0.1 mm) and the largest share of a bound
used along the reference (none is active, so all backends solve the same least squares).
TIAGo++'s differential base is kept: pink gets the planar root's twist with the lateral
velocity held at zero by an equality, the wheels' regularisation and speed limits through
``B^+`` (see ``peers.RobotSetup``); ``tiago_dual_fixed`` holds the base still instead
(robot.toml without ``[base]``, wheels locked). Skipped with a line when example-robot-data
(``pip install '.[robots]'``) or pink (``'.[bench]'``) is missing.

    python benchmarks/control_step.py [--steps N] [--repeat R] [--robots A,B | none]
                                      [--only-robots] [--check-steps M]

Add a case by appending to ``CASES``: ``(name, factory)``, the factory building
``(stack, solver)`` from the robot and the two hand tasks; a real robot by adding a
``RobotPlan`` to peers.py's ``ROBOTS``.
"""

from __future__ import annotations

import argparse
import platform
import textwrap
import time
from collections.abc import Callable

import numpy as np
import pinocchio as pin

import wholebody
from wholebody.control import Controller
from wholebody.planning.dual_arm import CoordinatedTrajectory
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.presets import PaperWeights, paper_metric, paper_stack
from wholebody.solvers import Level, ProjectionSolver, Solver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import (
    ArmPotentialEnergy,
    CollisionAvoidance,
    FrameTask,
    JointLimitAvoidance,
    JointPositionLimits,
    PostureTask,
    RelativeFrameTask,
    VelocityLimits,
)

DT = 0.01
BLOCK = 50  # steps of one case in a row in the warm schedule
ROBOTS = "tiago_dual,talos_upper"  # the real robots against pink (peers.py's ROBOTS)
PAPER = PaperWeights(manipulability=0.05)  # the full H = w1 f_p + w2 h1 - w3 h2

Factory = Callable[[wholebody.Robot, list[FrameTask]], tuple[Stack, Solver]]


def pinv(robot, hands):
    return paper_stack(robot, hands, objectives=False), ProjectionSolver()


def projection(robot, hands):
    return paper_stack(robot, hands, weights=PAPER, stiffness=0.1), ProjectionSolver()


def hqp_paper(robot, hands):
    return paper_stack(robot, hands, weights=PAPER, stiffness=0.1), HierarchicalQPSolver("daqp")


def collision(backend: str) -> Factory:
    """The paper's stack under a level of :class:`CollisionAvoidance` (the robot's own pairs:
    self-collision, 5 cm influence)."""

    def factory(robot, hands):
        stack = paper_stack(
            robot, hands, weights=PAPER, stiffness=0.1, collision=CollisionAvoidance(robot)
        )
        return stack, (
            ProjectionSolver() if backend == "projection" else HierarchicalQPSolver(backend)
        )

    return factory


def closed_chain(robot, hands):
    """The closed chain between the hands, its target their relative pose at home: the hand
    references carry a rigid object (see :func:`hand_references`), so the three tasks of the
    first level agree exactly."""
    chain = RelativeFrameTask(robot, hands[0].frame, hands[1].frame, kp=20.0, name="closed_chain")
    q0 = robot.home()
    chain.set_target(
        np.linalg.solve(robot.frame_pose(q0, hands[0].frame), robot.frame_pose(q0, hands[1].frame))
    )
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
            Level(
                (PostureTask(robot, kp=1.0), JointLimitAvoidance(robot, weight=0.05)),
                gain=1.0,
                name="posture",
            ),
        ],
        [JointPositionLimits(robot), VelocityLimits(robot)],
        metric=paper_metric(robot),
    )


def hqp_three_levels(engine):
    def factory(robot, hands):
        return three_levels(robot, hands), HierarchicalQPSolver(engine)

    return factory


def hierarchy(backend: str, scale: float) -> Factory:
    """Hands above posture, velocity limits scaled by ``scale``: 0.05 makes a bound active on
    almost every step (the tight case: saturation in the projection, pins in the HQP)."""

    def factory(robot, hands):
        limits = [JointPositionLimits(robot), VelocityLimits(robot, scale=scale)]
        stack = Stack(
            robot, [Level(hands, name="hands"), Level([PostureTask(robot, kp=1.0)])], limits
        )
        solver = ProjectionSolver() if backend == "projection" else HierarchicalQPSolver(backend)
        return stack, solver

    return factory


CASES: list[tuple[str, Factory]] = [
    ("pinv (plain pseudo-inverse)", pinv),
    ("projection (paper's stack)", projection),
    ("hqp daqp (paper's stack)", hqp_paper),
    ("projection (paper's stack + collision)", collision("projection")),
    ("hqp daqp (paper's stack + collision)", collision("daqp")),
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
        controller = Controller(robot, stack, solver, dt=DT)
        runs.append(
            {
                "name": name,
                "stack": stack,
                "controller": controller,
                "hands": hands,
                "cold": [],
                "warm": [],
            }
        )
    samples = [forth_and_back(refs, k * DT) for k in range(steps)]

    placo = placo_case()
    if placo is not None:
        case, targets = placo
        runs.append(
            {
                "name": "placo (peers.py hierarchy)",
                "peer": case,
                "targets": targets,
                "cold": [],
                "warm": [],
            }
        )

    def steps_of(r: dict, ks: range, out: list[float]) -> None:
        """Steps ``ks`` of case ``r`` from its current state (``r["q"]``)."""
        if "peer" in r:
            return peer_steps(r["peer"], r["targets"], ks, out)
        hands, controller = r["hands"], r["controller"]
        q = r["q"]
        for k in ks:
            start = time.perf_counter()
            for hand, (pose, twist) in zip(hands, samples[k], strict=True):
                hand.set_target(pose, twist)
            controller.step(q)
            q = controller.q_next.copy()
            out.append(time.perf_counter() - start)
            r["bounds"] = r.get("bounds", 0) + controller.result.limit_hit  # untimed
        r["q"] = q

    def reset(r: dict) -> None:
        r["q"] = q0.copy()
        if "peer" in r:
            r["peer"].reset()
        else:
            r["controller"].reset()

    interleave(runs, steps, repeat, steps_of, reset)
    print(
        f"control step, mobile_humanoid (nu = {robot.nu}), dt = {DT} s, "
        f"{steps} steps x {repeat}, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}"
    )
    cols = f"{'median us':>10s} {'p90 us':>9s} {'x pinv':>7s} {'Hz':>7s} {'x placo':>8s}"
    print(f"{'':42s} {'step-interleaved (cold)':^36s}  {'block-interleaved (warm)':^36s}".rstrip())
    print(f"{'case':42s} {cols}  {cols}")
    base = {sch: float(np.median(runs[0][sch])) * 1e6 for sch in ("cold", "warm")}
    ref = {
        sch: float(np.median(runs[-1][sch])) * 1e6 if placo else np.nan for sch in ("cold", "warm")
    }
    for r in runs:
        line = f"{r['name']:42s}"
        for sch in ("cold", "warm"):
            t = np.asarray(r[sch]) * 1e6
            med = float(np.median(t))
            line += (
                f" {med:10.1f} {np.percentile(t, 90):9.1f} {med / base[sch]:7.2f} "
                f"{1e6 / med:7.0f} {med / ref[sch]:8.2f} "
            )
        if "bounds" in r:
            line += f" bounds on {100 * r['bounds'] / (2 * steps * repeat):.0f} % of steps"
        print(line.rstrip())
    if placo is None:
        print("placo not installed (pip install '.[bench]'): no x placo column")
    print("paper (Table 2 / Sec. 5.2): pseudo-inverse 343.46 Hz, paper's method 40.55 Hz")


def interleave(
    runs: list[dict],
    steps: int,
    repeat: int,
    steps_of: Callable[[dict, range, list[float]], None],
    reset: Callable[[dict], None],
) -> None:
    """Time ``steps`` steps of every case in ``runs``, ``repeat`` times in both schedules:
    taking turns step by step (step times appended to ``r["cold"]``), then every ``BLOCK``
    steps (``r["warm"]``); each case is ``reset`` before each schedule, so that drifts of the
    machine's speed hit every case and both schedules alike."""
    for _ in range(repeat):
        for schedule in ("cold", "warm"):
            for r in runs:
                reset(r)
            size = 1 if schedule == "cold" else BLOCK
            for k in range(0, steps, size):
                for r in runs:
                    steps_of(r, range(k, min(k + size, steps)), r[schedule])


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


# ---------------------------------------------------------------------- real robots
def robot_rows(names: list[str], steps: int, repeat: int, check_steps: int) -> None:
    """wholebody against pink on robots of robots/ (peers.py's ``ROBOTS``), each robot's
    cases of both libraries in one interleaved run (all robots together, both schedules),
    then the agreement check; a robot whose URDF is not installed is skipped with a line, and
    all of them without pink (the rows are ratios to pink)."""
    import peers

    why = peers.peer_available("pink")
    if why is not None:
        print(
            f"\nskipped the real robots ({', '.join(names)}): pink is not installed ({why}); "
            "pip install '.[bench]'"
        )
        return
    setups = []
    for name in names:
        missing = peers.robot_available(name)
        if missing is None:
            setups.append(peers.make_robot_setup(name))
        else:
            print(f"\nskipped {name}: {missing}")
    if not setups:
        return
    runs, checks = [], {}
    for setup in setups:
        cases = peers.build_robot_cases(setup)
        checks[setup.name] = robot_check(setup, cases, check_steps)
        targets = [setup.targets(k) for k in range(2 * peers.PERIOD)]
        runs.extend(
            {"setup": setup, "peer": c, "targets": targets, "cold": [], "warm": []} for c in cases
        )

    def steps_of(r: dict, ks: range, out: list[float]) -> None:
        peer_steps(r["peer"], r["targets"], ks, out)

    interleave(runs, steps, repeat, steps_of, lambda r: r["peer"].reset())
    print_robot_table(setups, runs, steps, repeat)
    print_robot_check(setups, checks, check_steps)


def robot_check(setup, cases: list, steps: int) -> tuple[dict, dict]:
    """peers.py's agreement check on the robot's reference (every case against wholebody's
    HQP on the same problem), and the largest share of a position and a velocity bound
    wholebody's HQP uses along it, per problem (below 1: no bound active, so that the
    projection, the HQP and pink solve the same least squares)."""
    import peers

    check = peers.run_check(setup, cases, steps)
    use = {
        p: peers.limit_use(setup, peers.reference_case(cases, p), steps)
        for p in (peers.SINGLE, peers.HIERARCHY)
    }
    return check, use


def case_label(case) -> str:
    """``wholebody projection``, ``wholebody hqp daqp`` or ``pink daqp``."""
    backend = "hqp daqp" if case.library == "wholebody" and case.backend == "daqp" else case.backend
    return f"{case.library} {backend}"


def print_robot_table(setups: list, runs: list[dict], steps: int, repeat: int) -> None:
    """Median and p90 per case and schedule, and the ratios of each wholebody case's median
    to pink's on the same robot, problem and schedule (``wb/pink``) and back (``pink/wb``)."""
    import peers

    print(
        f"\nreal robots against pink, dt = {DT} s, {steps} steps x {repeat}, the {len(runs)} "
        "cases interleaved (robots/NAME/robot.toml, URDFs from example-robot-data)"
    )
    print(
        f"problem (peers.py's): 2 hand tasks (6-D, w = {peers.W_HAND:g}, dead-beat) + posture "
        f"(w = {peers.W_POSTURE:g}) + joint position/velocity limits\n  single: one weighted "
        "QP; hierarchy: hands strictly above posture; pink on wholebody's Pinocchio model "
        "(robot.model)\nbase per robot:"
    )
    for setup in setups:
        note = f"u = {setup.robot.nu}, {setup.base}"
        print(
            textwrap.fill(
                note, 100, initial_indent=f"  {setup.name:17s}", subsequent_indent=" " * 19
            )
        )
    cols = f"{'median us':>10s} {'p90 us':>9s} {'wb/pink':>8s} {'pink/wb':>8s}"
    print(f"{'':48s} {'step-interleaved (cold)':^39s}  {'block-interleaved (warm)':^39s}".rstrip())
    print(f"{'robot':16s} {'problem':10s} {'case':20s} {cols}  {cols}")
    for r in runs:
        case = r["peer"]
        pink = next(
            p
            for p in runs
            if p["setup"] is r["setup"]
            and p["peer"].library == "pink"
            and p["peer"].problem == case.problem
        )
        line = f"{r['setup'].name:16s} {case.problem:10s} {case_label(case):20s}"
        for sch in ("cold", "warm"):
            t = np.asarray(r[sch]) * 1e6
            med, ref = float(np.median(t)), float(np.median(pink[sch])) * 1e6
            ratios = (
                f"{med / ref:8.2f} {ref / med:8.2f}"
                if case.library != "pink"
                else f"{'':8s} {'':8s}"
            )
            line += f" {med:10.1f} {np.percentile(t, 90):9.1f} {ratios} "
        print(line.rstrip())
    print(
        "wb/pink: the case's median over pink daqp's median on the same robot and problem, same "
        "schedule and run (below 1: wholebody faster); pink/wb: its inverse"
    )


def print_robot_check(setups: list, checks: dict, steps: int) -> None:
    """The agreement check (tolerance 0.1 mm, as peers.py) and the bounds' use per robot."""
    print(
        f"\nagreement over {steps} steps of each robot's reference (max over steps and hands "
        "of the distance to wholebody daqp's hand, same problem; tolerance 0.1 mm)"
    )
    print(
        f"{'robot':16s} {'case':32s} {'max dev mm':>11s} {'1-step rel dv':>14s} "
        f"{'tracking mm':>12s}  ok"
    )
    for setup in setups:
        check, _ = checks[setup.name]
        for name, r in check.items():
            ok = "yes" if r["deviation"] <= 1e-4 else "NO"
            print(
                f"{setup.name:16s} {name:32s} {r['deviation'] * 1e3:11.5f} "
                f"{r['first_step_dv']:14.2e} {r['tracking'] * 1e3:12.3f}  {ok}"
            )
    print(
        "largest share of a bound wholebody daqp uses along the reference (1: active; position: "
        "|u| dt over the step the position limit allows)"
    )
    for setup in setups:
        _, use = checks[setup.name]
        text = ", ".join(
            f"{p}: position {pos:.3f}, velocity {vel:.3f}" for p, (pos, vel) in use.items()
        )
        print(f"  {setup.name:17s}{text}")


def robot_names(text: str) -> list[str]:
    """``--robots``: comma-separated names of peers.py's ``ROBOTS``; ``none`` (or empty):
    no real robot."""
    import peers

    names = [n.strip() for n in text.split(",") if n.strip() and n.strip() != "none"]
    unknown = [n for n in names if n not in peers.ROBOTS]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown robot(s) {', '.join(unknown)}; expected {', '.join(peers.ROBOTS)} or none"
        )
    return names


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--robots",
        type=robot_names,
        default=ROBOTS,
        help="real robots against pink, comma-separated (peers.py's ROBOTS: "
        "tiago_dual, tiago_dual_fixed, talos_upper); none: skip them "
        f"(default {ROBOTS})",
    )
    parser.add_argument(
        "--only-robots",
        action="store_true",
        help="only the real robots (skip mobile_humanoid's table)",
    )
    parser.add_argument(
        "--check-steps",
        type=int,
        default=None,
        help="steps of the robots' agreement check (default: --steps)",
    )
    args = parser.parse_args()
    if not args.only_robots:
        run(args.steps, args.repeat)
    if args.robots:
        robot_rows(args.robots, args.steps, args.repeat, args.check_steps or args.steps)


if __name__ == "__main__":
    main()
