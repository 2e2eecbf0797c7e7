"""daqp's C API from kernels (:mod:`wholebody.kernels.daqp`) against daqp's Python package
and against independent oracles: the KKT conditions of the returned point and multipliers,
and scipy's own QP solution (``trust-constr``).

Run in the three modes (compiled, ``NUMBA_DISABLE_JIT=1``, ``NUMBA_BOUNDSCHECK=1``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import daqp
import numba
import numpy as np
import pytest
from scipy.optimize import LinearConstraint, minimize

from wholebody.kernels import DISABLED
from wholebody.kernels import daqp as dk

SETTINGS = {"primal_tol": 1e-9, "iter_limit": 2000}


def random_qp(
    rng: np.random.Generator,
    n: int,
    ms: int,
    rows: int,
    *,
    n_eq: int = 0,
    n_inf: int = 0,
    inf: float = np.inf,
) -> dict:
    """A strictly convex QP in daqp's convention whose bounds are feasible by construction
    (they contain a random point x0): ``ms`` simple bounds, ``rows`` general rows, the last
    ``n_eq`` of them equalities (flagged ``EQUALITY``), ``n_inf`` bounds made infinite
    (``inf``) on one side or both."""
    M = rng.standard_normal((n + 3, n))
    H = M.T @ M + 0.1 * np.eye(n)
    f = 5.0 * rng.standard_normal(n)
    A = rng.standard_normal((rows, n))
    x0 = 0.3 * rng.standard_normal(n)
    g0 = np.concatenate([x0[:ms], A @ x0])
    m = ms + rows
    bl = g0 - rng.uniform(0.05, 1.0, m)
    bu = g0 + rng.uniform(0.05, 1.0, m)
    sense = np.zeros(m, np.int32)
    if n_eq:
        bl[m - n_eq :] = bu[m - n_eq :] = g0[m - n_eq :]
        sense[m - n_eq :] = dk.EQUALITY
    free = rng.choice(m - n_eq, size=min(n_inf, m - n_eq), replace=False)
    for j, i in enumerate(free):
        if j % 3 != 1:
            bu[i] = inf
        if j % 3 != 0:
            bl[i] = -inf
    return {"H": H, "f": f, "A": A, "bupper": bu, "blower": bl, "sense": sense}


def kernel_solve(qp: dict, **settings: float) -> tuple[int, int, np.ndarray, np.ndarray]:
    n, m = qp["f"].shape[0], qp["bupper"].shape[0]
    x, lam = np.empty(n), np.empty(m)
    s = dk.settings(**{**SETTINGS, **settings})
    flag, it = dk.solve(
        qp["H"], qp["f"], qp["A"], qp["bupper"], qp["blower"], qp["sense"], s, x, lam
    )
    return flag, it, x, lam


def python_solve(qp: dict, **settings: float) -> tuple[int, int, np.ndarray, np.ndarray]:
    x, _, flag, info = daqp.solve(
        qp["H"],
        qp["f"],
        qp["A"],
        qp["bupper"],
        qp["blower"],
        qp["sense"].copy(),
        **{**SETTINGS, **settings},
    )
    return flag, info["iterations"], x, info["lam"]


def rows_of(qp: dict) -> np.ndarray:
    """All m constraint rows, the simple bounds as unit rows: ``G`` with ``blower <= G x``."""
    n, ms = qp["f"].shape[0], qp["bupper"].shape[0] - qp["A"].shape[0]
    return np.vstack([np.eye(n)[:ms], qp["A"]])


def assert_kkt(qp: dict, x: np.ndarray, lam: np.ndarray, tol: float = 1e-8) -> None:
    """x and lam satisfy the KKT conditions of the (strictly convex) QP, which makes x its
    unique minimiser: stationarity ``H x + f + G' lam = 0``, feasibility, and each multiplier
    of the right sign and zero unless its bound is active (upper: > 0, lower: < 0)."""
    H, f, bu, bl = qp["H"], qp["f"], qp["bupper"], qp["blower"]
    G = rows_of(qp)
    g = G @ x
    scale = 1.0 + np.abs(f).max() + np.abs(H).max() * np.abs(x).max()
    np.testing.assert_allclose(H @ x + f + G.T @ lam, 0.0, atol=tol * scale)
    assert np.all(g <= bu + 1e-8) and np.all(g >= bl - 1e-8)
    at_upper = np.abs(g - bu) <= 1e-8 * (1 + np.abs(bu))
    at_lower = np.abs(g - bl) <= 1e-8 * (1 + np.abs(bl))
    big = np.abs(lam) > 1e-9 * scale
    assert np.all(~big | (lam > 0) & at_upper | (lam < 0) & at_lower), "complementarity"


def scipy_solve(qp: dict) -> np.ndarray:
    """The QP by scipy's trust-region interior-point method (no daqp involved)."""
    H, f = qp["H"], qp["f"]
    bu = np.where(qp["bupper"] >= dk.INF, np.inf, qp["bupper"])
    bl = np.where(qp["blower"] <= -dk.INF, -np.inf, qp["blower"])
    res = minimize(
        lambda z: 0.5 * z @ H @ z + f @ z,
        np.zeros(f.shape[0]),
        jac=lambda z: H @ z + f,
        hess=lambda z: H,
        method="trust-constr",
        constraints=[LinearConstraint(rows_of(qp), bl, bu)],
        options={"gtol": 1e-12, "xtol": 1e-14, "maxiter": 5000},
    )
    return res.x


