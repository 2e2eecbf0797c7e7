"""DMP speed: fit + 160-sample 3-D rollout, with and without the paper's two cylinders, and
the online stepper (the numba kernels of :mod:`wholebody.kernels.dmp`, the only
implementation).

Run as ``python benchmarks/dmp.py [--repeats N] [--write]``. The cases are interleaved (one
of each per round, in a new random order every round) so that load on the machine and cold
caches affect them alike; medians are printed. The paper (Niu et al. 2024, Section 5)
reports 160-point trajectories in 0.2252, 0.2444 and 0.2246 s on a laptop i7 (225 ms).

``movement_primitives`` (BSD; the optional ``bench`` extra) is timed as a baseline when it
imports, in the same interleaved rounds: fit (``imitate``) + 160-sample open-loop rollout, and
the same with its obstacle coupling term (``CouplingTermObstacleAvoidance3D``, Ijspeert et al.
2013: a steering acceleration around a *point*; it has no volumetric obstacles, so each
cylinder is represented by its centre point, one coupling term per obstacle, summed). Its
rollout integrates at its default ``int_dt = 1 ms`` with the ``rk4-cython`` step.

Everything runs with one BLAS thread (``threadpool_limits(1)``, as ``Controller.run``): on a
loaded 2-core machine OpenBLAS's threads, two pools of them (numpy's and scipy's), made
movement_primitives' fit + rollout take 55 ms instead of 6.

Also printed: the largest distance of the obstacle paths from the converged one
(``tolerance=1e-8``; the tests hold that one against scipy's ``solve_ivp``), and the
start-up cost of the kernels, measured in fresh processes: with an empty numba cache (the
first call compiles) and again with that cache warm (what every later process pays).
``--write`` puts the printed tables into ``benchmarks/README.md`` between
``<!-- dmp:begin -->`` and ``<!-- dmp:end -->``.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from wholebody.planning import DMP, DynamicPotential, cylinder, minimum_jerk_scaling

PAPER_S = 0.225
README = Path(__file__).resolve().parent / "README.md"
BEGIN, END = "<!-- dmp:begin -->", "<!-- dmp:end -->"

# The paper's obstacle scene (tests/test_obstacles.py): hand from START to GOAL in 2 s, two
# cylinders r = 4 cm, h = 20 cm, the second moved beyond the goal; reserved space 2 cm.
START = np.array([1.73, -0.54, 1.06])
GOAL = np.array([1.73, -0.30, 1.09])
CENTERS = (np.array([1.725, -0.4, 1.09]), np.array([1.725, -0.2, 1.09]))

# A fresh process: import, fit and one obstacle rollout (the kernels load or compile on the
# first call); prints the import time and the first call's.
STARTUP = """
import time
t0 = time.perf_counter()
import numpy as np
from wholebody.planning import DMP, DynamicPotential, cylinder, minimum_jerk_scaling
t1 = time.perf_counter()
t = np.linspace(0.0, 2.0, 160)
a, b = np.array([1.73, -0.54, 1.06]), np.array([1.73, -0.30, 1.09])
X = a + minimum_jerk_scaling(t / 2.0)[0][:, None] * (b - a)
pots = [DynamicPotential(cylinder(c, 0.04, 0.2, margin=0.02))
        for c in ([1.725, -0.4, 1.09], [1.725, -0.2, 1.09])]
