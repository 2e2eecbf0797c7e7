"""DMP speed: fit + 160-sample 3-D rollout, with and without the paper's two cylinders.

Run as ``python benchmarks/dmp.py``. The paper (Niu et al. 2024, Section 5) reports 160-point
trajectories in 0.2252, 0.2444 and 0.2246 s on a laptop i7; the ratio column compares the
median with 225 ms. Cases are interleaved (one of each per round) so that load on the
machine affects them alike. ``movement_primitives`` is timed as a baseline when it imports.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from wholebody.planning import DMP, DynamicPotential, cylinder, minimum_jerk_scaling

PAPER_S = 0.225

# The paper's obstacle scene (tests/test_obstacles.py): hand from START to GOAL in 2 s, two
# cylinders r = 4 cm, h = 20 cm, the second moved beyond the goal; reserved space 2 cm.
START = np.array([1.73, -0.54, 1.06])
GOAL = np.array([1.73, -0.30, 1.09])
CENTERS = (np.array([1.725, -0.4, 1.09]), np.array([1.725, -0.2, 1.09]))


def demonstration(n: int = 160, duration: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, duration, n)
    s = minimum_jerk_scaling(t / duration)[0]
    return t, START + s[:, None] * (GOAL - START)


def movement_primitives_case(t: np.ndarray, X: np.ndarray) -> Callable[[], object] | None:
    try:
        from movement_primitives.dmp import DMP as MPDMP
    except Exception as exc:  # an optional baseline: any import failure means "skip"
        print(f"movement_primitives baseline skipped: {type(exc).__name__}: {exc}")
        return None

    def run() -> object:
        dmp = MPDMP(n_dims=3, execution_time=float(t[-1]), dt=float(t[1] - t[0]),
                    n_weights_per_dim=50)  # fmt: skip
        dmp.imitate(t, X)
        return dmp.open_loop()

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()

    t, X = demonstration()
    dmp = DMP.fit(X, t)
    pots = [DynamicPotential(cylinder(c, 0.04, 0.2, margin=0.02), gain=10.0, beta=2.0, eta=2.0)
            for c in CENTERS]  # fmt: skip
    converged = dmp.rollout(160, obstacles=pots, tolerance=1e-8, max_substeps=4096).positions
    adaptive = dmp.rollout(160, obstacles=pots).positions
    fixed = dmp.rollout(160, obstacles=pots, max_substeps=1).positions
    err_adaptive = np.max(np.linalg.norm(adaptive - converged, axis=1))
    err_fixed = np.max(np.linalg.norm(fixed - converged, axis=1))

    cases: dict[str, Callable[[], object]] = {
        "fit + rollout (160 samples, 3-D)": lambda: DMP.fit(X, t).rollout(160),
        "rollout alone": lambda: dmp.rollout(160),
        "rollout + 2 cylinders (adaptive RK4)": lambda: dmp.rollout(160, obstacles=pots),
        "fit + rollout + 2 cylinders": lambda: DMP.fit(X, t).rollout(160, obstacles=pots),
        "rollout + 2 cylinders, fixed-step RK4 (*)": lambda: dmp.rollout(
            160, obstacles=pots, max_substeps=1
        ),
    }
    baseline = movement_primitives_case(t, X)
    if baseline is not None:
        cases["movement_primitives DMP fit + rollout"] = baseline

    for run in cases.values():  # warm up
        run()
    times: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(args.repeats):
        for name, run in cases.items():
            t0 = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - t0)

    print(f"\nDMP timings, {args.repeats} interleaved repeats (paper: 225 ms per trajectory)\n")
    print(f"{'case':<46}{'median ms':>11}{'p90 ms':>9}{'paper / median':>16}")
    for name, ts in times.items():
        arr = np.array(ts) * 1e3
        med, p90 = np.median(arr), np.percentile(arr, 90)
        print(f"{name:<46}{med:>11.3f}{p90:>9.3f}{PAPER_S * 1e3 / med:>15.0f}x")
    print(
        f"\nmax distance from the converged obstacle path: adaptive {err_adaptive * 1e3:.4f} mm,"
        f" (*) fixed step {err_fixed * 1e3:.1f} mm"
    )


if __name__ == "__main__":
    main()
