"""The closed loop: the paper's single-arm reach, the comparison with the plain pseudo-inverse,
and the run log."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from wholebody import WholebodyError
from wholebody.control import Controller, RunLog, summary
from wholebody.control.log import concatenate
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.presets import paper_stack
from wholebody.solvers import ProjectionSolver
from wholebody.tasks import ArmPotentialEnergy, FrameTask

SHELF_TARGET = np.array([1.701, -0.45675, 0.46133])  # m, the paper's object B


def reach(robot, objectives: bool):
    """Right hand from its initial pose to the shelf object in 5 s at 100 Hz, the hand turned
    to point forward; the same metric and limits with and without the objectives."""
    hand = FrameTask(robot, "right_tool", kp=20.0, ki=5.0)
    q0 = robot.neutral()
    start = robot.frame_pose(q0, hand.frame)
    goal = start.copy()
    goal[:3, 3] = SHELF_TARGET
    goal[:3, :3] = pin.exp3(np.array([0.0, -np.pi / 2, 0.0])) @ start[:3, :3]
    stack = paper_stack(robot, [hand], objectives=objectives, stiffness=0.1)
    monitors = [ArmPotentialEnergy(robot, arm, 0.1) for arm in ("left", "right")]
    controller = Controller(
        robot,
        stack,
        ProjectionSolver(),
        dt=0.01,
        references={hand: MinimumJerkTrajectory(start, goal, 5.0)},
        monitors=monitors,
    )
    return controller.run(q0, 5.0)


@pytest.fixture(scope="module")
def runs(humanoid):
    return {"paper": reach(humanoid, True), "pinv": reach(humanoid, False)}


def test_single_arm_reach_tracks_within_a_millimetre(runs):
    m = summary(runs["paper"])
    assert m["steps"] == 500
    for axis, mae in m["mae_m"]["right_tool"].items():
        assert mae <= 1e-3, f"MAE {axis} = {mae * 1e3:.3f} mm"
    final = runs["paper"].frame_positions["right_tool"][-1]
    assert np.linalg.norm(final - SHELF_TARGET) < 2e-3
    assert m["limit_violations"] == 0 and m["solver_failures"] == 0


def test_energy_objective_moves_more_arm_and_less_waist_than_the_pseudo_inverse(runs):
    paper, pinv = summary(runs["paper"]), summary(runs["pinv"])
    assert (
        paper["arm_energy_j"]["right"]["gravity_final"]
        < pinv["arm_energy_j"]["right"]["gravity_final"]
    )
    assert paper["joint_travel_rad"]["waist"] < pinv["joint_travel_rad"]["waist"]
    # the arm angle stays in a human range where it is defined (paper: mostly 0-0.8 rad)
    assert paper["arm_angle_rad"]["right"]["min"] >= 0.0
    assert paper["arm_angle_rad"]["right"]["max"] < 1.2


def test_monitored_energies_are_the_objective_at_every_logged_configuration(humanoid, runs):
    """With the energies in the stack the log takes the solve's own values; without them
    (the pseudo-inverse run) the monitor evaluates them: both are the objective's value."""
    monitors = [ArmPotentialEnergy(humanoid, arm, 0.1) for arm in ("left", "right")]
    for log in runs.values():
        for k in range(0, 500, 37):
            state = humanoid.update(log.q[k])
            for m in monitors:
                v, trace = m.evaluate(state), log.arms[m.arm.name]
                logged = np.array(dataclasses.astuple(trace))[:, k]
                expected = [v.value, v.gravity, v.spring, v.arm_angle, v.stiffness, v.rho]
                np.testing.assert_allclose(logged, expected, rtol=0, atol=1e-12)


