"""The whole-body centre of mass (RobotState.com_position() / com_jacobian() without a body):
the mass-weighted mean of every link of the URDF, its Jacobian in actuated coordinates
against finite differences, welded masses (a fixed base, locked joints) counted, and the
per-state cache."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from fdcheck import gradient_fd
from test_robot_building import MIMIC, NO_ROTATION, humanoid_copy

import wholebody
from wholebody.errors import WholebodyError
from wholebody.robot.urdf import example_robot_data_share

LOCK_RIGHT_WRIST = {
    '"right_wrist_flexion", "right_wrist_rotation",': "",
    '"right_clavicle", "right_shoulder_flexion", "right_shoulder_abduction",': '"right_clavicle", "right_shoulder_flexion", "right_shoulder_abduction",'  # noqa: E501
    '"right_forearm_rotation",',
    '"right_shoulder_rotation", "right_elbow_flexion", "right_forearm_rotation",': '"right_shoulder_rotation", "right_elbow_flexion",',  # noqa: E501
    "[home]": '[locked]\n"right_wrist_*" = 0.3\n\n[home]',
}
"""The humanoid's right wrist locked at 0.3 rad (test_robot_building's edit)."""


def com_jacobian_fd(robot: wholebody.Robot, q: np.ndarray) -> np.ndarray:
    """3 x nu central differences of the whole-body centre of mass along each ``u``."""
    return np.stack(
        [gradient_fd(robot, q, lambda x, i=i: robot.com_position(x)[i]) for i in range(3)]
    )


def link_mean(robot: wholebody.Robot, state) -> tuple[float, np.ndarray, np.ndarray]:
    """Total mass, mass-weighted mean of the links' centres and of their Jacobians, link by
    link of the URDF (Body.com in each link's frame)."""
    bodies = [robot.body(name) for name, (mass, _) in robot.urdf.links.items() if mass > 0]
    M = sum(b.mass for b in bodies)
    c = sum(b.mass * state.com_position(b) for b in bodies) / M
    J = sum(b.mass * state.com_jacobian(b) for b in bodies) / M
    return M, c, J


@pytest.fixture(params=["mobile_humanoid", "dual_arm_torso"])
def bundled(request, humanoid, torso) -> wholebody.Robot:
    return {"mobile_humanoid": humanoid, "dual_arm_torso": torso}[request.param]


def test_the_com_is_the_mass_weighted_mean_of_the_links(bundled, rng):
    """Every link counts, the torso's 20 kg root link (on Pinocchio's universe joint, which
    its centerOfMass leaves out) too."""
    robot = bundled
    for q in (robot.neutral(), robot.home(), *(robot.random_configuration(rng) for _ in range(4))):
        state = robot.update(q)
        M, c, J = link_mean(robot, state)
        assert robot.mass == pytest.approx(M, rel=1e-12)
        np.testing.assert_allclose(state.com_position(), c, atol=1e-12)
        np.testing.assert_allclose(state.com_jacobian(), J, atol=1e-12)
    if robot.name == "dual_arm_torso":  # the fixed root link, which Pinocchio leaves out
        root = robot.body(robot.urdf.root)
        assert root.mass > 0
        assert pin.computeTotalMass(robot.model) == pytest.approx(robot.mass - root.mass)


def test_the_com_jacobian_matches_finite_differences(bundled, rng):
    """Through the actuation map: the humanoid's wheel columns are Mecanum columns."""
    robot = bundled
    for q in (robot.home(), *(robot.random_configuration(rng) for _ in range(3))):
        J = robot.update(q).com_jacobian()
        assert J.shape == (3, robot.nu)
        np.testing.assert_allclose(J, com_jacobian_fd(robot, q), atol=1e-7)
    if robot.base.mobile:  # wheels move the whole mass: the base's twist moves the CoM
        wheels = [robot.index(w) for w in robot.base.wheel_joints]
        assert np.abs(J[:2, wheels]).max() > 0.01


@pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="example-robot-data is not installed (pip install '.[robots]')",
)
@pytest.mark.parametrize("name", ["talos_upper", "tiago_dual", "panda", "ur5"])
def test_real_robots_weigh_every_link(name, rng):
    """TALOS's pelvis and locked legs sit on the universe joint (welded to the world), TIAGo's
    casters and fingers are locked, the Panda's finger is a mimic joint: every link counts,
    and the Jacobian is exact."""
    robot = wholebody.load_robot(name)
    q = robot.random_configuration(rng, margin=0.05, base_range=0.5)
    state = robot.update(q)
    M, c, J = link_mean(robot, state)
    assert robot.mass == pytest.approx(M, rel=1e-12)
    np.testing.assert_allclose(state.com_position(), c, atol=1e-12)
    np.testing.assert_allclose(state.com_jacobian(), J, atol=1e-12)
    np.testing.assert_allclose(state.com_jacobian(), com_jacobian_fd(robot, q), atol=1e-7)


