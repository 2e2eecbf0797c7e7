"""Nothing bad gets in, nothing is lost: every reader names a bad file, every writer replaces
its file whole or not at all, and API misuse raises a named error instead of a NaN."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from wholebody.control import Controller, RunLog
from wholebody.errors import ConfigError, DataError, DimensionError
from wholebody.files import atomic_path, read_npz, write_npz
from wholebody.humanlike import NetworkStiffness, StiffnessDataset, default_stiffness
from wholebody.humanlike.recordings import load_participants, load_recording
from wholebody.resources import data_dir, robots_dir, tasks_dir
from wholebody.robot import load_robot
from wholebody.scenarios import load_scenario, run_scenario
from wholebody.solvers import Level, ProjectionSolver, Stack
from wholebody.tasks import FrameTask, PostureTask


def short_log(robot, n: int = 5) -> RunLog:
    hand = FrameTask(robot, "right_tool")
    stack = Stack(robot, [Level([hand]), Level([PostureTask(robot)])])
    return Controller(robot, stack, ProjectionSolver(), dt=0.01).run(robot.neutral(), n * 0.01)


def spoiled(path: Path, how: str) -> Path:
    """``path`` emptied, cut in half, or with garbage in the middle of its compressed data."""
    data = path.read_bytes()
    if how == "empty":
        path.write_bytes(b"")
    elif how == "truncated":
        path.write_bytes(data[: len(data) // 2])
    else:
        mid = len(data) // 2
        path.write_bytes(data[:mid] + bytes(64) + data[mid + 64 :])
    return path


SPOILS = ["empty", "truncated", "corrupt"]


@pytest.fixture(scope="module")
def log_file(humanoid, tmp_path_factory) -> Path:
    return short_log(humanoid).save(tmp_path_factory.mktemp("log") / "run.npz")


# ------------------------------------------------------------------ unreadable .npz files
@pytest.mark.parametrize("how", SPOILS)
def test_every_npz_reader_names_a_spoiled_file(tmp_path, log_file, how):
    net = robots_dir() / "mobile_humanoid" / "stiffness.npz"
    recording = next((data_dir() / "human_reaching").rglob("*.npz"), None)
    readers = {
        "run log": (log_file, RunLog.load),
        "stiffness network": (net, NetworkStiffness.load),
        "recording": (recording, load_recording),
    }
    dataset = tmp_path / "ds.npz"
    write_npz(dataset, {"k": np.zeros(2)})
    readers["stiffness dataset"] = (dataset, StiffnessDataset.load)
    for what, (source, read) in readers.items():
        if source is None:
            continue
        path = spoiled(Path(shutil.copy(source, tmp_path / f"{what}.npz")), how)
        with pytest.raises(DataError, match=f"{path.name}: not a readable {what}"):
            read(path)


def test_read_npz_says_what_the_file_is_not(tmp_path):
    np.save(tmp_path / "one.npy", np.ones(3))
    (tmp_path / "text.npz").write_text("hello")
    cases = {
        "one.npy": "a single .npy array",
        "text.npz": "no zip header",
        "missing.npz": "No such file",
    }
    for name, reason in cases.items():
        with pytest.raises(DataError, match=reason):
            read_npz(tmp_path / name, "thing")


def test_a_scenario_with_a_spoiled_demonstration_is_named(tmp_path):
    dst = tmp_path / "tasks"
    shutil.copytree(tasks_dir(), dst)
    spoiled(dst / "demos" / "reach_demo.npz", "truncated")
    spec = load_scenario(dst / "reach_generalisation.toml")
    with pytest.raises(DataError, match=r"reach_demo\.npz: not a readable DMP demonstration"):
        run_scenario(spec, duration_scale=0.01)


def test_the_run_cli_reports_a_spoiled_demonstration_without_a_traceback(tmp_path, capsys):
    from wholebody.cli import main

    dst = tmp_path / "tasks"
    shutil.copytree(tasks_dir(), dst)
    spoiled(dst / "demos" / "reach_demo.npz", "empty")
    code = main(["run", str(dst / "reach_generalisation.toml"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "not a readable DMP demonstration" in err and "Traceback" not in err


# ------------------------------------------------------------------ a run log's structure
def _rewrite(src: Path, dst: Path, change) -> Path:
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    return write_npz(dst, arrays)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda a: a.update(meta=np.array("{not json")), "key 'meta' is not valid JSON"),
        (lambda a: a.update(meta=np.array("[1, 2]")), "key 'meta' must be a JSON object"),
        (lambda a: a.pop("arm/right/spring"), "arm trace 'right' lacks spring"),
        (lambda a: a.update(u=a["u"][:-1]), "key 'u' has 4 rows, 't' has 5"),
        (lambda a: a.pop("q"), "run log lacks \\['q'\\]"),
    ],
    ids=["bad JSON", "meta not an object", "incomplete arm", "short array", "missing key"],
)
def test_a_malformed_run_log_is_named(humanoid, tmp_path, change, message):
    src = _with_arms(humanoid).save(tmp_path / "good.npz")
    bad = _rewrite(src, tmp_path / "bad.npz", change)
    with pytest.raises(DataError, match=message):
        RunLog.load(bad)


def _with_arms(robot) -> RunLog:
    from wholebody.tasks import ArmPotentialEnergy

    hand = FrameTask(robot, "right_tool")
    stack = Stack(robot, [Level([hand]), Level([PostureTask(robot)])])
    monitors = [ArmPotentialEnergy(robot, "right", 0.1)]
    return Controller(robot, stack, ProjectionSolver(), dt=0.01, monitors=monitors).run(
        robot.neutral(), 0.05
    )


# ------------------------------------------------------------------ numbers read from files
def test_a_network_with_nan_weights_is_refused(tmp_path):
    good = robots_dir() / "mobile_humanoid" / "stiffness.npz"
    bad = _rewrite(good, tmp_path / "nan.npz", lambda a: a["W0"].__setitem__((0, 0), np.nan))
    with pytest.raises(DataError, match="must be finite"):
        NetworkStiffness.load(bad)
    assert np.isfinite(default_stiffness().evaluate(np.array([0.3, 0.1, -0.2]))[0])


@pytest.mark.parametrize("height", ["nan", "-1.7", "17"])
def test_an_implausible_participant_height_is_refused(tmp_path, height):
    path = tmp_path / "participants.csv"
    path.write_text(f"participant,sex,height_m\nP01,F,{height}\n")
    with pytest.raises(DataError, match=r"column 'height_m'.*height in metres"):
        load_participants(path)


# ------------------------------------------------------------------ API misuse
def test_update_refuses_an_unnormalised_cos_sin_pair(humanoid):
    q = humanoid.neutral()
    q[2:4] = 2.0, 0.0  # the base yaw as (cos, sin): |.| = 2
    with pytest.raises(DimensionError, match=r"\(q\[2\], q\[3\]\) = \(2, 0\) is not a \(cos"):
        humanoid.update(q)
    humanoid.update(humanoid.neutral())  # and the fast path still takes a good one


@pytest.mark.parametrize("duration", [float("nan"), float("inf"), "1.0", None])
def test_run_refuses_a_duration_that_is_not_a_finite_number(humanoid, duration):
    hand = FrameTask(humanoid, "right_tool")
    stack = Stack(humanoid, [Level([hand])])
    controller = Controller(humanoid, stack, ProjectionSolver(), dt=0.01)
    with pytest.raises(DimensionError, match="duration must be a finite number of seconds"):
        controller.run(humanoid.neutral(), duration)


def test_integrate_refuses_what_would_give_a_nan_configuration(humanoid):
    q, u = humanoid.neutral(), np.zeros(humanoid.nu)
    with pytest.raises(DimensionError, match=r"actuated velocity .* is not finite"):
        humanoid.integrate(q, np.full(humanoid.nu, np.nan), 0.01)
    for dt in (float("nan"), "0.01", None):
        with pytest.raises(DimensionError, match="dt must be a finite number of seconds"):
            humanoid.integrate(q, u, dt)
    bad = q.copy()
    bad[2:4] = 0.5, 0.5
    with pytest.raises(DimensionError, match="is not a \\(cos, sin\\) pair"):
        humanoid.integrate(bad, u, 0.01)


def test_strings_are_not_numbers(humanoid):
    q = humanoid.neutral()
    with pytest.raises(DimensionError, match=r"configuration .* must be numbers"):
        humanoid.update(q.astype(str))
    with pytest.raises(DimensionError, match="target pose must be numbers"):
        FrameTask(humanoid, "right_tool").set_target(np.eye(4).astype(str))
    with pytest.raises(DimensionError, match="joint 'waist_yaw': expected a number"):
        humanoid.configuration({"waist_yaw": "0.1"})


@pytest.mark.parametrize("pose", [(1.0, 2.0), (1.0, 2.0, float("nan")), ("1", 2.0, 0.0), 3.0])
def test_a_base_pose_is_three_finite_numbers(humanoid, pose):
    with pytest.raises(DimensionError, match="base_pose must be three finite numbers"):
        humanoid.configuration(base_pose=pose)


@pytest.mark.parametrize("margin", [2, -0.1, 0.5, float("nan")])
def test_random_configuration_margin_is_a_fraction_below_one_half(humanoid, margin):
    with pytest.raises(DimensionError, match=r"margin .* in \[0, 0.5\)"):
        humanoid.random_configuration(np.random.default_rng(0), margin=margin)


@pytest.mark.parametrize("name", [None, "", 3])
def test_load_robot_needs_a_name_or_a_path(name):
    with pytest.raises(ConfigError, match="expected a bundled robot name"):
        load_robot(name)


# ------------------------------------------------------------------ nothing lost
def test_a_failed_save_leaves_the_previous_file_whole(humanoid, tmp_path, monkeypatch):
    log = short_log(humanoid)
    path = log.save(tmp_path / "run.npz")
    before = path.read_bytes()

    def disk_full(fh, **arrays):
        fh.write(b"PK\x03\x04 half a file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", disk_full)
    with pytest.raises(OSError, match="No space left"):
        log.save(path)
    assert path.read_bytes() == before and len(RunLog.load(path)) == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]  # no temporary left


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "table.json"
    path.write_text(json.dumps({"old": True}))
    with pytest.raises(KeyboardInterrupt), atomic_path(path) as tmp:
        tmp.write_text('{"new": tr')
        raise KeyboardInterrupt
    assert json.loads(path.read_text()) == {"old": True}
    assert [p.name for p in tmp_path.iterdir()] == ["table.json"]


def test_ctrl_c_while_writing_a_run_says_what_was_not_written(tmp_path, monkeypatch, capsys):
    from wholebody.cli import main
    from wholebody.scenarios import plots

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "joint_velocities", interrupted)
    out = tmp_path / "out"
    code = main(["run", "reach_generalisation", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 130
    assert "not written: joint_velocities, arm_energy" in err
    assert len(RunLog.load(out / "run.npz")) > 0
    assert json.loads((out / "metrics.json").read_text())["steps"] > 0
    assert (out / "hands.png").stat().st_size > 0 and not (out / "arm_energy.png").exists()


@pytest.mark.slow
def test_ctrl_c_during_compare_keeps_the_finished_backends(tmp_path, monkeypatch, capsys):
    from wholebody import cli
    from wholebody.scenarios import runner

    calls = []
    real = runner.run_scenario

    def second_interrupted(spec, **kwargs):
        calls.append(kwargs["backend"])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(spec, **{**kwargs, "duration_scale": 0.05})

    monkeypatch.setattr("wholebody.scenarios.run_scenario", second_interrupted)
    out = tmp_path / "cmp"
    code = cli.main(
        ["compare", "reach_generalisation", "--out", str(out), "--backends", "pinv", "projection"]
    )
    err = capsys.readouterr().err
    assert code == 130 and "not run: projection; finished: pinv" in err
    rows = json.loads((out / "comparison.json").read_text())["rows"]
    assert [r["backend"] for r in rows] == ["pinv"]
    assert len(RunLog.load(out / "pinv" / "run.npz")) > 0