DMP.fit(X, t).rollout(160, obstacles=pots)
t2 = time.perf_counter()
print(t1 - t0, t2 - t1)
"""


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
        dmp = MPDMP(
            n_dims=3, execution_time=float(t[-1]), dt=float(t[1] - t[0]), n_weights_per_dim=50
        )
        dmp.imitate(t, X)
        return dmp.open_loop(coupling_term=coupling)

    return run


def stepped(dmp: DMP, obstacles: list[DynamicPotential]) -> np.ndarray:
    """159 online steps of ``T / 159`` (the rollout's sampling): the positions (160, 3)."""
    stepper = dmp.stepper(obstacles=obstacles)
    state = stepper.initial_state()
    path = [state.x.copy()]
    for _ in range(159):
        stepper.step(state, dmp.duration / 159, out=state)
        path.append(state.x.copy())
    return np.array(path)


def startup() -> tuple[tuple[float, float], tuple[float, float]]:
    """(import s, first fit + obstacle rollout s) of a fresh process with an empty numba
    cache, then of another with that cache warm."""
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as cache:
        env["NUMBA_CACHE_DIR"] = cache
        runs = []
        for _ in range(2):
            out = subprocess.run(
                [sys.executable, "-c", STARTUP], env=env, check=True, capture_output=True, text=True
            ).stdout
            imp, first = (float(x) for x in out.split())
            runs.append((imp, first))
    return runs[0], runs[1]


def table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table, the first column left-aligned, the others right-aligned."""
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]

    def line(cells: list[str]) -> str:
        padded = (
            c.ljust(w) if i == 0 else c.rjust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        )
        return "| " + " | ".join(padded) + " |"

    rule = "|" + "|".join("-" * (w + 1) + ("-" if i == 0 else ":") for i, w in enumerate(widths))
    return "\n".join([line(header), rule + "|", *(line(r) for r in rows)])


def write_section(text: str, path: Path = README) -> None:
    """Replace this script's section of ``path`` (between ``BEGIN`` and ``END``) by ``text``,
    creating the file with a short header if need be; atomically (temp file + rename)."""
    body = f"{BEGIN}\n{text.strip()}\n{END}"
    old = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    if BEGIN in old and END in old.split(BEGIN, 1)[1]:
        head, rest = old.split(BEGIN, 1)
        new = head + body + rest.split(END, 1)[1]
    else:
        new = old.rstrip("\n") + "\n\n" + body + "\n"
    mode = path.stat().st_mode & 0o777 if path.exists() else 0o644
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".README.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(new)
        os.chmod(tmp, mode)  # mkstemp's file is private (0600)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def cases(
    dmp: DMP, t: np.ndarray, X: np.ndarray, pots: list[DynamicPotential]
) -> tuple[dict[str, Callable[[], object]], dict[str, Callable[[], object]], list[tuple[str, str]]]:
    """(wholebody's cases, every case to time: ours, then the baselines, (baseline, the case
    of ours it is compared with))."""
    ours: dict[str, Callable[[], object]] = {
        "fit + rollout (160 samples, 3-D)": lambda: DMP.fit(X, t).rollout(160),
        "rollout alone": lambda: dmp.rollout(160),
        "rollout + 2 cylinders (adaptive RK4)": lambda: dmp.rollout(160, obstacles=pots),
        "fit + rollout + 2 cylinders": lambda: DMP.fit(X, t).rollout(160, obstacles=pots),
        "rollout + 2 cylinders, fixed-step RK4 (*)": lambda: dmp.rollout(
            160, obstacles=pots, tolerance=math.inf, max_substeps=1
        ),
        "stepper, 159 steps": lambda: stepped(dmp, []),
        "stepper + 2 cylinders, 159 steps": lambda: stepped(dmp, pots),
    }
    timed: dict[str, Callable[[], object]] = dict(ours)
    baselines: list[tuple[str, str]] = []
    for label, points, mine in (
        ("movement_primitives fit + rollout", (), "fit + rollout (160 samples, 3-D)"),
        ("movement_primitives fit + rollout + 2 points", CENTERS, "fit + rollout + 2 cylinders"),
    ):
        baseline = movement_primitives_case(t, X, points)
        if baseline is None:
            break
        timed[label] = baseline
        baselines.append((label, mine))
    return ours, timed, baselines


def paths(dmp: DMP, pots: list[DynamicPotential]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The positions (160, 3) of the obstacle cases, and the converged obstacle path."""
    ours = {
        "rollout + 2 cylinders (adaptive)": dmp.rollout(160, obstacles=pots).positions,
        "2 cylinders, fixed-step RK4": dmp.rollout(
            160, obstacles=pots, tolerance=math.inf, max_substeps=1
        ).positions,
        "stepper + 2 cylinders": stepped(dmp, pots),
    }
    converged = dmp.rollout(160, obstacles=pots, tolerance=1e-8, max_substeps=4096).positions
    return ours, converged


