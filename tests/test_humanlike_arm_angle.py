"""The arm-angle model of people: records, the network (numpy against torch, gradient, file),
the cross-validation's scores recomputed, and the shipped network with its card."""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from wholebody.arm import (
    ConstantArmAngle,
    HumanArmAngleModel,
    NetworkArmAngle,
    default_arm_angle_model,
    normalised_wrist,
)
from wholebody.arm.angle import arm_angle
from wholebody.arm.human_arm_angle import arm_angle_model_path
from wholebody.errors import DataError, DimensionError
from wholebody.humanlike.arm_angle_data import ArmAngleRecords, arm_angle_records, kim_predictions
from wholebody.humanlike.arm_angle_model import CALIBRATED
from wholebody.humanlike.arm_angle_scores import (
    between_person_scatter,
    cross_validate,
    paired_comparison,
    spread_of,
    wrap,
)
from wholebody.humanlike.evaluation import (
    cluster_bootstrap,
    paired_r2_difference,
    r2_with_intervals,
    regression_scores,
)
from wholebody.humanlike.linear import fit_linear
from wholebody.humanlike.recordings import load_participants, load_recording, real_recordings_dir


def _random_net(rng, hidden=(6, 5), spread=0.2) -> NetworkArmAngle:
    sizes = [3, *hidden, 1]
    W = [rng.normal(size=(b, a)) for a, b in itertools.pairwise(sizes)]
    b = [rng.normal(size=n) for n in sizes[1:]]
    return NetworkArmAngle(
        W,
        b,
        rng.normal(size=3) * 0.1,
        rng.uniform(0.2, 0.5, 3),
        0.3,
        0.25,
        spread,
        spread_between=0.12,
        spread_within=0.16,
        input_low=-np.ones(3),
        input_high=np.ones(3),
    )


# ---------------------------------------------------------------------------- the models
def test_network_gradient_equals_finite_differences(rng):
    net = _random_net(rng)
    h = 1e-6
    for p in rng.uniform(-1.5, 1.5, (30, 3)):  # also outside the data's box
        alpha, g = net.evaluate(p)
        assert alpha == pytest.approx(float(net.predict(p)), abs=1e-14)
        np.testing.assert_allclose(g, net.gradient(p), atol=1e-13)
        fd = [
            (net.evaluate(p + h * e)[0] - net.evaluate(p - h * e)[0]) / (2 * h) for e in np.eye(3)
        ]
        np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
    P = rng.uniform(-1, 1, (7, 3))  # vectorised forms agree with the one-point form
    np.testing.assert_allclose(net.predict(P), [net.evaluate(p)[0] for p in P], atol=1e-14)
    np.testing.assert_allclose(net.gradient(P), [net.evaluate(p)[1] for p in P], atol=1e-13)


def test_the_robot_queries_with_its_own_lengths_and_chains_the_gradient(rng):
    """p = (W - S) / (L1 + L2): a wrist twice as far on an arm twice as long is the same
    query, and d alpha / d(W - S) = (d alpha / dp) / (L1 + L2)."""
    net = _random_net(rng)
    w = np.array([0.25, 0.05, -0.2])
    L1, L2 = 0.2662, 0.2482
    a1 = net.evaluate(normalised_wrist(w, L1, L2))[0]
    assert net.evaluate(normalised_wrist(2 * w, 2 * L1, 2 * L2))[0] == pytest.approx(a1)
    g = net.evaluate(normalised_wrist(w, L1, L2))[1] / (L1 + L2)
    h = 1e-7
    fd = [
        (
            net.evaluate(normalised_wrist(w + h * e, L1, L2))[0]
            - net.evaluate(normalised_wrist(w - h * e, L1, L2))[0]
        )
        / (2 * h)
        for e in np.eye(3)
    ]
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
    with pytest.raises(DimensionError, match="lengths must be > 0"):
        normalised_wrist(w, 0.0, L2)


