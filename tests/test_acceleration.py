"""Acceleration limits: ``[acceleration]`` of robot.toml, the box with its braking bound, and
closed loops on both backends in which no step changes a velocity by more than ``a dt``."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

import wholebody
from wholebody.control import Controller
from wholebody.errors import ConfigError
from wholebody.kernels.limits import braking_speed
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.presets import paper_stack
from wholebody.resources import robots_dir, tasks_dir
from wholebody.scenarios import load_scenario, run_scenario
from wholebody.solvers import ProjectionSolver
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import AccelerationLimits, FrameTask

DT = 0.01


def test_defaults_and_overrides_from_robot_toml(tmp_path, humanoid):
    a = humanoid.acceleration_limits
    wheels = [humanoid.index(w) for w in humanoid.base.wheel_joints]
    assert np.all(a[wheels] == 40.0) and a[humanoid.index("waist_yaw")] == 20.0
    d = tmp_path / "robot"
    shutil.copytree(robots_dir() / "mobile_humanoid", d)
    toml = d / "robot.toml"
    toml.write_text(
        toml.read_text() + "\n[acceleration]\njoints = 8.0\nwheels = 30.0\n"
        "waist = 2.0\nwaist_yaw = 1.5\n"
    )
    r = wholebody.load_robot(d)
    a = r.acceleration_limits
    assert np.all(a[wheels] == 30.0) and a[r.index("right_elbow_flexion")] == 8.0
    assert a[r.index("waist_pitch")] == 2.0 and a[r.index("waist_yaw")] == 1.5  # joint wins
    for bad, message in (
        ("waist = 0.0", "expected a number > 0"),
        ("wasit = 2.0", "not a group or joint of the robot"),
    ):
        toml.write_text(toml.read_text().split("[acceleration]")[0] + f"[acceleration]\n{bad}\n")
        with pytest.raises(ConfigError, match=message):
            wholebody.load_robot(d)


def _braking(d: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
    return np.array([braking_speed(di, ai, dt) for di, ai in zip(d, a, strict=True)])


def test_the_braking_bound_is_invariant_and_stops_at_the_limit(rng):
    a = rng.uniform(0.5, 50.0, 2000)
    d = rng.uniform(0.0, 1.0, 2000) ** 3
    v = _braking(d, a, DT)
    assert np.all(v >= 0) and np.all(v * DT <= d + 1e-15)  # one step never passes the limit
    after = _braking(d - v * DT, a, DT)
    assert np.all(after >= v - a * DT - 1e-12)  # braking at a per step is always allowed
    # and it is the largest such speed: braking from v, the distances sum to d
    np.testing.assert_allclose(v * DT + v**2 / (2 * a), d, rtol=1e-9, atol=1e-15)


def test_the_box_is_the_last_velocity_plus_minus_a_dt(humanoid, rng):
    limit = AccelerationLimits(humanoid, scale=0.5)
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.3))
    u = rng.uniform(-0.2, 0.2, humanoid.nu)
    limit.advance(u, DT)
    box = limit.bounds(state, DT)
    step = 0.5 * humanoid.acceleration_limits * DT
    assert np.all(box.lower <= u) and np.all(u <= box.upper)
    free = [humanoid.index(w) for w in humanoid.base.wheel_joints]  # no position limits
    np.testing.assert_allclose(box.upper[free] - u[free], step[free])
    np.testing.assert_allclose(u[free] - box.lower[free], step[free])
    assert np.all(box.upper - box.lower <= 2 * step + 1e-12)
    limit.reset()
    assert np.all(limit.bounds(state, DT).lower <= 0) and not np.any(limit.previous)


def fast_reach(robot, solver, acceleration: bool):
    """The right hand 40 cm forward and up in 0.6 s from rest: an abrupt start."""
    hand = FrameTask(robot, "right_tool", kp=20.0)
    q0 = robot.home()
    start = robot.frame_pose(q0, hand.frame)
    goal = start.copy()
    goal[:3, 3] += (0.3, 0.1, 0.25)
    stack = paper_stack(robot, [hand], stiffness=0.1, acceleration=acceleration)
    refs = {hand: MinimumJerkTrajectory(start, goal, 0.6)}
    return Controller(robot, stack, solver, dt=DT, references=refs).run(q0, 1.0)


@pytest.mark.parametrize(
    "solver", [ProjectionSolver(), HierarchicalQPSolver()], ids=["projection", "hqp"]
)
def test_no_step_changes_a_velocity_by_more_than_a_dt(humanoid, solver):
    a = humanoid.acceleration_limits
    free = fast_reach(humanoid, solver, acceleration=False)
    limited = fast_reach(humanoid, solver, acceleration=True)
    rate = lambda log: np.abs(np.diff(np.vstack([np.zeros(humanoid.nu), log.u]), axis=0)) / DT  # noqa: E731
    assert np.max(rate(free) / a) > 2.0  # the limits matter here
    assert np.max(rate(limited) / a) <= 1.0 + 1e-9
    err = np.linalg.norm(
        limited.frame_positions["right_tool"][-1] - free.frame_positions["right_tool"][-1]
    )
    assert err < 2e-3  # and the hand still gets there


@pytest.mark.parametrize("backend", ["projection", "hqp"])
def test_a_scenario_with_acceleration_limits_has_no_spike_across_its_phases(backend):
    spec = load_scenario(tasks_dir() / "obstacle_avoidance.toml")
    spec = dataclasses.replace(spec, stack=dataclasses.replace(spec.stack, acceleration=True))
    run = run_scenario(spec, backend=backend)
    robot = wholebody.load_robot(spec.robot)
    rate = np.abs(np.diff(run.log.u, axis=0)) / spec.dt
    assert np.max(rate / robot.acceleration_limits) <= 1.0 + 1e-9
    assert run.metrics["limit_violations"] == 0
    worst = max(v for hand in run.metrics["mae_m"].values() for v in hand.values())
    assert worst < 1e-3


def _goal(robot, index: int) -> list[np.ndarray]:
    """Target ``index`` of ``benchmarks/convergence.py --seed 0``."""
    rng = np.random.default_rng(0)
    for _ in range(index + 1):
        q = robot.random_configuration(rng, margin=0.05, base_range=0.5)
    return [robot.frame_pose(q, f) for f in ("left_tool", "right_tool")]


@pytest.mark.parametrize("index", [7, 27, 29])
def test_the_projection_reaches_far_targets_under_acceleration_limits(humanoid, index):
    """Step targets from home that the paper's stack reaches without acceleration limits: with
    them too (SNS in the acceleration window from rest scaled the hands by 0.001-0.005 and
    they crawled or oscillated), every velocity change within ``a dt``, the joints inside
    their ranges, the hands at rest at the end."""
    goal = _goal(humanoid, index)
    hands = [FrameTask(humanoid, f) for f in ("left_tool", "right_tool")]
    stack = paper_stack(humanoid, hands, acceleration=True)
    for hand, T in zip(hands, goal, strict=True):
        hand.set_target(T)
    log = Controller(humanoid, stack, ProjectionSolver(), dt=DT, recovery=False).run(
        humanoid.home(), 6.0
    )
    rate = np.abs(np.diff(np.vstack([np.zeros(humanoid.nu), log.u]), axis=0)) / DT
    assert np.max(rate / humanoid.acceleration_limits) <= 1.0 + 1e-9
    lo, hi = humanoid.position_limits
    jp = np.array([humanoid.joint_positions(q) for q in log.q])
    assert np.all(jp >= lo - 1e-9) and np.all(jp <= hi + 1e-9)
    for hand, T in zip(hands, goal, strict=True):
        p = log.frame_positions[hand.name]
        assert np.linalg.norm(p[-1] - T[:3, 3]) < 1e-3
        assert np.abs(np.diff(p[-50:], axis=0)).max() / DT < 1e-3  # settled, no oscillation


def _carry(robot, solver, acceleration: bool):
    """A closed chain between the hands on top, both hands carried 30 cm forward and 20 cm up
    as a step (they reach 1.4-2.7 m/s): the run and the chain's position error (m) per step."""
    from wholebody.solvers import Level, Stack
    from wholebody.tasks import JointPositionLimits, RelativeFrameTask, VelocityLimits

    q0 = robot.home()
    state = robot.update(q0)
    left, right = (FrameTask(robot, f) for f in ("left_tool", "right_tool"))
    chain = RelativeFrameTask(robot, "left_tool", "right_tool", name="chain")
    limits = [JointPositionLimits(robot), VelocityLimits(robot)]
    limits += [AccelerationLimits(robot)] if acceleration else []
    stack = Stack(robot, [Level([chain]), Level([left, right])], limits)
    for hand in (left, right):
        T = state.pose(hand.frame).copy()
        T[:3, 3] += [0.3, 0.0, 0.2]
        hand.set_target(T)
    log = Controller(robot, stack, solver, dt=DT, recovery=False).run(q0, 2.0)
    error = np.array([np.linalg.norm(chain.error(robot.update(q))[:3]) for q in log.q])
    return log, error, left


@pytest.mark.slow
def test_a_closed_chain_holds_under_acceleration_limits(humanoid):
    """The chain's rows are kept while the hands' level is scaled: its error (the drift of a
    velocity-level chain at these speeds, 1.6 mm without acceleration limits) stays below the
    HQP's on the same problem, and vanishes at the end; every velocity change within a dt."""
    log, error, left = _carry(humanoid, ProjectionSolver(), True)
    _, hqp_error, _ = _carry(humanoid, HierarchicalQPSolver(), True)
    rate = np.abs(np.diff(np.vstack([np.zeros(humanoid.nu), log.u]), axis=0)) / DT
    assert np.max(rate / humanoid.acceleration_limits) <= 1.0 + 1e-9
    assert error.max() <= hqp_error.max() and error[-1] < 1e-6, (error.max(), hqp_error.max())
    assert np.linalg.norm(log.frame_positions["left_tool"][-1] - left.target[:3, 3]) < 1e-3
