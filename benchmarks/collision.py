#!/usr/bin/env python3
"""What collision checking costs: :meth:`CollisionModel.distances` on the paper's robot.

At ``--steps`` random postures (seed 0): the distances of the pairs within a cut-off (5 cm,
the constraint's default influence, and 10 cm: a bounding-sphere test first, coal only for
the pairs that pass), and of every checked pair (no cut-off). Printed: median time per call
(us), the pairs within the cut-off per call, and the time per such pair (us).

    python benchmarks/collision.py [--steps N]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import wholebody
from wholebody.collision import CollisionModel


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    robot = wholebody.load_robot("mobile_humanoid")
    model = CollisionModel(robot)
    rng = np.random.default_rng(0)
    configurations = [robot.random_configuration(rng, margin=0.2, base_range=0.0)
                      for _ in range(args.steps)]  # fmt: skip
    print(model.summary())
    print("| cut-off | median per call (us) | pairs within the cut-off | per such pair (us) |")
    print("|---|---|---|---|")
    for within in (0.05, 0.1, np.inf):
        times, counts = [], []
        for q in configurations:
            state = robot.update(q)
            start = time.perf_counter()
            pairs = model.distances(state, within)
            times.append(time.perf_counter() - start)
            counts.append(len(pairs) if np.isfinite(within) else len(model.pairs))
        t, n = np.median(times) * 1e6, np.median(counts)
        label = f"{within * 100:.0f} cm" if np.isfinite(within) else "none (every pair)"
        per = f"{t / n:.1f}" if n else "-"
        print(f"| {label} | {t:.0f} | {n:.0f} | {per} |")


if __name__ == "__main__":
    main()
