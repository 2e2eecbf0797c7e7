"""The hierarchical QP backend against an independent certificate of lexicographic optimality.

The reference is not another solver but the optimality conditions themselves: ``x`` solves
level k of the lexicographic problem (minimise ``||A_k x - b_k||`` over the box and the optimal
sets of the levels above, ``A_j x = A_j x*``) exactly when the gradient
``A_k^T (A_k x - b_k)`` is a combination of the rows ``A_j`` (j < k) and of the active bounds
with multipliers of the right sign (KKT; sufficient for a convex problem). That is checked with
a bounded least squares (scipy's BVLS) per level, and once more for the final minimum-norm
choice. On synthetic stacks (rank-deficient levels, tight boxes, a box excluding 0) and on the
robot's stack. Then the properties the controller relies on: strict priority, redundant
levels, inequality rows, infeasibility and failure reporting, out-of-limits recovery, warm
start.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from wholebody.errors import SolverError
from wholebody.kernels.hqp_state import S_DEFER_M
from wholebody.solvers import Level, SolverStatus, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.qp import ENGINES, QPStatus, available_engines, make_engine
from wholebody.solvers.stack import LevelProblem, StackProblem
from wholebody.tasks import (
    ArmPotentialEnergy,
    FrameTask,
    JointLimitAvoidance,
    JointPositionLimits,
    PostureTask,
    RelativeFrameTask,
    Task,
    TaskRows,
    VelocityLimits,
)
from wholebody.tasks.inequality import FrameHalfSpace

DT = 0.01
ENGINE_NAMES = [e for e in ENGINES if e in available_engines()]


# ---------------------------------------------------------------------- the certificate
def kkt_residuals(levels, lower, upper, x, act=1e-7):
    """Relative KKT residual of each level, and of the final minimum-norm choice."""
    n = x.size
    lo_act = np.flatnonzero(x <= lower + act)
    up_act = np.flatnonzero(x >= upper - act)
    B = np.zeros((n, lo_act.size + up_act.size))
    B[lo_act, np.arange(lo_act.size)] = -1.0
    B[up_act, lo_act.size + np.arange(up_act.size)] = 1.0
    out, E = [], np.zeros((0, n))
    for A, b in [*levels, (np.eye(n), np.zeros(n))]:
        g = A.T @ (A @ x - b)
        K = np.hstack([E.T, B])
        if K.shape[1]:
            lb = np.r_[np.full(E.shape[0], -np.inf), np.zeros(B.shape[1])]
            fit = lsq_linear(K, -g, bounds=(lb, np.inf), method="bvls", tol=1e-14)
            res = np.linalg.norm(K @ fit.x + g)
        else:
            res = np.linalg.norm(g)
        out.append(res / max(1.0, np.linalg.norm(A.T @ b)))
        E = np.vstack([E, A])
    return np.array(out)


def synthetic(rng, n=8, box=0.5, shift=False):
    """A random 3-level stack: a rank-deficient level (duplicated rows), a conflicting one and
    an objective-like identity level; box of half-width ``box`` (shifted off 0 if asked)."""
    A1 = rng.normal(size=(3, n))
    A1 = np.vstack([A1, A1[:1] * 2.0])  # redundant row, consistent right-hand side
    b1 = rng.normal(size=3) * 2.0
    b1 = np.r_[b1, 2.0 * b1[0]]
    A2 = rng.normal(size=(4, n))
    b2 = rng.normal(size=4) * 2.0
    A3 = np.eye(n) * 0.5
    b3 = rng.normal(size=n)
    levels = []
    for i, (A, b) in enumerate(((A1, b1), (A2, b2), (A3, b3))):
        if i < 2:
            rows = {"t1": slice(0, 2), "t2": slice(2, A.shape[0])}
        else:
            rows = {"objectives": slice(0, n)}
        levels.append(
            LevelProblem(
                f"level {i}",
                A,
                b,
                np.zeros((0, n)),
                np.zeros(0),
                np.zeros(0),
                rows,
                {},
                0.5 if i == 2 else 0.0,
            )
        )
    centre = rng.uniform(-0.4, 0.4, n) if shift else np.zeros(n)
    lower = centre - box * rng.uniform(0.2, 1.0, n)
    upper = centre + box * rng.uniform(0.2, 1.0, n)
    if shift:  # some entries must move: 0 is outside the box
        lower[0], upper[0] = 0.2, 0.4
    return StackProblem(levels, lower, upper, np.ones(n), {})


def equalities(problem):
    return [(lv.A, lv.b) for lv in problem.levels]


# ---------------------------------------------------------------------- engines
@pytest.mark.parametrize("name", ENGINE_NAMES)
def test_engine_solves_a_box_qp_and_warm_starts(name, rng):
    eng, cold = make_engine(name), make_engine(name, warm_start=False)
    ref = make_engine("proxsuite" if name == "daqp" else "daqp", warm_start=False)  # another
    n = 12
    M = rng.normal(size=(20, n))
    for _ in range(15):
        M += 0.05 * rng.normal(size=M.shape)  # a slowly changing problem, same structure
        H = M.T @ M + 1e-3 * np.eye(n)
        g = rng.normal(size=n) * 5
        C = rng.normal(size=(3, n))
        lo, hi = -np.ones(3), np.r_[1.0, 1.0, np.inf]
        lb, ub = -0.3 * np.ones(n), 0.3 * np.ones(n)
        exact = ref.solve(H, g, C, lo, hi, lb, ub)
        for e in (eng, cold):
            sol = e.solve(H, g, C, lo, hi, lb, ub)
            assert sol.status == QPStatus.SOLVED, sol.message
            np.testing.assert_allclose(sol.x, exact.x, atol=1e-5)
    assert eng.setups == 1  # the workspace was reused


@pytest.mark.parametrize("name", ENGINE_NAMES)
def test_engine_edge_cases_are_statuses_not_crashes(name):
    """No rows and no box (twice: setup, then update); crossed bounds; inconsistent rows."""
    eng, g = make_engine(name), np.array([1.0, -2.0, 3.0])
    none = np.zeros(0)
    for _ in range(2):
        sol = eng.solve(np.eye(3), g, np.zeros((0, 3)), none, none)
        assert sol.status == QPStatus.SOLVED
        np.testing.assert_allclose(sol.x, -g, atol=1e-6)
    C, box = np.ones((1, 3)), (-np.ones(3), np.ones(3))
    crossed = make_engine(name).solve(
        np.eye(3), g, C, [1.0], [2.0], np.r_[0.5, -1, -1], np.r_[0.0, 1, 1]
    )
    assert crossed.status == QPStatus.INFEASIBLE
    # sum(x) in [5, 6] with |x_i| <= 1: no solution (proxsuite stops at its iteration limit)
    far = make_engine(name).solve(np.eye(3), g, C, np.array([5.0]), np.array([6.0]), *box)
    assert far.status == QPStatus.INFEASIBLE, far.message


def test_unknown_engine_is_a_clear_error():
    with pytest.raises(SolverError, match="unknown QP engine 'gurobi'"):
        HierarchicalQPSolver("gurobi")
    with pytest.raises(SolverError, match="tolerance"):
        HierarchicalQPSolver(tolerance=0.0)
    assert HierarchicalQPSolver().in_kernel and not HierarchicalQPSolver("proxsuite").in_kernel


@pytest.mark.parametrize(
    ("engine", "good"), [("daqp", "primal_tol"), ("proxsuite", "eps_abs"), ("osqp", "eps_abs")]
)
def test_a_misspelt_engine_setting_is_refused_on_construction(engine, good):
    """It was accepted, then daqp ignored it, osqp failed every solve and proxsuite raised
    out of solve()."""
    pytest.importorskip(engine)
    HierarchicalQPSolver(engine, engine_settings={good: 1e-8})
    with pytest.raises(SolverError, match=f"{engine}: (unknown|Unrecognized) setting.*{good}s"):
        HierarchicalQPSolver(engine, engine_settings={good + "s": 1e-8})


def test_engine_settings_that_the_engines_take_are_accepted():
    """osqp takes aliases and settings it does not list as attributes."""
    pytest.importorskip("osqp")
    for settings in ({"polish": True}, {"solver_type": "direct"}, {"cg_preconditioner": None}):
        HierarchicalQPSolver("osqp", engine_settings=settings)
    with pytest.raises(SolverError, match="warm_start argument"):
        HierarchicalQPSolver("osqp", engine_settings={"warm_starting": False})
    HierarchicalQPSolver("proxsuite", engine_settings={"update_preconditioner": False})


# ---------------------------------------------------------------------- lexicographic optimum
@pytest.mark.parametrize("shift", [False, True])
def test_lexicographic_optimum_on_synthetic_stacks(rng, shift):
    solver = HierarchicalQPSolver()
    with_qp = 0
    for _ in range(40):
        problem = synthetic(rng, box=rng.choice([0.3, 1.0, 5.0]), shift=shift)
        result = solver.solve_problem(problem)
        x = result.u
        assert np.all(np.isfinite(x))
        assert np.all(x >= problem.lower) and np.all(x <= problem.upper)
        kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, x)
        assert kkt.max() < 1e-6, kkt
        with_qp += any(rep.qp for rep in solver.levels)
    assert with_qp >= 10  # the box mattered in many of them


@pytest.mark.parametrize("name", [e for e in ENGINE_NAMES if e != "daqp"])
def test_other_engines_reach_the_same_optimum_or_report(name, rng):
    """proxsuite and osqp are first-order/proximal: looser, and allowed to fail, but never
    outside the box or NaN, and a failure is reported as FAILED."""
    solver = HierarchicalQPSolver(name)
    good = 0
    for _ in range(25):
        problem = synthetic(rng, box=rng.choice([0.3, 1.0]))
        result = solver.solve_problem(problem)
        assert np.all(np.isfinite(result.u))
        assert np.all(result.u >= problem.lower) and np.all(result.u <= problem.upper)
        kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, result.u)
        good += kkt.max() < 1e-4
        if result.status == SolverStatus.FAILED:
            assert name in result.message
    assert good >= 20


def test_without_active_bounds_it_is_the_recursive_pseudo_inverse(rng):
    problem = synthetic(rng, box=1e6)
    solver = HierarchicalQPSolver()
    result = solver.solve_problem(problem)
    assert result.status == SolverStatus.OK and not any(r.qp for r in solver.levels)
    x, P = np.zeros(8), np.eye(8)
    for A, b in equalities(problem):
        M = A @ P
        x = x + np.linalg.pinv(M, rcond=1e-9) @ (b - A @ x)
        P = P - np.linalg.pinv(M, rcond=1e-9) @ M
    np.testing.assert_allclose(result.u, x, atol=1e-9)


@pytest.mark.parametrize("kappa", [1.0, 3e2, 3e3, 3e4, 1e7])
def test_a_tall_level_is_solved_accurately_at_every_condition_number(rng, kappa):
    # A full-column-rank level with more rows than unknowns, unconstrained in effect: the
    # well-conditioned ones are solved by their normal equations (refined above 1e3), the others
    # by a QR; both must match an SVD's least squares to within 10x of the problem's own
    # sensitivity to rounding, eps (kappa + kappa^2 tan(theta)) with theta the angle between b
    # and the range of A, plus the eps kappa^2 of the unrefined normal equations at kappa <= 1e3
    # (unrefined at kappa 3e3 they are 3e3 times this).
    solver = HierarchicalQPSolver()
    worst = 0.0
    for trial in range(40):
        m, n = (30, 12) if trial % 2 else (4, 2)
        U, _ = np.linalg.qr(rng.normal(size=(m, n)))
        V, _ = np.linalg.qr(rng.normal(size=(n, n)))
        if trial % 4 < 2:  # singular values spread evenly, or one small one
            spread = np.logspace(0, -np.log10(kappa), n)
        else:
            spread = np.r_[np.ones(n - 1), 1.0 / kappa]
        A = (U * spread) @ V.T
        for b in (A @ rng.normal(size=n), rng.normal(size=m)):  # consistent, then not
            level = LevelProblem(
                "tall", A, b, np.zeros((0, n)), np.zeros(0), np.zeros(0), {"t": slice(0, m)}
            )
            box = np.full(n, 1e12)
            u = solver.solve_problem(StackProblem([level], -box, box, np.ones(n), {})).u
            exact = np.linalg.lstsq(A, b, rcond=None)[0]
            fit = A @ exact
            tan = np.linalg.norm(b - fit) / np.linalg.norm(fit)
            sensitivity = np.finfo(float).eps * (kappa + kappa**2 * (tan + (kappa <= 1e3)))
            worst = max(worst, np.linalg.norm(u - exact) / np.linalg.norm(exact) / sensitivity)
    assert worst <= 10.0


@pytest.mark.parametrize(
    "kappa",
    [
        1.0,
        3e2,
        pytest.param(3e3, marks=pytest.mark.slow),
        pytest.param(3e4, marks=pytest.mark.slow),
    ],
)
def test_a_wide_level_then_a_diagonal_one_are_exact_at_every_condition_number(rng, kappa):
    # A wide first level of full row rank (solved by the Cholesky factor of M M^T where that
    # is accurate, its null space then made only if a stage needs it) above a diagonal level
    # (a posture in its metric: solved on that null space without a basis), and a third
    # level below them, with and without the box binding: the recursive pseudo-inverse where
    # no bound is active, the levels' optimality conditions everywhere.
    solver = HierarchicalQPSolver()
    n, qp, deferred = 9, 0, 0
    for trial in range(24):
        U, _ = np.linalg.qr(rng.normal(size=(4, 4)))
        V, _ = np.linalg.qr(rng.normal(size=(n, 4)))
        A1 = (U * np.logspace(0, -np.log10(kappa), 4)) @ V.T
        A2 = np.diag(rng.uniform(0.02, 1.0, n)) if trial % 3 else rng.normal(size=(2, n))
        A3 = 0.1 * np.eye(n)
        rows = [(A1, rng.normal(size=4)), (A2, rng.normal(size=len(A2))), (A3, rng.normal(size=n))]
        empty = (np.zeros((0, n)), np.zeros(0), np.zeros(0))
        levels = [
            LevelProblem(f"l{k}", A, b, *empty, {"t": slice(0, len(b))})
            for k, (A, b) in enumerate(rows)
        ]
        box = 1e6 if trial % 2 else 0.3
        lower, upper = -np.full(n, box), np.full(n, box)
        if trial % 4 == 1:  # 0 outside the box, the first level's solution p inside it
            p = np.linalg.pinv(A1) @ rows[0][1]
            lower[0], upper[0] = (0.5 * p[0], box) if p[0] > 0 else (-box, 0.5 * p[0])
        problem = StackProblem(levels, lower, upper, np.ones(n), {})
        u = solver.solve_problem(problem).u
        qp += any(r.qp for r in solver.levels)
        deferred += solver._workspace.state[S_DEFER_M] > 0  # the first level took the route
        kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, u)
        assert kkt.max() < 1e-6, (trial, kkt)
        if trial % 4 == 3:  # the recursive pseudo-inverse on orthonormal null-space bases (SVD)
            x, Z = np.zeros(n), np.eye(n)
            for A, b in rows:
                _, sv, Vt = np.linalg.svd(A @ Z)
                rank = int(np.sum(sv > 1e-9 * max(1.0, np.linalg.norm(A, 2))))
                x = x + Z @ np.linalg.pinv(A @ Z, rcond=1e-9 / kappa) @ (b - A @ x)
                Z = Z @ Vt[rank:].T
            assert np.abs(u - x).max() <= 1e-12 * kappa * max(1.0, np.abs(x).max())
    assert qp >= 6
    assert deferred >= (6 if kappa <= 3e3 else 0), deferred  # (where its candidate held)


# ---------------------------------------------------------------------- the robot
def hands(robot, kp=10.0):
    return FrameTask(robot, "left_tool", kp=kp), FrameTask(robot, "right_tool", kp=kp)


def limits(robot):
    return [JointPositionLimits(robot), VelocityLimits(robot)]


def set_targets(state, tasks, rng, reach):
    for t in tasks:
        T = state.pose(t.frame).copy()
        T[:3, 3] += rng.uniform(-reach, reach, 3)
        t.set_target(T)


def test_robot_stack_is_lexicographically_optimal(humanoid, rng):
    L, R = hands(humanoid)
    energy = [ArmPotentialEnergy(humanoid, "left", 0.1), ArmPotentialEnergy(humanoid, "right", 0.1)]
    stack = Stack(
        humanoid,
        [[L, R], Level(energy, gain=0.5)],
        limits(humanoid),
        metric=np.r_[np.full(4, 0.01), np.ones(humanoid.nu - 4)],
    )
    solver = HierarchicalQPSolver()
    bound_limited = 0
    for _ in range(30):
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.02))
        set_targets(state, (L, R), rng, reach=rng.choice([0.02, 0.3]))
        result = solver.solve(stack, state, DT)
        problem = stack.evaluate(state, DT)
        x = result.u / problem.scale
        assert np.all(x >= problem.lower) and np.all(x <= problem.upper)
        kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, x)
        assert kkt.max() < 1e-6, kkt
        bound_limited += result.status == SolverStatus.INFEASIBLE
    assert bound_limited >= 1


def test_closed_loop_reach_from_the_singular_start_is_optimal_with_every_engine(humanoid):
    """The paper's stack driving both hands from the neutral posture (arms hanging, singular)
    to far targets, as in ``benchmarks/convergence.py``: at every state of the run, every
    engine's answer is lexicographically optimal and none fails. The objectives' QP there has
    one free direction (the wheels' internal mode) and joints on their bounds whose rows the
    free direction moves only by round-off (1e-16): bounded, two of them pinned it to 0, and
    proxsuite declared the QP infeasible (15 % of the steps), daqp returned y = 0."""
    from wholebody.presets import paper_stack

    L, R = hands(humanoid, kp=20.0)
    stack = paper_stack(humanoid, [L, R])
    rng = np.random.default_rng(0)
    goal = humanoid.random_configuration(rng, margin=0.05, base_range=0.5)
    for t in (L, R):
        t.set_target(humanoid.frame_pose(goal, t.frame))
    solvers = {e: HierarchicalQPSolver(engine=e) for e in ENGINE_NAMES if e != "osqp"}
    q = humanoid.neutral()
    for step in range(60):
        state = humanoid.update(q)
        problem = stack.evaluate(state, DT)
        results = {e: s.solve(stack, state, DT) for e, s in solvers.items()}
        for e, result in results.items():
            assert result.status != SolverStatus.FAILED, (e, step, result.message)
            x = result.u / problem.scale
            kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, x)
            assert kkt.max() < 1e-6, (e, step, kkt)
        q = humanoid.integrate(q, results["daqp"].u, DT)


def test_strict_priority(humanoid, rng):
    """The hands' residual does not change when lower levels are added, removed or made to
    conflict, also when bounds are active."""
    L, R = hands(humanoid, kp=30.0)
    energy = Level([ArmPotentialEnergy(humanoid, "left", 0.1)], gain=2.0)
    solver = HierarchicalQPSolver()
    for reach in (0.02, 0.5):
        for _ in range(5):
            state = humanoid.update(humanoid.random_configuration(rng, margin=0.05))
            set_targets(state, (L, R), rng, reach)
            posture = PostureTask(humanoid, target=rng.uniform(-1, 1, humanoid.nu), kp=50.0)
            stacks = [
                [[L, R]],
                [[L, R], energy],
                [[L, R], [posture]],
                [[L, R], [posture], energy],
                [[L, R], Level([posture, *energy.entries])],
            ]
            res = [solver.solve(Stack(humanoid, s, limits(humanoid)), state, DT) for s in stacks]
            top = [r.level_residuals[0] for r in res]
            assert max(top) - min(top) <= 1e-8 * (1 + top[0]), top
            if reach == 0.02:
                assert max(top) < 1e-8  # the hands are met exactly


def test_redundant_level_solves(humanoid, rng):
    """Both hands, the closed chain between them and an identical duplicate of a hand task:
    18 + 6 rows of rank 12 in one level."""
    L, R = hands(humanoid)
    chain = RelativeFrameTask(humanoid, "left_tool", "right_tool", name="closed_chain")
    twin = FrameTask(humanoid, "left_tool", kp=10.0, name="left_twin")
    energy = Level(
        [ArmPotentialEnergy(humanoid, "left", 0.1), ArmPotentialEnergy(humanoid, "right", 0.1)],
        gain=0.5,
    )
    stack = Stack(
        humanoid, [[L, R, chain, twin], energy, [JointLimitAvoidance(humanoid)]], limits(humanoid)
    )
    solver = HierarchicalQPSolver()
    for reach in (0.01, 0.3):
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.05))
        set_targets(state, (L, R), rng, reach)
        twin.set_target(L.target)
        TL, TR = L.target, R.target
        chain.set_target(np.linalg.solve(TL, TR))  # consistent with the hands' targets
        result = solver.solve(stack, state, DT)
        assert result.status != SolverStatus.FAILED, result.message
        assert np.all(np.isfinite(result.u))
        assert solver.levels[0].rank == 12
        assert solver.levels[2].free == 0  # the objective level used up the freedom
        assert result.task_residuals[L.name] == pytest.approx(
            result.task_residuals["left_twin"], abs=1e-9
        )
        if reach == 0.01:
            assert result.level_residuals[0] < 1e-8


def test_infeasible_level_is_named_and_the_answer_is_the_best_feasible(humanoid, rng):
    L, R = hands(humanoid, kp=10.0)
    stack = Stack(humanoid, [[L, R]], limits(humanoid))
    state = humanoid.update(humanoid.home())
    T = state.pose(L.frame).copy()
    T[:3, 3] += [0.0, 0.0, 2.0]  # 20 m/s asked of the left hand
    L.set_target(T)
    R.set_target(state.pose(R.frame))
    result = HierarchicalQPSolver().solve(stack, state, DT)
    problem = stack.evaluate(state, DT)
    lo, hi = problem.lower * problem.scale, problem.upper * problem.scale
    assert result.status == SolverStatus.INFEASIBLE
    assert ("level 0", L.name) in result.infeasible
    assert np.all(result.u >= lo) and np.all(result.u <= hi)
    assert result.active_bounds.size > 0
    # the best feasible answer: the KKT certificate of the level holds
    x = result.u / problem.scale
    assert kkt_residuals(equalities(problem), problem.lower, problem.upper, x).max() < 1e-6


class BrokenTask(Task):
    """Rows that turn NaN (a task evaluated at a singular point, say), or an infinite
    target, or a NaN Jacobian with a finite target."""

    name, weight = "broken", 1.0

    def __init__(self, kind: str = "nan") -> None:
        self.kind = kind

    @property
    def dim(self) -> int:
        return 2

    def compute(self, state):
        J = np.zeros((2, state.robot.nu))
        J[:, 6] = 1.0
        v = np.array([0.1, 0.0])
        if self.kind in ("nan", "nan_jacobian"):
            J[0, 5] = np.nan
        if self.kind == "nan":
            v[0] = np.nan
        if self.kind == "inf_target":
            v[0] = np.inf
        return TaskRows(J, v, np.ones(2))


@pytest.mark.parametrize("kind", ["nan", "inf_target", "nan_jacobian"])
def test_non_finite_level_is_reported_and_skipped(humanoid, rng, kind):
    L, R = hands(humanoid)
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.1))
    set_targets(state, (L, R), rng, 0.01)
    for levels, name in (
        ([[L, R], [BrokenTask(kind)], [PostureTask(humanoid)]], "level 1"),
        ([[BrokenTask(kind)], [L, R]], "level 0"),
    ):
        stack = Stack(humanoid, levels, limits(humanoid))
        result = HierarchicalQPSolver().solve(stack, state, DT)
        assert result.status == SolverStatus.FAILED
        assert (name, "broken") in result.infeasible and "broken" in result.message
        assert "non-finite rows" in result.message
        assert np.all(np.isfinite(result.u))
        good = 0 if name == "level 1" else 1
        assert result.level_residuals[good] < 1e-8  # the other levels were still solved


def test_inequality_task_keeps_the_hand_above_a_table(humanoid):
    """A half-space above the hands' level, the hand asked to go 20 cm below it: with the
    inequality on top the hand stops at the table; below the hand task it is ignored."""
    robot = humanoid
    q0 = robot.home()
    z0 = robot.frame_pose(q0, "left_tool")[2, 3]
    for order in ("table_first", "hand_first"):
        state = robot.update(q0)
        L = FrameTask(robot, "left_tool", kp=5.0, orientation=False)
        table = FrameHalfSpace(robot, "left_tool", [0, 0, 1], z0 - 0.05, gain=0.5, name="table")
        T = state.pose(L.frame).copy()
        T[2, 3] -= 0.2
        L.set_target(T)
        levels = [[table], [L]] if order == "table_first" else [[L], [table]]
        stack = Stack(robot, [*levels, [PostureTask(robot, kp=1.0)]], limits(robot))
        solver, q = HierarchicalQPSolver(), q0.copy()
        lowest = np.inf
        for _ in range(150):
            s = robot.update(q)
            result = solver.solve(stack, s, DT)
            assert np.all(np.isfinite(result.u))
            q = robot.integrate(q, result.u, DT)
            lowest = min(lowest, table.distance(robot.update(q)))
        if order == "table_first":
            assert lowest > -1e-3  # never through the table (first order, one step at most)
            assert table.distance(robot.update(q)) < 0.01  # and resting on it
        else:
            assert lowest < -0.1


def test_out_of_limits_start_recovers(humanoid, rng):
    """Joints 0.1 rad outside their limits are steered back: the violation never grows, and
    is below 1e-6 rad within 25 steps of 10 ms. Never NaN, never beyond the velocity limits.

    The box (JointPositionLimits, gain 0.5) asks a joint outside its limits to cover half of
    the remaining distance per step once the velocity limit allows it (before that it moves
    back at full speed): the QP honours exactly that, so the violation first shrinks by
    ``v_max dt`` per step, then halves each step. 0.1 rad at 1 rad/s: 8 steps, then 2e-2 rad
    halved 15 times."""
    robot = humanoid
    lower, upper = robot.position_limits
    L, R = hands(robot)
    stack = Stack(
        robot, [[L, R], Level([ArmPotentialEnergy(robot, "left", 0.1)], gain=0.5)], limits(robot)
    )

    def violation(q):
        jp = robot.joint_positions(q)
        return float(np.max(np.maximum(lower - jp, jp - upper)[np.isfinite(lower)]))

    for _ in range(3):
        q = robot.random_configuration(rng, margin=0.1)
        jp = robot.joint_positions(q)
        idx = rng.choice(np.flatnonzero(np.isfinite(lower)), size=4, replace=False)
        jp[idx] = np.where(rng.random(4) < 0.5, lower[idx] - 0.1, upper[idx] + 0.1)
        for i, j in enumerate(robot.actuated_joints):
            if np.isfinite(lower[i]):
                q[robot.model.joints[robot.model.getJointId(j)].idx_q] = jp[i]
        assert violation(q) == pytest.approx(0.1)
        state = robot.update(q)
        for t in (L, R):  # the hands want to stay where they are
            t.set_target(state.pose(t.frame))
        solver = HierarchicalQPSolver()
        history = [violation(q)]
        for _ in range(25):
            state = robot.update(q)
            result = solver.solve(stack, state, DT)
            assert np.all(np.isfinite(result.u))
            assert np.all(np.abs(result.u) <= robot.velocity_limits + 1e-9)
            q = robot.integrate(q, result.u, DT)
            history.append(violation(q))
        assert np.all(np.diff(history) <= 1e-12), history
        assert history[-1] < 1e-6, history


def test_warm_start_changes_nothing_but_time(humanoid, rng):
    """proxsuite keeps a workspace per level and warm-starts it (daqp is called from the
    kernel, cold: its answers do not depend on earlier steps)."""
    L, R = hands(humanoid, kp=30.0)
    stack = Stack(
        humanoid, [[L, R], Level([ArmPotentialEnergy(humanoid, "left", 0.1)])], limits(humanoid)
    )
    warm, cold = (
        HierarchicalQPSolver("proxsuite"),
        HierarchicalQPSolver("proxsuite", warm_start=False),
    )
    q = humanoid.random_configuration(rng, margin=0.05)
    state = humanoid.update(q)
    set_targets(state, (L, R), rng, 0.3)
    qps = 0
    for _ in range(30):
        state = humanoid.update(q)
        a, b = warm.solve(stack, state, DT), cold.solve(stack, state, DT)
        # the same optimum: equal level residuals to proxsuite's accuracy on these levels (its
        # level residuals reach 1e-6); u itself agrees to the engines' tolerance (a cascade
        # fixes level 1 to its tolerance, which the lower level then exploits)
        np.testing.assert_allclose(a.level_residuals, b.level_residuals, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(a.u, b.u, atol=1e-3)
        qps += any(r.qp for r in warm.levels)
        q = humanoid.integrate(q, a.u, DT)
    assert qps >= 5
    assert len(warm._engines) and warm._engines[0].setups <= 2


def test_result_fields(humanoid, rng):
    L = FrameTask(humanoid, "left_tool", kp=10.0, weight=4.0)
    stack = Stack(humanoid, [[L], [PostureTask(humanoid, kp=0.2)]], limits(humanoid))
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.1))
    set_targets(state, (L,), rng, 0.01)
    result = HierarchicalQPSolver().solve(stack, state, DT)
    rows = L.compute(state)
    assert result.task_residuals[L.name] == pytest.approx(
        np.linalg.norm(rows.J @ result.u - rows.v), abs=1e-10
    )
    post = PostureTask(humanoid, kp=0.2)  # unweighted
    pr = post.compute(state)
    assert result.task_residuals["posture"] == pytest.approx(
        np.linalg.norm(pr.J @ result.u - pr.v), rel=1e-9
    )
    assert result.level_residuals.shape == (2,) and result.scale.tolist() == [1.0, 1.0]
    assert result.solve_time > 0 and "daqp" in result.message
    assert result.status in (SolverStatus.OK, SolverStatus.BOUNDS_ACTIVE)


@pytest.mark.parametrize("engine", [e for e in ("daqp", "proxsuite") if e in ENGINE_NAMES])
def test_the_cascade_finds_the_top_levels_optimum_where_tikhonov_picks_another_face(
    humanoid, engine
):
    """A state where the Tikhonov term of the level QP lands on another face of the box than
    the exact optimum: the cascade must still meet the hands (residual ~1e-9), not report
    them infeasible at 3e-5; the energy level's residual is its lexicographic optimum (KKT)."""
    rng = np.random.default_rng(1)
    L, R = FrameTask(humanoid, "left_tool", kp=10.0), FrameTask(humanoid, "right_tool", kp=10.0)
    energy = [ArmPotentialEnergy(humanoid, arm, 0.1) for arm in ("left", "right")]
    stack = Stack(humanoid, [[L, R], Level(energy, gain=0.5)], limits(humanoid))
    for _ in range(5):  # the fifth of these random states
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.02))
        for t in (L, R):
            T = state.pose(t.frame).copy()
            T[:3, 3] += rng.uniform(-0.3, 0.3, 3)
            t.set_target(T)
    solver = HierarchicalQPSolver(engine)
    cascade = solver.solve(stack, state, DT)
    assert solver.levels[0].qp  # the bounds bite at the top level
    assert cascade.level_residuals[0] < 1e-7 and cascade.status == SolverStatus.BOUNDS_ACTIVE
    problem = stack.evaluate(state, DT)
    x = cascade.u / problem.scale
    kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, x)
    assert kkt.max() < 1e-5, kkt
