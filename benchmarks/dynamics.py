#!/usr/bin/env python3
"""The torque level against TSID on the same TALOS standing problem, in one run (issue 35).

The problem (``benchmarks/peers/tsid/talos_stand.py`` states TSID's side in full): TALOS
(example-robot-data's full_v2 URDF, the grippers locked) standing in its half-sitting
posture on both soles, 6-D contacts on soles of 0.2 m x 0.13 m with friction 0.3 and
5-1500 N of normal force; the centre of mass follows ``com0 + [0, 0.05 sin(pi t), 0]`` (m)
under a PD law of Kp = 100 1/s^2, Kd = 20 1/s with its reference's velocity as
feed-forward, above a posture task towards the start; 2000 steps of 1 ms, integrated
kinematically (``u += a dt``, ``q = integrate(q, u, dt)``; no simulator).

wholebody's side: :class:`wholebody.dynamics.DynamicsSolver` with the same contacts, a
:class:`~wholebody.tasks.ComTask` of gain 5 1/s under ``velocity_gain = 20`` (the same PD:
``K_d k = 100``), the posture (gain 0.5 1/s: ``K_p`` 10) and joint position and velocity
limits, in its strict mode (the CoM's level above the posture's) and its weighted mode
(one level, the posture's rows weighted ``sqrt(1e-3)``, TSID's weight), with TSID's
force regularisation replaced by wholebody's (the contacts' internal wrenches, then their
tangential forces and torques, kept small).

Measured per run: the step's wall time (wholebody: ``solver.solve``; TSID:
``computeProblemData`` + ``solve``), median and p90 over the steps after the first 10 (us),
and the median of its QP alone (wholebody: ``result.qp_time``, the weighted QP's kernel or
the cascade's; TSID: ``solver.solve``); the CoM's tracking error ``|com(q_k) -
com_ref(t_k)|`` (rms and max over the run, and rms over its second half, mm); the soles'
drift (mm). The cases are interleaved ``--repeat`` times; the table gives the medians over
the repeats.

    bash benchmarks/peers/tsid/setup.sh      # once: TSID's own virtual environment
    python benchmarks/dynamics.py [--repeat 3] [--steps 2000] [--no-tsid]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

import wholebody as wb
from wholebody.dynamics import DynamicsSolver, PatchContact

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tsid_peer import TsidPeerError, default_problem, run_tsid

DT = 1e-3
FEET = ("left_sole_link", "right_sole_link")
AMPLITUDE, FREQUENCY = 0.05, 0.5  # m, Hz
WARMUP = 10


def reference(com0: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """The CoM's reference and its velocity at ``t`` (m, m/s)."""
    w = 2.0 * math.pi * FREQUENCY
    return (
        com0 + np.array([0.0, AMPLITUDE * math.sin(w * t), 0.0]),
        np.array([0.0, AMPLITUDE * w * math.cos(w * t), 0.0]),
    )


def ours(mode: str, steps: int) -> dict:
    """One run of wholebody's side; its figures."""
    robot = wb.load_robot("talos_full")
    q = robot.home()
    com = wb.ComTask(robot, "xyz", kp=5.0)
    posture = wb.PostureTask(robot, kp=0.5)
    limits = [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)]
    stack = wb.Stack(robot, [[com], [posture]], limits)
    feet = [
        PatchContact(f, mu=0.3, f_min=5.0, f_max=1500.0, half_length=0.1, half_width=0.065)
        for f in FEET
    ]
    for c in feet:
        c.kp, c.kd = 10.0, 2.0 * math.sqrt(10.0)
    weights = [1.0, math.sqrt(1e-3)] if mode == "weighted" else None
    solver = DynamicsSolver(
        robot,
        feet,
        mode=mode,
        velocity_gain=20.0,
        acceleration_limits=False,
        level_weights=weights,
    )
    solver.make_contacts(q)
    com0, soles0 = robot.com_position(q), [robot.frame_pose(q, f)[:3, 3] for f in FEET]
    u = np.zeros(robot.nu)
    times, errors, qp = np.zeros(steps), np.zeros(steps), np.zeros(steps)
    for k in range(steps):
        target, velocity = reference(com0, k * DT)
        errors[k] = np.linalg.norm(robot.com_position(q) - target)
        com.set_target(target, velocity)
        start = time.perf_counter()
        res = solver.solve(stack, q, u, DT)
        times[k] = time.perf_counter() - start
        qp[k] = res.qp_time
        u = u + res.a * DT
        q = robot.integrate(q, u, DT)
        stack.advance(solver.state, DT)
    drift = max(
        np.linalg.norm(robot.frame_pose(q, f)[:3, 3] - p) for f, p in zip(FEET, soles0, strict=True)
    )
    return _figures(times[WARMUP:] * 1e6, errors, drift, 36 + 12, qp[WARMUP:] * 1e6)


