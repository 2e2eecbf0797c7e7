"""A swerve base (``[base] type = "swerve"``): Centauro as example-robot-data ships it
(``robots/centauro``), its legs locked straight on four steered wheels.

* the base is commanded by its twist (three virtual actuators); the steering and drive
  joints stay in the model, out of ``u``, and no command moves them;
* the module map (:func:`~wholebody.robot.swerve.module_commands`) gives each wheel the
  velocity the base twist gives its centre (finite differences of the model's wheel frames),
  the least-squares reconstruction recovers the twist, a reversed twist flips the wheel
  speeds rather than turning the modules, and the steering limits are kept;
* a hand target beyond the arm's reach is reached on both backends, the base driving.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import wholebody
from wholebody.errors import ConfigError, DimensionError
from wholebody.robot.swerve import SwerveModule, module_commands, module_twist
from wholebody.robot.urdf import example_robot_data_share
from wholebody.solvers import ProjectionSolver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import FrameTask, JointPositionLimits, PostureTask, VelocityLimits

pytestmark = pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="example-robot-data is not installed (pip install '.[robots]' from the checkout)",
)

STEERING = tuple(f"ankle_yaw_{i}" for i in range(1, 5))
DRIVES = tuple(f"j_wheel_{i}" for i in range(1, 5))


@pytest.fixture(scope="module")
def centauro() -> wholebody.Robot:
    return wholebody.load_robot("centauro")


def test_centauro_is_a_swerve_base_commanded_by_its_twist(centauro):
    assert centauro.base.type == "swerve" and len(centauro.swerve) == 4
    assert "ankle_yaw_1/j_wheel_1 at (0.2500, 0.2224) m" in centauro.summary()
    assert centauro.actuated_joints[:3] == ("base_vx", "base_vy", "base_wz")
    assert centauro.nu == 16 and not set(STEERING + DRIVES) & set(centauro.actuated_joints)
    for m in centauro.swerve:  # the legs straight under the hips, the wheels 0.124 m
        assert (abs(m.x), abs(m.y), m.radius) == pytest.approx((0.25, 0.2224, 0.124), abs=1e-4)
    model = centauro.model
    held = [model.joints[model.getJointId(j)].idx_v for j in STEERING + DRIVES]
    assert not np.any(centauro.actuation[held])  # no entry of u moves them
    q = centauro.home()
    moved = centauro.integrate(q, np.full(centauro.nu, 0.3), 1.0)
    idx_q = [model.joints[model.getJointId(j)].idx_q for j in STEERING]
    np.testing.assert_array_equal(moved[idx_q], q[idx_q])


def _wheel_velocities(robot: wholebody.Robot, twist: np.ndarray, eps: float = 1e-6):
    """Per module, the velocity (m/s, base frame, xy) of its wheel's centre when the base
    moves by ``twist``: central differences of the wheel frames' positions."""
    q = robot.home()
    u = np.zeros(robot.nu)
    u[:3] = twist
    plus, minus = robot.integrate(q, u, eps), robot.integrate(q, u, -eps)
    out = []
    for m in robot.swerve:
        frame = robot.frame(m.drive)
        d = robot.frame_pose(plus, frame)[:3, 3] - robot.frame_pose(minus, frame)[:3, 3]
        out.append(d[:2] / (2 * eps))  # the base is at the origin, facing x: world = base
    return np.array(out)