CASES = {  # name: (n, ms, general rows, equalities among them, infinite bounds, seed)
    "tiny": (1, 1, 0, 0, 0, 1),
    "box only": (23, 23, 0, 0, 0, 2),
    "level shape": (23, 23, 10, 0, 4, 3),
    "rows only": (11, 0, 23, 0, 0, 4),
    "some bounds": (17, 6, 8, 0, 5, 5),
    "equalities": (12, 12, 6, 2, 3, 6),
    "many equalities": (30, 10, 12, 8, 4, 7),  # daqp eliminates them (eq_reduction auto)
    "large": (30, 30, 20, 0, 10, 8),
}


@pytest.mark.parametrize("name", CASES)
def test_random_qps_against_daqp_and_oracles(name: str) -> None:
    n, ms, rows, n_eq, n_inf, seed = CASES[name]
    qp = random_qp(np.random.default_rng(seed), n, ms, rows, n_eq=n_eq, n_inf=n_inf)
    before = {k: v.copy() for k, v in qp.items()}
    flag, it, x, lam = kernel_solve(qp)
    ref_flag, ref_it, ref_x, ref_lam = python_solve(qp)
    assert flag == ref_flag == dk.OPTIMAL
    assert it == ref_it
    np.testing.assert_allclose(x, ref_x, rtol=0, atol=1e-12)  # the same C code on the same data
    np.testing.assert_allclose(lam, ref_lam, rtol=0, atol=1e-12)
    for k, v in before.items():  # nothing written but x and lam
        np.testing.assert_array_equal(qp[k], v)
    assert_kkt(qp, x, lam)
    # an interior-point method: it stops within about 1e-5 of the optimum
    np.testing.assert_allclose(x, scipy_solve(qp), rtol=0, atol=1e-4 * (1 + np.abs(x).max()))


def test_infinite_bounds_as_daqp_inf() -> None:
    """Bounds at +-1e30 (daqp's INF) are absent, as +-inf are."""
    rng = np.random.default_rng(9)
    qp = random_qp(rng, 15, 8, 6, n_inf=8, inf=dk.INF)
    qp_inf = {
        **qp,
        "bupper": np.where(qp["bupper"] >= dk.INF, np.inf, qp["bupper"]),
        "blower": np.where(qp["blower"] <= -dk.INF, -np.inf, qp["blower"]),
    }
    flag, _, x, lam = kernel_solve(qp)
    flag_inf, _, x_inf, _ = kernel_solve(qp_inf)
    assert flag == flag_inf == dk.OPTIMAL
    np.testing.assert_allclose(x, x_inf, rtol=0, atol=1e-12)
    assert_kkt(qp, x, lam)


def test_active_set_at_the_optimum_matches_a_dense_kkt_solve() -> None:
    """The point solves the equality-constrained QP of its active bounds (a dense KKT solve
    by numpy), and no bound left out is violated: the active-set optimality check."""
    qp = random_qp(np.random.default_rng(10), 23, 23, 10, n_inf=4)
    flag, _, x, lam = kernel_solve(qp)
    assert flag == dk.OPTIMAL
    G = rows_of(qp)
    act = np.flatnonzero(lam != 0)
    b = np.where(lam[act] > 0, qp["bupper"][act], qp["blower"][act])
    n, k = x.shape[0], act.shape[0]
    K = np.block([[qp["H"], G[act].T], [G[act], np.zeros((k, k))]])
    sol = np.linalg.solve(K, np.concatenate([-qp["f"], b]))
    np.testing.assert_allclose(x, sol[:n], rtol=0, atol=1e-10)
    np.testing.assert_allclose(lam[act], sol[n:], rtol=1e-8, atol=1e-10)


