"""The torque-level backend (wholebody.dynamics) against independent references: Pinocchio's
RNEA for the equations of motion, the contacts' own wrench limits written out here, finite
differences of the task velocities along the motion, Pinocchio's frame accelerations, and
the velocity-level HQP on a slow reach."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.dynamics import DynamicsSolver, PatchContact, PointContact
from wholebody.errors import ConfigError, DimensionError, SolverError
from wholebody.solvers.result import SolverStatus

DT = 1e-3
FEET = ("left_sole_link", "right_sole_link")


@pytest.fixture(scope="module")
def talos():
    return wb.load_robot("talos_full")


@pytest.fixture(scope="module")
def panda():
    return wb.load_robot("panda")


def standing(robot, kp=10.0, **kw):
    """TALOS on both feet: the CoM (gain ``kp``, 1/s) above a posture, soles as patch
    contacts."""
    com = wb.ComTask(robot, "xyz", kp=kp)
    stack = wb.Stack(
        robot,
        [[com], [wb.PostureTask(robot, kp=5.0)]],
        [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
    )
    feet = [
        PatchContact(f, mu=0.3, f_min=5.0, half_length=0.1, half_width=0.065, kp=10.0, kd=6.0)
        for f in FEET
    ]
    solver = DynamicsSolver(robot, feet, **kw)
    q = robot.home()
    solver.make_contacts(q)
    return com, stack, solver, q


def run(robot, stack, solver, q, u, steps, each=None):
    for _ in range(steps):
        res = solver.solve(stack, q, u, DT)
        if each is not None:
            each(q, u, res)
        u = u + res.a * DT
        q = robot.integrate(q, u, DT)
        stack.advance(robot.update(q), DT)
    return q, u, res


def test_the_step_satisfies_the_equations_of_motion_against_rnea(talos):
    com, stack, solver, q = standing(talos)
    com.set_target(talos.com_position(q) + np.array([0.0, 0.03, 0.0]))
    rng = np.random.default_rng(0)
    u = rng.normal(scale=0.2, size=talos.nu)
    res = solver.solve(stack, q, u, DT)
    data = talos.model.createData()
    v, dv = talos.actuation @ u, res.dv
    tau = pin.rnea(talos.model, data, q, v, dv).copy()
    tau += solver.rotor_inertia * dv + solver.friction * v  # the drives (robot.toml [sim])
    for frame, w in res.wrenches.items():
        fid = talos.model.getFrameId(frame)
        J = pin.computeFrameJacobian(talos.model, data, q, fid, pin.ReferenceFrame.LOCAL)
        tau -= J.T @ w
    assert np.abs(tau - res.force).max() < 1e-8 * (1 + np.abs(tau).max())
    assert np.abs(tau[:6]).max() < 1e-8 * (1 + np.abs(tau).max())  # no motor on the pelvis
    assert np.allclose(res.tau, talos.actuation.T @ res.force)
    assert res.status != SolverStatus.INFEASIBLE


def within_cone(contact, w, tol=1e-4):
    """The contact's wrench limits, written out: unilateral, pyramid, CoP, yaw friction
    (``tol`` N, N m: 1e-7 of TALOS's weight, the cascade's accuracy)."""
    fx, fy, fz, tx, ty, tz = w
    c = contact.mu / np.sqrt(2.0)
    hl, hw = contact.half_length, contact.half_width
    return (
        contact.f_min - tol <= fz <= contact.f_max + tol
        and abs(fx) <= c * fz + tol
        and abs(fy) <= c * fz + tol
        and abs(ty) <= hl * fz + tol
        and abs(tx) <= hw * fz + tol
        and abs(tz) <= contact.mu * min(hl, hw) * fz + tol
    )


@pytest.mark.slow
def test_torques_friction_and_cop_hold_on_every_step_while_the_com_sways(talos):
    com, stack, solver, q = standing(talos, kp=3.0)
    c0 = talos.com_position(q)
    shift = np.array([0.0, 0.06, -0.02])
    com.set_target(c0 + shift)  # far to the left foot: the CoP bounds bind
    seen = {"cop_at_edge": False}

    def check(q, u, res):
        effort = solver.effort
        assert np.all(np.abs(res.tau) <= effort + 1e-4)
        for contact in solver.contacts:
            w = res.wrenches[contact.frame]
            assert within_cone(contact, w), (contact.frame, w)
            seen["cop_at_edge"] |= contact.cop_margin(w) < 1e-6
        assert max(res.violations.values()) < 1e-4
        assert res.status != SolverStatus.INFEASIBLE

    q, _, _ = run(talos, stack, solver, q, np.zeros(talos.nu), 1500, check)
    assert seen["cop_at_edge"]
    assert np.linalg.norm(talos.com_position(q) - c0 - shift) < 0.01
    for f in FEET:  # the soles held where they were made (to the semi-implicit
        # integration's error over 1.5 s of 6 cm sway: the accelerations hold to 1e-7 m/s^2)
        ref = next(c for c in solver.contacts if c.frame == f).reference
        assert np.linalg.norm(talos.frame_pose(q, f)[:3, 3] - ref[:3, 3]) < 5e-4


def hand_stack(robot, kp=2.0):
    hand = wb.FrameTask(robot, "panda_hand_tcp", kp=kp)
    stack = wb.Stack(
        robot,
        [[hand], [wb.PostureTask(robot, kp=1.0)]],
        [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
    )
    return hand, stack


def test_task_accelerations_match_finite_differences_of_the_task_velocities(panda):
    """Solved for a feasible hand task, ``J a + Jdot u = Kd (b - J u)``: the hand's twist
    ``J(q) u`` along the integrated motion changes at exactly that rate."""
    hand, stack = hand_stack(panda)
    solver = DynamicsSolver(panda, acceleration_limits=False)  # the rows alone decide
    q = panda.home()
    goal = panda.frame_pose(q, "panda_hand_tcp")
    goal[:3, 3] += (0.05, -0.05, 0.05)
    hand.set_target(goal)
    u = np.random.default_rng(1).normal(scale=0.5, size=panda.nu)
    res = solver.solve(stack, q, u, DT)
    problem = stack.evaluate(panda.update(q), DT)
    J, b = problem.levels[0].A / problem.scale, problem.levels[0].b
    wanted = solver.velocity_gain * (b - J @ u)

    def twist(h):  # J u along q(t) = q + u t + a t^2 / 2, u(t) = u + a t
        qh = panda.integrate(q, u + 0.5 * res.a * h, h)
        return panda.frame_jacobian(qh, "panda_hand_tcp") @ (u + res.a * h)

    h = 1e-5
    rate = (twist(h) - twist(-h)) / (2 * h)
    assert np.abs(rate - wanted).max() < 1e-5 * (1 + np.abs(wanted).max())


def test_the_rows_drift_is_pinocchios_frame_acceleration(panda):
    """``Jdot u`` by forward differences of the stack's rows equals Pinocchio's classical
    acceleration of the frame at zero joint acceleration."""
    hand, stack = hand_stack(panda)
    solver = DynamicsSolver(panda)
    q = panda.home()
    hand.set_target(panda.frame_pose(q, "panda_hand_tcp"))
    u = np.random.default_rng(2).normal(scale=1.0, size=panda.nu)
    drift = solver.drifts(stack, q, u, DT)
    model, data = panda.model, panda.model.createData()
    fid = model.getFrameId("panda_hand_tcp")
    pin.forwardKinematics(model, data, q, panda.actuation @ u, np.zeros(model.nv))
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    acc = pin.getFrameClassicalAcceleration(model, data, fid, lwa)
    assert np.abs(drift[:6] - acc.vector).max() < 1e-7 * (1 + np.abs(acc.vector).max())


def test_priorities_are_strict(talos):
    """A lower level never changes a higher one's residual: the CoM's and the contacts' rows
    are met the same with or without a conflicting hand task below them."""
    com, stack, solver, q = standing(talos)
    com.set_target(talos.com_position(q) + np.array([0.02, 0.0, 0.0]))
    u = np.zeros(talos.nu)
    base_result = solver.solve(stack, q, u, DT)
    r0 = base_result.solution.task_residuals["com"]
    hand = wb.FrameTask(talos, "gripper_right_base_link", kp=10.0)
    far = talos.frame_pose(q, "gripper_right_base_link")
    far[:3, 3] += (1.0, -1.0, 0.5)  # out of reach: it must give way
    hand.set_target(far)
    with_hand = wb.Stack(talos, [[com], [hand], [wb.PostureTask(talos)]], stack.constraints)
    res = solver.solve(with_hand, q, u, DT)
    with pytest.raises(SolverError, match="solved again"):
        _ = base_result.solution  # a result's details are the last solve's only
    for name in ("contact left_sole_link", "contact right_sole_link"):
        assert res.solution.task_residuals[name] < 1e-8
    # the CoM asks more than friction allows (it is unmet), by exactly as much either way
    r = res.solution.task_residuals["com"]
    assert r0 > 0.1 and abs(r - r0) < 1e-8 * (1 + r0)
    assert res.solution.task_residuals[hand.name] > 1.0  # unmet, as it had to be


def test_weighted_mode_equals_strict_where_the_levels_do_not_conflict(panda):
    hand, stack = hand_stack(panda)
    q = panda.home()
    goal = panda.frame_pose(q, "panda_hand_tcp")
    goal[:3, 3] += (0.02, 0.0, 0.0)
    hand.set_target(goal)
    u = np.zeros(panda.nu)
    only_hand = wb.Stack(panda, [[hand]], stack.constraints)
    strict = DynamicsSolver(panda).solve(only_hand, q, u, DT)
    weighted = DynamicsSolver(panda, mode="weighted").solve(only_hand, q, u, DT)
    assert np.allclose(strict.a, weighted.a, atol=1e-9)
    # with the posture summed in, the hand gives way a little: no longer met exactly
    w2 = DynamicsSolver(panda, mode="weighted", level_weights=[1.0, 1.0]).solve(stack, q, u, DT)
    s2 = DynamicsSolver(panda).solve(stack, q, u, DT)
    assert s2.solution.task_residuals[hand.name] < 1e-8 < w2.solution.task_residuals[hand.name]


@pytest.mark.slow
def test_a_slow_reach_agrees_with_the_velocity_hqp(panda):
    """Panda's hand 10 cm away, gains low: the torque-level run (integrated) follows the
    velocity-level one within a millimetre and ends on the goal."""
    goal_shift = np.array([0.1, -0.05, 0.05])
    hand, stack = hand_stack(panda, kp=2.0)
    q0 = panda.home()
    goal = panda.frame_pose(q0, "panda_hand_tcp")
    goal[:3, 3] += goal_shift
    hand.set_target(goal)
    controller = wb.Controller(panda, stack, wb.HierarchicalQPSolver(), dt=DT, recovery=False)
    q = q0.copy()
    kin = []
    for _ in range(2500):
        controller.step(q)
        q = controller.q_next.copy()
        kin.append(panda.frame_pose(q, "panda_hand_tcp")[:3, 3])
    hand2, stack2 = hand_stack(panda, kp=2.0)
    hand2.set_target(goal)
    solver = DynamicsSolver(panda, velocity_gain=200.0, acceleration_limits=False)
    q, u = q0.copy(), np.zeros(panda.nu)
    gap = 0.0
    for k in range(2500):
        q, u, _ = run(panda, stack2, solver, q, u, 1)
        gap = max(gap, np.linalg.norm(panda.frame_pose(q, "panda_hand_tcp")[:3, 3] - kin[k]))
    assert gap < 2e-3
    assert np.linalg.norm(panda.frame_pose(q, "panda_hand_tcp")[:3, 3] - goal[:3, 3]) < 1e-3


def test_a_point_contact_holds_its_point_within_its_pyramid(panda):
    """The Panda's hand pressed on a table as a point contact (normal up): the hand's point
    stays, the force stays in the pyramid, and the arm obeys its torque limits."""
    q = panda.home()
    hand = PointContact("panda_hand_tcp", mu=0.5, f_min=2.0)
    solver = DynamicsSolver(panda, [hand])
    solver.make_contacts(q)
    stack = wb.Stack(panda, [[wb.PostureTask(panda, kp=1.0)]], [wb.VelocityLimits(panda)])
    c = 0.5 / np.sqrt(2.0)
    q1, _, _ = run(
        panda,
        stack,
        solver,
        q,
        np.zeros(panda.nu),
        50,
        lambda q, u, r: _point_ok(r.wrenches["panda_hand_tcp"], c, 2.0),
    )
    assert np.linalg.norm(panda.frame_pose(q1, "panda_hand_tcp")[:3, 3] - hand.reference) < 1e-6


def _point_ok(f, c, f_min):
    assert f[2] >= f_min - 1e-6
    assert abs(f[0]) <= c * f[2] + 1e-6 and abs(f[1]) <= c * f[2] + 1e-6


def test_bad_input_is_refused_clearly(panda, talos):
    with pytest.raises(ConfigError, match="no frame"):
        DynamicsSolver(panda, [PatchContact("nowhere")])
    with pytest.raises(ConfigError, match="mu"):
        PatchContact("panda_hand_tcp", mu=-1.0)
    with pytest.raises(ConfigError, match="f_min"):
        PointContact("panda_hand_tcp", f_min=20.0, f_max=10.0)
    with pytest.raises(ConfigError, match="mode"):
        DynamicsSolver(panda, mode="soft")
    with pytest.raises(ConfigError, match="never made"):
        DynamicsSolver(panda, [PointContact("panda_hand_tcp")]).solve(
            hand_stack(panda)[1], panda.home(), np.zeros(panda.nu), DT
        )
    solver = DynamicsSolver(panda)
    with pytest.raises(DimensionError, match=r"u \(8,\)"):
        solver.solve(hand_stack(panda)[1], panda.home(), np.zeros(3), DT)
    with pytest.raises(ConfigError, match="another robot"):
        solver.solve(standing(talos)[1], panda.home(), np.zeros(panda.nu), DT)


def test_a_force_task_sets_a_contacts_wrench_above_the_tasks(panda):
    """The Panda's hand pressing down on a table with 20 N (a wrench target on its point
    contact, the tangential force left free): met exactly every step, while the posture
    below moves the arm; without it the contact takes the least force it can."""
    q = panda.home()
    hand = PointContact("panda_hand_tcp", mu=0.5, f_min=1.0)
    solver = DynamicsSolver(panda, [hand])
    solver.make_contacts(q)
    stack = wb.Stack(panda, [[wb.PostureTask(panda, kp=1.0)]], [wb.VelocityLimits(panda)])
    assert solver.solve(stack, q, np.zeros(panda.nu), DT).wrenches["panda_hand_tcp"][2] < 20.0
    hand.set_wrench_target([np.nan, np.nan, 20.0])

    def pressing(q, u, res):
        assert abs(res.wrenches["panda_hand_tcp"][2] - 20.0) < 1e-6
        assert max(res.violations.values()) < 1e-6

    run(panda, stack, solver, q, np.zeros(panda.nu), 50, pressing)
    with pytest.raises(ConfigError, match="wrench target"):
        hand.set_wrench_target([0.0, 20.0])


@pytest.mark.slow
def test_an_infeasible_weighted_step_falls_back_to_the_cascade(talos):
    """Soles that take at most 100 N each cannot carry TALOS: the weighted QP has no
    answer, the cascade solves the same levels instead (the contacts held as closely as the
    bounds allow), and the step is INFEASIBLE with the excess named; with soles that can,
    the QP answers."""
    _, stack, solver, q = standing(talos, mode="weighted")
    u = np.zeros(talos.nu)
    assert solver.solve(stack, q, u, DT).status in (SolverStatus.OK, SolverStatus.BOUNDS_ACTIVE)
    assert not solver.cascaded
    for f in FEET:
        solver.remove_contact(f)
        solver.add_contact(PatchContact(f, mu=0.3, f_max=100.0, half_length=0.1, half_width=0.065))
    solver.make_contacts(q)
    res = solver.solve(stack, q, u, DT)
    assert solver.cascaded and res.status == SolverStatus.INFEASIBLE
    assert max(res.violations.values()) > 1.0  # N: a whole-body weight short
    assert res.solution.task_residuals["contact left_sole_link"] >= 0.0  # (it reports)
