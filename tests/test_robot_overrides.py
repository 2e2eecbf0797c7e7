"""robot.toml over the URDF: ``[joints]`` overrides a joint's type and limits without an edit
of the URDF (checked, with clear errors), and ``[base] height`` places the root link above the
floor for kinematics, collision, drawing geometry, the MuJoCo plant and a scenario run."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import wholebody
from wholebody import ConfigError, ModelError
from wholebody.resources import robots_dir


def copy_robot(tmp_path: Path, name: str = "mobile_humanoid") -> Path:
    dst = tmp_path / name
    shutil.copytree(robots_dir() / name, dst)
    return dst


def edit(path: Path, old: str, new: str, count: int = 1) -> None:
    text = path.read_text()
    assert old in text, f"fixture text {old!r} not found in {path.name}"
    path.write_text(text.replace(old, new, count))


def append(path: Path, text: str) -> None:
    path.write_text(path.read_text() + "\n" + text)


def revolute_wheels(d: Path) -> None:
    """The URDF fault of the issue: wheels declared revolute without lower and upper."""
    edit(d / "robot.urdf", 'type="continuous"', 'type="revolute"', count=-1)


def test_a_wheel_declared_revolute_without_limits_is_made_continuous(tmp_path):
    """As the URDF says, the wheels' range is [0, 0] and the robot does not load; one
    [joints] table makes them continuous, and the robot is the shipped one."""
    d = copy_robot(tmp_path)
    revolute_wheels(d)
    urdf = (d / "robot.urdf").read_text()
    hint = r"'wheel_front_left' cannot move.*\[joints.wheel_front_left\].*\"continuous\""
    with pytest.raises(ModelError, match=hint):  # the message says how to fix it
        wholebody.load_robot(d)
    append(d / "robot.toml", '[joints."wheel_*"]\ntype = "continuous"\n')
    robot, shipped = wholebody.load_robot(d), wholebody.load_robot("mobile_humanoid")
    assert (d / "robot.urdf").read_text() == urdf  # the URDF file is not written
    assert robot.nq == shipped.nq and robot.nu == shipped.nu
    np.testing.assert_array_equal(robot.actuation, shipped.actuation)
    q = robot.home()
    np.testing.assert_allclose(robot.frame_pose(q, "left_tool"), shipped.frame_pose(q, "left_tool"))


def test_limits_are_overridden_where_given_and_the_urdfs_kept_elsewhere(tmp_path):
    d = copy_robot(tmp_path)
    append(
        d / "robot.toml", "[joints.left_elbow_flexion]\nupper = 1.5\nvelocity = 0.5\neffort = 7.5\n"
    )
    robot, shipped = wholebody.load_robot(d), wholebody.load_robot("mobile_humanoid")
    k = robot.index("left_elbow_flexion")
    lower, upper = robot.position_limits
    assert upper[k] == 1.5 and lower[k] == shipped.position_limits[0][k]
    assert robot.velocity_limits[k] == 0.5
    j = robot.model.joints[robot.model.getJointId("left_elbow_flexion")]
    assert robot.model.effortLimit[j.idx_v] == 7.5
    other = robot.index("right_elbow_flexion")
    assert upper[other] == shipped.position_limits[1][other]


@pytest.mark.parametrize(
    ("table", "key", "words"),
    [
        (
            "[joints.left_elbow_flexon]\nupper = 1.0\n",
            "joints.left_elbow_flexon",
            "matches no joint of robot.urdf (did you mean 'left_elbow_flexion'",
        ),
        (
            '[joints.left_tool_joint]\ntype = "continuous"\n',
            "joints.left_tool_joint",
            "is fixed in the URDF",
        ),
        (
            "[joints.left_elbow_flexion]\nvelocity = -1.0\n",
            "joints.left_elbow_flexion.velocity",
            "expected a number > 0",
        ),
        (
            "[joints.left_elbow_flexion]\nlower = 1.0\nupper = 0.5\n",
            "joints.left_elbow_flexion",
            "lower = 1 must be below upper = 0.5",
        ),
        (
            "[joints.left_elbow_flexion]\nlower = 3.0\n",
            "joints.left_elbow_flexion",
            "would have the range [3, 2.53]",
        ),
        (
            '[joints.left_elbow_flexion]\ntype = "continuous"\nupper = 1.0\n',
            "joints.left_elbow_flexion",
            "a continuous joint turns without position limits",
        ),
        (
            '[joints.left_elbow_flexion]\ntype = "ball"\n',
            "joints.left_elbow_flexion.type",
            "expected one of",
        ),
        (
            "[joints.left_elbow_flexion]\nlimit = 1.0\n",
            "joints.left_elbow_flexion.limit",
            "unknown key",
        ),
        ("[joints.left_elbow_flexion]\n", "joints.left_elbow_flexion", "expected a table of"),
    ],
)
def test_bad_joint_overrides_are_named(tmp_path, table, key, words):
    d = copy_robot(tmp_path)
    append(d / "robot.toml", table)
    with pytest.raises(ConfigError) as info:
        wholebody.load_robot(d)
    text = " ".join(str(info.value).split())
    assert f"[{key}]" in text and words in text, text


HEIGHT = 0.69  # m: the pelvis height of the robot


def raised(tmp_path: Path, name: str, base: str) -> wholebody.Robot:
    """A bundled robot with ``height = HEIGHT`` under its [base] line ``base``."""
    d = copy_robot(tmp_path, name)
    edit(d / "robot.toml", base, f"{base}\nheight = {HEIGHT}")
    return wholebody.load_robot(d)


@pytest.mark.parametrize(
    ("name", "base"),
    [("mobile_humanoid", 'type = "mecanum"'), ("dual_arm_torso", 'type = "fixed"')],
)
def test_the_base_height_raises_every_frame_shape_and_the_centre_of_mass(tmp_path, rng, name, base):
    """At any configuration every frame, the centre of mass and every drawn and collision
    shape are HEIGHT higher, and the Jacobians are the same."""
    robot, ground = raised(tmp_path, name, base), wholebody.load_robot(name)
    up = np.array([0.0, 0.0, HEIGHT])
    for q in (robot.home(), robot.random_configuration(rng)):
        a, b = robot.update(q), ground.update(q)
        for f in (robot.urdf.root, *(arm.tool.name for arm in robot.arms.values())):
            np.testing.assert_allclose(
                a.position(robot.frame(f)), b.position(ground.frame(f)) + up, atol=1e-12
            )
            np.testing.assert_allclose(
                a.jacobian(robot.frame(f)), b.jacobian(ground.frame(f)), atol=1e-12
            )
        np.testing.assert_allclose(robot.com_position(q), ground.com_position(q) + up, atol=1e-12)
        for kind in ("visual", "collision"):
            (ga, _), (gb, _) = robot.geometry(kind), ground.geometry(kind)
            da, db = ga.createData(), gb.createData()
            pin.updateGeometryPlacements(robot.model, robot.data, ga, da)
            pin.updateGeometryPlacements(ground.model, ground.data, gb, db)
            for ma, mb in zip(da.oMg, db.oMg, strict=True):
                np.testing.assert_allclose(ma.translation, mb.translation + up, atol=1e-12)


def test_the_base_height_moves_the_collision_distances_with_the_robot(tmp_path):
    """An obstacle raised with the robot is as far from it as before."""
    from wholebody.collision import CollisionModel, Obstacle

    robot = raised(tmp_path, "mobile_humanoid", 'type = "mecanum"')
    ground = wholebody.load_robot("mobile_humanoid")

    def nearest(r: wholebody.Robot, z: float) -> float:
        pose = np.eye(4)
        pose[:3, 3] = (0.6, -0.2, 0.9 + z)
        model = CollisionModel(r, [Obstacle("ball", "sphere", (0.05,), pose)], self_collision=False)
        return min(p.distance for p in model.distances(r.update(r.home())))

    assert nearest(robot, HEIGHT) == pytest.approx(nearest(ground, 0.0), abs=1e-9)
    assert nearest(robot, 0.0) != pytest.approx(nearest(ground, 0.0), abs=1e-3)


def test_the_mujoco_plant_places_the_raised_root(tmp_path):
    """Every body of the MuJoCo model is where Pinocchio puts its joint (HEIGHT up)."""
    mujoco = pytest.importorskip("mujoco")
    from wholebody.sim.world import build_world

    robot = raised(tmp_path, "mobile_humanoid", 'type = "mecanum"')
    world = build_world(robot)
    data = mujoco.MjData(world.model)
    mujoco.mj_forward(world.model, data)
    pin.forwardKinematics(robot.model, robot.data, robot.neutral())
    for j in range(1, robot.model.njoints):
        body = world.model.body(robot.model.names[j]).id
        np.testing.assert_allclose(data.xpos[body], robot.data.oMi[j].translation, atol=1e-9)
    root = world.model.body(robot.model.names[1]).id
    assert data.xpos[root][2] == pytest.approx(HEIGHT)


SCENARIO = """
format = 2
[scenario]
name = "raised"
robot = "{robot}"
backend = "pinv"
rate_hz = 100.0
[stack]
stiffness = 0.1
acceleration = false
[hands.right]
frame = "right_tool"
[[phases]]
name = "reach"
duration = 0.3
[phases.hands.right]
planner = "min_jerk"
goal = [0.45, -0.3, {z}]
"""


def test_a_scenario_run_of_a_raised_robot_is_the_same_run_raised(tmp_path):
    """The goal HEIGHT higher: the raised humanoid's hand moves as the shipped one's,
    HEIGHT higher, with the same joint motion."""
    from wholebody.scenarios import load_scenario, run_scenario

    raised(tmp_path, "mobile_humanoid", 'type = "mecanum"')
    runs = []
    shipped, mine = robots_dir() / "mobile_humanoid", tmp_path / "mobile_humanoid"
    for robot, z in ((shipped, 0.8), (mine, 0.8 + HEIGHT)):
        path = tmp_path / f"s{len(runs)}.toml"
        path.write_text(SCENARIO.format(robot=robot, z=z))
        runs.append(run_scenario(load_scenario(path)).log)
    np.testing.assert_allclose(runs[1].u, runs[0].u, atol=1e-9)
    hands = [run.frame_positions["right"] for run in runs]
    np.testing.assert_allclose(hands[1], hands[0] + [0, 0, HEIGHT], atol=1e-9)