def timings(timed: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median ms of each case over ``repeats`` interleaved rounds."""
    for run in timed.values():  # warm up
        run()
    times: dict[str, list[float]] = {name: [] for name in timed}
    names = list(timed)
    order = np.random.default_rng(0)
    for _ in range(repeats):
        # a new order every round: no case always follows the same (cold caches after a
        # heavy neighbour would otherwise fall on one case)
        for i in order.permutation(len(names)):
            name = names[i]
            t0 = time.perf_counter()
            timed[name]()
            times[name].append(time.perf_counter() - t0)
    return {name: float(np.median(ts)) * 1e3 for name, ts in times.items()}


def gap(a: np.ndarray, b: np.ndarray) -> str:
    """The largest distance between two paths (N, 3), m."""
    return f"{float(np.max(np.linalg.norm(a - b, axis=1))):.2e}"


def report(
    repeats: int,
    ours: dict[str, Callable[[], object]],
    baselines: list[tuple[str, str]],
    med: dict[str, float],
    path_sets: tuple[dict[str, np.ndarray], np.ndarray],
    start: tuple[tuple[float, float], tuple[float, float]],
) -> str:
    """The tables, in Markdown."""
    machine = platform.processor() or platform.machine()
    out = [
        f"DMP timings: `python benchmarks/dmp.py --repeats {repeats}`, medians of {repeats} "
        f"interleaved rounds (ms), {machine}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}.",
        "",
        table(
            ["case", "ms", "paper / wholebody"],
            [[n, f"{med[n]:.3f}", f"{PAPER_S * 1e3 / med[n]:.0f}x"] for n in ours],
        ),
    ]
    if baselines:
        mp_fit = med[baselines[0][0]]
        rows = [[label, med[label], mine] for label, mine in baselines]
        rows += [
            [f"{baselines[0][0]} vs {mine}", mp_fit, mine]
            for mine in ("rollout + 2 cylinders (adaptive RK4)", "fit + rollout + 2 cylinders")
        ]
        out += [
            "",
            "Against movement_primitives (same run; ratio = its median / wholebody's):",
            "",
            table(
                ["movement_primitives case", "its ms", "wholebody ms", "ratio"],
                [
                    [label, f"{theirs:.3f}", f"{med[mine]:.3f}", f"{theirs / med[mine]:.1f}x"]
                    for label, theirs, mine in rows
                ],
            ),
        ]
    found, converged = path_sets
    cold, warm = start
    out += [
        "",
        "Largest distance from the converged path (160 samples, m):",
        "",
        table(["path", "vs converged"], [[n, gap(found[n], converged)] for n in found]),
        "",
        "(converged: `tolerance=1e-8, max_substeps=4096`; (*) fixed-step RK4 is not meant to "
        "converge: it shows why the substeps are adaptive.)",
        "",
        "Start-up in a fresh process (import; first fit + obstacle rollout, s):",
        "",
        table(
            ["numba cache", "import s", "first call s"],
            [
                ["empty (compiles the DMP kernels)", f"{cold[0]:.2f}", f"{cold[1]:.2f}"],
                ["warm (loads them)", f"{warm[0]:.2f}", f"{warm[1]:.2f}"],
            ],
        ),
    ]
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument(
        "--write", action="store_true", help="write the tables into benchmarks/README.md"
    )
    args = parser.parse_args()

    t, X = demonstration()
    dmp = DMP.fit(X, t)  # compiles the kernels (or loads them) before any timing
    pots = [
        DynamicPotential(cylinder(c, 0.04, 0.2, margin=0.02), gain=10.0, beta=2.0, eta=2.0)
        for c in CENTERS
    ]
    ours, timed, baselines = cases(dmp, t, X, pots)
    path_sets = paths(dmp, pots)
    start = startup()
    with threadpool_limits(1):
        med = timings(timed, args.repeats)
    text = report(args.repeats, ours, baselines, med, path_sets, start)
    print(text)
    if args.write:
        write_section("## DMP planner\n\n" + text)
        print(f"\nwritten to {README}")


if __name__ == "__main__":
    main()
