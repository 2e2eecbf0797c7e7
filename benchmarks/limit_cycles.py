#!/usr/bin/env python3
"""A stalled lower level under a closed chain: does the command settle or cycle?

Both hands of a two-armed robot hold their relative pose (a closed chain, level 1) while one
hand's pose task (level 2) is sent to a target its wrist and elbow cannot reach while the
chain holds: a rotation of ``--rotation`` rad about the world ``--axis`` (x by default) and
``--lift`` m up.
Joint position and velocity limits are constraints. The lower level stalls against the limits
and the chain. The run reports, from the second ``--settle`` on (the stall), the steps where
some actuated velocity reversed sign (both magnitudes above 1e-3 rad/s:
:func:`wholebody.control.metrics.u_reversals`), the largest ``|u|`` at the end, the chain's
position error (m), the largest limit overshoot and the median control step (us); over the
whole run, the reversals too.

    python benchmarks/limit_cycles.py [--robot mobile_humanoid] [--duration 5] [--settle 2]
        [--rotation 1.5] [--axis 1 0 0] [--lift 0.05] [--damping 0.1 0]
        [--engines daqp proxsuite osqp] [--projection]

TIAGo++ (``--robot tiago_dual --axis 0 0 1 --rotation -1``, example-robot-data) cycles with
its wrists at their velocity limits.

``--damping`` lists the HQP's ``stall_damping`` values to run (0: the exact lexicographic
solve, which cycles); the projection backend runs with its defaults. ``--targets N`` then
runs N random targets for the hand (:func:`targets`, reachable or not) with each solver and
prints the targets reached, the runs still cycling at the end, the final ``|u|`` and chain
error.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from functools import partial

import numpy as np
import pinocchio as pin

import wholebody as wb
from wholebody.control.metrics import closed_chain_error, limit_overshoot, u_reversals
from wholebody.solvers.base import Solver
from wholebody.solvers.hqp import STALL_DAMPING


def stalled_run(
    robot: wb.Robot,
    solver: Solver,
    *,
    rotation: float = 1.5,
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0),
    shift: tuple[float, float, float] = (0.0, 0.0, 0.05),
    duration: float = 3.0,
    dt: float = 0.01,
) -> tuple[wb.RunLog, wb.Controller]:
    """The closed chain on level 1, the right hand's pose on level 2 sent to the home pose
    turned by ``rotation`` rad about the world ``axis`` (a unit vector) and moved by ``shift``
    (m, world); position and velocity limits. Returns the run's log (the tasks are named
    ``"chain"`` and ``"hand"``) and the controller."""
    left, right = robot.arms["left"].tool, robot.arms["right"].tool
    q0 = robot.home()
    chain = wb.RelativeFrameTask(robot, left, right, name="chain", kp=10.0)
    hand = wb.FrameTask(robot, right, name="hand", kp=10.0)
    TL, TR = robot.frame_pose(q0, left), robot.frame_pose(q0, right)
    chain.set_target(np.linalg.solve(TL, TR))
    goal = TR.copy()
    goal[:3, :3] = pin.exp3(rotation * np.asarray(axis, dtype=float)) @ TR[:3, :3]
    goal[:3, 3] += shift
    hand.set_target(goal)
    limits = [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)]
    stack = wb.Stack(robot, [[chain], [hand]], limits)
    controller = wb.Controller(robot, stack, solver, dt=dt, recovery=False)  # (the solver alone)
    return controller.run(q0, duration), controller


def report(log: wb.RunLog, settle: float) -> dict[str, float]:
    """The figures of a stalled run, the stall taken from ``settle`` s on."""
    k0 = round(settle / log.dt)
    u = log.u
    return {
        "reversals": u_reversals(u),
        "reversals_stalled": u_reversals(u[k0:]),
        "stalled_steps": len(u) - k0,
        "u_final": float(np.max(np.abs(u[-1]))),
        "u_max_last_0.5s": float(np.max(np.abs(u[-round(0.5 / log.dt) :]))),
        "chain_final_m": closed_chain_error(log, "chain", np.arange(len(u)) == len(u) - 1),
        "chain_max_stalled_m": closed_chain_error(log, "chain", np.arange(len(u)) >= k0),
        "limit_overshoot": limit_overshoot(log),
        "step_us": float(np.median(log.step_time) * 1e6),
    }


def targets(n: int, seed: int) -> list[tuple[float, tuple[float, ...], tuple[float, ...]]]:
    """``n`` random targets ``(rotation, axis, shift)``: a rotation of up to 2 rad about a
    random axis and a shift of up to 0.15 m along each world axis (reachable or not)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        rotation = rng.uniform(0.0, 2.0)
        out.append((rotation, tuple(axis), tuple(rng.uniform(-0.15, 0.15, 3))))
    return out


