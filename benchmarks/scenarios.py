#!/usr/bin/env python3
"""The control step of every bundled scenario, per backend, against the paper stack's step.

Each round runs, in a new random order, every bundled scenario (``tasks/*.toml``) on both
backends (``projection``, ``hqp`` with daqp), ``reach_under_shelf`` also without its
``[collision]`` table, and ``benchmarks/control_step.py``'s paper-stack cases (the paper's
stack on the humanoid, both hands on minimum-jerk reaches; ``--steps`` steps each, in a
block: the scenarios' loops are blocks of their own steps too). A scenario's step is its
log's ``step_time``: the references sampled, the targets set, the kinematics, rows, solve,
integrals and integration (not the logging; :mod:`wholebody.control.controller`). Printed per
case: the median and p99 of its steps over all rounds (us), ``p99 / median``, and the median
over the paper stack's median with the same backend (``x paper``); then the ratios the
project holds itself to. Kernels compile first (``wholebody warmup``); scenarios on
example-robot-data's robots are skipped with a line when it is not installed.

    python benchmarks/scenarios.py [--rounds R] [--steps N] [--only NAME,NAME]
"""

from __future__ import annotations

import argparse
import dataclasses
import random
import sys
import time
from pathlib import Path

import numpy as np

import wholebody
from wholebody.control import Controller
from wholebody.errors import WholebodyError
from wholebody.scenarios.runner import run_scenario, scenario_robot
from wholebody.scenarios.spec import load_scenario
from wholebody.tasks import FrameTask
from wholebody.warmup import warmup

sys.path.insert(0, str(Path(__file__).resolve().parent))
import control_step

ROOT = Path(__file__).resolve().parents[1]
BACKENDS = ("projection", "hqp")
PAPER = {"projection": control_step.projection, "hqp": control_step.hqp_paper}


def scenario_cases(only: set[str] | None) -> list[tuple[str, str, object]]:
    """``(label, backend, spec)`` of every bundled scenario that loads on this machine."""
    cases = []
    for path in sorted((ROOT / "tasks").glob("*.toml")):
        if only and path.stem not in only:
            continue
        try:
            spec = load_scenario(path)
            scenario_robot(spec)
        except WholebodyError as exc:  # a robot from a package that is not installed
            print(f"skipped {path.stem}: {exc}")
            continue
        variants = [(path.stem, spec)]
        if spec.collision is not None:
            variants.append(
                (f"{path.stem} (no [collision])", dataclasses.replace(spec, collision=None))
            )
        cases += [(label, backend, s) for label, s in variants for backend in BACKENDS]
    return cases


def paper_steps(backend: str, steps: int) -> list[float]:
    """``steps`` steps of control_step.py's paper-stack case (s each), from home."""
    robot = wholebody.load_robot("mobile_humanoid")
    q, refs = control_step.hand_references(robot)
    hands = [FrameTask(robot, "left_tool", kp=20.0), FrameTask(robot, "right_tool", kp=20.0)]
    stack, solver = PAPER[backend](robot, hands)
    controller = Controller(robot, stack, solver, dt=control_step.DT)
    out = []
    for k in range(steps):
        start = time.perf_counter()
        for hand, (pose, twist) in zip(
            hands, control_step.forth_and_back(refs, k * 0.01), strict=True
        ):
            hand.set_target(pose, twist)
        controller.step(q)
        q = controller.q_next.copy()
        out.append(time.perf_counter() - start)
    controller.close()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--steps", type=int, default=600, help="paper-stack steps per round")
    parser.add_argument("--only", help="comma-separated scenario names")
    args = parser.parse_args()
    warmup()
    cases = scenario_cases(set(args.only.split(",")) if args.only else None)
    jobs = [("paper", b, None) for b in BACKENDS] + cases
    times: dict[tuple[str, str], list[float]] = {(label, b): [] for label, b, _ in jobs}
    for _ in range(args.rounds):
        for label, backend, spec in random.sample(jobs, len(jobs)):
            if spec is None:
                times[label, backend] += paper_steps(backend, args.steps)
            else:
                run = run_scenario(spec, backend=backend)
                times[label, backend] += list(run.log.step_time)
    report(times)


def report(times: dict[tuple[str, str], list[float]]) -> None:
    """The table and the ratios (module docstring)."""
    med = {key: float(np.median(t)) * 1e6 for key, t in times.items()}
    head = f"{'case':42s} {'backend':10s} {'steps':>6s} {'median us':>10s} {'p99 us':>9s}"
    print(f"{head} {'p99/med':>8s} {'x paper':>8s}")
    for (label, backend), t in times.items():
        m, p99 = med[label, backend], float(np.percentile(t, 99)) * 1e6
        ratio = m / med["paper", backend]
        row = f"{label:42s} {backend:10s} {len(t):6d} {m:10.1f} {p99:9.1f}"
        print(f"{row} {p99 / m:8.2f} {ratio:8.2f}")
    print()
    shelf, carry, tiago = "reach_under_shelf", "coordinated_carry", "tiago_dual_carry"
    for backend in BACKENDS:
        worst = max(
            (m / med["paper", backend], label)
            for (label, b), m in med.items()
            if b == backend and label != "paper"
        )
        print(
            f"{backend}: worst scenario median {worst[0]:.2f}x the paper stack's ({worst[1]}; "
            "target <= 2)"
        )
        if (shelf, backend) in med:
            ratio = med[shelf, backend] / med[f"{shelf} (no [collision])", backend]
            print(f"{backend}: {shelf} {ratio:.2f}x without [collision] (target <= 1.5)")
        if (tiago, backend) in med and (carry, backend) in med:
            print(
                f"{backend}: {tiago} {med[tiago, backend] / med[carry, backend]:.2f}x "
                f"{carry} (target <= 2)"
            )
        if (carry, backend) in med:
            p99 = float(np.percentile(times[carry, backend], 99)) * 1e6
            print(
                f"{backend}: {carry} p99 {p99 / med[carry, backend]:.2f}x its median (target <= 3)"
            )


if __name__ == "__main__":
    main()
