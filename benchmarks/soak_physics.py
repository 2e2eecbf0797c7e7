#!/usr/bin/env python3
"""The carry under physics, read through a sensor: does it still track within 5 mm?

The coordinated carry (``tasks/coordinated_carry.toml``, 27 s) under MuJoCo physics on both
backends, its controller reading the joints through a
:class:`~wholebody.control.JointSensor`: uniform noise of ``--noise`` (rad; m for a
prismatic joint) on every encoder and a delay of ``--delay`` control periods (10 ms each).
Per backend, the cases:

* ``exact``: the plant's state as it is (the README's physics run);
* ``noise + delay``: the sensor, once per noise seed (``--seeds``), the controller
  compensating its latency (``Controller(latency=delay)``, the default of a scenario run);
* ``uncompensated``: the same sensor (seed 0), ``latency=0``: the feedback on a stale pose.

Printed per case, on the simulated (true) configuration, not on what the controller saw: the
hands' distance to their references (mean over the steps and hands, and the largest), the
closed chain's largest error while carrying, whether every hand stayed within 5 mm, and
the largest hand error the controller saw. With ``--figure PATH`` it draws the worse hand's
true error over time for the three cases, one panel per backend.

    python benchmarks/soak_physics.py [--noise 1e-4] [--delay 1] [--seeds 5] [--figure PATH]
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

import numpy as np

import wholebody
from wholebody.control import JointSensor
from wholebody.resources import tasks_dir
from wholebody.scenarios import load_scenario, run_scenario

BOUND = 5e-3  # m: issue 32's tracking bound for the carry


def true_hand_errors(run) -> np.ndarray:
    """(N,) the worse hand's distance (m) to its reference at each step, on the simulated
    configuration (NaN where no hand has a reference)."""
    robot = wholebody.load_robot(run.spec.robot)
    q = run.physics["configuration"]
    out = np.full(len(run.log), np.nan)
    for hand, spec in run.spec.hands.items():
        ref = run.log.reference_positions[hand]
        for k in np.flatnonzero(np.isfinite(ref).all(axis=1)):
            e = np.linalg.norm(robot.frame_pose(q[k], spec.frame)[:3, 3] - ref[k])
            out[k] = e if np.isnan(out[k]) else max(out[k], e)
    return out


def case(spec, backend: str, sensor: JointSensor | None, latency: int | None) -> dict:
    """One physics run's figures (mm; on the true state) and its worse hand's error per step
    (m)."""
    run = run_scenario(spec, backend=backend, sim="mujoco", sensor=sensor, latency=latency)
    m = run.metrics
    seen = max(m["max_tracking_error_m"].values())
    if sensor is None:  # what the controller saw is the true state
        log = run.log
        mean = np.mean(
            [
                np.nanmean(
                    np.linalg.norm(log.frame_positions[h] - log.reference_positions[h], axis=1)
                )
                for h in log.frame_positions
            ]
        )
        true_max, chain = seen, m["closed_chain_error_max_m"]
    else:
        mean = np.mean(list(m["true_mean_tracking_error_m"].values()))
        true_max = max(m["true_max_tracking_error_m"].values())
        chain = m["true_closed_chain_error_max_m"]
    return {
        "mean": 1e3 * mean,
        "max": 1e3 * true_max,
        "chain": 1e3 * chain,
        "seen": 1e3 * seen,
        "stopped": m["stopped"],
        "t": run.log.t,
        "errors": true_hand_errors(run),
    }


def report(label: str, backend: str, c: dict) -> None:
    ok = "yes" if c["max"] <= BOUND * 1e3 and c["stopped"] is None else "NO"
    print(
        f"| {label} | {backend} | {c['mean']:.3f} | {c['max']:.3f} | {c['chain']:.3f} | "
        f"{ok} | {c['seen']:.3f} |"
    )


def figure(
    path: Path, curves: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]], title: str
) -> None:
    """The worse hand's true error (mm) over time, per backend and case."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(curves), 1, figsize=(9, 3.2 * len(curves)), sharex=True)
    for ax, (backend, cases) in zip(np.atleast_1d(axes), curves.items(), strict=True):
        for label, (t, e) in cases.items():
            ax.plot(t, 1e3 * e, lw=0.8, label=label)
        ax.axhline(1e3 * BOUND, color="k", ls=":", lw=0.8, label="5 mm")
        ax.set_ylabel("true hand error (mm)")
        ax.set_title(backend, fontsize=9)
        ax.legend(fontsize=8, loc="upper right")
    np.atleast_1d(axes)[-1].set_xlabel("t (s)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise", type=float, default=1e-4, help="rad (m prismatic)")
    parser.add_argument("--delay", type=int, default=1, help="control periods")
    parser.add_argument("--seeds", type=int, default=5, help="noise seeds 0 .. S-1")
    parser.add_argument("--backends", default="projection,hqp")
    parser.add_argument("--figure", type=Path, default=None)
    args = parser.parse_args()
    spec = load_scenario(tasks_dir() / "coordinated_carry.toml")
    print(
        f"coordinated_carry under MuJoCo, {spec.duration:.0f} s at {spec.rate_hz:.0f} Hz; "
        f"sensor noise U[-{args.noise:g}, {args.noise:g}] rad (m) per encoder, delay "
        f"{args.delay} period(s) = {args.delay / spec.rate_hz * 1e3:.0f} ms; "
        f"{platform.machine()}, Python {platform.python_version()}\n"
    )
    print(
        "errors in mm, on the simulated configuration; 'seen': the largest hand error the "
        "controller saw\n"
    )
    print("| case | backend | hand mean | hand max | closed chain max | within 5 mm | seen max |")
    print("|---|---|---|---|---|---|---|")
    curves: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for backend in args.backends.split(","):
        exact = case(spec, backend, None, None)
        report("exact", backend, exact)
        runs = [
            case(spec, backend, JointSensor(args.noise, args.delay, seed), None)
            for seed in range(args.seeds)
        ]
        for seed, c in enumerate(runs):
            report(f"noise + delay, seed {seed}", backend, c)
        worst = max(runs, key=lambda c: c["max"])
        report(f"noise + delay, worst of {args.seeds} seeds", backend, worst)
        stale = case(spec, backend, JointSensor(args.noise, args.delay, 0), 0)
        report("uncompensated (latency 0), seed 0", backend, stale)
        curves[backend] = {
            "exact": (exact["t"], exact["errors"]),
            "noise + delay, compensated (seed 0)": (runs[0]["t"], runs[0]["errors"]),
            "noise + delay, uncompensated": (stale["t"], stale["errors"]),
        }
    if args.figure is not None:
        figure(
            args.figure,
            curves,
            f"Coordinated carry under MuJoCo: joints read with "
            f"±{args.noise:g} rad noise, {args.delay} period(s) late",
        )
        print(f"\nfigure: {args.figure}")


if __name__ == "__main__":
    main()