def test_constant_model_and_the_abstract_contract():
    c = ConstantArmAngle(0.3, 0.2)
    alpha, g = c.evaluate(np.array([0.4, 0.0, -0.3]))
    assert alpha == 0.3 and not g.any() and c.spread == 0.2
    np.testing.assert_array_equal(c.predict(np.zeros((4, 3))), np.full(4, 0.3))
    with pytest.raises(DimensionError, match=r"\(3,\) array"):
        c.evaluate(np.zeros(4))
    with pytest.raises(DimensionError, match="spread"):
        ConstantArmAngle(0.3, -0.1)
    with pytest.raises(TypeError):
        HumanArmAngleModel()  # type: ignore[abstract]

    class Tilted(HumanArmAngleModel):  # the default predict loops over evaluate
        spread = 0.1

        def evaluate(self, p):
            return float(p[2]), np.array([0.0, 0.0, 1.0])

    P = np.arange(12.0).reshape(2, 2, 3)
    np.testing.assert_array_equal(Tilted().predict(P), P[..., 2])


def test_file_round_trip_and_malformed_files(rng, tmp_path: Path):
    net = _random_net(rng)
    net.meta["training"] = {"epochs": 3}
    path = net.save(tmp_path / "a.npz")
    back = NetworkArmAngle.load(path)
    P = rng.uniform(-1, 1, (20, 3))
    np.testing.assert_array_equal(back.predict(P), net.predict(P))
    assert (back.spread, back.spread_between, back.spread_within) == (0.2, 0.12, 0.16)
    assert back.meta["training"]["epochs"] == 3
    assert back.in_range(np.zeros(3)) and not back.in_range(np.full(3, 1.1))
    with np.load(path, allow_pickle=False) as z:
        arrays = dict(z)
    for name, change, fragment in (
        ("W1", np.full_like(arrays["W1"], np.nan), "must be finite"),
        ("b0", np.array([np.inf, *arrays["b0"][1:]]), "must be finite"),
        ("alpha_scale", np.array(np.nan), "alpha_scale must be > 0|must be finite"),
        ("x_mean", np.zeros(4), r"x_mean must have shape \(3,\)"),
        ("spread", np.array(-0.1), "spread must be a finite angle"),
        ("spread", np.array(np.nan), "spread must be a finite angle"),
        ("W9", np.zeros((1, 1)), "beyond n_layers"),
        ("format", np.array("wholebody.stiffness_mlp/1"), "format"),
        ("x_scale", np.array([object()]), "not a readable arm-angle network"),
        ("meta", np.array("[1, 2]"), "must be a JSON object"),
    ):
        bad = tmp_path / f"bad_{name}_{fragment[:4]}.npz"
        np.savez(bad, **{**arrays, name: change})
        with pytest.raises(DataError, match=fragment) as info:
            NetworkArmAngle.load(bad)
        assert str(bad) in str(info.value)
    for key in ("alpha_mean", "b1"):
        bad = tmp_path / f"no_{key}.npz"
        np.savez(bad, **{k: v for k, v in arrays.items() if k != key})
        with pytest.raises(DataError, match="missing"):
            NetworkArmAngle.load(bad)
    stiffness = tmp_path / "k.npz"  # a stiffness network is not an arm-angle network
    from wholebody.arm.network import default_stiffness

    default_stiffness().save(stiffness)
    with pytest.raises(DataError, match="missing key"):
        NetworkArmAngle.load(stiffness)


# ---------------------------------------------------------------------------- the records
@pytest.fixture(scope="module")
def trials():
    names = [
        f"ADL00{i}_{t}_{s}{n}"
        for i in (2, 5, 9)
        for t in ("forward", "combing")
        for s in "RL"
        for n in (1, 2)
    ]
    return [load_recording(real_recordings_dir() / f"{n}.csv") for n in names]


def test_records_are_the_persons_arm_angle_at_the_normalised_wrist(trials):
    people = load_participants()
    rec = arm_angle_records(trials, people, n_records=240)
    assert len(rec) == 240 and set(rec.task) == {"forward", "combing"}
    per_trial = [int((rec.trial == t).sum()) for t in set(rec.trial)]
    assert len(per_trial) == len(trials) and max(per_trial) - min(per_trial) <= 1
    # alpha is the lab posture's own arm angle with its side, p the wrist over the arm length
    for t in trials[:8]:
        sel = rec.trial == t.name
        idx = np.searchsorted(t.time_s, rec.time_s[sel])
        lab = arm_angle(t.shoulder[idx], t.elbow[idx], t.wrist[idx], t.side_sign)
        np.testing.assert_allclose(rec.alpha[sel], lab)
        reach = np.median(t.upper_arm_lengths()) + np.median(t.forearm_lengths())
        np.testing.assert_allclose(
            np.linalg.norm(rec.p[sel], axis=1),
            np.linalg.norm(t.wrist[idx] - t.shoulder[idx], axis=1) / reach,
        )
    assert np.all(np.linalg.norm(rec.p, axis=1) < 1.02)
    # mirrored arms: both reach forward (+x) and medial-ish, combing lifts the hand up
    assert np.all(rec.p[rec.task == "forward", 0] > 0)
    assert rec.p[rec.task == "combing", 2].max() > 0.3 > rec.p[rec.task == "forward", 2].max()
    np.testing.assert_allclose(np.linalg.norm(rec.hand, axis=1), 1.0)
    c = rec.counts["combing"]
    assert c["kept"] + c["dropped"] == c["frames"] and c["vertical"] > 0  # the hand overhead


