"""The scenario runner on small scenarios written for the test: phase timing, carried
objects, the "straight" DMP shape, and the checks of the scenario reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wholebody.control import RunLog
from wholebody.errors import ConfigError
from wholebody.planning import minimum_jerk_scaling
from wholebody.scenarios import load_scenario, run_scenario

HEAD = """
format = 2
[scenario]
name = "small"
robot = "mobile_humanoid"
backend = "pinv"
rate_hz = 100.0
[stack]
stiffness = 0.1
acceleration = false  # the phases here are 2-10 steps: abrupt on purpose
[hands.right]
frame = "right_tool"
"""
LEFT = """
[hands.left]
frame = "left_tool"
"""


def scenario(tmp_path: Path, text: str, start: str | None = None) -> Path:
    """The small scenario's file: ``HEAD``, with ``start = <start>`` in ``[scenario]`` unless
    None, then ``text``."""
    line = "" if start is None else f"start = {start}\n"
    path = tmp_path / "small.toml"
    path.write_text(HEAD.replace("rate_hz = 100.0\n", f"rate_hz = 100.0\n{line}") + text)
    return path


def test_a_phase_lasts_a_whole_number_of_steps(tmp_path):
    """0.025 s at 100 Hz: the phase and its reference last 2 steps, so the next phase starts
    where the reference ended and each step is counted in its own phase."""
    path = scenario(
        tmp_path,
        LEFT
        + """
[[phases]]
name = "one"
duration = 0.025
[phases.hands.right]
planner = "min_jerk"
goal = [0.2, -0.4, 0.5]
[phases.hands.left]
planner = "hold"
[[phases]]
name = "two"
duration = 0.025
[phases.hands.right]
planner = "hold"
[phases.hands.left]
planner = "hold"
""",
    )
    log = run_scenario(load_scenario(path)).log
    assert log.meta["phases"] == {"one": [0.0, 0.02], "two": [0.02, 0.04]}
    assert log.phase_mask("one").tolist() == [True, True, False, False]
    assert log.phase_mask("two").tolist() == [False, False, True, True]
    ref = log.reference_positions["right"]
    np.testing.assert_allclose(ref[2:], [[0.2, -0.4, 0.5]] * 2, atol=1e-12)  # held at the goal


def test_a_carried_object_stays_where_it_is_left(tmp_path):
    # the object is at the right hand of the neutral posture
    path = scenario(
        tmp_path,
        """
[[objects]]
name = "obj"
kind = "sphere"
radius = 0.02
position = [0.1, -0.47, 0.4]
[[phases]]
name = "carry"
duration = 0.1
[phases.hands.right]
planner = "min_jerk"
goal = [0.15, -0.47, 0.45]
carry = "obj"
[[phases]]
name = "leave"
duration = 0.1
[phases.hands.right]
planner = "min_jerk"
goal = [0.1, -0.47, 0.4]
""",
        start='"neutral"',
    )
    run = run_scenario(load_scenario(path))
    poses, log = run.object_poses["obj"], run.log
    carry, leave = log.phase_mask("carry"), log.phase_mask("leave")
    assert np.ptp(poses[carry][:, :3, 3], axis=0).max() > 0.02  # moved with the hand
    np.testing.assert_array_equal(poses[leave], np.repeat(poses[leave][:1], leave.sum(), 0))
    first_leave = int(np.flatnonzero(leave)[0])  # left where the hand was at the end
    step = np.linalg.norm(poses[first_leave, :3, 3] - poses[first_leave - 1, :3, 3])
    assert 0 < step < 5e-3


def test_the_straight_shape_does_not_need_times_from_zero(tmp_path):
    """A demonstration whose clock starts at 10 s: the "straight" DMP still follows the
    minimum-jerk profile from start to goal."""
    demo = Path(__file__).resolve().parents[1] / "tasks" / "demos" / "reach_demo.npz"
    with np.load(demo) as z:
        np.savez(tmp_path / "late.npz", times=z["times"] + 10.0, positions=z["positions"])
    path = scenario(
        tmp_path,
        """
