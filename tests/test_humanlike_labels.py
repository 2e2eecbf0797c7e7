"""Posture mapping, canonical axes and the stiffness label against the gravity energy."""

from __future__ import annotations

import numpy as np
import pytest

from wholebody.arm.angle import arm_angle
from wholebody.humanlike.arm_angle_model import elbow_on_circle
from wholebody.humanlike.labels import (
    frame_rules,
    gravity_energy,
    rotate_elbow,
    stiffness_labels,
)
from wholebody.humanlike.mapping import (
    CANONICAL_SIDE,
    ArmParameters,
    canonical_to_lab,
    lab_to_canonical,
    map_to_robot,
)


@pytest.fixture(scope="module")
def params(humanoid) -> ArmParameters:
    return ArmParameters.from_robot(humanoid, "right")


def _postures(rng: np.random.Generator, n: int, L1: float = 0.3, L2: float = 0.27):
    """Random human-like postures (shoulder-relative, canonical axes) with alpha in +-1.2 rad."""
    S = rng.normal(0.0, 0.05, (n, 3))
    d = rng.normal(size=(n, 3))
    d[:, 0] = np.abs(d[:, 0]) + 0.3
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    W = S + d * rng.uniform(0.25, 0.9, (n, 1)) * (L1 + L2)
    alpha = rng.uniform(-1.2, 1.2, n)
    return S, elbow_on_circle(S, W, L1, L2, alpha, CANONICAL_SIDE), W, alpha


def test_parameters_come_from_the_robot_model(humanoid, torso):
    for robot in (humanoid, torso):
        for side in ("left", "right"):
            p = ArmParameters.from_robot(robot, side)
            arm = robot.arms[side]
            assert p.upper_arm == arm.upper_arm_length and p.forearm == arm.forearm_length
            assert (p.upper_arm_mass, p.forearm_mass) == (arm.upper_arm.mass, arm.forearm.mass)
            state = robot.update(robot.home())
            S, E = state.position(arm.shoulder), state.position(arm.elbow)
            c1 = S + p.upper_arm_com * (E - S)
            np.testing.assert_allclose(c1, state.com_position(arm.upper_arm), atol=1e-9)
    p = ArmParameters.from_robot(humanoid, "right")
    assert (p.upper_arm_com, p.forearm_com) == pytest.approx((0.45, 0.43))  # robots/README
    assert p.lever == pytest.approx(9.81 * (2.0 * 0.45 + 1.5 * 0.57))


def test_label_equals_derivative_of_gravity_energy_over_arm_angle(params, rng):
    """k (pi - |alpha|) = d f_g / d|alpha|, by central differences of the gravity energy under
    a rotation of the elbow about the shoulder-wrist line at fixed S and W."""
    S, E, W, alpha = _postures(rng, 40, params.upper_arm, params.forearm)
    lab = stiffness_labels(S, E, W, params)
    np.testing.assert_allclose(lab.alpha, alpha, atol=1e-12)
    h = 1e-6
    # which rotation sense increases alpha in these axes
    sense = np.sign(arm_angle(S, rotate_elbow(S, E, W, h), W, CANONICAL_SIDE) - alpha)
    assert np.all(sense == sense[0])
    fg = lambda a: gravity_energy(S, rotate_elbow(S, E, W, sense[0] * a), W, params)  # noqa: E731
    dfg = (fg(h) - fg(-h)) / (2 * h)  # d f_g / d alpha
    dfg_dmag = dfg * np.sign(alpha)
    np.testing.assert_allclose(lab.k * (np.pi - np.abs(alpha)), dfg_dmag, rtol=1e-6, atol=1e-8)
    assert np.all(lab.k >= 0)
    assert (alpha < 0).any() and (alpha > 0).any()
    # the closed form: f_g = const - A cos(alpha)
    np.testing.assert_allclose(dfg, lab.amplitude * np.sin(alpha), rtol=1e-6, atol=1e-8)


def test_label_is_even_in_alpha(params, rng):
    S, E, W, alpha = _postures(rng, 10, params.upper_arm, params.forearm)
    E_mirror = elbow_on_circle(S, W, params.upper_arm, params.forearm, -alpha, CANONICAL_SIDE)
    k1 = stiffness_labels(S, E, W, params).k
    k2 = stiffness_labels(S, E_mirror, W, params).k
    np.testing.assert_allclose(k1, k2, rtol=1e-10)


def test_mapping_keeps_directions_and_gives_robot_lengths(params, rng):
    S, E, W, _ = _postures(rng, 50)
    E_R, W_R = map_to_robot(S, E, W, params.upper_arm, params.forearm)
    np.testing.assert_allclose(np.linalg.norm(E_R - S, axis=1), params.upper_arm, rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(W_R - E_R, axis=1), params.forearm, rtol=1e-14)
    unit = lambda v: v / np.linalg.norm(v, axis=1, keepdims=True)  # noqa: E731
    np.testing.assert_allclose(unit(E_R - S), unit(E - S), atol=1e-14)
    np.testing.assert_allclose(unit(W_R - E_R), unit(W - E), atol=1e-14)
    # the wrist moves when the length ratio changes
    assert np.linalg.norm(W_R - W, axis=1).min() > 1e-3


def test_canonical_axes_mirror_left_arms(rng):
    """A left arm and the mirror-image right arm give the same canonical posture and arm
    angle, which equals the lab-frame arm angle with the arm's own side."""
    S, E, W, _ = _postures(rng, 20)
    lab_R = [canonical_to_lab(v, "R") for v in (S, E, W)]
    mirror = np.array([-1.0, 1.0, 1.0])  # lab x is the participant's right
    lab_L = [v * mirror for v in lab_R]
    for side, lab, sign in (("R", lab_R, -1.0), ("L", lab_L, 1.0)):
        can = [lab_to_canonical(v, side) for v in lab]
        for a, b in zip(can, (S, E, W), strict=True):
            np.testing.assert_allclose(a, b, atol=1e-15)
        np.testing.assert_allclose(
            arm_angle(*lab, sign), arm_angle(*can, CANONICAL_SIDE), atol=1e-12
        )
    # right arm: +y canonical (medial) is the participant's left (-x lab)
    np.testing.assert_allclose(lab_to_canonical(np.array([-1.0, 0.0, 0.0]), "R"), [0, 1, 0])
    np.testing.assert_allclose(lab_to_canonical(np.array([1.0, 0.0, 0.0]), "L"), [0, 1, 0])


def test_frame_rules_flag_straight_and_vertical_arms(params):
    S = np.zeros((3, 3))
    W = np.array([[0.3, 0.0, -0.3], [0.05, 0.0, -0.45], [0.50, 0.0, -0.1]])
    E = elbow_on_circle(S, W, params.upper_arm, params.forearm, 0.3, CANONICAL_SIDE)
    lab = stiffness_labels(S, E, W, params)
    rules = frame_rules(lab, np.array([0.0, 0.0, 0.03]))
    assert rules["straight"].tolist() == [False, False, True]  # W 0.51 m away: nearly straight
    assert rules["vertical"].tolist() == [False, True, False]  # 6 deg from vertical
    assert rules["forearm"].tolist() == [False, False, True]