def sweep(robot: wb.Robot, make: Callable[[], Solver], cases: list, duration: float) -> str:
    """The random targets' summary for one solver: targets reached (the hand within 1 mm and
    0.01 rad), runs still cycling in their last second (a reversal on more than half its
    steps), the final ``|u|`` (median, max) and the largest final chain error."""
    reached = cycling = 0
    u_end, chain_end = [], []
    for rotation, axis, shift in cases:
        log, _ = stalled_run(
            robot, make(), rotation=rotation, axis=axis, shift=shift, duration=duration
        )
        error = log.task_errors["hand"][-1]
        reached += bool(np.linalg.norm(error[:3]) < 1e-3 and np.linalg.norm(error[3:]) < 1e-2)
        last = round(1.0 / log.dt)
        cycling += u_reversals(log.u[-last:]) > last // 2
        u_end.append(float(np.max(np.abs(log.u[-1]))))
        chain_end.append(float(np.linalg.norm(log.task_errors["chain"][-1, :3])))
    return (
        f"{reached:>7d}/{len(cases):<3d} {cycling:>7d} {np.median(u_end):>12.2g} "
        f"{max(u_end):>9.3g} {max(chain_end):>13.2e}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", default="mobile_humanoid")
    parser.add_argument("--duration", type=float, default=5.0, help="s")
    parser.add_argument("--settle", type=float, default=2.0, help="s: the stall from then on")
    parser.add_argument("--rotation", type=float, default=1.5, help="rad about --axis")
    parser.add_argument(
        "--axis", type=float, nargs=3, default=[1.0, 0.0, 0.0], help="unit vector (world)"
    )
    parser.add_argument("--lift", type=float, default=0.05, help="m")
    parser.add_argument("--damping", type=float, nargs="+", default=[STALL_DAMPING, 0.0])
    parser.add_argument("--engines", nargs="+", default=["daqp"])
    parser.add_argument("--projection", action="store_true", help="run the projection too")
    parser.add_argument(
        "--targets", type=int, default=0, help="also run N random targets (see targets())"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    robot = wb.load_robot(args.robot)
    runs: list[tuple[str, Solver]] = [
        (f"hqp/{engine} mu={mu:g}", wb.HierarchicalQPSolver(engine, stall_damping=mu))
        for engine in args.engines
        for mu in args.damping
    ]
    if args.projection:
        runs.append(("projection", wb.ProjectionSolver()))
    print(
        f"{args.robot}: rotation {args.rotation} rad about {tuple(args.axis)}, "
        f"lift {args.lift} m, {args.duration} s, stall from {args.settle} s"
    )
    print(
        f"{'solver':<26} {'reversals':>9} {'stalled':>11} {'|u| end':>9} {'|u| 0.5s':>9} "
        f"{'chain end m':>11} {'chain max m':>11} {'overshoot':>9} {'step us':>7}"
    )
    for name, solver in runs:
        log, _ = stalled_run(
            robot,
            solver,
            rotation=args.rotation,
            axis=tuple(args.axis),
            shift=(0.0, 0.0, args.lift),
            duration=args.duration,
        )
        r = report(log, args.settle)
        stalled = f"{r['reversals_stalled']}/{r['stalled_steps']}"
        print(
            f"{name:<26} {r['reversals']:>9d} {stalled:>11} "
            f"{r['u_final']:>9.3g} {r['u_max_last_0.5s']:>9.3g} {r['chain_final_m']:>11.2e} "
            f"{r['chain_max_stalled_m']:>11.2e} {r['limit_overshoot']:>9.1e} "
            f"{r['step_us']:>7.1f}"
        )
    if not args.targets:
        return
    cases = targets(args.targets, args.seed)
    print(f"\n{args.targets} random targets (seed {args.seed}), {args.duration} s each")
    print(
        f"{'solver':<26} {'reached':>11} {'cycling':>7} {'|u| end p50':>12} {'max':>9} "
        f"{'chain end max':>13}"
    )
    makers: list[tuple[str, Callable[[], Solver]]] = [
        (f"hqp/{engine} mu={mu:g}", partial(wb.HierarchicalQPSolver, engine, stall_damping=mu))
        for engine in args.engines
        for mu in args.damping
    ]
    if args.projection:
        makers.append(("projection", wb.ProjectionSolver))
    for name, make in makers:
        print(f"{name:<26} {sweep(robot, make, cases, args.duration)}", flush=True)


if __name__ == "__main__":
    main()
