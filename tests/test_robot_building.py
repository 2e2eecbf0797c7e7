"""What a real robot's files need without edits: mimic joints moved by their leader, joints
locked out of the model, frames declared in robot.toml, arm segments over several links,
``package://`` paths, and a URDF whose extensions (transmissions) name joints too."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from fdcheck import frame_jacobian_fd

import wholebody
from wholebody.resources import robots_dir
from wholebody.robot.urdf import resolve_package
from wholebody.tasks import ArmPotentialEnergy


def humanoid_copy(
    tmp_path: Path, toml: dict[str, str] | None = None, urdf: dict[str, str] | None = None
) -> wholebody.Robot:
    """The bundled humanoid with text replacements in its robot.toml and URDF."""
    dst = tmp_path / "h"
    shutil.copytree(robots_dir() / "mobile_humanoid", dst)
    for name, edits in (("robot.toml", toml or {}), ("robot.urdf", urdf or {})):
        text = (dst / name).read_text()
        for old, new in edits.items():
            assert old in text, old
            text = text.replace(old, new, 1)
        (dst / name).write_text(text)
    return wholebody.load_robot(dst)


MIMIC = {
    '<joint name="right_wrist_rotation" type="revolute">': '<joint name="right_wrist_rotation" type="revolute">'  # noqa: E501
    '<mimic joint="right_wrist_flexion" multiplier="-0.5" offset="0.1"/>'
}
NO_ROTATION = {'"right_wrist_flexion", "right_wrist_rotation",': '"right_wrist_flexion",'}


def test_a_mimic_joint_moves_with_its_leader(tmp_path, humanoid, rng):
    robot = humanoid_copy(tmp_path, NO_ROTATION, MIMIC)
    assert robot.nu == humanoid.nu - 1 and "right_wrist_rotation" not in robot.actuated_joints
    k = robot.index("right_wrist_flexion")
    lead, follow = (
        robot.model.joints[robot.model.getJointId(n)].idx_q
        for n in ("right_wrist_flexion", "right_wrist_rotation")
    )
    for q in (
        robot.neutral(),
        robot.home(),
        robot.random_configuration(rng),
        robot.configuration({"right_wrist_flexion": 0.4}),
    ):
        assert q[follow] == pytest.approx(-0.5 * q[lead] + 0.1)
    q = robot.random_configuration(rng, margin=0.1)
    u = np.zeros(robot.nu)
    u[k] = 0.3
    q2 = robot.integrate(q, u, 0.1)
    assert q2[follow] - q[follow] == pytest.approx(-0.5 * 0.03)
    # the tool's Jacobian column of the leader includes the follower's motion
    J = robot.frame_jacobian(q, "right_tool")
    np.testing.assert_allclose(J, frame_jacobian_fd(robot, q, "right_tool"), atol=1e-6)
    # the follower's limits narrow the leader's: q_f in [-1.57, 1.57] <=> q_l in [-2.94, 3.34]
    lo, hi = robot.position_limits
    assert (lo[k], hi[k]) == (humanoid.position_limits[0][k], humanoid.position_limits[1][k])
    assert robot.velocity_limits[k] == min(humanoid.velocity_limits[k], 3.0 / 0.5)
    with pytest.raises(wholebody.FrameError, match="mimic joint: give its leader"):
        robot.configuration({"right_wrist_rotation": 0.2})


def test_a_fixed_joint_with_a_mimic_and_a_transmission_are_ignored(tmp_path, humanoid):
    fixed = '<joint name="head_mount" type="fixed">'
    robot = humanoid_copy(
        tmp_path,
        urdf={
            fixed: fixed + '<mimic joint="waist_yaw"/>',
            "</robot>": '<transmission name="t"><joint name="waist_yaw"><hardwareInterface>x'
            "</hardwareInterface></joint></transmission></robot>",
        },
    )
    assert robot.actuated_joints == humanoid.actuated_joints


def test_locked_joints_leave_u_and_hold_their_position(tmp_path, humanoid, rng):
    robot = humanoid_copy(
        tmp_path,
        {
            '"right_wrist_flexion", "right_wrist_rotation",': "",
            '"right_clavicle", "right_shoulder_flexion", "right_shoulder_abduction",': '"right_clavicle", "right_shoulder_flexion", "right_shoulder_abduction",'  # noqa: E501
            '"right_forearm_rotation",',  # (moved, so that the group stays valid)
            '"right_shoulder_rotation", "right_elbow_flexion", "right_forearm_rotation",': '"right_shoulder_rotation", "right_elbow_flexion",',  # noqa: E501
            "[home]": '[locked]\n"right_wrist_*" = 0.3\n\n[home]',
        },
    )
    assert robot.locked == {"right_wrist_flexion": 0.3, "right_wrist_rotation": 0.3}
    assert robot.nu == humanoid.nu - 2 and robot.model.nv == humanoid.model.nv - 2
    # the same kinematics as the full robot with those joints at 0.3
    q_full = humanoid.configuration(
        {"right_wrist_flexion": 0.3, "right_wrist_rotation": 0.3, "right_elbow_flexion": 1.1}
    )
    q = robot.configuration({"right_elbow_flexion": 1.1})
    np.testing.assert_allclose(
        robot.frame_pose(q, "right_tool"), humanoid.frame_pose(q_full, "right_tool"), atol=1e-12
    )
    q = robot.random_configuration(rng)
    np.testing.assert_allclose(
        robot.frame_jacobian(q, "right_tool"), frame_jacobian_fd(robot, q, "right_tool"), atol=1e-6
    )
    assert "locked: 2 joints" in robot.summary()


def test_a_locked_group_goes_with_its_joints(tmp_path, humanoid):
    robot = humanoid_copy(tmp_path, {"[home]": "[locked]\nwaist = 0.0\n\n[home]"})
    assert "waist" not in robot.groups and robot.nu == humanoid.nu - 3


def test_declared_frames_are_frames(tmp_path, humanoid, rng):
    robot = humanoid_copy(
        tmp_path,
        {
            "[home]": (
                '[frames.grip]\nparent = "right_tool"\nxyz = [0.05, 0.0, 0.02]\nrpy = [0.0, 0.0, 1.0]\n'  # noqa: E501
                '\n[frames.shoulder_mark]\nparent = "right_shoulder_flexion"\nxyz = [0.0, 0.1, 0.0]\n'  # noqa: E501
                "\n[home]"
            )
        },
    )
    q = robot.random_configuration(rng)
    T_tool, T = robot.frame_pose(q, "right_tool"), robot.frame_pose(q, "grip")
    local = np.linalg.inv(T_tool) @ T
    np.testing.assert_allclose(local[:3, 3], [0.05, 0.0, 0.02], atol=1e-12)
    np.testing.assert_allclose(
        local[:2, :2], [[np.cos(1), -np.sin(1)], [np.sin(1), np.cos(1)]], atol=1e-12
    )
    for name in ("grip", "shoulder_mark"):
        np.testing.assert_allclose(
            robot.frame_jacobian(q, name), frame_jacobian_fd(robot, q, name), atol=1e-6
        )


def test_an_arm_segment_over_two_links_adds_their_gravity(tmp_path, humanoid, rng):
    """The forearm of the left arm made of the forearm and the wrist link: the energy is the
    one-link energy plus g m h of the wrist link, its gradient matches finite differences."""
    robot = humanoid_copy(
        tmp_path, {'forearm = "left_forearm"': 'forearm = ["left_forearm", "left_wrist"]'}
    )
    assert [b.name for b in robot.arm("left").forearm_bodies] == ["left_forearm", "left_wrist"]
    one = ArmPotentialEnergy(humanoid, "left", 0.1)
    two = ArmPotentialEnergy(robot, "left", 0.1)
    wrist = robot.body("left_wrist")
    for _ in range(5):
        q = robot.random_configuration(rng, margin=0.1)
        s1 = humanoid.update(q)
        v1 = one.evaluate(s1).value
        s2 = robot.update(q)
        shoulder = s2.position(robot.arm("left").shoulder)[2]
        extra = two.g * wrist.mass * (s2.com_position(wrist)[2] - shoulder)
        v2 = two.evaluate(s2)
        assert v2.value == pytest.approx(v1 + extra, abs=1e-12)
        assert two.parts(robot.update(q))[1] == pytest.approx(one.parts(s1)[1] + extra)
        g_fd = np.empty(robot.nu)
        for k in range(robot.nu):
            du = np.zeros(robot.nu)
            du[k] = 1.0
            up = two.evaluate(robot.update(robot.integrate(q, du, 1e-6))).value
            down = two.evaluate(robot.update(robot.integrate(q, -du, 1e-6))).value
            g_fd[k] = (up - down) / 2e-6
        np.testing.assert_allclose(two.evaluate(robot.update(q)).gradient, g_fd, atol=1e-5)


def test_package_paths_resolve_through_the_search_path(tmp_path, monkeypatch):
    (tmp_path / "my_pkg" / "urdf").mkdir(parents=True)
    (tmp_path / "my_pkg" / "urdf" / "r.urdf").write_text("<robot/>")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path))
    assert resolve_package("package://my_pkg/urdf/r.urdf", []) == tmp_path / "my_pkg/urdf/r.urdf"
    with pytest.raises(FileNotFoundError, match="package 'other_pkg' not found"):
        resolve_package("package://other_pkg/r.urdf", [])
