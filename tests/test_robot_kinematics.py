"""The paper's robot against an independent modified-DH implementation of Table 1, Jacobians
against finite differences, the Mecanum base, and the paper's initial hand positions."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import frame_jacobian_fd

from wholebody import DimensionError, WholebodyError

PI = np.pi
# Table 1 of Niu et al. 2024, written out again here (alpha_{i-1}, a_{i-1} [mm], d_i [mm],
# theta_i offset), independent of robots/mobile_humanoid/generate.py.
WAIST = [(-PI / 2, 0, 0, PI), (-PI / 2, 0, 377, -PI / 2), (-PI / 2, 0, 34.5, PI)]
LEFT = [
    (-PI / 2, 144.5, 130, -PI / 2),
    (PI / 2, 0, -322.5, PI / 2),
    (PI / 2, 0, 0, PI / 2),
    (PI / 2, 0, -266.2, PI / 2),
    (PI / 2, 0, 0, 0),
    (-PI / 2, 0, -248.2, 0),
    (PI / 2, 0, 0, 0),
    (-PI / 2, 0, -336.1, PI),
]
PAPER_LEFT_HAND = np.array([0.0955, 0.43966, 0.40401])
PAPER_RIGHT_HAND = np.array([0.0955, -0.46596, 0.40401])
S = np.diag([1.0, -1.0, 1.0, 1.0])


def mdh(alpha: float, a_mm: float, d_mm: float, theta: float) -> np.ndarray:
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    a, d = a_mm / 1000, d_mm / 1000
    return np.array(
        [
            [ct, -st, 0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0, 0, 0, 1],
        ]
    )


def chain(rows: list, q: np.ndarray) -> list[np.ndarray]:
    T, out = np.eye(4), []
    for (alpha, a, d, theta), qi in zip(rows, q, strict=True):
        T = T @ mdh(alpha, a, d, theta + qi)
        out.append(T)
    return out


def dh_arm_frames(qw: np.ndarray, qa: np.ndarray, side: str, base: np.ndarray) -> list:
    """World DH frames 4..11 of one arm. Frame 0 is at (0.061, 0, 0.7475) in the base
    frame, turned by pi about z; the right arm is the mirror of the left across the
    sagittal plane y0 = 0, attached to the same chest frame."""
    mount = np.eye(4)
    mount[:3, :3] = [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]
    mount[:3, 3] = (0.061, 0.0, 0.7475)
    W = chain(WAIST, qw)[-1]
    L = chain(LEFT, qa)
    if side == "left":
        rel = L
    else:
        W0 = chain(WAIST, np.zeros(3))[-1]
        rel = [np.linalg.inv(W0) @ S @ W0 @ F @ S for F in L]
    return [base @ mount @ W @ F for F in rel]


def base_transform(x: float, y: float, yaw: float) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    T[:2, 3] = x, y
    return T


@pytest.mark.parametrize("trial", range(6))
def test_forward_kinematics_matches_table_1(humanoid, rng, trial):
    r = humanoid
    q = r.neutral() if trial == 0 else r.random_configuration(rng, base_range=2.0)
    jp = r.joint_positions(q)
    qw = jp[r.group("waist").indices]
    state = r.update(q)
    base = base_transform(*r.base_pose(q))
    for side in ("left", "right"):
        qa = jp[r.group(f"{side}_arm").indices]
        F = dh_arm_frames(qw, qa, side, base)
        arm = r.arms[side]
        np.testing.assert_allclose(state.pose(arm.tool), F[7], atol=1e-12)
        np.testing.assert_allclose(state.position(arm.shoulder), F[1][:3, 3], atol=1e-12)
        np.testing.assert_allclose(state.position(arm.elbow), F[4][:3, 3], atol=1e-12)
        np.testing.assert_allclose(state.position(arm.wrist), F[6][:3, 3], atol=1e-12)


def test_right_arm_is_the_mirror_of_the_left(humanoid, rng):
    r = humanoid
    for _ in range(5):
        arm_q = rng.uniform(-0.3, 0.3, 8) + np.array([0, 0.5, 0.3, 0, 1.0, 0, 0, 0])
        names_l = r.group("left_arm").joints
        names_r = r.group("right_arm").joints
        q = r.configuration(
            {**dict(zip(names_l, arm_q, strict=True)), **dict(zip(names_r, arm_q, strict=True))}
        )
        pl, pr = r.frame_pose(q, "left_tool"), r.frame_pose(q, "right_tool")
        np.testing.assert_allclose(pr, S @ pl @ S, atol=1e-12)


def test_zero_configuration_hands_within_3_cm_of_the_paper(humanoid):
    q = humanoid.neutral()
    left = humanoid.frame_pose(q, "left_tool")[:3, 3]
    right = humanoid.frame_pose(q, "right_tool")[:3, 3]
    assert np.linalg.norm(left - PAPER_LEFT_HAND) < 0.03
    assert np.linalg.norm(right - PAPER_RIGHT_HAND) < 0.03
    # the shoulders are at the same height (the mirrored right arm)
    sl = humanoid.frame_pose(q, "left_shoulder_centre")[:3, 3]
    sr = humanoid.frame_pose(q, "right_shoulder_centre")[:3, 3]
    assert sl[2] == pytest.approx(sr[2], abs=1e-12)


@pytest.mark.parametrize(
    "frame",
    [
        "left_tool",
        "right_tool",
        "left_elbow_centre",
        "right_elbow_centre",
        "left_wrist_centre",
        "right_wrist_centre",
    ],
)
def test_frame_jacobian_matches_finite_differences(humanoid, rng, frame):
    for _ in range(3):
        q = humanoid.random_configuration(rng, margin=0.02, base_range=3.0)
        J = humanoid.frame_jacobian(q, frame)
        np.testing.assert_allclose(J, frame_jacobian_fd(humanoid, q, frame), atol=2e-8)


def test_wheel_columns_go_through_the_mecanum_matrix(humanoid, rng):
    r = humanoid
    q = r.random_configuration(rng)
    wheels = r.group("wheels").indices
    J = r.frame_jacobian(q, "right_tool")
    # a wheel moves the hand only through the base: its column is J_base_twist @ B
    nb = r.model.joints[1].nv
    Jm = r.update(q).world_jacobian(r.frame("right_tool"))  # noqa: F841 (updates data)
    import pinocchio as pin

    Jmodel = pin.getFrameJacobian(
        r.model, r.data, r.frame("right_tool").index, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    )
    np.testing.assert_allclose(J[:, wheels], Jmodel[:, :nb] @ r.base.matrix, atol=1e-14)


@pytest.mark.parametrize(
    ("pattern", "expected"),
    [
        ([1, 1, 1, 1], (1, 0, 0)),  # forward
        ([-1, 1, 1, -1], (0, 1, 0)),  # lateral, to the left
        ([-1, 1, -1, 1], (0, 0, 1)),  # rotation, counter-clockwise
    ],
)
def test_mecanum_patterns_give_the_expected_base_twist(humanoid, pattern, expected):
    r = humanoid
    radius, lx, ly = 0.08, 0.25, 0.22
    w, dt, yaw = 2.0, 0.1, 0.7
    u = np.zeros(r.nu)
    u[r.group("wheels").indices] = w * np.array(pattern, float)
    twist = r.base.matrix @ u[r.group("wheels").indices]
    scale = np.array([radius * w, radius * w, radius * w / (lx + ly)])
    np.testing.assert_allclose(twist, scale * np.array(expected), atol=1e-14)
    # integrated from a turned base, the motion is along the base's own axes (local twist)
    q = r.configuration(base_pose=(1.0, -2.0, yaw))
    before, after = r.base_pose(q), r.base_pose(r.integrate(q, u, dt))
    vx, vy, wz = twist
    if wz == 0:
        c, s = np.cos(yaw), np.sin(yaw)
        np.testing.assert_allclose(
            after[:2] - before[:2], dt * np.array([c * vx - s * vy, s * vx + c * vy]), atol=1e-12
        )
        assert after[2] == pytest.approx(yaw, abs=1e-12)
    else:
        np.testing.assert_allclose(after[:2], before[:2], atol=1e-12)
        assert after[2] - yaw == pytest.approx(wz * dt, abs=1e-12)


def test_mecanum_internal_mode_moves_nothing(humanoid, rng):
    r = humanoid
    null = r.base.null_space()
    assert null.shape == (4, 1)
    np.testing.assert_allclose(np.abs(null[:, 0]), 0.5, atol=1e-12)
    assert null[0, 0] * null[1, 0] > 0 > null[0, 0] * null[2, 0]  # front pair vs rear pair
    q = r.random_configuration(rng)
    u = np.zeros(r.nu)
    u[r.group("wheels").indices] = 5.0 * null[:, 0]
    q2 = r.integrate(q, u, 0.3)
    np.testing.assert_allclose(r.base_pose(q2), r.base_pose(q), atol=1e-14)
    for f in ("left_tool", "right_tool"):
        np.testing.assert_allclose(r.frame_pose(q2, f), r.frame_pose(q, f), atol=1e-14)
    # ... while the wheels did turn
    wheels = r.group("wheels").indices
    turned = np.angle(np.exp(1j * (r.joint_positions(q2) - r.joint_positions(q))[wheels]))
    np.testing.assert_allclose(np.abs(turned), 5.0 * 0.5 * 0.3, atol=1e-12)


def test_limits_and_groups(humanoid):
    r = humanoid
    assert r.nu == 23
    assert [len(r.group(g)) for g in ("wheels", "waist", "left_arm", "right_arm")] == [4, 3, 8, 8]
    indices = np.concatenate([r.group(g).indices for g in r.groups])
    assert sorted(indices) == list(range(23))
    lower, upper = r.position_limits
    wheels = r.group("wheels").indices
    assert np.all(np.isinf(lower[wheels])) and np.all(np.isinf(upper[wheels]))
    joints = np.setdiff1d(np.arange(23), wheels)
    assert np.all(lower[joints] < 0) and np.all(upper[joints] > 0)  # zero is inside
    assert np.all(np.isfinite(r.velocity_limits)) and np.all(r.velocity_limits > 0)
    # both arms share their limits (the mirror convention)
    left, right = r.group("left_arm").indices, r.group("right_arm").indices
    np.testing.assert_array_equal(lower[right], lower[left])
    np.testing.assert_array_equal(upper[right], upper[left])
    jp = r.joint_positions(r.home())
    assert np.all(jp[joints] >= lower[joints]) and np.all(jp[joints] <= upper[joints])
    assert jp[r.index("left_elbow_flexion")] == pytest.approx(1.2)


def test_arm_bodies_masses_and_centres_of_mass(humanoid, rng):
    r = humanoid
    q = r.random_configuration(rng)
    state = r.update(q)
    for arm in r.arms.values():
        assert arm.upper_arm.mass == pytest.approx(2.0)
        assert arm.forearm.mass == pytest.approx(1.5)
        assert arm.upper_arm_length == pytest.approx(0.2662)
        assert arm.forearm_length == pytest.approx(0.2482)
        S_, E, W = (state.position(f) for f in (arm.shoulder, arm.elbow, arm.wrist))
        # the centres of mass lie on the segments at the documented fractions
        np.testing.assert_allclose(
            state.com_position(arm.upper_arm), S_ + 0.45 * (E - S_), atol=1e-12
        )
        np.testing.assert_allclose(state.com_position(arm.forearm), E + 0.43 * (W - E), atol=1e-12)

    np.testing.assert_allclose(
        r.com_position(q, "left_forearm"), r.update(q).com_position(r.arms["left"].forearm), atol=0
    )


def test_com_jacobian_matches_finite_differences(humanoid, rng):
    r = humanoid
    q = r.random_configuration(rng, margin=0.05)
    for arm in r.arms.values():
        for body in (arm.upper_arm, arm.forearm):
            J = r.update(q).com_jacobian(body)
            Jfd = np.zeros_like(J)
            for k in range(r.nu):
                u = np.zeros(r.nu)
                u[k] = 1e-6
                Jfd[:, k] = (
                    r.com_position(r.integrate(q, u, 1.0), body)
                    - r.com_position(r.integrate(q, u, -1.0), body)
                ) / 2e-6
            np.testing.assert_allclose(J, Jfd, atol=1e-8)


def test_state_views_go_stale(humanoid):
    s1 = humanoid.update(humanoid.neutral())
    humanoid.update(humanoid.home())
    with pytest.raises(WholebodyError, match="stale"):
        s1.pose(humanoid.frame("left_tool"))


def test_bad_arguments_are_reported(humanoid):
    with pytest.raises(DimensionError, match=r"shape \(3,\); expected \(31,\)"):
        humanoid.update(np.zeros(3))
    with pytest.raises(DimensionError, match="not finite"):
        humanoid.update(np.full(31, np.nan))
    with pytest.raises(DimensionError, match=r"expected \(23,\)"):
        humanoid.integrate(humanoid.neutral(), np.zeros(22), 0.01)
    with pytest.raises(WholebodyError, match="did you mean 'left_tool'"):
        humanoid.frame("left_tol")
    with pytest.raises(WholebodyError, match="outside the joint's limits"):
        humanoid.configuration({"left_elbow_flexion": 3.0})


def test_a_copied_robot_reads_its_own_kinematics(humanoid, rng):
    """copy.deepcopy of a Robot (e.g. one per worker) computes poses from its own data."""
    import copy

    other = copy.deepcopy(humanoid)
    q = humanoid.random_configuration(rng)
    state = other.update(q)
    frame = other.frame("right_tool")
    np.testing.assert_allclose(state.position(frame), other.data.oMf[frame.index].translation)
    np.testing.assert_allclose(state.pose(frame), humanoid.frame_pose(q, "right_tool"), atol=1e-12)
