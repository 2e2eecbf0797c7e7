#!/usr/bin/env python3
"""Arm angle against waist travel: the human-like preset over its waist metric (issue 37).

The preset (``wholebody.presets.HUMAN_LIKE``) drives the arm angle to people's with a task
level below the hands; that level moves the elbow in the hands' null space, where the waist
moves too unless it is dear in the velocity metric (``PaperWeights.waist_metric``). Over the
bundled recordings (every ``--every``-th trial of the 12 participants), each participant's
trials driven by an arm-angle network trained on the others (held out, as
``wholebody humanlike evaluate --held-out``), this prints per waist metric the arm angle's rms
against people's (deg, 95 % interval over participants resampled) and the waist's travel per
trial (rad, the same interval), beside the paper's stack on the same trials.

    python benchmarks/humanlike_tradeoff.py [--every 1] [--metrics 1,10,30,100,300]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from wholebody.humanlike.recordings import load_recordings
from wholebody.presets import HUMAN_LIKE, PaperWeights
from wholebody.robot import load_robot
from wholebody.scenarios.human_motion import evaluate, held_out_arm_angle_models


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=1, help="every N-th trial")
    parser.add_argument("--metrics", default="1,10,30,100,300", help="waist metrics to try")
    args = parser.parse_args()
    start = time.perf_counter()
    every = load_recordings(None)
    recs = every[:: args.every]
    models = held_out_arm_angle_models(every, only=sorted({r.participant for r in recs}))
    controllers: dict[str, PaperWeights] = {"the paper's stack": PaperWeights()}
    for m in (float(x) for x in args.metrics.split(",")):
        controllers[f"human-like, waist metric {m:g}"] = dataclasses.replace(
            HUMAN_LIKE, waist_metric=m
        )
    scores = evaluate(load_robot("mobile_humanoid"), recs, controllers, arm_angle_model=models)
    print(
        "| controller | arm angle rms (deg) | 95 % (people) | waist travel per trial (rad) |"
        " 95 % (people) | waist travel, all trials (rad) | wrist error median / max (mm) |"
    )
    print("|---" * 7 + "|")
    for name, sc in scores.items():
        (a0, a1), (w0, w1) = sc.alpha_rms_deg_interval, sc.waist_travel_rad_per_trial_interval
        print(
            f"| {name} | {sc.alpha_rms_deg:.2f} | [{a0:.2f}, {a1:.2f}] | "
            f"{sc.waist_travel_rad_per_trial:.3f} | [{w0:.3f}, {w1:.3f}] | "
            f"{sc.waist_travel_rad:.0f} | {sc.wrist_error_median_mm:.2f} / "
            f"{sc.wrist_error_mm:.0f} |"
        )
    n = len({r.participant for r in recs})
    print(
        f"\n{len(recs)} trials of {n} participants, held-out arm-angle networks; "
        f"{time.perf_counter() - start:.0f} s"
    )


if __name__ == "__main__":
    main()