def test_run_log_round_trip(runs, tmp_path):
    log = runs["paper"]
    path = log.save(tmp_path / "run.npz")
    back = RunLog.load(path)
    for name in ("t", "q", "u", "joint_positions", "step_time", "status", "level_residuals"):
        np.testing.assert_array_equal(getattr(back, name), getattr(log, name))
    np.testing.assert_array_equal(back.arms["right"].arm_angle, log.arms["right"].arm_angle)
    np.testing.assert_array_equal(
        back.frame_positions["right_tool"], log.frame_positions["right_tool"]
    )
    assert back.meta == log.meta
    assert summary(back) == summary(log)
    with np.load(path, allow_pickle=False) as z:  # no pickle in the file
        assert "meta" in z.files


def test_controller_rejects_bad_setups(humanoid):
    hand = FrameTask(humanoid, "right_tool")
    other = FrameTask(humanoid, "left_tool")
    stack = paper_stack(humanoid, [hand], objectives=False)
    traj = MinimumJerkTrajectory(np.eye(4), np.eye(4), 1.0)
    with pytest.raises(WholebodyError, match="not in the stack"):
        Controller(humanoid, stack, ProjectionSolver(), dt=0.01, references={other: traj})
    with pytest.raises(WholebodyError, match="dt"):
        Controller(humanoid, stack, ProjectionSolver(), dt=0.0)
    with pytest.raises(WholebodyError, match="shorter than one step"):
        Controller(humanoid, stack, ProjectionSolver(), dt=0.01).run(humanoid.neutral(), 0.001)


def test_summary_of_logs_joined_with_an_unmonitored_run(humanoid):
    """concatenate() pads an arm a run did not monitor with NaN: the summary reads the
    monitored rows."""
    hand = FrameTask(humanoid, "right_tool", kp=20.0)
    q0 = humanoid.neutral()
    start = humanoid.frame_pose(q0, hand.frame)
    goal = start.copy()
    goal[:3, 3] += (0.05, 0.0, 0.0)
    stack = paper_stack(humanoid, [hand], stiffness=0.1)
    monitors = [ArmPotentialEnergy(humanoid, arm, 0.1) for arm in ("left", "right")]
    moving = {hand: MinimumJerkTrajectory(start, goal, 0.2)}
    holding = {hand: MinimumJerkTrajectory(goal, goal, 0.1)}
    first = Controller(
        humanoid, stack, ProjectionSolver(), dt=0.01, monitors=monitors, references=moving
    ).run(q0, 0.2)
    second = Controller(humanoid, stack, ProjectionSolver(), dt=0.01, references=holding).run(
        np.array(first.meta["final_q"]), 0.1
    )
    joined = summary(concatenate([first, second]))["arm_energy_j"]["right"]
    alone = summary(first)["arm_energy_j"]["right"]
    assert joined == pytest.approx(alone, rel=1e-12)


def test_solver_failures_count_only_what_could_be_met_for_every_backend(torso, tmp_path):
    """A posture level that the velocity limits hold back is INFEASIBLE for both backends
    (the box cost it part of its optimum); the hand above it is met by both, so neither run
    counts a failure. A hand target out of reach leaves the first level unmet on every step,
    and that is no failure either: no velocity within the limits meets it (the causes are in
    ``unmet_steps``)."""
    from wholebody.solvers import Level, Stack
    from wholebody.solvers.hqp import HierarchicalQPSolver
    from wholebody.solvers.result import SolverStatus
    from wholebody.tasks import PostureTask, VelocityLimits

    q0 = torso.home()
    target = torso.joint_positions(q0) + 1.0  # far: the posture row asks for 50 rad/s

    def run(solver, reach: float):
        hand = FrameTask(torso, "left_tool", kp=20.0)
        pose = torso.frame_pose(q0, "left_tool")
        pose[0, 3] += reach
        hand.set_target(pose)
        posture = PostureTask(torso, target=target, kp=50.0)
        stack = Stack(
            torso,
            [Level([hand], name="hand"), Level([posture], name="posture")],
            [VelocityLimits(torso)],
        )
        log = Controller(torso, stack, solver, dt=0.01).run(q0, 0.1)
        log = RunLog.load(log.save(tmp_path / "run.npz"))  # the rule survives a round trip
        return log, summary(log)["solver_failures"]

    hqp_log, hqp_failures = run(HierarchicalQPSolver(), 0.0)
    proj_log, proj_failures = run(ProjectionSolver(), 0.0)
    for log in (hqp_log, proj_log):
        assert np.any(log.status == SolverStatus.INFEASIBLE)  # the posture level was limited
    assert hqp_failures == proj_failures == 0
    for solver in (HierarchicalQPSolver(), ProjectionSolver()):
        log, failures = run(solver, 5.0)  # 5 m away: the first level cannot be met
        assert failures == 0 and not log.failed.any()
        assert np.all(log.unmet["left_tool"] > 0)