def _figures(
    step_us: np.ndarray, errors: np.ndarray, drift: float, n_var: int, qp_us: np.ndarray
) -> dict:
    half = errors[errors.size // 2 :]
    return {
        "step_us": float(np.median(step_us)),
        "qp_us": float(np.median(qp_us)),
        "p90_us": float(np.percentile(step_us, 90)),
        "rms_mm": float(np.sqrt(np.mean(errors**2)) * 1e3),
        "max_mm": float(errors.max() * 1e3),
        "rms2_mm": float(np.sqrt(np.mean(half**2)) * 1e3),
        "drift_mm": float(drift * 1e3),
        "n_var": n_var,
    }


def tsid(steps: int) -> dict:
    """One run of TSID's side (its own venv, a subprocess); its figures."""
    out = run_tsid(default_problem(steps=steps, dt=DT))
    solve = out["solve_us"]
    err = out["com_error_m"]
    return {
        "step_us": solve["median"],
        "qp_us": out["qp_us"]["median"],
        "p90_us": solve["p90"],
        "rms_mm": err["rms"] * 1e3,
        "max_mm": err["max"] * 1e3,
        "rms2_mm": out["com_error_second_half_m"]["rms"] * 1e3,
        "drift_mm": max(f["translation_m"] for f in out["feet_drift"].values()) * 1e3,
        "n_var": out["qp"]["n_var"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--no-tsid", action="store_true", help="wholebody's side only")
    args = parser.parse_args()
    cases = {"wholebody strict": lambda: ours("strict", args.steps)}
    cases["wholebody weighted"] = lambda: ours("weighted", args.steps)
    if not args.no_tsid:
        cases["TSID 1.10 (eiquadprog-fast)"] = lambda: tsid(args.steps)
    runs: dict[str, list[dict]] = {name: [] for name in cases}
    with threadpool_limits(1):
        for _ in range(args.repeat):  # interleaved
            for name, case in cases.items():
                try:
                    runs[name].append(case())
                except TsidPeerError as exc:
                    sys.exit(f"TSID: {exc}")
    keys = ("step_us", "p90_us", "qp_us", "rms_mm", "max_mm", "rms2_mm", "drift_mm", "n_var")
    head = "| case | step median (us) | step p90 (us) | of which the QP (us) | CoM rms (mm) |"
    head += " CoM max (mm) | CoM rms, 2nd half (mm) | soles' drift (mm) | QP variables |"
    print(head)
    print("|---" * 9 + "|")
    for name, rs in runs.items():
        med = [float(np.median([r[k] for r in rs])) for k in keys]
        print(f"| {name} | " + " | ".join(_cell(v) for v in med) + " |")
    print(f"\n{args.repeat} interleaved runs of {args.steps} steps; medians over the runs.")


def _cell(value: float) -> str:
    return f"{value:.0f}" if abs(value) >= 100 else f"{value:.3g}"


if __name__ == "__main__":
    main()
