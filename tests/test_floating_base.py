"""A floating base (``[base] type = "floating"``): TALOS full body as example-robot-data ships
it (``robots/talos_full``), its pelvis a free flyer with six virtual actuators.

* it loads standing (the soles on the floor), its Jacobians and their derivatives equal
  finite differences on the manifold, its base reads back as (x, y, z, roll, pitch, yaw);
* with the soles held by 6-D frame tasks at the top level, both backends reach with both
  hands while the soles stay within 1e-6 m and rad and no joint leaves its limits;
* in MuJoCo (the base a free joint that nothing drives), TALOS stands on its soles while its
  hands reach, when tasks also hold its centre of mass over its feet and its pelvis upright
  (without them it falls: with one hand reaching 0.15 m the kinematic solution moves the
  pelvis 12 cm and the centre of mass 9 cm forward, out over the toes).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from fdcheck import frame_jacobian_fd, jacobian_fd

import wholebody
from wholebody.errors import ConfigError, DimensionError
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.robot.hessian import actuated_support_mask, frame_hessian
from wholebody.robot.urdf import example_robot_data_share
from wholebody.solvers import ProjectionSolver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import ComTask, FrameTask, JointPositionLimits, PostureTask, VelocityLimits

pytestmark = pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="example-robot-data is not installed (pip install '.[robots]' from the checkout)",
)

SOLES = ("left_sole_link", "right_sole_link")
HANDS = ("gripper_left_base_link", "gripper_right_base_link")
DT = 0.01


@pytest.fixture(scope="module")
def talos() -> wholebody.Robot:
    return wholebody.load_robot("talos_full")


def test_talos_loads_standing_on_its_soles(talos):
    assert talos.base.type == "floating" and talos.base.floating
    assert talos.actuated_joints[:6] == (
        "base_vx",
        "base_vy",
        "base_vz",
        "base_wx",
        "base_wy",
        "base_wz",
    )
    assert (talos.nq, talos.nv, talos.nu) == (37, 36, 36)
    np.testing.assert_array_equal(talos.actuation, np.eye(36))
    np.testing.assert_array_equal(talos.velocity_limits[:6], 1.0)  # the [base] defaults
    np.testing.assert_array_equal(talos.acceleration_limits[:6], [2, 2, 2, 4, 4, 4])
    for q in (talos.home(), talos.neutral()):
        state = talos.update(q)
        soles = [state.position(talos.frame(s))[2] for s in SOLES]
        assert soles == pytest.approx([0.0, 0.0], abs=1e-12)
        lowest = min(M.translation[2] for M in talos.data.oMf[1:])
        assert lowest == pytest.approx(0.0, abs=1e-12)
    # TALOS's SRDF puts its half-sitting pelvis 1.01927 m up: the home posture is that one
    assert talos.home()[2] == pytest.approx(1.01927, abs=1e-5)


def test_floating_jacobians_equal_finite_differences_on_the_manifold(talos, rng):
    mask = actuated_support_mask(talos)
    hand = talos.frame(HANDS[1])
    for _ in range(2):
        q = talos.random_configuration(rng, margin=0.1, base_range=0.5)
        q[3:7] = pin.Quaternion(pin.exp3(rng.uniform(-0.5, 0.5, 3))).coeffs()  # tilted too
        for frame in (*SOLES, HANDS[0], "head_2_link"):
            np.testing.assert_allclose(
                talos.frame_jacobian(q, frame), frame_jacobian_fd(talos, q, frame), atol=1e-6
            )
        np.testing.assert_allclose(
            talos.update(q).com_jacobian(),
            jacobian_fd(talos, q, lambda s: s.com_position()),
            atol=1e-6,
        )
        H = frame_hessian(talos.update(q), hand, mask)
        np.testing.assert_allclose(H, jacobian_fd(talos, q, lambda s: s.jacobian(hand)), atol=1e-6)


def test_the_base_moves_in_its_own_frame_and_reads_back_as_roll_pitch_yaw(talos, rng):
    q = talos.configuration(base_pose=(0.3, -0.2, 1.0))
    u = np.zeros(talos.nu)
    u[0] = 0.5  # base_vx: forward along the base's x, which points at yaw 1.0
    moved = talos.integrate(q, u, 1.0)
    np.testing.assert_allclose(
        moved[:3] - q[:3], [0.5 * np.cos(1.0), 0.5 * np.sin(1.0), 0.0], atol=1e-12
    )
    np.testing.assert_allclose(talos.base_pose(q), (0.3, -0.2, 1.0), atol=1e-12)
    near = [pin.rpy.rpyToMatrix(0.3, s * (np.pi / 2 - 1e-4), -0.2) for s in (1, -1)]
    for R in [pin.exp3(rng.uniform(-3, 3, 3)) for _ in range(20)] + near:
        q[3:7] = pin.Quaternion(R).coeffs()
        jp = talos.joint_positions(q)
        np.testing.assert_allclose(jp[:3], q[:3])
        np.testing.assert_allclose(jp[3:6], pin.rpy.matrixToRpy(R), atol=1e-9)
    for pitch in (np.pi / 2, -np.pi / 2):  # at the singularity: roll 0, the heading in yaw
        R = pin.rpy.rpyToMatrix(0.3, pitch, -0.2)
        q[3:7] = pin.Quaternion(R).coeffs()
        jp = talos.joint_positions(q)
        assert jp[3] == 0.0
        np.testing.assert_allclose(pin.rpy.rpyToMatrix(*jp[3:6]), R, atol=1e-7)


def test_a_floating_configuration_needs_a_unit_quaternion(talos):
    q = talos.home()
    q[3:7] = 0.0, 0.0, 0.0, 0.9
    with pytest.raises(DimensionError, match="unit quaternion"):
        talos.update(q)


def test_the_default_posture_leaves_the_floating_base_free(talos):
    posture = PostureTask(talos)
    assert posture.dim == talos.nu - 6
    assert 0 not in posture.indices and talos.index("leg_left_1_joint") in posture.indices


def test_a_floating_base_takes_only_its_velocity_limits(tmp_path):
    (tmp_path / "robot.toml").write_text(
        'format = 1\n[robot]\nname = "x"\nurdf = "package://example-robot-data/robots/'
        'talos_data/robots/talos_full_v2.urdf"\n[base]\ntype = "floating"\nwheels = ["a"]\n'
    )
    with pytest.raises(ConfigError, match="wheels"):
        wholebody.load_robot(tmp_path)


def _stand_and_reach(robot: wholebody.Robot, extra_levels=(), feet_kp: float = 1.0 / DT):
    """The soles held where they are at home (6-D, top level, gain ``feet_kp``), then
    ``extra_levels``, both
    hands along minimum-jerk lines to goals 0.15 m ahead, posture last; the references, the
    goals and the soles' poses."""
    state = robot.update(robot.home())
    feet = [FrameTask(robot, s, kp=feet_kp) for s in SOLES]
    soles = {t.name: state.pose(t.frame).copy() for t in feet}
    for t in feet:
        t.set_target(soles[t.name])
    hands = [FrameTask(robot, h, kp=10.0) for h in HANDS]
    references, goals = {}, {}
    for t, offset in zip(hands, ([0.15, 0.1, 0.05], [0.15, -0.1, 0.1]), strict=True):
        start = state.pose(t.frame).copy()
        goals[t.name] = start.copy()
        goals[t.name][:3, 3] += offset
        references[t] = MinimumJerkTrajectory(start, goals[t.name], 2.0)
    stack = Stack(
        robot,
        [feet, *extra_levels, hands, [PostureTask(robot)]],
        [JointPositionLimits(robot), VelocityLimits(robot)],
    )
    return stack, references, goals, soles


