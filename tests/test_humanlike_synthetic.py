"""The arm-angle model (Kim et al. 2012) and the synthetic standing-reach generator."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from wholebody.arm.angle import arm_angle
from wholebody.humanlike.arm_angle_model import (
    CALIBRATED,
    HEAD_CENTRE,
    calibrate,
    elbow_on_circle,
    kim_arm_angle,
    summarise_arm_angles,
)
from wholebody.humanlike.mapping import CANONICAL_SIDE, ArmParameters, lab_to_canonical
from wholebody.humanlike.pipeline import make_dataset
from wholebody.humanlike.recordings import (
    load_participants,
    load_recording,
    load_recordings,
    real_recordings_dir,
)
from wholebody.humanlike.synthetic import (
    DEFAULT_PARTICIPANTS,
    ROWS,
    generate_synthetic,
    minimum_jerk,
    protocol_targets,
)


def test_elbow_on_circle_has_the_requested_arm_angle_and_lengths(rng):
    S = rng.normal(0, 0.05, (30, 3))
    d = rng.normal(0, 1, (30, 3)) + np.array([1.0, 0.0, -0.5])
    W = S + d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.1, 0.55, (30, 1))
    alpha = rng.uniform(-3.0, 3.0, 30)
    for side in (-1.0, 1.0):
        E = elbow_on_circle(S, W, 0.3, 0.27, alpha, side)
        np.testing.assert_allclose(arm_angle(S, E, W, side), alpha, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(E - S, axis=1), 0.3, rtol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(W - E, axis=1), 0.27, rtol=1e-12)


def test_kim_closed_form_matches_the_criterion_by_search(rng):
    """The closed form maximises |major axis of J J^T . h| over the elbow circle; with
    ``elbow_down`` it keeps the candidate (optimum or the other stationary point, pi away)
    below the shoulder-wrist line."""
    L1, L2 = 0.3, 0.27
    grid = np.linspace(-np.pi, np.pi, 1441)
    flipped = 0
    for _ in range(8):
        S = np.zeros(3)
        W = np.array([0.3, 0.05, -0.15]) + rng.normal(0, 0.08, 3)
        T = np.array([0.0, 0.2, 0.2]) + rng.normal(0, 0.15, 3)
        h = (T - W) / np.linalg.norm(T - W)
        Sg, Wg = np.tile(S, (len(grid), 1)), np.tile(W, (len(grid), 1))
        E = elbow_on_circle(Sg, Wg, L1, L2, grid, CANONICAL_SIDE)
        n = np.cross(E - Sg, Wg - E)
        t = np.cross(n / np.linalg.norm(n, axis=1, keepdims=True), Wg - E)  # per elbow rate
        r = W - S
        M = (r @ r) * np.eye(3) - np.outer(r, r) + t[:, :, None] * t[:, None, :]  # shoulder+hinge
        w, V = np.linalg.eigh(M)
        score = np.sqrt(w[:, -1]) * np.abs(V[:, :, -1] @ h)
        best = grid[int(np.argmax(score))]
        free = float(kim_arm_angle(S, W, L1, L2, T, CANONICAL_SIDE, elbow_down=False))
        assert np.cos(free - best) == pytest.approx(1.0, abs=1e-5)
        down = float(kim_arm_angle(S, W, L1, L2, T, CANONICAL_SIDE))
        assert abs(down) <= np.pi / 2
        assert np.cos(down - best) == pytest.approx(
            1.0 if abs(best) <= np.pi / 2 else -1.0, abs=1e-5
        )
        flipped += abs(best) > np.pi / 2
    assert 0 < flipped < 8  # both cases were exercised


def test_minimum_jerk_path():
    p0, p1 = np.zeros(3), np.array([0.3, 0.1, 0.2])
    t = np.linspace(0.0, 1.5, 301)
    p = minimum_jerk(p0, p1, 1.5, t)
    np.testing.assert_allclose(p[[0, -1]], [p0, p1], atol=1e-15)
    v = np.gradient(p, t, axis=0)
    assert np.linalg.norm(v[0]) < 1e-3 and np.linalg.norm(v[-1]) < 1e-3
    # bell-shaped speed peaking at the middle at 1.875 D / T
    speed = np.linalg.norm(v, axis=1)
    assert abs(t[np.argmax(speed)] - 0.75) < 0.01
    assert speed.max() == pytest.approx(1.875 * np.linalg.norm(p1) / 1.5, rel=1e-3)


def test_protocol_targets_follow_the_paper():
    p = DEFAULT_PARTICIPANTS[3]
    targets = protocol_targets(p)
    standing = np.array([t for task, _, t in targets if task == "standing"])
    table = np.array([t for task, _, t in targets if task == "tabletop"])
    assert len(standing) == 27 and len(table) == 9
    planes = np.unique(np.round(standing[:, 0], 9))
    np.testing.assert_allclose(np.diff(planes), [0.15, 0.15])  # 3 planes 15 cm apart
    heights = np.unique(np.round(standing[:, 2] + p.shoulder[2], 9))
    np.testing.assert_allclose(heights, ROWS)  # lowest row 1.40 m above the floor
    np.testing.assert_allclose(np.unique(np.round(standing[:, 1], 9)), [-0.15, 0.0, 0.15])
    assert np.ptp(table[:, 2]) == 0.0  # on one table


def test_synthetic_recordings_are_labelled_and_reproducible():
    people = DEFAULT_PARTICIPANTS[:2]
    a = generate_synthetic(people, seed=3)
    b = generate_synthetic(people, seed=3)
    c = generate_synthetic(people, seed=4)
    assert len(a) == 72
    assert {r.source for r in a} == {"synthetic"}
    assert {r.participant for r in a} == {"SYN01", "SYN02"}
    assert all("SYNTHETIC" in r.note for r in a)
    np.testing.assert_array_equal(a[5].elbow, b[5].elbow)
    assert not np.allclose(a[5].elbow, c[5].elbow)
    # de Leva lengths, scaled by stature, held in every frame; the wrist ends at its target
    r = a[40]
    p = people[1]
    np.testing.assert_allclose(r.upper_arm_lengths(), p.upper_arm, rtol=1e-12)
    np.testing.assert_allclose(r.forearm_lengths(), p.forearm, rtol=1e-12)
    assert p.upper_arm == pytest.approx(0.2817 * p.stature / 1.741)
    assert np.all(np.diff(r.time_s) > 0) and r.time_s[1] == pytest.approx(1 / 30)


@pytest.mark.slow
def test_calibration_on_real_reaches():
    """On a subset of the real reaches the fitted target explains the arm angle better than
    Kim et al.'s head-centre target, which puts the elbow far too lateral."""
    recs = [
        r
        for r in load_recordings(tasks=("forward", "across"))
        if r.trial <= 2 and r.participant <= "ADL006"
    ]
    cal = calibrate(
        recs,
        load_participants(),
        every=10,
        medial=np.linspace(-0.05, 0.15, 9),
        up=np.linspace(0.0, 0.3, 13),
    )
    pub_mean, pub_sd = cal.published_residual
    mean, sd = cal.calibrated_residual
    assert abs(pub_mean) > 20.0  # the head-centre target puts the elbow far too lateral
    assert sd < pub_sd
    assert cal.model.bias == pytest.approx(np.radians(mean))
    assert np.degrees(cal.model.sd_participant) < sd
    assert HEAD_CENTRE[1] > CALIBRATED.target[1]  # the fitted target is nearer the midline


