"""Stacks found by fuzzing the HQP against an independent lexicographic reference (two
solvers, KKT-certified): each failed a promise of the module docstring before its fix."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.result import SolverStatus
from wholebody.solvers.stack import LevelProblem, StackProblem

# ruff: noqa: E501  (the fuzzed stacks' data, kept on one line per array)


def top_level_with_a_lower_level(seed: int = 1075) -> StackProblem:
    """Level 0: rank-1 equality rows and one inequality row; level 1: random rows; a box."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 12))
    m = int(rng.integers(1, 13))
    A = np.outer(rng.normal(size=m), rng.normal(size=n))
    b = rng.normal(size=m) * rng.choice([0.3, 1, 3])
    C = rng.normal(size=(1, n))
    hi = rng.normal(size=1) * rng.choice([0.3, 1, 3])
    L0 = LevelProblem(
        "L0", A, b, C, np.full(1, -np.inf), hi, {"t0": slice(0, m)}, {"i0": slice(0, 1)}
    )
    m1 = int(rng.integers(1, n + 1))
    L1 = LevelProblem(
        "L1",
        rng.normal(size=(m1, n)),
        rng.normal(size=m1),
        np.zeros((0, n)),
        np.zeros(0),
        np.zeros(0),
        {"t1": slice(0, m1)},
        {},
    )
    h = rng.uniform(0.1, 0.5, n) * rng.choice([0.3, 1, 3])
    return StackProblem([L0, L1], -h, h, np.ones(n), {})


def objective(lev: LevelProblem, x: np.ndarray) -> float:
    """sqrt(||A x - b||^2 + ||s||^2), s the least slack of the inequality rows."""
    r = lev.A @ x - lev.b
    Cx = lev.C @ x
    s = np.maximum(Cx - lev.upper, 0.0) + np.maximum(lev.lower - Cx, 0.0)
    return math.sqrt(r @ r + s @ s)


@pytest.mark.parametrize("engine", ["daqp", "proxsuite", "osqp"])
def test_the_cascade_removes_the_tikhonov_bias_of_a_level_with_inequality_rows(engine):
    """10 x1 = 10 and x2 >= 100 are met exactly at (1, 100); the Tikhonov term used to leave
    x2 = 99.99999 and the row reported INFEASIBLE."""
    lev = LevelProblem(
        "top",
        np.array([[10.0, 0.0]]),
        np.array([10.0]),
        np.array([[0.0, 1.0]]),
        np.array([100.0]),
        np.array([np.inf]),
        {"task": slice(0, 1)},
        {"above": slice(0, 1)},
    )
    problem = StackProblem([lev], np.full(2, -1000.0), np.full(2, 1000.0), np.ones(2), {})
    r = HierarchicalQPSolver(engine).solve_problem(problem)
    assert r.status == SolverStatus.OK and not r.infeasible
    assert r.u[0] == pytest.approx(1.0, abs=1e-8) and r.u[1] >= 100.0 - 1e-8