def _sole_error(robot, q, soles) -> float:
    """The larger of the soles' displacement (m) and rotation (rad) from their poses."""
    state = robot.update(q)
    worst = 0.0
    for name, P in soles.items():
        T = state.pose(robot.frame(name))
        worst = max(
            worst,
            np.abs(T[:3, 3] - P[:3, 3]).max(),
            np.linalg.norm(pin.log3(T[:3, :3] @ P[:3, :3].T)),
        )
    return worst


@pytest.mark.parametrize("solver", [ProjectionSolver, HierarchicalQPSolver])
def test_both_backends_reach_with_the_soles_held(talos, solver):
    stack, references, goals, soles = _stand_and_reach(talos)
    log = wholebody.Controller(talos, stack, solver(), dt=DT, references=references).run(
        talos.home(), 2.5
    )
    assert max(_sole_error(talos, q, soles) for q in log.q) < 1e-6
    state = talos.update(log.q[-1])
    for name, goal in goals.items():
        assert np.linalg.norm(state.position(talos.frame(name)) - goal[:3, 3]) < 1e-5
    lower, upper = talos.position_limits
    jp = np.array([talos.joint_positions(q) for q in log.q])
    assert np.all(jp >= lower) and np.all(jp <= upper)
    assert abs(log.q[-1][2] - log.q[0][2]) > 1e-3  # the pelvis moved: the base was solved for


