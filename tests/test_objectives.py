"""Objectives: analytic gradients against finite differences, the arm angle, and the kinematic
Hessian used by the manipulability gradient."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import gradient_fd
from test_tasks import configurations

from wholebody.errors import FrameError
from wholebody.humanlike import StiffnessModel, arm_angle
from wholebody.robot.hessian import actuated_support_mask, frame_hessian
from wholebody.tasks import ArmPotentialEnergy, JointLimitAvoidance, Manipulability


class QuadraticStiffness(StiffnessModel):
    """A smooth non-constant k(p) to exercise the chain rule through the wrist position."""

    def evaluate(self, wrist):
        p = np.asarray(wrist)
        return 0.4 + p @ p + p[0] * p[2], 2 * p + np.array([p[2], 0.0, p[0]])


def check_gradient(robot, objective, qs, rtol=1e-6):
    for q in qs:
        value = objective.evaluate(robot.update(q))
        fd = gradient_fd(robot, q, lambda qq: objective.evaluate(robot.update(qq)).value)
        scale = max(1.0, np.abs(fd).max())
        np.testing.assert_allclose(value.gradient / scale, fd / scale, atol=rtol)


@pytest.mark.parametrize("arm", ["left", "right"])
@pytest.mark.parametrize("stiffness", ["constant", "model"])
@pytest.mark.parametrize("reference", ["shoulder", "world"])
def test_arm_energy_gradient(humanoid, rng, arm, stiffness, reference):
    k = 0.8 if stiffness == "constant" else QuadraticStiffness()
    objective = ArmPotentialEnergy(humanoid, arm, k, reference=reference)
    check_gradient(humanoid, objective, configurations(humanoid, rng))


def test_arm_energy_parts(humanoid, rng):
    arm = humanoid.arms["right"]
    energy = ArmPotentialEnergy(humanoid, arm, 0.7, reference="world")
    for _ in range(50):  # a bent arm, away from the smoothing (0.05 rad) and the fade
        state = humanoid.update(humanoid.random_configuration(rng, margin=0.1))
        v = energy.evaluate(state)
        if v.rho > 0.05 and abs(v.arm_angle) > 0.3:
            break
    else:
        pytest.fail("no bent-arm configuration found")
    g = 9.81
    c1, c2 = state.com_position(arm.upper_arm), state.com_position(arm.forearm)
    assert v.gravity == pytest.approx(g * (2.0 * c1[2] + 1.5 * c2[2]), rel=1e-12)
    S, E, W = (state.position(f) for f in (arm.shoulder, arm.elbow, arm.wrist))
    alpha = arm_angle(S, E, W, -1.0)
    assert v.arm_angle == pytest.approx(alpha, abs=1e-12)
    assert v.stiffness == 0.7
    fade = v.rho**2 / (v.rho**2 + energy.fade**2)  # the spring fades out as rho -> 0
    assert v.spring == pytest.approx(0.5 * 0.7 * (np.pi - abs(alpha)) ** 2 * fade, rel=1e-12)
    assert v.value == pytest.approx(v.gravity + v.spring, rel=1e-12)
    shoulder = ArmPotentialEnergy(humanoid, arm, 0.7).evaluate(state)
    assert shoulder.gravity == pytest.approx(v.gravity - g * 3.5 * S[2], rel=1e-12)


def test_arm_energy_defined_for_a_straight_hanging_arm(humanoid):
    """At q = 0 the arm is straight and vertical: the arm angle is undefined there, but the
    energy and its gradient exist (the spring fades out) and match finite differences."""
    objective = ArmPotentialEnergy(humanoid, "left", 1.0)
    v = objective.evaluate(humanoid.update(humanoid.neutral()))
    assert np.all(np.isfinite(v.gradient)) and v.rho < 1e-9
    check_gradient(humanoid, objective, [humanoid.neutral()], rtol=1e-5)


def test_joint_limit_avoidance_gradient_and_curvature(humanoid, rng):
    objective = JointLimitAvoidance(humanoid)
    assert objective.indices.size == 19  # the paper's 19 revolute joints
    check_gradient(humanoid, objective, configurations(humanoid, rng))
    q = humanoid.random_configuration(rng, margin=0.05)
    v = objective.evaluate(humanoid.update(q))
    # the curvature is the exact second derivative (diagonal)
    eps = 1e-6
    for k in objective.indices[:5]:
        u = np.zeros(humanoid.nu)
        u[k] = 1.0
        gp = objective.evaluate(humanoid.update(humanoid.integrate(q, u, eps))).gradient[k]
        gm = objective.evaluate(humanoid.update(humanoid.integrate(q, u, -eps))).gradient[k]
        assert v.curvature[k] == pytest.approx((gp - gm) / (2 * eps), rel=1e-5)
    mid = humanoid.configuration(
        {
            n: 0.5 * (lo + hi)
            for n, lo, hi in zip(humanoid.actuated_joints, *humanoid.position_limits, strict=True)
            if np.isfinite(lo)
        }
    )
    assert objective.evaluate(humanoid.update(mid)).value == pytest.approx(19.0)


def test_joint_limit_avoidance_stays_finite_outside_limits(humanoid):
    objective = JointLimitAvoidance(humanoid, ["right_arm"])
    q = humanoid.neutral()
    i = humanoid.index("right_elbow_flexion")
    q[humanoid.model.joints[humanoid.model.getJointId("right_elbow_flexion")].idx_q] = -0.5
    v = objective.evaluate(humanoid.update(q))
    assert np.isfinite(v.value) and np.all(np.isfinite(v.gradient))
    assert v.gradient[i] < 0  # descending the gradient moves the elbow back inside


def test_joint_limit_avoidance_takes_one_group_name(humanoid, rng):
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.1))
    one = JointLimitAvoidance(humanoid, "left_arm").evaluate(state)
    listed = JointLimitAvoidance(humanoid, ["left_arm"]).evaluate(state)
    assert one.value == listed.value and np.array_equal(one.gradient, listed.gradient)


def test_unknown_arm_is_a_frame_error_with_a_suggestion(humanoid):
    with pytest.raises(FrameError, match=r"no arm 'Left'.*left"):
        ArmPotentialEnergy(humanoid, "Left", 1.0)


@pytest.mark.parametrize("frames", [["left_tool", "right_tool"], ["right_tool"]])
def test_manipulability_gradient(humanoid, rng, frames):
    objective = Manipulability(humanoid, frames)
    check_gradient(humanoid, objective, configurations(humanoid, rng), rtol=1e-6)
    value = objective.evaluate(humanoid.update(humanoid.home())).value
    J = np.vstack([humanoid.frame_jacobian(humanoid.home(), f) for f in frames])
    assert value == pytest.approx(np.sqrt(np.linalg.det(J @ J.T)))


def test_kinematic_hessian_matches_finite_differences(humanoid, torso, rng):
    for robot, frames in ((humanoid, ["left_tool", "right_wrist_centre"]), (torso, ["right_tool"])):
        mask = actuated_support_mask(robot)
        q = robot.random_configuration(rng, margin=0.05)
        for name in frames:
            frame = robot.frame(name)
            H = frame_hessian(robot.update(q), frame, mask)
            for k in range(robot.nu):
                u = np.zeros(robot.nu)
                u[k] = 1.0
                fd = (
                    robot.frame_jacobian(robot.integrate(q, u, 1e-6), frame)
                    - robot.frame_jacobian(robot.integrate(q, u, -1e-6), frame)
                ) / 2e-6
                np.testing.assert_allclose(H[:, :, k], fd, atol=1e-7)


def lowest_highest_outward(S, W, side):
    u = (W - S) / np.linalg.norm(W - S)
    r = np.array([0, 0, -1.0]) + u[2] * u
    r /= np.linalg.norm(r)
    out = np.cross(u, np.array([0, 0, -1.0]))
    out *= side / np.linalg.norm(out)
    mid = S + 0.5 * (W - S)
    return mid + 0.1 * r, mid - 0.1 * r, mid + 0.1 * out


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_arm_angle_reference_points(rng, side):
    for _ in range(5):
        S = rng.normal(size=3)
        W = S + rng.normal(size=3) * [0.3, 0.3, 0.2] + [0.3, -0.2 * side, -0.2]
        low, high, outward = lowest_highest_outward(S, W, side)
        assert arm_angle(S, low, W, side) == pytest.approx(0.0, abs=1e-12)
        assert abs(arm_angle(S, high, W, side)) == pytest.approx(np.pi, abs=1e-12)
        assert arm_angle(S, outward, W, side) == pytest.approx(np.pi / 2, abs=1e-12)


def test_arm_angle_equal_for_mirrored_postures(humanoid, rng):
    M = np.diag([1.0, -1.0, 1.0])
    for _ in range(10):
        S, E, W = rng.normal(size=(3, 3))
        assert arm_angle(S, E, W, 1.0) == pytest.approx(arm_angle(M @ S, M @ E, M @ W, -1.0))
    # on the robot: the same joint values give mirror postures, hence equal arm angles
    names_l, names_r = humanoid.group("left_arm").joints, humanoid.group("right_arm").joints
    values = rng.uniform(-0.4, 0.4, 8) + np.array([0, 0.6, 0.3, 0, 1.0, 0, 0, 0])
    q = humanoid.configuration(
        {**dict(zip(names_l, values, strict=True)), **dict(zip(names_r, values, strict=True))}
    )
    state = humanoid.update(q)
    angles = [
        ArmPotentialEnergy(humanoid, a, 1.0).evaluate(state).arm_angle for a in ("left", "right")
    ]
    assert angles[0] == pytest.approx(angles[1], abs=1e-12)


def test_joint_limit_avoidance_names_groups_and_joints(humanoid):
    from wholebody.errors import WholebodyError
    from wholebody.tasks import JointLimitAvoidance

    with pytest.raises(WholebodyError, match=r"'rigth_arm' is neither a joint group .*'right_arm'"):
        JointLimitAvoidance(humanoid, ["left_arm", "rigth_arm"])
    both = JointLimitAvoidance(humanoid, ["left_arm", "waist_yaw"])
    assert humanoid.index("waist_yaw") in both.indices.tolist()