def test_infeasible() -> None:
    """x0 <= -1 as a simple bound and x0 + 0 x1 >= 1 as a row: daqp's exit flag -1, x and
    lam left NaN or daqp's, as the Python package says."""
    qp = {
        "H": np.eye(2),
        "f": np.zeros(2),
        "A": np.array([[1.0, 0.0]]),
        "bupper": np.array([-1.0, np.inf]),
        "blower": np.array([-np.inf, 1.0]),
        "sense": np.zeros(2, np.int32),
    }
    flag, _, _, lam = kernel_solve(qp)
    assert flag == python_solve(qp)[0] == dk.INFEASIBLE
    assert np.all(np.isnan(lam))


def test_iteration_limit() -> None:
    """A QP that takes many iterations, cut at 3: ITERLIMIT after 3 iterations, daqp's last
    iterate in x, both as daqp's Python package reports them."""
    qp = random_qp(np.random.default_rng(11), 30, 30, 20)
    assert kernel_solve(qp)[1] > 5
    flag, it, x, _ = kernel_solve(qp, iter_limit=3)
    ref_flag, ref_it, ref_x, _ = python_solve(qp, iter_limit=3)
    assert flag == ref_flag == dk.ITERLIMIT
    assert it == ref_it
    np.testing.assert_allclose(x, ref_x, rtol=0, atol=1e-12)


def test_soft_bounds() -> None:
    """Two soft rows that cannot both hold: exit flag SOFT_OPTIMAL, the violation priced by
    rho_soft and w_soft (both passed through the settings struct) as daqp's package does."""
    qp = {
        "H": np.eye(2),
        "f": np.zeros(2),
        "A": np.array([[1.0, 1.0], [1.0, 1.0]]),
        "bupper": np.array([np.inf, -1.0]),
        "blower": np.array([1.0, -np.inf]),
        "sense": np.full(2, dk.SOFT, np.int32),
    }
    for extra in ({}, {"rho_soft": 1e-2, "w_soft": 0.5}):
        flag, _, x, lam = kernel_solve(qp, **extra)
        ref_flag, _, ref_x, ref_lam = python_solve(qp, **extra)
        assert flag == ref_flag == dk.SOFT_OPTIMAL
        np.testing.assert_allclose(x, ref_x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lam, ref_lam, rtol=0, atol=1e-12)
    assert abs(x[0] + x[1]) < 1.0  # both rows violated: the penalty split them