def test_misused_arguments_say_what_is_expected(torso):
    """Mistakes a user makes on a first try fail at construction with the fix in the message,
    not later with an AttributeError."""
    from wholebody.planning import DMP, cylinder
    from wholebody.solvers import Stack
    from wholebody.tasks import Manipulability

    hand = FrameTask(torso, "left_tool")
    stack = Stack(torso, [[hand]])
    pose = torso.frame_pose(torso.home(), "left_tool")
    traj = MinimumJerkTrajectory(pose, pose, 1.0)
    with pytest.raises(WholebodyError, match="solver must be a solver object"):
        Controller(torso, stack, "hqp", dt=0.01)
    with pytest.raises(WholebodyError, match="keyed by the task object"):
        Controller(torso, stack, ProjectionSolver(), dt=0.01, references={"left_tool": traj})
    with pytest.raises(WholebodyError, match=r"must be a Trajectory .*set_target"):
        Controller(torso, stack, ProjectionSolver(), dt=0.01, references={hand: pose})
    with pytest.raises(WholebodyError, match=r"a number .* or a StiffnessModel"):
        ArmPotentialEnergy(torso, "left", "learned")
    assert len(Manipulability(torso, "left_tool").frames) == 1  # one name, not its letters
    t = np.linspace(0.0, 1.0, 60)
    dmp = DMP.fit(np.c_[t, t, t], t)
    with pytest.raises(WholebodyError, match=r"DynamicPotential\(cylinder"):
        dmp.rollout(obstacles=[cylinder(np.zeros(3), 0.04, 0.2)])


def test_runs_with_different_periods_are_not_joined_and_an_empty_log_has_no_metrics(torso):
    """The metrics read one dt from a log's metadata: joining runs at 0.01 and 0.002 s gave a
    wrong joint travel and duration. A log without steps has no metrics to give."""
    from wholebody.errors import DataError
    from wholebody.tasks import PostureTask

    posture = PostureTask(torso, kp=2.0)
    stack = paper_stack(torso, [posture], stiffness=0.1)
    q0 = torso.neutral()
    a = Controller(torso, stack, ProjectionSolver(), dt=0.01).run(q0, 0.05)
    b = Controller(torso, stack, ProjectionSolver(), dt=0.002).run(q0, 0.01)
    with pytest.raises(DataError, match="different control periods"):
        concatenate([a, b])
    assert len(concatenate([a, a])) == 2 * len(a)
    nq, nu = a.q.shape[1], a.u.shape[1]
    empty = RunLog(
        np.zeros(0),
        np.zeros((0, nq)),
        np.zeros((0, nu)),
        np.zeros((0, nu)),
        np.zeros(0),
        np.zeros(0),
        np.zeros(0, np.int8),
        np.zeros(0, bool),
        np.zeros((0, 1)),
        meta=dict(a.meta),
    )
    with pytest.raises(DataError, match="no steps"):
        summary(empty)


