"""Coordinated dual-arm mode: the secondary hand from the primary's trajectory."""

from __future__ import annotations

import numpy as np
import pytest

from wholebody.errors import DimensionError
from wholebody.planning import (
    DMP,
    CoordinatedTrajectory,
    DMPTrajectory,
    HoldTrajectory,
    exp_so3,
    log_so3,
    minimum_jerk_scaling,
    secondary_pose,
)


def pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


@pytest.fixture(scope="module")
def carry() -> tuple[DMPTrajectory, np.ndarray, np.ndarray]:
    """The paper's carry: right hand primary, a DMP position and a 90 degree yaw (slerp);
    panel C 0.3 x 0.1 x 0.02 m held at its two short ends."""
    t = np.linspace(0.0, 4.0, 200)
    s = minimum_jerk_scaling(t / 4.0)[0]
    a, b = np.array([1.5, -0.28, 0.72]), np.array([1.1, -0.6, 0.95])
    path = a + s[:, None] * (b - a) + np.sin(np.pi * s)[:, None] * [0.0, 0.1, 0.08]
    dmp = DMP.fit(path, t)
    R0 = exp_so3(np.array([0.0, np.pi / 2, 0.0]))  # gripper pointing down-forward
    R1 = exp_so3(np.array([0.0, 0.0, -np.pi / 2])) @ R0  # 90 degrees of yaw
    primary = DMPTrajectory(dmp, pose(R0, a), pose(R1, b), 6.0)
    T_PO = pose(exp_so3(np.array([0.1, -0.2, 0.3])), [0.02, 0.15, 0.01])
    T_SO = pose(exp_so3(np.array([-0.2, 0.1, np.pi])), [-0.01, 0.15, 0.0])
    return primary, T_PO, T_SO


def test_secondary_keeps_the_grasp_along_the_carry(carry) -> None:
    primary, T_PO, T_SO = carry
    sec = CoordinatedTrajectory(primary, T_PO, T_SO)
    t = np.linspace(-0.5, primary.duration + 0.5, 401)
    P, S = primary.sample_many(t), sec.sample_many(t)
    obj_from_p = P.poses @ T_PO
    obj_from_s = S.poses @ T_SO
    assert np.max(np.abs(obj_from_p - obj_from_s)) < 1e-9
    # the primary really turns by 90 degrees and the object with it
    turn = log_so3(obj_from_p[-1, :3, :3] @ obj_from_p[0, :3, :3].T)
    assert np.linalg.norm(turn) == pytest.approx(np.pi / 2, abs=1e-9)
    assert np.allclose(sec.start_pose, secondary_pose(primary.start_pose, T_PO, T_SO))
    assert np.allclose(sec.end_pose, S.poses[-1])


def test_secondary_twist_and_acceleration_are_derivatives_of_its_pose(carry) -> None:
    primary, T_PO, T_SO = carry
    sec = CoordinatedTrajectory(primary, T_PO, T_SO)
    t = np.linspace(0.05, primary.duration - 0.05, 97)
    h = 1e-5
    s, p, m = sec.sample_many(t), sec.sample_many(t + h), sec.sample_many(t - h)
    v_fd = (p.positions - m.positions) / (2 * h)
    w_fd = np.array([log_so3(a @ b.T) for a, b in zip(p.rotations, m.rotations, strict=True)])
    w_fd /= 2 * h
    assert np.allclose(s.linear_velocities, v_fd, atol=1e-8)
    assert np.allclose(s.angular_velocities, w_fd, atol=1e-8)
    a_fd = (p.linear_velocities - m.linear_velocities) / (2 * h)
    assert np.allclose(s.linear_accelerations, a_fd, atol=1e-6)
    # the lever arm matters: the secondary's velocity differs from the primary's
    prim = primary.sample_many(t)
    assert np.max(np.linalg.norm(s.linear_velocities - prim.linear_velocities, axis=1)) > 0.05
    assert np.allclose(s.angular_velocities, prim.angular_velocities)


def test_invalid_grasps_are_rejected(carry) -> None:
    primary, T_PO, _ = carry
    with pytest.raises(DimensionError, match="T_secondary_object"):
        CoordinatedTrajectory(primary, T_PO, np.eye(3))
    with pytest.raises(DimensionError, match="primary must be a Trajectory"):
        CoordinatedTrajectory(np.eye(4), T_PO, T_PO)  # type: ignore[arg-type]
    # a hold of the primary gives a resting secondary
    rest = CoordinatedTrajectory(HoldTrajectory(primary.start_pose, 1.0), T_PO, T_PO)
    assert np.allclose(rest.sample(0.5).pose, primary.start_pose)
