"""The stiffness network: numpy inference against torch, its gradient, its file, its use."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from wholebody.arm.network import NetworkStiffness, default_stiffness  # noqa: E402
from wholebody.errors import DataError  # noqa: E402
from wholebody.humanlike.arm_angle_model import CALIBRATED  # noqa: E402
from wholebody.humanlike.dataset import build_dataset  # noqa: E402
from wholebody.humanlike.evaluation import regression_scores  # noqa: E402
from wholebody.humanlike.mapping import ArmParameters  # noqa: E402
from wholebody.humanlike.synthetic import DEFAULT_PARTICIPANTS, generate_synthetic  # noqa: E402
from wholebody.humanlike.training import TrainingConfig, torch_module, train_network  # noqa: E402

NOISE_FREE = dataclasses.replace(
    CALIBRATED, sd_participant=0.0, sd_block=0.0, sd_trial=0.0, sd_within=0.0
)


@pytest.fixture(scope="module")
def small_split(humanoid):
    """A small slice: four synthetic participants with the calibrated arm-angle model
    without its noise (so k is a function of the wrist), one held out."""
    params = ArmParameters.from_robot(humanoid, "right")
    recs = generate_synthetic(DEFAULT_PARTICIPANTS[:4], seed=0, model=NOISE_FREE)
    ds, _ = build_dataset(recs, params, n_records=800)
    return ds.split(["SYN04"])


@pytest.fixture(scope="module")
def trained(small_split):
    torch.set_num_threads(1)
    train, _ = small_split
    return train_network(train.wrist, train.k, TrainingConfig(hidden=(16, 16), epochs=60))


def test_short_training_beats_the_mean_on_held_out_participants(small_split, trained):
    train, test = small_split
    assert "SYN04" not in set(train.participant) and set(test.participant) == {"SYN04"}
    s = regression_scores(test.k, trained.network.predict(test.wrist))
    assert s["r2"] > 0.5, s
    mean = regression_scores(test.k, np.full(len(test), train.k.mean()))
    assert s["mse"] < 0.5 * mean["mse"]
    assert trained.loss[-1] < 0.5 * trained.loss[0]


def test_numpy_inference_equals_torch(trained, rng):
    net = trained.network
    P = rng.uniform([-0.1, -0.4, -0.6], [0.6, 0.4, 0.5], (500, 3))
    with torch.no_grad():
        k32 = trained.module(torch.as_tensor(P, dtype=torch.float32)).double().numpy()
        k64 = torch_module(net)(torch.as_tensor(P)).numpy()
    np.testing.assert_allclose(net.predict(P), k32, rtol=0, atol=1e-6)  # the trained module
    np.testing.assert_allclose(net.predict(P), k64, rtol=0, atol=1e-12)  # same maths in float64
    for p in P[:20]:
        k, g = net.evaluate(p)
        assert k == pytest.approx(float(net.predict(p)), abs=1e-14)
        np.testing.assert_allclose(g, net.gradient(p), atol=1e-12)


def test_gradient_equals_finite_differences(trained, rng):
    net = trained.network
    h = 1e-6
    P = rng.uniform([-0.3, -0.6, -0.8], [0.8, 0.6, 0.8], (40, 3))  # also outside the data
    for p in P:
        _, g = net.evaluate(p)
        fd = [
            (net.evaluate(p + h * e)[0] - net.evaluate(p - h * e)[0]) / (2 * h) for e in np.eye(3)
        ]
        np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-7)


def test_floor_keeps_k_positive_with_a_consistent_gradient(rng):
    """A network whose raw output goes negative: k stays > 0 and its gradient is exact."""
    W = [rng.normal(size=(8, 3)), rng.normal(size=(1, 8))]
    b = [rng.normal(size=8), np.array([0.0])]
    net = NetworkStiffness(W, b, np.zeros(3), np.full(3, 0.2), 0.0, 1.0, 20.0)
    P = rng.uniform(-0.5, 0.5, (300, 3))
    raw, k = net.raw(P), net.predict(P)
    assert (raw < -0.2).any() and np.all(k > 0)
    np.testing.assert_allclose(k[raw > 1.0], raw[raw > 1.0], atol=np.log(2) / 20)
    h = 1e-7
    for p in P[raw < 0][:10]:
        fd = [
            (net.evaluate(p + h * e)[0] - net.evaluate(p - h * e)[0]) / (2 * h) for e in np.eye(3)
        ]
        np.testing.assert_allclose(net.evaluate(p)[1], fd, rtol=1e-5, atol=1e-9)


def test_file_round_trip_and_errors(trained, tmp_path: Path, rng):
    net = trained.network
    path = net.save(tmp_path / "k.npz")
    back = NetworkStiffness.load(path)
    P = rng.uniform(-0.5, 0.5, (50, 3))
    np.testing.assert_array_equal(back.predict(P), net.predict(P))
    assert back.meta["training"]["epochs"] == 60
    assert back.in_range(net.input_low) and not back.in_range(net.input_high + 0.1)
    with np.load(path, allow_pickle=False) as z:
        arrays = dict(z)
    for key, fragment in (("W1", "missing layer key"), ("k_scale", "missing key")):
        bad = {k: v for k, v in arrays.items() if k != key}
        np.savez(tmp_path / f"no_{key}.npz", **bad)
        with pytest.raises(DataError, match=fragment):
            NetworkStiffness.load(tmp_path / f"no_{key}.npz")
    np.savez(tmp_path / "shape.npz", **{**arrays, "W1": arrays["W1"][:, :3]})
    with pytest.raises(DataError, match="layer 1"):
        NetworkStiffness.load(tmp_path / "shape.npz")
    np.savez(tmp_path / "fmt.npz", **{**arrays, "format": np.array("other")})
    with pytest.raises(DataError, match="format"):
        NetworkStiffness.load(tmp_path / "fmt.npz")
    # every malformed file is a DataError naming the file (some were ValueError/TypeError, or
    # loaded and failed later)
    for name, change, fragment in (
        ("x_mean", np.zeros(4), r"x_mean must have shape \(3,\)"),
        ("k_mean", np.zeros(2), "k_mean must be a number"),
        ("input_low", np.zeros(2), r"input_low must have shape \(3,\)"),
        ("W9", np.zeros((1, 1)), "beyond n_layers"),
        ("x_scale", np.array([object()]), "not a readable stiffness network"),
    ):
        bad_path = tmp_path / f"bad_{name}.npz"
        np.savez(bad_path, **{**arrays, name: change})
        with pytest.raises(DataError, match=fragment) as info:
            NetworkStiffness.load(bad_path)
        assert str(bad_path) in str(info.value)
    # a name without .npz: the path returned is the file written
    named = net.save(tmp_path / "model.weights")
    assert named.name == "model.weights.npz" and named.is_file()
    # without a training range: none after a round trip either (not an infinite box)
    bare = NetworkStiffness(
        net.weights, net.biases, net.x_mean, net.x_scale, net.k_mean, net.k_scale, net.floor_beta
    )
    again = NetworkStiffness.load(bare.save(tmp_path / "bare.npz"))
    with pytest.raises(DataError, match="no stored training range"):
        again.in_range(np.zeros(3))


def test_shipped_default_plugs_into_the_arm_energy(humanoid):
    """One call loads the shipped network; the arm energy uses it as its stiffness model and
    its gradient (through dk/dwrist) matches finite differences."""
    from fdcheck import gradient_fd

    from wholebody.tasks.arm_energy import ArmPotentialEnergy

    model = default_stiffness(humanoid)
    assert model.meta["robot"] == "mobile_humanoid"
    k, g = model.evaluate(np.array([0.25, 0.05, -0.25]))
    assert k > 0 and g.shape == (3,)
    joints = {
        "right_shoulder_flexion": 0.6,
        "right_elbow_flexion": 1.1,
        "right_shoulder_abduction": 0.3,
    }
    q = humanoid.configuration(joints, base_pose=(0.1, -0.2, 0.3))
    energy = ArmPotentialEnergy(humanoid, "right", model)
    value = energy.evaluate(humanoid.update(q))
    assert value.stiffness > 0
    fd = gradient_fd(humanoid, q, lambda x: energy.evaluate(humanoid.update(x)).value)
    np.testing.assert_allclose(value.gradient, fd, rtol=1e-5, atol=1e-6)
    with pytest.raises(DataError, match="has no trained stiffness network there"):
        default_stiffness("dual_arm_torso")


def test_model_selection_follows_the_one_standard_error_rule(small_split):
    from wholebody.humanlike.pipeline import group_folds, select_model

    train, _ = small_split
    folds = group_folds(train.participant, 3)
    for tr, va in folds:  # whole participants held out in each fold
        assert not set(train.participant[tr]) & set(train.participant[va])
    cands = [
        {"hidden": (4,), "weight_decay": 0.1},
        {"hidden": (8, 8), "weight_decay": 0.0},
        {"hidden": (8,), "weight_decay": 0.0},
    ]
    chosen, table = select_model(train, cands, TrainingConfig(epochs=4))
    assert len(table) == 3 and sum(r["chosen"] for r in table) == 1
    best = min(table, key=lambda r: r["cv_mse"])
    pick = next(r for r in table if r["chosen"])
    assert pick["cv_mse"] <= best["cv_mse"] + best["cv_mse_se"]
    band = [r for r in table if r["cv_mse"] <= best["cv_mse"] + best["cv_mse_se"]]
    assert pick["weight_decay"] == max(r["weight_decay"] for r in band)
    assert chosen == {"hidden": tuple(pick["hidden"]), "weight_decay": pick["weight_decay"]}
