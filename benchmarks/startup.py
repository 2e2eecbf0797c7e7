#!/usr/bin/env python3
"""A cached start: a new process imports wholebody, builds the paper's stack on the humanoid
and takes its first ``Controller.step`` (the kernels loaded from the cache, not compiled).

Each case runs in a fresh interpreter ``--repeat`` times, the backends alternating; the table
gives the median and range of the wall time of the whole process and of its three parts.
Run ``wholebody warmup`` first (else the first run compiles).

    python benchmarks/startup.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np

CHILD = """
import json, sys, time
t0 = time.perf_counter()
import wholebody as wb
from wholebody.presets import paper_stack
from wholebody.solvers.hqp import HierarchicalQPSolver
t1 = time.perf_counter()
robot = wb.load_robot("mobile_humanoid")
stack = paper_stack(robot, [wb.FrameTask(robot, f) for f in ("left_tool", "right_tool")])
solver = HierarchicalQPSolver() if sys.argv[1] == "hqp" else wb.ProjectionSolver()
controller = wb.Controller(robot, stack, solver, dt=0.01)
t2 = time.perf_counter()
controller.step(robot.neutral())
t3 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "build": t2 - t1, "first step": t3 - t2}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rows: dict[str, dict[str, list[float]]] = {}
    for _ in range(args.repeat):
        for backend in ("projection", "hqp"):
            start = time.perf_counter()
            out = subprocess.run(
                [sys.executable, "-c", CHILD, backend], capture_output=True, text=True, check=True
            )
            parts = json.loads(out.stdout.strip().splitlines()[-1])
            parts["process"] = time.perf_counter() - start
            for name, value in parts.items():
                rows.setdefault(backend, {}).setdefault(name, []).append(value)
    print(f"cached start, {args.repeat} fresh processes per backend (s: median [min-max])")
    for backend, parts in rows.items():
        cells = [f"{n} {np.median(v):.2f} [{min(v):.2f}-{max(v):.2f}]" for n, v in parts.items()]
        print(f"{backend:11s} " + ", ".join(cells))


if __name__ == "__main__":
    main()
