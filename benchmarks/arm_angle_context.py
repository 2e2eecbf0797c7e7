#!/usr/bin/env python3
"""Does the arm angle people choose follow from more than the wrist? (issue 37, item 1)

The shipped arm-angle model predicts ``alpha_h`` from the normalised wrist ``p`` alone
(``data/arm_angle/README.md``). This scores, under the card's own leave-one-participant-out
cross-validation (the same records, network settings and seed), the same network given more
of what a reach knows at run time: the hand's direction (fingertip - wrist, canonical axes),
the reach's start and its goal (``p`` at the trial's first record, and at the record farthest
from it), alone and together. Printed per input set: the rms (deg) over all held-out records
with its 95 % interval over participants resampled, the paired difference from the wrist
alone (the same resamples), and the between-person scatter of the residuals (deg; the
wrist-only model's is the card's 5.5).

    python benchmarks/arm_angle_context.py [--records 20000] [--bootstrap 2000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from wholebody.humanlike.arm_angle_data import arm_angle_records
from wholebody.humanlike.arm_angle_fit import ArmAngleConfig, train_predictor
from wholebody.humanlike.arm_angle_scores import cross_validate, paired_comparison
from wholebody.humanlike.recordings import load_participants, load_recordings

CONFIG = ArmAngleConfig(hidden=(8,), epochs=100, lr=0.01, batch_size=256, weight_decay=0.01)
"""The shipped model's settings (its card's "Reproduce" command)."""


def reach_context(records) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per trial, the normalised wrist at its first record (the start) and at the record
    farthest from it (the goal)."""
    start, goal = {}, {}
    for trial in np.unique(records.trial):
        idx = np.flatnonzero(records.trial == trial)
        first = idx[np.argmin(records.time_s[idx])]
        far = idx[np.argmax(np.linalg.norm(records.p[idx] - records.p[first], axis=1))]
        start[trial], goal[trial] = records.p[first], records.p[far]
    return start, goal


def inputs(which: str, start: dict, goal: dict):
    """The features function of an input set: the wrist, then what ``which`` names."""

    def features(r) -> np.ndarray:
        parts = [r.p]
        if "hand" in which:
            parts.append(r.hand)
        if "start" in which:
            parts.append(np.array([start[t] for t in r.trial]))
        if "goal" in which:
            parts.append(np.array([goal[t] for t in r.trial]))
        return np.hstack(parts)

    return features


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", type=int, default=20000)
    parser.add_argument("--bootstrap", type=int, default=2000)
    args = parser.parse_args()
    t0 = time.perf_counter()
    import torch

    torch.set_num_threads(1)
    records = arm_angle_records(load_recordings(None), load_participants(), n_records=args.records)
    start, goal = reach_context(records)
    runs = {}
    for which in ("wrist", "wrist + hand", "wrist + start + goal", "wrist + hand + start + goal"):
        features = inputs(which, start, goal)
        runs[which] = cross_validate(
            records,
            lambda tr, f=features: train_predictor(f(tr), tr.alpha, CONFIG),
            features=features,
            n_boot=args.bootstrap,
        )
    print(
        "| inputs | rms (deg) | 95 % (participants) | minus wrist alone (deg) | "
        "between-person scatter (deg) |"
    )
    print("|---|---|---|---|---|")
    for which, cv in runs.items():
        s = cv["summary"]["network"]
        d = paired_comparison(runs["wrist"], cv, records, n_boot=args.bootstrap)
        print(
            f"| {which} | {s['rms_deg']:.2f} | [{s['low']:.2f}, {s['high']:.2f}] | "
            f"{d['minus_base_deg']:+.2f} [{d['low']:+.2f}, {d['high']:+.2f}] | "
            f"{cv['scatter_deg']['network']['sd']:.2f} |"
        )
    print(f"{len(records)} records; {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
