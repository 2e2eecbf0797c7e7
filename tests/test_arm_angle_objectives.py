"""Objectives on the arm angle: the pull towards a human arm angle and the signed spring,
their gradients against finite differences, what they do in a stack on both backends, and
the paper stack's options that use them."""

from __future__ import annotations

import numpy as np
import pytest

import wholebody as wb
from wholebody.arm.angle import arm_angle
from wholebody.arm.human_arm_angle import NetworkArmAngle
from wholebody.arm.stiffness import StiffnessModel
from wholebody.errors import DimensionError
from wholebody.presets import PaperWeights, paper_objectives
from wholebody.tasks import ArmAngleSpring, ArmPotentialEnergy, HumanArmAngle, HumanArmAngleTask
from wholebody.testing import assert_objective_gradient, assert_task_jacobian, jacobian_fd

DT = 0.01


class Linear:
    """``alpha_h(p) = a.p + b``: a model whose gradient is not zero."""

    def __init__(self, a=(0.2, -0.5, 0.7), b=0.3):
        self.a, self.b = np.array(a), b

    def evaluate(self, p):
        return float(self.a @ p + self.b), self.a.copy()


class Answer:
    """A model that answers the same, whatever ``p``."""

    def __init__(self, alpha, gradient):
        self.alpha, self.gradient = alpha, gradient

    def evaluate(self, p):
        return self.alpha, self.gradient


class Constant(Linear):
    def __init__(self, alpha):
        super().__init__((0.0, 0.0, 0.0), alpha)


class Sloped(StiffnessModel):
    """A stiffness that grows with the wrist's height (N m/rad, m)."""

    def evaluate(self, wrist):
        return 0.2 + 0.3 * float(wrist[2]) ** 2, np.array([0.0, 0.0, 0.6 * float(wrist[2])])


def alpha_of(robot, state, arm):
    side = 1.0 if arm.side == "left" else -1.0
    S, E, W = (state.position(f) for f in (arm.shoulder, arm.elbow, arm.wrist))
    return float(arm_angle(S, E, W, side))


@pytest.mark.parametrize("arm", ["left", "right"])
def test_gradients_match_finite_differences(humanoid, rng, arm):
    objectives = [
        HumanArmAngle(humanoid, arm, Linear()),
        ArmAngleSpring(humanoid, arm, 0.3),
        ArmAngleSpring(humanoid, arm, Sloped()),
        ArmAngleSpring(humanoid, arm, 0.3, signed=False),
    ]
    for _ in range(4):
        q = humanoid.random_configuration(rng, margin=0.1, base_range=0.5)
        for objective in objectives:
            assert_objective_gradient(objective, humanoid, q, atol=1e-6)


def test_the_signed_spring_pulls_a_tucked_elbow_out(humanoid, rng):
    """With the elbow tucked in (alpha < 0) the paper's spring's descent lowers alpha further;
    the signed spring's raises it."""
    arm = humanoid.arm("right")
    found = 0
    for _ in range(200):
        q = humanoid.random_configuration(rng, margin=0.1, base_range=0.0)
        state = humanoid.update(q)
        alpha = alpha_of(humanoid, state, arm)
        if not -1.5 < alpha < -0.2:
            continue
        found += 1
        d_alpha = jacobian_fd(humanoid, q, lambda s: np.array([alpha_of(humanoid, s, arm)]))[0]
        state = humanoid.update(q)  # (the differences updated the robot)
        paper = ArmPotentialEnergy(humanoid, arm, 0.3).evaluate(state).gradient
        spring = ArmAngleSpring(humanoid, arm, 0.3).evaluate(state).gradient
        # descent -grad moves alpha at the rate -grad . d_alpha (the metric is the identity)
        assert -(spring @ d_alpha) > 0 > -((paper - _gravity(humanoid, arm, q)) @ d_alpha)
        if found == 5:
            break
    assert found == 5


def _gravity(robot, arm, q):
    """The arm energy's gravity part's gradient (the spring alone is compared)."""
    return ArmPotentialEnergy(robot, arm, 0.0).evaluate(robot.update(q)).gradient


