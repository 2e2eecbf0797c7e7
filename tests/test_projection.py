"""The projection backend: the paper's formula, the plain pseudo-inverse by configuration, the
box under Saturation in the Null Space, null-space flow and singularities."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from test_tasks import configurations

from wholebody.solvers import Level, ProjectionSolver, SolverStatus, Stack
from wholebody.solvers.stack import LevelProblem, StackProblem
from wholebody.tasks import (
    ArmPotentialEnergy,
    Bounds,
    FrameTask,
    JointLimitAvoidance,
    JointPositionLimits,
    Limit,
    Manipulability,
    PostureTask,
    VelocityLimits,
)

DT = 0.01


def hands(robot, kp=10.0):
    return FrameTask(robot, "left_tool", kp=kp), FrameTask(robot, "right_tool", kp=kp)


def near_targets(robot, state, tasks, rng, reach=0.05):
    for t in tasks:
        T = state.pose(t.frame)
        T[:3, 3] += rng.uniform(-reach, reach, 3)
        t.set_target(T, rng.uniform(-0.05, 0.05, 6))


def box(stack, state, dt=DT):
    p = stack.evaluate(state, dt)
    return p.lower * p.scale, p.upper * p.scale


def objectives(robot):
    return [
        ArmPotentialEnergy(robot, "left", 0.3),
        ArmPotentialEnergy(robot, "right", 0.3),
        JointLimitAvoidance(robot, weight=0.1),
        Manipulability(robot, ["left_tool", "right_tool"], weight=-0.5),
    ]


@pytest.mark.parametrize("with_limits_term", [False, True])
def test_projection_is_the_papers_formula(humanoid, rng, with_limits_term):
    """u = J+ v - k (I - J+ J) grad H, exactly, whenever no bound is active; with the
    joint-limit term, whose curvature is known, the step is the semi-implicit
    -k grad / (1 + k dt h'') (see wholebody.solvers.stack)."""
    L, R = hands(humanoid)
    objs = [
        o
        for o in objectives(humanoid)
        if with_limits_term or not isinstance(o, JointLimitAvoidance)
    ]
    k = 0.05
    stack = Stack(
        humanoid,
        [[L, R], Level(objs, gain=k)],
        [JointPositionLimits(humanoid), VelocityLimits(humanoid)],
    )
    solver, checked = ProjectionSolver(), 0
    for _ in range(20):
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.15))
        near_targets(humanoid, state, (L, R), rng)
        result = solver.solve(stack, state, DT)
        if result.status != SolverStatus.OK:
            continue
        rows = [t.compute(state) for t in (L, R)]
        J = np.vstack([r.J for r in rows])
        v = np.concatenate([r.v for r in rows])
        grad = sum(o.weight * o.evaluate(state).gradient for o in objs)
        curvature = sum(
            o.weight * o.evaluate(state).curvature
            for o in objs
            if isinstance(o, JointLimitAvoidance)
        )
        Jp = np.linalg.pinv(J)
        step = grad / (1 + k * DT * curvature) if with_limits_term else grad
        paper = Jp @ v - k * (np.eye(humanoid.nu) - Jp @ J) @ step
        np.testing.assert_allclose(result.u, paper, atol=1e-9)
        checked += 1
    assert checked >= 10


def test_plain_pseudo_inverse_is_the_same_solver_without_objectives(humanoid, rng):
    L, R = hands(humanoid)
    stack = Stack(humanoid, [[L, R]], [JointPositionLimits(humanoid), VelocityLimits(humanoid)])
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.15))
    near_targets(humanoid, state, (L, R), rng)
    result = ProjectionSolver().solve(stack, state, DT)
    assert result.status == SolverStatus.OK
    J = np.vstack([t.compute(state).J for t in (L, R)])
    v = np.concatenate([t.compute(state).v for t in (L, R)])
    np.testing.assert_allclose(result.u, np.linalg.pinv(J) @ v, atol=1e-10)


def test_box_is_never_violated_and_the_task_stays_exact_when_it_can(humanoid, rng):
    L, R = hands(humanoid, kp=30.0)
    stack = Stack(
        humanoid,
        [[L, R], Level(objectives(humanoid), gain=1.0)],
        [JointPositionLimits(humanoid), VelocityLimits(humanoid)],
    )
    solver = ProjectionSolver()
    counts = dict.fromkeys(SolverStatus, 0)
    exact_with_bounds = 0
    for _ in range(150):
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.01))
        near_targets(humanoid, state, (L, R), rng, reach=rng.choice([0.02, 0.3, 1.0]))
        result = solver.solve(stack, state, DT)
        lo, hi = box(stack, state)
        assert np.all(np.isfinite(result.u))
        assert np.all(result.u >= lo - 1e-9) and np.all(result.u <= hi + 1e-9)
        counts[result.status] += 1
        if result.status == SolverStatus.BOUNDS_ACTIVE and result.level_residuals[0] < 1e-8:
            exact_with_bounds += 1
    assert counts[SolverStatus.SCALED] > 0 and exact_with_bounds > 0, counts


def test_clipping_the_textbook_solution_wrecks_the_task_where_sns_does_not(humanoid, rng):
    L, R = hands(humanoid, kp=10.0)
    stack = Stack(humanoid, [[L, R]], [JointPositionLimits(humanoid), VelocityLimits(humanoid)])
    sns, free = ProjectionSolver(), ProjectionSolver(saturate=False)
    found = 0
    for _ in range(100):
        # joints near their limits, moderate hand speeds: feasible, but only with bounds
        state = humanoid.update(configurations(humanoid, rng, n=2)[1])
        near_targets(humanoid, state, (L, R), rng, reach=0.02)
        a, b = sns.solve(stack, state, DT), free.solve(stack, state, DT)
        lo, hi = box(stack, state)
        clipped = np.clip(b.u, lo, hi)
        if a.status != SolverStatus.BOUNDS_ACTIVE or np.allclose(clipped, b.u):
            continue
        J = np.vstack([t.compute(state).J for t in (L, R)])
        v = np.concatenate([t.compute(state).v for t in (L, R)])
        assert np.linalg.norm(J @ a.u - v) < 1e-8  # SNS: still exact
        assert np.linalg.norm(J @ clipped - v) > 1e-3  # clipping: the hands go astray
        found += 1
    assert found >= 3


def test_lower_levels_do_not_disturb_higher_ones(humanoid, rng):
    L, R = hands(humanoid)
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.2))
    near_targets(humanoid, state, (L, R), rng, reach=0.02)
    limits = [VelocityLimits(humanoid, scale=100.0)]
    one = ProjectionSolver().solve(Stack(humanoid, [[L, R]], limits), state, DT)
    conflicting = PostureTask(humanoid, target=rng.uniform(-0.3, 0.3, humanoid.nu), kp=50.0)
    two = ProjectionSolver().solve(Stack(humanoid, [[L, R], [conflicting]], limits), state, DT)
    assert two.level_residuals[0] == pytest.approx(one.level_residuals[0], abs=1e-8)
    assert two.level_residuals[0] < 1e-8 < 1e-2 < two.level_residuals[1]


def test_null_space_flow_lowers_the_energy_with_the_hands_held(humanoid):
    """Hands held still (level 1), arm energy descended in the null space (level 2): the
    energy decreases at every step and neither hand drifts by 1e-6 m."""
    robot = humanoid
    q = robot.configuration(
        {
            "left_shoulder_flexion": 0.6,
            "left_shoulder_abduction": 0.8,
            "left_elbow_flexion": 1.4,
            "right_shoulder_flexion": 0.5,
            "right_shoulder_abduction": 0.9,
            "right_elbow_flexion": 1.2,
        }
    )
    L, R = hands(robot, kp=20.0)
    state = robot.update(q)
    start = {t.name: state.position(t.frame) for t in (L, R)}
    for t in (L, R):
        t.set_target(state.pose(t.frame))
    energy = [ArmPotentialEnergy(robot, "left", 0.1), ArmPotentialEnergy(robot, "right", 0.1)]
    stack = Stack(
        robot,
        [[L, R], Level(energy, gain=0.2)],
        [JointPositionLimits(robot), VelocityLimits(robot)],
    )
    solver, dt = ProjectionSolver(), 0.002
    values, drift = [], 0.0
    for _ in range(400):
        state = robot.update(q)
        values.append(sum(e.evaluate(state).value for e in energy))
        drift = max(
            drift, *(np.linalg.norm(state.position(t.frame) - start[t.name]) for t in (L, R))
        )
        q = robot.integrate(q, solver.solve(stack, state, dt).u, dt)
    steps = np.diff(values)
    assert np.all(steps < 0), f"energy rose at steps {np.flatnonzero(steps >= 0)}"
    assert values[0] - values[-1] > 0.05  # it really moved (J)
    assert drift < 1e-6


def test_singular_configuration_gives_a_bounded_answer(humanoid):
    """Straight hanging arms are a singularity of the hand Jacobians: the damped inverse
    still answers, finite and inside the box."""
    L, R = hands(humanoid)
    state = humanoid.update(humanoid.neutral())
    for t in (L, R):
        T = state.pose(t.frame)
        T[2, 3] -= 0.05  # straight down: along the singular direction
        t.set_target(T)
    stack = Stack(humanoid, [[L, R]], [JointPositionLimits(humanoid), VelocityLimits(humanoid)])
    result = ProjectionSolver().solve(stack, state, DT)
    lo, hi = box(stack, state)
    assert np.all(np.isfinite(result.u)) and np.all(result.u >= lo - 1e-9)
    assert np.all(result.u <= hi + 1e-9)


def test_level_with_more_rows_than_columns_is_plain_least_squares(humanoid, rng):
    """Both hands and a posture task in one level: 35 rows, 23 columns, full column rank and
    far from singular. The answer is the weighted least-squares solution, undamped (the
    zero eigenvalues of the 35 x 35 Gram matrix must not count as directions)."""
    L, R = hands(humanoid)
    posture = PostureTask(humanoid, kp=1.0, weight=1e-3)
    stack = Stack(humanoid, [Level([L, R, posture])], [])
    for q in configurations(humanoid, rng, 5):
        state = humanoid.update(q)
        near_targets(humanoid, state, (L, R), rng)
        problem = stack.evaluate(state, DT)
        A, b = problem.levels[0].A, problem.levels[0].b
        assert A.shape == (35, 23) and np.linalg.svd(A, compute_uv=False)[-1] > 0.03
        expected = problem.to_u(np.linalg.lstsq(A, b, rcond=None)[0])
        result = ProjectionSolver().solve(stack, state, DT)
        np.testing.assert_allclose(result.u, expected, atol=1e-9 * (1 + np.abs(expected).max()))


@pytest.mark.parametrize("kappa", [1.0, 3e2, 3e3, 3e4, 1e7])
def test_a_tall_level_is_its_least_squares_solution_at_every_condition_number(rng, kappa):
    # Singular values from 0.03 kappa down to 0.03 (> singular_threshold: no damping): the
    # well-conditioned levels go through the normal equations (refined above kappa 1e3), the
    # others through the eigen-decomposition; a second level has no freedom left.
    m, n = 30, 12
    worst = 0.0
    for _ in range(20):
        U, _ = np.linalg.qr(rng.normal(size=(m, n)))
        V, _ = np.linalg.qr(rng.normal(size=(n, n)))
        A = (U * (0.03 * np.logspace(np.log10(kappa), 0, n))) @ V.T
        for b in (A @ rng.normal(size=n), rng.normal(size=m)):  # consistent, then not
            levels = [
                LevelProblem(
                    "tall", A, b, np.zeros((0, n)), np.zeros(0), np.zeros(0), {"t": slice(0, m)}
                ),
                LevelProblem(
                    "rest",
                    np.eye(n),
                    rng.normal(size=n),
                    np.zeros((0, n)),
                    np.zeros(0),
                    np.zeros(0),
                    {"objectives": slice(0, n)},
                    {},
                    1.0,
                ),
            ]
            box = np.full(n, 1e12)
            problem = StackProblem(levels, -box, box, np.ones(n), {})
            u = ProjectionSolver().solve_problem(problem).u
            exact = np.linalg.lstsq(A, b, rcond=None)[0]
            worst = max(worst, np.linalg.norm(u - exact) / np.linalg.norm(exact))
    assert worst <= 1e-10 * max(1.0, kappa / 1e4)


def test_round_off_of_a_computed_projector_does_not_damp_a_tall_level_below(rng):
    # A nearly singular first level (singular values 220 to 0.004, two zero): its projector,
    # from M M^T, is accurate to about kappa^2 eps (3e-7), which leaves singular values of
    # that size in the tall level below where 0 is exact. Counted as directions, they would
    # damp the whole level (found by fuzzing): it must stay optimal on what level 0 leaves.
    n = 23
    for _ in range(10):
        U, _ = np.linalg.qr(rng.normal(size=(9, 9)))
        V, _ = np.linalg.qr(rng.normal(size=(n, n)))
        A0 = (U * [220, 207, 161, 1.3, 1.2, 0.56, 0.004, 0, 0]) @ V[:, :9].T
        A1, b1 = rng.normal(size=(46, n)), rng.normal(size=46)
        levels = [
            LevelProblem(
                "L0",
                A0,
                rng.normal(size=9),
                np.zeros((0, n)),
                np.zeros(0),
                np.zeros(0),
                {"t0": slice(0, 9)},
            ),
            LevelProblem(
                "L1", A1, b1, np.zeros((0, n)), np.zeros(0), np.zeros(0), {"t1": slice(0, 46)}
            ),
        ]
        box = np.full(n, 1e12)
        u = ProjectionSolver().solve_problem(StackProblem(levels, -box, box, np.ones(n), {})).u
        N = np.linalg.svd(A0)[2][7:].T  # what level 0 leaves free, exactly
        gradient = N.T @ A1.T @ (A1 @ u - b1)
        assert np.linalg.norm(gradient) <= 1e-5 * np.linalg.norm(N.T @ A1.T @ b1)


def _level(name, A, b):
    """A level of one task (rows ``A u = b``), no inequality rows."""
    n = A.shape[1]
    return LevelProblem(
        name, A, b, np.zeros((0, n)), np.zeros(0), np.zeros(0), {name: slice(0, A.shape[0])}
    )


def _wide(rng, m, n, largest=5.0, smallest=0.05):
    """A random m x n matrix of full row rank, singular values from ``largest`` down to
    ``smallest``."""
    U, _ = np.linalg.qr(rng.normal(size=(m, m)))
    V, _ = np.linalg.qr(rng.normal(size=(n, m)))
    return (U * np.logspace(np.log10(largest), np.log10(smallest), m)) @ V.T


def _solve(levels, n):
    """The projection's solution of ``levels`` (no box)."""
    box = np.full(n, 1e12)
    return ProjectionSolver().solve_problem(StackProblem(levels, -box, box, np.ones(n), {})).u


