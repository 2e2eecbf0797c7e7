"""The compiled step against the Python reference, on the same states.

Each stack runs in closed loop (driven by the reference) along a reach; at every state the
compiled path (``Stack.evaluate`` by the plan, the solver's kernels) and the reference
(``compiled=False``) must give

* the same rows, objectives and box (to 1e-12, relative to the rows' size);
* the same decisions: status, message, infeasible tasks, active bounds;
* the same ``u`` to 1e-9 (rad/s, m/s), or, where the problem itself decides less finely,
  within 10x of the reference's own answer to a 1e-15 relative perturbation of its rows
  (round-off alone moves a rank-deficient least-squares answer that far; the kernels take
  other, equally exact, floating-point routes);
* for the HQP, where a level's optimum is flat (the tight box leaves a 1e-3-weighted
  posture level to decide a few joints), the QP engine's tolerance decides the last digits
  and its warm start differs between the two paths: there ``u`` agrees to 1e-6 (the
  cascade's documented accuracy) with every level's residual the same to 1e-8.

CI runs this file three times: compiled, with ``NUMBA_DISABLE_JIT=1`` (the kernels as plain
Python, so that the code numba compiles is the code that is tested) and with
``NUMBA_BOUNDSCHECK=1`` (an out-of-bounds index in a kernel raises instead of corrupting
memory).
"""

from __future__ import annotations

import copy
import os

import numpy as np
import pytest

from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.presets import paper_metric, paper_stack
from wholebody.solvers import Level, ProjectionSolver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import (
    ArmPotentialEnergy,
    FrameTask,
    JointLimitAvoidance,
    JointPositionLimits,
    PostureTask,
    RelativeFrameTask,
    VelocityLimits,
)

DT = 0.01
UNCOMPILED = os.environ.get("NUMBA_DISABLE_JIT", "0") == "1"
STEPS = 12 if UNCOMPILED else 60  # plain-Python kernels run ~100x slower
TOL = 1e-9


def hierarchy(robot, hands, scale=1.0):
    posture = PostureTask(robot, kp=1.0 / DT, weight=1e-3)
    limits = [JointPositionLimits(robot, gain=0.5), VelocityLimits(robot, scale=scale)]
    return Stack(robot, [Level(hands, name="hands"), Level([posture], name="posture")], limits)


def three_levels(robot, hands):
    q0 = robot.home()
    chain = RelativeFrameTask(robot, hands[0].frame, hands[1].frame, kp=20.0, name="chain")
    chain.set_target(np.linalg.solve(robot.frame_pose(q0, hands[0].frame),
                                     robot.frame_pose(q0, hands[1].frame)))  # fmt: skip
    energy = [ArmPotentialEnergy(robot, arm, 0.1, weight=0.5) for arm in robot.arms]
    return Stack(
        robot,
        [Level([chain], name="chain"), Level(hands, name="hands"),
         Level(energy, gain=1.0, name="energy"),
         Level([PostureTask(robot, kp=1.0), JointLimitAvoidance(robot, weight=0.05)],
               gain=1.0, name="posture")],
        [JointPositionLimits(robot), VelocityLimits(robot)],
        metric=paper_metric(robot),
    )  # fmt: skip


STACKS = {
    "hierarchy": hierarchy,
    "tight": lambda robot, hands: hierarchy(robot, hands, scale=0.05),
    "paper": lambda robot, hands: paper_stack(robot, hands),  # the shipped stiffness network
    "three_levels": three_levels,
}
SOLVERS = {
    "projection": lambda compiled: ProjectionSolver(compiled=compiled),
    "hqp": lambda compiled: HierarchicalQPSolver("daqp", compiled=compiled),
}


def reaches(robot, rng):
    """Both hands on minimum-jerk moves of up to 15 cm and 0.3 rad from home."""
    q0 = robot.home()
    refs = []
    for frame in ("left_tool", "right_tool"):
        start = robot.frame_pose(q0, frame)
        end = start.copy()
        end[:3, 3] += rng.uniform(-0.15, 0.15, 3)
        refs.append(MinimumJerkTrajectory(start, end, STEPS * DT))
    return q0, refs


