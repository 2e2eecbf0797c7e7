"""Task rows against finite differences: the exact rate of each task's error.

A task asks for ``A u = v``; with the feedback removed (kp = ki = 0, target twist 0) ``v = 0``
and ``A`` is minus the derivative of the task error along u: ``d e / dt = -A u``. So every
column of A is checked against the central difference of the error through
``Robot.integrate``, at random configurations (base anywhere, waist and both arms moving,
some near their joint limits).
"""

from __future__ import annotations

import numpy as np
import pytest

from wholebody import DimensionError
from wholebody.tasks import FrameTask, PostureTask, RelativeFrameTask, RelativePositionTask
from wholebody.tasks.frame import pose_error


def error_rate_fd(robot, q, task, eps=1e-6):
    cols = []
    for k in range(robot.nu):
        u = np.zeros(robot.nu)
        u[k] = 1.0
        ep = task.error(robot.update(robot.integrate(q, u, eps)))
        em = task.error(robot.update(robot.integrate(q, u, -eps)))
        cols.append((ep - em) / (2 * eps))
    return np.array(cols).T


def configurations(robot, rng, n=4):
    """Random configurations; half of them with joints within 2% of a limit."""
    out = []
    lower, upper = robot.position_limits
    for i in range(n):
        q = robot.random_configuration(rng, margin=0.02, base_range=3.0)
        if i % 2:
            jp = robot.joint_positions(q)
            idx = np.flatnonzero(np.isfinite(lower))
            near = rng.choice(idx, size=6, replace=False)
            side = rng.random(6) < 0.5
            span = upper[near] - lower[near]
            jp[near] = np.where(side, lower[near] + 0.01 * span, upper[near] - 0.01 * span)
            values = {robot.actuated_joints[j]: jp[j] for j in idx}
            q = robot.configuration(values, base_pose=tuple(robot.base_pose(q)))
        out.append(q)
    return out


def random_target(rng):
    T = np.eye(4)
    w = rng.normal(size=3)
    T[:3, :3] = _rot(w / np.linalg.norm(w) * rng.uniform(0.2, 2.5))
    T[:3, 3] = rng.uniform(-1, 1, 3)
    return T


def _rot(w):
    import pinocchio as pin

    return pin.exp3(w)


@pytest.mark.parametrize("frame", ["left_tool", "right_tool", "right_elbow_centre"])
@pytest.mark.parametrize("mask", ["pose", "position", "orientation"])
def test_frame_task_jacobian_is_the_exact_error_rate(humanoid, rng, frame, mask):
    task = FrameTask(
        humanoid, frame, kp=0.0, position=mask != "orientation", orientation=mask != "position"
    )
    assert task.dim == (6 if mask == "pose" else 3)
    for q in configurations(humanoid, rng):
        # orientation errors up to 2.5 rad exercise the full log3 Jacobian
        target = random_target(rng)
        target[:3, 3] += humanoid.frame_pose(q, frame)[:3, 3]
        task.set_target(target)
        rows = task.compute(humanoid.update(q))
        np.testing.assert_allclose(rows.v, 0.0, atol=1e-12)
        np.testing.assert_allclose(-rows.J, error_rate_fd(humanoid, q, task), atol=5e-7)


def test_relative_frame_task_jacobian_is_the_exact_error_rate(humanoid, rng):
    task = RelativeFrameTask(humanoid, "right_tool", "left_tool", kp=0.0)
    for q in configurations(humanoid, rng):
        task.set_target(random_target(rng))
        rows = task.compute(humanoid.update(q))
        np.testing.assert_allclose(-rows.J, error_rate_fd(humanoid, q, task), atol=5e-7)


