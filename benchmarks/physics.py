"""Physics in the loop: how fast a scenario runs on MuJoCo, and where the time goes.

For each scenario and backend, in one process with the kernels warm, ``run_scenario`` runs
kinematically and under MuJoCo physics (``sim="mujoco"``), the cases interleaved round by
round in a new random order so that load on this shared machine hits them alike. Printed,
medians over the rounds:

* the physics run's **real-time factor**: simulated seconds per wall second, everything
  included (control, physics, logging); above 1 it runs faster than the robot would;
* its wall time split into the controller's steps (``RunLog.step_time``), the plant's
  physics steps (10 MuJoCo steps of 1 ms per 10 ms control period, the servos in Python) and
  the rest (planning, logging, metrics);
* the kinematic run's wall time beside it, and the ratio.

With ``--figure PATH`` it also draws the coordinated carry's tracking error over time under
physics beside the kinematic run's (the README's figure).

    python benchmarks/physics.py [--rounds R] [--scenarios NAME ...] [--figure PATH]
"""

from __future__ import annotations

import argparse
import random
import statistics
import time
from pathlib import Path

from wholebody.resources import tasks_dir
from wholebody.scenarios import load_scenario, plots, run_scenario
from wholebody.sim import MujocoPlant

DEFAULT = [
    "coordinated_carry",
    "independent_dual_arm",
    "reach_generalisation",
    "tiago_dual_carry",
    "talos_upper_reach",
    "panda_reach",
]


class _Timed:
    """Wraps :meth:`MujocoPlant.step` to add up its wall time."""

    total = 0.0

    def __enter__(self) -> _Timed:
        self._step = MujocoPlant.step
        timed = self

        def step(plant, q, u, dt):
            start = time.perf_counter()
            out = timed._step(plant, q, u, dt)
            timed.total += time.perf_counter() - start
            return out

        MujocoPlant.step = step  # type: ignore[method-assign]
        return self

    def __exit__(self, *exc) -> None:
        MujocoPlant.step = self._step  # type: ignore[method-assign]


def measure(name: str, backend: str, sim: str) -> dict[str, float]:
    """One run: wall time (s), the controller's and the plant's shares, simulated time."""
    spec = load_scenario(tasks_dir() / f"{name}.toml")
    with _Timed() as plant:
        start = time.perf_counter()
        run = run_scenario(spec, backend=backend, sim=sim)
        wall = time.perf_counter() - start
    control = float(run.log.step_time.sum())
    return {
        "wall": wall,
        "control": control,
        "plant": plant.total,
        "simulated": len(run.log) * spec.dt,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--scenarios", nargs="+", default=DEFAULT)
    parser.add_argument("--figure", type=Path, default=None)
    args = parser.parse_args()
    cases = [
        (n, b, s)
        for n in args.scenarios
        for b in ("projection", "hqp")
        for s in ("kinematic", "mujoco")
    ]
    for case in cases[:4]:  # warm, both backends: kernels loaded, first-call costs paid
        measure(*case)
    results: dict[tuple[str, str, str], list[dict[str, float]]] = {c: [] for c in cases}
    for _ in range(args.rounds):
        for case in random.sample(cases, len(cases)):
            results[case].append(measure(*case))
    print(f"median of {args.rounds} rounds, interleaved; wall times in s\n")
    print(
        "| scenario | backend | simulated | physics run | real-time factor | controller | "
        "MuJoCo + servos | rest | kinematic run | physics / kinematic |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenarios:
        for backend in ("projection", "hqp"):
            phys = {
                k: statistics.median(r[k] for r in results[(name, backend, "mujoco")])
                for k in ("wall", "control", "plant", "simulated")
            }
            kin = statistics.median(r["wall"] for r in results[(name, backend, "kinematic")])
            rest = phys["wall"] - phys["control"] - phys["plant"]
            print(
                f"| {name} | {backend} | {phys['simulated']:.1f} | {phys['wall']:.2f} | "
                f"{phys['simulated'] / phys['wall']:.1f} | {phys['control']:.2f} | "
                f"{phys['plant']:.2f} | {rest:.2f} | {kin:.2f} | "
                f"{phys['wall'] / kin:.1f} |"
            )
    if args.figure is not None:
        spec = load_scenario(tasks_dir() / "coordinated_carry.toml")
        run = run_scenario(spec, sim="mujoco")
        kinematic = run_scenario(spec)
        title = "Coordinated carry (Sec. 5.3), projection, under MuJoCo physics"
        plots.physics(run.log, run.physics, args.figure, title=title, kinematic=kinematic.log)
        print(f"\nfigure: {args.figure}")


if __name__ == "__main__":
    main()
