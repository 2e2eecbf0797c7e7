"""The ROS node's logic without ROS: the state assembly, the command limiter, the input
checks, the period clock and a control core closed on an exact integration (the ROS
processes themselves: test_ros_nodes.py)."""

from __future__ import annotations

import math
import sys

import numpy as np
import pinocchio as pin
import pytest

import wholebody
from wholebody.cli import main
from wholebody.ros.core import ControlCore
from wholebody.ros.environment import ros_environment
from wholebody.ros.interface import velocity_order
from wholebody.ros.joint_state import StateAssembler
from wholebody.ros.safety import CommandLimiter, Reach, check_pose, check_twist
from wholebody.ros.simulated import SimulatedRobot
from wholebody.ros.stacks import default_stack
from wholebody.ros.timing import Metronome
from wholebody.scenarios.runner import make_solver


@pytest.fixture(scope="module")
def ur5() -> wholebody.Robot:
    from wholebody.robot.urdf import example_robot_data_share

    if example_robot_data_share() is None:
        pytest.skip("example-robot-data is not installed (pip install '.[robots]')")
    return wholebody.load_robot("ur5")


# ---------------------------------------------------------------------- state assembly
def _message(robot: wholebody.Robot, q: np.ndarray) -> tuple[list[str], list[float]]:
    jp = robot.joint_positions(q)
    return list(robot.actuated_joints), jp.tolist()


def test_state_is_q_of_the_message_and_ages(humanoid: wholebody.Robot, rng) -> None:
    asm = StateAssembler(humanoid)
    q = humanoid.random_configuration(rng, margin=0.1)
    assert asm.reading(0.0).q is None
    names, positions = _message(humanoid, q)
    assert asm.update_joints(names, positions, now=1.0, stamp=7) is None
    reading = asm.reading(1.0)
    assert reading.q is None and reading.missing == ("odometry",)  # a mobile base needs it
    x, y, yaw = humanoid.base_pose(q)
    assert asm.update_base(x, y, yaw, now=1.5) is None
    reading = asm.reading(2.0)
    np.testing.assert_allclose(reading.q, q, atol=1e-12)
    assert reading.age == pytest.approx(1.0)  # the oldest part: the joints at 1.0
    assert reading.stamp == 7 and reading.arrived == 1.0


def test_state_merges_partial_messages_and_ignores_unknown_joints(humanoid) -> None:
    asm = StateAssembler(humanoid)
    names, positions = _message(humanoid, humanoid.home())
    asm.update_base(0.0, 0.0, 0.0, now=0.0)
    asm.update_joints([*names[4:10], "gripper"], [*positions[4:10], 99.0], now=0.0)
    assert asm.reading(0.0).q is None  # the other joints never came
    assert asm.update_joints(names[10:], positions[10:], now=0.5) is None
    reading = asm.reading(0.5)  # the wheels are optional
    np.testing.assert_allclose(reading.q, humanoid.home(), atol=1e-12)
    assert reading.age == pytest.approx(0.5)


def test_bad_joint_states_are_refused_whole(humanoid) -> None:
    asm = StateAssembler(humanoid, tolerance=0.02)
    names, positions = _message(humanoid, humanoid.home())
    asm.update_base(0.0, 0.0, 0.0, now=0.0)
    assert asm.update_joints(names, positions, now=0.0) is None
    k = humanoid.index("left_elbow_flexion")
    upper = humanoid.position_limits[1][k]
    for bad, words in ((math.nan, "not finite"), (upper + 0.05, "outside its limits")):
        moved = list(positions)
        moved[k], moved[k - 1] = bad, positions[k - 1] + 0.1
        why = asm.update_joints(names, moved, now=1.0)
        assert why is not None and words in why and "left_elbow_flexion" in why
        reading = asm.reading(1.0)  # nothing of the message was kept, nor its time
        np.testing.assert_allclose(reading.q, humanoid.home(), atol=1e-12)
        assert reading.age == pytest.approx(1.0)
    near = list(positions)
    near[k] = upper + 0.01  # within the tolerance: clipped to the limit
    assert asm.update_joints(names, near, now=2.0) is None
    assert humanoid.joint_positions(asm.reading(2.0).q)[k] == upper
    assert "not finite" in asm.update_base(math.nan, 0.0, 0.0, now=2.0)


