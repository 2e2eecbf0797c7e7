"""The motion test on people: the mapped wrist path, the tracking, and the comparison of arm
angles (wrapped, per participant)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from wholebody.humanlike.mapping import lab_to_canonical
from wholebody.humanlike.recordings import load_recordings, real_recordings_dir
from wholebody.presets import PaperWeights
from wholebody.scenarios.human_motion import (
    PathTrajectory,
    TrialResult,
    compare_arm_angles,
    held_out_arm_angle_models,
    robot_wrist_path,
    run_trial,
)


class Constant:
    def __init__(self, alpha):
        self.alpha = alpha

    def evaluate(self, p):
        return self.alpha, np.zeros(3)


@pytest.fixture(scope="module")
def trials():
    files = sorted(real_recordings_dir().glob("ADL010_*.csv"))
    return load_recordings([files[0], files[-1]])  # an across reach and a combing trial


def test_the_path_interpolates_the_samples_and_their_slopes():
    t = np.array([0.0, 1.0, 3.0])
    p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 2.0, 0.0]])
    s = PathTrajectory(t + 5.0, p).sample_many([0.5, 2.0, 3.0])  # times from its first
    np.testing.assert_allclose(s.positions, [[0.5, 0, 0], [1, 1, 0], [1, 2, 0]])
    np.testing.assert_allclose(s.linear_velocities[:2], [[1, 0, 0], [0, 1, 0]])


def test_the_mapped_wrist_keeps_the_persons_directions_with_the_robots_lengths(humanoid, trials):
    for rec in trials:
        arm = humanoid.arm("right" if rec.side == "R" else "left")
        path = robot_wrist_path(arm, rec)
        assert np.all(
            np.linalg.norm(path, axis=1) <= arm.upper_arm_length + arm.forearm_length + 1e-9
        )
        # the arm's plane and the wrist's height order are the person's: z up stays up
        human = lab_to_canonical(rec.wrist - rec.shoulder, rec.side)
        robot = path * [1.0, 1.0 if arm.side == "right" else -1.0, 1.0]
        assert np.corrcoef(human[:, 2], robot[:, 2])[0, 1] > 0.99
        # directions: the normalised wrists agree to within the length ratios' difference
        reach = arm.upper_arm_length + arm.forearm_length
        person = np.median(rec.upper_arm_lengths()) + np.median(rec.forearm_lengths())
        assert np.median(np.linalg.norm(robot / reach - human / person, axis=1)) < 0.05


def test_a_trial_is_tracked_and_the_pull_sets_the_elbow(humanoid, trials):
    """The wrist follows the person's path relative to the shoulder (to 1 mm at the median
    frame; the arm's velocity limits may leave a fast stretch a few cm behind); with the pull
    towards a constant 0.4 rad the robot's arm angle stays near it while the wrist moves."""
    for rec in trials:
        plain = run_trial(humanoid, rec, None)
        assert plain.wrist_error_median_m < 1e-3 and plain.wrist_error_m < 0.05
        assert plain.human.size > 100
        pulled = run_trial(
            humanoid,
            rec,
            PaperWeights(spring="none", energy=0.0, human_arm_angle=5.0),
            arm_angle_model=Constant(0.4),
        )
        assert pulled.wrist_error_median_m < 1e-3 and pulled.wrist_error_m < 0.05
        assert abs(np.median(pulled.robot) - 0.4) < 0.05
        assert abs(np.median(pulled.robot) - 0.4) < abs(np.median(plain.robot) - 0.4)


def test_arm_angles_are_compared_wrapped_and_per_participant():
    a = TrialResult("P1", "t1", np.array([3.1, 0.0]), np.array([-3.1, 0.1]), 1.0, 1e-4, 1e-5)
    b = TrialResult("P2", "t2", np.array([0.5]), np.array([0.2]), 2.0, 2e-4, 3e-5)
    sc = compare_arm_angles([a, b])
    d = np.degrees([2 * math.pi - 6.2, 0.1, -0.3])  # -3.1 - 3.1 wraps to 0.083 rad
    assert sc.alpha_rms_deg == pytest.approx(np.sqrt(np.mean(d**2)))
    assert sc.alpha_rms_deg_by_participant["P2"] == pytest.approx(np.degrees(0.3))
    assert sc.frames == 3 and sc.waist_travel_rad == 3.0 and sc.wrist_error_mm == 0.2
    assert sc.wrist_error_median_mm == pytest.approx(0.02)
    # resampling the two people: the rms of P1 alone, of P2 alone, or of both
    low, high = sc.alpha_rms_deg_interval
    assert low == pytest.approx(sc.alpha_rms_deg_by_participant["P1"])
    assert high == pytest.approx(np.degrees(0.3))


def _evaluate(tmp_path, *argv):
    from wholebody.cli import main

    assert main(["humanlike", "evaluate", "--out", str(tmp_path), *argv]) == 0
    return json.loads((tmp_path / "humanlike.json").read_text())


@pytest.mark.slow
def test_the_command_writes_the_table_and_the_plot(tmp_path, capsys):
    """Two trials of one participant: humanlike.json has, per controller, the rms over all
    frames (the only participant's too), the waist travel and the frames."""
    out = _evaluate(tmp_path, "--participants", "ADL010", "--every", "20")
    assert set(out["controllers"]) == {"pseudo_inverse", "paper", "human_arm_angle"}
    assert out["participants"] == ["ADL010"] and len(out["trials"]) == 2
    for c in out["controllers"].values():
        assert c["alpha_rms_deg_by_participant"]["ADL010"] == pytest.approx(c["alpha_rms_deg"])
        assert c["alpha_rms_deg_interval"] == pytest.approx([c["alpha_rms_deg"]] * 2)
        assert c["frames"] > 200 and c["waist_travel_rad"] >= 0.0
        person = c["participants"]["ADL010"]
        assert person["trials"] == 2
        assert person["waist_travel_rad"] == pytest.approx(c["waist_travel_rad"])
        low, high = person["waist_travel_rad_per_trial_interval"]
        assert low <= person["waist_travel_rad_per_trial"] <= high
    assert (tmp_path / "humanlike.png").stat().st_size > 10_000
    assert "ADL010" in capsys.readouterr().out


