"""DMP speed: fit + 160-sample 3-D rollout, with and without the paper's two cylinders.

Run as ``python benchmarks/dmp.py``. The paper (Niu et al. 2024, Section 5) reports 160-point
trajectories in 0.2252, 0.2444 and 0.2246 s on a laptop i7; the ratio column compares the
median with 225 ms. Cases are interleaved (one of each per round) so that load on the
machine affects them alike.

``movement_primitives`` (BSD; the optional ``bench`` extra) is timed as a baseline when it
imports, in the same interleaved rounds: fit (``imitate``) + 160-sample open-loop rollout, and
the same with its obstacle coupling term (``CouplingTermObstacleAvoidance3D``, Ijspeert et al.
2013: a steering acceleration around a *point*; it has no volumetric obstacles, so each
cylinder is represented by its centre point, one coupling term per obstacle, summed). Its
rollout integrates at its default ``int_dt = 1 ms`` with the ``rk4-cython`` step. A second
table gives its medians over wholebody's for the matching case (fit + rollout, and fit +
rollout with the two obstacles), measured in the same run.
"""

from __future__ import annotations

import argparse
import math
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


def movement_primitives_case(
    t: np.ndarray, X: np.ndarray, obstacles: tuple[np.ndarray, ...] = ()
) -> Callable[[], object] | None:
    """movement_primitives' DMP fit + rollout (160 samples), with point obstacles if given;
    None (and a line saying why) when it does not import."""
    try:
        from movement_primitives.dmp import DMP as MPDMP
        from movement_primitives.dmp import CouplingTermObstacleAvoidance3D
    except Exception as exc:  # an optional baseline: any import failure means "skip"
        print(f"movement_primitives baseline skipped: {type(exc).__name__}: {exc}")
        return None

    terms = [CouplingTermObstacleAvoidance3D(c) for c in obstacles]

    class Obstacles:
        """The sum of one point-obstacle coupling term per obstacle."""

        def coupling(self, y: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            cd, cdd = terms[0].coupling(y, yd)
            for term in terms[1:]:
                cdd = cdd + term.coupling(y, yd)[1]
            return cd, cdd

    coupling = Obstacles() if terms else None

    def run() -> object:
        dmp = MPDMP(n_dims=3, execution_time=float(t[-1]), dt=float(t[1] - t[0]),
                    n_weights_per_dim=50)  # fmt: skip
        dmp.imitate(t, X)
        return dmp.open_loop(coupling_term=coupling)

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
    fixed = dmp.rollout(160, obstacles=pots, tolerance=math.inf, max_substeps=1).positions
    err_adaptive = np.max(np.linalg.norm(adaptive - converged, axis=1))
    err_fixed = np.max(np.linalg.norm(fixed - converged, axis=1))

    cases: dict[str, Callable[[], object]] = {
        "fit + rollout (160 samples, 3-D)": lambda: DMP.fit(X, t).rollout(160),
        "rollout alone": lambda: dmp.rollout(160),
        "rollout + 2 cylinders (adaptive RK4)": lambda: dmp.rollout(160, obstacles=pots),
        "fit + rollout + 2 cylinders": lambda: DMP.fit(X, t).rollout(160, obstacles=pots),
        "rollout + 2 cylinders, fixed-step RK4 (*)": lambda: dmp.rollout(
            160, obstacles=pots, tolerance=math.inf, max_substeps=1
        ),
    }
    # (movement_primitives case, the wholebody case it is compared with)
    pairs: list[tuple[str, str]] = []
    for label, obstacles, ours in (
        ("movement_primitives fit + rollout", (), "fit + rollout (160 samples, 3-D)"),
        ("movement_primitives fit + rollout + 2 points", CENTERS, "fit + rollout + 2 cylinders"),
    ):
        baseline = movement_primitives_case(t, X, obstacles)
        if baseline is None:
            break
        cases[label] = baseline
        pairs.append((label, ours))
    if pairs:
        _, mp_path = cases[pairs[-1][0]]()  # type: ignore[misc]
        mp_clear = min(float(np.min(np.linalg.norm((mp_path - c)[:, :2], axis=1))) for c in CENTERS)
        ours_clear = min(
            float(np.min(np.linalg.norm((adaptive - c)[:, :2], axis=1))) for c in CENTERS
        )

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
    if pairs:
        print("\nagainst movement_primitives (same run, interleaved; ratio of medians)\n")
        print(f"{'movement_primitives case':<46}{'its ms':>9}{'wholebody ms':>14}{'ratio':>8}")
        for label, ours in pairs:
            mp, wb = np.median(times[label]) * 1e3, np.median(times[ours]) * 1e3
            print(f"{label:<46}{mp:>9.3f}{wb:>14.3f}{mp / wb:>7.1f}x")
        print(
            "(movement_primitives: point obstacles at the cylinder centres, coupling term of "
            "Ijspeert et al. 2013 with its default gamma, beta; closest approach of the path "
            f"to a cylinder axis: movement_primitives {mp_clear * 1e3:.1f} mm, wholebody "
            f"{ours_clear * 1e3:.1f} mm, cylinder radius 40 mm + 20 mm reserved)"
        )


if __name__ == "__main__":
    main()
