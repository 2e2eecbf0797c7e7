"""The compiled control step against independent references.

* The rows, right-hand sides and box the kernels evaluate equal what Pinocchio and the tasks'
  formulas give, computed here with numpy (frame Jacobians from ``getFrameJacobian``, the
  orientation error from ``log3`` and ``Jlog3``, the limits' boxes from their definitions).
* One call of :meth:`Controller.step` (the kernel computing the kinematics, integrating
  ``q``) gives the same motion as the loop of four calls with Pinocchio's kinematics and
  integration.
* :meth:`Controller.step_many` gives each state what the same steps one by one give.

CI runs this file three times: compiled, with ``NUMBA_DISABLE_JIT=1`` (the kernels as plain
Python: the code numba compiles is the code tested) and with ``NUMBA_BOUNDSCHECK=1``.
"""

from __future__ import annotations

import os

import numpy as np
import pinocchio as pin
import pytest

from wholebody.control import Controller
from wholebody.errors import DimensionError
from wholebody.kernels.linalg import combine
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.presets import paper_stack
from wholebody.solvers import Level, ProjectionSolver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.plan import BoundCall
from wholebody.tasks import (
    AccelerationLimits,
    FrameTask,
    JointPositionLimits,
    PostureTask,
    RelativeFrameTask,
    VelocityLimits,
)

DT = 0.01
UNCOMPILED = os.environ.get("NUMBA_DISABLE_JIT", "0") == "1"
STEPS = 8 if UNCOMPILED else 60  # plain-Python kernels run ~100x slower
SOLVERS = {"projection": ProjectionSolver, "hqp": HierarchicalQPSolver}


def limits(robot, scale=1.0):
    return [
        JointPositionLimits(robot, gain=0.5),
        VelocityLimits(robot, scale=scale),
        AccelerationLimits(robot),
    ]


def hands(robot, ki=5.0):
    return [FrameTask(robot, f, kp=20.0, ki=ki) for f in ("left_tool", "right_tool")]


def chained(robot, tasks):
    """The hands under a closed chain between them, a weighted posture below."""
    q0 = robot.home()
    chain = RelativeFrameTask(robot, "left_tool", "right_tool", kp=10.0, name="chain")
    chain.set_target(
        np.linalg.solve(robot.frame_pose(q0, "left_tool"), robot.frame_pose(q0, "right_tool"))
    )
    posture = PostureTask(robot, kp=2.0, weight=1e-3)
    return Stack(
        robot,
        [Level([chain]), Level(tasks), Level([posture])],
        limits(robot, 0.3),
        metric=np.r_[np.full(4, 0.01), np.ones(robot.nu - 4)],
    )


def reach(robot, tasks, rng, duration):
    q0 = robot.home()
    refs = {}
    for task in tasks:
        start = robot.frame_pose(q0, task.frame)
        end = start.copy()
        end[:3, 3] += rng.uniform(-0.15, 0.15, 3)
        refs[task] = MinimumJerkTrajectory(start, end, duration)
    return q0, refs


# ---------------------------------------------------------------------- rows
def frame_jacobian(robot, state, frame):
    J = pin.getFrameJacobian(robot.model, robot.data, frame.index, pin.LOCAL_WORLD_ALIGNED)
    return J @ robot.actuation


def pose_rows(robot, state, task):
    """A pose task's rows from Pinocchio (module docstring)."""
    if isinstance(task, RelativeFrameTask):
        Ma, Mb = state.placement(task.frame_a), state.placement(task.frame_b)
        Ja, Jb = (
            frame_jacobian(robot, state, task.frame_a),
            frame_jacobian(robot, state, task.frame_b),
        )
        Ra, r = Ma.rotation, Mb.translation - Ma.translation
        skew = pin.skew(r)
        J = np.vstack([Ra.T @ (Jb[:3] - Ja[:3] + skew @ Ja[3:]), Ra.T @ (Jb[3:] - Ja[3:])])
        p, R = Ra.T @ r, Ra.T @ Mb.rotation
    else:
        M = state.placement(task.frame)
        J, p, R = frame_jacobian(robot, state, task.frame), M.translation, M.rotation
    target, twist = task.target, task.target_twist
    E = target[:3, :3] @ R.T
    e = np.r_[target[:3, 3] - p, pin.log3(E)]
    K = np.eye(6)
    K[3:, 3:] = pin.Jlog3(E)
    v = K @ np.r_[twist[:3], E.T @ twist[3:]] + task.kp * e + task.ki * task.integral
    return (K @ J)[task.rows], v[task.rows]


