"""The command line: run, compare, demo, info, and errors without tracebacks."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from wholebody.cli import main
from wholebody.control import RunLog
from wholebody.resources import robots_dir

SMALL = """
format = 2
[scenario]
name = "small"
robot = "mobile_humanoid"
backend = "pinv"
rate_hz = 100.0
[stack]
stiffness = 0.1
acceleration = false
[hands.right]
frame = "right_tool"
[[phases]]
name = "reach"
duration = 0.05
[phases.hands.right]
planner = "min_jerk"
goal = [0.2, -0.4, 0.5]
"""


def test_info(capsys):
    assert main(["info", "--list"]) == 0
    assert "mobile_humanoid" in capsys.readouterr().out
    assert main(["info", "dual_arm_torso"]) == 0
    assert "nu = 15" in capsys.readouterr().out


def test_info_names_the_tool_frames_and_the_frames(capsys):
    """Every snippet needs a frame name (``right_tool``): info lists the arms' tool frames and
    the link frames; --frames adds the joints."""
    assert main(["info", "mobile_humanoid"]) == 0
    out = capsys.readouterr().out
    assert "tool frames (hand tasks): left_tool (arm left), right_tool (arm right)" in out
    assert "link frames (35): base_link, column," in out and "wheel_rear_right_link" in out
    assert "joint frames" not in out and "--frames" in out
    assert main(["info", "mobile_humanoid", "--frames"]) == 0
    full = capsys.readouterr().out
    assert "joint frames" in full and "waist_pitch" in full.split("joint frames")[1]


def test_info_abridges_a_long_frame_list(monkeypatch):
    """A robot with more links than FRAMES_SHOWN gets the first ones and a pointer to
    --frames; its declared frames ([frames]) are listed apart."""
    from types import SimpleNamespace

    import wholebody.cli as cli

    links = [f"link_{i}" for i in range(cli.FRAMES_SHOWN + 7)]
    kinds = {"links": links, "declared": ["shoulder_centre"], "joints": ["j1"]}
    monkeypatch.setattr(cli, "_frame_kinds", lambda robot: kinds)
    from wholebody.resources import robots_dir

    config = SimpleNamespace(path=robots_dir() / "big" / "robot.toml")  # bundled: its name
    robot = SimpleNamespace(name="big", arms={}, config=config)
    text, full = cli.frames_text(robot), cli.frames_text(robot, full=True)
    assert "... 7 more (wholebody info big --frames)" in " ".join(text.split())
    assert f"link_{cli.FRAMES_SHOWN} " not in text.replace(",", " ")
    assert "declared frames (1): shoulder_centre" in text
    assert f"link_{cli.FRAMES_SHOWN + 6}" in full and "joint frames (1): j1" in full


def test_the_frames_hint_names_the_directory_a_robot_was_loaded_from(tmp_path, monkeypatch, capsys):
    """A robot loaded from a directory of its own is pointed at by that directory's absolute
    path in the --frames hint: the hinted command loads it from any directory."""
    (tmp_path / "mine").mkdir()
    shutil.copy(robots_dir() / "tiago_dual" / "robot.toml", tmp_path / "mine" / "robot.toml")
    monkeypatch.chdir(tmp_path)
    assert main(["info", "mine"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    hint = out.split("more (wholebody info ")[1].split(" --frames)")[0]
    assert hint == str((tmp_path / "mine").resolve())
    monkeypatch.chdir(tmp_path.parent)
    assert main(["info", hint, "--frames"]) == 0
    assert "joint frames" in capsys.readouterr().out


def test_a_reader_that_leaves_early_ends_info_without_a_traceback():
    """``wholebody info ... | head -1``: the reader closes the pipe before the output is
    written; the command ends quietly with the status of a program stopped by SIGPIPE."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "wholebody", "info", "dual_arm_torso"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # before the child has imported anything, so it writes after
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "BrokenPipe" not in err


HEAVY = (
    "numba",
    "matplotlib",
    "scipy",
    "torch",
    "meshcat",
    "tqdm",
    "wholebody.scenarios",
    "wholebody.humanlike",
    "wholebody.kernels",
)


