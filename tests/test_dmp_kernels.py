"""The compiled DMP (wholebody.kernels.dmp) against the Python reference implementation:
the same paths to rounding, the same substep decisions, the same errors, and the fallback to
the reference where a potential is not one the kernels compute.

Every comparison runs the reference inside ``reference_implementation()``; under
``NUMBA_DISABLE_JIT=1`` the "compiled" side is the kernels' own Python, which must agree as
well.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wholebody.errors import DimensionError, IntegrationError
from wholebody.kernels import DISABLED
from wholebody.kernels import dmp as kernels
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
)
from wholebody.planning.dmp import adaptive, reference_implementation
from wholebody.planning.dmp.compiled import kernels as active_kernels
from wholebody.planning.obstacles import kernel_rows

PATH_TOL = 1e-9  # m: the compiled and the reference paths (they agree to ~1e-13)

START = np.array([1.73, -0.54, 1.06])
GOAL = np.array([1.73, -0.30, 1.09])
CENTERS = ([1.725, -0.4, 1.09], [1.725, -0.2, 1.09])


def reach(start: np.ndarray, goal: np.ndarray, n: int = 160, T: float = 2.0) -> DMP:
    """A DMP of a minimum-jerk straight reach in ``T`` s."""
    t = np.linspace(0.0, T, n)
    return DMP.fit(start + minimum_jerk_scaling(t / T)[0][:, None] * (goal - start), t)


@pytest.fixture(scope="module")
def scene() -> DMP:
    return reach(START, GOAL)


def paper_potentials(beta: float = 2.0) -> list[DynamicPotential]:
    return [DynamicPotential(cylinder(c, 0.04, 0.2, margin=0.02), 10.0, beta, 2.0)
            for c in CENTERS]  # fmt: skip


def both_rollouts(dmp: DMP, obstacles, **kw) -> tuple[tuple, tuple]:
    """(rollout, substeps per interval, evaluations), compiled and reference."""
    x0, g, T = dmp._targets(kw.pop("start", None), kw.pop("goal", None), kw.pop("duration", None))
    N = kw.pop("samples", 160)
    args = (N, x0, g, T, tuple(obstacles), kw.pop("tolerance", 1e-3), kw.pop("max_substeps", 256))
    fast = adaptive.rollout_obstacles(dmp, *args, active_kernels())
    reference = adaptive.rollout_obstacles(dmp, *args, None)
    return fast, reference


def assert_same_rollout(a, b, tol: float = PATH_TOL) -> None:
    gap = np.max(np.linalg.norm(a.positions - b.positions, axis=1))
    assert gap < tol, gap
    scale = max(1.0, float(np.abs(b.accelerations).max()))
    np.testing.assert_allclose(a.velocities, b.velocities, rtol=0, atol=1e3 * tol)
    np.testing.assert_allclose(a.accelerations, b.accelerations, rtol=0, atol=1e5 * tol * scale)
    np.testing.assert_allclose(a.times, b.times, rtol=0, atol=1e-14)
    np.testing.assert_allclose(a.phase, b.phase, rtol=1e-14, atol=0)


def test_the_kernels_constants_are_the_references() -> None:
    from wholebody.planning import obstacles

    assert kernels._ACCEPT_AT_LIMIT == adaptive.ACCEPT_AT_LIMIT
    assert kernels._Q_FLOOR == obstacles._Q_FLOOR


def test_the_switch_selects_the_implementation(scene: DMP, monkeypatch) -> None:
    """Compiled by default; the reference inside ``reference_implementation()`` (nested
    blocks restore the outer choice); a stepper keeps the one it was built with."""
    calls = []
    original = adaptive.ObstacleIntegrator.rollout
    monkeypatch.setattr(adaptive.ObstacleIntegrator, "rollout",
                        lambda self, *a: calls.append(1) or original(self, *a))  # fmt: skip
    pots = paper_potentials()
    scene.rollout(160, obstacles=pots)
    assert calls == []
    with reference_implementation():
        assert active_kernels() is None
        with reference_implementation(False):
            assert active_kernels() is kernels
        scene.rollout(160, obstacles=pots)
        stepper = scene.stepper(obstacles=pots)
    assert calls == [1] and active_kernels() is kernels
    assert stepper._kernels is None and scene.stepper(obstacles=pots)._kernels is kernels


def test_paper_scene_same_path_and_substeps(scene: DMP) -> None:
    (a, na, ea), (b, nb, eb) = both_rollouts(scene, paper_potentials())
    assert_same_rollout(a, b)
    assert np.array_equal(na, nb) and ea == eb  # the same decisions, interval by interval
    assert na.max() > 4 and na.min() == 1  # the step control did work near the cylinders
    assert np.max(np.abs(a.positions[:, 0] - START[0])) > 0.04  # and the obstacle acted
    # the public rollout is the compiled one
    np.testing.assert_array_equal(scene.rollout(160, obstacles=paper_potentials()).positions,
                                  a.positions)  # fmt: skip


def test_paper_scene_converged_and_moved_goal(scene: DMP) -> None:
    (a, na, _), (b, nb, _) = both_rollouts(scene, paper_potentials(), tolerance=1e-8,
                                           max_substeps=4096)  # fmt: skip
    assert_same_rollout(a, b) and np.array_equal(na, nb)
    goal = GOAL + np.array([0.02, 0.05, -0.03])
    (a, na, _), (b, nb, _) = both_rollouts(scene, paper_potentials(), goal=goal, duration=3.0,
                                           samples=97)  # fmt: skip
    assert_same_rollout(a, b)
    assert np.array_equal(na, nb)


R1 = exp_so3(np.array([0.3, -0.5, 0.9]))
R2 = exp_so3(np.array([-1.2, 0.4, 0.2]))
SCENES = {
    "sphere": [DynamicPotential(sphere([1.72, -0.42, 1.08], 0.03, margin=0.01))],
    "rotated box": [DynamicPotential(box([1.735, -0.42, 1.075], [0.05, 0.03, 0.08], rotation=R1,
                                         margin=0.01), gain=5.0, beta=1.5, eta=1.0)],
    "tilted cylinder": [DynamicPotential(cylinder([1.74, -0.4, 1.07], 0.03, 0.1, axis=[1, 1, 0.2],
                                                  margin=0.01))],
    "static box and sphere": [
        StaticPotential(box([1.74, -0.40, 1.08], [0.04, 0.04, 0.04], rotation=R2), 1e-3, 2.0),
        StaticPotential(sphere([1.72, -0.36, 1.08], 0.02), 1e-3, 1.0),
    ],
    "three mixed": [
        DynamicPotential(Superquadric([1.73, -0.44, 1.07], R2, [0.03, 0.02, 0.04], 2.0, 3.0)),
        StaticPotential(sphere([1.70, -0.35, 1.1], 0.02), 1e-3, 1.0),
        DynamicPotential(box([1.75, -0.36, 1.06], [0.02, 0.02, 0.02], exponent=8), 2.0),
    ],
}  # fmt: skip


@pytest.mark.parametrize("name", list(SCENES))
def test_obstacles_at_several_poses(scene: DMP, name: str) -> None:
    pots = SCENES[name]
    assert kernel_rows(pots) is not None
    (a, na, ea), (b, nb, eb) = both_rollouts(scene, pots)
    assert_same_rollout(a, b)
    assert np.array_equal(na, nb) and ea == eb
    free = scene.rollout(160).positions
    assert np.max(np.linalg.norm(a.positions - free, axis=1)) > 1e-3  # the obstacles acted


@pytest.mark.parametrize("substeps", [1, 3, 16])
def test_fixed_step_rk4(scene: DMP, substeps: int) -> None:
    (a, na, ea), (b, nb, eb) = both_rollouts(scene, paper_potentials(), tolerance=math.inf,
                                             max_substeps=substeps)  # fmt: skip
    assert_same_rollout(a, b)
    assert np.all(na == substeps) and np.array_equal(na, nb) and ea == eb


def raised(fn) -> tuple[type, str]:
    """The type and message of what ``fn()`` raises."""
    with pytest.raises(ArithmeticError) as info:
        fn()
    return type(info.value), str(info.value)


def both_raise(fn) -> tuple[type, str]:
    compiled = raised(fn)
    with reference_implementation():
        reference = raised(fn)
    assert compiled == reference
    return compiled


def test_unresolved_intervals_raise_as_the_reference(scene: DMP) -> None:
    kind, message = both_raise(lambda: scene.rollout(160, obstacles=paper_potentials(),
                                                     max_substeps=1))  # fmt: skip
    assert kind is IntegrationError and "with 1 substeps" in message
    # a steep box 1 cm off a straight reach: the estimate stays above 10 x the tolerance
    steep = reach(np.array([0.0, 0.01, 0.0]), np.array([0.8, 0.01, 0.0]), n=200, T=1.0)
    pot = [DynamicPotential(box([0.5, 0.0, 0.0], [0.04, 0.04, 0.04], exponent=12))]
    kind, message = both_raise(lambda: steep.rollout(160, obstacles=pot))
    assert kind is IntegrationError and "above 10 x the tolerance 0.001 m" in message

    def stepped() -> None:
        stepper = steep.stepper(obstacles=pot, max_substeps=8)
        state = stepper.initial_state()
        for _ in range(159):
            stepper.step(state, 1.0 / 159, out=state)

    kind, message = both_raise(stepped)
    assert kind is IntegrationError and "with 8 substeps" in message


def shapes_and_points(rng: np.random.Generator) -> list[tuple[object, np.ndarray]]:
    """Potentials of every kind with points around, inside, on the axis and at the centre."""
    out = []
    for shape in (
        sphere([0.1, -0.2, 0.3], 0.05),
        cylinder([0.0, 0.0, 0.0], 0.04, 0.2, rotation=R1, margin=0.01),
        box([0.2, 0.1, 0.0], [0.1, 0.05, 0.08], rotation=R2, exponent=6),
        Superquadric([0.0, 0.1, -0.1], np.eye(3), [0.05, 0.08, 0.03], 3.0, 2.0),
    ):
        near = shape.center + rng.normal(size=(60, 3)) * 2.0 * shape.semi_axes.max()
        inside = shape.center + (rng.random((20, 3)) - 0.5) * shape.semi_axes @ shape.rotation.T
        axis = shape.center + np.outer([0.0, 0.3, -2.0], shape.semi_axes[2] * shape.rotation[:, 2])
        x = np.vstack([near, inside, axis])
        for pot in (DynamicPotential(shape, 2.0, 2.0, 2.0), DynamicPotential(shape, 0.5, 1.0, 0.5),
                    StaticPotential(shape, 1.0, 1.5)):  # fmt: skip
            out.append((pot, x))
    return out


def test_compiled_forces_equal_the_point_forces(rng: np.random.Generator) -> None:
    """Force by force, the kernels' forces are the reference closures' (the same arithmetic:
    equal to rounding, also inside, on the axis and at the centre, where the saturation and
    the floors act)."""
    for pot, x in shapes_and_points(rng):
        rows = kernel_rows([pot])
        force = pot.point_force()
        x = np.vstack([x, pot.shape.center])
        v = rng.normal(size=x.shape)
        v[-1] = 0.0  # at rest at the centre
        for a, b in zip(x, v, strict=True):
            *got, over = kernels._force(rows, *a, *b)
            assert not over
            np.testing.assert_allclose(got, force(*a, *b), rtol=1e-15, atol=1e-300)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # uncompiled: numpy scalars overflow
def test_non_finite_and_overflowing_forces_raise_as_the_reference(scene: DMP) -> None:
    # a gain so large that the force overflows to inf: a non-finite state
    huge = [DynamicPotential(cylinder(CENTERS[0], 0.04, 0.2, margin=0.02), gain=1e305)]
    kind, message = both_raise(lambda: scene.rollout(160, obstacles=huge))
    assert kind is IntegrationError and "non-finite state" in message
    # a 10 um box with exponent 32: |u|^62 overflows beyond 0.48 m. Where the path starts
    # that far, Python's power raised OverflowError at the first evaluation ...
    far = [
        DynamicPotential(box(START + np.array([0.6, 0.0, 0.0]), [1e-5, 1e-5, 1e-5], exponent=32))
    ]
    kind, _ = both_raise(lambda: scene.rollout(160, obstacles=far))
    assert kind is OverflowError
    # ... and a power that overflows in the middle of an interval: Python raised there, the
    # interval was redone with more substeps, none resolved it. A 10 um thin cylinder along x:
    # q^32, q = (r / f)^2, overflows beyond r = 0.66 m; the path runs from 0.5 m to 0.74 m
    thin = [DynamicPotential(cylinder(START - [0.0, 0.5, 0.0], 1e-5, 1.0, axis=[1, 0, 0],
                                      exponent=32))]  # fmt: skip
    kind, message = both_raise(lambda: scene.rollout(160, obstacles=thin, max_substeps=16))
    assert kind is IntegrationError and "non-finite state with 16 substeps" in message
    # the stepper too, having counted the same force evaluations (none where one overflowed)
    steppers = [scene.stepper(obstacles=thin, max_substeps=16)]
    with reference_implementation():
        steppers.append(scene.stepper(obstacles=thin, max_substeps=16))
    steps = []
    for stepper in steppers:
        state = stepper.initial_state()
        with pytest.raises(IntegrationError, match="non-finite state with 16 substeps"):
            for k in range(159):
                steps.append(k)
                stepper.step(state, 2.0 / 159, out=state)
    assert steps[-1] > 20 and len(steps) == 2 * (steps[-1] + 1)  # mid-path, the same step
    assert steppers[0]._state[1] == steppers[1]._integrator.evaluations


def test_stepper_with_obstacles_same_states_and_decisions(scene: DMP) -> None:
    pots = paper_potentials()
    compiled = scene.stepper(obstacles=pots)
    with reference_implementation():
        reference = scene.stepper(obstacles=pots)
    a, b = compiled.initial_state(), reference.initial_state()
    for k in range(1, 200):
        if k == 120:  # a moved goal, and a sampling the rollout does not use
            for st in (compiled, reference):
                st.set_goal(GOAL + np.array([0.0, 0.03, 0.01]))
        dt = 2.0 / 159 if k < 100 else 0.0137
        if k == 60:  # float32 arrays for one step: the compiled stepper's Python path
            a.x = a.x.astype(np.float32)
            b = DMPState(a.x.copy(), a.v.copy(), a.s, a.t)
        compiled.step(a, dt, out=a)
        b = reference.step(b, dt, out=b if k == 60 else None)
        if k == 60:
            np.testing.assert_array_equal(a.x, b.x)
            a.x, b.x = a.x.astype(float), b.x.astype(float)
        assert np.linalg.norm(a.x - b.x) < PATH_TOL and np.linalg.norm(a.v - b.v) < 1e3 * PATH_TOL
        assert a.s == pytest.approx(b.s, rel=1e-14) and a.t == pytest.approx(b.t, rel=1e-14)
        assert compiled._state[2] == reference._integrator.last  # substeps of this step
    assert compiled._state[1] == reference._integrator.evaluations
    assert compiled._state[0] == reference._integrator.m
    np.testing.assert_allclose(compiled.acceleration(a), reference.acceleration(b), atol=1e-6)


@pytest.mark.parametrize("dt", [0.01, 2.0 / 159, 0.5])  # 0.5 s: several RK4 steps per call
def test_linear_stepper_same_states(scene: DMP, dt: float) -> None:
    compiled = scene.stepper(duration=3.0)
    with reference_implementation():
        reference = scene.stepper(duration=3.0)
    a, b = compiled.initial_state(), reference.initial_state()
    for k in range(40):
        if k == 10:
            for st in (compiled, reference):
                st.set_goal(GOAL + np.array([0.05, 0.0, -0.02]))
        a = compiled.step(a, dt)
        reference.step(b, dt, out=b)
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-13)
        np.testing.assert_allclose(a.v, b.v, rtol=0, atol=1e-12)
        assert a.s == pytest.approx(b.s, rel=1e-14)
    # float32 states (and lists) take the reference's numpy code, rounding where it stores
    a.x, a.v = a.x.astype(np.float32), a.v.astype(np.float32)
    b.x, b.v, b.s = a.x.copy(), a.v.copy(), a.s
    for _ in range(3):
        compiled.step(a, dt, out=a)
        reference.step(b, dt, out=b)
    assert a.x.dtype == np.float32 and a.v.dtype == np.float32
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.v, b.v)


def test_linear_stepper_allocates_nothing_and_matches_in_place(scene: DMP) -> None:
    compiled = scene.stepper()
    with reference_implementation():
        reference = scene.stepper()
    a, b = compiled.initial_state(), reference.initial_state()
    x, v = a.x, a.v
    for _ in range(159):
        assert compiled.step(a, 2.0 / 159, out=a) is a
        reference.step(b, 2.0 / 159, out=b)
    assert a.x is x and a.v is v
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a.v, b.v, rtol=0, atol=1e-12)


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
        "1-D, 12 narrow basis functions": (t, 0.4 * s[:, None] ** 2,
                                           DMPConfig(n_basis=12, overlap=0.5, alpha_s=3)),
        "6-D stiff": (t, np.outer(s, np.arange(1, 7) * 0.1) + 0.02 * np.sin(6 * s)[:, None],
                      DMPConfig(stiffness=400.0, damping=30.0, phase_end=1e-3)),
    }  # fmt: skip


@pytest.mark.parametrize("name", list(demonstrations()))
def test_fit_and_rollout_same_paths(name: str) -> None:
    t, X, cfg = demonstrations()[name]
    a = DMP.fit(X, t, config=cfg)
    with reference_implementation():
        b = DMP.fit(X, t, config=cfg)
    np.testing.assert_allclose(a.start, b.start, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.goal, b.goal, rtol=0, atol=1e-12)
    for kw in ({"samples": 160}, {"samples": 5}, {"samples": 1001, "duration": 1.3},
               {"samples": 50, "goal": b.goal + 0.1, "start": b.start - 0.05}):  # fmt: skip
        ra = a.rollout(**kw)
        with reference_implementation():
            rb = b.rollout(**kw)
        assert_same_rollout(ra, rb)
    # and the demonstration is reproduced (the fit is a fit)
    r = a.rollout(len(t))
    demo = np.stack([np.interp(r.times, t - t[0], x) for x in X.T], axis=1)
    assert np.max(np.abs(r.positions - demo)) < 2e-2


def test_singular_normal_equations_fall_back_to_a_general_solve(monkeypatch) -> None:
    """Without the ridge and with nearly coincident basis functions the Cholesky factorisation
    fails; both implementations then solve the normal equations by LU (np.linalg.solve)."""
    solves = []
    solve = np.linalg.solve
    monkeypatch.setattr(np.linalg, "solve", lambda A, b: solves.append(A.shape) or solve(A, b))
    t = np.linspace(0.0, 1.0, 60)
    X = np.stack([minimum_jerk_scaling(t)[0], np.sin(3 * t), t**2], 1)
    cfg = DMPConfig(n_basis=50, overlap=0.999)
    a = DMP.fit(X, t, config=cfg, regularization=0.0)
    with reference_implementation():
        b = DMP.fit(X, t, config=cfg, regularization=0.0)
    assert solves == [(50, 50), (50, 50)]
    assert np.all(np.isfinite(a.weights)) and np.all(np.isfinite(b.weights))


def test_exp_is_accurate_to_an_ulp() -> None:
    """The kernels' vectorisable exp: within 1 ulp of the C library's (as numpy's vectorised
    one) on (-708, 0], exactly 1 at 0, exactly 0 from -708 down (subnormal results) and for
    NaN."""
    x = np.concatenate([np.linspace(-707.9999, 0.0, 20001), -np.logspace(-12, 2.8, 3001),
                        [-0.5 * math.log(2.0), -1e-300, -0.0]])  # fmt: skip
    got = np.array([kernels._exp(float(v)) for v in x])
    ref = np.array([math.exp(v) for v in x])
    assert np.all(np.abs(got - ref) <= np.spacing(ref)), np.max(np.abs(got - ref) / ref)
    assert np.mean(got == ref) > 0.8  # mostly the same double
    assert kernels._exp(0.0) == 1.0
    assert kernels._exp(-708.0) == 0.0 and kernels._exp(-1e4) == 0.0
    assert kernels._exp(math.nan) == 0.0


class Scaled(DynamicPotential):
    """A user's potential: twice the force of its base class, by its own point_force."""

    def point_force(self):
        base = super().point_force()

        def force(*args: float) -> tuple[float, float, float]:
            return tuple(2.0 * f for f in base(*args))  # type: ignore[return-value]

        return force