@pytest.mark.parametrize("axes", [None, "right_elbow_centre"])
def test_relative_position_task_jacobian_is_the_exact_error_rate(humanoid, rng, axes):
    """b relative to a in a third frame's axes (its rotation counts: the [r]x w_c term)."""
    task = RelativePositionTask(
        humanoid, "right_shoulder_centre", "right_wrist_centre", axes=axes, kp=0.0
    )
    assert task.dim == 3
    for q in configurations(humanoid, rng):
        task.set_target(random_target(rng))
        state = humanoid.update(q)
        rows = task.compute(state)
        Rc = state.rotation(task.axes)
        r = state.position(task.frame_b) - state.position(task.frame_a)
        np.testing.assert_allclose(task.relative_position(state), Rc.T @ r, atol=1e-12)
        np.testing.assert_allclose(-rows.J, error_rate_fd(humanoid, q, task), atol=5e-7)


def test_relative_task_ignores_motions_that_keep_the_pair_rigid(humanoid, rng):
    """Moving the whole robot (base, waist) with the arms still leaves b-in-a unchanged."""
    task = RelativeFrameTask(humanoid, "right_tool", "left_tool", kp=0.0)
    q = humanoid.random_configuration(rng, margin=0.1)
    J = task.relative_jacobian(humanoid.update(q))
    rigid = np.concatenate([humanoid.group("wheels").indices, humanoid.group("waist").indices])
    np.testing.assert_allclose(J[:, rigid], 0.0, atol=1e-12)
    assert np.abs(J[:, humanoid.group("left_arm").indices]).max() > 0.1


def test_frame_task_paper_law_and_feedforward(humanoid, rng):
    """At zero orientation error the rows are J u = x'_d + Kp e + Ki I: the paper's law."""
    q = humanoid.random_configuration(rng, margin=0.1)
    state = humanoid.update(q)
    task = FrameTask(humanoid, "right_tool", kp=[1, 2, 3, 4, 5, 6], ki=0.5)
    T = state.pose(task.frame)
    T[:3, 3] += [0.01, -0.02, 0.03]
    twist = rng.normal(size=6)
    task.set_target(T, twist)
    task.integral[:] = [1e-3, 2e-3, 0, 0, 0, -1e-3]
    rows = task.compute(state)
    e = np.array([0.01, -0.02, 0.03, 0, 0, 0])
    np.testing.assert_allclose(rows.J, state.jacobian(task.frame), atol=1e-12)
    np.testing.assert_allclose(
        rows.v, twist + np.arange(1, 7) * e + 0.5 * task.integral, atol=1e-12
    )


def test_integral_anti_windup(humanoid):
    state = humanoid.update(humanoid.neutral())
    task = FrameTask(humanoid, "right_tool", kp=1.0, ki=1.0, integral_limit=0.02)
    T = state.pose(task.frame)
    T[:3, 3] += [0.5, 0, 0]
    task.set_target(T)
    for _ in range(100):
        task.advance(state, 0.01)
    assert task.integral[0] == pytest.approx(0.02)  # clamped
    task.reset()
    task.advance(state, 0.01, saturated=True)
    assert task.integral[0] == 0.0  # no winding up while the solver is saturated
    task.integral[0] = -0.01
    task.advance(state, 0.01, saturated=True)
    assert task.integral[0] == pytest.approx(-0.01 + 0.5 * 0.01)  # but it may unwind
    task.integral[0] = -0.001
    task.advance(state, 0.02, saturated=True)
    assert task.integral[0] == 0.0  # down to 0, not past it (its size would grow)