@pytest.mark.parametrize("backend", [wb.ProjectionSolver, wb.HierarchicalQPSolver])
def test_the_pull_brings_the_arm_angle_to_the_human_one(humanoid, backend):
    """The hand held where it is, the pull in the null space turns the elbow to
    alpha_h = 0.4 rad on both backends."""
    q = humanoid.home()
    arm = humanoid.arm("right")
    hand = wb.FrameTask(humanoid, arm.tool, kp=20.0)
    hand.set_target(humanoid.frame_pose(q, arm.tool))
    pull = HumanArmAngle(humanoid, arm, Constant(0.4), weight=5.0)
    stack = wb.Stack(
        humanoid,
        [[hand], wb.Level([pull], gain=1.0)],
        [wb.JointPositionLimits(humanoid), wb.VelocityLimits(humanoid)],
    )
    alpha0 = alpha_of(humanoid, humanoid.update(q), arm)
    solver = backend()
    for _ in range(300):
        state = humanoid.update(q)
        result = solver.solve(stack, state, DT)
        stack.advance(state, DT, result=result)
        q = humanoid.integrate(q, result.u, DT)
    state = humanoid.update(q)
    assert abs(alpha0 - 0.4) > 0.2
    assert abs(alpha_of(humanoid, state, arm) - 0.4) < 1e-2
    assert np.linalg.norm(hand.error(state)) < 1e-4


def test_paper_weights_choose_the_spring_and_the_pull(humanoid):
    names = lambda weights: [type(o).__name__ for o in paper_objectives(humanoid, weights, 0.1)]  # noqa: E731
    assert names(PaperWeights()).count("ArmAngleSpring") == 0
    signed = paper_objectives(humanoid, PaperWeights(spring="signed"), 0.1)
    energies = [o for o in signed if isinstance(o, ArmPotentialEnergy)]
    assert all(e.stiffness.k == 0.0 for e in energies)  # gravity only: the spring is signed
    assert sum(isinstance(o, ArmAngleSpring) and o.signed for o in signed) == 2
    plain = paper_objectives(humanoid, PaperWeights(spring="none"), 0.1)
    assert all(o.stiffness.k == 0.0 for o in plain if isinstance(o, ArmPotentialEnergy))
    pulls = [
        o
        for o in paper_objectives(humanoid, PaperWeights(human_arm_angle=5.0), 0.1)
        if isinstance(o, HumanArmAngle)
    ]
    assert len(pulls) == 2 and all(o.weight == 5.0 for o in pulls)
    assert all(isinstance(o.model, NetworkArmAngle) for o in pulls)  # the shipped model
    with pytest.raises(DimensionError, match="spring must be one of"):
        paper_objectives(humanoid, PaperWeights(spring="curly"), 0.1)
    with pytest.raises(DimensionError, match="human_arm_angle must be a weight >= 0"):
        paper_objectives(humanoid, PaperWeights(human_arm_angle=-1.0), 0.1)
    with pytest.raises(DimensionError, match="model must have evaluate"):
        HumanArmAngle(humanoid, "left", 0.4)
    with pytest.raises(DimensionError, match="stiffness must be a number"):
        ArmAngleSpring(humanoid, "left", "learned")
    assert ArmAngleSpring(humanoid, "left", np.int64(1)).stiffness.k == 1.0


def test_bad_models_and_arms_are_named(humanoid):
    """A stiffness model is not an arm-angle model; a model answering NaN or a gradient of
    the wrong shape is named at its first evaluation; arm_only needs the arm's group."""
    import dataclasses

    with pytest.raises(DimensionError, match="model must have evaluate"):
        HumanArmAngle(humanoid, "left", Sloped())
    state = humanoid.update(humanoid.home())
    for alpha, gradient in ((float("nan"), np.zeros(3)), (0.3, 0.0)):
        bad = HumanArmAngle(humanoid, "left", Answer(alpha, gradient))
        with pytest.raises(DimensionError, match="left_human_arm_angle: the arm-angle model"):
            bad.evaluate(state)
    groupless = dataclasses.replace(humanoid.arm("left"), group=None)
    with pytest.raises(DimensionError, match="arm_only needs the arm's joint group"):
        HumanArmAngleTask(humanoid, groupless, Constant(0.4))
    assert HumanArmAngleTask(humanoid, groupless, Constant(0.4), arm_only=False).columns is None


@pytest.mark.parametrize("arm", ["left", "right"])
def test_the_task_row_is_the_residuals_jacobian_and_the_curvature_bounds_its_hessian(
    humanoid, rng, arm
):
    """Row ``d(alpha - alpha_h)/du`` (no fade: eps 1e-7 m), and the objective's curvature
    ``diag(c) >= w a a^T`` (Gershgorin) with ``a`` that row."""
    task = HumanArmAngleTask(humanoid, arm, Linear(), fade=1e-7, arm_only=False)
    own = HumanArmAngleTask(humanoid, arm, Linear(), fade=1e-7)  # the arm's joints only
    cols = humanoid.arm(arm).group.indices
    objective = HumanArmAngle(humanoid, arm, Linear())
    for _ in range(4):
        q = humanoid.random_configuration(rng, margin=0.1, base_range=0.5)
        assert_task_jacobian(task, humanoid, q, lambda s: task.error(s), atol=1e-5)
        state = humanoid.update(q)
        full, mine = task.compute(state).J[0], own.compute(state).J[0]
        np.testing.assert_array_equal(mine[cols], full[cols])
        assert np.count_nonzero(mine) == np.count_nonzero(full[cols]) > 0
        e, w, w_de, _ = objective.residual(state)
        c = objective.evaluate(state).curvature
        assert np.linalg.eigvalsh(np.diag(c) - np.outer(w_de, w_de) / w).min() > -1e-9
        rate = np.clip(-10.0 * e, -1.0, 1.0)  # kp 10 1/s, max_rate 1 rad/s, w = 1
        assert task.compute(state).v[0] == pytest.approx(rate, rel=1e-6)
        w3 = HumanArmAngle(humanoid, arm, Linear(), fade=0.03).residual(state)[1]
        faded = HumanArmAngleTask(humanoid, arm, Linear()).compute(state).v[0]  # fade 3 cm
        assert faded == pytest.approx(w3 * w3 * rate, rel=1e-6, abs=1e-12)


