"""Malformed or inconsistent robot descriptions are rejected with messages that name the file,
the key and what was expected; other base types and robots are just other robot.toml files."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from fdcheck import frame_jacobian_fd

import wholebody
from wholebody import ConfigError, ModelError
from wholebody.errors import DimensionError, FrameError
from wholebody.resources import robots_dir


def copy_robot(tmp_path: Path, name: str = "mobile_humanoid") -> Path:
    dst = tmp_path / name
    shutil.copytree(robots_dir() / name, dst)
    return dst


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, f"fixture text {old!r} not found in {path.name}"
    path.write_text(text.replace(old, new, 1))


# (description, file, old text, new text, error type, substrings the message must contain)
CASES = [
    (
        "missing [robot] table",
        "robot.toml",
        "[robot]\n",
        "[robt]\n",
        ConfigError,
        ["robot.toml", "[robt]", "unknown key"],
    ),
    (
        "missing urdf key",
        "robot.toml",
        'urdf = "robot.urdf"\n',
        "",
        ConfigError,
        ["[robot.urdf]", "missing key"],
    ),
    (
        "urdf file not found",
        "robot.toml",
        'urdf = "robot.urdf"',
        'urdf = "nope.urdf"',
        ConfigError,
        ["[robot.urdf]", "nope.urdf", "does not exist"],
    ),
    (
        "unknown frame in an arm",
        "robot.toml",
        'tool = "left_tool"',
        'tool = "left_tol"',
        ConfigError,
        ["[arms.left.tool]", "no frame 'left_tol'", "did you mean 'left_tool'"],
    ),
    (
        "unknown link for a body",
        "robot.toml",
        'forearm = "right_forearm"',
        'forearm = "right_fore_arm"',
        ConfigError,
        ["[arms.right.forearm]", "not a link"],
    ),
    (
        "joint in two groups",
        "robot.toml",
        'waist = ["waist_pitch", "waist_yaw", "waist_roll"]',
        'waist = ["waist_pitch", "waist_yaw", "waist_roll", "left_clavicle"]',
        ConfigError,
        ["[groups.left_arm]", "'left_clavicle' is already in group 'waist'"],
    ),
    (
        "unknown joint in a group",
        "robot.toml",
        '"waist_pitch", "waist_yaw", "waist_roll"]',
        '"waist_pitch", "waist_yw", "waist_roll"]',
        ConfigError,
        ["[groups.waist]", "'waist_yw' is not an actuated joint", "did you mean 'waist_yaw'"],
    ),
    (
        "wheel base does not match the URDF",
        "robot.toml",
        "wheel_base = 0.50",
        "wheel_base = 0.60",
        ConfigError,
        ["[base]", "do not match the URDF", "wheel_front_left"],
    ),
    (
        "wheels in the wrong order",
        "robot.toml",
        'wheels = ["wheel_front_left", "wheel_front_right", "wheel_rear_left", "wheel_rear_right"]'
        "\nwheel_radius",
        'wheels = ["wheel_front_right", "wheel_front_left", "wheel_rear_left", "wheel_rear_right"]'
        "\nwheel_radius",
        ConfigError,
        ["[base]", "wheel order", "'wheel_front_right'"],
    ),
    (
        "three Mecanum wheels",
        "robot.toml",
        'wheels = ["wheel_front_left", "wheel_front_right", "wheel_rear_left", "wheel_rear_right"]'
        "\nwheel_radius",
        'wheels = ["wheel_front_left", "wheel_front_right", "wheel_rear_left"]\nwheel_radius',
        ConfigError,
        ["[base.wheels]", "exactly 4 names, got 3"],
    ),
    (
        "a joint whose URDF limit has no lower and upper",
        "robot.urdf",
        '<limit lower="-0.79" upper="0.79" effort="300.0" velocity="1.0"/>',
        '<limit effort="300.0" velocity="1.0"/>',
        ModelError,
        ["robot.urdf", "joint 'waist_yaw' cannot move", "[0, 0]", "fixed joint"],
    ),
    (
        "negative wheel radius",
        "robot.toml",
        "wheel_radius = 0.08",
        "wheel_radius = -0.08",
        ConfigError,
        ["[base.wheel_radius]", "> 0"],
    ),
    (
        "wheel radius as a string",
        "robot.toml",
        "wheel_radius = 0.08",
        'wheel_radius = "8cm"',
        ConfigError,
        ["[base.wheel_radius]", "expected a number"],
    ),
    (
        "unknown base type",
        "robot.toml",
        'type = "mecanum"',
        'type = "tracked"',
        ConfigError,
        ["[base.type]", "'tracked'", "fixed, mecanum, differential, planar"],
    ),
    (
        "typo in a key",
        "robot.toml",
        "track = 0.44",
        "trak = 0.44",
        ConfigError,
        ["[base.trak]", "unknown key"],
    ),
    (
        "wheel that is not a joint",
        "robot.toml",
        '"wheel_rear_right"]\nwheel_radius',
        '"wheel_rear_rigth"]\nwheel_radius',
        ConfigError,
        ["[base.wheels]", "'wheel_rear_rigth' is not a joint", "did you mean 'wheel_rear_right'"],
    ),
    (
        "home outside the limits",
        "robot.toml",
        "left_elbow_flexion = 1.2",
        "left_elbow_flexion = 3.2",
        ConfigError,
        ["[home.left_elbow_flexion]", "outside"],
    ),
    (
        "home names an unknown joint",
        "robot.toml",
        "left_elbow_flexion = 1.2",
        "left_elbow = 1.2",
        ConfigError,
        ["[home.left_elbow]", "not a joint"],
    ),
    (
        "bad arm side",
        "robot.toml",
        'side = "left"',
        'side = "port"',
        ConfigError,
        ["[arms.left.side]", "'port'", "left, right"],
    ),
    (
        "arm names an undefined group",
        "robot.toml",
        'group = "left_arm"',
        'group = "larm"',
        ConfigError,
        ["[arms.left.group]", "unknown group 'larm'"],
    ),
    ("not TOML", "robot.toml", "[robot]\n", "[robot\n", ConfigError, ["not valid TOML"]),
    (
        "URDF mass NaN",
        "robot.urdf",
        '<mass value="40.0"/>',
        '<mass value="nan"/>',
        ModelError,
        ["<mass value>", "expected 1 finite numbers, got 'nan'"],
    ),
    (
        "URDF mass negative",
        "robot.urdf",
        '<mass value="40.0"/>',
        '<mass value="-4"/>',
        ModelError,
        ["mass -4 kg is negative"],
    ),
    (
        "URDF inertia inf",
        "robot.urdf",
        'ixx="0.5466666666666667"',
        'ixx="inf"',
        ModelError,
        ["<inertia ixx>"],
    ),
    (
        "URDF velocity negative",
        "robot.urdf",
        'effort="300.0" velocity="1.0"',
        'effort="300.0" velocity="-1"',
        ModelError,
        ["joint 'waist_pitch'", "<limit velocity> = -1 is negative"],
    ),
    (
        "URDF zero axis",
        "robot.urdf",
        '<origin xyz="0.0 0.377 0.0" rpy="0.0 -1.5707963267948966 '
        '-1.5707963267948966"/>\n    <axis xyz="0.0 0.0 1.0"/>',
        '<origin xyz="0.0 0.377 0.0" '
        'rpy="0.0 -1.5707963267948966 -1.5707963267948966"/>\n    <axis xyz="0 0 0"/>',
        ModelError,
        ["joint 'waist_yaw'", "<axis xyz> is zero"],
    ),
    (
        "URDF origin NaN",
        "robot.urdf",
        '<origin xyz="0.0 0.377 0.0"',
        '<origin xyz="0.0 nan 0.0"',
        ModelError,
        ["joint 'waist_yaw' <origin xyz>"],
    ),
    (
        "URDF not XML",
        "robot.urdf",
        "<robot name=",
        "<robot name=<",
        ModelError,
        ["robot.urdf", "not well-formed XML"],
    ),
    (
        "URDF with a dangling joint",
        "robot.urdf",
        '<parent link="chest"/><child link="head"/>',
        '<parent link="chesst"/><child link="head"/>',
        ModelError,
        ["robot.urdf", "Pinocchio cannot load"],
    ),
    (
        "multi-DOF joint below the root",
        "robot.urdf",
        '<joint name="head_mount" type="fixed">',
        '<joint name="head_mount" type="floating">',
        ModelError,
        ["robot.urdf", "'head_mount' has 6 DOF", "1-DOF joints"],
    ),
    (
        "wheel radius not the URDF's",
        "robot.toml",
        "wheel_radius = 0.08",
        "wheel_radius = 0.2",
        ConfigError,
        ["[base.wheel_radius]", "0.2 m", "'wheel_front_left' has a radius of 0.08 m"],
    ),
    (
        "mimic joint in a group",
        "robot.urdf",
        '<joint name="right_wrist_rotation" type="revolute">',
        '<joint name="right_wrist_rotation" type="revolute"><mimic joint="right_wrist_flexion"/>',
        ConfigError,
        ["[groups.right_arm]", "'right_wrist_rotation' is a mimic joint", "no velocity of u"],
    ),
    (
        "mimic of a fixed joint",
        "robot.urdf",
        '<joint name="right_wrist_rotation" type="revolute">',
        '<joint name="right_wrist_rotation" type="revolute"><mimic joint="head_mount"/>',
        ModelError,
        ["robot.urdf", "'right_wrist_rotation' mimics 'head_mount'", "not a moving joint"],
    ),
    (
        "locked pattern matching nothing",
        "robot.toml",
        "[home]",
        '[locked]\n"finger_*" = 0.0\n\n[home]',
        ConfigError,
        ["[locked.finger_*]", "matches no joint"],
    ),
    (
        "locked joint outside its limits",
        "robot.toml",
        "[home]",
        "[locked]\nleft_wrist_rotation = 3.0\n\n[home]",
        ConfigError,
        ["[locked]", "'left_wrist_rotation' locked at 3", "outside its limits"],
    ),
    (
        "locked joint still in a group",
        "robot.toml",
        "[home]",
        "[locked]\nleft_wrist_rotation = 0.0\n\n[home]",
        ConfigError,
        ["[groups.left_arm]", "'left_wrist_rotation' is locked"],
    ),
    (
        "declared frame on an unknown parent",
        "robot.toml",
        "[home]",
        '[frames.grip]\nparent = "left_hand_link"\n\n[home]',
        ConfigError,
        ["[frames.grip.parent]", "'left_hand_link' is no link or joint"],
    ),
    (
        "declared frame with the name of a link",
        "robot.toml",
        "[home]",
        '[frames.left_forearm]\nparent = "left_upper_arm"\n\n[home]',
        ConfigError,
        ["[frames.left_forearm]", "already has a frame 'left_forearm'"],
    ),
    (
        "declared frame with a short xyz",
        "robot.toml",
        "[home]",
        '[frames.grip]\nparent = "left_tool"\nxyz = [0.1, 0.0]\n\n[home]',
        ConfigError,
        ["[frames.grip.xyz]", "expected a list of 3 numbers"],
    ),
    (
        "arm segment list with an unknown link",
        "robot.toml",
        'forearm = "left_forearm"',
        'forearm = ["left_forearm", "left_fourarm"]',
        ConfigError,
        ["[arms.left.forearm]", "'left_fourarm' is not a link", "did you mean"],
    ),
    (
        "arm group not a string",
        "robot.toml",
        'group = "left_arm"',
        'group = ["left_arm"]',
        ConfigError,
        ["[arms.left.group]", "expected a non-empty string"],
    ),
    (
        "arm elbow on the other arm",
        "robot.toml",
        'elbow = "left_elbow_centre"',
        'elbow = "right_elbow_centre"',
        ConfigError,
        ["[arms.left.elbow]", "not below the shoulder", "one kinematic chain"],
    ),
    (
        "arm group of the other arm",
        "robot.toml",
        'group = "left_arm"',
        'group = "right_arm"',
        ConfigError,
        ["[arms.left.group]", "do not move the tool 'left_tool'", "'right_clavicle'"],
    ),
    (
        "upper arm body outside its segment",
        "robot.toml",
        'upper_arm = "left_upper_arm"',
        'upper_arm = "left_hand"',
        ConfigError,
        ["[arms.left.upper_arm]", "'left_hand' is not on the chain between the shoulder"],
    ),
    (
        "shoulder frame off the joint centre",
        "robot.toml",
        'shoulder = "left_shoulder_centre"',
        'shoulder = "left_clavicle"',
        ConfigError,
        ["[arms.left.elbow]", "shoulder-elbow distance changes with the posture"],
    ),
]


@pytest.mark.parametrize(
    ("file", "old", "new", "error", "parts"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_malformed_robot_is_rejected_with_a_precise_message(tmp_path, file, old, new, error, parts):
    d = copy_robot(tmp_path)
    edit(d / file, old, new)
    with pytest.raises(error) as info:
        wholebody.load_robot(d / "robot.toml")
    message = str(info.value)
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"
    if file == "robot.toml":
        assert str(d / "robot.toml") in message


def test_a_robot_toml_that_is_not_utf8_is_named(tmp_path):
    d = copy_robot(tmp_path)
    toml = d / "robot.toml"
    toml.write_bytes(toml.read_bytes() + "# café\n".encode("latin-1"))
    message = r"robot.toml: robot configuration is not UTF-8 text.*byte 0xe9"
    with pytest.raises(ConfigError, match=message):
        wholebody.load_robot(d)


def test_massless_arm_body_is_rejected(tmp_path):
    d = copy_robot(tmp_path)
    edit(d / "robot.toml", 'upper_arm = "left_upper_arm"', 'upper_arm = "left_tool"')
    with pytest.raises(ConfigError, match=r"\[arms.left.upper_arm\].*no mass"):
        wholebody.load_robot(d)


def test_unknown_robot_name_lists_the_bundled_ones():
    with pytest.raises(ConfigError, match="mobile_humanoid"):
        wholebody.load_robot("no_such_robot")
    with pytest.raises(ConfigError, match=r"no robot\.toml"):
        wholebody.load_robot(Path(__file__).parent)
    assert wholebody.load_robot(Path("dual_arm_torso")).name == "dual_arm_torso"  # a name


def test_unknown_names_suggest_or_list(humanoid):
    with pytest.raises(FrameError, match="did you mean 'left_tool'"):
        humanoid.frame("left_tol")
    with pytest.raises(FrameError, match=r"known: .*right_tool"):  # nothing close: the list
        humanoid.frame("nope")
    with pytest.raises(KeyError, match="no arm 'rigth' \\(did you mean 'right'"):
        humanoid.arms["rigth"]  # the README's idiom
    with pytest.raises(KeyError, match="no joint group 'wasit'"):
        humanoid.groups["wasit"]
    assert humanoid.groups.get("wasit") is None and "waist" in humanoid.groups


def test_fixed_base_torso_is_just_another_robot_toml(torso, rng):
    assert torso.nu == 15 and torso.base.type == "fixed"
    assert set(torso.arms) == {"left", "right"}
    assert torso.arms["left"].upper_arm_length == pytest.approx(0.30)
    assert torso.arms["left"].forearm_length == pytest.approx(0.25)
    q = torso.random_configuration(rng, margin=0.05)
    for f in ("left_tool", "right_elbow_centre"):
        np.testing.assert_allclose(
            torso.frame_jacobian(q, f), frame_jacobian_fd(torso, q, f), atol=2e-8
        )
    assert torso.joint_positions(torso.home())[torso.index("left_elbow")] == pytest.approx(1.0)


def test_planar_base_adds_three_virtual_actuators(tmp_path, rng):
    d = copy_robot(tmp_path, "dual_arm_torso")
    edit(d / "robot.toml", 'type = "fixed"', 'type = "planar"\nmax_linear_velocity = 0.8')
    r = wholebody.load_robot(d)
    assert r.nu == 18 and r.actuated_joints[:3] == ("base_vx", "base_vy", "base_wz")
    assert r.velocity_limits[0] == pytest.approx(0.8)
    q = r.random_configuration(rng, margin=0.05)
    np.testing.assert_allclose(
        r.frame_jacobian(q, "left_tool"), frame_jacobian_fd(r, q, "left_tool"), atol=2e-8
    )
    u = np.zeros(r.nu)
    u[0] = 0.5  # forward in the base frame
    yaw = r.base_pose(q)[2]
    moved = r.base_pose(r.integrate(q, u, 1.0)) - r.base_pose(q)
    np.testing.assert_allclose(moved[:2], 0.5 * np.array([np.cos(yaw), np.sin(yaw)]), atol=1e-12)


DIFF_DRIVE_URDF = """<?xml version="1.0"?>
<robot name="diff">
  <link name="base"><inertial><mass value="10"/><inertia ixx="1" iyy="1" izz="1" ixy="0"
    ixz="0" iyz="0"/></inertial></link>
  <link name="wl"/><link name="wr"/>
  <joint name="wheel_left" type="continuous"><parent link="base"/><child link="wl"/>
    <origin xyz="0 0.2 0.1"/><axis xyz="0 1 0"/><limit effort="1" velocity="10"/></joint>
  <joint name="wheel_right" type="continuous"><parent link="base"/><child link="wr"/>
    <origin xyz="0 -0.2 0.1"/><axis xyz="0 1 0"/><limit effort="1" velocity="10"/></joint>
  <link name="arm"><inertial><origin xyz="0.2 0 0"/><mass value="1"/><inertia ixx="0.1"
    iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="arm_yaw" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0.1 0 0.5"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <link name="tip"/>
  <joint name="tip_joint" type="fixed"><parent link="arm"/><child link="tip"/>
    <origin xyz="0.4 0 0"/></joint>
