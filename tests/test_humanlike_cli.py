"""The stiffness command line, the SVR baseline and the shipped data card."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("sklearn")

from wholebody.arm.network import NetworkStiffness
from wholebody.errors import DataError
from wholebody.humanlike.cli import add_stiffness_parser
from wholebody.humanlike.dataset import StiffnessDataset
from wholebody.resources import robots_dir


def _run(*argv: str) -> int:
    parser = argparse.ArgumentParser(prog="wholebody")
    sub = parser.add_subparsers(dest="command", required=True)
    add_stiffness_parser(sub)
    args = parser.parse_args(["stiffness", *argv])
    return args.func(args)


@pytest.mark.slow
def test_dataset_fit_report_end_to_end(tmp_path: Path, capsys):
    ds_path = tmp_path / "ds.npz"
    assert (
        _run(
            "dataset",
            "--no-real",
            "--synthetic-participants",
            "3",
            "--records",
            "300",
            "--quiet",
            "--out",
            str(ds_path),
        )
        == 0
    )
    ds = StiffnessDataset.load(ds_path)
    assert 250 <= len(ds) <= 300
    assert set(ds.source) == {"synthetic"} and set(ds.participant) == {"SYN01", "SYN02", "SYN03"}
    assert ds.meta["robot"] == "mobile_humanoid"
    assert ds.meta["counts"]["synthetic"]["vertical"] > 0  # the hanging starts are dropped
    out = capsys.readouterr().out
    assert "synthetic: 108 trials" in out

    net_path, card = tmp_path / "k.npz", tmp_path / "card.md"
    assert (
        _run(
            "fit",
            "--dataset",
            str(ds_path),
            "--test-participants",
            "SYN03",
            "--hidden",
            "4,4",
            "--epochs",
            "3",
            "--quiet",
            "--date",
            "2026-11-22",
            "--out",
            str(net_path),
            "--card",
            str(card),
        )
        == 0
    )
    net = NetworkStiffness.load(net_path)
    scores = net.meta["scores_held_out_participants"]
    assert set(scores) >= {"network", "svr", "mean"}
    assert net.meta["split"]["test_participants"] == ["SYN03"]
    text = card.read_text()
    assert "2026-11-22" in text and "SYN03" in text
    assert f"{scores['svr']['r2']:.3f}" in text
    assert "--test-participants SYN03" in text  # the card's command reproduces this split
    # ... and the dataset's options: the card's dataset command rebuilds this dataset
    assert (
        "wholebody stiffness dataset --robot mobile_humanoid --arm right --records 300 "
        "--seed 0 --synthetic-participants 3 --no-real --out"
    ) in text

    rep = tmp_path / "rep"
    assert (
        _run(
            "report",
            "--model",
            str(net_path),
            "--dataset",
            str(ds_path),
            "--quiet",
            "--out",
            str(rep),
        )
        == 0
    )
    assert (rep / "k_workspace.png").stat().st_size > 10_000
    saved = json.loads((rep / "scores.json").read_text())
    again = saved["recomputed_network_held_out"]
    assert again["r2"] == pytest.approx(scores["network"]["r2"], abs=1e-9)
    with pytest.raises(DataError, match=r"nope\.npz"):  # a dataset named must exist
        _run(
            "report",
            "--model",
            str(net_path),
            "--dataset",
            str(tmp_path / "nope.npz"),
            "--quiet",
            "--out",
            str(rep),
        )


@pytest.mark.parametrize(
    "argv",
    [
        ("fit", "--epochs", "0"),
        ("fit", "--batch-size", "0"),
        ("fit", "--threads", "0"),
        ("dataset", "--synthetic-participants", "-1"),
        ("dataset", "--records", "0"),
    ],
)
def test_counts_are_checked_by_the_parser(argv, capsys):
    with pytest.raises(SystemExit) as info:
        _run(*argv)
    assert info.value.code == 2 and "expected an integer >=" in capsys.readouterr().err


def test_svr_baseline_on_a_noise_free_slice(humanoid):
    import dataclasses

    from wholebody.humanlike.arm_angle_model import CALIBRATED
    from wholebody.humanlike.dataset import build_dataset
    from wholebody.humanlike.evaluation import regression_scores
    from wholebody.humanlike.mapping import ArmParameters
    from wholebody.humanlike.svr import fit_svr, select_svr
    from wholebody.humanlike.synthetic import DEFAULT_PARTICIPANTS, generate_synthetic

    model = dataclasses.replace(
        CALIBRATED, sd_participant=0.0, sd_block=0.0, sd_trial=0.0, sd_within=0.0
    )
    recs = generate_synthetic(DEFAULT_PARTICIPANTS[:4], seed=0, model=model)
    ds, _ = build_dataset(recs, ArmParameters.from_robot(humanoid), n_records=600)
    train, test = ds.split(["SYN02"])
    params, table = select_svr(
        train.wrist, train.k, train.participant, grid={"C": (1.0, 10.0), "gamma": (1.0,)}
    )
    assert len(table) == 2 and params["C"] in (1.0, 10.0)
    s = regression_scores(test.k, fit_svr(train.wrist, train.k, **params).predict(test.wrist))
    assert s["r2"] > 0.5


def test_shipped_card_reports_the_full_run():
    """The card beside the shipped network states the scores stored in the network file,
    next to the paper's, the split and the date; per real held-out participant with
    intervals; and the network shipped before, scored the same way, below the new one."""
    folder = robots_dir() / "mobile_humanoid"
    net = NetworkStiffness.load(folder / "stiffness.npz")
    text = (folder / "stiffness_card.md").read_text()
    tr = net.meta["training"]
    assert (tr["epochs"], tr["lr"], tr["batch_size"]) == (1000, 0.01, 32)
    assert f"Date: {net.meta['date']}." in text
    scores = net.meta["scores_held_out_participants"]
    for name, label in (("network", "network"), ("svr", "SVR (RBF)")):
        row = next(line for line in text.splitlines() if line.startswith(f"| {label} |"))
        assert f"{scores[name]['r2']:.3f}" in row and f"{scores[name]['mse']:.4f}" in row
    assert "0.9304 / 0.1673" in text and "0.9169 / 0.2352" in text
    held = net.meta["split"]["test_participants"]
    assert held == ["ADL003", "ADL008", "ADL011"]  # real people only (issue 20)
    assert "No synthetic data" in text and np.isfinite(scores["network"]["r2"])
    per = net.meta["scores_real_held_out"]["per_participant"]
    (previous,) = net.meta["references"]
    for person in [*held, "all"]:
        line = next(x for x in text.splitlines() if x.startswith(f"| {person} |"))
        for model in ("network", "svr", "mean", previous):
            v = per[model][person]
            assert f"{v['r2']:.3f} [{v['low']:.3f}, {v['high']:.3f}]" in line
    # measured the same way: the pooled row of the per-participant table is the pooled score
    assert per["network"]["all"]["r2"] == pytest.approx(scores["network"]["r2"])
    assert per[previous]["all"]["r2"] == pytest.approx(scores[previous]["r2"])
    # shipped because it is better on the real held-out people, each of them
    assert per["network"]["all"]["low"] > per[previous]["all"]["high"]
    assert all(per["network"][p]["r2"] > per[previous][p]["r2"] for p in held)
    assert "--compare-with stiffness_previous.npz" in text


def test_shipped_scores_recomputed_from_the_shipped_dataset():
    """The card's per-participant R^2 of the shipped network, recomputed from the shipped
    dataset's records of the held-out participants."""
    from wholebody.humanlike.evaluation import regression_scores
    from wholebody.resources import data_dir

    net = NetworkStiffness.load(robots_dir() / "mobile_humanoid" / "stiffness.npz")
    ds = StiffnessDataset.load(data_dir() / "stiffness" / "mobile_humanoid.npz")
    per = net.meta["scores_real_held_out"]["per_participant"]["network"]
    for person in net.meta["split"]["test_participants"]:
        s = ds.participant == person
        got = regression_scores(ds.k[s], net.predict(ds.wrist[s]))["r2"]
        assert got == pytest.approx(per[person]["r2"], abs=1e-9)
        assert per[person]["low"] <= got <= per[person]["high"]
