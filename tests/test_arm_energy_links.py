"""The arm energy of real robots, whose arm segments are split over several links (TIAGo++'s
and TALOS's forearms: ``forearm = ["arm_*_4_link", "arm_*_5_link"]``), in the kernel.

* The energy, its parts and its gradient, from the kernel called by
  :meth:`ArmPotentialEnergy.evaluate` and inside the compiled step, equal an independent
  computation: the links' masses and centres of mass from Pinocchio's model (the joints'
  inertias placed by ``data.oMi``), the arm angle from its geometric definition, the
  stiffness network in numpy; the gradient equals central differences of that computation
  through :meth:`Robot.integrate`.
* A stack with both arms' energies steps in one kernel call, with the ``u`` of the same stack
  whose energies run as Python entries (Pinocchio's kinematics, the energy evaluated in
  Python and copied into the arena), to rounding.

Runs compiled, with ``NUMBA_DISABLE_JIT=1`` and with ``NUMBA_BOUNDSCHECK=1``.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pinocchio as pin
import pytest
from fdcheck import gradient_fd

import wholebody
from wholebody.arm.network import default_stiffness
from wholebody.arm.stiffness import StiffnessModel
from wholebody.control import Controller
from wholebody.robot.urdf import example_robot_data_share
from wholebody.solvers import Level, ProjectionSolver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import (
    AccelerationLimits,
    ArmPotentialEnergy,
    FrameTask,
    JointLimitAvoidance,
    JointPositionLimits,
    VelocityLimits,
)

pytestmark = pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="example-robot-data is not installed (pip install '.[robots]' from the checkout)",
)

UNCOMPILED = os.environ.get("NUMBA_DISABLE_JIT", "0") == "1"
STEPS = 3 if UNCOMPILED else 15  # plain-Python kernels run ~100x slower
TOOLS = {
    "tiago_dual": ("arm_left_tool_link", "arm_right_tool_link"),
    "talos_upper": ("gripper_left_base_link", "gripper_right_base_link"),
}
SOLVERS = {"projection": ProjectionSolver, "hqp": HierarchicalQPSolver}


@pytest.fixture(scope="module", params=sorted(TOOLS))
def robot(request) -> wholebody.Robot:
    return wholebody.load_robot(request.param)


@pytest.fixture(scope="module")
def network():
    """A stiffness network the kernels evaluate (the shipped humanoid's: any k(p) serves)."""
    return default_stiffness("mobile_humanoid")


def test_the_real_robots_split_a_segment_over_several_links(robot):
    for arm in robot.arms.values():
        links = arm.upper_arm_bodies + arm.forearm_bodies  # as robot.toml names them
        assert len(links) > 2
        assert ArmPotentialEnergy(robot, arm, 0.1).links == links


# ---------------------------------------------------------------------- the oracle
class Oracle:
    """An arm's energy (J) computed from Pinocchio's model and the definitions of the
    module docstring of :mod:`wholebody.tasks.arm_energy`, on its own ``pin.Data``."""

    def __init__(self, robot, arm, stiffness, reference, smoothing=0.05, fade=0.01):
        model = robot.model
        self.robot, self.model, self.data = robot, model, model.createData()
        self.stiffness, self.reference = stiffness, reference
        self.smoothing, self.fade = smoothing, fade
        self.side = 1.0 if arm.side == "left" else -1.0
        frame = model.getFrameId
        self.S, self.E, self.W = (frame(f.name) for f in (arm.shoulder, arm.elbow, arm.wrist))
        self.base = frame(robot.base_frame.name)
        self.links = []  # (joint, mass kg, centre of mass in the joint frame m)
        for body in arm.upper_arm_bodies + arm.forearm_bodies:  # the links robot.toml names
            f = model.frames[frame(body.name)]
            joint = f.parentJoint
            # the link is its joint's body, alone on it: the joint's inertia is the link's
            assert f.placement.isIdentity()
            assert not any(o.parentJoint == joint and o.inertia.mass > 0 for o in model.frames)
            inertia = model.inertias[joint]
            self.links.append((joint, inertia.mass, inertia.lever.copy()))
        self.g = float(np.linalg.norm(model.gravity.linear))

    def __call__(self, q):
        """``(value, gravity, spring)`` (J) at ``q``."""
        model, data = self.model, self.data
        pin.framesForwardKinematics(model, data, q)
        S, E, W = (data.oMf[i].translation for i in (self.S, self.E, self.W))
        height = S[2] if self.reference == "shoulder" else 0.0
        gravity = sum(self.g * m * (data.oMi[j].act(c)[2] - height) for j, m, c in self.links)
        u = (W - S) / np.linalg.norm(W - S)
        down = np.array([0.0, 0.0, -1.0]) + u[2] * u  # -z projected across the line S-W
        elbow = E - S
        x, y = down @ elbow, self.side * (np.cross(u, down) @ elbow)  # 0: elbow lowest
        alpha, rho2 = math.atan2(y, x), x * x + y * y
        d = self.smoothing
        s = alpha * alpha / (2 * d) + d / 2 if abs(alpha) < d else abs(alpha)
        fade = rho2 / (rho2 + self.fade**2)
        if isinstance(self.stiffness, float):
            k = self.stiffness
        else:  # at the wrist in the arm's canonical axes: Mirror R_b^T (W - S)
            p = data.oMf[self.base].rotation.T @ (W - S)
            k = self.stiffness.evaluate(p * np.array([1.0, -self.side, 1.0]))[0]
        spring = 0.5 * k * (np.pi - s) ** 2 * fade
        return gravity + spring, gravity, spring

    def gradient(self, q):
        """Central differences of the value through ``robot.integrate`` (actuated)."""
        return gradient_fd(self.robot, q, lambda qq: self(qq)[0])


def assert_gradient(grad, fd):
    scale = max(1.0, np.abs(fd).max())
    np.testing.assert_allclose(grad / scale, fd / scale, atol=1e-6)


class QuadraticStiffness(StiffnessModel):
    """A model of your own: evaluated in Python, its k and dk/dp handed to the kernel."""

    def evaluate(self, wrist):
        p = np.asarray(wrist)
        return 0.4 + p @ p + p[0] * p[2], 2 * p + np.array([p[2], 0.0, p[0]])


@pytest.mark.parametrize("reference", ["shoulder", "world"])
@pytest.mark.parametrize("stiffness", ["constant", "network", "model"])
def test_energy_and_gradient_are_pinocchios_links(robot, network, rng, stiffness, reference):
    k = {"constant": 0.3, "network": network, "model": QuadraticStiffness()}[stiffness]
    for arm in robot.arms.values():
        energy = ArmPotentialEnergy(robot, arm, k, reference=reference)
        oracle = Oracle(robot, arm, k, reference)
        for _ in range(3):
            q = robot.random_configuration(rng, margin=0.05, base_range=0.5)
            v = energy.evaluate(robot.update(q))
            value, gravity, spring = oracle(q)
            assert v.value == pytest.approx(value, rel=1e-12, abs=1e-12)
            assert v.gravity == pytest.approx(gravity, rel=1e-12, abs=1e-12)
            assert v.spring == pytest.approx(spring, rel=1e-12, abs=1e-12)
            parts = energy.parts(robot.update(q))  # (no Jacobians)
            np.testing.assert_allclose(parts[:3], [value, gravity, spring], rtol=1e-12)
            assert_gradient(v.gradient, oracle.gradient(q))


# ---------------------------------------------------------------------- the compiled step
class PythonArmEnergy(ArmPotentialEnergy):
    """The same energy as a Python entry (a subclass overriding ``evaluate`` is one)."""

    def evaluate(self, state):
        return super().evaluate(state)


def energy_stack(robot, tools, energy, network):
    """Hands on top; the arms' energies (left: network stiffness, heights from the shoulder;
    right: constant, world heights) and joint-limit avoidance below; the limits."""
    q0 = robot.home()
    hands = []
    for i, tool in enumerate(tools):
        hand = FrameTask(robot, tool, kp=20.0, ki=5.0)
        target = robot.frame_pose(q0, tool)
        target[:3, 3] += (0.05, 0.1 * (-1) ** i, 0.08)
        hand.set_target(target)
        hands.append(hand)
    left, right = robot.arms["left"], robot.arms["right"]
    objectives = [
        energy(robot, left, network, weight=0.5),
        energy(robot, right, 0.3, weight=0.5, reference="world"),
        JointLimitAvoidance(robot, weight=0.05),
    ]
    limits = [JointPositionLimits(robot), VelocityLimits(robot), AccelerationLimits(robot)]
    return Stack(robot, [Level(hands), Level(objectives, gain=1.0)], limits), objectives


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_a_stack_of_arm_energies_steps_in_one_kernel_call(robot, network, solver):
    tools = TOOLS[robot.name]
    stack, (left, right, _) = energy_stack(robot, tools, ArmPotentialEnergy, network)
    python, _ = energy_stack(robot, tools, PythonArmEnergy, network)
    fast = Controller(robot, stack, SOLVERS[solver](), dt=0.01)
    slow = Controller(robot, python, SOLVERS[solver](), dt=0.01)
    oracles = [Oracle(robot, left.arm, network, "shoulder"), Oracle(robot, right.arm, 0.3, "world")]
    q = robot.home()
    for _ in range(STEPS):
        u = fast.step(q).copy()
        assert fast._fast and not stack.plan().python  # one kernel call
        values = stack.plan().objective_values()  # as the kernel evaluated them at q
        for energy, oracle in zip((left, right), oracles, strict=True):
            v = values[energy.name]
            assert v.value == pytest.approx(oracle(q)[0], rel=1e-12, abs=1e-12)
            assert_gradient(v.gradient, oracle.gradient(q))
        np.testing.assert_allclose(u, slow.step(q), rtol=0, atol=1e-10)
        assert [r.entry.name for r in python.plan().python] == [left.name, right.name]
        q = fast.q_next.copy()
    assert np.abs(u).max() > 1e-3  # (the hands moved the arms)