class Named(DynamicPotential):
    """A subclass that adds nothing to the force: the kernels compute it."""

    name = "cup"


def test_user_potentials_fall_back_to_the_reference(scene: DMP) -> None:
    shape = cylinder(CENTERS[0], 0.04, 0.2, margin=0.02)
    scaled = [Scaled(shape), DynamicPotential(cylinder(CENTERS[1], 0.04, 0.2, margin=0.02))]
    assert kernel_rows(scaled) is None and kernel_rows([Named(shape)]) is not None
    got = scene.rollout(160, obstacles=scaled)
    with reference_implementation():
        ref = scene.rollout(160, obstacles=scaled)
    np.testing.assert_array_equal(got.positions, ref.positions)  # the same Python code
    assert scene.stepper(obstacles=scaled)._kernels is None
    # its own force was used: twice the base's (= the base's with twice the gain)
    second = scaled[1]
    unscaled = scene.rollout(160, obstacles=[DynamicPotential(shape), second]).positions
    doubled = scene.rollout(160, obstacles=[DynamicPotential(shape, 20.0), second]).positions
    assert np.max(np.linalg.norm(got.positions - unscaled, axis=1)) > 1e-3
    assert np.max(np.linalg.norm(got.positions - doubled, axis=1)) < PATH_TOL
    named = scene.rollout(160, obstacles=[Named(shape)]).positions
    base = scene.rollout(160, obstacles=[DynamicPotential(shape)]).positions
    np.testing.assert_array_equal(named, base)
    for mode in (False, True):
        with reference_implementation(mode), pytest.raises(DimensionError, match="wrap each"):
            scene.rollout(160, obstacles=[shape])