def perturbed(problem, rng, eps=1e-15):
    """A copy of ``problem`` with every row entry moved by a relative ``eps``."""
    p = copy.deepcopy(problem)
    for level in p.levels:
        level.A *= 1.0 + eps * rng.standard_normal(level.A.shape)
        level.b *= 1.0 + eps * rng.standard_normal(level.b.shape)
    return p


def assert_same_problem(compiled, reference):
    for lc, lr in zip(compiled.levels, reference.levels, strict=True):
        for name in ("A", "b", "C", "lower", "upper"):
            x, y = getattr(lc, name), getattr(lr, name)
            assert x.shape == y.shape, (lr.name, name)
            size = max(1.0, float(np.max(np.abs(y), initial=0.0, where=np.isfinite(y))))
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * size, err_msg=f"{lr.name}.{name}")
    for name in ("lower", "upper", "scale"):
        np.testing.assert_allclose(getattr(compiled, name), getattr(reference, name),
                                   rtol=0, atol=1e-12)  # fmt: skip
    assert compiled.objective_values.keys() == reference.objective_values.keys()
    for key, value in reference.objective_values.items():
        np.testing.assert_allclose(compiled.objective_values[key].value, value.value,
                                   rtol=1e-12, atol=1e-12, err_msg=key)  # fmt: skip


def assert_same_decisions(rc, rr):
    assert rc.status == rr.status
    assert rc.message == rr.message
    assert rc.infeasible == rr.infeasible
    np.testing.assert_array_equal(np.sort(rc.active_bounds), np.sort(rr.active_bounds))


def own_sensitivity(solver, problem, u, rng, samples=4):
    """How far the reference's answer moves under 1e-15 relative noise in its rows."""
    return max(float(np.max(np.abs(solver.solve_problem(perturbed(problem, rng)).u - u)))
               for _ in range(samples))  # fmt: skip


def same_optimum(rc, rr, gap):
    """Both answers are the cascade's optimum to its accuracy (see the module docstring)."""
    r = rr.level_residuals
    return gap <= 1e-6 and bool(np.all(np.abs(rc.level_residuals - r) <= 1e-8 * (1 + r)))


@pytest.mark.parametrize("solver_name", sorted(SOLVERS))
@pytest.mark.parametrize("stack_name", sorted(STACKS))
def test_compiled_step_is_the_reference(humanoid, rng, stack_name, solver_name):
    robot = humanoid
    q0, refs = reaches(robot, rng)
    hands = [FrameTask(robot, "left_tool", kp=20.0), FrameTask(robot, "right_tool", kp=20.0)]
    stack = STACKS[stack_name](robot, hands)
    compiled, reference = SOLVERS[solver_name](True), SOLVERS[solver_name](False)
    q, worst, limited = q0, 0.0, 0
    for k in range(STEPS):
        for hand, ref in zip(hands, refs, strict=True):
            sample = ref.sample(k * DT)
            hand.set_target(sample.pose, sample.twist)
        state = robot.update(q)
        problem_c = copy.deepcopy(stack.evaluate(state, DT))
        rc = compiled.solve(stack, state, DT)
        problem_r = stack.evaluate(state, DT, compiled=False)
        assert_same_problem(problem_c, problem_r)
        rr = reference.solve_problem(problem_r)
        assert_same_decisions(rc, rr)
        gap = float(np.max(np.abs(rc.u - rr.u)))
        if gap > TOL and not (solver_name == "hqp" and same_optimum(rc, rr, gap)):
            allowed = 10.0 * own_sensitivity(SOLVERS[solver_name](False), problem_r, rr.u, rng)
            assert gap <= allowed, f"step {k}: |u_c - u_r| = {gap:.3g} > {allowed:.3g}"
        worst, limited = max(worst, gap), limited + rr.limit_hit
        stack.advance(state, DT, rr.limit_hit)
        q = robot.integrate(q, rr.u, DT)
    if stack_name == "tight":
        assert limited > STEPS // 2  # the case is meant to have bounds active
    print(f"{stack_name}/{solver_name}: max |u_c - u_r| = {worst:.2e}, bounds on {limited} steps")