def test_synthetic_tabletop_matches_real_arm_angles():
    """The calibration's purpose: synthetic seated reaches look like the real ones (the
    seated reaches: drinking and combing lift the hand to the face)."""
    syn = [r for r in generate_synthetic(seed=0) if r.task == "tabletop"]
    real = load_recordings(tasks=("forward", "across"))
    s, r = summarise_arm_angles(syn), summarise_arm_angles(real)
    assert abs(s["end_mean"] - r["end_mean"]) < 6.0
    assert abs(s["all_mean"] - r["all_mean"]) < 6.0
    assert abs(s["all_sd"] - r["all_sd"]) < 4.0
    assert 0.05 < s["negative_fraction"] < 0.35
    # and the real reaches in canonical axes go forward and down from the shoulder
    W = np.concatenate([lab_to_canonical(x.wrist[-1:] - x.shoulder[-1:], x.side) for x in real])
    assert W[:, 0].min() > 0.1 and W[:, 2].max() < 0.0


@pytest.mark.slow
def test_synthetic_out_writes_the_recordings_the_dataset_was_built_from(humanoid, tmp_path):
    """With --calibrate the synthetic participants come from the re-fitted model: the files
    written beside the dataset must be those recordings."""
    sub = tmp_path / "real"
    sub.mkdir()
    for name in ("ADL001_forward_R1", "ADL001_across_R1", "ADL002_forward_R1", "ADL002_across_R1"):
        shutil.copy(real_recordings_dir() / f"{name}.csv", sub)
    params = ArmParameters.from_robot(humanoid, "right")
    make_dataset(
        params,
        recordings_dir=sub,
        recalibrate=True,
        synthetic=DEFAULT_PARTICIPANTS[:1],
        n_records=200,
        synthetic_out=tmp_path / "syn",
    )
    model = calibrate(load_recordings(sub), load_participants()).model
    expected = generate_synthetic(DEFAULT_PARTICIPANTS[:1], seed=0, model=model)
    written = sorted((tmp_path / "syn").glob("*.npz"))
    assert len(written) == len(expected)
    for rec in expected:
        np.testing.assert_array_equal(
            load_recording(tmp_path / "syn" / f"{rec.name}.npz").elbow, rec.elbow
        )
