#!/usr/bin/env python3
"""The stiffness network against a linear model and the SVR on people it never saw (issue 37).

Leave one participant out over the bundled stiffness dataset (``data/stiffness/
mobile_humanoid.npz``: the 12 people's records): for each participant, the network (the
shipped settings: hidden 16,16, weight decay 0.1, 1000 epochs, seed 0), the least-squares
linear model (:mod:`wholebody.humanlike.linear`) and the SVR (the shipped card's
hyper-parameters) are fitted to the other eleven and scored on the one left out (R^2 about
that person's own mean: how well a new person's k is predicted). Printed: each
participant's R^2 per model, the mean over participants with its 95 % interval over
participants resampled, and the paired differences network - linear and network - SVR with
theirs (the same resamples for both models).

    python benchmarks/stiffness_baselines.py [--epochs 1000] [--out runs/stiffness_baselines.json]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from wholebody.files import write_json
from wholebody.humanlike.dataset import StiffnessDataset
from wholebody.humanlike.evaluation import cluster_bootstrap, regression_scores
from wholebody.humanlike.linear import fit_linear
from wholebody.humanlike.svr import fit_svr
from wholebody.humanlike.training import TrainingConfig, train_network

DATASET = Path(__file__).resolve().parents[1] / "data" / "stiffness" / "mobile_humanoid.npz"
SVR = {"C": 1.0, "gamma": 0.3, "epsilon": 0.1}  # (robots/mobile_humanoid/stiffness_card.md)


def held_out(ds: StiffnessDataset, person: str, config: TrainingConfig) -> dict[str, float]:
    """Each model's R^2 on ``person``, fitted to everyone else."""
    train, test = ds.split([person])
    net = train_network(train.wrist, train.k, config).network
    models = {
        "network": net.predict(test.wrist),
        "linear": fit_linear(train.wrist, train.k).predict(test.wrist),
        "SVR": fit_svr(train.wrist, train.k, **SVR).predict(test.wrist),
    }
    return {name: regression_scores(test.k, p)["r2"] for name, p in models.items()}


def summary(scores: dict[str, dict[str, float]]) -> dict[str, list[float]]:
    """Mean over participants (with its interval over participants resampled) of each model
    and of the paired differences."""
    people = sorted(scores)
    table = {m: np.array([scores[p][m] for p in people]) for m in ("network", "linear", "SVR")}
    table["network - linear"] = table["network"] - table["linear"]
    table["network - SVR"] = table["network"] - table["SVR"]
    ids = np.arange(len(people))
    return {
        name: list(cluster_bootstrap(lambda i, v=v: float(v[i].mean()), ids))
        for name, v in table.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=1000)
    parser.add_argument("--out", default="runs/stiffness_baselines.json")
    args = parser.parse_args()
    start = time.perf_counter()
    import torch

    torch.set_num_threads(1)
    ds = StiffnessDataset.load(DATASET)
    config = TrainingConfig(hidden=(16, 16), weight_decay=0.1, epochs=args.epochs)
    scores = {}
    for person in sorted(set(ds.participant.tolist())):
        scores[person] = held_out(ds, person, config)
        row = "  ".join(f"{m} {v:.3f}" for m, v in scores[person].items())
        print(f"{person}: {row}", flush=True)
    out = summary(scores)
    wins = sum(s["network"] > s["linear"] for s in scores.values())
    print("\n| model | mean R^2 over participants | 95 % (participants) |")
    print("|---|---|---|")
    for name, (value, low, high) in out.items():
        print(f"| {name} | {value:.3f} | [{low:.3f}, {high:.3f}] |")
    print(f"\nthe network above the linear model for {wins} of {len(scores)} participants")
    print(f"{time.perf_counter() - start:.0f} s")
    write_json(args.out, {"per_participant": scores, "summary": out, "epochs": args.epochs})


if __name__ == "__main__":
    main()
