"""Projection versus hierarchical QP on the same stacks: where they agree, where they differ.

* With no bound active both solve the same rows the same way (the recursive pseudo-inverse):
  the same ``u`` to 1e-6, with one level and with the paper's objective level below it.
* With bounds active the QP never leaves the box and keeps the task exact whenever some
  feasible motion does; the projection (Saturation in the Null Space) also keeps the box but
  may have to scale the whole level down where the QP still meets it, and the textbook
  projection (no saturation) leaves the box.
* 200 random reachable targets for both hands with the paper's stack, in closed loop: no
  limit violation, no NaN, and the success rate of each backend (printed).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from wholebody.presets import PaperWeights, paper_stack
from wholebody.solvers import ProjectionSolver, SolverStatus, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import (
    FrameTask,
    JointLimitAvoidance,
    JointPositionLimits,
    PostureTask,
    VelocityLimits,
)

DT = 0.01


def hands(robot, kp=10.0):
    return FrameTask(robot, "left_tool", kp=kp), FrameTask(robot, "right_tool", kp=kp)


def near_targets(state, tasks, rng, reach):
    for t in tasks:
        T = state.pose(t.frame).copy()
        T[:3, 3] += rng.uniform(-reach, reach, 3)
        t.set_target(T, rng.uniform(-0.05, 0.05, 6))


def away_from_singularities(stack, state, threshold=0.05):
    """The projection damps below s_min = 0.02; compare where it does not."""
    A = stack.evaluate(state, DT).levels[0].A
    return np.linalg.svd(A, compute_uv=False)[-1] > threshold


@pytest.mark.parametrize("objectives", [False, True])
def test_same_u_when_no_bound_is_active(humanoid, rng, objectives):
    L, R = hands(humanoid)
    # the paper's stack with a descent gain small enough that the objective step often fits
    # in the box (with the default gain the wheels' cheap metric saturates them)
    stack = paper_stack(
        humanoid, (L, R), objectives=objectives, stiffness=0.1, weights=PaperWeights(gain=0.01)
    )
    proj, hqp = ProjectionSolver(), HierarchicalQPSolver()
    checked = 0
    for _ in range(30):
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.15))
        near_targets(state, (L, R), rng, reach=0.01)
        if not away_from_singularities(stack, state):
            continue
        a, b = proj.solve(stack, state, DT), hqp.solve(stack, state, DT)
        if a.status != SolverStatus.OK or b.status != SolverStatus.OK:
            continue
        np.testing.assert_allclose(b.u, a.u, atol=1e-6)
        np.testing.assert_allclose(b.level_residuals, a.level_residuals, atol=1e-6)
        checked += 1
    assert checked >= 10


def test_with_bounds_active_the_qp_keeps_the_box_and_the_task(humanoid, rng):
    """The QP's hands residual is never worse than the projection's (both inside the same
    box); there are cases where the projection (SNS) has to scale the hands' motion down or
    leaves them unmet while the QP meets them exactly inside the box; and the textbook
    projection (no saturation) leaves the box."""
    L, R = hands(humanoid, kp=10.0)
    stack = Stack(humanoid, [[L, R]], [JointPositionLimits(humanoid), VelocityLimits(humanoid)])
    sns, textbook = ProjectionSolver(), ProjectionSolver(saturate=False)
    hqp = HierarchicalQPSolver()
    short_but_exact = textbook_outside = better = 0
    for _ in range(200):
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.01))
        near_targets(state, (L, R), rng, reach=float(rng.choice([0.01, 0.03, 0.1, 0.3])))
        problem = stack.evaluate(state, DT)
        lo, hi = problem.lower * problem.scale, problem.upper * problem.scale
        q, s, t = (solver.solve(stack, state, DT) for solver in (hqp, sns, textbook))
        for r in (q, s):
            assert np.all(np.isfinite(r.u))
            assert np.all(r.u >= lo - 1e-9) and np.all(r.u <= hi + 1e-9)
        assert q.level_residuals[0] <= s.level_residuals[0] + 1e-7
        better += q.level_residuals[0] < s.level_residuals[0] - 1e-6
        if s.status in (SolverStatus.SCALED, SolverStatus.INFEASIBLE) and (
            q.level_residuals[0] < 1e-8 and q.status == SolverStatus.BOUNDS_ACTIVE
        ):
            short_but_exact += 1
        if np.any(t.u < lo - 1e-9) or np.any(t.u > hi + 1e-9):
            textbook_outside += 1
    assert short_but_exact >= 3 and better >= 10 and textbook_outside >= 20, (
        short_but_exact,
        better,
        textbook_outside,
    )


@pytest.mark.parametrize(
    "solver", [ProjectionSolver(), HierarchicalQPSolver()], ids=["projection", "hqp"]
)
def test_both_backends_report_unweighted_task_residuals(humanoid, rng, solver):
    """``task_residuals`` is ``||J u - v||`` of each task's own rows whatever its weight
    (scalar, per row, with a zero row), for both backends; the objectives are not a task."""
    L = FrameTask(humanoid, "left_tool", kp=10.0, weight=4.0)
    R = FrameTask(humanoid, "right_tool", kp=10.0, weight=[1.0, 2.0, 0.5, 0.0, 3.0, 0.25])
    posture = PostureTask(humanoid, kp=0.5, weight=0.01)
    stack = Stack(
        humanoid,
        [[L, R, posture], [JointLimitAvoidance(humanoid)]],
        [JointPositionLimits(humanoid), VelocityLimits(humanoid)],
    )
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.1))
    near_targets(state, (L, R), rng, reach=0.05)
    result = solver.solve(stack, state, DT)
    assert set(result.task_residuals) == {L.name, R.name, posture.name}
    for task, keep in ((L, slice(None)), (R, [0, 1, 2, 4, 5]), (posture, slice(None))):
        rows = task.compute(state)
        r = (rows.J @ result.u - rows.v)[keep]  # a row of weight 0 carries no information
        assert result.task_residuals[task.name] == pytest.approx(np.linalg.norm(r), rel=1e-9)


def random_targets(robot, rng, count):
    """Hand poses of random configurations around home (joints +-1.2 rad within their limits,
    base +-0.5 m): reachable by construction, some of them far."""
    lower, upper = robot.position_limits
    home = robot.joint_positions(robot.home())
    out = []
    for _ in range(count):
        jp = home + rng.uniform(-1.2, 1.2, robot.nu)
        values = {
            j: float(np.clip(jp[i], lower[i] + 0.05, upper[i] - 0.05))
            for i, j in enumerate(robot.actuated_joints)
            if np.isfinite(lower[i])
        }
        q = robot.configuration(values, base_pose=(*rng.uniform(-0.5, 0.5, 2), 0.0))
        out.append((robot.frame_pose(q, "left_tool"), robot.frame_pose(q, "right_tool")))
    return out


def pose_error(T, Td):
    return np.linalg.norm(Td[:3, 3] - T[:3, 3]), np.linalg.norm(pin.log3(Td[:3, :3] @ T[:3, :3].T))


@pytest.mark.slow
def test_random_reachable_targets(humanoid):
    """200 seeded targets, paper's stack (hands; arm energy and joint-limit avoidance), 1 s
    of closed loop from home at 50 Hz each, both backends on the same targets. Measured:
    projection 94.5 %, hqp 95.5 %."""
    robot, dt, steps = humanoid, 0.02, 50
    lower, upper = robot.position_limits
    targets = random_targets(robot, np.random.default_rng(4), 200)
    rates = {}
    for name, solver in (("projection", ProjectionSolver()), ("hqp", HierarchicalQPSolver())):
        L, R = hands(robot, kp=8.0)
        stack = paper_stack(robot, (L, R), stiffness=0.1)
        success = violations = nans = 0
        for TL, TR in targets:
            q = robot.home()
            stack.reset()
            L.set_target(TL)
            R.set_target(TR)
            for _ in range(steps):
                state = robot.update(q)
                result = solver.solve(stack, state, dt)
                nans += not np.all(np.isfinite(result.u))
                problem = stack.evaluate(state, dt)
                lo, hi = problem.lower * problem.scale, problem.upper * problem.scale
                violations += bool(np.any(result.u < lo - 1e-9) or np.any(result.u > hi + 1e-9))
                stack.advance(state, dt, result.limit_hit)
                q = robot.integrate(q, result.u, dt)
                jp = robot.joint_positions(q)
                violations += bool(np.any(jp < lower - 1e-9) or np.any(jp > upper + 1e-9))
            ok = [pose_error(robot.frame_pose(q, t.frame), t.target) for t in (L, R)]
            success += all(p < 5e-3 and o < 2e-2 for p, o in ok)
        assert nans == 0 and violations == 0, (name, nans, violations)
        rates[name] = success / len(targets)
    print(f"\nrandom reachable targets (200, both hands, 1 s): success rate {rates}")
    assert min(rates.values()) >= 0.8, rates
