"""Goal-shift DMPs: reproduction, convergence, generalisation, stepping, DMPTrajectory."""

from __future__ import annotations

import numpy as np
import pytest

from wholebody.errors import DimensionError
from wholebody.planning import (
    DMP,
    DMPConfig,
    DMPState,
    DMPTrajectory,
    DynamicPotential,
    cylinder,
    exp_so3,
    log_so3,
    minimum_jerk_scaling,
)

# The paper's right-hand demonstration (Section 5): start and end points, 5 s, with a bend
# so that the forcing term has something to learn.
P0 = np.array([0.095, -0.466, 0.404])
P1 = np.array([1.701, -0.586, 0.761])
T_DEMO = 5.0


def demo(n: int = 160) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, T_DEMO, n)
    s = minimum_jerk_scaling(t / T_DEMO)[0]
    bend = np.sin(np.pi * s)[:, None] * np.array([0.05, -0.15, 0.2])
    wiggle = np.sin(3 * np.pi * s)[:, None] * np.array([0.0, 0.03, -0.02])
    return t, P0 + s[:, None] * (P1 - P0) + bend + wiggle


@pytest.fixture(scope="module")
def dmp() -> DMP:
    t, X = demo()
    return DMP.fit(X, t)


def test_reproduces_the_demonstration_within_a_millimetre(dmp: DMP) -> None:
    t, X = demo()
    r = dmp.rollout(160)
    assert r.positions.shape == (160, 3) and np.allclose(r.times, t)
    err = np.linalg.norm(r.positions - X, axis=1)
    assert err.max() < 1e-3
    assert np.linalg.norm(r.positions[-1] - P1) < 1e-3
    # the model's velocities and accelerations are consistent with its positions
    h = t[1]
    v_fd = (r.positions[2:] - r.positions[:-2]) / (2 * h)
    assert np.max(np.abs(v_fd - r.velocities[1:-1])) < 2e-3
    a_fd = (r.velocities[2:] - r.velocities[:-2]) / (2 * h)
    assert np.max(np.abs(a_fd - r.accelerations[1:-1])) < 2e-2
    assert r.phase[0] == 1.0 and r.phase[-1] == pytest.approx(dmp.config.phase_end)


@pytest.mark.parametrize(
    "shift", [[0.0, 0.2, 0.1], [-0.1, 0.3, -0.2], [0.3, 0.0, 0.0], [0.05, -0.25, 0.15]]
)
def test_moved_goals_are_reached_and_start_without_an_acceleration_jump(
    dmp: DMP, shift: list[float]
) -> None:
    goal = P1 + np.array(shift)
    r = dmp.rollout(160, goal=goal)
    assert np.linalg.norm(r.positions[-1] - goal) < 1e-3
    assert np.linalg.norm(r.velocities[-1]) < 1e-3
    old = dmp.rollout(160)
    # goal-shift form: at t = 0 the goal does not enter the acceleration
    assert np.allclose(r.accelerations[0], old.accelerations[0], atol=1e-12)
    # and continuous from there: a(h) - a(0) shrinks in proportion to h (a jump would not)
    fine = dmp.rollout(1591, goal=goal)
    coarse_step = np.abs(r.accelerations[1] - r.accelerations[0]).max()
    fine_step = np.abs(fine.accelerations[1] - fine.accelerations[0]).max()
    assert 7.0 < coarse_step / fine_step < 13.0
    # starting at rest where the demonstration starts
    assert np.array_equal(r.positions[0], dmp.start) and not np.any(r.velocities[0])


def test_new_start_and_duration(dmp: DMP) -> None:
    start, goal = P0 + np.array([0.05, 0.1, -0.05]), P1 + np.array([-0.1, 0.1, 0.05])
    r = dmp.rollout(300, start=start, goal=goal, duration=3.0)
    assert np.allclose(r.positions[0], start) and r.times[-1] == 3.0
    assert np.linalg.norm(r.positions[-1] - goal) < 1e-3
    # changing the duration only rescales time: same path, velocities scale with 1/T
    a, b = dmp.rollout(160, duration=2.0), dmp.rollout(160, duration=8.0)
    assert np.allclose(a.positions, b.positions, atol=1e-12)
    assert np.allclose(a.velocities, 4.0 * b.velocities, atol=1e-10)
    assert np.allclose(a.accelerations, 16.0 * b.accelerations, atol=1e-8)