def test_locked_joints_keep_their_mass(tmp_path, humanoid, rng):
    """Welded by Pinocchio's reduced model, the wrist's links still weigh: the same mass and
    centre of mass as the full humanoid with the wrist at the locked position."""
    robot = humanoid_copy(tmp_path, LOCK_RIGHT_WRIST)
    assert set(robot.locked) == {"right_wrist_flexion", "right_wrist_rotation"}
    assert robot.mass == pytest.approx(humanoid.mass, rel=1e-12)
    for q in (robot.home(), *(robot.random_configuration(rng) for _ in range(3))):
        positions = robot.joint_positions(q)
        joints = {n: float(positions[k]) for k, n in enumerate(robot.actuated_joints)}
        full = humanoid.configuration({**joints, **robot.locked}, base_pose=robot.base_pose(q))
        state = robot.update(q)
        np.testing.assert_allclose(state.com_position(), humanoid.com_position(full), atol=1e-12)
        M, c, J = link_mean(robot, state)  # the wrist's links are still frames of the model
        assert robot.mass == pytest.approx(M, rel=1e-12)
        np.testing.assert_allclose(state.com_position(), c, atol=1e-12)
        np.testing.assert_allclose(state.com_jacobian(), J, atol=1e-12)
        np.testing.assert_allclose(state.com_jacobian(), com_jacobian_fd(robot, q), atol=1e-7)


def test_a_mimic_joint_moves_the_com_with_its_leader(tmp_path, rng):
    robot = humanoid_copy(tmp_path, NO_ROTATION, MIMIC)
    q = robot.random_configuration(rng)
    np.testing.assert_allclose(robot.update(q).com_jacobian(), com_jacobian_fd(robot, q), atol=1e-7)


def test_the_com_is_cached_per_state(humanoid, rng):
    """Computed once per state, read-only; an older state keeps its values, and a stale
    state that never computed it raises. Computing it leaves the joint Jacobians (which the
    compiled core reads in place) as they were."""
    robot = humanoid
    q1, q2 = robot.random_configuration(rng), robot.random_configuration(rng)
    s1 = robot.update(q1)
    J_joints = robot.data.J.copy()
    c1, J1 = s1.com_position(), s1.com_jacobian()
    assert np.array_equal(robot.data.J, J_joints)
    assert s1.com_position() is c1 and s1.com_jacobian() is J1
    assert not c1.flags.writeable and not J1.flags.writeable
    kept = c1.copy(), J1.copy()
    s2 = robot.update(q2)
    assert not np.allclose(s2.com_position(), kept[0])
    np.testing.assert_array_equal(s1.com_position(), kept[0])  # cached before s2
    np.testing.assert_array_equal(s1.com_jacobian(), kept[1])
    s3 = robot.update(q1)
    robot.update(q2)
    with pytest.raises(WholebodyError, match="stale"):
        s3.com_position()
    # the convenience method: a copy at q
    c = robot.com_position(q1)
    np.testing.assert_array_equal(c, kept[0])
    assert c.flags.writeable