@pytest.mark.parametrize(
    "argv", [["--help"], ["run", "--help"], ["run", "no_such_scenario"], ["run", "--bogus"]]
)
def test_help_and_argument_errors_import_nothing_heavy(argv):
    """--help and argument errors answer without importing the solvers, kernels, plots or
    torch (it took 2 s): the commands import what they need when they run. (``import
    wholebody.cli`` itself is the package's business; only what main adds is checked.)"""
    code = (
        "import sys\n"
        "import wholebody.cli\n"
        "before = set(sys.modules)\n"
        "try:\n"
        f"    code = wholebody.cli.main({argv!r})\n"
        "except SystemExit as exc:\n"
        "    code = exc.code\n"
        "new = sorted(m for m in set(sys.modules) - before\n"
        f"             if m.split('.')[0] in {HEAVY!r} or m.startswith({HEAVY!r}))\n"
        "print('NEW', new, 'CODE', code)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )
    assert "NEW [] CODE" in done.stdout, done.stdout + done.stderr


def test_parser_constants_match_their_sources():
    """The parser repeats the backends and the stiffness help line so as not to import their
    modules; they are the same."""
    import argparse

    from wholebody.cli import BACKENDS, STIFFNESS_HELP, build_parser
    from wholebody.scenarios.spec import BACKENDS as SPEC_BACKENDS

    assert BACKENDS == SPEC_BACKENDS

    def command_help(parser: argparse.ArgumentParser) -> dict[str, str]:
        (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        return {a.dest: a.help for a in sub._choices_actions}

    real, light = command_help(build_parser(stiffness=True)), command_help(build_parser(False))
    assert real == light and light["stiffness"] == STIFFNESS_HELP


def test_run_help_lists_the_bundled_scenarios(capsys):
    from wholebody.resources import tasks_dir

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    names = sorted(p.stem for p in tasks_dir().glob("*.toml"))
    assert len(names) >= 4
    assert "a bundled name: " + ", ".join(names) in out


def test_stiffness_still_parses_its_subcommands(capsys):
    with pytest.raises(SystemExit):
        main(["stiffness", "--help"])
    out = capsys.readouterr().out
    assert "dataset" in out and "report" in out


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
        "median_step_rate_hz",
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
    out = capsys.readouterr().out
    assert "worst hand MAE" in out
    median, rate = map(
        float, re.search(r"control step median (\d+) us \(1/median = (\d+) Hz\)", out).groups()
    )
    assert rate == pytest.approx(1e6 / metrics["step_time_us"]["median"], abs=1)
    assert median == pytest.approx(metrics["step_time_us"]["median"], abs=1)


@pytest.mark.slow
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
    for r in rows:
        assert r["median_step_rate_hz"] == pytest.approx(1e6 / r["step_time_us_median"])
    table = (out / "comparison.md").read_text()
    assert "MSE x (m²)" in table and "waist travel (rad)" in table and "343.46 Hz" in table
    assert "| median step (us) | 1 / median step (Hz) |" in table
    for backend in ("pinv", "projection"):  # each backend's figures, like run's
        for name in (
            "run.npz",
            "metrics.json",
            "hands.png",
            "joint_velocities.png",
            "arm_energy.png",
        ):
            assert (out / backend / name).is_file(), (backend, name)


def test_errors_are_reported_without_a_traceback(tmp_path, capsys):
    assert main(["run", "no_such_scenario"]) == 2
    err = capsys.readouterr().err
    assert "no scenario 'no_such_scenario'" in err and "coordinated_carry" in err
    bad = tmp_path / "bad.toml"
    bad.write_text('format = 2\n[scenario]\nname = "x"\nbackend = "mpc"\n')
    assert main(["run", str(bad)]) == 2
    assert "[scenario.backend]" in capsys.readouterr().err
    taken = tmp_path / "a_file"
    taken.write_text("")
    assert main(["run", "obstacle_avoidance", "--out", str(taken)]) == 2  # before the run
    assert "exists and is not a directory" in capsys.readouterr().err
    below_a_file = taken / "x"  # cannot be made: found before the run, not after it
    assert main(["run", "obstacle_avoidance", "--out", str(below_a_file)]) == 2
    assert "cannot make the directory" in capsys.readouterr().err


def test_demo_opens_a_viewer_only_with_viz(monkeypatch, capsys, tmp_path):
    """With DISPLAY set, plain ``demo`` stays headless (a viewer that blocks until Enter is
    opt-in: --viz)."""
    import wholebody.cli as cli

    calls = []
    monkeypatch.setattr(cli, "_run_one", lambda path, backend, viz, out, hold: calls.append(viz))
    monkeypatch.setenv("DISPLAY", ":0")
    assert main(["demo", "--out", str(tmp_path / "d")]) == 0
    assert calls == [False] and "headless" in capsys.readouterr().out
    assert main(["demo", "--viz", "--out", str(tmp_path / "d")]) == 0
    assert calls == [False, True]


@pytest.mark.slow
def test_run_viz_without_a_terminal_leaves_a_standalone_replay(tmp_path, monkeypatch, capsys):
    """--viz with no terminal to wait on: the replay is saved as one HTML page that needs no
    server, the output says where, and the MeshCat URL is printed once (meshcat's own print
    silenced)."""
    scenario = tmp_path / "small.toml"
    scenario.write_text(SMALL)
    monkeypatch.setattr(sys.stdin, "isatty", lambda: False, raising=False)
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--viz", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    page = out / "replay.html"
    assert page.is_file() and f"replay            {page}" in text
    html = page.read_text()
    assert "MeshCat.Viewer" in html and "set_animation" in html
    assert text.count("http://127.0.0.1") == 1, text
    assert "You can open the visualizer" not in text


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
