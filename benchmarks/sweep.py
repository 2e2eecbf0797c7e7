"""Sweep throughput: cases per minute on 1 and 2 local processes and on a local Ray
instance, and what each case costs beyond its own run.

One campaign (the coordinated carry, 27 s simulated a case, a grid of energy weights times
random hand gains) is swept into a fresh directory per round and mode; the modes are
interleaved round by round in a new random order so that load on this shared machine hits
them alike; medians over the rounds are printed. "Overhead per case" is the sweep's wall
time times its workers over the cases, minus a case's own run time (``wall_s`` in its
result): starting the processes (or Ray), shipping the case and its result, writing its
file, the table and the plots.

    python benchmarks/sweep.py [--rounds R] [--cases N]
"""

from __future__ import annotations

import argparse
import random
import statistics
import tempfile
import time
from pathlib import Path

from wholebody.sweep import load_campaign, run_sweep

CAMPAIGN = """
format = 1
[campaign]
name = "throughput"
scenario = "coordinated_carry"
samples = {samples}

[[axes]]
key = "stack.energy"
values = [0.0, 0.5]

[[axes]]
key = "hands.right.kp"
uniform = [10.0, 30.0]
"""


def measure(campaign, mode: str) -> dict[str, float]:
    """One sweep of the campaign in a fresh directory: wall time, cases, mean case time."""
    workers = 2 if mode in ("local 2", "ray") else 1
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        result = run_sweep(campaign, out, workers=workers, ray=mode == "ray", progress=False)
        wall = time.perf_counter() - start
    own = statistics.mean(r["wall_s"] for r in result.rows)
    return {
        "wall": wall,
        "cases": len(result.rows),
        "own": own,
        "overhead": wall * workers / len(result.rows) - own,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--cases", type=int, default=24, help="an even number")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "campaign.toml"
        path.write_text(CAMPAIGN.format(samples=max(1, args.cases // 2)))
        campaign = load_campaign(path)
        modes = ["local 1", "local 2", "ray"]
        results: dict[str, list[dict[str, float]]] = {m: [] for m in modes}
        for _ in range(args.rounds):
            for mode in random.sample(modes, len(modes)):
                results[mode].append(measure(campaign, mode))
    n = len(campaign.cases())
    print(
        f"{n} cases (the coordinated carry, {n * 27} s simulated in all), median of "
        f"{args.rounds} rounds\n"
    )
    print(
        "| mode | workers | sweep wall (s) | cases per minute | a case's own run (s) | "
        "overhead per case (s) |"
    )
    print("|---|---|---|---|---|---|")
    for mode in modes:
        med = {k: statistics.median(r[k] for r in results[mode]) for k in results[mode][0]}
        workers = 1 if mode == "local 1" else 2
        print(
            f"| {mode} | {workers} | {med['wall']:.1f} | {60 * med['cases'] / med['wall']:.1f} "
            f"| {med['own']:.2f} | {med['overhead']:.2f} |"
        )


if __name__ == "__main__":
    main()