def test_ill_defined_frames_are_dropped(trials):
    """A hanging arm (vertical shoulder-wrist line) or a straight one: no arm angle."""
    t = trials[0]
    down = np.array([0.0, 0.0, -1.0])
    hanging = replace(
        t, elbow=t.shoulder + 0.28 * down + [0.02, 0.0, 0.0], wrist=t.shoulder + 0.52 * down
    )
    with pytest.raises(DataError, match="no frame of the 1 recording"):
        arm_angle_records([hanging])
    straight = replace(t, elbow=t.shoulder + 0.5 * (t.wrist - t.shoulder))
    with pytest.raises(DataError, match="passed the frame rules"):
        arm_angle_records([straight])


def test_kim_baseline_is_the_calibrated_model_per_person(trials):
    people = load_participants()
    rec = arm_angle_records(trials, people, n_records=120)
    kim = kim_predictions(rec, CALIBRATED)
    for i in (0, 50, 119):  # one person at a time through the model's own predict
        one = CALIBRATED.predict(
            np.zeros(3),
            rec.wrist[i],
            rec.upper_arm[i],
            rec.forearm[i],
            people[rec.participant[i]].stature,
        )
        assert kim[i] == pytest.approx(float(one), abs=1e-12)
    with pytest.raises(DataError, match="stature of ADL002"):
        kim_predictions(arm_angle_records(trials[:2], None, n_records=10), CALIBRATED)


# ---------------------------------------------------------------------------- the scores
def test_cluster_bootstrap_resamples_whole_clusters():
    """Ten zeros in one trial and a one in another: drawing two trials gives a mean of 0,
    1/11 or 1, each pair of equal trials a quarter of the time, so the 95 % interval is
    [0, 1]. Resampling the 11 frames instead would give a narrow interval about 1/11."""
    values = np.array([0.0] * 10 + [1.0])
    clusters = np.array(["a"] * 10 + ["b"])
    v, lo, hi = cluster_bootstrap(lambda i: float(values[i].mean()), clusters, n_boot=400)
    assert v == pytest.approx(1 / 11)
    assert (lo, hi) == (0.0, 1.0)
    again = cluster_bootstrap(lambda i: float(values[i].mean()), clusters, n_boot=400)
    assert again == (v, lo, hi)  # seeded
    with pytest.raises(DataError, match=">= 2 clusters"):
        cluster_bootstrap(np.mean, np.zeros(5))


def test_r2_per_group_is_each_groups_own_r2(rng):
    y = rng.normal(size=60)
    pred = y + rng.normal(scale=0.5, size=60)
    groups = np.repeat(["P1", "P2", "P3"], 20)
    clusters = np.repeat(np.arange(12), 5)
    out = r2_with_intervals(y, {"m": pred}, groups, clusters, n_boot=50)
    for g in ("P1", "P2", "P3"):
        s = groups == g
        assert out["m"][g]["r2"] == pytest.approx(regression_scores(y[s], pred[s])["r2"])
        assert out["m"][g]["low"] <= out["m"][g]["r2"] <= out["m"][g]["high"]
    assert out["m"]["all"]["r2"] == pytest.approx(regression_scores(y, pred)["r2"])


