"""The generic QP engine ``"qpsolvers:<solver>"``: the engine contract mapped onto qpsolvers,
and the hierarchical QP served by a qpsolvers solver, certified by the same KKT conditions
as with the daqp engine (``test_hqp.kkt_residuals``) and agreeing with its answers."""

from __future__ import annotations

import numpy as np
import pytest
from test_hqp import DT, equalities, hands, kkt_residuals, limits, set_targets, synthetic

from wholebody.errors import SolverError
from wholebody.solvers import Level, SolverStatus, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.qp import QPStatus, make_engine
from wholebody.solvers.qpsolvers_engine import qpsolvers_engines
from wholebody.tasks import ArmPotentialEnergy, PostureTask
from wholebody.tasks.inequality import FrameHalfSpace

qpsolvers = pytest.importorskip("qpsolvers")

# exact solvers need a tight tolerance, as the built-in adapters set (qpsolvers' defaults
# are the solvers' own: proxqp's eps_abs 1e-3)
SETTINGS = {
    "qpsolvers:daqp": {"primal_tol": 1e-9},
    "qpsolvers:proxqp": {"eps_abs": 1e-9, "eps_rel": 0.0},
}
ENGINES = [e for e in SETTINGS if e in qpsolvers_engines()]
EXACT = "qpsolvers:daqp"  # an active-set solver: daqp's answers to round-off, as the adapter
if not ENGINES:  # pragma: no cover - qpsolvers without daqp or proxqp
    pytest.skip("no daqp or proxqp for qpsolvers", allow_module_level=True)


def hqp(engine: str, **kwargs) -> HierarchicalQPSolver:
    return HierarchicalQPSolver(engine, engine_settings=SETTINGS[engine], **kwargs)


# ---------------------------------------------------------------------- the engine contract
@pytest.mark.parametrize("name", ENGINES)
def test_the_contract_maps_onto_qpsolvers(name, rng):
    """Two-sided, one-sided, equality and unbounded rows, a box with infinite entries and
    none: the same optimum as the daqp adapter."""
    eng = make_engine(name, **SETTINGS[name])
    ref = make_engine("daqp", warm_start=False)
    n = 6
    for trial in range(12):
        M = rng.normal(size=(9, n))
        H = M.T @ M + 1e-3 * np.eye(n)
        g = rng.normal(size=n) * 3
        C = rng.normal(size=(5, n))
        lo = np.array([-1.0, -np.inf, 0.3, -np.inf, -0.5])
        hi = np.array([1.0, 0.5, 0.3, np.inf, np.inf])  # (row 2: an equality, row 3: free)
        box = (-0.4 * np.ones(n), 0.4 * np.ones(n))
        if trial % 3 == 1:
            box = (np.r_[-np.inf, -0.4 * np.ones(n - 1)], np.r_[0.4 * np.ones(n - 1), np.inf])
        args = (H, g, C, lo, hi) if trial % 3 == 2 else (H, g, C, lo, hi, *box)
        exact = ref.solve(*args)
        sol = eng.solve(*args)
        assert exact.status == QPStatus.SOLVED, exact.message
        assert sol.status == QPStatus.SOLVED, sol.message
        np.testing.assert_allclose(sol.x, exact.x, atol=1e-6)


@pytest.mark.parametrize("name", ENGINES)
def test_engine_edge_cases_are_statuses_not_crashes(name):
    """No rows and no box (twice: setup, then update with the last answer as initvals);
    crossed bounds; inconsistent rows (told from a solver failure by a feasibility LP)."""
    eng, g = make_engine(name, **SETTINGS[name]), np.array([1.0, -2.0, 3.0])
    none = np.zeros(0)
    for _ in range(2):
        sol = eng.solve(np.eye(3), g, np.zeros((0, 3)), none, none)
        assert sol.status == QPStatus.SOLVED
        np.testing.assert_allclose(sol.x, -g, atol=1e-6)
    assert eng.setups == 1
    C, box = np.ones((1, 3)), (-np.ones(3), np.ones(3))
    crossed = eng.solve(np.eye(3), g, C, [1.0], [2.0], np.r_[0.5, -1, -1], np.r_[0.0, 1, 1])
    assert crossed.status == QPStatus.INFEASIBLE
    far = eng.solve(np.eye(3), g, C, np.array([5.0]), np.array([6.0]), *box)
    assert far.status == QPStatus.INFEASIBLE, far.message
    assert not np.any(np.isfinite(far.x))


