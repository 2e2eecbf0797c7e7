"""The kernels the torque step is made of beyond its QP, against independent oracles: the
whole-body centre of mass (:func:`wholebody.kernels.rows.com_rows`) against Pinocchio's and
finite differences, the contacts' rows (:mod:`wholebody.kernels.contacts`) against
Pinocchio's frame Jacobians, velocities, accelerations, ``log6`` and dual action matrices,
and the forward difference's first half on the kernels' own kinematics
(:func:`wholebody.kernels.torque.ahead`) against the same on Pinocchio's.

Run in the three modes (compiled, ``NUMBA_DISABLE_JIT=1``, ``NUMBA_BOUNDSCHECK=1``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.dynamics import DynamicsSolver, PatchContact, PointContact
from wholebody.kernels import contacts as kc

DT = 1e-3
LOCAL = pin.ReferenceFrame.LOCAL
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@pytest.mark.parametrize("name", ["talos_full", "panda", "mobile_humanoid", "centauro"])
def test_the_com_rows_are_pinocchios_centre_of_mass_and_its_jacobian(rng, name):
    """``com_rows`` (a ComTask's rows) against Pinocchio's ``centerOfMass`` and
    ``jacobianCenterOfMass`` (with a fixed base's welded mass, :mod:`wholebody.robot.com`),
    and ``J_c u`` against a central difference of the centre of mass along ``u``."""
    robot = wb.load_robot(name)
    target, kp = np.array([0.1, -0.2, 0.7]), 3.0
    task = wb.ComTask(robot, "xyz", target=target, kp=kp)
    for _ in range(3):
        q = robot.random_configuration(rng)
        state = robot.update(q)
        rows = task.compute(state)
        c, Jc = state.com_position(), state.com_jacobian()  # Pinocchio's
        np.testing.assert_allclose(rows.J, Jc, atol=1e-12)
        np.testing.assert_allclose(rows.v, kp * (target - c), atol=1e-12)
        u, h = rng.normal(size=robot.nu), 1e-6
        rate = (
            robot.com_position(robot.integrate(q, u, h))
            - robot.com_position(robot.integrate(q, u, -h))
        ) / (2 * h)
        np.testing.assert_allclose(rows.J @ u, rate, atol=1e-7 * (1 + np.abs(rate).max()))


class PythonCom(wb.ComTask):
    """A ComTask the stack evaluates in Python (a subclass overriding one of its methods)."""

    def error(self, state):
        return super().error(state)


def test_the_compiled_com_task_is_its_python_evaluation(rng):
    """A stack with a ComTask evaluated by the kernel equals the same stack with the task
    evaluated in Python (a subclass: the stack then asks the task for its rows)."""

    robot = wb.load_robot("talos_full")
    q = robot.random_configuration(rng)
    problems = []
    for cls in (wb.ComTask, PythonCom):
        task = cls(robot, "xy", kp=2.0, weight=3.0)
        stack = wb.Stack(robot, [[task], [wb.PostureTask(robot)]], [wb.VelocityLimits(robot)])
        problems.append(stack.evaluate(robot.update(q), DT))
    np.testing.assert_allclose(problems[0].levels[0].A, problems[1].levels[0].A, atol=1e-14)
    np.testing.assert_allclose(problems[0].levels[0].b, problems[1].levels[0].b, atol=1e-14)


def test_log6_is_pinocchios(rng):
    """The contacts' drift ``log6(M_ref^-1 M)`` against Pinocchio's, at large, small and
    tiny rotations (Pinocchio's Taylor branch); to 1e-12 (the rotation's angle is
    Pinocchio's ``acos``, whose error grows as the angle shrinks)."""
    for scale in (1.0, 1e-3, 1e-7, 0.0):
        ref = pin.SE3.Random()
        M = ref * pin.exp6(pin.Motion(rng.normal(size=6) * scale))
        out = np.empty(6)
        kc.log6(ref.actInv(M).rotation, ref.actInv(M).translation, out)
        np.testing.assert_allclose(out, pin.log6(ref.actInv(M)).vector, rtol=0, atol=1e-12)


def _solved(robot, contact, q, u):
    """One weighted step with ``contact`` made at ``q`` then moved (the robot at ``q``, going
    at ``u``), and the step's layout."""
    solver = DynamicsSolver(robot, [contact], mode="weighted")
    solver.make_contacts(robot.home())
    stack = wb.Stack(robot, [[wb.PostureTask(robot, kp=1.0)]], [])
    solver.solve(stack, q, u, DT)
    return solver


@pytest.mark.parametrize("kind", ["patch", "point"])
def test_the_contact_rows_are_pinocchios(rng, kind):
    """A contact's rows in the step (the Panda's hand, made at home, the arm then moved):
    its Jacobian, ``-kp e - kd V - Jdot v`` and its map to the world against Pinocchio's
    frame Jacobian, ``log6``, frame velocity and acceleration at zero joint acceleration
    (``LOCAL`` for a patch, the classical one in world axes for a point) and dual action
    matrix."""
    robot = wb.load_robot("panda")
    frame = "panda_hand_tcp"
    if kind == "patch":
        contact = PatchContact(frame, kp=30.0, kd=4.0)
    else:
        contact = PointContact(frame, kp=30.0, kd=4.0)
    q = robot.integrate(robot.home(), rng.normal(size=robot.nu), 0.05)
    u = rng.normal(scale=0.8, size=robot.nu)
    layout = _solved(robot, contact, q, u).layout
    model, data = robot.model, robot.model.createData()
    fid, v = model.getFrameId(frame), robot.actuation @ u
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)
    pin.computeJointJacobians(model, data, q)
    here = data.oMf[fid]
    if kind == "patch":
        J = pin.getFrameJacobian(model, data, fid, LOCAL)
        e = pin.log6(pin.SE3(contact.reference).actInv(here)).vector
        V = pin.getFrameVelocity(model, data, fid, LOCAL).vector
        drift = pin.getFrameAcceleration(model, data, fid, LOCAL).vector
        G = here.toDualActionMatrix()
    else:
        J = pin.getFrameJacobian(model, data, fid, LWA)[:3]
        e = here.translation - contact.reference
        V = pin.getFrameVelocity(model, data, fid, LWA).linear
        drift = pin.getFrameClassicalAcceleration(model, data, fid, LWA).linear
        G = np.vstack([np.eye(3), pin.skew(here.translation)])
    k = contact.size
    np.testing.assert_allclose(layout.Jw[:k], J, atol=1e-12)
    np.testing.assert_allclose(layout.eq_dv[:k], J, atol=1e-12)
    np.testing.assert_allclose(layout.G, G, atol=1e-12)
    wanted = -contact.kp * e - contact.kd * V - drift
    assert np.abs(layout.eq_b[:k] - wanted).max() < 1e-6 * (1 + np.abs(drift).max())


def test_the_rows_ahead_on_the_kernels_kinematics_are_pinocchios(rng):
    """``Jdot u`` of a compiled stack (the forward difference's first half in one kernel on
    the kernels' own kinematics) and the soles' velocities there equal the same computed on
    Pinocchio's kinematics (the path of a stack with an entry evaluated in Python)."""
    robot = wb.load_robot("talos_full")
    q, u = robot.home(), rng.normal(scale=0.5, size=robot.nu)
    out = []
    for com in (wb.ComTask(robot, "xyz"), PythonCom(robot, "xyz")):
        hand = wb.FrameTask(robot, "gripper_left_base_link", kp=2.0)
        levels = [[com, hand], [wb.PostureTask(robot)]]
        stack = wb.Stack(robot, levels, [wb.JointPositionLimits(robot)])
        feet = [PatchContact(f) for f in ("left_sole_link", "right_sole_link")]
        solver = DynamicsSolver(robot, feet)
        out.append((solver.drifts(stack, q, u, DT), solver._twists.copy()))
    (d0, t0), (d1, t1) = out
    assert np.abs(d0 - d1).max() < 1e-6 * (1 + np.abs(d1).max())
    np.testing.assert_allclose(t0, t1, atol=1e-12)
    assert np.abs(t1).max() > 1e-3  # (the soles move: the twists were computed)
