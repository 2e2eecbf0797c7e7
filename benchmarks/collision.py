#!/usr/bin/env python3
"""What collision checking costs on the paper's robot: the kernel
:func:`wholebody.kernels.collision.collision_rows` (what the control step calls: the closest
pairs' distances and rows, 32 at most) and :meth:`CollisionModel.distances` (the Python path:
every pair within the cut-off as a ``PairDistance``).

Two cases: the robot alone at ``--steps`` random postures (seed 0; 374 pairs checked), and
tasks/reach_under_shelf.toml's model (the robot and the shelf board, 404 pairs) at every
step of the scenario's own run (the hand reaching under the board, held 1 cm off it). Per
cut-off (5 cm, the constraint's default influence, 10 cm, none): the median time per call
(us) of the kernel (after ``robot.update``, not counted) and of ``distances()``, and the pairs
within the cut-off. ``--compile``: the first compile of the collision kernels, in a fresh
``NUMBA_CACHE_DIR`` (a subprocess; its cache thrown away).

    python benchmarks/collision.py [--steps N] [--compile]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

import wholebody
from wholebody.collision import CollisionModel
from wholebody.kernels.collision import RESULT_WIDTH, collision_rows

MAX_ROWS = 32  # CollisionAvoidance's default
COMPILE = """
import time
t = time.perf_counter()
import wholebody
from wholebody.collision import CollisionModel
robot = wholebody.load_robot("mobile_humanoid")
loaded = time.perf_counter()
model = CollisionModel(robot)  # nearest_pairs (the contacts at home)
model.distances(robot.update(robot.home()), 0.05)  # collision_rows
print(f"{time.perf_counter() - loaded:.1f}")
"""


def time_model(
    robot: wholebody.Robot, model: CollisionModel, postures: list[np.ndarray], label: str
) -> None:
    """One table row per cut-off."""
    rows = np.empty((MAX_ROWS, robot.nu))
    found = np.empty((len(model.pairs), RESULT_WIDTH))
    index = np.empty(len(model.pairs), dtype=np.int64)
    external = np.empty((0, RESULT_WIDTH))
    for within in (0.05, 0.1, np.inf):
        kernel, python, counts = [], [], []
        for q in postures:
            state = robot.update(q)
            J, oMf = robot.kinematics.views()
            start = time.perf_counter()
            _, near = collision_rows(J, oMf, model.packed, external, within, rows, found, index)
            middle = time.perf_counter()
            model.distances(state, within)
            kernel.append(middle - start)
            python.append(time.perf_counter() - middle)
            counts.append(near)
        cut = f"{within * 100:.0f} cm" if np.isfinite(within) else "none"
        k, p, n = np.median(kernel) * 1e6, np.median(python) * 1e6, np.median(counts)
        print(f"| {label} | {cut} | {k:.1f} | {p:.0f} | {n:.0f} |")


def first_compile() -> None:
    """The collision kernels' first compile, in a fresh cache directory."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        command = [sys.executable, "-c", COMPILE]
        out = subprocess.run(command, env=env, check=True, capture_output=True, text=True)
    took = out.stdout.strip()
    print(f"\nfirst compile of the collision kernels (fresh NUMBA_CACHE_DIR): {took} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--compile", action="store_true", help="time the first compile")
    args = parser.parse_args()
    from wholebody.resources import tasks_dir
    from wholebody.scenarios import load_scenario, run_scenario
    from wholebody.scenarios.runner import collision_model

    robot = wholebody.load_robot("mobile_humanoid")
    model = CollisionModel(robot)
    rng = np.random.default_rng(0)
    postures = [
        robot.random_configuration(rng, margin=0.2, base_range=0.0) for _ in range(args.steps)
    ]
    spec = load_scenario(tasks_dir() / "reach_under_shelf.toml")
    run = run_scenario(spec)
    shelf = collision_model(spec, robot)
    print(f"robot alone: {model.summary()}")
    print(f"reach_under_shelf: {shelf.summary()}; {len(run.log.q)} steps")
    print("\n| case | cut-off | kernel median (us) | distances() median (us) | pairs within |")
    print("|---|---|---|---|---|")
    time_model(robot, model, postures, "random postures")
    time_model(robot, shelf, list(run.log.q), "reach_under_shelf")
    if args.compile:
        first_compile()


if __name__ == "__main__":
    main()