def test_the_centre_of_mass_task_has_the_jacobian_of_its_error(talos, rng):
    q = talos.random_configuration(rng, margin=0.1)
    com = ComTask(talos, "xz", target=[0.1, 0.2, 0.9], kp=2.0)
    rows = com.compute(talos.update(q))
    np.testing.assert_allclose(rows.J, -jacobian_fd(talos, q, com.error), atol=1e-6)
    np.testing.assert_allclose(rows.v, 2.0 * com.error(talos.update(q)))
    home = ComTask(talos, "xz").target  # the default: the centre of mass at home
    np.testing.assert_allclose(
        com.error(talos.update(talos.home())), [0.1 - home[0], 0.9 - home[2]]
    )
    with pytest.raises(DimensionError, match="axes"):
        ComTask(talos, "xw")


@pytest.mark.slow
def test_talos_stands_in_mujoco_while_its_hands_reach(talos):
    """The free joint is not driven; the joints' servos (robot.toml ``[sim] servo_hz = 10``)
    with the contacts' force fed forward hold TALOS on its soles through 2.5 s of the reach,
    with its centre of mass held over the feet and its pelvis upright below the soles (as
    measured: pelvis tilt <= 1.0 deg, height within 2.2 mm of the kinematic run's, soles slid
    <= 7.3 mm and lifted <= 2.2 mm, hands 2.4 and 2.5 cm short of their goals at the end)."""
    pytest.importorskip("mujoco")
    from wholebody.sim import MujocoPlant

    q0 = talos.home()
    state = talos.update(q0)
    pelvis = FrameTask(talos, talos.base_frame, position=False, kp=5.0)
    pelvis.set_target(state.pose(talos.base_frame).copy())
    level = [ComTask(talos, "xy", kp=5.0), pelvis]
    stack, references, goals, soles = _stand_and_reach(talos, [level], feet_kp=10.0)
    kinematic = wholebody.Controller(
        talos, stack, ProjectionSolver(), dt=DT, references=references
    ).run(q0, 2.5)
    plant = MujocoPlant(talos, settings=talos.sim_settings)
    plant.reset(q0)
    log = wholebody.Controller(
        talos, stack, ProjectionSolver(), dt=DT, references=references, plant=plant
    ).run(q0, 2.5)
    assert plant.stop_reason is None and len(log.q) == 250
    assert np.array(plant.log.torque_peak)[:, :6].max() == 0.0  # nothing drives the base
    for q, q_kinematic in zip(log.q, kinematic.q, strict=True):
        assert abs(q[2] - q_kinematic[2]) < 5e-3
        state = talos.update(q)
        assert state.rotation(talos.base_frame)[2, 2] > np.cos(np.radians(2.0))
        for name, P in soles.items():
            p = state.position(talos.frame(name))
            assert np.linalg.norm(p[:2] - P[:2, 3]) < 0.015 and p[2] < 5e-3
    state = talos.update(log.q[-1])
    for name, goal in goals.items():
        assert np.linalg.norm(state.position(talos.frame(name)) - goal[:3, 3]) < 0.05