</robot>
"""


def test_differential_base(tmp_path, rng):
    (tmp_path / "robot.urdf").write_text(DIFF_DRIVE_URDF)
    (tmp_path / "robot.toml").write_text(
        'format = 1\n[robot]\nname = "diff"\nurdf = "robot.urdf"\n\n[base]\ntype = "differential"\n'
        'wheels = ["wheel_left", "wheel_right"]\nwheel_radius = 0.1\ntrack = 0.4\n'
    )
    r = wholebody.load_robot(tmp_path)
    assert r.nu == 3 and r.actuated_joints == ("wheel_left", "wheel_right", "arm_yaw")
    np.testing.assert_allclose(r.base.matrix, [[0.05, 0.05], [0, 0], [-0.25, 0.25]])
    q = r.random_configuration(rng)
    np.testing.assert_allclose(
        r.frame_jacobian(q, "tip"), frame_jacobian_fd(r, q, "tip"), atol=2e-8
    )
    # equal wheel speeds drive straight ahead; opposite ones turn in place
    yaw = r.base_pose(q)[2]
    ahead = r.base_pose(r.integrate(q, np.array([2.0, 2.0, 0.0]), 0.5)) - r.base_pose(q)
    np.testing.assert_allclose(ahead, [0.1 * np.cos(yaw), 0.1 * np.sin(yaw), 0.0], atol=1e-12)
    turn = r.base_pose(r.integrate(q, np.array([-2.0, 2.0, 0.0]), 0.5)) - r.base_pose(q)
    np.testing.assert_allclose(turn[:2], 0.0, atol=1e-12)
    assert turn[2] == pytest.approx(0.5, abs=1e-12)
    # a differential base whose track contradicts the URDF is rejected
    (tmp_path / "robot.toml").write_text(
        (tmp_path / "robot.toml").read_text().replace("track = 0.4", "track = 0.5")
    )
    with pytest.raises(ConfigError, match=r"\[base\].*'wheel_left'"):
        wholebody.load_robot(tmp_path)


def _diff_robot(tmp_path: Path, urdf: str) -> wholebody.Robot:
    (tmp_path / "robot.urdf").write_text(urdf)
    (tmp_path / "robot.toml").write_text(
        'format = 1\n[robot]\nname = "diff"\nurdf = "robot.urdf"\n\n[base]\ntype = "differential"\n'
        'wheels = ["wheel_left", "wheel_right"]\nwheel_radius = 0.1\ntrack = 0.4\n'
    )
    return wholebody.load_robot(tmp_path)


AXLE_BEHIND = [
    ('<origin xyz="0 0.2 0.1"/>', '<origin xyz="-0.3 0.2 0.1"/>'),
    ('<origin xyz="0 -0.2 0.1"/>', '<origin xyz="-0.3 -0.2 0.1"/>'),
]
RIGHT_AXIS_REVERSED = [
    (
        '<origin xyz="0 -0.2 0.1"/><axis xyz="0 1 0"/>',
        '<origin xyz="0 -0.2 0.1"/><axis xyz="0 -1 0"/>',
    )
]


@pytest.mark.parametrize(
    ("changes", "signs"),
    [([], (1.0, 1.0)), (AXLE_BEHIND, (1.0, 1.0)), (RIGHT_AXIS_REVERSED, (1.0, -1.0))],
    ids=["reference", "axle behind the origin", "right axis reversed"],
)
def test_differential_wheels_roll_without_slipping(tmp_path, rng, changes, signs):
    """Whatever the axle's place and the wheels' axis directions in the URDF, the base model
    moves every wheel centre straight ahead at r times its spin about its own joint axis (no
    slip, no sideways drag)."""
    urdf = DIFF_DRIVE_URDF
    for old, new in changes:
        assert old in urdf
        urdf = urdf.replace(old, new)
    r = _diff_robot(tmp_path, urdf)
    q = r.random_configuration(rng)
    u = rng.uniform(-3, 3, r.nu)
    state = r.update(q)
    R = state.rotation(r.base_frame)
    for k, (link, sign) in enumerate(zip(("wl", "wr"), signs, strict=True)):
        v = R.T @ (state.jacobian(r.frame(link)) @ u)[:3]  # wheel centre velocity, base axes
        np.testing.assert_allclose(v[1:], 0.0, atol=1e-12)  # no sideways or vertical speed
        # spinning by +w about +y rolls forward: v = r w, here w = sign * u_k
        assert v[0] == pytest.approx(0.1 * sign * u[k], abs=1e-12)


def test_differential_wheels_off_one_axle_or_axis_are_rejected(tmp_path):
    split = DIFF_DRIVE_URDF.replace('<origin xyz="0 0.2 0.1"/>', '<origin xyz="0.1 0.2 0.1"/>')
    with pytest.raises(ConfigError, match=r"share one axle.*'wheel_left' is at x=0\.1000"):
        _diff_robot(tmp_path, split)
    axis = '<axis xyz="0 1 0"/><limit effort="1" velocity="10"/>'
    upright = DIFF_DRIVE_URDF.replace(axis, axis.replace("0 1 0", "0 0 1"), 1)
    with pytest.raises(ConfigError, match=r"wheel 'wheel_left' turns about \(0, 0, 1\)"):
        _diff_robot(tmp_path, upright)


def test_a_mecanum_wheel_axis_reversed_in_the_urdf_reverses_its_speed(tmp_path, humanoid):
    d = copy_robot(tmp_path)
    front_left = '<origin xyz="0.25 0.22 0.08" rpy="0.0 0.0 0.0"/>\n    <axis xyz="0.0 1.0 0.0"/>'
    edit(d / "robot.urdf", front_left, front_left.replace("0.0 1.0 0.0", "0.0 -1.0 0.0"))
    r = wholebody.load_robot(d)
    expected = humanoid.base.matrix.copy()
    expected[:, 0] *= -1.0  # wheel_front_left: the same motion needs the opposite joint speed
    np.testing.assert_allclose(r.base.matrix, expected, atol=1e-15)


def endless_wrist(tmp_path: Path) -> wholebody.Robot:
    """The torso with its left wrist roll made a continuous joint (no limits)."""
    d = copy_robot(tmp_path, "dual_arm_torso")
    edit(
        d / "robot.urdf",
        '<joint name="left_wrist_roll" type="revolute">',
        '<joint name="left_wrist_roll" type="continuous">',
    )
    return wholebody.load_robot(d)


def test_an_endless_arm_joint_is_left_out_of_joint_limit_avoidance(tmp_path):
    from wholebody.presets import paper_objectives

    r = endless_wrist(tmp_path)
    h1 = {o.name: o for o in paper_objectives(r)}["joint_limits_arms"]
    arm = [r.index(j) for g in ("left_arm", "right_arm") for j in r.group(g).joints]
    assert sorted(h1.indices.tolist()) == sorted(set(arm) - {r.index("left_wrist_roll")})


def test_posture_error_of_an_endless_joint_is_wrapped(tmp_path):
    from wholebody.tasks import PostureTask

    r = endless_wrist(tmp_path)
    task = PostureTask(r, "left_arm")
    k = r.group("left_arm").joints.index("left_wrist_roll")
    target = task.target.copy()
    target[k] = -3.0
    task.set_target(target)
    state = r.update(r.configuration({"left_wrist_roll": 3.0}))
    e = task.error(state)
    assert e[k] == pytest.approx(2 * np.pi - 6.0)  # -3 - 3 = -6 rad: 0.28 rad the short way
    J, v = np.zeros((task.dim, r.nu)), np.zeros(task.dim)
    task.write_rows(state, J, v)
    np.testing.assert_allclose(v, task.kp * e)


def test_a_robot_loaded_from_its_own_directory_finds_its_network_there(tmp_path):
    """A user's robot keeps its trained network beside its robot.toml; the bundled one of
    the same name is not taken instead, and a missing one says where it was looked for."""
    from wholebody.arm.stiffness import ConstantStiffness
    from wholebody.errors import DataError
    from wholebody.humanlike import NetworkStiffness, default_stiffness
    from wholebody.presets import default_stiffness as preset

    d = tmp_path / "mobile_humanoid"
    shutil.copytree(robots_dir() / "mobile_humanoid", d)
    (d / "stiffness.npz").unlink()
    robot = wholebody.load_robot(d)
    assert isinstance(preset(robot), ConstantStiffness)  # not the bundled robot's network
    with pytest.raises(DataError, match=str(d / "stiffness.npz")):
        default_stiffness(robot)
    shutil.copy(robots_dir() / "mobile_humanoid" / "stiffness.npz", d / "own.npz")
    (d / "own.npz").rename(d / "stiffness.npz")
    assert isinstance(preset(robot), NetworkStiffness)
    assert isinstance(default_stiffness(robot), NetworkStiffness)


def test_a_joint_whose_range_excludes_zero_starts_at_its_nearer_limit(tmp_path):
    """neutral() (where scenarios start) and the joints [home] leaves out are valid states."""
    d = copy_robot(tmp_path, "dual_arm_torso")
    edit(d / "robot.urdf", '<limit lower="-0.05" upper="2.4"', '<limit lower="0.1" upper="2.4"')
    edit(d / "robot.toml", "left_elbow = 1.0\n", "")
    r = wholebody.load_robot(d)
    k = r.index("left_elbow")
    lower, upper = r.position_limits
    for q in (r.neutral(), r.home(), r.configuration({"torso_yaw": 0.2})):
        jp = r.joint_positions(q)
        assert jp[k] == pytest.approx(0.1)
        assert np.all(jp[r.positional] >= lower[r.positional])
        assert np.all(jp[r.positional] <= upper[r.positional])
    assert r.joint_positions(r.neutral())[r.index("torso_yaw")] == 0.0  # 0 where 0 is inside


def test_a_configuration_with_broken_cos_sin_pairs_is_rejected(humanoid):
    """np.zeros(nq) looks like "the zero configuration" but its base yaw and wheel angles are
    (cos, sin) = (0, 0): it gave a singular pose and, closed-loop, FAILED steps."""
    with pytest.raises(
        DimensionError, match=r"\(q\[2\], q\[3\]\) = \(0, 0\) is not a \(cos, sin\)"
    ):
        humanoid.frame_pose(np.zeros(humanoid.nq), "right_tool")
    q = humanoid.neutral()
    q[23:25] = (0.6, 0.6)  # a wheel's pair off the unit circle
    with pytest.raises(DimensionError, match=r"q\[23\], q\[24\]"):
        humanoid.check_configuration(q)
    humanoid.check_configuration(humanoid.random_configuration(np.random.default_rng(3)))


def test_the_stiffness_network_checks_its_input(humanoid):
    from wholebody.humanlike import default_stiffness

    model = default_stiffness(humanoid)
    k, _ = model.evaluate([0.25, 0.05, -0.25])  # a list is a position too
    assert k == pytest.approx(model.evaluate(np.array([0.25, 0.05, -0.25]))[0])
    with pytest.raises(DimensionError, match=r"\(3,\) array .* got shape \(2,\)"):
        model.evaluate(np.zeros(2))


def test_h1_of_a_group_named_like_one_of_its_joints(tmp_path):
    """A group "torso" holding the joint "torso" and an endless roll: h1 takes the joint
    only (the group's name used to bring the endless joint back in, and loading failed)."""
    from wholebody.presets import paper_objectives

    d = copy_robot(tmp_path, "dual_arm_torso")
    roll = '<joint name="right_wrist_roll" type="revolute">'
    urdf = (d / "robot.urdf").read_text().replace('"torso_yaw"', '"torso"')
    (d / "robot.urdf").write_text(urdf.replace(roll, roll.replace("revolute", "continuous")))
    edit(d / "robot.toml", 'torso = ["torso_yaw"]', 'torso = ["torso", "right_wrist_roll"]')
    edit(d / "robot.toml", '"right_wrist_pitch", "right_wrist_roll",', '"right_wrist_pitch",')
    r = wholebody.load_robot(d)
    h1 = {o.name: o for o in paper_objectives(r)}["joint_limits_body"]
    assert h1.indices.tolist() == [r.index("torso")]


def test_a_stiffness_read_back_from_a_file_is_a_number(humanoid):
    from wholebody.tasks import ArmPotentialEnergy

    energy = ArmPotentialEnergy(humanoid, "right", np.array(0.1))  # a 0-d array, as from .npz
    assert energy.stiffness.k == pytest.approx(0.1)


def test_a_link_and_a_joint_with_one_name_resolve_to_the_link(humanoid):
    """URDF allows it (the bundled robot has a link and a joint ``left_clavicle``); Pinocchio
    refuses an untyped lookup of such a name."""
    import pinocchio as pin

    frame = humanoid.frame("left_clavicle")
    assert humanoid.model.frames[frame.index].type == pin.FrameType.BODY
    assert humanoid.body("left_clavicle").mass > 0


def test_a_directory_without_robot_toml_does_not_hide_a_bundled_robot(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mobile_humanoid").mkdir()  # e.g. a scenario's output directory
    assert wholebody.load_robot("mobile_humanoid").nu == 23
    with pytest.raises(ConfigError, match=r"robot directory has no robot\.toml"):
        wholebody.load_robot(tmp_path / "mobile_humanoid")
    own = copy_robot(tmp_path / "mine")  # a directory with one is loaded, by path or by name
    monkeypatch.chdir(own.parent)
    assert wholebody.load_robot("mobile_humanoid").config.path.resolve() == own / "robot.toml"


def test_jacobian_derivatives_of_a_frame_on_a_wheel_are_refused(humanoid):
    from wholebody.tasks import Manipulability

    with pytest.raises(DimensionError, match="on the wheel 'wheel_front_left'"):
        Manipulability(humanoid, ["wheel_front_left_link"])


def test_a_robot_with_unbounded_joint_limits_loads_and_samples_finite_configurations(tmp_path):
    """Limits of +-1e308 are no limits: loading (which checks the arm lengths at random arm
    postures) overflowed in random_configuration."""
    d = copy_robot(tmp_path, "dual_arm_torso")
    edit(
        d / "robot.urdf",
        '<limit lower="-1.0" upper="3.0" effort="20.0" velocity="2.0"/>',
        '<limit lower="-1e308" upper="1e308" effort="20.0" velocity="2.0"/>',
    )
    robot = wholebody.load_robot(d)
    q = robot.random_configuration(np.random.default_rng(0))
    assert np.all(np.isfinite(q))
    j = robot.index("left_shoulder_pitch")
    assert -np.pi <= robot.joint_positions(q)[j] <= np.pi


def test_an_arm_group_with_a_joint_of_the_other_arm_names_that_joint(tmp_path):
    d = copy_robot(tmp_path, "dual_arm_torso")
    edit(d / "robot.toml", '"left_shoulder_yaw", "left_elbow",', '"left_shoulder_yaw",')
    edit(
        d / "robot.toml",
        '"right_shoulder_yaw", "right_elbow",',
        '"right_shoulder_yaw", "right_elbow", "left_elbow",',
    )
    with pytest.raises(ConfigError, match=r"\[arms.right.group\].*: 'left_elbow'$"):
        wholebody.load_robot(d)
