"""Reference trajectories: minimum jerk, hold, sequences, the sampling contract, SO(3) maths."""

from __future__ import annotations

import numpy as np
import pytest

from wholebody.errors import DimensionError, WholebodyError
from wholebody.planning import (
    HoldTrajectory,
    MinimumJerkTrajectory,
    TrajectoryError,
    TrajectorySequence,
    exp_so3,
    log_so3,
    slerp,
)


def pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def fd_twist(traj, t: np.ndarray, h: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
    """Central differences of position and of rotation (via log of R+ R-^T)."""
    plus, minus = traj.sample_many(t + h), traj.sample_many(t - h)
    v = (plus.positions - minus.positions) / (2 * h)
    w = np.array([log_so3(a @ b.T) for a, b in zip(plus.rotations, minus.rotations, strict=True)])
    return v, w / (2 * h)


@pytest.fixture
def mj(rng: np.random.Generator) -> MinimumJerkTrajectory:
    R0 = exp_so3(np.array([0.2, -0.4, 0.3]))
    R1 = exp_so3(np.array([-0.5, 0.9, 1.4]))
    return MinimumJerkTrajectory(pose(R0, [0.1, -0.4, 0.8]), pose(R1, [0.6, 0.2, 1.1]), 2.5)


def test_rotations_roundtrip_including_near_pi_and_zero(rng: np.random.Generator) -> None:
    axes = rng.normal(size=(20, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([[1e-9, 1e-6, 1e-3, np.pi - 1e-7, np.pi - 1e-3], rng.uniform(0, 3, 15)])
    for axis, angle in zip(axes, angles, strict=True):
        phi = axis * angle
        R = exp_so3(phi)
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-14)
        assert np.allclose(log_so3(R), phi, atol=1e-9 * max(1.0, 1.0 / (np.pi - angle + 1e-3)))


def test_slerp_is_a_geodesic_with_the_returned_axis() -> None:
    R0, R1 = exp_so3(np.array([0.1, 0.2, 0.3])), exp_so3(np.array([1.0, -0.5, 0.2]))
    sig = np.linspace(0.0, 1.0, 11)
    R, axis = slerp(R0, R1, sig)
    assert np.allclose(R[0], R0, atol=1e-14) and np.allclose(R[-1], R1, atol=1e-12)
    for k in range(10):  # equal steps about the same world axis
        step = log_so3(R[k + 1] @ R[k].T)
        assert np.allclose(step, axis / 10, atol=1e-12)


def test_slerp_equals_the_exponential_form(rng: np.random.Generator) -> None:
    # R0 Exp(sigma Log(R0^T R1)), outside [0, 1] too, for no rotation, tiny ones and near pi
    sig = np.linspace(-0.2, 1.2, 8)
    for angle in (0.0, 1e-9, 1e-4, 0.7, 3.0, np.pi - 1e-6):
        R0 = exp_so3(rng.normal(size=3))
        axis = rng.normal(size=3)
        R1 = R0 @ exp_so3(angle * axis / np.linalg.norm(axis))
        phi = log_so3(R0.T @ R1)
        R, world = slerp(R0, R1, sig)
        expected = np.array([R0 @ exp_so3(s * phi) for s in sig])
        np.testing.assert_allclose(R, expected, atol=1e-14)
        np.testing.assert_allclose(world, R0 @ phi, atol=1e-15)


def test_minimum_jerk_endpoints_and_rest(mj: MinimumJerkTrajectory) -> None:
    a, b = mj.sample(0.0), mj.sample(mj.duration)
    assert np.allclose(a.pose, mj.start_pose, atol=1e-14)
    assert np.allclose(b.pose, mj.end_pose, atol=1e-12)
    for s in (a, b):
        assert np.allclose(s.twist, 0.0, atol=1e-14)
        assert np.allclose(s.linear_acceleration, 0.0, atol=1e-14)
        assert np.allclose(s.angular_acceleration, 0.0, atol=1e-14)


def test_minimum_jerk_derivatives_match_finite_differences(mj: MinimumJerkTrajectory) -> None:
    t = np.linspace(0.01, mj.duration - 0.01, 57)
    s = mj.sample_many(t)
    v, w = fd_twist(mj, t)
    assert np.allclose(s.linear_velocities, v, atol=1e-8)
    assert np.allclose(s.angular_velocities, w, atol=1e-8)
    h = 1e-5
    acc = (mj.sample_many(t + h).linear_velocities - mj.sample_many(t - h).linear_velocities) / (
        2 * h
    )
    alpha = (
        mj.sample_many(t + h).angular_velocities - mj.sample_many(t - h).angular_velocities
    ) / (2 * h)
    assert np.allclose(s.linear_accelerations, acc, atol=1e-7)
    assert np.allclose(s.angular_accelerations, alpha, atol=1e-7)
    # the path is the straight line and the rotations stay orthonormal
    d = mj.end_pose[:3, 3] - mj.start_pose[:3, 3]
    rel = s.positions - mj.start_pose[:3, 3]
    assert np.allclose(np.cross(rel, d), 0.0, atol=1e-14)
    RtR = np.einsum("nji,njk->nik", s.rotations, s.rotations)
    assert np.allclose(RtR, np.eye(3), atol=1e-13)


def test_outside_the_interval_the_end_poses_are_held_at_rest(mj: MinimumJerkTrajectory) -> None:
    arr = mj.sample_many(np.array([-3.0, -1e-9, 0.3, mj.duration + 1e-9, 50.0]))
    assert np.allclose(arr.poses[0], mj.start_pose) and np.allclose(arr.poses[1], mj.start_pose)
    assert np.allclose(arr.poses[3], mj.end_pose) and np.allclose(arr.poses[4], mj.end_pose)
    for k in (0, 1, 3, 4):
        assert not np.any(arr.twists[k])
        assert not np.any(arr.linear_accelerations[k]) and not np.any(arr.angular_accelerations[k])
    assert np.linalg.norm(arr.twists[2]) > 0.01
    one = mj.sample(0.3)  # sample() is the same as one row of sample_many()
    assert np.array_equal(one.pose, arr.poses[2]) and np.array_equal(one.twist, arr.twists[2])


def test_hold_is_constant(rng: np.random.Generator) -> None:
    T = pose(exp_so3(rng.normal(size=3)), rng.normal(size=3))
    hold = HoldTrajectory(T, 1.5)
    arr = hold.sample_many(np.linspace(-1, 3, 9))
    assert np.allclose(arr.poses, T) and not np.any(arr.twists)
    assert hold.duration == 1.5


def test_sequence_concatenates_and_checks_joins(mj: MinimumJerkTrajectory) -> None:
    back = MinimumJerkTrajectory(mj.end_pose, mj.start_pose, 1.0)
    seq = TrajectorySequence([mj, HoldTrajectory(mj.end_pose, 0.5), back])
    assert seq.duration == pytest.approx(mj.duration + 1.5)
    t = np.array([0.7, mj.duration + 0.2, mj.duration + 0.5 + 0.4])
    got = seq.sample_many(t)
    assert np.allclose(got.poses[0], mj.sample(0.7).pose)
    assert np.allclose(got.poses[1], mj.end_pose) and not np.any(got.twists[1])
    assert np.allclose(got.poses[2], back.sample(0.4).pose)
    assert np.allclose(got.twists[2], back.sample(0.4).twist)
    # continuous everywhere (rest-to-rest segments)
    tt = np.linspace(0, seq.duration, 4001)
    dense = seq.sample_many(tt)
    vmax = np.max(np.linalg.norm(dense.linear_velocities, axis=1))
    assert np.max(np.linalg.norm(np.diff(dense.positions, axis=0), axis=1)) <= vmax * tt[1] * 1.001
    assert np.allclose(seq.start_pose, mj.start_pose) and np.allclose(seq.end_pose, mj.start_pose)
    one = seq.sample_many([0.7, 0.9])  # both in the first segment
    assert np.allclose(one.poses, [mj.sample(0.7).pose, mj.sample(0.9).pose])
    assert np.allclose(one.twists, [mj.sample(0.7).twist, mj.sample(0.9).twist])
    nested = TrajectorySequence([seq, HoldTrajectory(seq.end_pose, 1.0)])
    assert np.allclose(nested.sample(0.7).pose, mj.sample(0.7).pose)

    shifted = mj.end_pose.copy()
    shifted[0, 3] += 1e-3
    with pytest.raises(TrajectoryError, match="segment 0 ends at a pose that is not the start"):
        TrajectorySequence([mj, HoldTrajectory(shifted, 1.0)])
    with pytest.raises(TrajectoryError, match="at least one segment"):
        TrajectorySequence([])
    with pytest.raises(TrajectoryError, match="expected a Trajectory"):
        TrajectorySequence([mj, "hold"])  # type: ignore[list-item]


def test_inputs_are_validated() -> None:
    good = np.eye(4)
    bad_rot = np.eye(4)
    bad_rot[:3, :3] = [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]
    reflect = np.diag([1.0, 1.0, -1.0, 1.0])
    nan = np.eye(4)
    nan[0, 3] = np.nan
    cases = [
        (np.eye(3), "4x4 pose, got shape \\(3, 3\\)"),
        (bad_rot, "not a rotation matrix"),
        (reflect, "det < 0"),
        (nan, "NaN"),
    ]
    for T, msg in cases:
        with pytest.raises(DimensionError, match=msg):
            MinimumJerkTrajectory(T, good, 1.0)
    with pytest.raises(DimensionError, match="duration"):
        MinimumJerkTrajectory(good, good, -1.0)
    with pytest.raises(DimensionError, match="duration"):
        HoldTrajectory(good, 0.0)
    with pytest.raises(WholebodyError, match="times"):
        HoldTrajectory(good, 1.0).sample_many(np.array([[0.0, 1.0]]))


def test_the_planner_and_the_tasks_accept_the_same_poses(humanoid) -> None:
    """One pose validator: a last row 1e-8 off or a rotation 1e-5 off orthonormal is refused
    by a trajectory and by a frame task alike; 1e-12 off is accepted by both."""
    from wholebody.tasks import FrameTask

    task = FrameTask(humanoid, "right_tool")
    for delta, ok in ((1e-8, False), (1e-12, True)):
        T = np.eye(4)
        T[3, 0] = delta
        outcomes = []
        for make in (HoldTrajectory, task.set_target):
            try:
                make(T, 1.0) if make is HoldTrajectory else make(T)
                outcomes.append(True)
            except DimensionError:
                outcomes.append(False)
        assert outcomes == [ok, ok], (delta, outcomes)
    T = np.eye(4)
    T[0, 1] = 1e-5
    with pytest.raises(DimensionError, match="not a rotation matrix"):
        HoldTrajectory(T, 1.0)
    with pytest.raises(DimensionError, match="not a rotation matrix"):
        task.set_target(T)
