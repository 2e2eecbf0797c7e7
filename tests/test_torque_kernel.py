"""The torque level's kernels (:mod:`wholebody.kernels.torque`) against independent oracles:
the braking bound against bisection on its two conditions, the internal-wrench rows against
numpy's pseudo-inverse and their defining property, and the weighted mode's single QP against
scipy on the same problem, torque limits active.

Run in the three modes (compiled, ``NUMBA_DISABLE_JIT=1``, ``NUMBA_BOUNDSCHECK=1``).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy.optimize import LinearConstraint, minimize

import wholebody as wb
from wholebody.dynamics import DynamicsSolver, PatchContact
from wholebody.kernels import layout as lay
from wholebody.kernels import torque

DT = 1e-3


def test_the_braking_bound_is_the_largest_acceleration_that_can_still_stop(rng):
    """``a_hi`` is where one of its conditions becomes tight: after the step (constant
    acceleration) the joint is inside its limit, and its velocity ``u'`` can still be
    braked to rest at ``b`` before the limit (``u'^2 <= 2 b d``, ``d`` from the position
    after a step at the current velocity); bisection on the two conditions finds it."""
    b, lo, hi = 10.0, -1.0, 1.0
    for _ in range(200):
        q, u, dt = rng.uniform(-0.99, 0.99), rng.uniform(-3.0, 3.0), rng.choice([1e-3, 1e-2])
        a_lo, a_hi = torque.braking(q, u, lo, hi, dt, b)

        def ok(a: float, q: float = q, u: float = u, dt: float = dt) -> bool:
            d = hi - q - u * dt
            inside = q + u * dt + 0.5 * a * dt * dt <= hi + 1e-12
            un = u + a * dt
            return inside and (un <= 0.0 or un * un <= 2.0 * b * max(d, 0.0) + 1e-9)

        left, right = -1e7, 1e7
        for _ in range(200):
            mid = 0.5 * (left + right)
            left, right = (mid, right) if ok(mid) else (left, mid)
        assert abs(a_hi - left) <= 1e-6 * (1.0 + abs(left))
        mirrored = torque.braking(-q, -u, lo, hi, dt, b)[1]  # the lower limit is the mirror
        assert abs(a_lo + mirrored) <= 1e-9 * (1.0 + abs(a_lo))
    assert torque.braking(0.0, 1.0, -np.inf, np.inf, DT, b) == (-np.inf, np.inf)


@pytest.mark.parametrize("columns", [12, 3])
def test_the_internal_rows_remove_exactly_the_net_wrench(rng, columns):
    """``L^T P`` against numpy's pseudo-inverse, and ``G P = 0``: the rows see nothing of a
    wrench's sum about the origin (two soles, 12 columns of full rank; one point contact, 3
    columns of rank 3)."""
    G = rng.standard_normal((6, columns))
    R = rng.standard_normal((columns + 2, columns))
    W = R.T @ R + 1e-6 * np.eye(columns)
    W_inv, L_t = np.linalg.inv(W), np.linalg.cholesky(W).T
    out = torque.internal_rows(G, W_inv, L_t)
    P = np.eye(columns) - W_inv @ G.T @ np.linalg.pinv(G @ W_inv @ G.T) @ G
    np.testing.assert_allclose(out, L_t @ P, atol=1e-9)
    assert np.abs(G @ scipy.linalg.solve_triangular(L_t, out, lower=False)).max() < 1e-9


def qp_oracle(arena, spec: np.ndarray, hard: int, quiet_weight: float) -> np.ndarray:
    """The weighted QP of :func:`~wholebody.kernels.torque.weighted_qp`, written out from
    the arena's levels (every inequality row included) and solved by scipy
    (``trust-constr``)."""
    A, b = arena.view(lay.F_A), arena.view(lay.F_B)
    C, CB, box = arena.view(lay.F_C), arena.view(lay.F_CB), arena.view(lay.F_BOX)
    n = A.shape[1]
    H, g, n_eq = _objective(arena, spec, hard, quiet_weight)
    constraints = [
        LinearConstraint(np.vstack([C, np.eye(n)]), np.r_[CB[0], box[0]], np.r_[CB[1], box[1]])
    ]
    if n_eq:
        constraints.append(LinearConstraint(A[:n_eq], b[:n_eq], b[:n_eq]))
    out = minimize(
        lambda x: 0.5 * x @ H @ x + g @ x,
        np.zeros(n),
        jac=lambda x: H @ x + g,
        hess=lambda x: H,
        constraints=constraints,
        method="trust-constr",
        options={"gtol": 1e-12, "xtol": 1e-14, "maxiter": 20000},
    )
    return out.x


def standing(sideways: float):
    """TALOS standing on both soles in the weighted mode, its CoM asked ``sideways`` (m) to
    its left: ``(robot, stack, solver, q)``."""
    robot = wb.load_robot("talos_full")
    com = wb.ComTask(robot, "xyz", kp=5.0)
    stack = wb.Stack(robot, [[com], [wb.PostureTask(robot, kp=0.5)]], [])
    feet = [
        PatchContact(f, mu=0.3, f_min=5.0, half_length=0.1, half_width=0.065)
        for f in ("left_sole_link", "right_sole_link")
    ]
    solver = DynamicsSolver(robot, feet, mode="weighted", level_weights=[1.0, 0.03])
    q = robot.home()
    solver.make_contacts(q)
    com.set_target(robot.com_position(q) + np.array([0.0, sideways, 0.0]))
    return robot, stack, solver, q


@pytest.mark.parametrize(
    "case", [pytest.param("standing", marks=pytest.mark.slow), "torque-bound arm"]
)
def test_the_weighted_qp_is_scipys_answer(case):
    """One weighted step's QP (TALOS standing on both soles; the Panda reaching with its
    torque limits cut to a third, so that some are active and the deferred rows come back)
    solved by the kernel and by scipy: the same answer."""
    if case == "standing":
        robot, stack, solver, q = standing(0.03)
    else:
        robot = wb.load_robot("panda")
        hand = wb.FrameTask(robot, "panda_hand_tcp", kp=10.0)
        q = robot.home()
        goal = robot.frame_pose(q, "panda_hand_tcp")
        goal[:3, 3] += (0.3, -0.3, -0.3)
        hand.set_target(goal)
        stack = wb.Stack(robot, [[hand], [wb.PostureTask(robot)]], [])
        solver = DynamicsSolver(robot, mode="weighted", level_weights=[1.0, 0.1])
        solver.effort = solver.effort / 5.0
    u = np.random.default_rng(5).normal(scale=0.2, size=robot.nu)
    res = solver.solve(stack, q, u, DT)
    layout = solver.layout
    scale = layout.arena.view(lay.F_METRIC)[0]  # (x~ -> [a, f])
    x = qp_oracle(layout.arena, layout.spec, layout.hard, solver.wrench_regularization) * scale
    f = np.concatenate(list(res.wrenches.values())) if res.wrenches else np.zeros(0)
    top = 1.0 + np.abs(x).max()
    np.testing.assert_allclose(np.r_[res.a, f], x, atol=1e-6 * top)  # (scipy: interior point)
    assert not solver.cascaded  # (the QP was feasible: its answer, not the cascade's)
    if case != "standing":
        d = solver.driven
        assert np.any(np.abs(res.tau[d]) > solver.effort[d] - 1e-6)  # a torque limit holds it
        assert res.violations["torque limits"] < 1e-6


def test_the_equality_optimum_is_the_kkt_solution(rng):
    """``_equality_optimum`` against the KKT system ``[H E^T; E 0] [x; mu] = [-g; e]`` solved
    by numpy, H ill-conditioned as the step's is (1e-9 on a floating base's directions);
    dependent rows refused."""
    n, m = 30, 9
    X, Y = rng.standard_normal((20, n)), rng.standard_normal((3, n))
    X[:, :6] = 0.0  # (the posture-like rows leave the base; three CoM-like rows do not)
    H = X.T @ X + Y.T @ Y + 1e-9 * np.eye(n)
    E, e, g = rng.standard_normal((m, n)), rng.standard_normal(m), rng.standard_normal(n)
    x, mu = np.empty(n), np.empty(m)
    assert torque._equality_optimum(H, g, E, e, x, mu)
    kkt = np.block([[H, E.T], [E, np.zeros((m, m))]])
    oracle = np.linalg.solve(kkt, np.r_[-g, e])
    np.testing.assert_allclose(E @ x, e, atol=1e-12 * (1 + np.abs(e).max()))
    np.testing.assert_allclose(x, oracle[:n], atol=1e-7 * (1 + np.abs(oracle[:n]).max()))
    np.testing.assert_allclose(H @ x + g + E.T @ mu, 0.0, atol=1e-7 * (1 + np.abs(g).max()))
    E[-1] = E[0] + E[1]
    assert not torque._equality_optimum(H, g, E, e, x, mu)  # (rows dependent)


def test_trtrs_rows_solves_every_row(rng):
    """One LAPACK call for many right-hand sides against scipy's triangular solve, both
    ``op``."""
    from wholebody.kernels.lapack import trtrs_rows

    L = np.tril(rng.standard_normal((7, 7))) + 5.0 * np.eye(7)
    B = rng.standard_normal((4, 7))
    for transpose in (False, True):
        Y = B.copy()
        assert trtrs_rows(np.asfortranarray(L), Y, True, transpose) == 0
        expected = scipy.linalg.solve_triangular(L, B.T, lower=True, trans=int(transpose)).T
        np.testing.assert_allclose(Y, expected, atol=1e-12)


def test_the_last_working_set_gives_daqps_answer_or_is_refused():
    """The weighted QP's warm start (:func:`~wholebody.kernels.torque._warm`): on the
    working set daqp's answer left (TALOS standing, its CoM pushed aside so that the soles'
    cones bind), the equality optimum is daqp's answer; a working set with a bound that is
    not active (a wrong side, a free row held) is refused."""
    robot, stack, solver, q = standing(0.08)
    u = np.random.default_rng(7).normal(scale=0.2, size=robot.nu)
    solver.solve(stack, q, u, DT)
    layout = solver.layout
    active = layout.active.copy()
    assert active.any()  # (bounds bind: daqp found them)
    arena = (layout.arena.f, layout.arena.i, layout.arena.h)
    first = np.empty(layout.n)
    flag, _ = torque.weighted_qp(
        arena,
        layout.spec,
        layout.hard,
        solver.wrench_regularization,
        layout.deferred,
        solver._daqp,
        np.zeros_like(active),
        first,
    )  # (from an empty working set: daqp)
    H, g, n_eq = _objective(layout.arena, layout.spec, layout.hard, solver.wrench_regularization)
    x = np.empty(layout.n)
    solved, bounded = torque._warm(arena, H, g, n_eq, active, x)
    assert flag > 0 and solved and bounded
    np.testing.assert_allclose(x, first, atol=1e-9 * (1 + np.abs(first).max()))
    for k in np.flatnonzero(active):
        wrong = active.copy()
        wrong[k] = -wrong[k]  # the other side of the same bound
        assert not torque._warm(arena, H, g, n_eq, wrong, x)[0]
    free = np.flatnonzero(active == 0)[-1]
    held = active.copy()
    held[free] = 1
    assert not torque._warm(arena, H, g, n_eq, held, x)[0]


def _objective(arena, spec, hard, quiet_weight):
    """The weighted QP's ``H``, ``g`` and equality count, written out from the arena."""
    A, b, levels = arena.view(lay.F_A), arena.view(lay.F_B), arena.view(lay.I_LEVEL)
    n = A.shape[1]
    H, g = 1e-9 * np.eye(n), np.zeros(n)
    for lv in range(hard, levels.shape[0]):
        w2 = (quiet_weight if spec[lv, 0] == torque.LEVEL_QUIET else 1.0) ** 2
        rows = slice(levels[lv, 0], levels[lv, 2])
        H += w2 * A[rows].T @ A[rows]
        g -= w2 * A[rows].T @ b[rows]
    return H, g, int(levels[hard - 1, 2])