def test_phase_end_is_what_makes_moved_goals_converge() -> None:
    """With the phase on tau = T (phase_end = exp(-4)) the goal shift is missed by ~1.8 %."""
    t, X = demo()
    shift = np.array([0.0, 0.2, 0.1])
    paper = DMP.fit(X, t, config=DMPConfig(phase_end=np.exp(-4.0)))
    r = paper.rollout(160, goal=P1 + shift)
    miss = np.linalg.norm(r.positions[-1] - P1 - shift)
    assert 0.01 * np.linalg.norm(shift) < miss < 0.03 * np.linalg.norm(shift)


def test_stepper_agrees_with_rollout_and_updates_in_place(dmp: DMP) -> None:
    goal = P1 + np.array([0.1, 0.1, -0.1])
    r = dmp.rollout(160, goal=goal, duration=4.0)
    stepper = dmp.stepper(goal=goal, duration=4.0)
    state = stepper.initial_state()
    x_ref, v_ref = state.x, state.v
    h = 4.0 / 159
    for k in range(1, 160):
        out = stepper.step(state, h, out=state)
        assert out is state and state.x is x_ref and state.v is v_ref
        assert np.allclose(state.x, r.positions[k], atol=1e-12)
        assert np.allclose(state.v, r.velocities[k], atol=1e-11)
    assert state.t == pytest.approx(4.0) and state.s == pytest.approx(r.phase[-1])
    assert np.allclose(stepper.acceleration(state), r.accelerations[-1], atol=1e-9)
    fresh = stepper.step(stepper.initial_state(), h)  # without out: a new state
    assert isinstance(fresh, DMPState) and np.allclose(fresh.x, r.positions[1], atol=1e-12)


def test_stepper_with_obstacles_agrees_with_rollout() -> None:
    t = np.linspace(0.0, 2.0, 160)
    a, b = np.array([1.73, -0.54, 1.06]), np.array([1.73, -0.3, 1.09])
    d = DMP.fit(a + minimum_jerk_scaling(t / 2.0)[0][:, None] * (b - a), t)
    pots = [DynamicPotential(cylinder([1.725, -0.4, 1.09], 0.04, 0.2, margin=0.02), 10.0, 2, 2)]
    r = d.rollout(160, obstacles=pots)
    stepper = d.stepper(obstacles=pots)
    state = stepper.initial_state()
    for k in range(1, 160):
        stepper.step(state, 2.0 / 159, out=state)
        assert np.allclose(state.x, r.positions[k], atol=1e-9)
    assert np.allclose(stepper.acceleration(state), r.accelerations[-1], atol=1e-6)
    assert np.max(np.abs(r.positions[:, 0] - a[0])) > 0.03  # the obstacle did act


@pytest.mark.parametrize("samples", [2, 5, 11, 20])
def test_coarse_sampling_is_stable_and_accurate(dmp: DMP, samples: int) -> None:
    """Few samples: the linear rollout takes as many RK4 steps per interval as it needs (one
    RK4 step per interval of 0.5 s diverges), and the stepper does the same."""
    dense = dmp.rollout(100 * (samples - 1) + 1)
    r = dmp.rollout(samples)
    np.testing.assert_allclose(r.times, dense.times[::100], atol=1e-12)
    np.testing.assert_allclose(r.positions, dense.positions[::100], atol=1e-3)
    stepper = dmp.stepper()
    state = stepper.initial_state()
    for k in range(1, samples):
        stepper.step(state, dmp.duration / (samples - 1), out=state)
        np.testing.assert_allclose(state.x, r.positions[k], atol=1e-12)


def test_many_basis_functions_stay_finite_after_the_movement() -> None:
    """Past T every Gaussian underflows; the normalised basis must not become 0/0."""
    t, X = demo()
    d = DMP.fit(X, t, config=DMPConfig(n_basis=150))
    stepper = d.stepper(tolerance=1e-3, max_substeps=64)
    state = stepper.initial_state()
    for _ in range(2 * 160):
        stepper.step(state, T_DEMO / 159, out=state)
    np.testing.assert_allclose(state.x, d.goal, atol=1e-6)