def test_the_paired_r2_difference_scores_both_models_on_the_same_resamples(rng):
    """``R^2(a) - R^2(b)`` per group equals the difference of their R^2; a model that is the
    other plus noise is worse with an interval below 0; a model against itself is 0 on every
    resample (the resamples are shared: paired)."""
    y = rng.normal(size=120)
    a = y + rng.normal(scale=0.3, size=120)
    b = a + rng.normal(scale=0.5, size=120)
    groups = np.repeat(["P1", "P2"], 60)
    clusters = np.repeat(np.arange(24), 5)
    out = paired_r2_difference(y, a, b, groups, clusters, n_boot=200)
    for g in ("P1", "P2"):
        s = groups == g
        r2 = [regression_scores(y[s], p[s])["r2"] for p in (a, b)]
        assert out[g]["r2"] == pytest.approx(r2[0] - r2[1])
    assert out["all"]["low"] > 0.0  # a is better, and the interval says so
    same = paired_r2_difference(y, a, a, groups, clusters, n_boot=50)
    assert all(v == {"r2": 0.0, "low": 0.0, "high": 0.0} for v in same.values())


def test_the_linear_baseline_is_least_squares(rng):
    """``fit_linear`` recovers a plane exactly, and is numpy's least squares otherwise."""
    X = rng.normal(size=(50, 3))
    model = fit_linear(X, 0.3 + X @ np.array([1.0, -2.0, 0.5]))
    assert model.intercept == pytest.approx(0.3)
    np.testing.assert_allclose(model.coef, [1.0, -2.0, 0.5], atol=1e-12)
    y = rng.normal(size=50)
    A = np.column_stack([np.ones(50), X])
    np.testing.assert_allclose(
        fit_linear(X, y).predict(X), A @ np.linalg.lstsq(A, y, rcond=None)[0]
    )


class _Linear:
    """A cheap model for the cross-validation's tests: least squares on p."""

    def __init__(self, records: ArmAngleRecords) -> None:
        X = np.hstack([records.p, np.ones((len(records), 1))])
        self.coef = np.linalg.lstsq(X, records.alpha, rcond=None)[0]

    def predict(self, P):
        return P @ self.coef[:3] + self.coef[3]


