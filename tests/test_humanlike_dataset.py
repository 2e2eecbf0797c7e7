"""The stiffness dataset: labelling, frame rules, per-trial subsampling, split and file."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from wholebody.errors import DataError
from wholebody.humanlike.arm_angle_model import CALIBRATED_ON
from wholebody.humanlike.dataset import (
    DEFAULT_TEST_PARTICIPANTS,
    StiffnessDataset,
    build_dataset,
    label_recording,
)
from wholebody.humanlike.linear import fit_linear
from wholebody.humanlike.mapping import ArmParameters
from wholebody.humanlike.pipeline import fit_and_evaluate, make_dataset
from wholebody.humanlike.recordings import load_recording, real_recordings_dir
from wholebody.humanlike.synthetic import DEFAULT_PARTICIPANTS, generate_synthetic
from wholebody.resources import data_dir


@pytest.fixture(scope="module")
def params(humanoid) -> ArmParameters:
    return ArmParameters.from_robot(humanoid, "right")


@pytest.fixture(scope="module")
def recordings():
    real = [
        load_recording(real_recordings_dir() / f"ADL00{i}_{t}_{s}1.csv")
        for i in (1, 2, 9)
        for t in ("forward", "across")
        for s in "RL"
    ]
    return real + generate_synthetic(DEFAULT_PARTICIPANTS[:2], seed=0)


def test_records_are_robot_wrists_in_canonical_axes(recordings, params):
    """Left and right arms both reach forward (+x) and below the shoulder, at the robot's
    reach, and the labels are those of the mapped robot posture."""
    for rec in recordings[:12]:
        lab = label_recording(rec, params)
        W = lab["wrist"]
        assert np.all(np.linalg.norm(W, axis=1) <= params.upper_arm + params.forearm + 1e-12)
        assert W[-1, 0] > 0.15 and W[-1, 2] < 0.0, rec.name
        assert np.all(lab["k"] >= 0)


def test_build_subsamples_evenly_per_trial(recordings, params):
    ds, report = build_dataset(recordings, params, n_records=400)
    n_trials = len(recordings)
    assert len(ds) == 400
    per_trial = {t: int((ds.trial == t).sum()) for t in set(ds.trial)}
    assert len(per_trial) == n_trials
    assert max(per_trial.values()) - min(per_trial.values()) <= 1
    c = report.counts
    assert c["real"]["trials"] == 12 and c["synthetic"]["trials"] == 72
    assert c["synthetic"]["vertical"] > 0  # hanging-arm starts
    for src in ("real", "synthetic"):
        assert c[src]["kept"] + c[src]["dropped"] == c[src]["frames"]
    # records are well-conditioned frames, in time order within a trial
    t = ds.time_s[ds.trial == ds.trial[0]]
    assert np.all(np.diff(t) > 0)
    assert set(ds.source) == {"real", "synthetic"}


def test_split_by_participant_and_file_round_trip(recordings, params, tmp_path: Path):
    ds, _ = build_dataset(recordings, params, n_records=300)
    train, test = ds.split(["ADL002", "SYN02"])
    assert not set(train.participant) & set(test.participant)
    assert set(test.participant) == {"ADL002", "SYN02"}
    assert len(train) + len(test) == len(ds)
    with pytest.raises(DataError, match="ADL013"):
        ds.split(["ADL013"])
    back = StiffnessDataset.load(ds.save(tmp_path / "ds.npz"))
    np.testing.assert_array_equal(back.wrist, ds.wrist)
    np.testing.assert_array_equal(back.participant, ds.participant)
    assert back.meta["robot"] == "mobile_humanoid"
    with np.load(tmp_path / "ds.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files if k != "k"}
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(DataError, match="missing key"):
        StiffnessDataset.load(tmp_path / "bad.npz")


def test_no_surviving_frame_is_a_data_error(recordings, params, tmp_path: Path):
    rec = recordings[0]
    down = np.array([0.0, 0.0, 1.0])
    hanging = replace(
        rec, elbow=rec.shoulder - 0.3 * down + [0.01, 0.0, 0.0], wrist=rec.shoulder - 0.55 * down
    )
    with pytest.raises(DataError, match="no frame of the 1 recording"):
        build_dataset([hanging], params, n_records=100)
    ds, _ = build_dataset(recordings[:2], params, n_records=50)
    assert ds.save(tmp_path / "named").name == "named.npz"  # the file written


def test_shipped_dataset():
    """Real recordings only (issue 20): the four tasks of the 12 participants, every trial
    alike, the default held-out participants among them."""
    ds = StiffnessDataset.load(data_dir() / "stiffness" / "mobile_humanoid.npz")
    assert 4900 <= len(ds) <= 5000
    assert set(ds.source) == {"real"} and "synthetic" not in ds.meta
    assert set(DEFAULT_TEST_PARTICIPANTS) <= set(ds.participant)
    assert all(p.startswith("ADL") for p in DEFAULT_TEST_PARTICIPANTS)
    assert ds.meta["real"]["tasks"] == {
        t: 120 for t in ("across", "combing", "drinking", "forward")
    }
    tasks = {t.split("_")[1] for t in ds.trial}
    assert tasks == {"forward", "across", "drinking", "combing"}
    per_trial = np.unique(ds.trial, return_counts=True)[1]
    assert len(per_trial) == 480 and per_trial.max() - per_trial.min() <= 1
    assert np.all(ds.k >= 0)
    assert ds.meta["real"]["turned_180"] and all(
        t.startswith("ADL009") for t in ds.meta["real"]["turned_180"]
    )
    # the hand goes above the shoulder only in the new tasks
    up = ds.wrist[:, 2] > 0
    assert up.any() and {t.split("_")[1] for t in ds.trial[up]} <= {"drinking", "combing"}


def test_real_data_by_default_and_tasks_on_request(params):
    ds, report, info = make_dataset(params, tasks=("forward",), n_records=120)
    assert set(ds.source) == {"real"} and "synthetic" not in report.counts
    assert "arm_angle_model" not in info  # nothing synthetic to shape
    assert info["real"]["tasks"] == {"forward": 120}
    assert {t.split("_")[1] for t in ds.trial} == {"forward"}
    syn, _, info = make_dataset(
        params, real=False, synthetic=DEFAULT_PARTICIPANTS[:1], n_records=60
    )
    assert set(syn.source) == {"synthetic"} and info["arm_angle_model"]["calibrated_on"]


def test_participants_that_shaped_the_synthetic_data_cannot_be_held_out(params):
    """The synthetic elbows come from an arm-angle model calibrated on real participants;
    scoring on one of them would leak: fit_and_evaluate refuses."""
    ds, _, info = make_dataset(
        params, real=False, synthetic=DEFAULT_PARTICIPANTS[:2], n_records=200
    )
    assert info["arm_angle_model"]["calibrated_on"] == list(CALIBRATED_ON)
    assert not set(CALIBRATED_ON) & set(DEFAULT_TEST_PARTICIPANTS)
    with pytest.raises(DataError, match="ADL001 shaped the synthetic training data"):
        fit_and_evaluate(ds, test_participants=["ADL001", "SYN02"])


def test_reference_networks_are_scored_alike_and_must_not_have_seen_the_test_people(
    params, tmp_path: Path
):
    """fit_and_evaluate scores a reference (the network shipped before) on the same records
    in the same way, per real participant with intervals; one that trained on a test
    participant is refused."""
    pytest.importorskip("torch")
    from wholebody.arm.network import default_stiffness
    from wholebody.humanlike.evaluation import regression_scores
    from wholebody.humanlike.training import TrainingConfig

    for person in ("ADL001", "ADL003", "ADL005", "ADL008"):  # a slice of the recordings
        for name in (
            f"{person}_forward_R1",
            f"{person}_forward_L2",
            f"{person}_drinking_R3",
            f"{person}_drinking_L4",
            f"{person}_combing_R1",
        ):
            shutil.copy(real_recordings_dir() / f"{name}.csv", tmp_path)
    ds, _, _ = make_dataset(
        params, recordings_dir=tmp_path, tasks=("forward", "drinking"), n_records=400
    )
    assert {t.split("_")[1] for t in ds.trial} == {"forward", "drinking"}
    ref = default_stiffness()
    held = ref.meta["split"]["test_participants"]
    out = fit_and_evaluate(
        ds,
        test_participants=["ADL003", "ADL008"],
        svr=False,
        config=TrainingConfig(hidden=(4,), epochs=2),
        references={"before": ref},
        n_boot=30,
    )
    det = out.network.meta["scores_real_held_out"]
    _, test = ds.split(["ADL003", "ADL008"])
    for name, net in (("network", out.network), ("before", ref)):
        pred = net.predict(test.wrist)
        assert out.scores[name]["r2"] == pytest.approx(regression_scores(test.k, pred)["r2"])
        for person in ("ADL003", "ADL008"):
            s = test.participant == person
            row = det["per_participant"][name][person]
            assert row["r2"] == pytest.approx(regression_scores(test.k[s], pred[s])["r2"])
            assert row["low"] <= row["r2"] <= row["high"]
        assert det["per_participant"][name]["all"]["r2"] == pytest.approx(out.scores[name]["r2"])
    assert set(det["by_task"]["network"]) == {"forward", "drinking", "all"}
    assert set(det["by_task_group"]["before"]) == {"forward+across", "drinking+combing", "all"}
    s = np.array(["_forward_" in t for t in test.trial])
    assert det["by_task"]["before"]["forward"]["r2"] == pytest.approx(
        regression_scores(test.k[s], ref.predict(test.wrist[s]))["r2"]
    )
    train, _ = ds.split(["ADL003", "ADL008"])
    linear = fit_linear(train.wrist, train.k)
    paired = det["network_minus"]["linear"]
    for person in ("ADL003", "ADL008", "all"):  # the paired difference, the same records
        s = test.participant == person if person != "all" else np.ones(len(test), bool)
        r2 = [
            regression_scores(test.k[s], m.predict(test.wrist[s]))["r2"]
            for m in (out.network, linear)
        ]
        assert paired[person]["r2"] == pytest.approx(r2[0] - r2[1])
        assert paired[person]["low"] <= paired[person]["r2"] <= paired[person]["high"]
    assert out.network.meta["references"]["before"]["split"]["test_participants"] == held
    seen = sorted(set(ds.participant) - set(held))[0]
    with pytest.raises(DataError, match=f"trained on test participant.*{seen}"):
        fit_and_evaluate(
            ds,
            test_participants=[seen],
            svr=False,
            references={"before": ref},
            config=TrainingConfig(hidden=(4,), epochs=1),
        )
