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


def scenario(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "small.toml"
    path.write_text(HEAD + text)
    return path


def test_a_phase_lasts_a_whole_number_of_steps(tmp_path):
    """0.025 s at 100 Hz: the phase and its reference last 2 steps, so the next phase starts
    where the reference ended and each step is counted in its own phase."""
    path = scenario(tmp_path, LEFT + """
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
""")  # fmt: skip
    log = run_scenario(load_scenario(path)).log
    assert log.meta["phases"] == {"one": [0.0, 0.02], "two": [0.02, 0.04]}
    assert log.phase_mask("one").tolist() == [True, True, False, False]
    assert log.phase_mask("two").tolist() == [False, False, True, True]
    ref = log.reference_positions["right"]
    np.testing.assert_allclose(ref[2:], [[0.2, -0.4, 0.5]] * 2, atol=1e-12)  # held at the goal


def test_a_carried_object_stays_where_it_is_left(tmp_path):
    path = scenario(tmp_path, """
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
""")  # fmt: skip
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
    path = scenario(tmp_path, """
[planner]
demo = "late.npz"
[[phases]]
name = "reach"
duration = 1.0
[phases.hands.right]
planner = "dmp"
shape = "straight"
goal = [0.3, -0.45, 0.5]
""")  # fmt: skip
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
    path = scenario(tmp_path, """
[[phases]]
name = "p"
duration = 0.02
[phases.hands.right]
planner = "hold"
""")  # fmt: skip
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

    text = HEAD.replace("mobile_humanoid", "dual_arm_torso") + """
[[phases]]
name = "hold"
duration = 0.03
[phases.hands.right]
planner = "hold"
"""  # fmt: skip
    path = tmp_path / "torso.toml"
    path.write_text(text)
    run = run_scenario(load_scenario(path))
    assert plots.plotted_groups(run.log) == ["left_arm", "right_arm", "torso"]
    table = outputs.comparison_markdown(outputs.comparison([run]), "torso")
    assert "waist" not in table and "| method | frequency (Hz) |" in table
    outputs.write_run(run, tmp_path / "out")  # the figures draw on this robot too