def _toy(rng) -> ArmAngleRecords:
    """Four people whose arm angle is a plane in p plus a personal offset and noise."""
    n = 400
    who = np.repeat([f"P{i}" for i in range(4)], n // 4)
    trial = np.array([f"{w}_t_R{j % 10}" for j, w in enumerate(who)])
    p = rng.uniform(-0.5, 0.8, (n, 3))
    offset = {"P0": 0.1, "P1": -0.05, "P2": 0.0, "P3": -0.08}
    alpha = 0.2 + p @ [0.3, -0.2, 0.5] + np.array([offset[w] for w in who])
    alpha = alpha + rng.normal(scale=0.05, size=n)
    z = np.zeros((n, 3))
    return ArmAngleRecords(
        p,
        alpha,
        0.5 * p,
        np.full(n, 0.28),
        np.full(n, 0.24),
        np.full(n, 1.7),
        z,
        np.arange(n) / 100.0,
        who,
        np.full(n, "t"),
        trial,
    )


def test_cross_validation_scores_recomputed(rng):
    rec = _toy(rng)
    cv = cross_validate(rec, _Linear, kim=CALIBRATED, n_boot=100)
    net = wrap(rec.alpha - cv["predictions"]["network"])
    for person, row in cv["participants"].items():
        s = rec.participant == person
        train = rec.subset(~s)
        # the held-out prediction is the model trained without that person
        np.testing.assert_allclose(
            cv["predictions"]["network"][s], _Linear(train).predict(rec.p[s])
        )
        assert cv["predictions"]["constant"][s][0] == pytest.approx(train.alpha.mean())
        assert row["network"]["rms_deg"] == pytest.approx(
            math.degrees(np.sqrt(np.mean(net[s] ** 2)))
        )
        assert row["network"]["low"] <= row["network"]["rms_deg"] <= row["network"]["high"]
        assert row["network"]["rms_deg"] < row["constant"]["rms_deg"]
    total, between, within = spread_of(net, rec.participant)
    assert (cv["spread"]["spread"], cv["spread"]["between"]) == (total, between)
    assert total == pytest.approx(math.hypot(between, within))
    # with every person weighted alike the spread is the rms of all held-out residuals
    assert total == pytest.approx(np.sqrt(np.mean(net**2)))
    assert cv["summary"]["network"]["rms_deg"] == pytest.approx(math.degrees(total))
    d = cv["summary"]["network_minus_constant"]
    assert d["high"] < 0  # the plane beats the constant beyond the interval
    # the personal offsets are the between-person scatter: sd of the people's mean residual
    means = [np.mean(net[rec.participant == p]) for p in rec.participants()]
    sc = between_person_scatter(net, rec)
    assert sc["sd"] == pytest.approx(math.degrees(np.std(means)))
    assert sc["sd_ddof1"] == pytest.approx(math.degrees(np.std(means, ddof=1)))
    assert sc["sd_corrected"] <= sc["sd"]
    # comparing a model with itself: no difference
    same = paired_comparison(cv, cv, rec, n_boot=20)
    assert same["minus_base_deg"] == 0.0 and same["low"] == same["high"] == 0.0


def test_wrap_keeps_residuals_in_minus_pi_pi():
    np.testing.assert_allclose(
        wrap(np.array([0.0, np.pi, -np.pi, 1.5 * np.pi, 2 * np.pi + 0.1])),
        [0.0, np.pi, np.pi, -0.5 * np.pi, 0.1],
        atol=1e-12,
    )


# ---------------------------------------------------------------------------- training
@pytest.fixture(scope="module")
def trained():
    torch = pytest.importorskip("torch")
    torch.set_num_threads(1)
    from wholebody.humanlike.arm_angle_fit import ArmAngleConfig, train_arm_angle

    rng = np.random.default_rng(5)
    P = rng.uniform([0.0, -0.3, -0.6], [0.9, 0.5, 0.5], (600, 3))
    alpha = 0.3 + 0.6 * np.tanh(2 * P[:, 2]) - 0.3 * P[:, 0] ** 2
    config = ArmAngleConfig(hidden=(8,), epochs=40, batch_size=64)
    return P, alpha, config, train_arm_angle(P, alpha, config, spread=(0.2, 0.1, 0.17))


def test_training_learns_a_smooth_function_and_is_reproducible(trained):
    from wholebody.humanlike.arm_angle_fit import train_arm_angle

    P, alpha, config, res = trained
    err = res.network.predict(P) - alpha
    assert np.sqrt(np.mean(err**2)) < 0.1 * np.std(alpha)
    assert res.loss[-1] < 0.1 * res.loss[0]
    assert res.network.spread == 0.2 and res.network.spread_within == 0.17
    again = train_arm_angle(P[:200], alpha[:200], replace(config, epochs=2))
    twice = train_arm_angle(P[:200], alpha[:200], replace(config, epochs=2))
    for a, b in zip(again.network.weights, twice.network.weights, strict=True):
        np.testing.assert_array_equal(a, b)  # seeded
    with pytest.raises(DataError, match=r"need P \(N, 3\)"):
        train_arm_angle(P[:, :2], alpha, config)


def test_numpy_inference_equals_torch(trained, rng):
    import torch

    from wholebody.humanlike.arm_angle_fit import torch_arm_angle_module

    _, _, _, res = trained
    net = res.network
    P = rng.uniform(-1.2, 1.2, (300, 3))
    with torch.no_grad():
        trained_module = res.module(torch.as_tensor(P)).numpy()
        rebuilt = torch_arm_angle_module(net)(torch.as_tensor(P)).numpy()
    np.testing.assert_allclose(net.predict(P), trained_module, rtol=0, atol=1e-12)
    np.testing.assert_allclose(net.predict(P), rebuilt, rtol=0, atol=1e-12)
    # and torch's autograd gives the analytic gradient
    x = torch.as_tensor(P[:10], dtype=torch.float64).requires_grad_(True)
    torch_arm_angle_module(net)(x).sum().backward()
    np.testing.assert_allclose(net.gradient(P[:10]), x.grad.numpy(), atol=1e-12)


# ---------------------------------------------------------------------------- shipped
def test_shipped_network_and_its_card_agree():
    net = default_arm_angle_model()
    assert isinstance(net, HumanArmAngleModel) and net.hidden_sizes == (8,)
    cv = net.meta["cross_validation"]
    sp = cv["spread"]
    assert (net.spread, net.spread_between, net.spread_within) == (
        sp["spread"],
        sp["between"],
        sp["within"],
    )
    assert net.spread == pytest.approx(math.hypot(net.spread_between, net.spread_within))
    # the spread is the rms over every held-out record (participants alike): the summary's
    assert math.degrees(net.spread) == pytest.approx(cv["summary"]["network"]["rms_deg"], abs=0.05)
    text = (arm_angle_model_path().parent / "README.md").read_text()
    assert f"`spread` {math.degrees(net.spread):.1f} deg" in text
    for person, row in cv["participants"].items():
        line = next(x for x in text.splitlines() if x.startswith(f"| {person} |"))
        for model in ("network", "constant", "kim"):
            r = row[model]
            assert f"{r['rms_deg']:.1f} [{r['low']:.1f}, {r['high']:.1f}]" in line
    assert len(cv["participants"]) == 12
    assert sorted(net.meta["data"]["tasks"]) == ["across", "combing", "drinking", "forward"]
    assert re.search(r"wholebody stiffness armangle fit .*--seed 0", text)
    # what the card claims: better than both baselines overall, beyond the interval
    assert cv["summary"]["network_minus_constant"]["high"] < 0
    assert cv["summary"]["network_minus_kim"]["high"] < 0
    # a typical query: reaching forward at table height, elbow slightly out
    alpha, g = net.evaluate(np.array([0.6, 0.1, -0.45]))
    assert 0.0 < alpha < 0.5 and g.shape == (3,) and np.isfinite(g).all()


@pytest.mark.slow
def test_shipped_network_recomputed_on_its_own_records():
    """Recompute: on the records it was trained on, the shipped network's rms is below the
    held-out spread it states (in sample < out of sample), and its arm angle keeps the
    recordings' per-task order (combing > drinking > forward)."""
    from wholebody.humanlike.recordings import load_recordings

    net = default_arm_angle_model()
    rec = arm_angle_records(
        load_recordings(), load_participants(), n_records=net.meta["data"]["records"]
    )
    assert len(rec) == net.meta["training"]["records"]
    rms = float(np.sqrt(np.mean(wrap(rec.alpha - net.predict(rec.p)) ** 2)))
    assert 0.5 * net.spread < rms < net.spread
    means = {t: float(np.mean(net.predict(rec.p[rec.task == t]))) for t in set(rec.task)}
    assert means["combing"] > means["drinking"] > means["forward"]
    assert np.all(net.in_range(rec.p))


@pytest.mark.slow
def test_shipped_scores_are_reproduced_by_the_command_in_the_card(tmp_path: Path):
    """Re-run the card's `score` command (about 40 s): the same per-participant rms."""
    import json
    import shlex

    from wholebody.cli import main

    text = (arm_angle_model_path().parent / "README.md").read_text()
    line = next(x for x in text.splitlines() if x.startswith("wholebody stiffness armangle score"))
    argv = shlex.split(line)[1:]
    out = tmp_path / "scores.json"
    argv[argv.index("--out") + 1] = str(out)
    assert main([*argv, "--quiet"]) == 0
    got = json.loads(out.read_text())
    want = default_arm_angle_model().meta["cross_validation"]
    for person, row in want["participants"].items():
        for model in ("network", "constant", "kim"):
            assert got["participants"][person][model]["rms_deg"] == pytest.approx(
                row[model]["rms_deg"], abs=1e-9
            )
    assert got["spread"] == pytest.approx(want["spread"], abs=1e-12)


def test_cross_validation_runs_the_real_fit_end_to_end(tmp_path: Path):
    """The command line on a slice (one task, few records, two epochs): a network file and a
    card whose numbers are the file's."""
    pytest.importorskip("torch")
    from wholebody.cli import main

    out, card = tmp_path / "aa.npz", tmp_path / "README.md"
    argv = [
        "stiffness",
        "armangle",
        "fit",
        "--tasks",
        "forward",
        "--records",
        "240",
        "--epochs",
        "2",
        "--bootstrap",
        "20",
        "--no-kim-scatter",
        "--quiet",
        "--date",
        "2026-12-24",
        "--out",
        str(out),
        "--card",
        str(card),
    ]
    assert main(argv) == 0
    net = NetworkArmAngle.load(out)
    text = card.read_text()
    assert "Date: 2026-12-24." in text and "| forward | 120 |" in text
    assert f"`spread` {math.degrees(net.spread):.1f} deg" in text
    assert "--tasks forward" in text and "--no-kim-scatter" in text
    assert (
        net.meta["data"]["tasks"] == ["forward"]
        and len(net.meta["cross_validation"]["participants"]) == 12
    )