@pytest.mark.parametrize("above", [1, 2])
@pytest.mark.parametrize("s", [1.0, 0.05, 0.01])
def test_a_task_level_of_rows_s_identity_is_its_closed_form_below_wide_levels(rng, above, s):
    # A posture task in a uniform metric has rows s I: under ``above`` wide levels (certified,
    # undamped, condition numbers up to 1700) it moves by P (b / s - u), P the projector on
    # what they leave, far above the singular threshold eps (0.02); below it, every direction
    # of s Zb has the singular value s and is damped alike: g = s / (s^2 + (1 - (s / eps)^2)
    # lambda^2) instead of 1/s. Its move leaves the levels above as they were, to rounding.
    n, m, solver = 23, 6, ProjectionSolver()
    eps, lam = solver.singular_threshold, solver.damping
    gain = 1.0 / s if s >= eps else s / (s * s + (1.0 - (s / eps) ** 2) * lam**2)
    for _ in range(5):
        rows = [_wide(rng, m, n, largest=50.0, smallest=0.03) for _ in range(above)]
        levels = [_level(f"L{k}", A, rng.normal(size=m)) for k, A in enumerate(rows)]
        b = rng.normal(size=n)
        u_above = _solve(levels, n)
        levels.append(_level("posture", s * np.eye(n), b))
        u = _solve(levels, n)
        expected, N = np.zeros(n), np.eye(n)  # N: orthonormal basis of what is left free
        for level in levels[:-1]:
            M = level.A @ N
            expected += N @ np.linalg.pinv(M) @ (level.b - level.A @ expected)
            N = N @ scipy.linalg.null_space(M)
        expected += gain * N @ N.T @ (b - s * expected)
        np.testing.assert_allclose(u, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
        move = u - u_above
        for A in rows:
            assert np.abs(A @ move).max() <= 1e-14 * np.linalg.norm(A, 2) * np.abs(move).max()


@pytest.mark.parametrize("diagonal", ["s I", "non-uniform"])
@pytest.mark.parametrize("tight", [False, True])
def test_a_posture_level_takes_the_general_routes_step(rng, tight, diagonal):
    # The shortcuts for a posture level below a certified one, rows s I (tasks) or a
    # non-uniform diagonal (solved on the complement of the rows above, without the basis
    # level_step builds), are the step of the general route, with or without the box: the
    # same level with one off-diagonal entry at 1e-300 (numerically nothing, structurally
    # not diagonal) goes through level_step and, in SNS, the task's saturation. With no
    # bound active, the non-uniform one is also the least squares on what the hands leave.
    n, solver = 23, ProjectionSolver()
    for _ in range(5):
        A0, b0, b1 = _wide(rng, 12, n, smallest=0.5), rng.normal(size=12), rng.normal(size=n)
        weights = np.ones(n) if diagonal == "s I" else rng.uniform(0.2, 2.0, n)
        u = {}
        for off in (0.0, 1e-300):
            A1 = np.diag(weights)
            A1[3, 7] = off
            box = np.full(n, 1.5 if tight else 1e12)
            problem = StackProblem(
                [_level("hands", A0, b0), _level("posture", A1, b1)], -box, box, np.ones(n), {}
            )
            result = solver.solve_problem(problem)
            u[off] = result.u
        if tight:
            assert np.abs(u[0.0]).max() <= 1.5 + 1e-9 and result.status != SolverStatus.OK
        np.testing.assert_allclose(u[0.0], u[1e-300], rtol=0, atol=1e-11 * np.abs(u[0.0]).max())
        if not tight:
            N, W = scipy.linalg.null_space(A0), np.diag(weights)
            expected = np.linalg.pinv(A0) @ b0
            expected += N @ np.linalg.lstsq(W @ N, b1 - W @ expected, rcond=None)[0]
            np.testing.assert_allclose(
                u[0.0], expected, rtol=0, atol=1e-10 * np.abs(expected).max()
            )


class _Box(Limit):
    """A fixed velocity box (test helper)."""

    name = "box"

    def __init__(self, lower: np.ndarray, upper: np.ndarray) -> None:
        self.lower, self.upper = lower, upper

    def bounds(self, state, dt):
        return Bounds(self.lower, self.upper)


def test_no_saturation_when_the_whole_stack_fits_the_box(humanoid, rng):
    """A bound that the first level's own solution crosses but the full stack's solution
    respects changes nothing: the answer is the unsaturated one (saturating the first level
    would give up a direction the second level needs, and made the carry chatter)."""
    nu = humanoid.nu
    L, R = hands(humanoid)
    posture = PostureTask(humanoid, kp=5.0)
    found = 0
    for q in configurations(humanoid, rng, 20):
        state = humanoid.update(q)
        near_targets(humanoid, state, (L, R), rng)
        posture.set_target(humanoid.joint_positions(humanoid.random_configuration(rng, margin=0.2)))
        inf = np.full(nu, np.inf)
        first = ProjectionSolver().solve(Stack(humanoid, [[L, R]], [_Box(-inf, inf)]), state, DT).u
        stack = Stack(humanoid, [[L, R], [posture]], [_Box(-inf, inf)])
        whole = ProjectionSolver().solve(stack, state, DT).u
        j = int(np.argmax(whole - first))
        if whole[j] - first[j] < 1e-2:
            continue
        lower = -inf.copy()
        lower[j] = 0.5 * (first[j] + whole[j])  # crossed by the first level, not by the sum
        boxed = Stack(humanoid, [[L, R], [posture]], [_Box(lower, inf)])
        result = ProjectionSolver().solve(boxed, state, DT)
        np.testing.assert_allclose(result.u, whole, atol=1e-9)
        assert result.status == SolverStatus.OK
        found += 1
    assert found >= 5


def _hands_problem(robot, seed=5):
    q = robot.random_configuration(np.random.default_rng(seed), margin=0.15)
    state = robot.update(q)
    L, R = hands(robot)
    near_targets(robot, state, (L, R), np.random.default_rng(seed + 1))
    J = np.vstack([t.compute(state).J for t in (L, R)])
    v = np.concatenate([t.compute(state).v for t in (L, R)])
    return state, (L, R), J, v


def test_a_weight_common_to_a_level_changes_nothing(humanoid):
    """The damping is decided on the rows divided by sqrt(lightest task weight): far from a
    singularity (smallest singular value 0.08 here) the answer is the plain pseudo-inverse
    however small the level's common weight (weight 1e-2 damped 54 % of the task away)."""
    state, (L, R), J, v = _hands_problem(humanoid)
    assert np.linalg.svd(J, compute_uv=False)[-1] > 0.05
    exact = np.linalg.pinv(J) @ v
    for w in (1.0, 1e-2, 1e-4):
        L.weight = R.weight = w
        u = ProjectionSolver().solve(Stack(humanoid, [Level([L, R])], []), state, DT).u
        assert np.linalg.norm(u - exact) < 1e-9 * np.linalg.norm(exact), w


@pytest.mark.parametrize("w_waist", [1.0, 10.0, 100.0])
def test_a_heavier_task_does_not_make_a_lighter_one_singular(humanoid, w_waist):
    """The hands beside a task holding the waist, 100 times heavier: a consistent level, so
    the weighted least squares meets the hands exactly; judged in the heavy task's units, the
    hands' directions would fall below eps and lose half of the task."""
    state, (L, R), J, v = _hands_problem(humanoid)
    waist = PostureTask(humanoid, "waist", kp=1.0, weight=w_waist)
    waist.set_target(state.joint_positions()[humanoid.group("waist").indices])
    stack = Stack(humanoid, [Level([L, R, waist])], [])
    u = ProjectionSolver().solve(stack, state, DT).u
    assert np.linalg.norm(J @ u - v) < 1e-9 * np.linalg.norm(v)


@pytest.mark.parametrize("w_posture", [4e-4, 1e-4, 1e-5])
def test_a_low_weight_regulariser_does_not_pull_the_hands_off(humanoid, w_posture):
    """Hands and a posture regulariser in one level: only the directions the level barely
    moves (singular value below eps, here the posture's) are damped, so the hands track as in
    the weighted least squares (before, the whole level was damped and the hands missed by
    more as the posture's weight went down: 3.7e-2 against 3.2e-4 at 1e-5)."""
    state, (L, R), J, v = _hands_problem(humanoid)
    posture = PostureTask(humanoid, kp=1.0, weight=w_posture)
    posture.set_target(
        humanoid.joint_positions(
            humanoid.random_configuration(np.random.default_rng(7), margin=0.2)
        )
    )
    stack = Stack(humanoid, [Level([L, R, posture])], [])
    p = stack.evaluate(state, DT)
    lstsq = p.to_u(np.linalg.lstsq(p.levels[0].A, p.levels[0].b, rcond=None)[0])
    u = ProjectionSolver().solve(stack, state, DT).u
    best = np.linalg.norm(J @ lstsq - v)
    assert np.linalg.norm(J @ u - v) <= 1.05 * best + 1e-12


def test_the_unsaturated_solution_starts_from_zero_when_the_box_excludes_it(humanoid):
    """A joint 0.1 mrad past its limit: the box excludes u = 0. The plain pseudo-inverse J+ v
    fits the box, so it is the answer (it was J+ v + (I - J+ J) clip(0, box))."""
    rng = np.random.default_rng(1)
    hi = humanoid.position_limits[1]
    j = humanoid.index("left_shoulder_flexion")
    iq = humanoid.model.joints[humanoid.model.getJointId("left_shoulder_flexion")].idx_q
    tested = 0
    for _ in range(50):
        q = humanoid.random_configuration(rng, margin=0.2)
        q[iq] = hi[j] + 1e-4
        state = humanoid.update(q)
        L, R = hands(humanoid)
        near_targets(humanoid, state, (L, R), rng)
        stack = Stack(
            humanoid, [Level([L, R])], [JointPositionLimits(humanoid), VelocityLimits(humanoid)]
        )
        blo, bhi = box(stack, state)
        assert not blo[j] <= 0.0 <= bhi[j]
        J = np.vstack([t.compute(state).J for t in (L, R)])
        v = np.concatenate([t.compute(state).v for t in (L, R)])
        exact = np.linalg.pinv(J) @ v
        inside = np.all(exact >= blo) and np.all(exact <= bhi)
        if not inside or np.linalg.svd(J, compute_uv=False)[-1] < 0.05:
            continue
        for solver in (ProjectionSolver(), ProjectionSolver(saturate=False)):
            assert np.linalg.norm(solver.solve(stack, state, DT).u - exact) < 1e-9
        tested += 1
    assert tested >= 3


PARAMETERS = ("damping", "singular_threshold", "rank_tolerance", "tolerance")


@pytest.mark.parametrize("name", PARAMETERS)
def test_non_finite_parameters_are_refused(name):
    from wholebody.errors import SolverError

    with pytest.raises(SolverError, match=f"{name} must be a finite float"):
        ProjectionSolver(**{name: float("nan")})
    solver = ProjectionSolver()
    before = getattr(solver, name)
    for bad in (float("inf"), -1.0, "x"):  # checked when set, the setting kept
        with pytest.raises(SolverError, match=name):
            setattr(solver, name, bad)
    assert getattr(solver, name) == before
    setattr(solver, name, 0.5)
    assert solver.parameters()[list(PARAMETERS).index(name)] == 0.5