# fmt: off
def inherited_rows_off_by_round_off() -> StackProblem:
    """Fuzz seed 204: three levels, inequality rows inherited down."""
    n = 10
    levels = []
    levels.append(LevelProblem('L0', np.array([]).reshape(0, n), np.array([]), np.array([[1.096039412089566, 0.05691587474064322, -0.8391628657432598, -0.8221751342080243, 0.3325989942003731, -1.9280692858999664, 0.11209641208466647, -1.310405694834296, -0.8677925637577188, -0.40422157426117156]]).reshape(1, n), np.array([0.9032428496447734]), np.array([1.3080171131334075]), {}, {'i0': slice(0, 1, None)}, 0.0))
    levels.append(LevelProblem('L1', np.array([[2.921301596304578, 0.18532191955645536, -1.0425468370244437, -3.382833031322096, 4.0514227125968905, -3.0231020716267025, 1.793381234848084, 5.162794980279268, 0.050219947805589804, -4.710531214070736], [-3.276777663108734, -0.3663802314204625, -4.200258179090208, -9.896687741419258, 0.5110190033223702, -4.492175761325114, 3.0261592756536926, -2.3924649730023244, -7.121070193462943, 4.131226509495153], [5.842603192609156, 0.3706438391129107, -2.0850936740488875, -6.765666062644192, 8.102845425193781, -6.046204143253405, 3.586762469696168, 10.325589960558537, 0.10043989561117961, -9.421062428141472]]).reshape(3, n), np.array([-0.37581891855078875, 0.0002261807692221507, -0.7516378371015776]), np.array([[-0.3042966241007544, 0.7021518015544637, 0.26841658396666507, -1.6106439061795974, 1.2900964325333935, 1.0542424814624531, -0.7940502423513628, 0.015576879289825466, -0.47331825371290354, 1.3636930995241778], [-0.17177429145659237, 1.084312687300683, 0.499411278649456, -1.6707851783688454, 1.0027090380942487, -0.2495901766422241, 0.7792310454298716, 1.9875091492752166, 0.6673848421177521, -0.2087533554667897], [0.22872010155347455, -0.34667996722947586, 1.1277302258412574, 1.4945346459120974, -2.5988905470069166, -0.592349165235548, -0.34396241663885446, 1.2523523079565597, 0.0675126652962519, 1.467525654976188]]).reshape(3, n), np.array([1.4662588865429769, -np.inf, -0.06578802338404069]), np.array([1.4662588865429769, -0.9192493087564896, -0.0029601567380109634]), {'t1': slice(0, 2, None), 't2': slice(2, 3, None)}, {'i3': slice(0, 1, None), 'i4': slice(1, 3, None)}, 0.0))
    levels.append(LevelProblem('L2', np.array([[0.5923448293205124, 0.3239802127213234, 0.49171508409032605, 0.07457472380785883, -0.12540789064074495, -0.2714660794691634, -0.22151137387264974, -0.24956440530556667, -0.19393729093690923, 0.17057459694403754], [0.16135704380737767, 0.08378801740336542, 0.29021438363105334, 0.20537324463404324, 0.15715459721650435, -0.34056972894160475, -0.046559420471664274, -0.0858671522296936, -0.11199669948794438, -0.04126270601442074], [-0.4241333811686716, -0.014619482834295797, -0.1233411769319248, -0.21515436333697202, -0.1819494314779348, -0.009661336983970249, -0.09472817716766051, 0.5183834569092242, -0.2486177235084743, -0.5414330448145852], [-0.007413670763647447, 0.06537966800616622, 0.02342066399201319, 0.5045829362460517, 0.3896187092313722, 0.10271277516266926, -0.0852880402607728, -0.15795242231267592, 0.4240613685278568, 0.2555038701631787], [0.03611141215096971, -0.2518403734356324, -0.062213155004885716, 0.23582642539632792, -0.5647311327870623, 0.15373646813109765, 0.08190687786918845, -0.22045346224643075, 0.25741615712250565, 0.04809014104104835], [-0.013559039102341306, -0.03764728086299159, -0.39653590637309516, 0.4010258192848344, 0.15392111183987836, 0.1516929234310559, -0.03783178813857609, 0.11993600785712742, 0.2851090352169951, -0.06320099231256242], [-0.5388801948706521, -0.4799751931984888, -0.4600283191047441, -0.2666149357398341, -0.4817251273233658, 0.5719560756296763, 0.6705565686855233, 0.052306853476283034, 0.2374423883958397, -0.21061819329790143], [-0.1290693363451308, -0.3655353248824744, 0.407649084011624, 0.3228330749973318, 0.09223906106476182, 0.03628897853390855, 0.004618158180945707, -0.2432960926390616, 0.20012043223060572, 0.32732881669935954], [0.13071634284372352, -0.053288943088218015, -0.07132897888797392, -0.0830325890641373, -0.4583488047171829, -0.1929198496213279, -0.19172409318409392, -0.09219763251470287, -0.0905856162486071, -0.02669134583863292]]).reshape(9, n), np.array([1.8379763348167577, -0.6643339118380369, -4.9584851428286285, 0.3873470215807612, 1.7250617718938974, -2.661015748878566, 2.232512705672293, 2.3867308281619417, -0.13217390024717404]), np.array([]).reshape(0, n), np.array([]), np.array([]), {'t5': slice(0, 2, None), 't6': slice(2, 9, None)}, {}, 0.0))
    PROBLEM = StackProblem(levels, np.array([-0.04417740208581993, -0.021303630853667366, -0.0454130569188396, -0.02560705501597116, -0.012661946269875865, -0.04768782979080765, 0.025768440221358935, -0.016951877784693665, -0.01318337888572032, -0.049473732039425504]), np.array([0.04417740208581993, 0.021303630853667366, 0.0454130569188396, 0.02560705501597116, 0.012661946269875865, 0.04768782979080765, 0.025768440221358935, 0.016951877784693665, 0.01318337888572032, 0.049473732039425504]), np.ones(n), {})
    return PROBLEM