def test_an_unknown_solver_or_setting_is_refused_on_construction():
    available = ", ".join(qpsolvers.available_solvers)
    with pytest.raises(
        SolverError,
        match=f"unknown qpsolvers solver 'no_such_solver'.*available_solvers here: {available}",
    ):
        HierarchicalQPSolver("qpsolvers:no_such_solver")
    with pytest.raises(SolverError, match="unknown qpsolvers solver ''"):
        make_engine("qpsolvers:")
    name = ENGINES[0]
    good = next(iter(SETTINGS[name]))
    with pytest.raises(SolverError, match=f"{name}: setting.*{good}s.*refused"):
        HierarchicalQPSolver(name, engine_settings={good + "s": 1e-9})
    assert qpsolvers_engines() == [f"qpsolvers:{s}" for s in qpsolvers.available_solvers]


# ---------------------------------------------------------------------- the hierarchy
@pytest.mark.parametrize("name", ENGINES)
def test_lexicographic_optimum_on_synthetic_stacks(rng, name):
    """test_hqp's synthetic stacks (rank-deficient levels, tight boxes, a box excluding 0):
    certified optimal, and the daqp engine's answer."""
    solver, ref = hqp(name), HierarchicalQPSolver()
    with_qp = 0
    for trial in range(30):
        problem = synthetic(rng, box=rng.choice([0.3, 1.0, 5.0]), shift=bool(trial % 2))
        result = solver.solve_problem(problem)
        x = result.u
        assert result.status != SolverStatus.FAILED, result.message
        assert np.all(x >= problem.lower) and np.all(x <= problem.upper)
        kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, x)
        assert kkt.max() < 1e-6, kkt
        np.testing.assert_allclose(x, ref.solve_problem(problem).u, atol=1e-6)
        with_qp += any(rep.qp for rep in solver.levels)
    assert with_qp >= 10  # the box mattered in many of them


@pytest.mark.parametrize("name", ENGINES)
def test_robot_stack_is_lexicographically_optimal(humanoid, rng, name):
    """test_hqp's robot stack (hands; arm energy; joint limits), certified, and a stack with
    inequality tasks at two levels (each hand above a table), at random states: the daqp
    engine's residuals, to its accuracy with an exact solver (proxqp's inequality levels
    are off by up to 1e-3, as with the proxsuite adapter, and the levels below inherit
    that: only the first level is compared)."""
    L, R = hands(humanoid)
    energy = [ArmPotentialEnergy(humanoid, "left", 0.1), ArmPotentialEnergy(humanoid, "right", 0.1)]
    stack = Stack(
        humanoid,
        [[L, R], Level(energy, gain=0.5)],
        limits(humanoid),
        metric=np.r_[np.full(4, 0.01), np.ones(humanoid.nu - 4)],
    )
    z0 = humanoid.frame_pose(humanoid.home(), "left_tool")[2, 3]
    tables = [
        FrameHalfSpace(humanoid, f, [0, 0, 1], z0 - 0.05, gain=0.5, name=f"table_{f}")
        for f in ("left_tool", "right_tool")
    ]
    tabled = Stack(
        humanoid,
        [[L, tables[0]], [R, tables[1]], [PostureTask(humanoid, kp=1.0)]],
        limits(humanoid),
    )
    solver, ref = hqp(name), HierarchicalQPSolver()
    bound_limited = 0
    for trial in range(40):
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.02))
        set_targets(state, (L, R), rng, reach=rng.choice([0.02, 0.3]))
        current = stack if trial % 2 else tabled
        result = solver.solve(current, state, DT)
        assert result.status != SolverStatus.FAILED, result.message
        problem = current.evaluate(state, DT)
        x = result.u / problem.scale
        assert np.all(x >= problem.lower) and np.all(x <= problem.upper)
        if current is stack:  # (the certificate knows equality levels only)
            kkt = kkt_residuals(equalities(problem), problem.lower, problem.upper, x)
            assert kkt.max() < 1e-6, kkt
        other = ref.solve(current, state, DT)
        levels, tol = (slice(None), 1e-7) if name == EXACT else (slice(0, 1), 1e-3)
        np.testing.assert_allclose(
            result.level_residuals[levels], other.level_residuals[levels], rtol=1e-6, atol=tol
        )
        bound_limited += result.status == SolverStatus.INFEASIBLE
    assert bound_limited >= 1