# ---------------------------------------------------------------------- limiter, checks
def test_limiter_keeps_every_command_inside_both_limits(rng) -> None:
    vmax, amax, dt = np.array([1.0, 2.0, 0.5]), np.array([10.0, 5.0, 20.0]), 0.01
    lim = CommandLimiter(vmax, amax, dt)
    previous = np.zeros(3)
    for _ in range(500):
        u, _ = lim.limit(rng.normal(0.0, 3.0, 3))
        assert np.all(np.abs(u) <= vmax + 1e-15)
        assert np.all(np.abs(u - previous) <= amax * dt + 1e-12)
        previous = u
    inside = previous + 0.5 * amax * dt * np.sign(-previous)
    u, clipped = lim.limit(inside)  # a command inside both passes unchanged
    assert not clipped and np.array_equal(u, inside)
    u, clipped = lim.limit(np.array([np.nan, 0.0, 0.0]))
    assert clipped and np.array_equal(u, np.zeros(3)) and np.array_equal(lim.last, np.zeros(3))


def test_pose_checks() -> None:
    reach, root = Reach(1.0, travel=0.5), np.zeros(3)
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 1.1)
    x, y, z, w = pin.Quaternion(R).coeffs()
    pose, why = check_pose("world", (0.5, 0.2, 0.3), (x, y, z, w), reach, root)
    assert why == "" and np.allclose(pose[:3, :3], R) and np.allclose(pose[:3, 3], (0.5, 0.2, 0.3))
    cases = {
        ("base_link", (0.5, 0.2, 0.3), (x, y, z, w)): "frame_id",
        ("odom", (np.nan, 0.2, 0.3), (x, y, z, w)): "not finite",
        ("world", (0.5, 0.2, 0.3), (x, y, z, 2 * w)): "norm",
        ("world", (1.4, 0.0, 0.95), (0.0, 0.0, 0.0, 1.0)): "out of reach",
    }
    for (frame, p, quat), words in cases.items():
        pose, why = check_pose(frame, p, quat, reach, root)
        assert pose is None and words in why
    # the base may drive 0.5 m: 1.4 m away in the plane is 0.9 m of reach
    assert check_pose("world", (1.4, 0.0, 0.3), (0, 0, 0, 1), reach, root)[1] == ""
    twist, why = check_twist("world", (0.1, 0, 0), (0, 0, 0.2), 1.0, 1.0)
    assert why == "" and np.allclose(twist, [0.1, 0, 0, 0, 0, 0.2])
    assert "too fast" in check_twist("world", (2.0, 0, 0), (0, 0, 0), 1.0, 1.0)[1]
    assert "not finite" in check_twist("world", (math.inf, 0, 0), (0, 0, 0), 1.0, 1.0)[1]


def test_metronome_counts_and_skips_missed_periods() -> None:
    t = [0.0]
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        t[0] += s

    m = Metronome(0.01, clock=lambda: t[0], sleep=sleep)
    assert m.wait() == 0.0
    t[0] += 0.002  # work within the period
    assert m.wait() == pytest.approx(0.01) and m.missed == 0
    t[0] += 0.025  # work overran two deadlines (0.02, 0.03): the next is 0.04
    assert m.wait() == pytest.approx(0.04) and m.missed == 2
    assert slept[-1] == pytest.approx(0.005)


# ---------------------------------------------------------------------- the core
def _send(core: ControlCore, robot: wholebody.Robot, q: np.ndarray, now: float) -> None:
    names, positions = _message(robot, q)
    core.on_joint_state(names, positions, now, stamp=round(now * 1e9))
    if robot.base.mobile:
        core.on_odometry(*robot.base_pose(q), now)