@pytest.mark.parametrize("stack_name", ["hierarchy", "chained"])
def test_rows_and_box_are_pinocchios_and_the_limits_definitions(humanoid, rng, stack_name):
    robot, tasks = humanoid, hands(humanoid)
    stack = (
        Stack(robot, [tasks, [PostureTask(robot, weight=1e-3)]], limits(robot))
        if stack_name == "hierarchy"
        else chained(robot, tasks)
    )
    D = stack.scale
    for trial in range(3 if UNCOMPILED else 10):
        q = robot.random_configuration(rng, margin=0.02)
        state = robot.update(q)
        for task in tasks:
            T = state.pose(task.frame).copy()
            T[:3, 3] += rng.uniform(-0.2, 0.2, 3)
            task.set_target(T, rng.normal(size=6))
            task.integral[:] = rng.uniform(-0.01, 0.01, 6)
        u_prev = rng.uniform(-0.5, 0.5, robot.nu)
        stack.set_velocity(u_prev, DT)
        problem = stack.evaluate(state, DT)
        for level in problem.levels:
            for task in [t for lv in stack.levels for t in lv.tasks]:
                if task.name not in level.task_rows:
                    continue
                rows = level.task_rows[task.name]
                if isinstance(task, PostureTask):
                    J = np.eye(robot.nu)[task.indices]
                    err = task.target - robot.joint_positions(q)[task.indices]
                    err[~task.tracked] = 0.0
                    v = task.kp * err
                else:
                    J, v = pose_rows(robot, state, task)
                w = np.sqrt(task.weight)
                np.testing.assert_allclose(level.A[rows], w * J * D, atol=1e-11, err_msg=task.name)
                np.testing.assert_allclose(level.b[rows], w * v, atol=1e-10, err_msg=task.name)
        # the box: position (gain 0.5), velocity and acceleration limits with the braking bound
        lo, hi = robot.position_limits
        jp = robot.joint_positions(q)
        vmax = next(c for c in stack.constraints if isinstance(c, VelocityLimits)).upper
        amax = robot.acceleration_limits
        with np.errstate(invalid="ignore"):
            brake_hi = amax * DT * (np.sqrt(1 + 2 * np.maximum(hi - jp, 0) / (amax * DT**2)) - 1)
            brake_lo = amax * DT * (np.sqrt(1 + 2 * np.maximum(jp - lo, 0) / (amax * DT**2)) - 1)
        finite = np.isfinite(lo) & np.isfinite(hi)
        upper = np.minimum.reduce([0.5 * (hi - jp) / DT, vmax, u_prev + amax * DT])
        lower = np.maximum.reduce([0.5 * (lo - jp) / DT, -vmax, u_prev - amax * DT])
        upper[finite] = np.minimum(upper[finite], brake_hi[finite])
        lower[finite] = np.maximum(lower[finite], -brake_lo[finite])
        crossed = lower > upper
        lower[crossed] = upper[crossed] = np.where(
            lower[crossed] > 0, upper[crossed], lower[crossed]
        )
        np.testing.assert_allclose(problem.lower * D, lower, atol=1e-10, err_msg=f"trial {trial}")
        np.testing.assert_allclose(problem.upper * D, upper, atol=1e-10, err_msg=f"trial {trial}")
        np.testing.assert_allclose(problem.anchor * D, u_prev, atol=1e-12)