def test_the_command_rejects_unknown_participants(tmp_path, capsys):
    from wholebody.cli import main

    one = sorted(real_recordings_dir().glob("ADL010_*.csv"))[0]
    (tmp_path / one.name).write_bytes(one.read_bytes())
    argv = ["--recordings", str(tmp_path), "--participants", "X9"]
    assert main(["humanlike", "evaluate", "--out", str(tmp_path / "out"), *argv]) != 0
    assert "no recordings of X9" in capsys.readouterr().err


@pytest.mark.slow
def test_held_out_models_never_saw_the_participant_they_drive(tmp_path):
    """--held-out on three participants: one network per participant, trained on the other
    two; the pull still brings the robot closer to people than the plain pseudo-inverse."""
    pytest.importorskip("torch")
    rec = tmp_path / "recordings"
    rec.mkdir()
    for p in ("ADL001", "ADL002", "ADL003"):
        for f in sorted(real_recordings_dir().glob(f"{p}_*.csv"))[::8]:
            (rec / f.name).write_bytes(f.read_bytes())
    models = held_out_arm_angle_models(load_recordings(rec), only=["ADL002"])
    assert list(models) == ["ADL002"] and models["ADL002"].meta["participants"] == [
        "ADL001",
        "ADL003",
    ]
    out = _evaluate(tmp_path / "out", "--recordings", str(rec), "--held-out")
    assert out["arm_angle_model"].startswith("held out")
    c = out["controllers"]
    assert c["human_arm_angle"]["alpha_rms_deg"] < c["pseudo_inverse"]["alpha_rms_deg"]


def test_a_one_armed_robot_is_refused_by_name(trials):
    from wholebody.errors import DataError
    from wholebody.robot import load_robot
    from wholebody.robot.urdf import example_robot_data_share

    if example_robot_data_share() is None:
        pytest.skip("example-robot-data is not installed (pip install '.[robots]')")
    panda = load_robot("panda")  # one right arm
    for rec in trials:
        expected = "has one arm" if rec.side == "R" else "no left arm"
        with pytest.raises(DataError, match=expected):
            run_trial(panda, rec, None)


def test_waist_travel_and_arm_angle_come_with_intervals_per_controller_and_participant():
    """P1's two trials travel 1 and 3 rad, P2's one trial 5 rad: 3 rad per trial over
    everyone, its interval from all-P1 (2 rad) to all-P2 (5 rad) resamples of the people;
    P1's own from all-first (1 rad) to all-second (3 rad) resamples of P1's trials."""
    zero = np.zeros(1)
    trials = [
        TrialResult("P1", "a", zero, np.array([0.1]), 1.0, 0.0),
        TrialResult("P1", "b", zero, np.array([0.3]), 3.0, 0.0),
        TrialResult("P2", "c", zero, np.array([0.2]), 5.0, 0.0),
    ]
    sc = compare_arm_angles(trials)
    assert sc.waist_travel_rad == 9.0 and sc.waist_travel_rad_per_trial == 3.0
    assert sc.waist_travel_rad_per_trial_interval == pytest.approx((2.0, 5.0))
    p1, p2 = sc.participants["P1"], sc.participants["P2"]
    assert (p1.waist_travel_rad, p1.trials, p2.trials) == (4.0, 2, 1)
    assert p1.waist_travel_rad_per_trial_interval == pytest.approx((1.0, 3.0))
    assert p2.waist_travel_rad_per_trial_interval == pytest.approx((5.0, 5.0))
    assert p1.alpha_rms_deg == pytest.approx(np.degrees(np.sqrt((0.01 + 0.09) / 2)))
    assert p1.alpha_rms_deg_interval == pytest.approx(np.degrees([0.1, 0.3]))
    row = json.loads(json.dumps(sc.as_dict()))  # what humanlike.json holds
    assert row["participants"]["P1"]["waist_travel_rad_per_trial_interval"] == [1.0, 3.0]
    assert row["waist_travel_rad_per_trial"] == 3.0


@pytest.mark.slow
def test_the_human_like_preset_moves_the_arms_more_and_the_waist_less(humanoid, trials):
    """The waist dear in the velocity metric (``HUMAN_LIKE``): on the same trials its waist
    travels less than with the metric's default, the elbow still pulled to the arm angle and
    the wrist still tracked."""
    import dataclasses

    from wholebody.presets import HUMAN_LIKE, paper_metric

    metric = paper_metric(humanoid, HUMAN_LIKE)
    waist = humanoid.groups["waist"].indices
    assert np.all(metric[waist] == 100.0) and np.sum(metric == 100.0) == waist.size
    with pytest.raises(Exception, match="waist_metric must be a finite weight > 0"):
        paper_metric(humanoid, PaperWeights(waist_metric=0.0))
    cheap = dataclasses.replace(HUMAN_LIKE, waist_metric=1.0)
    for rec in trials:
        dear = run_trial(humanoid, rec, HUMAN_LIKE, arm_angle_model=Constant(0.4))
        plain = run_trial(humanoid, rec, cheap, arm_angle_model=Constant(0.4))
        assert dear.waist_travel < 0.8 * plain.waist_travel
        assert dear.wrist_error_median_m < 1e-3
        assert abs(np.median(dear.robot) - 0.4) < 0.05