def test_core_waits_holds_reaches_refuses_and_stops(ur5) -> None:
    dt = 0.01
    core = ControlCore(ur5, default_stack(ur5, None, make_solver("projection")), dt)
    q = ur5.home()
    core.warm_up(q)
    assert core.tick(0.0).mode == "WAITING" and core.level() == "ERROR"
    _send(core, ur5, q, 0.0)
    tick = core.tick(0.0)
    assert tick.mode == "HOLDING" and not tick.u.any()  # no target: the robot stays put
    T = ur5.frame_pose(q, "tool0")
    goal = T[:3, 3] + (0.05, 0.03, -0.04)
    quat = pin.Quaternion(T[:3, :3]).coeffs()
    assert core.on_target("tool0", "world", goal, quat) is None
    why = core.on_target("tool0", "world", (math.nan, 0.0, 0.0), quat)
    assert (
        "not finite" in why and core.refused == 1 and "not finite" in core.report()["last refusal"]
    )
    commands = [np.zeros(ur5.nu)]
    for k in range(1, 150):
        _send(core, ur5, q, k * dt)
        tick = core.tick(k * dt)
        assert tick.mode == "RUNNING" and tick.stamp == round(k * dt * 1e9)
        commands.append(tick.u)
        q = ur5.integrate(q, tick.u, dt)
    assert np.linalg.norm(ur5.frame_pose(q, "tool0")[:3, 3] - goal) < 1e-3  # the NaN ignored
    u = np.array(commands)
    assert np.abs(u).max(axis=0).max() > 0.05  # it moved
    assert np.all(np.abs(u) <= ur5.velocity_limits + 1e-12)
    assert np.all(np.abs(np.diff(u, axis=0)) <= ur5.acceleration_limits * dt + 1e-9)
    assert core.level() == "WARN"  # the refusal is recent
    # the states stop: at most 3 more periods on the last one, then zero and STALE
    modes = [core.tick((149 + k) * dt + 1e-6) for k in range(1, 6)]
    assert [m.mode for m in modes] == ["RUNNING"] * 2 + ["STALE"] * 3
    assert all(not m.u.any() for m in modes[2:]) and core.level() == "STALE"


def test_core_runs_a_scenario_stack_with_the_hierarchical_qp(ur5) -> None:
    from wholebody.resources import tasks_dir
    from wholebody.ros.stacks import scenario_stack

    dt = 0.01
    node_stack = scenario_stack(ur5, tasks_dir() / "ur5_reach.toml", make_solver("hqp"), "hqp")
    assert list(node_stack.tasks) == ["tool0"] and node_stack.posture is None
    core = ControlCore(ur5, node_stack, dt)
    q = ur5.home()
    core.warm_up(q)
    T = ur5.frame_pose(q, "tool0")
    goal = T[:3, 3] + (-0.04, 0.05, 0.03)
    core.on_target("tool0", "odom", goal, pin.Quaternion(T[:3, :3]).coeffs())
    for k in range(150):
        _send(core, ur5, q, k * dt)
        q = ur5.integrate(q, core.tick(k * dt).u, dt)
    assert core.mode == "RUNNING" and core.report()["solver status"] in ("OK", "BOUNDS_ACTIVE")
    assert np.linalg.norm(ur5.frame_pose(q, "tool0")[:3, 3] - goal) < 1e-3


# ---------------------------------------------------------------------- the rest
def test_velocity_order_is_robot_toml_order(humanoid) -> None:
    order = velocity_order(humanoid)
    listed = [j for g in humanoid.config.groups.values() for j in g]
    assert order == list(dict.fromkeys(listed)) and sorted(order) == sorted(
        humanoid.actuated_joints
    )