# ---------------------------------------------------------------------- the one-call step
def four_calls(robot, stack, solver, refs, q, k):
    """Step k of the loop of four calls (the references set as ``Controller`` samples them,
    the pose at the step's start and the twist at its midpoint): ``(u, q_next, result)``."""
    for task, traj in refs.items():
        task.set_target(traj.sample(k * DT).pose, traj.sample((k + 0.5) * DT).twist)
    state = robot.update(q)
    result = solver.solve(stack, state, DT)
    stack.advance(state, DT, result=result)
    return result.u, robot.integrate(q, result.u, DT), result


@pytest.mark.parametrize("solver_name", sorted(SOLVERS))
@pytest.mark.parametrize("stack_name", ["paper", "chained"])
def test_one_call_step_is_the_loop_of_four_calls(humanoid, rng, solver_name, stack_name):
    """The kernel's kinematics, anti-windup, acceleration memory and integration against
    Pinocchio's kinematics, the stack's advance and Pinocchio's integrate, along a reach with
    bounds active."""
    robot = humanoid
    runs = []
    for fast in (True, False):
        tasks = hands(robot)
        stack = (
            paper_stack(robot, tasks, acceleration=True)
            if stack_name == "paper"
            else chained(robot, tasks)
        )
        q, refs = reach(robot, tasks, np.random.default_rng(7), STEPS * DT)
        solver = SOLVERS[solver_name]()
        controller = Controller(robot, stack, solver, dt=DT, references=refs)
        path, statuses = [], []
        for k in range(STEPS):
            if fast:
                u = controller.step(q)
                q = controller.q_next.copy()
            else:
                u, q, result = four_calls(robot, stack, solver, refs, q, k)
            path.append(np.r_[u, q])
            statuses.append(int(controller.result.status) if fast else int(result.status))
        controller.close()
        runs.append((np.array(path), statuses, [t.integral.copy() for t in tasks]))
    (fast_path, fast_status, fast_int), (slow_path, slow_status, slow_int) = runs
    assert fast_status == slow_status
    # the projection to rounding; the HQP to its accuracy (1e-6: rounding-level differences
    # of the kinematics can take daqp along another active-set path)
    np.testing.assert_allclose(
        fast_path, slow_path, atol=1e-8 if solver_name == "projection" else 1e-6
    )
    for a, b in zip(fast_int, slow_int, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-10)
    if stack_name == "chained":
        assert any(s > 0 for s in fast_status)  # bounds were active


@pytest.mark.parametrize("solver_name", sorted(SOLVERS))
def test_step_many_gives_each_state_its_own_steps(humanoid, rng, solver_name):
    robot = humanoid
    tasks = hands(robot, ki=0.0)
    stack = Stack(robot, [tasks, [PostureTask(robot, weight=1e-3)]], limits(robot))
    controller = Controller(robot, stack, SOLVERS[solver_name](), dt=DT)
    n, steps = (3, 2) if UNCOMPILED else (9, 5)
    Q = np.array([robot.random_configuration(rng, margin=0.05, base_range=0.3) for _ in range(n)])
    targets = {}
    for task in tasks:
        poses = []
        for q in Q:
            T = robot.frame_pose(q, task.frame).copy()
            T[:3, 3] += rng.uniform(-0.1, 0.1, 3)
            poses.append(T)
        targets[task] = np.array(poses)
    batch = controller.step_many(Q, targets, steps=steps, threads=2)
    for s in range(n):  # the same steps one at a time
        controller.reset()
        for task in tasks:
            task.set_target(targets[task][s])
        q = Q[s].copy()
        for _ in range(steps):
            last = q
            u = controller.step(q)
            q = controller.q_next.copy()
        np.testing.assert_allclose(batch.u[s], u, atol=1e-9)
        np.testing.assert_allclose(batch.q[s], q, atol=1e-9)
        assert batch.status[s] == int(controller.result.status)
        state = robot.update(last)  # the errors are those of the last step's rows
        for task in tasks:
            np.testing.assert_allclose(batch.errors[task.name][s], task.error(state), atol=1e-9)
    controller.close()