# fmt: on


def test_a_level_qp_is_feasible_at_its_start_when_inherited_rows_drifted():
    """proxsuite's answer at a level left an inherited inequality row 3.4e-10 beyond its
    relaxed bound, in directions the next level cannot move: that level's QP was infeasible
    at y = 0 (with the default iteration limit, 230 s and FAILED). The inherited bounds are
    now widened to contain the current point, like the box."""
    solver = HierarchicalQPSolver("proxsuite", engine_settings={"max_iter": 100})
    r = solver.solve_problem(inherited_rows_off_by_round_off())
    assert r.status != SolverStatus.FAILED, r.message
    assert not any(rep.failed for rep in solver.levels)


# fmt: off
def a_level_proxsuite_skips() -> StackProblem:
    """Fuzz seed 48: a level of inequality rows only, which proxsuite fails."""
    n = 4
    levels = []
    levels.append(LevelProblem('L0', np.array([[0.016220601299327113, -0.10186127214970553, 0.08604499368154317, -0.06393893788146486], [0.04136954767406533, 0.11701316796473267, 0.0734079433625417, 0.03485055989857369], [-0.10546043925563467, -0.0038198929092664504, -0.07443676955067277, 0.134099276570765], [-0.08273909534813066, -0.23402633592946534, -0.1468158867250834, -0.06970111979714738]]).reshape(4, n), np.array([2.317027489805335, 0.7295438483562269, -4.728755217182777, -1.4590876967124538]), np.array([[0.2659036732597148, -0.06291214267953195, 0.5228093225601586, 1.0878171125335243], [2.4700336888381353, -1.1747857367542427, 0.383714419583565, 1.308381953258571], [0.7832877888632044, 1.5329713674277197, 1.2754514445188159, 0.11672772826045018]]).reshape(3, n), np.array([-0.19578573229639945, -np.inf, -np.inf]), np.array([0.378682391171929, -1.1650947192787695, 0.3384002713131977]), {'t0': slice(0, 4, None)}, {'i1': slice(0, 2, None), 'i2': slice(2, 3, None)}, 0.0))
    levels.append(LevelProblem('L1', np.array([]).reshape(0, n), np.array([]), np.array([[1.894155003115881, -1.7758737888237626, -1.7652428352785405, 1.6821814381302067], [0.20666147427968162, -0.26419927468041104, 0.6713824697288665, -0.6518178099961335]]).reshape(2, n), np.array([-0.06306845716293247, -0.4393403795160304]), np.array([np.inf, -0.25379165245890317]), {}, {'i3': slice(0, 2, None)}, 0.0))
    PROBLEM = StackProblem(levels, np.array([-304.62228503623106, -0.032813929632419025, -459.89055323207623, -508.68191382754844]), np.array([304.62228503623106, -0.032813929632419025, 459.89055323207623, 508.68191382754844]), np.ones(n), {})
    return PROBLEM
# fmt: on


def test_a_skipped_levels_inequality_tasks_are_listed_as_infeasible():
    """proxsuite fails the second level's QP (inequality rows only; here held to one
    iteration): the level is skipped and its inequality task, violated at the answer, is
    listed like its equalities."""
    solver = HierarchicalQPSolver("proxsuite", engine_settings={"max_iter": 1})
    r = solver.solve_problem(a_level_proxsuite_skips())  # one iteration: the level fails
    assert solver.levels[1].failed
    assert r.status == SolverStatus.FAILED
    assert ("L1", "i3") in r.infeasible


