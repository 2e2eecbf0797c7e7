"""Scenario files: the bundled ones load, malformed ones are rejected precisely."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from wholebody import ConfigError
from wholebody.resources import tasks_dir
from wholebody.scenarios import load_scenario

BUNDLED = [
    "reach_generalisation",
    "obstacle_avoidance",
    "independent_dual_arm",
    "coordinated_carry",
]


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_scenarios_load(name):
    spec = load_scenario(tasks_dir() / f"{name}.toml")
    assert spec.name == name and spec.robot == "mobile_humanoid" and spec.rate_hz == 100.0
    assert spec.planner.demo is not None and spec.planner.demo.is_file()
    assert spec.duration > 5.0
    assert spec.start == "neutral"  # the paper's initial state, which the files were made for


def test_paper_numbers_are_in_the_files():
    carry = load_scenario(tasks_dir() / "coordinated_carry.toml")
    assert carry.objects["panel"].size == (0.1, 0.3, 0.02)
    assert carry.objects["panel"].position == (1.65, -0.125, 0.7)
    assert [p.duration for p in carry.phases if p.name in ("approach", "carry")] == [5.0, 20.0]
    assert carry.phases[-1].closed_chain and carry.phases[-1].primary == "right"
    indep = load_scenario(tasks_dir() / "independent_dual_arm.toml")
    reach = indep.phases[0]
    assert reach.hands["left"].goal == (1.6761, 0.21825, 0.46133)
    assert reach.hands["right"].goal == (1.701, -0.45675, 0.46133)
    assert indep.phases[1].duration == 3.0 and indep.phases[2].duration == 20.0
    obst = load_scenario(tasks_dir() / "obstacle_avoidance.toml")
    for c in ("cylinder_1", "cylinder_2"):
        assert obst.objects[c].radius == 0.04 and obst.objects[c].height == 0.2
    printed = (tasks_dir() / "obstacle_avoidance.toml").read_text()
    assert "(1.725, -0.4, 1.09)" in printed  # the paper's place, in the file's header
    assert obst.objects["cylinder_1"].position == (1.755, -0.4, 1.09)  # moved 3 cm: said why
    assert "printed at x = 1.725" in obst.objects["cylinder_1"].note


def copy_scenario(tmp_path: Path, name: str = "coordinated_carry") -> Path:
    dst = tmp_path / "tasks"
    shutil.copytree(tasks_dir(), dst)
    return dst / f"{name}.toml"


CASES = [
    (
        "unknown backend",
        'backend = "projection"',
        'backend = "mpc"',
        ["[scenario.backend]", "'mpc'", "projection, pinv, hqp"],
    ),
    ("negative rate", "rate_hz = 100.0", "rate_hz = -5.0", ["[scenario.rate_hz]", "> 0"]),
    (
        "typo in the stack",
        "wheel_metric = 0.01",
        "wheel_metrik = 0.01",
        ["[stack.wheel_metrik]", "unknown key"],
    ),
    (
        "bad stiffness",
        'stiffness = "learned"',
        'stiffness = "soft"',
        ["[stack.stiffness]", "expected a number"],
    ),
    (
        "unknown spring",
        "wheel_metric = 0.01",
        'wheel_metric = 0.01\nspring = "curly"',
        ["[stack.spring]", "'curly'", "paper, signed, none"],
    ),
    (
        "negative arm-angle rate",
        "wheel_metric = 0.01",
        "wheel_metric = 0.01\nhuman_arm_angle_kp = -1.0",
        ["[stack.human_arm_angle_kp]", "rate >= 0"],
    ),
    (
        "missing demo file",
        'demo = "demos/reach_demo.npz"',
        'demo = "demos/nope.npz"',
        ["[planner.demo]", "does not exist"],
    ),
    (
        "unknown planner",
        'planner = "follow"',
        'planner = "chase"',
        ["[phases[2].hands.left.planner]", "'chase'", "dmp, min_jerk, hold, follow, free"],
    ),
    (
        "goal of the wrong size",
        "goal = [1.65, -0.275, 0.7]",
        "goal = [1.65, -0.275]",
        ["[phases[0].hands.right.goal]", "3 numbers"],
    ),
    (
        "hand not declared",
        '[phases.hands.left]\nplanner = "follow"',
        '[phases.hands.middle]\nplanner = "follow"',
        ["[phases[2].hands.middle]", "unknown hand 'middle'"],
    ),
    (
        "follow without a primary",
        'primary = "right"\n',
        "",
        ["[phases[2].primary]", "needs primary"],
    ),
    (
        "carrying an unknown object",
        'carry = "panel"',
        'carry = "door"',
        ["[phases[2].hands.right.carry]", "unknown object 'door'"],
    ),
    (
        "non-positive phase duration",
        "duration = 20.0",
        "duration = 0.0",
        ["[phases[3].duration]", "> 0"],
    ),
    (
        "box with a zero edge",
        "size = [0.1, 0.3, 0.02]",
        "size = [0.1, 0.0, 0.02]",
        ["[objects[0].size]", "> 0"],
    ),
    (
        "rotation in degrees",
        "rotate = [0.0, 0.0, -1.5708]",
        "rotate = [0.0, 0.0, -90.0]",
        ["rotate]", "angle of at most pi", "90 deg = 1.5708 rad"],
    ),
    (
        "phase defined twice",
        'name = "grasp"',
        'name = "approach"',
        ["[phases[1].name]", "phase 'approach' is defined twice"],
    ),
]


@pytest.mark.parametrize(("old", "new", "parts"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_malformed_scenario_is_rejected(tmp_path, old, new, parts):
    path = copy_scenario(tmp_path)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    message = str(info.value)
    assert str(path) in message
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"


def test_avoid_must_name_an_obstacle(tmp_path):
    path = copy_scenario(tmp_path, "obstacle_avoidance")
    path.write_text(
        path.read_text().replace(
            'avoid = ["cylinder_1", "cylinder_2"]', 'avoid = ["cylinder_1", "object"]'
        )
    )
    with pytest.raises(ConfigError, match=r"avoid\].*'object' is not an object with obstacle"):
        load_scenario(path)
