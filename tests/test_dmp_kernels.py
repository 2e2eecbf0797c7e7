"""The DMP kernels (wholebody.kernels.dmp, wholebody.kernels.potentials) against independent
oracles: rollouts against scipy's solve_ivp of the ODE written here from the equations in
wholebody.planning.dmp's docstring, the fit against a least-squares solution computed here,
the stepper against the rollout and the ODE, the basis against its formula; errors, refused
potentials and argument types. The forces against finite differences of the potentials:
tests/test_obstacles.py.

Under ``NUMBA_DISABLE_JIT=1`` the kernels run as plain Python, the same code: every test
holds there too, and with ``NUMBA_BOUNDSCHECK=1``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter

from wholebody.errors import DimensionError, IntegrationError
from wholebody.kernels import DISABLED
from wholebody.kernels import dmp as kernels
from wholebody.kernels import potentials as force_kernels
from wholebody.planning import (
    DMP,
    DMPConfig,
    DMPState,
    DynamicPotential,
    StaticPotential,
    Superquadric,
    box,
    cylinder,
    exp_so3,
    minimum_jerk_scaling,
    sphere,
    total_force,
)
from wholebody.planning.dmp import integrator, savitzky_golay
from wholebody.planning.obstacles import potential_rows

START = np.array([1.73, -0.54, 1.06])
GOAL = np.array([1.73, -0.30, 1.09])
CENTERS = ([1.725, -0.4, 1.09], [1.725, -0.2, 1.09])


def _first_fast(names: object) -> list:
    """The cases as parameters, all but the first marked slow (``-m "not slow"`` keeps one)."""
    return [
        pytest.param(n, id=n, marks=() if k == 0 else pytest.mark.slow)
        for k, n in enumerate(names)  # type: ignore[call-overload]
    ]


def reach(start: np.ndarray, goal: np.ndarray, n: int = 160, T: float = 2.0) -> DMP:
    """A DMP of a minimum-jerk straight reach in ``T`` s."""
    t = np.linspace(0.0, T, n)
    return DMP.fit(start + minimum_jerk_scaling(t / T)[0][:, None] * (goal - start), t)


@pytest.fixture(scope="module")
def scene() -> DMP:
    return reach(START, GOAL)


def paper_potentials(beta: float = 2.0) -> list[DynamicPotential]:
    return [DynamicPotential(cylinder(c, 0.04, 0.2, margin=0.02), 10.0, beta, 2.0) for c in CENTERS]


# ------------------------------------------------------------------------------------------
# The oracle: the DMP's equations (wholebody.planning.dmp, .config, .model), written here


def basis_formula(cfg: DMPConfig, s: np.ndarray) -> np.ndarray:
    """``s psi_i(s) / sum_j psi_j(s)``, ``psi_i = exp(-h_i (s - c_i)^2)``, ``c_i =
    phase_end^(i / (n - 1))``, ``h_i = 4 ln(1 / overlap) / (c_i - c_{i+1})^2`` (the last
    gap repeated), at the phases ``s`` (J,)."""
    n = cfg.n_basis
    c = cfg.phase_end ** (np.arange(n) / (n - 1))
    gap = np.abs(np.diff(c))
    h = 4.0 * np.log(1.0 / cfg.overlap) / np.append(gap, gap[-1]) ** 2
    psi = np.exp(-h * (np.asarray(s, dtype=float)[:, None] - c) ** 2)
    return s[:, None] * psi / psi.sum(axis=1, keepdims=True)


def ode_solution(
    dmp: DMP,
    x0,
    g,
    T: float,
    times: np.ndarray,
    potentials=(),
    rtol=1e-12,
    atol=1e-13,
    state=None,
    t0: float = 0.0,
):
    """``x``, ``x'``, ``x''`` (J, d) and the phase (J,) at ``times`` by DOP853 of::

        tau v' = K (g - x) - D v - K (g - x0) s + K f(s) + phi(x, v),   tau x' = v
        tau_s s' = -alpha_s s,    tau = T,   tau_s = alpha_s T / ln(1 / phase_end)

    from rest at ``x0`` (or from ``state`` = (x, x', s) at ``t0``), ``phi`` the sum of the
    potentials' own ``force()``."""
    cfg = dmp.config
    K = cfg.stiffness
    D = 2.0 * math.sqrt(K) if cfg.damping is None else cfg.damping
    tau, tau_s = T, cfg.alpha_s * T / math.log(1.0 / cfg.phase_end)
    x0, g = np.asarray(x0, dtype=float), np.asarray(g, dtype=float)
    d = x0.size

    def rhs(t: float, z: np.ndarray) -> np.ndarray:
        x, v, s = z[:d], z[d : 2 * d], z[2 * d]
        f = basis_formula(cfg, np.array([s]))[0] @ dmp.weights
        dv = K * (g - x) - D * v - K * (g - x0) * s + K * f
        for pot in potentials:
            dv = dv + pot.force(x, v)
        return np.concatenate([v / tau, dv / tau, [-cfg.alpha_s * s / tau_s]])

    if state is None:
        z0 = np.concatenate([x0, np.zeros(d), [1.0]])
    else:
        z0 = np.concatenate([state[0], tau * np.asarray(state[1]), [state[2]]])
    sol = solve_ivp(rhs, (t0, times[-1]), z0, method="DOP853", t_eval=times, rtol=rtol, atol=atol)
    assert sol.success, sol.message
    Z = sol.y.T
    acc = np.array([rhs(t, z)[d : 2 * d] for t, z in zip(times, Z, strict=True)]) / tau
    return Z[:, :d], Z[:, d : 2 * d] / tau, acc, Z[:, 2 * d]


def gap(a: np.ndarray, b: np.ndarray) -> float:
    """The largest distance between two paths (N, d), m."""
    return float(np.max(np.linalg.norm(a - b, axis=1)))


# ------------------------------------------------------------------------------------------
# Rollouts


def demonstrations() -> dict[str, tuple[np.ndarray, np.ndarray, DMPConfig]]:
    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 5.0, 160)
    s = minimum_jerk_scaling(t / 5.0)[0]
    bend = np.outer(np.sin(np.pi * s), [0.05, -0.15, 0.2])
    bend += np.outer(np.sin(3 * np.pi * s), [0.0, 0.03, -0.02])
    X3 = np.array([0.095, -0.466, 0.404]) + np.outer(s, [1.606, -0.12, 0.357]) + bend
    tn = np.sort(np.concatenate([[0.0, 5.0], rng.uniform(0.0, 5.0, 298)]))
    sn = minimum_jerk_scaling(tn / 5.0)[0]
    long = np.linspace(0.0, 4.0, 401)
    sl = minimum_jerk_scaling(long / 4.0)[0]
    return {
        "3-D bend": (t, X3, DMPConfig()),
        "noisy": (t, X3 + rng.normal(scale=5e-4, size=X3.shape), DMPConfig()),
        "non-uniform times": (tn, np.stack([sn, np.sin(2 * sn), sn**3], 1), DMPConfig()),
        "401 samples (FFT filter)": (long, np.stack([sl, 0.3 * sl**2], 1), DMPConfig()),
        "1-D, 12 narrow basis functions": (
            t,
            0.4 * s[:, None] ** 2,
            DMPConfig(n_basis=12, overlap=0.5, alpha_s=3),
        ),
        "6-D stiff": (
            t,
            np.outer(s, np.arange(1, 7) * 0.1) + 0.02 * np.sin(6 * s)[:, None],
            DMPConfig(stiffness=400.0, damping=30.0, phase_end=1e-3),
        ),
    }


@pytest.mark.parametrize("name", _first_fast(demonstrations()))
def test_rollout_solves_the_dmp_ode_to_fourth_order(name: str) -> None:
    """Without obstacles the rollout is RK4 of the DMP's equations: against DOP853 at 1e-12
    its error falls 16-fold when the step halves, and is below 2e-5 of the reach at 160
    samples (|lambda| h = 0.2; 9e-6 with 12 narrow basis functions, 1e-6 with 50). Moved
    start and goal, another duration, and a sampling so coarse that each interval takes
    several substeps (5 samples) alike."""
    t, X, cfg = demonstrations()[name]
    dmp = DMP.fit(X, t, config=cfg)
    reach_ = float(np.ptp(X, axis=0).max())
    for kw in ({}, {"duration": 1.3, "goal": dmp.goal + 0.1, "start": dmp.start - 0.05}):
        T = kw.get("duration", dmp.duration)
        x0, g = kw.get("start", dmp.start), kw.get("goal", dmp.goal)
        errors = []
        for N in (160, 319):
            r = dmp.rollout(N, **kw)
            x, v, a, s = ode_solution(dmp, x0, g, T, r.times)
            np.testing.assert_array_equal(r.times, np.linspace(0.0, T, N))
            np.testing.assert_allclose(r.phase, s, rtol=1e-10, atol=0)
            assert np.array_equal(r.positions[0], x0) and not np.any(r.velocities[0])
            errors.append(gap(r.positions, x))
            scale = np.abs(a).max()
            assert gap(r.velocities, v) < 1e-3 * reach_ / T
            assert np.abs(r.accelerations - a).max() < 2e-4 * scale
        assert errors[0] < 2e-5 * reach_
        assert 10.0 < errors[0] / errors[1] < 24.0, errors  # fourth order: 16
    coarse = dmp.rollout(5)  # 0.5 s+ intervals: several substeps each, stable
    x, *_ = ode_solution(dmp, dmp.start, dmp.goal, dmp.duration, coarse.times)
    assert gap(coarse.positions, x) < 2e-5 * reach_


R1 = exp_so3(np.array([0.3, -0.5, 0.9]))
R2 = exp_so3(np.array([-1.2, 0.4, 0.2]))
SCENES = {
    "paper's two cylinders": paper_potentials(),
    "sphere": [DynamicPotential(sphere([1.72, -0.42, 1.08], 0.03, margin=0.01))],
    "rotated box, beta 1.5": [
        DynamicPotential(
            box([1.735, -0.42, 1.075], [0.05, 0.03, 0.08], rotation=R1, margin=0.01),
            gain=5.0,
            beta=1.5,
            eta=1.0,
        )
    ],
    "tilted cylinder": [
        DynamicPotential(cylinder([1.74, -0.4, 1.07], 0.03, 0.1, axis=[1, 1, 0.2], margin=0.01))
    ],
    "static box and sphere": [
        StaticPotential(box([1.74, -0.40, 1.08], [0.04, 0.04, 0.04], rotation=R2), 1e-3, 2.0),
        StaticPotential(sphere([1.72, -0.36, 1.08], 0.02), 1e-3, 1.0),
    ],
    "three mixed": [
        DynamicPotential(Superquadric([1.73, -0.44, 1.07], R2, [0.03, 0.02, 0.04], 2.0, 3.0)),
        StaticPotential(sphere([1.70, -0.35, 1.1], 0.02), 1e-3, 1.0),
        DynamicPotential(box([1.75, -0.36, 1.06], [0.02, 0.02, 0.02], exponent=8), 2.0),
    ],
}


@pytest.mark.parametrize("name", _first_fast(SCENES))
def test_obstacle_rollout_solves_the_ode_with_the_forces(scene: DMP, name: str) -> None:
    """With obstacles, at a tolerance of 1e-7 m, the rollout is the solution of the DMP's
    equations with the potentials' forces (DOP853 at 1e-10: the path within 5 um, where the
    obstacles move it by centimetres; 1.3 um where a beta = 1.5 force switches on with a
    kink, 1e-9 m elsewhere)."""
    pots = SCENES[name]
    r, counts, evaluations = integrator.rollout(
        scene, 160, START, GOAL, 2.0, potential_rows(pots), 1e-7, 4096
    )
    x, v, a, _ = ode_solution(scene, START, GOAL, 2.0, r.times, pots, rtol=1e-10, atol=1e-12)
    assert gap(x, scene.rollout(160).positions) > 0.03  # the obstacles act
    assert gap(r.positions, x) < 5e-6
    assert gap(r.velocities, v) < 5e-5
    assert np.abs(r.accelerations - a).max() < 5e-3 * max(1.0, np.abs(a).max())
    assert counts.shape == (159,) and counts.min() >= 1 and evaluations > 4 * counts.sum()
    # the public rollout is this one
    public = scene.rollout(
        160, start=START, goal=GOAL, obstacles=pots, tolerance=1e-7, max_substeps=4096
    )
    np.testing.assert_array_equal(public.positions, r.positions)


@pytest.mark.slow
def test_default_tolerance_in_the_papers_scene(scene: DMP) -> None:
    """At the default tolerance (1e-3 m on the local estimate) the paper's scene is within
    1e-5 m of the ODE's solution; the steps shrink near the cylinders only, where one RK4
    step per interval would miss the path by centimetres."""
    pots = paper_potentials()
    r, counts, evaluations = integrator.rollout(
        scene, 160, START, GOAL, 2.0, potential_rows(pots), 1e-3, 256
    )
    x, *_ = ode_solution(scene, START, GOAL, 2.0, r.times, pots, rtol=1e-10, atol=1e-12)
    assert gap(r.positions, x) < 1e-5
    assert counts.max() > 4 and np.mean(counts == 1) > 0.5
    assert 4 * 159 < evaluations < 2000
    fixed = scene.rollout(160, obstacles=pots, tolerance=math.inf, max_substeps=1)
    assert gap(fixed.positions, x) > 0.01


@pytest.mark.slow
def test_an_infinite_tolerance_is_fixed_step_rk4(scene: DMP) -> None:
    """``tolerance=inf``: every interval ``max_substeps`` RK4 substeps, none redone; the
    error against the ODE falls with the substep: one per interval misses the paper's path
    by 10 cm (why the substeps adapt), 16 resolve it."""
    pots = paper_potentials()
    errors = []
    for substeps in (1, 3, 16):
        r, counts, evaluations = integrator.rollout(
            scene, 160, START, GOAL, 2.0, potential_rows(pots), math.inf, substeps
        )
        assert np.all(counts == substeps) and evaluations == 4 * 159 * substeps + 1
        x, *_ = ode_solution(scene, START, GOAL, 2.0, r.times, pots, rtol=1e-10, atol=1e-12)
        errors.append(gap(r.positions, x))
    assert errors[0] > 0.05 and errors[0] > errors[1] > errors[2] and errors[2] < 1e-6


# ------------------------------------------------------------------------------------------
# Fit


@pytest.mark.parametrize("name", _first_fast(demonstrations()))
def test_fit_is_the_ridge_least_squares_solution(name: str) -> None:
    """The weights solve ``min |Phi W - F|^2 + r |W|^2`` (``r = ridge tr(Phi^T Phi) / nb``)
    for the forcing targets ``F = (tau^2 x'' + D tau x') / K - (g - x) + (g - x0) s`` of the
    Savitzky-Golay-filtered demonstration (scipy's filter), here by an orthogonal
    least-squares solve of the stacked system: the fitted forcing term agrees to 1e-8 of its
    size; with a larger ridge (well conditioned) the weights themselves."""
    t, X, cfg = demonstrations()[name]
    N = len(t)
    T = t[-1] - t[0]
    h = T / (N - 1)
    uniform = np.linspace(0.0, T, N)
    Xu = X if np.allclose(np.diff(t), h) else CubicSpline(t - t[0], X, axis=0)(uniform)
    window = max(7, round(N / 8)) | 1
    xs, xd, xdd = (
        savgol_filter(Xu, window, 5, deriv=k, delta=h, axis=0, mode="interp") for k in range(3)
    )
    K = cfg.stiffness
    D = 2.0 * math.sqrt(K) if cfg.damping is None else cfg.damping
    s = np.exp(-cfg.alpha_s * uniform / (cfg.alpha_s * T / math.log(1.0 / cfg.phase_end)))
    F = (T * T * xdd + D * T * xd) / K - (xs[-1] - xs) + np.outer(s, xs[-1] - xs[0])
    Phi = basis_formula(cfg, s)
    for ridge in (1e-10, 1e-3):
        r = ridge * np.trace(Phi.T @ Phi) / cfg.n_basis
        stacked = np.vstack([Phi, math.sqrt(r) * np.eye(cfg.n_basis)])
        rhs = np.vstack([F, np.zeros((cfg.n_basis, F.shape[1]))])
        W = np.linalg.lstsq(stacked, rhs, rcond=None)[0]
        dmp = DMP.fit(X, t, config=cfg, regularization=ridge)
        np.testing.assert_allclose(dmp.start, xs[0], rtol=0, atol=1e-10)
        np.testing.assert_allclose(dmp.goal, xs[-1], rtol=0, atol=1e-10)
        assert dmp.duration == T
        scale = np.abs(Phi @ W).max()
        np.testing.assert_allclose(Phi @ dmp.weights, Phi @ W, rtol=0, atol=1e-8 * scale)
        if ridge == 1e-3:
            np.testing.assert_allclose(dmp.weights, W, rtol=0, atol=1e-8 * np.abs(W).max())
        else:  # and the demonstration is reproduced (the fit is a fit)
            r = dmp.rollout(len(t))
            demo = np.stack([np.interp(r.times, t - t[0], x) for x in X.T], axis=1)
            assert np.max(np.abs(r.positions - demo)) < 2e-2


def test_basis_is_the_formula() -> None:
    """``DMP.basis`` (the kernels' basis) against the formula, also far past the movement's
    end where every Gaussian underflows (normalised by the largest: no 0/0)."""
    for cfg in (DMPConfig(), DMPConfig(n_basis=7, overlap=0.3, phase_end=1e-2)):
        dmp = DMP(np.zeros((cfg.n_basis, 2)), [0.0, 0.0], [1.0, 1.0], 1.0, cfg)
        s = np.concatenate([np.linspace(1.0, 1e-4, 97), [1e-3, 2.5e-5]])
        np.testing.assert_allclose(dmp.basis(s), basis_formula(cfg, s), rtol=1e-12, atol=1e-15)
        late = dmp.basis(np.array([1e-30, 0.0]))
        assert np.all(np.isfinite(late)) and np.all(late[1] == 0.0)


def test_singular_normal_equations_fall_back_to_a_general_solve(monkeypatch) -> None:
    """Without the ridge and with nearly coincident basis functions the Cholesky factorisation
    fails; the normal equations are then solved by LU (np.linalg.solve)."""
    solves = []
    solve = np.linalg.solve
    monkeypatch.setattr(np.linalg, "solve", lambda A, b: solves.append(A.shape) or solve(A, b))
    t = np.linspace(0.0, 1.0, 60)
    X = np.stack([minimum_jerk_scaling(t)[0], np.sin(3 * t), t**2], 1)
    dmp = DMP.fit(X, t, config=DMPConfig(n_basis=50, overlap=0.999), regularization=0.0)
    assert solves == [(50, 50)]
    assert np.all(np.isfinite(dmp.weights))


# ------------------------------------------------------------------------------------------
# Stepper


@pytest.mark.parametrize("dt", [2.0 / 159, 0.5])  # 0.5 s: several RK4 substeps per call
def test_stepper_reproduces_the_rollout(scene: DMP, dt: float) -> None:
    """Stepping with the rollout's sampling gives its samples (the same integrator), with
    and without obstacles (whose 0.5 s intervals no substep count resolves), in place."""
    N = round(2.0 / dt) + 1
    for pots in ([], paper_potentials()) if N > 5 else ([],):
        r = scene.rollout(N, obstacles=pots)
        stepper = scene.stepper(obstacles=pots)
        state = stepper.initial_state()
        x, v = state.x, state.v
        for k in range(1, N):
            assert stepper.step(state, dt, out=state) is state
            np.testing.assert_allclose(state.x, r.positions[k], rtol=0, atol=1e-12)
            np.testing.assert_allclose(state.v, r.velocities[k], rtol=0, atol=1e-10)
            assert state.s == pytest.approx(r.phase[k], rel=1e-13)
        assert state.x is x and state.v is v and state.t == pytest.approx(2.0, rel=1e-14)
        np.testing.assert_allclose(stepper.acceleration(state), r.accelerations[-1], atol=1e-8)


@pytest.mark.slow
def test_stepper_follows_a_moved_goal_as_the_ode_does(scene: DMP) -> None:
    """A goal moved mid-way and a sampling the rollout does not use: the stepper's states
    against DOP853 of the equations, restarted at the move with the new goal."""
    goal = GOAL + np.array([0.0, 0.03, 0.01])
    for pots, tol in (([], 2e-6), (paper_potentials(), 4e-6)):
        stepper = scene.stepper(obstacles=pots)
        state = stepper.initial_state()
        path = [state.copy()]
        for k in range(1, 150):
            if k == 80:
                stepper.set_goal(goal)
            path.append(stepper.step(path[-1], 0.0137))
        times = np.array([p.t for p in path])
        first = ode_solution(scene, START, GOAL, 2.0, times[:80], pots, rtol=1e-11, atol=1e-13)
        at = path[79]
        np.testing.assert_allclose(at.x, first[0][-1], rtol=0, atol=tol)
        start = (first[0][-1], first[1][-1], first[3][-1])
        second = ode_solution(
            scene,
            START,
            goal,
            2.0,
            times[79:],
            pots,
            rtol=1e-11,
            atol=1e-13,
            state=start,
            t0=times[79],
        )
        x = np.array([p.x for p in path[79:]])
        assert gap(x, second[0]) < tol
        assert abs(path[-1].s - second[3][-1]) < 1e-12


def test_stepper_states_of_other_types(scene: DMP) -> None:
    """float32 states are read as float64 and written back rounded; lists as float64."""
    state = scene.stepper().step(scene.stepper().initial_state(), 0.6)

    def step(st: DMPState, out: DMPState | None = None) -> DMPState:
        stepper = scene.stepper(obstacles=paper_potentials())  # the same step control
        return stepper.step(st, 2.0 / 159, out=out)

    single = DMPState(state.x.astype(np.float32), state.v.astype(np.float32), state.s, state.t)
    wide = step(DMPState(single.x.astype(float), single.v.astype(float), state.s, state.t))
    assert step(single, out=single) is single
    assert single.x.dtype == np.float32 and single.v.dtype == np.float32
    np.testing.assert_array_equal(single.x, wide.x.astype(np.float32))
    np.testing.assert_array_equal(single.v, wide.v.astype(np.float32))
    listed = step(DMPState(state.x.tolist(), state.v.tolist(), state.s, state.t))
    np.testing.assert_array_equal(listed.x, step(state).x)


# ------------------------------------------------------------------------------------------
# Errors and refusals


def raised(fn) -> str:
    """The message of the IntegrationError ``fn()`` raises."""
    with pytest.raises(IntegrationError) as info:
        fn()
    return str(info.value)


def test_unresolved_intervals_raise(scene: DMP) -> None:
    assert "with 1 substeps" in raised(
        lambda: scene.rollout(160, obstacles=paper_potentials(), max_substeps=1)
    )
    # a steep box 1 cm off a straight reach: the estimate stays above 10 x the tolerance
    steep = reach(np.array([0.0, 0.01, 0.0]), np.array([0.8, 0.01, 0.0]), n=200, T=1.0)
    pot = [DynamicPotential(box([0.5, 0.0, 0.0], [0.04, 0.04, 0.04], exponent=12))]
    message = raised(lambda: steep.rollout(160, obstacles=pot))
    assert "above 10 x the tolerance 0.001 m" in message and "interval from t = 0.5" in message

    def stepped() -> None:
        stepper = steep.stepper(obstacles=pot, max_substeps=8)
        state = stepper.initial_state()
        for _ in range(159):
            stepper.step(state, 1.0 / 159, out=state)

    assert "DMPStepper.step" in raised(stepped) and "with 8 substeps" in raised(stepped)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy's overflow: the oracle's too
def test_non_finite_and_overflowing_forces_raise(scene: DMP) -> None:
    """A force that overflows where it acts gives a non-finite state, which no substep count
    resolves: an IntegrationError, never a path of NaN; where it does not act (moving away)
    an overflowing power does no harm."""
    huge = [DynamicPotential(cylinder(CENTERS[0], 0.04, 0.2, margin=0.02), gain=1e305)]
    assert "non-finite state" in raised(lambda: scene.rollout(160, obstacles=huge))
    # a 10 um box with exponent 32: |u|^64 overflows beyond about 0.5 m. The static force
    # acts everywhere outside: from 0.3 s on, where the path is that far, it is NaN
    far = [StaticPotential(box(START - [0.0, 0.3, 0.0], [1e-5, 1e-5, 1e-5], exponent=32), 1e-3)]
    message = raised(lambda: scene.rollout(160, obstacles=far, max_substeps=16))
    assert "non-finite state with 16 substeps in the interval from t = 0.3019 s" in message
    stepper = scene.stepper(obstacles=far, max_substeps=16)
    state = stepper.initial_state()
    steps = []
    with pytest.raises(IntegrationError, match="non-finite state with 16 substeps"):
        for k in range(159):
            steps.append(k)
            stepper.step(state, 2.0 / 159, out=state)
    assert steps[-1] == 24  # the same interval, t = 24 x 2/159 s
    # a 10 um thin cylinder along x: q^32 overflows beyond r = 0.66 m, where the path runs,
    # moving away from it: no force, the free path
    thin = [
        DynamicPotential(cylinder(START - [0.0, 0.5, 0.0], 1e-5, 1.0, axis=[1, 0, 0], exponent=32))
    ]
    assert np.isinf(thin[0].shape.isopotential(scene.rollout(160).positions)).any()
    np.testing.assert_allclose(
        scene.rollout(160, obstacles=thin).positions,
        scene.rollout(160).positions,
        rtol=0,
        atol=1e-12,
    )


class Scaled(DynamicPotential):
    """A user's potential: twice the force of its base class, by its own force()."""

    def force(self, x, v):
        return 2.0 * super().force(x, v)


class Named(DynamicPotential):
    """A subclass that adds nothing to the force: the kernels compute it."""

    name = "cup"


class Sheet:
    """A user-written potential (the Potential protocol before the kernels): refused."""

    def potential(self, x, v):
        return np.zeros(len(x))

    def force(self, x, v):
        return np.zeros_like(x)


def test_potentials_the_kernels_do_not_compute_are_refused(scene: DMP) -> None:
    shape = cylinder(CENTERS[0], 0.04, 0.2, margin=0.02)
    for pots in ([Scaled(shape)], [DynamicPotential(shape), Sheet()]):
        kind = type(pots[-1]).__name__
        with pytest.raises(DimensionError, match=f"DynamicPotential or StaticPotential.*{kind}"):
            scene.rollout(160, obstacles=pots)
        with pytest.raises(DimensionError, match="may not override force"):
            scene.stepper(obstacles=pots)
        with pytest.raises(DimensionError, match="sphere, cylinder, box"):
            total_force(pots, START, np.ones(3))
    with pytest.raises(DimensionError, match="wrap each"):
        scene.rollout(160, obstacles=[shape])
    named = scene.rollout(160, obstacles=[Named(shape)]).positions
    np.testing.assert_array_equal(
        named, scene.rollout(160, obstacles=[DynamicPotential(shape)]).positions
    )


def test_obstacles_need_three_dimensions() -> None:
    t = np.linspace(0.0, 1.0, 60)
    flat = DMP.fit(np.stack([t, t**2], 1), t)
    with pytest.raises(DimensionError, match="obstacles need a 3-D DMP, this one is 2-D"):
        flat.rollout(obstacles=paper_potentials())
    with pytest.raises(DimensionError, match="obstacles need a 3-D DMP"):
        flat.stepper(obstacles=paper_potentials())


# ------------------------------------------------------------------------------------------
# The kernels themselves


def test_exp_is_accurate_to_an_ulp() -> None:
    """The kernels' vectorisable exp: within 1 ulp of the C library's on (-708, 0], exactly
    1 at 0, exactly 0 from -708 down (subnormal results) and for NaN."""
    x = np.concatenate(
        [
            np.linspace(-707.9999, 0.0, 20001),
            -np.logspace(-12, 2.8, 3001),
            [-0.5 * math.log(2.0), -1e-300, -0.0],
        ]
    )
    got = np.array([kernels._exp(float(v)) for v in x])
    ref = np.array([math.exp(v) for v in x])
    assert np.all(np.abs(got - ref) <= np.spacing(ref)), np.max(np.abs(got - ref) / ref)
    assert np.mean(got == ref) > 0.8  # mostly the same double
    assert kernels._exp(0.0) == 1.0
    assert kernels._exp(-708.0) == 0.0 and kernels._exp(-1e4) == 0.0
    assert kernels._exp(math.nan) == 0.0


def test_the_python_side_agrees_with_the_kernels_layout() -> None:
    from wholebody.planning import obstacles

    assert obstacles._Q_FLOOR == force_kernels._Q_FLOOR  # potential() and the force's floor
    assert potential_rows(()).shape == (0, force_kernels.ROW)


@pytest.mark.skipif(DISABLED, reason="NUMBA_DISABLE_JIT=1: nothing is compiled")
def test_inputs_of_other_types_compile_nothing_new(scene: DMP) -> None:
    """Arguments are converted to the kernels' types: ints, lists, float32 demonstrations,
    float32 and list states reuse the compiled code; each kernel has one signature."""
    entries = [kernels.fit, kernels.integrate, kernels.basis, kernels.savgol, force_kernels.forces]
    scene.rollout(160, obstacles=paper_potentials())
    scene.basis(np.array([0.5]))
    paper_potentials()[0].force(START, np.ones(3))
    savitzky_golay(np.ones((30, 2)), 7, 3, 0.1)
    before = [len(k.signatures) for k in entries]
    assert all(n == 1 for n in before)
    t = np.linspace(0, 2, 120)
    X = (np.outer(minimum_jerk_scaling(t / 2)[0], [1, 2, 3]) * 0.1).astype(np.float32)
    dmp = DMP.fit(X, list(t), config=DMPConfig(alpha_s=4, stiffness=900, n_basis=30))
    dmp.rollout(30, goal=[0.1, 0.2, 0.3], duration=3)
    dmp.rollout(30, obstacles=[DynamicPotential(sphere([0.1, 0.1, 0.1], 0.02))])
    st = dmp.stepper(obstacles=[StaticPotential(sphere([1, 1, 1], 0.1))])
    st.step(st.initial_state(), 1)
    st = dmp.stepper()
    state = st.initial_state()
    state.x = state.x.astype(np.float32)
    st.step(state, 0.01)
    st.acceleration(state)
    dmp.forcing([0.3, 0.2])
    total_force([DynamicPotential(sphere([0, 0, 0], 1))], [[1, 2, 3]], [[0, 0, 1]])
    savitzky_golay(np.arange(40.0).reshape(20, 2).astype(np.float32), 5, 2, 1)
    assert [len(k.signatures) for k in entries] == before