def test_a_level_bought_off_its_optimum_by_the_tikhonov_term_does_not_freeze_the_next():
    """Three consistent rank-1 levels whose exact answer lies inside the box (the recursive
    pseudo-inverse meets every row). The Tikhonov term held the second level's QP on a box
    face with a 2.7e-5 residual, that face was pinned, and the third level lost all its
    freedom (residual 0.75). Proximal-point QPs now walk the level to its exact optimum."""
    n = 4
    none = (np.zeros((0, n)), np.zeros(0), np.zeros(0))
    rows = [
        (
            [
                [
                    0.10768802093886205,
                    -0.11149084417956046,
                    -0.006547636480641782,
                    -0.016465019683374993,
                ]
            ],
            [0.4839591707781613],
        ),
        (
            [
                [
                    0.1014796419487467,
                    -0.02417750431791603,
                    -0.010611651929785377,
                    -0.06214827546833107,
                ]
            ],
            [0.3420448611465455],
        ),
        (
            [
                [-0.5742738652264434, 1.5340271673908883, -0.8381439152506317, -0.5730366720775424],
                [0.435038123239999, -1.162094151085485, 0.6349314812574374, 0.4341008941265498],
            ],
            [-0.9784726279284293, 0.7412367538749924],
        ),
    ]
    levels = [
        LevelProblem(f"L{k}", np.array(A), np.array(b), *none, {f"t{k}": slice(0, len(b))}, {})
        for k, (A, b) in enumerate(rows)
    ]
    lower = np.array(
        [-0.05253910673085642, -2.0671328175526664, -3.5174178321854197, -0.8560662118772109]
    )
    upper = np.array(
        [2.0731344405461356, 0.06390362752565901, 0.09517461611250529, 0.08258190095972785]
    )
    problem = StackProblem(levels, lower, upper, np.ones(n), {})
    r = HierarchicalQPSolver("daqp").solve_problem(problem)
    assert r.status == SolverStatus.OK and not r.infeasible
    np.testing.assert_array_less(r.level_residuals, 1e-8)


def test_proxsuite_keeps_solving_a_stack_with_a_safety_half_space(humanoid):
    """A hand sent 0.3 m below a half-space it must stay above, a posture level below: from
    step 11 on, steps took up to 1.5 million proxsuite iterations (14 s) on a lower level's
    QP that was infeasible at its start. (proxsuite may still call a level infeasible now and
    then, a documented limitation; the step is then FAILED at once, not after seconds.)"""
    from wholebody.presets import paper_metric
    from wholebody.solvers import Level, Stack
    from wholebody.tasks import (
        FrameHalfSpace,
        FrameTask,
        JointPositionLimits,
        PostureTask,
        VelocityLimits,
    )

    q = humanoid.home()
    hand = FrameTask(humanoid, "right_tool", kp=20.0, orientation=False)
    start = humanoid.frame_pose(q, "right_tool")
    goal = start.copy()
    goal[:3, 3] += [0.2, 0.0, -0.3]
    hand.set_target(goal)
    floor = FrameHalfSpace(humanoid, "right_tool", [0, 0, 1], start[2, 3] - 0.1)
    stack = Stack(
        humanoid,
        [
            Level([floor], name="safety"),
            Level([hand], name="hand"),
            Level([PostureTask(humanoid, kp=1.0)], name="posture"),
        ],
        [JointPositionLimits(humanoid), VelocityLimits(humanoid)],
        metric=paper_metric(humanoid),
    )
    solver = HierarchicalQPSolver("proxsuite")
    for _ in range(40):
        state = humanoid.update(q)
        result = solver.solve(stack, state, 0.01)
        assert sum(rep.iterations for rep in solver.levels) < 20_000, result.message
        stack.advance(state, 0.01, saturated=result.limit_hit)
        q = humanoid.integrate(q, result.u, 0.01)
    assert humanoid.frame_pose(q, "right_tool")[2, 3] >= start[2, 3] - 0.1 - 1e-3