def test_references_sampled_in_blocks_are_the_trajectory_at_every_step(humanoid):
    """The controller samples its references a block of steps at a time: over more than one
    block, every step's target is the trajectory at that step's time."""
    from wholebody.control import controller as module

    robot = humanoid
    hand = FrameTask(robot, "right_tool", kp=20.0)
    start = robot.frame_pose(robot.home(), "right_tool")
    end = start.copy()
    end[:3, 3] += (0.1, 0.0, 0.1)
    duration = (module._BLOCK + 76) * 0.01
    traj = MinimumJerkTrajectory(start, end, duration)
    ctrl = Controller(
        robot,
        paper_stack(robot, [hand], objectives=False),
        ProjectionSolver(),
        dt=0.01,
        references={hand: traj},
    )
    log = ctrl.run(robot.home(), duration)
    expected = np.array([traj.sample(t).pose[:3, 3] for t in log.t])
    np.testing.assert_allclose(log.reference_positions[hand.name], expected, atol=1e-12)


@pytest.mark.parametrize("recovery", [False, True])
@pytest.mark.parametrize("backend", ["projection", "hqp"])
def test_a_joint_resting_on_its_limit_does_not_stop_a_hand_integral(humanoid, backend, recovery):
    """The left elbow rests on its upper limit and no task moves it: its velocity sits on
    the box at every step (``limit_hit``). The right hand does not use it, so the hand's PI
    integral keeps integrating (it stayed 0 when any active bound froze every integral),
    with or without a stall recovery advancing the stack."""
    from wholebody.control import StallRecovery
    from wholebody.solvers import Level, Stack
    from wholebody.solvers.hqp import HierarchicalQPSolver
    from wholebody.tasks import JointPositionLimits, VelocityLimits

    robot = humanoid
    elbow = robot.index("left_elbow_flexion")
    q0 = robot.configuration(
        {
            "right_shoulder_flexion": 0.3,
            "right_elbow_flexion": 1.2,
            "left_elbow_flexion": robot.position_limits[1][elbow],
        }
    )
    hand = FrameTask(robot, "right_tool", kp=5.0, ki=5.0)
    goal = robot.frame_pose(q0, hand.frame)
    goal[:3, 3] += (0.02, 0.0, 0.0)
    hand.set_target(goal)
    stack = Stack(robot, [Level([hand])], [JointPositionLimits(robot), VelocityLimits(robot)])
    solver = ProjectionSolver() if backend == "projection" else HierarchicalQPSolver()
    watch = StallRecovery(robot, stack) if recovery else None
    log = Controller(robot, stack, solver, dt=0.01, recovery=watch).run(q0, 0.2)
    assert np.all(log.limit_hit) and np.all(log.u[:, elbow] == 0.0)
    assert np.abs(hand.integral[:3]).max() > 1e-4


def _blas_threads() -> set[int]:
    """The thread counts of the BLAS libraries loaded in this process."""
    from threadpoolctl import threadpool_info

    return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}


def test_the_loop_runs_with_the_blas_threads_asked_for(torso):
    """``threads=1`` (the default) limits BLAS to one thread inside the loop only; None
    leaves the libraries' setting; a count that is not a whole number >= 1 is refused."""
    from threadpoolctl import threadpool_limits

    from wholebody.solvers import Stack

    hand = FrameTask(torso, "left_tool", kp=20.0)
    stack = Stack(torso, [[hand]])
    q0 = torso.home()
    with threadpool_limits(2):
        if _blas_threads() != {2}:
            pytest.skip("this BLAS cannot run two threads")
        for threads, inside in ((1, {1}), (None, {2}), (3, {3})):
            seen: list[set[int]] = []
            ctrl = Controller(torso, stack, ProjectionSolver(), dt=0.01, threads=threads)
            ctrl.run(q0, 0.03, callback=lambda k, t, q, seen=seen: seen.append(_blas_threads()))
            assert seen == [inside] * 3, threads
            assert _blas_threads() == {2}  # restored after the run
        assert Controller(torso, stack, ProjectionSolver(), dt=0.01).threads == 1
    for bad in (0, -1, 1.5, True, "1"):
        with pytest.raises(WholebodyError, match="threads must be a whole number"):
            Controller(torso, stack, ProjectionSolver(), dt=0.01, threads=bad)