@pytest.mark.parametrize("engine", ["osqp", "proxsuite"])
def test_controller_step_with_an_engine_solving_in_python(humanoid, engine):
    """With an engine outside the kernel the step is the kernel's kinematics, the cascade's
    stages around the engine's QPs and the kernel's integration: the same steps as the 4-call
    loop with that engine, and as daqp's to the engines' accuracy."""
    robot = humanoid
    paths = []
    for fast, name in ((True, engine), (False, engine), (True, "daqp")):
        tasks = hands(robot)
        stack = Stack(robot, [tasks, [PostureTask(robot, weight=1e-3)]], limits(robot))
        q, refs = reach(robot, tasks, np.random.default_rng(3), 10 * DT)
        solver = HierarchicalQPSolver(name)
        controller = Controller(robot, stack, solver, dt=DT, references=refs)
        path = []
        for k in range(10):
            if fast:
                u = controller.step(q)
                q = controller.q_next.copy()
            else:
                u, q, _ = four_calls(robot, stack, solver, refs, q, k)
            path.append(np.r_[u, q])
        controller.close()
        paths.append(np.array(path))
    np.testing.assert_allclose(paths[0], paths[1], atol=1e-6)
    np.testing.assert_allclose(paths[0], paths[2], atol=1e-3)


def test_a_bound_call_gives_the_dispatchers_answers(rng):
    """A bound call's first call goes through numba's dispatcher, the next ones through the
    compiled entry point of the arguments' types, with the same answers."""
    x, y = rng.normal(size=7), rng.normal(size=7)
    call = BoundCall("linalg.combine", "a test kernel", combine, x, 0.5, y)
    for _ in range(3):
        np.testing.assert_array_equal(call(), x + 0.5 * y)
        assert call.bound != UNCOMPILED
    y[:] = rng.normal(size=7)  # the same objects, new numbers
    np.testing.assert_array_equal(call(), x + 0.5 * y)


@pytest.mark.parametrize("solver_name", sorted(SOLVERS))
def test_a_levels_gain_changed_between_steps_is_the_next_steps(humanoid, rng, solver_name):
    """A level's gain and objective weight set between one-call steps are those the next
    step uses: its u is that of a controller built with them."""
    from wholebody.tasks import JointLimitAvoidance

    robot = humanoid
    q = robot.random_configuration(rng, margin=0.2, base_range=0.3)

    def controller(gain, weight):
        level = Level([*hands(robot, ki=0.0), JointLimitAvoidance(robot)], gain, weight)
        stack = Stack(robot, [level, [PostureTask(robot, weight=1e-3)]], limits(robot))
        return Controller(robot, stack, SOLVERS[solver_name](), dt=DT)

    changed = controller(1.0, 1.0)
    changed.step(q)
    changed.reset()
    changed.stack.levels[0].gain, changed.stack.levels[0].objective_weight = 3.0, 0.5
    u = changed.step(q)
    np.testing.assert_allclose(u, controller(3.0, 0.5).step(q), atol=1e-12)
    assert np.abs(u - controller(1.0, 1.0).step(q)).max() > 1e-6  # (the gain matters here)


@pytest.mark.parametrize("engine", ["projection", "daqp", "osqp"])
def test_a_configuration_not_finite_is_refused_and_changes_nothing(humanoid, rng, engine):
    """A NaN in ``q`` raises DimensionError, on the first step and on a bound one-call step
    (checked by the kernel there), and the next steps are those of a controller that never
    saw it."""
    robot = humanoid

    def controller():
        solver = ProjectionSolver() if engine == "projection" else HierarchicalQPSolver(engine)
        tasks = hands(robot)
        stack = Stack(robot, [tasks, [PostureTask(robot, weight=1e-3)]], limits(robot))
        return Controller(robot, stack, solver, dt=DT)

    q = robot.random_configuration(rng, margin=0.2, base_range=0.3)
    bad = q.copy()
    bad[5] = np.nan
    seen, clean = controller(), controller()
    with pytest.raises(DimensionError, match="not finite"):
        seen.step(bad)
    for _ in range(3):
        np.testing.assert_array_equal(seen.step(q), clean.step(q))
        with pytest.raises(DimensionError, match="not finite"):
            seen.step(bad)
        q = clean.q_next.copy()