def _equality_levels(rows: list[tuple[list[list[float]], list[float]]]) -> list[LevelProblem]:
    n = len(rows[0][0][0])
    none = (np.zeros((0, n)), np.zeros(0), np.zeros(0))
    return [
        LevelProblem(f"L{k}", np.array(A), np.array(b), *none, {f"t{k}": slice(0, len(b))}, {})
        for k, (A, b) in enumerate(rows)
    ]


@pytest.mark.parametrize("engine", ["daqp", "osqp"])
def test_round_off_rows_do_not_use_up_a_lower_levels_freedom(engine):
    """L0 leaves a segment free; L1's row is 2e-16 along it (pure round-off) and used to be
    given rank 1, which froze the segment: L2 then missed its optimum (4.33 against 4.05)."""
    levels = _equality_levels(
        [
            ([[-1.0, 1.0, 0.6, 0.25], [-1.0, 1.0, 0.3, -0.95]], [-3.0, 0.0]),
            ([[0.0, 0.0, 0.0, 1.0]], [3.0]),
            ([[0.1, 1.0, 0.0, 0.0]], [-5.0]),
        ]
    )
    problem = StackProblem(
        levels, np.array([-1.0, -1.0, -0.1, -0.1]), np.array([1.0, 1.0, 0.1, 0.1]), np.ones(4), {}
    )
    u = HierarchicalQPSolver(engine).solve_problem(problem).u
    np.testing.assert_allclose(u, [0.49, -1.0, -0.1, -0.1], atol=1e-6)  # the certified optimum


@pytest.mark.parametrize("engine", ["daqp", "osqp"])
def test_a_bound_the_optimal_set_does_not_move_along_is_not_pinned_away(engine):
    """The box caps L0 at x1 = 1 and leaves the segment x0 in [-1, -0.5], x2 = -1.1 - 0.2 x0;
    pinning x1 projected to a round-off row that removed the segment, and L2 got x0 = -0.5
    (residual 0.5) instead of -1 (0.39)."""
    levels = _equality_levels(
        [([[0.2, -0.9, 1.0], [0.2, -0.3, 1.0]], [-2.9, -0.5]), ([[0.4, 0.0, 0.9]], [-1.6])]
    )
    problem = StackProblem(levels, -np.ones(3), np.ones(3), np.ones(3), {})
    u = HierarchicalQPSolver(engine).solve_problem(problem).u
    np.testing.assert_allclose(u, [-1.0, 1.0, -0.9], atol=1e-6)