def test_linear_rollout_equals_plain_rk4() -> None:
    """The precomputed recurrence is algebraically RK4: compare with a textbook loop (2-D)."""
    rng = np.random.default_rng(5)
    cfg = DMPConfig(n_basis=12, stiffness=300.0)
    d = DMP(rng.normal(size=(12, 2)) * 0.1, [0.0, 0.1], [0.5, -0.2], 1.5, cfg)
    N = 80  # one RK4 step per interval (|lambda| h = 0.22)
    r = d.rollout(N)
    K, D, T = cfg.K, cfg.D, 1.5
    rate = cfg.alpha_s / (cfg.phase_tau_ratio * T)

    centers, widths = cfg.centers(), cfg.widths()

    def F(t: float, z: np.ndarray) -> np.ndarray:
        s = np.exp(-rate * t)
        psi = np.exp(-widths * (s - centers) ** 2)
        f = s * (psi @ d.weights) / psi.sum()  # the forcing term, from its formula
        x, v = z[:2], z[2:]
        dv = K * (d.goal - x) - D * v - K * (d.goal - d.start) * s + K * f
        return np.concatenate([v, dv]) / T

    z, h = np.concatenate([d.start, [0.0, 0.0]]), T / (N - 1)
    for k in range(N - 1):
        tk = k * h
        k1 = F(tk, z)
        k2 = F(tk + h / 2, z + h / 2 * k1)
        k3 = F(tk + h / 2, z + h / 2 * k2)
        k4 = F(tk + h, z + h * k3)
        z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        assert np.allclose(z[:2], r.positions[k + 1], atol=1e-12)
        assert np.allclose(z[2:] / T, r.velocities[k + 1], atol=1e-11)


@pytest.mark.parametrize("d", [1, 2, 6])
def test_any_dimension(d: int) -> None:
    t = np.linspace(0.0, 1.0, 120)
    s = minimum_jerk_scaling(t)[0]
    X = np.outer(s, np.arange(1, d + 1) * 0.1) + 0.02 * np.sin(2 * np.pi * s)[:, None]
    dmp = DMP.fit(X, dt=t[1])
    r = dmp.rollout(120)
    assert r.positions.shape == (120, d)
    assert np.max(np.abs(r.positions - X)) < 1e-3
    assert dmp.stepper().step(dmp.stepper().initial_state(), 0.01).x.shape == (d,)


def test_noisy_demonstration_is_smoothed_not_amplified() -> None:
    t, X = demo()
    clean = DMP.fit(X, t).rollout(160)
    rng = np.random.default_rng(11)
    noisy = DMP.fit(X + rng.normal(scale=5e-4, size=X.shape), t).rollout(160)
    assert np.max(np.linalg.norm(noisy.positions - X, axis=1)) < 1.5e-3
    amax = np.abs(clean.accelerations).max()
    assert np.abs(noisy.accelerations).max() < 1.5 * amax


def test_non_uniform_times_match_uniform() -> None:
    t, X = demo(400)
    rng = np.random.default_rng(2)
    tn = np.sort(np.concatenate([[0.0, T_DEMO], rng.uniform(0, T_DEMO, 398)]))
    s = minimum_jerk_scaling(tn / T_DEMO)[0]
    bend = np.sin(np.pi * s)[:, None] * np.array([0.05, -0.15, 0.2])
    wiggle = np.sin(3 * np.pi * s)[:, None] * np.array([0.0, 0.03, -0.02])
    Xn = P0 + s[:, None] * (P1 - P0) + bend + wiggle
    a = DMP.fit(X, t).rollout(160)
    b = DMP.fit(Xn, tn).rollout(160)
    assert np.max(np.abs(a.positions - b.positions)) < 1e-3


def test_invalid_arguments() -> None:
    t, X = demo()
    with pytest.raises(DimensionError, match="exactly one of times"):
        DMP.fit(X)
    with pytest.raises(DimensionError, match="strictly increasing"):
        DMP.fit(X, t[::-1])
    with pytest.raises(DimensionError, match="NaN"):
        DMP.fit(np.where(X > 1.0, np.nan, X), t)
    with pytest.raises(DimensionError, match="need at least"):
        DMP.fit(X[:4], t[:4])
    with pytest.raises(DimensionError, match="cannot determine 50 basis weights"):
        DMP.fit(X[::4], t[::4])  # 40 samples for 50 weights
    with pytest.raises(DimensionError, match=r"expected shape \(N, M\)"):
        DMP.fit(X[:, 0], t)
    dmp = DMP.fit(X, t)
    with pytest.raises(DimensionError, match="samples"):
        dmp.rollout(1)
    with pytest.raises(DimensionError, match="goal"):
        dmp.rollout(goal=[1.0, 2.0])
    with pytest.raises(DimensionError, match="phase_end"):
        DMPConfig(phase_end=1.5)
    with pytest.raises(DimensionError, match="3-D"):
        DMP.fit(X[:, :2], t).rollout(obstacles=[DynamicPotential(cylinder([0, 0, 0], 1, 1))])
    for ridge in (float("nan"), -1.0, float("inf")):
        with pytest.raises(DimensionError, match="regularization must be a finite number"):
            DMP.fit(X, t, regularization=ridge)
    stepper = dmp.stepper()
    with pytest.raises(DimensionError, match=r"state must hold x and v of shape \(3,\)"):
        stepper.step(DMPState(np.zeros(1), np.zeros(1)), 0.01)
    listed = stepper.step(DMPState([0.1, 0.2, 0.3], [0.0, 0.0, 0.0]), 0.01)  # lists are fine
    np.testing.assert_allclose(
        listed.x, stepper.step(DMPState(np.array([0.1, 0.2, 0.3]), np.zeros(3)), 0.01).x
    )


