#!/usr/bin/env python3
"""Does the arm angle people choose follow from more than the wrist? (issue 37, item 1)

The shipped arm-angle model predicts ``alpha_h`` from the normalised wrist ``p`` alone
(``data/arm_angle/README.md``). This scores, under the card's own leave-one-participant-out
cross-validation (the same records, network settings and seed), the same network given more
of what a reach knows at run time:

- the hand's direction (fingertip - wrist), in the canonical axes, or in the arm's own
  axes (along shoulder-wrist, toward alpha's downward reference, and their cross product:
  the axes in which the arm angle is measured);
- the wrist's velocity (normalised units per s: its direction, its length capped at 0.2 1/s,
  by differences over each trial's records), which a planned reach knows;
- the reach's phase (time over the trial's duration);
- the reach's start and goal (``p`` at the trial's first record, and at the record farthest
  from it);

and, on the wrist alone, an ensemble of five networks (seeds 0-4, their mean), which tells
whether the wrist's own model has room left. It also prints how far the hand's direction
alone places the elbow from where people hold it, and the wrist model's residuals split
into between and within people. Printed per input set: the rms (deg) over all
held-out records with its 95 % interval over participants resampled, the paired difference
from the wrist alone (the same resamples), and the between-person scatter of the residuals
(deg; the wrist-only model's is the card's 5.5).

    python benchmarks/arm_angle_context.py [--records 20000] [--bootstrap 2000]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from wholebody.arm.angle import DOWN, arm_angle
from wholebody.humanlike.arm_angle_data import ArmAngleRecords, arm_angle_records
from wholebody.humanlike.arm_angle_fit import ArmAngleConfig, train_predictor
from wholebody.humanlike.arm_angle_scores import cross_validate, paired_comparison
from wholebody.humanlike.mapping import CANONICAL_SIDE
from wholebody.humanlike.recordings import load_participants, load_recordings

CONFIG = ArmAngleConfig(hidden=(8,), epochs=100, lr=0.01, batch_size=256, weight_decay=0.01)
"""The shipped model's settings (its card's "Reproduce" command)."""

SPEED_CAP = 0.2
"""1/s: the wrist's velocity enters as its direction times ``min(speed / cap, 1)``."""

INPUT_SETS = (
    "wrist",
    "wrist + hand",
    "wrist + hand in the arm's axes",
    "wrist + velocity",
    "wrist + phase",
    "wrist + start + goal",
    "wrist + hand + start + goal",
)


def reach_context(records: ArmAngleRecords) -> dict[tuple[str, float], np.ndarray]:
    """Per record (keyed by trial and time): the start, the goal, the velocity and the phase
    (module docstring), as one row ``[start(3), goal(3), velocity(3), phase]``."""
    context = {}
    for trial in np.unique(records.trial):
        idx = np.flatnonzero(records.trial == trial)
        idx = idx[np.argsort(records.time_s[idx])]
        p, t = records.p[idx], records.time_s[idx]
        far = np.argmax(np.linalg.norm(p - p[0], axis=1))
        v = np.gradient(p, t, axis=0) if len(idx) > 1 else np.zeros_like(p)
        speed = np.linalg.norm(v, axis=1, keepdims=True)
        v = v / np.maximum(speed, 1e-9) * np.minimum(speed / SPEED_CAP, 1.0)
        phase = (t - t[0]) / max(t[-1] - t[0], 1e-9)
        for k in range(len(idx)):
            context[trial, t[k]] = np.concatenate([p[0], p[far], v[k], [phase[k]]])
    return context


def hand_in_arm_axes(r: ArmAngleRecords) -> np.ndarray:
    """The hand's direction in the arm's axes: along S-W, along alpha's downward reference
    ``DOWN - (DOWN.u) u``, and along their cross product (``wholebody.arm.angle``)."""
    u = r.wrist / np.linalg.norm(r.wrist, axis=1, keepdims=True)
    ref = DOWN - (u @ DOWN)[:, None] * u
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    third = np.cross(u, ref)
    return np.column_stack([np.sum(r.hand * a, axis=1) for a in (u, ref, third)])


def inputs(which: str, context: dict):
    """The features function of an input set: the wrist, then what ``which`` names."""

    def features(r: ArmAngleRecords) -> np.ndarray:
        rows = np.array([context[key] for key in zip(r.trial, r.time_s, strict=True)])
        parts = [r.p]
        if which.endswith("hand") or "hand +" in which:
            parts.append(r.hand)
        if "arm's axes" in which:
            parts.append(hand_in_arm_axes(r))
        if "start" in which:
            parts.append(rows[:, 0:3])
        if "goal" in which:
            parts.append(rows[:, 3:6])
        if "velocity" in which:
            parts.append(rows[:, 6:9])
        if "phase" in which:
            parts.append(rows[:, 9:10])
        return np.hstack(parts)

    return features


def hand_as_forearm(r: ArmAngleRecords) -> tuple[float, float]:
    """The arm angle the hand's direction alone gives (an elbow on the line the hand
    continues back from the wrist) against the person's: the mean offset and the rms about
    it (deg)."""
    elbow = r.wrist - r.hand
    d = np.angle(np.exp(1j * (r.alpha - arm_angle(0.0 * elbow, elbow, r.wrist, CANONICAL_SIDE))))
    offset = np.angle(np.mean(np.exp(1j * d)))
    rms = np.sqrt(np.mean(np.angle(np.exp(1j * (d - offset))) ** 2))
    return float(np.degrees(offset)), float(np.degrees(rms))


class Ensemble:
    """The mean of ``n`` networks on the wrist, seeds 0 .. n-1 (rad)."""

    def __init__(self, records: ArmAngleRecords, n: int) -> None:
        self.members = [
            train_predictor(records.p, records.alpha, dataclasses.replace(CONFIG, seed=s))
            for s in range(n)
        ]

    def predict(self, X: np.ndarray) -> np.ndarray:
        return np.mean([m.predict(X) for m in self.members], axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", type=int, default=20000)
    parser.add_argument("--bootstrap", type=int, default=2000)
    args = parser.parse_args()
    t0 = time.perf_counter()
    import torch

    torch.set_num_threads(1)
    records = arm_angle_records(load_recordings(None), load_participants(), n_records=args.records)
    context = reach_context(records)
    runs = {}
    for which in INPUT_SETS:
        features = inputs(which, context)
        runs[which] = cross_validate(
            records,
            lambda tr, f=features: train_predictor(f(tr), tr.alpha, CONFIG),
            features=features,
            n_boot=args.bootstrap,
        )
    runs["wrist, five networks averaged"] = cross_validate(
        records, lambda tr: Ensemble(tr, 5), n_boot=args.bootstrap
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
    offset, rms = hand_as_forearm(records)
    print(
        f"the hand continuing the forearm: {rms:.1f} deg rms from the person's about its mean "
        f"offset {offset:+.1f} deg; alpha's own sd {np.degrees(np.std(records.alpha)):.1f} deg"
    )
    spread = {k: np.degrees(v) for k, v in runs["wrist"]["spread"].items()}
    print(
        f"the wrist model's held-out residuals: {spread['between']:.2f} deg between people, "
        f"{spread['within']:.2f} deg within a person, {spread['spread']:.2f} deg in all"
    )
    print(f"{len(records)} records; {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