[planner]
demo = "late.npz"
[[phases]]
name = "reach"
duration = 1.0
[phases.hands.right]
planner = "dmp"
shape = "straight"
goal = [0.3, -0.45, 0.5]
""",
    )
    log = run_scenario(load_scenario(path)).log
    ref = log.reference_positions["right"]
    start, goal = ref[0], np.array([0.3, -0.45, 0.5])
    s = minimum_jerk_scaling(log.t / 1.0)[0]
    np.testing.assert_allclose(ref, start + np.outer(s, goal - start), atol=1e-3)


@pytest.mark.parametrize(
    ("text", "parts"),
    [
        (
            """
[[phases]]
name = "p"
duration = 1.0
closed_chain = true
primary = "right"
[phases.hands.right]
planner = "hold"
""",
            ["[phases[0].closed_chain]", "needs two hands"],
        ),
        (
            """
[[phases]]
name = "p"
duration = 1.0
[phases.hands.right]
planner = "hold"
rotate = [0.0, 0.0, 1.0]
""",
            ["[phases[0].hands.right.rotate]", "takes no rotate"],
        ),
    ],
    ids=["closed chain with one hand", "rotate on hold"],
)
def test_inconsistent_phases_are_rejected(tmp_path, text, parts):
    path = scenario(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    for part in [str(path), *parts]:
        assert part in str(info.value)


def test_a_log_with_numpy_metadata_round_trips(tmp_path):
    path = scenario(
        tmp_path,
        """
[[phases]]
name = "p"
duration = 0.02
[phases.hands.right]
planner = "hold"
""",
    )
    log = run_scenario(load_scenario(path)).log
    log.meta["trial"] = np.int64(3)
    log.meta["gain"] = np.float32(0.5)
    back = RunLog.load(log.save(tmp_path / "log.npz"))
    assert back.meta["trial"] == 3 and back.meta["gain"] == 0.5


@pytest.mark.slow
def test_outputs_follow_the_robots_own_groups(tmp_path):
    """On a robot without a waist and with a torso group, the velocity plot shows every group
    and the comparison table has no waist column (it read nan)."""
    from wholebody.scenarios import outputs, plots

    text = (
        HEAD.replace("mobile_humanoid", "dual_arm_torso")
        + """