@pytest.mark.skipif(DISABLED, reason="NUMBA_DISABLE_JIT=1: nothing is compiled")
def test_inputs_of_other_types_compile_nothing_new(scene: DMP) -> None:
    """Arguments are converted to the kernels' types: ints, lists, Fortran-ordered weights
    (the reference fit's) and float32 states reuse the compiled code."""
    entries = [kernels.fit, kernels.rollout_linear, kernels.rollout_obstacles,
               kernels.step_linear, kernels.step_obstacles]  # fmt: skip
    before = [len(k.signatures) for k in entries]
    assert all(n == 1 for n in before)
    t = np.linspace(0, 2, 120)
    X = (np.outer(minimum_jerk_scaling(t / 2)[0], [1, 2, 3]) * 0.1).astype(np.float32)
    dmp = DMP.fit(X[:, :3], list(t), config=DMPConfig(alpha_s=4, stiffness=900, n_basis=30))
    with reference_implementation():
        fortran = DMP.fit(X, t)
    assert not fortran.weights.flags.c_contiguous
    for d in (dmp, fortran):
        d.rollout(30, goal=[0.1, 0.2, 0.3], duration=3)
        d.rollout(30, obstacles=[DynamicPotential(sphere([0.1, 0.1, 0.1], 0.02))])
        st = d.stepper(obstacles=[StaticPotential(sphere([1, 1, 1], 0.1))])
        st.step(st.initial_state(), 1)
        st = d.stepper()
        state = st.initial_state()
        state.x = state.x.astype(np.float32)
        st.step(state, 0.01)
    assert [len(k.signatures) for k in entries] == before