def test_initial_working_set() -> None:
    """A bound flagged ACTIVE (with LOWER) starts in the working set: the same optimum, and
    the same iterations as daqp's package with that sense."""
    qp = random_qp(np.random.default_rng(12), 10, 10, 4)
    _, _, x, lam = kernel_solve(qp)
    sense = np.where(lam > 0, dk.ACTIVE, np.where(lam < 0, dk.ACTIVE | dk.LOWER, 0))
    warm = {**qp, "sense": sense.astype(np.int32)}
    flag, it, x_warm, _ = kernel_solve(warm)
    ref_flag, ref_it, _, _ = python_solve(warm)
    assert flag == ref_flag == dk.OPTIMAL and it == ref_it
    np.testing.assert_allclose(x_warm, x, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(warm["sense"], sense)  # daqp does not write it


def test_settings_reach_daqp() -> None:
    """The settings struct as daqp fills it matches daqp's own defaults (the layout), and
    the ten settings the project uses, all changed, give daqp.solve's answer."""
    assert dk.default_settings() == pytest.approx(daqp.Model().settings)
    values = {
        "primal_tol": 1e-8,
        "dual_tol": 1e-11,
        "zero_tol": 1e-12,
        "pivot_tol": 1e-7,
        "progress_tol": 1e-13,
        "cycle_tol": 20,
        "iter_limit": 500,
        "eps_prox": 0.0,
        "eta_prox": 1e-7,
        "rho_soft": 1e-5,
    }
    out = np.empty(dk.N_SETTINGS)
    dk.read_settings(dk.settings(**values), out)
    assert dict(zip(dk.SETTING_NAMES, out, strict=True)) == pytest.approx(
        {**daqp.Model().settings, **values}
    )
    qp = random_qp(np.random.default_rng(13), 20, 20, 8, n_inf=3)
    flag, it, x, _ = kernel_solve(qp, **values)
    ref_flag, ref_it, ref_x, _ = python_solve(qp, **values)
    assert flag == ref_flag == dk.OPTIMAL and it == ref_it
    np.testing.assert_allclose(x, ref_x, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="unknown"):
        dk.settings(primal_tolerance=1e-9)


def test_bad_input() -> None:
    """Wrong shapes or a non-contiguous matrix: BAD_INPUT, daqp not called, x NaN."""
    qp = random_qp(np.random.default_rng(14), 5, 5, 3)
    n, m = 5, 8
    x = np.empty(n)
    s = dk.settings()
    args = (qp["H"], qp["f"], qp["A"], qp["bupper"], qp["blower"], qp["sense"], s)
    assert dk.solve(*args, x, np.empty(m + 1))[0] == dk.BAD_INPUT
    assert np.all(np.isnan(x))
    strided = np.empty((3, 2 * n))[:, ::2]
    strided[:] = qp["A"]
    assert dk.solve(*args[:2], strided, *args[3:], x, np.empty(m))[0] == dk.BAD_INPUT


@numba.njit
def _batch(H, f, A, bu, bl, sense, settings, x, lam, flags):
    """A test kernel: QP k of the batch (arrays stacked on the first axis) solved from
    compiled code."""
    for k in range(H.shape[0]):
        flags[k] = dk.solve(H[k], f[k], A[k], bu[k], bl[k], sense[k], settings, x[k], lam[k])[0]


def test_called_from_a_kernel() -> None:
    """The same QPs solved from inside compiled code give daqp.solve's answers."""
    rng = np.random.default_rng(15)
    qps = [random_qp(rng, 23, 23, 10, n_inf=4, n_eq=k % 3) for k in range(6)]
    qps.append(random_qp(rng, 23, 23, 10))
    qps[-1]["blower"][0], qps[-1]["bupper"][0] = 1.0, -1.0  # crossed: infeasible
    stack = {k: np.stack([qp[k] for qp in qps]) for k in qps[0]}
    x, lam, flags = np.empty((7, 23)), np.empty((7, 33)), np.empty(7, np.int64)
    _batch(
        stack["H"],
        stack["f"],
        stack["A"],
        stack["bupper"],
        stack["blower"],
        stack["sense"],
        dk.settings(**SETTINGS),
        x,
        lam,
        flags,
    )
    for k, qp in enumerate(qps):
        ref_flag, _, ref_x, ref_lam = python_solve(qp)
        assert flags[k] == ref_flag
        if ref_flag == dk.OPTIMAL:
            np.testing.assert_allclose(x[k], ref_x, rtol=0, atol=1e-12)
            np.testing.assert_allclose(lam[k], ref_lam, rtol=0, atol=1e-12)
            assert_kkt(qp, x[k], lam[k])
    assert flags[-1] == dk.INFEASIBLE


def test_version_guard(monkeypatch: pytest.MonkeyPatch) -> None:
    """Another daqp than 0.11 is refused with a message that says which to install."""
    monkeypatch.setattr(dk.importlib.metadata, "version", lambda name: "0.12.1")
    with pytest.raises(ImportError, match=r"daqp 0\.12\.1 is installed.*daqp>=0\.11,<0\.12"):
        dk._check_version()


@pytest.mark.skipif(DISABLED, reason="caching concerns compiled kernels")
@pytest.mark.slow
def test_cached_without_warnings() -> None:
    """A fresh process compiles solve into the cache with no numba warning (a kernel holding
    a ctypes pointer would say "Cannot cache"), and the next process loads it from there."""
    code = (
        "import numpy as np; from wholebody.kernels import daqp as dk; "
        "print(dk.solve(np.eye(2), np.ones(2), np.zeros((0, 2)), np.zeros(2), -np.ones(2), "
        "np.zeros(2, np.int32), dk.settings(), np.empty(2), np.empty(2)))"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = {
            **os.environ,
            "NUMBA_CACHE_DIR": cache,
            "PYTHONPATH": str(Path(dk.__file__).parents[2]),
        }
        for _ in range(2):
            out = subprocess.run(
                [sys.executable, "-W", "error::numba.NumbaWarning", "-c", code],
                capture_output=True,
                text=True,
                env=env,
                check=False,
            )
            assert out.returncode == 0, out.stderr
            assert out.stdout.strip() == "(1, 1)" and "Cannot cache" not in out.stderr
        assert list(Path(cache).rglob("daqp.solve-*.nbc")), "solve was not cached"