[[phases]]
name = "hold"
duration = 0.03
[phases.hands.right]
planner = "hold"
"""
    )
    path = tmp_path / "torso.toml"
    path.write_text(text)
    run = run_scenario(load_scenario(path))
    assert plots.plotted_groups(run.log) == ["left_arm", "right_arm", "torso"]
    table = outputs.comparison_markdown(outputs.comparison([run]), "torso")
    assert "waist" not in table
    assert "| method | median step (us) | 1 / median step (Hz) |" in table
    outputs.write_run(run, tmp_path / "out")  # the figures draw on this robot too


HOLD = """
[[phases]]
name = "p"
duration = 0.02
[phases.hands.right]
planner = "hold"
"""


def with_start(tmp_path: Path, start: str | None) -> Path:
    """The small scenario holding the right hand for 2 steps, with ``start = <start>``."""
    return scenario(tmp_path, HOLD, start)


def home_joints(robot) -> dict[str, float]:
    """The home posture's joints by name (the base's actuators left out)."""
    base = len(robot.base.actuators)
    return dict(
        zip(robot.actuated_joints[base:], robot.joint_positions(robot.home())[base:], strict=True)
    )


@pytest.mark.parametrize(
    ("start", "expected"),
    [
        (None, lambda robot: robot.home()),
        ('"home"', lambda robot: robot.home()),
        ('"neutral"', lambda robot: robot.neutral()),
        (
            "{ left_elbow_flexion = 0.8, waist_yaw = -0.2 }",
            lambda robot: robot.configuration(
                {**home_joints(robot), "left_elbow_flexion": 0.8, "waist_yaw": -0.2}
            ),
        ),
    ],
    ids=["default", "home", "neutral", "table"],
)
def test_a_scenario_starts_at_its_start_posture(humanoid, tmp_path, start, expected):
    """The first logged configuration is the start posture: home by default; a table moves
    the named joints from home."""
    run = run_scenario(load_scenario(with_start(tmp_path, start)))
    q0 = expected(humanoid)
    np.testing.assert_array_equal(run.log.q[0], q0)
    assert not np.array_equal(humanoid.home(), humanoid.neutral())  # the cases differ


@pytest.mark.parametrize(
    ("start", "parts", "when"),
    [
        ("3", ["[scenario.start]", '"home", "neutral" or a table', "got 3"], "load"),
        ('"crouch"', ["[scenario.start]", "'crouch'", "home, neutral"], "load"),
        ('{ waist_yaw = "left" }', ["[scenario.start.waist_yaw]", "expected a number"], "load"),
        ("{ waist_yw = 0.1 }", ["[scenario.start.waist_yw]", "unknown joint", "waist_yaw"], "run"),
        (
            "{ left_elbow_flexion = 3.0 }",
            ["[scenario.start.left_elbow_flexion]", "outside the joint's limits"],
            "run",
        ),
        (
            "{ wheel_front_left = 1.0 }",
            ["[scenario.start.wheel_front_left]", "base actuator"],
            "run",
        ),
    ],
    ids=[
        "wrong type",
        "unknown posture",
        "not a number",
        "unknown joint",
        "out of limits",
        "a wheel",
    ],
)
def test_a_bad_start_is_refused_by_name(tmp_path, start, parts, when):
    path = with_start(tmp_path, start)
    with pytest.raises(ConfigError) as info:
        spec = load_scenario(path)
        assert when == "run", "load_scenario accepted it"
        run_scenario(spec)  # checked against the robot before the first step
    for part in [str(path), *parts]:
        assert part in str(info.value), info.value


def test_the_step_rate_is_one_over_the_median_step_everywhere(tmp_path):
    """metrics.json, the comparison row and its table give the median step and 1/median: a
    slow first step (kernels loading) moves a mean, not them; no 1/mean is reported."""
    from wholebody.control.metrics import summary
    from wholebody.scenarios import outputs

    run = run_scenario(load_scenario(with_start(tmp_path, None)))
    run.log.step_time = np.array([0.5, 0.002, 0.003, 0.001, 0.004])  # s: a slow first step
    m = summary(run.log)
    assert m["step_time_us"]["median"] == pytest.approx(3000.0)
    assert m["median_step_rate_hz"] == pytest.approx(1 / 0.003)  # 333 Hz; 1/mean would be 9.9
    assert "frequency_hz" not in m
    run.metrics.update(m)
    (row,) = outputs.comparison([run])
    assert row["step_time_us_median"] == pytest.approx(3000.0)
    assert row["median_step_rate_hz"] == pytest.approx(1 / 0.003)
    table = outputs.comparison_markdown([row], "t").splitlines()
    header = [c.strip() for c in table[2].split("|")[1:-1]]
    cells = [c.strip() for c in table[4].split("|")[1:-1]]
    assert cells[header.index("median step (us)")] == "3000"
    assert cells[header.index("1 / median step (Hz)")] == "333"


def test_progress_in_a_log_is_plain_lines_not_a_bar(tmp_path, capsys):
    """Without a terminal (capsys: stderr is no TTY) a run's progress is plain lines, never
    tqdm's carriage-return redraws, which a log keeps as one huge line."""
    run_scenario(load_scenario(with_start(tmp_path, None)), progress=True)
    err = capsys.readouterr().err
    assert "\r" not in err and "small: 2/2 steps in" in err
    assert len(err.strip().splitlines()) == 1


def test_progress_is_a_bar_on_a_terminal_and_periodic_lines_elsewhere():
    import io

    from tqdm import tqdm

    from wholebody.control.controller import progress_report

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    bar = progress_report(10, True, "x", stream=Terminal())
    assert isinstance(bar, tqdm)
    bar.close()
    assert progress_report(10, False) is None
    log = io.StringIO()
    lines = progress_report(4, True, "run", every=0.0, stream=log)  # a line at every update
    lines.set_postfix_str("reach")
    for _ in range(4):
        lines.update(1)
    lines.close()
    out = log.getvalue().splitlines()
    assert out[:3] == [f"run: {k}/4 steps ({25 * k} %), 0 s, reach" for k in (1, 2, 3)]
    assert out[3].startswith("run: 4/4 steps in ") and len(out) == 4
