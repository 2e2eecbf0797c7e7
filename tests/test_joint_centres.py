"""Arms whose shoulder, elbow or wrist frames are not joint centres: the error names each frame
that is off and where a joint centre is, and ``wholebody info DIR --suggest-frames`` prints
``[frames]`` entries that, pasted into robot.toml, make the arm check pass."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import wholebody
from wholebody import ConfigError
from wholebody.cli import main
from wholebody.resources import robots_dir
from wholebody.robot.urdf import example_robot_data_share

BAXTER = """format = 1

[robot]
name = "baxter"
urdf = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"

[groups]
left_arm = ["left_s0", "left_s1", "left_e0", "left_e1", "left_w0", "left_w1", "left_w2"]

# the link origins a new user would try first: none is a joint centre (the shoulder, elbow
# and wrist axes of Baxter's arm miss each other by 69, 69 and 10 mm)
[arms.left]
side = "left"
group = "left_arm"
shoulder = "left_upper_shoulder"
elbow = "left_upper_elbow"
wrist = "left_upper_forearm"
tool = "left_gripper"
upper_arm = "left_lower_shoulder"
forearm = "left_lower_elbow"
"""


def paste(toml: Path, printed: str) -> None:
    """Append the printed [frames] entries to ``toml`` and point the arms at them, as its
    comment line ``# and in [arms.NAME]: key = "frame", ...`` says."""
    text = toml.read_text() + "\n" + printed
    for arm, keys in re.findall(r"^# and in \[arms\.(\w+)\]: (.*)$", printed, re.M):
        head, rest = text.split(f"[arms.{arm}]\n", 1)
        table, tail = [*rest.split("\n[", 1), ""][:2]
        for key, frame in re.findall(r'(\w+) = "([^"]+)"', keys):
            table = re.sub(rf'^{key} = "[^"]*"$', f'{key} = "{frame}"', table, flags=re.M)
        text = f"{head}[arms.{arm}]\n{table}" + (f"\n[{tail}" if tail else "")
    toml.write_text(text)


def suggest(d: Path, capsys) -> str:
    assert main(["info", str(d), "--suggest-frames"]) == 0
    return capsys.readouterr().out


@pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="example-robot-data is not installed (pip install '.[robots]' from the checkout)",
)
def test_baxters_arm_axes_do_not_meet_and_the_suggested_frames_make_it_load(tmp_path, capsys):
    """Baxter (example-robot-data, not shipped): the error names the three frames off their
    centres and the command; the pasted suggestion loads, with the shoulder where the axes
    of s1 and e0 meet, the elbow where e1 and w0 meet and the wrist where w1 and w2 meet."""
    d = tmp_path / "baxter"
    d.mkdir()
    (d / "robot.toml").write_text(BAXTER)
    with pytest.raises(ConfigError) as info:
        wholebody.load_robot(d)
    text = str(info.value)
    for key, frame in (
        ("shoulder", "left_upper_shoulder"),
        ("elbow", "left_upper_elbow"),
        ("wrist", "left_upper_forearm"),
    ):
        assert f"the {key} '{frame}' is " in text
    assert f"wholebody info {d.resolve()} --suggest-frames" in text
    printed = suggest(d, capsys)
    assert "on the axes of left_s1, left_e0" in printed
    assert "on the axes of left_e1, left_w0" in printed
    assert "on the axes of left_w1, left_w2" in printed
    paste(d / "robot.toml", printed)
    robot = wholebody.load_robot(d)
    arm = robot.arm("left")
    assert arm.shoulder.name == "left_shoulder_centre" and arm.wrist.name == "left_wrist_centre"
    state = robot.update(robot.neutral())
    for frame, joints in (
        (arm.shoulder, ("left_s1", "left_e0")),
        (arm.elbow, ("left_e1", "left_w0")),
        (arm.wrist, ("left_w1", "left_w2")),
    ):
        for j in joints:  # on each axis, to the 20 um the suggestion allows
            assert _distance_to_axis(robot, state.position(frame), j) < 2e-5
    assert "joint centres already" in suggest(d, capsys)


def _distance_to_axis(robot: wholebody.Robot, p: np.ndarray, joint: str) -> float:
    """Distance (m) of the world point ``p`` from ``joint``'s axis at the last update."""
    j = robot.model.getJointId(joint)
    column = robot.model.joints[j].idx_v
    axis = pin.getJointJacobian(robot.model, robot.data, j, pin.WORLD)[3:, column]
    return float(np.linalg.norm(np.cross(p - robot.data.oMi[j].translation, axis)))


def test_an_elbow_frame_two_centimetres_off_its_axis_is_named_and_put_back(tmp_path, capsys):
    """A shipped robot with its left elbow frame declared 2 cm off the elbow axis: the error
    names that frame alone (20.0 mm off, on the axis of left_elbow), and the pasted suggestion
    puts the arm back to the shipped lengths."""
    d = tmp_path / "torso"
    shutil.copytree(robots_dir() / "dual_arm_torso", d)
    toml = d / "robot.toml"
    text = toml.read_text().replace('elbow = "left_elbow_centre"', 'elbow = "my_elbow"', 1)
    toml.write_text(
        text + '\n[frames.my_elbow]\nparent = "left_elbow_centre"\nxyz = [0.02, 0.0, 0.0]\n'
    )
    with pytest.raises(ConfigError) as info:
        wholebody.load_robot(d)
    text = str(info.value)
    assert "the elbow 'my_elbow' is 20.0 mm from one (on the axes of left_elbow" in text
    assert "the shoulder '" not in text and "the wrist '" not in text
    printed = suggest(d, capsys)
    assert printed.count("[frames.") == 1 and "# arm right: its shoulder" in printed
    paste(toml, printed)
    robot, shipped = wholebody.load_robot(d), wholebody.load_robot("dual_arm_torso")
    for a, b in ((robot.arm("left"), shipped.arm("left")),):
        assert a.upper_arm_length == pytest.approx(b.upper_arm_length, abs=1e-9)
        assert a.forearm_length == pytest.approx(b.forearm_length, abs=1e-9)