def test_simulated_robot_integrates_named_and_ordered_commands(humanoid) -> None:
    sim = SimulatedRobot(humanoid, "kinematic", 0.01, command_timeout=0.05)
    q0 = sim.q.copy()
    k = humanoid.index("waist_yaw")
    assert sim.on_command(["waist_yaw", "unknown"], [0.5, 3.0], now=0.0) is None
    sim.step(0.0)
    assert humanoid.joint_positions(sim.q)[k] == pytest.approx(0.005)
    values = np.zeros(humanoid.nu)
    values[velocity_order(humanoid).index("waist_yaw")] = -0.5
    assert sim.on_array(values, now=0.01) is None
    sim.step(0.01)
    np.testing.assert_allclose(sim.q, q0, atol=1e-12)
    sim.on_command(["waist_yaw"], [0.5], now=0.02)
    sim.step(0.1)  # no command for longer than the timeout: it stays
    np.testing.assert_allclose(sim.q, q0, atol=1e-12)
    assert "not finite" in sim.on_command(["waist_yaw"], [math.nan], now=0.2)
    assert "expected 23" in sim.on_array([0.0], now=0.2)


def test_discovery_stays_on_this_host_unless_set() -> None:
    assert ros_environment({})["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert ros_environment(env)["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"


def test_ros_commands_without_the_extra_say_what_to_install(monkeypatch, capsys) -> None:
    monkeypatch.setitem(sys.modules, "rclpy", None)  # import rclpy raises ImportError
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    for command in (["ros", "ur5"], ["ros-sim", "ur5"]):
        assert main(command) == 2
        assert "pip install 'wholebody[ros]'" in capsys.readouterr().err


def test_the_guides_controller_yaml_is_tiago_dual_joint_order() -> None:
    from pathlib import Path

    from wholebody.robot.urdf import example_robot_data_share
    from wholebody.ros.interface import controller_yaml

    if example_robot_data_share() is None:
        pytest.skip("example-robot-data is not installed (pip install '.[robots]')")
    readme = (Path(__file__).resolve().parents[1] / "docs" / "guides" / "ros.md").read_text()
    block = readme.split("<!-- ros:tiago_dual controller -->\n```yaml\n", 1)[1].split("```")[0]
    tiago = wholebody.load_robot("tiago_dual")
    assert block == controller_yaml(tiago)
    joints = [line.strip()[2:] for line in block.splitlines() if line.strip().startswith("- ")]
    assert joints == velocity_order(tiago) and sorted(joints) == sorted(tiago.actuated_joints)


def test_state_keeps_mimic_joints_with_their_leader() -> None:
    from wholebody.robot.urdf import example_robot_data_share

    if example_robot_data_share() is None:
        pytest.skip("example-robot-data is not installed (pip install '.[robots]')")
    panda = wholebody.load_robot("panda")  # its second finger mimics the first
    q = panda.random_configuration(np.random.default_rng(3), margin=0.1)
    asm = StateAssembler(panda)
    assert asm.update_joints(*_message(panda, q), now=0.0) is None
    np.testing.assert_allclose(asm.reading(0.0).q, q, atol=1e-12)


def test_phase_lock_brings_the_deadlines_just_after_the_states() -> None:
    from wholebody.ros.timing import phase_error

    T, lead = 0.01, 0.002
    assert phase_error(0.0305, 0.0300, T, lead) == pytest.approx(0.0025)  # come 2.5 ms later
    assert phase_error(0.0299, 0.0300, T, lead) == pytest.approx(0.0019)
    assert phase_error(0.0250, 0.0300, T, lead) == pytest.approx(-0.003)  # 3 ms earlier
    # states every T at phase 7.3 ms, the loop from phase 0: locked within 30 periods
    t = [0.0]
    m = Metronome(T, clock=lambda: t[0], sleep=lambda s: t.__setitem__(0, t[0] + s))
    for _ in range(40):
        deadline = m.wait()
        arrived = math.floor((deadline - 0.0073) / T) * T + 0.0073  # the newest state
        m.shift(0.2 * phase_error(arrived, deadline, T, lead))
    assert (deadline - arrived) == pytest.approx(lead, abs=1e-4) and m.missed == 0
