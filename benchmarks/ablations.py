#!/usr/bin/env python3
"""What causes what in the paper's method: its four scenarios with parts of ``H`` removed.

Every case runs the scenario with the projection backend (the paper's method) and changes
only the ``[stack]`` weights:

* ``paper``: ``H = w1 f_p + w2 h1`` as shipped (arm energy with the learned stiffness, joint-
  limit avoidance heavy on the waist);
* ``h1 only``: no arm energy (``energy = 0``);
* ``energy only``: no joint-limit avoidance (``limits_arms = limits_waist = 0``);
* ``constant k``: the spring's stiffness a constant (``--k``, N m/rad; default the mean label
  of the shipped dataset, 0.27) instead of the network;
* ``signed spring``: ``1/2 k (pi - alpha)^2`` on the signed arm angle;
* ``human arm angle``: the spring replaced by a level of the human arm angle as a task
  below the hands (the shipped model, ``human_arm_angle_kp = 10`` 1/s; the arm energy keeps
  its gravity part), the motion test on people's ``human_arm_angle`` controller;
* ``human arm angle in H``: the spring replaced by the pull towards it as an objective of
  ``H`` (``human_arm_angle = 20``).

Printed per scenario and case: the worst per-axis MAE of the hands (mm), the waist's travel
(rad), both arms' energy at the last posture by the same measure (the paper's energy with the
learned stiffness, whatever the case ran with, J), the median arm angle of each arm (deg,
frames where it is defined), the share of those frames in the human range [0, 0.8] rad, and
the failures (steps where a task that could have been met was not).

    python benchmarks/ablations.py [--scenarios a,b] [--k 0.27]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from wholebody.control.metrics import ARM_ANGLE_MIN_RHO
from wholebody.presets import default_stiffness
from wholebody.resources import data_dir, tasks_dir
from wholebody.scenarios import load_scenario, run_scenario
from wholebody.scenarios.runner import scenario_robot
from wholebody.tasks import ArmPotentialEnergy

SCENARIOS = (
    "reach_generalisation",
    "obstacle_avoidance",
    "independent_dual_arm",
    "coordinated_carry",
)
HUMAN_RANGE = (0.0, 0.8)  # rad: where most frames of people's arm angles lie


def cases(k: float) -> dict[str, dict[str, object]]:
    """Case name -> the [stack] fields it changes."""
    return {
        "paper": {},
        "h1 only": {"energy": 0.0},
        "energy only": {"limits_arms": 0.0, "limits_waist": 0.0},
        "constant k": {"stiffness": k},
        "signed spring": {"spring": "signed"},
        "human arm angle": {"spring": "none", "human_arm_angle_kp": 10.0},
        "human arm angle in H": {"spring": "none", "human_arm_angle": 20.0},
    }


def mean_label() -> float:
    """The mean stiffness label of the shipped dataset (N m/rad): the constant k of the
    ``constant k`` case."""
    with np.load(data_dir() / "stiffness" / "mobile_humanoid.npz") as data:
        return float(np.mean(data["k"]))


def final_energies(run) -> dict[str, float]:
    """Each arm's energy at the run's last posture by the paper's energy with the robot's
    learned stiffness, whatever stiffness the case ran with (J)."""
    robot = scenario_robot(run.spec)
    state = robot.update(run.log.q[-1])
    learned = default_stiffness(robot)
    return {
        arm: ArmPotentialEnergy(robot, arm, learned).evaluate(state).value for arm in robot.arms
    }


def row(run) -> list[str]:
    m, log = run.metrics, run.log
    mae = max(max(v.values()) for v in m["mae_m"].values()) * 1e3
    cells = [f"{mae:.3f}", f"{m['joint_travel_rad'].get('waist', float('nan')):.2f}"]
    energies = final_energies(run)
    for arm in ("left", "right"):
        energy = energies.get(arm, float("nan"))
        trace = log.arms.get(arm)
        ok = trace.rho >= ARM_ANGLE_MIN_RHO if trace is not None else np.zeros(0, bool)
        alpha = trace.arm_angle[ok] if trace is not None else np.zeros(0)
        inside = np.mean((alpha >= HUMAN_RANGE[0]) & (alpha <= HUMAN_RANGE[1])) if alpha.size else 0
        median = np.degrees(np.median(alpha)) if alpha.size else float("nan")
        cells += [f"{energy:.2f}", f"{median:.0f}", f"{inside:.0%}"]
    cells.append(str(m["solver_failures"]))
    return cells


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument(
        "--k",
        type=float,
        default=None,
        help="the constant stiffness (N m/rad; default the dataset's mean label)",
    )
    args = parser.parse_args()
    args.k = mean_label() if args.k is None else args.k
    head = [
        "case",
        "MAE mm",
        "waist rad",
        "E left J",
        "alpha left deg",
        "left in range",
        "E right J",
        "alpha right deg",
        "right in range",
        "failures",
    ]
    for name in args.scenarios.split(","):
        spec = load_scenario(tasks_dir() / f"{name}.toml")
        print(f"\n{name} (projection backend)")
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
        for case, change in cases(args.k).items():
            variant = dataclasses.replace(spec, stack=dataclasses.replace(spec.stack, **change))
            run = run_scenario(variant, backend="projection")
            print("| " + " | ".join([case, *row(run)]) + " |", flush=True)


if __name__ == "__main__":
    main()