@pytest.mark.parametrize("engine", ["daqp", "osqp"])
def test_inequality_only_levels_and_slacks_are_exact_in_the_cascade(engine):
    """Three stacks of the second fuzzing round (each against a hand-derived optimum)."""
    n, none = 3, (np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    # (1) a level of one inequality row, x >= 400: its Tikhonov bias left it violated by 8e-6
    L0 = LevelProblem(
        "L0",
        np.zeros((0, 1)),
        np.zeros(0),
        np.array([[0.05]]),
        np.array([20.0]),
        np.array([np.inf]),
        {},
        {"above": slice(0, 1)},
    )
    L1 = LevelProblem(
        "L1",
        np.eye(1),
        np.zeros(1),
        np.zeros((0, 1)),
        np.zeros(0),
        np.zeros(0),
        {"t1": slice(0, 1)},
        {},
    )
    r = HierarchicalQPSolver(engine).solve_problem(
        StackProblem([L0, L1], np.full(1, -1000.0), np.full(1, 1000.0), np.ones(1), {})
    )
    assert ("L0", "above") not in r.infeasible and r.u[0] == pytest.approx(400.0, abs=1e-6)
    assert r.status == SolverStatus.OK  # the level above, not the box, holds L1 (was INFEASIBLE)
    # (2) an inequality level above objectives: the bounded least squares (BVLS) of the
    # objectives' level ignored the inherited row and violated it by 0.66
    C = np.array([[1.0351879907581838, -0.7756413745956193, 1.6667497504903537]])
    L0 = LevelProblem(
        "L0",
        np.zeros((0, n)),
        np.zeros(0),
        C,
        np.array([0.8062776506186784]),
        np.array([np.inf]),
        {},
        {"half_space": slice(0, 1)},
    )
    L1 = LevelProblem(
        "L1",
        np.eye(n),
        np.array([2.2191508000828906, -1.7598913582999285, -2.813567964954028]),
        *none,
        {"t1": slice(0, n)},
        {},
    )
    u = (
        HierarchicalQPSolver(engine)
        .solve_problem(StackProblem([L0, L1], -np.ones(n), np.ones(n), np.ones(n), {}))
        .u
    )
    assert C[0] @ u >= 0.8062776506186784 - 1e-8
    # (3) the slack of a violated row presses on a bound too: pinning from the equality rows
    # alone took a free direction from the next level (1.94 optimal, 2.02 found)
    L0 = LevelProblem(
        "L0",
        np.array([[-0.9, -0.3, -0.9]]),
        np.array([2.7]),
        np.array([[-1.2, -0.4, 1.1]]),
        np.array([-np.inf]),
        np.array([-0.6]),
        {"t0": slice(0, 1)},
        {"i0": slice(0, 1)},
    )
    L1 = LevelProblem(
        "L1",
        np.array([[1.5, 0.8, 0.2], [-1.9, -0.3, 0.4]]),
        np.array([-0.8, -0.4]),
        *none,
        {"t1": slice(0, 2)},
        {},
    )
    u = (
        HierarchicalQPSolver(engine)
        .solve_problem(StackProblem([L0, L1], -np.ones(n), np.ones(n), np.ones(n), {}))
        .u
    )
    assert np.linalg.norm(L1.A @ u - L1.b) == pytest.approx(1.941162, abs=1e-5)


@pytest.mark.parametrize("engine", ["daqp", "proxsuite", "osqp"])
def test_degenerate_and_ill_conditioned_levels_in_the_cascade(engine):
    """(1) A lower level repeating the top task (nothing left to move) whose minimum-norm step
    leaves the box: its QP had a Hessian of 3e-41 and daqp's answer broke the top level
    (residual 1.8 where 0 is met). (2) One ill-conditioned level (condition 5e5): every
    engine stopped 3.7 % above the bounded least squares (BVLS ran out of iterations)."""
    row = np.array([[-0.15, -0.47, -1.0]])
    none = (np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    levels = [
        LevelProblem("L0", row, np.array([-3.5]), *none, {"t0": slice(0, 1)}, {}),
        LevelProblem("L1", 1.2 * row, np.array([4.77]), *none, {"t1": slice(0, 1)}, {}),
    ]
    box = np.array([-1.0, -np.inf, -1.0]), np.array([1.0, np.inf, 1.0])
    r = HierarchicalQPSolver(engine).solve_problem(StackProblem(levels, *box, np.ones(3), {}))
    assert r.level_residuals[0] < 1e-6 and ("L0", "t0") not in r.infeasible
    A = np.array(
        [
            [0.7432992844579642, 1.3956691799968912, -1.6596900207256087],
            [-2.857295096361623, -5.371464595273765, 6.373232673829478],
            [1.3417655506407502, 2.5330469464517904, -2.9822336150290942],
        ]
    )
    b = np.array([0.04744111040380759, 0.02734634733457533, -0.5447686686658867])
    lo = np.array([-112.4481878597328, -200.88631992778832, -5.382834797819274])
    hi = np.array([209.79712291742493, 238.5391295942699, 10.781618844429781])
    level = LevelProblem("L0", A, b, *none, {"t": slice(0, 3)}, {})
    r = HierarchicalQPSolver(engine).solve_problem(StackProblem([level], lo, hi, np.ones(3), {}))
    assert np.linalg.norm(A @ r.u - b) == pytest.approx(0.0261061, abs=1e-6)


def test_a_skipped_non_finite_level_above_the_box_does_not_reach_the_engine():
    """A level with a NaN row above the level where the box bites: daqp handed a NaN row
    crashed the interpreter (segmentation fault, in its hierarchical mode). A level with
    non-finite rows is skipped and named; its rows never reach a QP."""
    nan = np.nan
    A0 = np.array(
        [
            [0.0, -0.02061451360305048, -0.5617523805824108],
            [nan, 1.1081409761263175, 0.7097628465866269],
        ]
    )
    A1 = np.array(
        [
            [-0.5216332373487103, 2.8065705664572045, 1.2863515893997708],
            [0.38238251521982985, 0.6243504721410483, -0.5335848232646581],
            [1.1121140414174382, -0.4699411842889205, 0.13076835453805727],
            [0.4157167037590058, -0.7570211712261788, -0.8590386030961711],
            [-1.0432664746974205, 5.613141132914409, 2.5727031787995416],
        ]
    )
    b1 = np.array(
        [
            -0.01188243700543709,
            -0.4380092039163905,
            -1.3401647525622187,
            0.8541465887273845,
            1.3946269048150957,
        ]
    )
    A2 = np.array(
        [
            [-0.06672551314376893, -0.25665992769349466, 0.4634593001228585],
            [-0.8290025489061839, -0.5894225737338709, 2.404494189059856],
            [-0.5231392114562813, 0.42278887012683747, 1.050042085947754],
            [-0.3861482113660763, -0.17184191207864485, -1.0595741911736751],
            [1.7739648041982747, 0.2713555635785586, -0.11738104074371104],
            [-0.7946390555859278, -1.378933999928254, -1.3178410785173642],
        ]
    )
    b2 = np.array(
        [
            -1.1418066915503562,
            0.63358668168871679,
            -1.1045924837067844,
            0.13517070965908234,
            4.2032863576706294e-04,
            -0.17816489776400191,
        ]
    )
    none = (np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    levels = [
        LevelProblem(
            "level 0",
            A0,
            np.array([-0.18684829560143262, 0.06817893402286822]),
            *none,
            {"t2": slice(0, 2)},
        ),
        LevelProblem("level 1", A1, b1, *none, {"t1": slice(0, 2), "t2": slice(2, 5)}),
        LevelProblem("level 2", A2, b2, *none, {"t1": slice(0, 2), "t2": slice(2, 6)}),
    ]
    lower = np.array([-0.2597349005370813, -0.19271378763852473, -0.06332819674228664])
    upper = np.array([0.26197943146421515, 0.15254391681296, 0.2081913430327174])
    problem = StackProblem(levels, lower, upper, np.ones(3), {})
    result = HierarchicalQPSolver().solve_problem(problem)
    assert result.status == SolverStatus.FAILED and "non-finite rows from t2" in result.message
    assert np.all(result.u >= lower) and np.all(result.u <= upper)


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_a_non_finite_level_with_no_freedom_left_is_reported(value):
    """A level below one that fixes every direction moves nothing, but its NaN or inf rows
    are still named (they were not: status INFEASIBLE, the task not even listed, as NaN
    compares false with the tolerance)."""
    rng = np.random.default_rng(5)
    n = 4
    A1 = rng.normal(size=(5, n))
    A1[3] = value
    none = (np.zeros((0, n)), np.zeros(0), np.zeros(0))
    levels = [
        LevelProblem(
            "full", rng.normal(size=(n, n)), rng.normal(size=n), *none, {"t0": slice(0, n)}
        ),
        LevelProblem(
            "below", A1, rng.normal(size=5), *none, {"t1": slice(0, 2), "t2": slice(2, 5)}
        ),
    ]
    box = np.full(n, 1e12)
    problem = StackProblem(levels, -box, box, np.ones(n), {})
    with np.errstate(invalid="ignore", over="ignore"):  # (the residuals of the inf rows)
        result = HierarchicalQPSolver().solve_problem(problem)
    assert result.status == SolverStatus.FAILED
    assert "below: non-finite rows from t2" in result.message
    assert ("below", "t2") in result.infeasible and np.all(np.isfinite(result.u))