@pytest.mark.parametrize("kind", ["frame", "relative"])
def test_the_integral_advances_with_the_error_at_that_state_and_target(humanoid, rng, kind):
    # advance() reuses the error the rows were written with when the state and the target
    # are those of the rows; a target set in between, or another state, is used as given
    def task_and_error():
        if kind == "frame":
            task = FrameTask(humanoid, "right_tool", kp=10.0, ki=5.0)

            def error(state, T):
                return pose_error(state.position(task.frame), state.rotation(task.frame), T)[0]

            def pose(state):
                return state.pose(task.frame)
        else:
            task = RelativeFrameTask(humanoid, "left_tool", "right_tool", kp=10.0, ki=5.0)

            def error(state, T):
                rel = task.relative_pose(state)
                return pose_error(rel[:3, 3], rel[:3, :3], T)[0]

            def pose(state):
                return task.relative_pose(state)

        return task, error, pose

    task, error, pose = task_and_error()
    states = [humanoid.update(humanoid.random_configuration(rng, margin=0.1))]
    T = pose(states[0]).copy()
    T[:3, 3] += [0.01, -0.02, 0.005]
    task.set_target(T)
    task.write_rows(states[0], np.empty((6, humanoid.nu)), np.empty(6))
    task.advance(states[0], 0.01)
    np.testing.assert_allclose(task.integral, 0.01 * error(states[0], T), atol=1e-15)
    T2 = T.copy()
    T2[:3, 3] += 0.01
    task.set_target(T2)
    before = task.integral.copy()
    task.advance(states[0], 0.01)
    np.testing.assert_allclose(task.integral - before, 0.01 * error(states[0], T2), atol=1e-15)
    state = humanoid.update(humanoid.random_configuration(rng, margin=0.1))
    before = task.integral.copy()
    task.advance(state, 0.01)
    expected = np.clip(before + 0.01 * error(state, T2), -0.05, 0.05)
    np.testing.assert_allclose(task.integral, expected, atol=1e-15)


@pytest.mark.parametrize("kind", ["frame", "relative"])
def test_reset_forgets_a_captured_target_and_keeps_a_set_one(humanoid, kind):
    """Without a target a pose task holds the pose it first sees; reset() (a new run) must
    capture it anew, not drag the frame back to the first run's pose."""
    if kind == "frame":
        task = FrameTask(humanoid, "left_tool")
    else:
        task = RelativeFrameTask(humanoid, "right_tool", "left_tool")
    moved = humanoid.configuration({"left_elbow_flexion": 0.3}, base_pose=(0.5, 0.0, 0.0))
    task.compute(humanoid.update(humanoid.home()))
    second = humanoid.update(moved)
    assert np.abs(task.error(second)).max() > 1e-3  # still holds the first pose
    task.reset()
    np.testing.assert_allclose(task.error(second), 0.0, atol=1e-12)  # captured anew
    if kind == "frame":
        task.set_target(humanoid.frame_pose(humanoid.home(), "left_tool"))
        task.reset()
        assert task.target is not None  # a target set by the user is kept


def test_posture_task(humanoid, rng):
    q = humanoid.random_configuration(rng, margin=0.1)
    state = humanoid.update(q)
    task = PostureTask(humanoid, "waist", kp=2.0, target=[0.1, -0.2, 0.0])
    rows = task.compute(state)
    jp = state.joint_positions()[humanoid.group("waist").indices]
    np.testing.assert_allclose(rows.v, 2.0 * (np.array([0.1, -0.2, 0.0]) - jp))
    np.testing.assert_allclose(-rows.J, error_rate_fd(humanoid, q, task), atol=1e-8)
    wheels = PostureTask(humanoid, "wheels", kp=5.0)
    np.testing.assert_array_equal(wheels.compute(state).v, 0.0)  # damping rows for wheels
    with pytest.raises(DimensionError, match="target must be 3"):
        task.set_target([0.0, 0.0])


def test_bad_targets_are_rejected(humanoid):
    task = FrameTask(humanoid, "left_tool")
    with pytest.raises(DimensionError, match="4x4"):
        task.set_target(np.eye(3))
    bad = np.eye(4)
    bad[:3, :3] *= 2
    with pytest.raises(DimensionError, match="not a rotation"):
        task.set_target(bad)
    with pytest.raises(DimensionError, match="twist"):
        task.set_target(np.eye(4), np.zeros(5))
    pose = humanoid.frame_pose(humanoid.home(), "left_tool")
    with pytest.raises(DimensionError, match="last row"):
        task.set_target(pose.T)  # a transposed transform
    with pytest.raises(DimensionError, match="kp"):
        FrameTask(humanoid, "left_tool", kp=-1.0)
