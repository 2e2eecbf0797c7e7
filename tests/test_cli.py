"""The command line: run, compare, demo, info, and errors without tracebacks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wholebody.cli import main
from wholebody.control import RunLog


def test_info(capsys):
    assert main(["info", "--list"]) == 0
    assert "mobile_humanoid" in capsys.readouterr().out
    assert main(["info", "dual_arm_torso"]) == 0
    assert "nu = 15" in capsys.readouterr().out


@pytest.mark.slow
def test_run_writes_the_log_metrics_and_figures(tmp_path, capsys):
    out = tmp_path / "obstacles"
    assert main(["run", "obstacle_avoidance", "--out", str(out)]) == 0
    for name in ("run.npz", "metrics.json", "hands.png", "joint_velocities.png", "arm_energy.png"):
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())
    for key in (
        "mae_m",
        "mse_m2",
        "frequency_hz",
        "joint_travel_rad",
        "limit_violations",
        "closed_chain_error_max_m",
        "arm_energy_j",
        "arm_angle_rad",
        "solver_failures",
    ):
        assert key in metrics, key
    assert set(metrics["mae_m"]["right"]) == {"x", "y", "z"}
    assert set(metrics["joint_travel_rad"]) == {"wheels", "waist", "left_arm", "right_arm"}
    assert set(metrics["arm_energy_j"]["right"]) >= {"initial", "final", "mean"}
    log = RunLog.load(out / "run.npz")
    assert len(log) == 1100 and log.meta["scenario"] == "obstacle_avoidance"
    assert np.isclose(log.t[-1], 10.99)
    assert "worst hand MAE" in capsys.readouterr().out


def test_compare_writes_table_2(tmp_path):
    out = tmp_path / "cmp"
    assert (
        main(
            ["compare", "obstacle_avoidance", "--out", str(out), "--backends", "pinv", "projection"]
        )
        == 0
    )
    rows = json.loads((out / "comparison.json").read_text())["rows"]
    assert [r["backend"] for r in rows] == ["pinv", "projection"]
    table = (out / "comparison.md").read_text()
    assert "MSE x (m²)" in table and "waist travel (rad)" in table and "343.46 Hz" in table


def test_errors_are_reported_without_a_traceback(tmp_path, capsys):
    assert main(["run", "no_such_scenario"]) == 2
    err = capsys.readouterr().err
    assert "no scenario 'no_such_scenario'" in err and "coordinated_carry" in err
    bad = tmp_path / "bad.toml"
    bad.write_text('[scenario]\nname = "x"\nbackend = "mpc"\n')
    assert main(["run", str(bad)]) == 2
    assert "[scenario.backend]" in capsys.readouterr().err
    taken = tmp_path / "a_file"
    taken.write_text("")
    assert main(["run", "obstacle_avoidance", "--out", str(taken)]) == 2  # before the run
    assert "exists and is not a directory" in capsys.readouterr().err
    below_a_file = taken / "x"  # cannot be made: found before the run, not after it
    assert main(["run", "obstacle_avoidance", "--out", str(below_a_file)]) == 2
    assert "cannot make the directory" in capsys.readouterr().err


@pytest.mark.slow
def test_demo_runs_headless_without_a_display(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    pytest.importorskip("wholebody.planning.dual_arm")
    assert main(["demo", "--out", str(tmp_path / "demo")]) == 0
    out = capsys.readouterr().out
    assert "headless" in out and "closed chain" in out
    assert (tmp_path / "demo" / "hands.png").is_file()


def test_warmup_compiles_every_kernel_and_says_where_they_are_cached(capsys):
    assert main(["warmup"]) == 0
    out = capsys.readouterr().out
    assert "kernels ready in" in out or "nothing to compile" in out
