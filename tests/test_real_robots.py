"""Real robots as they ship in example-robot-data (``pip install '.[robots]'``):
TIAGo++, TALOS's upper body, Panda and UR5 load from their own URDFs through their
robot.toml, with exact Jacobians, and their scenarios track within a millimetre on both
backends without a limit violation."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import frame_jacobian_fd

import wholebody
from wholebody.cli import main
from wholebody.robot import robot_catalogue
from wholebody.robot.urdf import example_robot_data_share

pytestmark = pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="example-robot-data is not installed (pip install '.[robots]' from the checkout)",
)

# name: (actuated velocities, velocities of the URDF as shipped, tool frames)
ROBOTS = {
    "tiago_dual": (19, 101, ("arm_left_tool_link", "arm_right_tool_link")),
    "talos_upper": (18, 32, ("gripper_left_base_link", "gripper_right_base_link")),
    "panda": (8, 9, ("panda_hand_tcp",)),
    "ur5": (6, 6, ("tool0",)),
}


@pytest.mark.parametrize("name", ROBOTS)
def test_a_shipped_robot_loads_with_exact_jacobians(name, rng):
    nu, shipped, tools = ROBOTS[name]
    robot = wholebody.load_robot(name)
    full = robot._built.full
    assert robot.nu == nu
    assert full.nv - (3 if robot.base.mobile else 0) == shipped
    for _ in range(3):
        q = robot.random_configuration(rng, margin=0.05, base_range=0.5)
        for tool in tools:
            np.testing.assert_allclose(
                robot.frame_jacobian(q, tool), frame_jacobian_fd(robot, q, tool), atol=1e-6
            )
    for arm in robot.arms.values():  # the arm chain's joint centres: fixed lengths
        assert 0.2 < arm.upper_arm_length < 0.5 and 0.2 < arm.forearm_length < 0.5


def test_tiago_wheels_below_locked_suspensions_drive_the_base(rng):
    """The wheels hang from suspension joints in the URDF; locked, they drive the base like
    any differential base: equal speeds move it forward at r w, opposite ones turn it."""
    robot = wholebody.load_robot("tiago_dual")
    assert robot.base.type == "differential" and robot.base.wheel_joints == (
        "wheel_left_joint",
        "wheel_right_joint",
    )
    q = robot.home()
    u = np.zeros(robot.nu)
    u[:2] = 1.0
    x, y, yaw = robot.base_pose(robot.integrate(q, u, 0.1))
    assert x == pytest.approx(0.1 * 0.0985) and y == pytest.approx(0.0) and yaw == 0.0
    u[:2] = -1.0, 1.0
    assert robot.base_pose(robot.integrate(q, u, 0.1))[2] == pytest.approx(
        0.1 * 2 * 0.0985 / 0.4044
    )


def test_panda_fingers_move_together():
    robot = wholebody.load_robot("panda")
    q = robot.home()
    model = robot.model
    f1, f2 = (model.joints[model.getJointId(f"panda_finger_joint{i}")].idx_q for i in (1, 2))
    assert q[f1] == q[f2] == pytest.approx(0.02)
    u = np.zeros(robot.nu)
    u[robot.index("panda_finger_joint1")] = 0.1
    q2 = robot.integrate(q, u, 0.1)
    assert q2[f1] == q2[f2] == pytest.approx(0.03)


def test_the_catalogue_marks_robots_whose_package_is_missing(monkeypatch, capsys):
    import wholebody.robot.urdf as urdf

    assert all(available for _, _, available in robot_catalogue())
    monkeypatch.setattr(urdf, "example_robot_data_share", lambda: None)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    status = {name: (available, text) for name, text, available in robot_catalogue()}
    assert status["mobile_humanoid"][0]
    assert not status["tiago_dual"][0]
    assert "pip install '.[robots]' from the checkout" in status["tiago_dual"][1]
    assert main(["info", "--list"]) == 0
    out = capsys.readouterr().out
    assert "tiago_dual" in out and "unavailable" in out
    with pytest.raises(wholebody.ConfigError, match=r"pip install .\.\[robots\]."):
        wholebody.load_robot("panda")


SCENARIOS = {
    "tiago_dual_reach": "tiago_dual",
    "tiago_dual_carry": "tiago_dual",
    "talos_upper_reach": "talos_upper",
    "panda_reach": "panda",
    "ur5_reach": "ur5",
}


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["projection", "hqp"])
@pytest.mark.parametrize("name", SCENARIOS)
def test_a_shipped_robots_scenario_tracks_within_a_millimetre(name, backend):
    """From the robot's home posture (the scenarios' default start): every hand within 1 mm
    of its reference on every step, no limit violated, the closed chain within 1 mm."""
    from wholebody.cli import _scenario_path
    from wholebody.scenarios import load_scenario, run_scenario

    run = run_scenario(load_scenario(_scenario_path(name)), backend=backend)
    m = run.metrics
    assert max(m["max_tracking_error_m"].values()) < 1e-3, m["max_tracking_error_m"]
    assert m["limit_violations"] == 0 and m["solver_failures"] == 0
    assert m["closed_chain_error_max_m"] < 1e-3
    assert all(end["reached"] for end in m["final_error"].values()), m["final_error"]
    # every hand met on every step, but the carry's, whose absolute rows yield to the
    # closed chain above them (by design)
    assert set(m["unmet_steps"]) <= ({"priority"} if name == "tiago_dual_carry" else set())
    np.testing.assert_array_equal(run.log.q[0], wholebody.load_robot(SCENARIOS[name]).home())
    if name == "tiago_dual_carry":  # the carry is longer than the arms: the base drives
        assert np.linalg.norm(run.log.q[-1][:2] - run.log.q[0][:2]) > 0.3