def test_the_module_map_gives_each_wheel_its_velocity_and_inverts(centauro, rng):
    for _ in range(20):
        twist = rng.uniform([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5])
        now = rng.uniform(-1.0, 1.0, 4)
        angles, speeds = module_commands(centauro.swerve, twist, now)
        for m, a in zip(centauro.swerve, angles, strict=True):
            assert m.lower <= a <= m.upper
        assert np.all(np.abs(angles - now) <= math.pi / 2 + 1e-12)  # never a turn beyond 90
        phi = [m.heading + m.sign * a for m, a in zip(centauro.swerve, angles, strict=True)]
        rolled = (speeds * 0.124)[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
        np.testing.assert_allclose(rolled, _wheel_velocities(centauro, twist), atol=1e-8)
        np.testing.assert_allclose(module_twist(centauro.swerve, angles, speeds), twist, atol=1e-12)


def test_a_reversed_twist_flips_the_wheels_not_the_modules(centauro):
    twist = np.array([0.3, 0.1, 0.2])
    angles, speeds = module_commands(centauro.swerve, twist, np.zeros(4))
    back, reverse = module_commands(centauro.swerve, -twist, angles)
    np.testing.assert_allclose(back, angles, atol=1e-12)
    np.testing.assert_allclose(reverse, -speeds, atol=1e-12)
    held, still = module_commands(centauro.swerve, np.zeros(3), angles)  # at rest: kept
    np.testing.assert_array_equal(held, angles)
    np.testing.assert_array_equal(still, 0.0)


def test_a_steering_limit_is_kept_or_refused():
    narrow = SwerveModule("s", "d", 0.0, 0.0, 0.1, 1.0, 0.0, -0.5, 2.0)
    # heading 100 deg: 1.745 rad is inside; its reverse, -1.396, is not
    angles, speeds = module_commands([narrow], (math.cos(1.745), math.sin(1.745), 0.0), [-0.4])
    assert angles[0] == pytest.approx(1.745) and speeds[0] == pytest.approx(10.0)
    with pytest.raises(DimensionError, match="no steering angle"):  # -2.6 and 0.54 outside
        module_commands(
            [SwerveModule("s", "d", 0, 0, 0.1, 1.0, 0.0, -0.5, 0.5)],
            (math.cos(-2.6), math.sin(-2.6), 0.0),
            [0.0],
        )


@pytest.mark.parametrize(
    ("edits", "match"),
    [
        (
            {
                '"hip_*" = 0.0': '"hip_yaw_*" = 0.0\n"hip_pitch_[234]" = 0.0',
                '"ankle_yaw_1"': '"hip_pitch_1"',
            },
            "axis must be vertical",
        ),
        ({'"ankle_yaw_1"': '"torso_yaw"'}, "must be below the steering joint"),
        ({"0.124 }": "0.2 }"}, "radius of 0.124 m"),
        ({'"ankle_yaw_1"': '"knee_pitch_1"'}, "not a moving joint"),
    ],
)
def test_a_module_that_is_no_steered_wheel_is_an_error(tmp_path, edits, match):
    from wholebody.resources import robots_dir

    text = (robots_dir() / "centauro" / "robot.toml").read_text()
    for old, new in edits.items():
        text = text.replace(old, new, 1)
    (tmp_path / "robot.toml").write_text(text)
    with pytest.raises(ConfigError, match=r"base\.modules\[0\]") as error:
        wholebody.load_robot(tmp_path)
    assert match in str(error.value)


@pytest.mark.parametrize("solver", [ProjectionSolver, HierarchicalQPSolver])
def test_the_swerve_base_drives_a_reach(centauro, solver):
    """A hand target 0.8 m ahead and 0.3 m aside of the hand: the base drives, the hand
    reaches it, no limit is violated, and every twist the controller sent has module
    commands inside the steering limits."""
    q0 = centauro.home()
    hand = FrameTask(centauro, "ball1_tip", kp=2.0)
    goal = centauro.frame_pose(q0, "ball1_tip").copy()
    goal[:3, 3] += [0.8, 0.3, 0.0]
    hand.set_target(goal)
    stack = Stack(
        centauro,
        [[hand], [PostureTask(centauro)]],
        [JointPositionLimits(centauro), VelocityLimits(centauro)],
    )
    log = wholebody.Controller(centauro, stack, solver(), dt=0.02).run(q0, 6.0)
    q = log.q[-1]
    assert np.linalg.norm(centauro.frame_pose(q, "ball1_tip")[:3, 3] - goal[:3, 3]) < 1e-3
    assert np.linalg.norm(q[:2] - q0[:2]) > 0.3  # the base drove
    lower, upper = centauro.position_limits
    jp = np.array([centauro.joint_positions(qq) for qq in log.q])
    assert np.all(jp >= lower) and np.all(jp <= upper)
    angles = np.zeros(4)
    for u in log.u:
        angles, speeds = module_commands(centauro.swerve, u[:3], angles)
        np.testing.assert_allclose(module_twist(centauro.swerve, angles, speeds), u[:3], atol=1e-12)


def test_the_swerve_base_drives_under_physics(centauro):
    """In MuJoCo the base is the planar servo of a twist-commanded base; the held steering
    and drive joints, whose URDF gives them no range, are joints without limits there that
    no command moves."""
    pytest.importorskip("mujoco")
    from wholebody.sim import MujocoPlant

    plant = MujocoPlant(centauro, settings=centauro.sim_settings)
    q = centauro.home()
    plant.reset(q)
    u = np.zeros(centauro.nu)
    u[0] = 0.2  # m/s forward
    for _ in range(50):
        q = plant.step(q, u, 0.02)
    assert plant.stop_reason is None
    assert q[0] == pytest.approx(0.2 * 1.0, abs=0.01) and abs(q[1]) < 1e-3
    model = centauro.model
    steering = [model.joints[model.getJointId(j)].idx_q for j in STEERING]
    np.testing.assert_allclose(q[steering], 0.0, atol=1e-3)