@pytest.mark.parametrize("backend", [wb.ProjectionSolver, wb.HierarchicalQPSolver])
@pytest.mark.parametrize("arm_only", [False, True])
def test_the_task_level_decays_the_residual_at_its_rate(humanoid, backend, arm_only):
    """The wrist held, a level of the arm-angle task below it: alpha - alpha_h decays as
    exp(-kp t) (kp = 5 1/s; to 5 % of the start after 0.2 s), by the whole body or by the
    arm's own joints; the wrist's error, first-order drift of its PI law, stays below 0.5 mm."""
    q = humanoid.home()
    arm = humanoid.arm("right")
    hand = wb.FrameTask(humanoid, arm.wrist, kp=20.0, orientation=False)
    hand.set_target(humanoid.frame_pose(q, arm.wrist))
    task = HumanArmAngleTask(
        humanoid, arm, Constant(0.4), kp=5.0, max_rate=10.0, arm_only=arm_only, fade=1e-3
    )  # w = 1 to 1e-4
    stack = wb.Stack(
        humanoid, [[hand], [task]], [wb.JointPositionLimits(humanoid), wb.VelocityLimits(humanoid)]
    )
    e0 = task.error(humanoid.update(q))[0]
    solver = backend()
    for _ in range(20):
        state = humanoid.update(q)
        result = solver.solve(stack, state, DT)
        q = humanoid.integrate(q, result.u, DT)
    state = humanoid.update(q)
    assert abs(e0) > 0.2
    assert task.error(state)[0] == pytest.approx(e0 * (1 - 5.0 * DT) ** 20, abs=0.05 * abs(e0))
    assert np.linalg.norm(hand.error(state)) < 5e-4


def test_the_task_level_is_built_by_paper_weights(humanoid):
    stack = wb.paper_stack(
        humanoid,
        [wb.FrameTask(humanoid, "right_tool")],
        weights=PaperWeights(human_arm_angle_kp=5.0),
    )
    level = stack.levels[1]
    assert [type(t).__name__ for t in level.tasks] == ["HumanArmAngleTask"] * 2
    assert all(t.kp == 5.0 and isinstance(t.pull.model, NetworkArmAngle) for t in level.tasks)
    with pytest.raises(DimensionError, match="human_arm_angle_kp must be >= 0"):
        wb.paper_stack(humanoid, [], weights=PaperWeights(human_arm_angle_kp=-1.0))
    with pytest.raises(DimensionError, match="kp must be a finite number >= 0"):
        HumanArmAngleTask(humanoid, "left", Constant(0.4), kp=float("nan"))


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["projection", "hqp"])
def test_the_carry_holds_its_chain_with_the_arms_where_people_hold_them(backend):
    """The paper's panel carry with the spring replaced by the arm-angle task level: hands
    within 0.2 mm (per-axis MAE), the chain within 0.1 mm, no limit violated, and most frames
    of both arms in people's range [0, 0.8] rad (the paper's spring: 0 and 8 %)."""
    import dataclasses

    from wholebody.control.metrics import ARM_ANGLE_MIN_RHO
    from wholebody.resources import tasks_dir
    from wholebody.scenarios import load_scenario, run_scenario

    spec = load_scenario(tasks_dir() / "coordinated_carry.toml")
    stack = dataclasses.replace(spec.stack, spring="none", human_arm_angle_kp=10.0)
    run = run_scenario(dataclasses.replace(spec, stack=stack), backend=backend)
    m = run.metrics
    assert max(max(v.values()) for v in m["mae_m"].values()) < 2e-4
    assert m["closed_chain_error_max_m"] < 1e-4 and m["limit_violations"] == 0
    for arm in ("left", "right"):
        trace = run.log.arms[arm]
        alpha = trace.arm_angle[trace.rho >= ARM_ANGLE_MIN_RHO]
        assert np.mean((alpha >= 0.0) & (alpha <= 0.8)) > 0.7
