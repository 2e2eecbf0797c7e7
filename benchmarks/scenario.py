"""A whole scenario's simulation time: ``run_scenario`` (the control loop, planning and
logging; no plots, no files), in fresh processes, against an older source tree.

Each case is one process that imports wholebody from a source tree, loads the scenario and
times ``run_scenario`` twice: the **first** run pays what every new process pays once (loading
the cached numba kernels, numba's own start-up), the **second** is the steady state of a
process that runs many scenarios (a sweep, a notebook). The import time is printed apart.
Cases (tree x backend) are interleaved round by round in a new random order, so that load on
this shared machine hits them alike; medians are printed, with the ratio baseline / this tree.

    python benchmarks/scenario.py [--scenario NAME] [--rounds R] [--baseline SRC]

``--baseline`` is the ``src`` directory of another checkout, e.g. the last commit before the
compiled core: ``git worktree add /tmp/old d1697df~1`` then ``--baseline /tmp/old/src``.
Kernels must be compiled first (``wholebody warmup``), or the first run includes compiling.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = """
import json, sys, time
t0 = time.perf_counter()
from wholebody.scenarios.runner import run_scenario
from wholebody.scenarios.spec import load_scenario
t1 = time.perf_counter()
spec = load_scenario(sys.argv[1])
runs = []
for _ in range(2):
    start = time.perf_counter()
    run_scenario(spec, backend=sys.argv[2])
    runs.append(time.perf_counter() - start)
print(json.dumps({"import": t1 - t0, "first": runs[0], "second": runs[1]}))
"""


def run_case(src: Path, scenario: Path, backend: str) -> dict[str, float]:
    """One fresh process importing wholebody from ``src``: its import and two run times, s."""
    env = {"PYTHONPATH": str(src), "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(scenario), backend],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="coordinated_carry")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--baseline", type=Path, help="src directory of an older checkout")
    args = parser.parse_args()
    scenario = ROOT / "tasks" / f"{args.scenario}.toml"
    trees = {"this tree": ROOT / "src"}
    if args.baseline is not None:
        trees["baseline"] = args.baseline.resolve()
    cases = [(t, b) for t in trees for b in ("projection", "hqp")]
    times: dict[tuple[str, str], list[dict[str, float]]] = {c: [] for c in cases}
    rng = random.Random(0)
    for _ in range(args.rounds):
        order = cases[:]
        rng.shuffle(order)
        for tree, backend in order:
            times[tree, backend].append(run_case(trees[tree], scenario, backend))
    print(f"{args.scenario}: run_scenario wall time, s (median of {args.rounds} processes)")
    print(
        f"{'tree':<10} {'backend':<11} {'import':>7} {'first':>7} {'second':>7}"
        f" {'x first':>8} {'x second':>9}"
    )
    for tree, backend in cases:
        med = {k: statistics.median(r[k] for r in times[tree, backend]) for k in times[cases[0]][0]}
        ratio = ""
        if "baseline" in trees and tree == "this tree":
            base = {
                k: statistics.median(r[k] for r in times["baseline", backend])
                for k in ("first", "second")
            }
            ratio = f" {base['first'] / med['first']:>8.2f} {base['second'] / med['second']:>9.2f}"
        print(
            f"{tree:<10} {backend:<11} {med['import']:>7.2f} {med['first']:>7.3f}"
            f" {med['second']:>7.3f}{ratio}"
        )
    if "baseline" in trees:
        print("x first / x second: the baseline's median over this tree's, same run")


if __name__ == "__main__":
    main()
