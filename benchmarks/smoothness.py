#!/usr/bin/env python3
"""Smoothness of the bundled scenarios with and without acceleration limits.

For every scenario and both energy-shaped backends, runs it with ``[stack] acceleration``
off and on and prints the largest velocity change per step relative to the robot's limit
(``max |u_k - u_{k-1}| / (a dt)`` over steps, phase boundaries included, and joints), the
steps above it, the solver failures (steps where a task that could have been met was not)
and the worst per-axis MAE of a hand over the run.

    python benchmarks/smoothness.py [SCENARIO ...]
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np

from wholebody.resources import tasks_dir
from wholebody.scenarios import load_scenario, run_scenario
from wholebody.scenarios.runner import scenario_robot

SCENARIOS = (
    "reach_generalisation",
    "obstacle_avoidance",
    "independent_dual_arm",
    "coordinated_carry",
)


def main() -> None:
    names = sys.argv[1:] or SCENARIOS
    print(
        f"{'scenario':<22} {'accel':<6} {'backend':<11} {'max du/(a dt)':>13} "
        f"{'steps over':>10} {'failures':>8} {'worst MAE mm':>12}"
    )
    for name in names:
        base = load_scenario(tasks_dir() / f"{name}.toml")
        amax = scenario_robot(base).acceleration_limits
        for on in (False, True):
            stack = dataclasses.replace(base.stack, acceleration=on)
            spec = dataclasses.replace(base, stack=stack)
            for backend in ("projection", "hqp"):
                run = run_scenario(spec, backend=backend)
                ratio = np.abs(np.diff(run.log.u, axis=0)) / spec.dt / amax
                over = int(np.count_nonzero((ratio > 1.0 + 1e-6).any(axis=1)))
                m = run.metrics
                worst = max(v for hand in m["mae_m"].values() for v in hand.values())
                print(
                    f"{name:<22} {'on' if on else 'off':<6} {backend:<11} "
                    f"{ratio.max():>13.2f} {over:>10d} {m['solver_failures']:>8d} "
                    f"{worst * 1e3:>12.3f}"
                )


if __name__ == "__main__":
    main()