def test_dmp_trajectory(dmp: DMP) -> None:
    R0 = exp_so3(np.array([0.0, 0.3, 0.1]))
    R1 = exp_so3(np.array([0.4, -0.2, 1.2]))
    T0, T1 = np.eye(4), np.eye(4)
    T0[:3, :3], T0[:3, 3] = R0, P0
    T1[:3, :3], T1[:3, 3] = R1, P1 + np.array([0.0, 0.1, 0.05])
    traj = DMPTrajectory(dmp, T0, T1, 4.0)
    r = traj.rollout
    # exact at the rollout's samples
    got = traj.sample_many(r.times)
    assert np.allclose(got.positions, r.positions, atol=1e-12)
    assert np.allclose(got.linear_velocities, r.velocities, atol=1e-10)
    assert np.allclose(got.linear_accelerations, r.accelerations, atol=1e-8)
    # start and end: exact start pose, goal rotation, goal position within a millimetre, rest
    assert np.allclose(traj.sample(0.0).pose, T0, atol=1e-12)
    end = traj.sample(4.0)
    assert np.allclose(end.rotation, R1, atol=1e-12)
    assert np.linalg.norm(end.position - T1[:3, 3]) < 1e-3
    assert np.allclose(traj.end_pose, end.pose) and np.allclose(end.angular_velocity, 0.0)
    # derivatives between the samples are those of the interpolant
    tt = np.linspace(0.05, 3.95, 77)
    s = traj.sample_many(tt)
    h = 1e-5
    p, m = traj.sample_many(tt + h), traj.sample_many(tt - h)
    assert np.allclose(s.linear_velocities, (p.positions - m.positions) / (2 * h), atol=1e-7)
    assert np.allclose(
        s.linear_accelerations, (p.linear_velocities - m.linear_velocities) / (2 * h), atol=1e-5
    )
    w = np.array([log_so3(a @ b.T) for a, b in zip(p.rotations, m.rotations, strict=True)])
    assert np.allclose(s.angular_velocities, w / (2 * h), atol=1e-8)


@pytest.mark.parametrize(
    ("n", "window", "polyorder"), [(160, 21, 3), (50, 7, 2), (200, 25, 5), (9, 9, 3), (30, 5, 1)]
)
def test_savitzky_golay_equals_scipy(n, window, polyorder):
    """The fit's own Savitzky-Golay derivatives equal scipy's ``mode="interp"`` filter."""
    from scipy.signal import savgol_filter

    from wholebody.planning.dmp import savitzky_golay

    X = np.random.default_rng(n).normal(size=(n, 3)).cumsum(axis=0)
    h = 0.013
    ours = savitzky_golay(X, window, polyorder, h)
    for k, mine in enumerate(ours):
        ref = savgol_filter(X, window, polyorder, deriv=k, delta=h, axis=0, mode="interp")
        np.testing.assert_allclose(mine, ref, rtol=0, atol=1e-10 * max(1.0, np.abs(ref).max()))


@pytest.mark.parametrize("n", [400, 401, 3001])
def test_savitzky_golay_of_long_signals_is_the_local_polynomial(n):
    """Beyond 400 samples the filter is a set of FFT convolutions (memory O(N), not a
    cached dense (3N, N) matrix: 20 000 samples asked for 9 GB); either way each sample is
    the least-squares polynomial of its window, checked against numpy's polyfit in the
    normalised offset (scipy's filter itself loses its interior at windows of ~1000)."""
    import tracemalloc

    from wholebody.planning.dmp import savitzky_golay

    X = np.random.default_rng(n).normal(size=(n, 2)).cumsum(axis=0)
    window, h = (n // 8) * 2 + 1, 0.01
    m = window // 2
    tracemalloc.start()
    ours = savitzky_golay(X, window, 5, h)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 5e6 + 1000 * n  # bytes (a dense operator: 24 n^2, 216 MB at n = 3001)
    for i in (0, m // 2, m, n // 2, n - m - 1, n - 1):
        lo = min(max(i - m, 0), n - window)
        x = (np.arange(lo, lo + window) - i) / m
        c = np.polynomial.polynomial.polyfit(x, X[lo : lo + window], 5)
        for k in range(3):
            ref = c[k] * [1.0, 1.0, 2.0][k] / (m * h) ** k
            np.testing.assert_allclose(ours[k][i], ref, rtol=1e-8, atol=1e-8 * np.abs(ref).max())
