"""The kernels' building blocks against independent references: LAPACK through the kernels
against scipy's wrappers, SO(3) against Pinocchio, frame kinematics against Pinocchio's
frame Jacobians."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg.lapack as scipy_lapack

import wholebody.kernels as kernels
from wholebody.kernels import lapack, linalg
from wholebody.kernels.kinematics import frame_kinematics, joint_positions
from wholebody.kernels.so3 import jlog3, log3


def test_lapack_routines_give_scipys_answers_bit_for_bit(rng):
    M = rng.normal(size=(12, 23))
    qr, jp, tau, _, _ = scipy_lapack.dgeqp3(M.T, lwork=8 * 13)
    a = M.copy().T  # Fortran-ordered M^T
    jpvt, tau_k = np.zeros(12, np.int32), np.zeros(12)
    assert lapack.geqp3(a, jpvt, tau_k) == 0
    np.testing.assert_array_equal(a, qr)
    np.testing.assert_array_equal(jpvt, jp)
    G = M @ M.T
    L, _ = scipy_lapack.dpotrf(G, lower=1, clean=1)
    a = np.asfortranarray(G)
    assert lapack.potrf(a, True) == 0
    np.testing.assert_array_equal(a, L)
    Li, _ = scipy_lapack.dtrtri(L, lower=1)
    assert lapack.trtri(a, True) == 0
    np.testing.assert_array_equal(a, Li)
    full = np.zeros((23, 23), order="F")
    full[:, :12] = qr
    Q, _, _ = scipy_lapack.dorgqr(full.copy(order="F"), tau, lwork=8 * 23)
    assert lapack.orgqr(full, tau, 12, 8 * 23) == 0
    np.testing.assert_array_equal(full, Q)
    c = rng.normal(size=12)
    z, _ = scipy_lapack.dtrtrs(qr[:12, :12], c, lower=0, trans=1)
    b = c.copy()
    assert lapack.trtrs(np.asfortranarray(qr)[:12, :12], b, False, True) == 0
    np.testing.assert_array_equal(b, z)
    T, y = rng.normal(size=(30, 8)), rng.normal(size=30)
    _, x, _ = scipy_lapack.dgels(T, y)
    a, b = np.asfortranarray(T), y.copy()
    assert lapack.gels(a, b) == 0
    np.testing.assert_array_equal(b[:8], x[:8])
    # a singular factorisation is reported, not hidden
    assert lapack.potrf(np.asfortranarray(np.zeros((3, 3))), True) != 0


@pytest.mark.parametrize("n", [1, 5, 12, 23])
def test_cholesky_inverse_is_the_inverse_of_numpys_factor(rng, n):
    M = rng.normal(size=(n, n + 4)) * np.logspace(0, -3, n + 4)  # kappa(G) ~ 1e4 and more
    G = M @ M.T
    ok, Linv = linalg.cholesky_inverse(G)
    L = np.linalg.cholesky(G)
    assert ok and Linv.flags.f_contiguous and np.array_equal(Linv, np.tril(Linv))
    assert np.abs(Linv @ L - np.eye(n)).max() <= 1e-12 * np.linalg.cond(L)
    nan = G.copy()
    nan[n - 1, n - 1] = np.nan
    singular = np.ones((n, n)) if n > 1 else np.zeros((1, 1))  # a pivot exactly 0
    for H in (singular, -G, nan):  # a pivot not above 0 is reported, not hidden
        assert not linalg.cholesky_inverse(H)[0]


def test_products_are_numpys_and_grams_the_products_sums(rng):
    # the same sums in the same order: Gram matrices exactly the general products'
    for m, p in ((12, 23), (23, 11), (3, 1), (5, 0)):
        M, x = rng.normal(size=(m, p)), rng.normal(size=p)
        np.testing.assert_allclose(linalg.mv(M, x), M @ x, rtol=0, atol=1e-13 * (1 + p))
        np.testing.assert_array_equal(linalg.gram_rows(M), linalg.mmt(M, M))
        np.testing.assert_array_equal(linalg.gram_cols(M), linalg.mtm(M, M))
        np.testing.assert_allclose(linalg.gram_rows(M), M @ M.T, atol=1e-13 * (1 + p))


@pytest.mark.parametrize("kind", ["generic", "small", "near_pi", "zero", "pi", "perturbed"])
def test_log3_and_jlog3_are_pinocchios(rng, kind):
    worst = 0.0
    for _ in range(200):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = {
            "generic": rng.uniform(0, np.pi),
            "small": rng.uniform(0, 1e-5),
            "near_pi": np.pi - rng.uniform(0, 1e-5),
            "zero": 0.0,
            "pi": np.pi,
            "perturbed": rng.uniform(0, np.pi),
        }[kind]
        R = pin.exp3(angle * axis)
        if kind == "perturbed":  # not quite orthonormal: both re-orthonormalise
            R = R + 1e-9 * rng.normal(size=(3, 3))
        w = np.empty(3)
        theta = log3(R, w)
        Jl = np.empty((3, 3))
        jlog3(theta, w, Jl)
        worst = max(worst, np.abs(w - pin.log3(R)).max(), np.abs(Jl - pin.Jlog3(R)).max())
    assert worst < 1e-12


@pytest.mark.parametrize("name", ["mobile_humanoid", "dual_arm_torso"])
def test_frame_kinematics_equal_pinocchios_frame_jacobians(name, humanoid, torso, rng):
    robot = humanoid if name == "mobile_humanoid" else torso
    kin = robot.kinematics
    assert kin.fast  # the views of Pinocchio's memory are used, their layout checked
    frames = [robot.frame(f.name) for f in robot.model.frames]
    index = np.array([f.index for f in frames])
    support = kin.support(frames)
    F = len(frames)
    J, p, R = np.zeros((F, 6, robot.nu)), np.zeros((F, 3)), np.zeros((F, 3, 3))
    jp = np.zeros(robot.nu)
    for _ in range(5):
        q = robot.random_configuration(rng)
        state = robot.update(q)
        Jd, oMf = kin.views()
        frame_kinematics(Jd, oMf, index, support, kin.act_k, kin.act_j, kin.act_a, J, p, R)
        joint_positions(q, kin.position_index, kin.position_pair, jp)
        for k, frame in enumerate(frames):
            np.testing.assert_allclose(J[k], state.jacobian(frame), rtol=0, atol=1e-14)
            np.testing.assert_allclose(p[k], state.position(frame), rtol=0, atol=1e-15)
            np.testing.assert_allclose(R[k], state.rotation(frame), rtol=0, atol=1e-15)
        np.testing.assert_allclose(jp, state.joint_positions(), rtol=0, atol=1e-15)


def test_the_cache_falls_back_to_the_user_directory_when_the_package_one_is_not_writable(
    tmp_path, monkeypatch
):
    """An installed package directory that cannot be written (a file where the cache
    directory would go: refused even for root) sends the cache to the next candidate."""
    import wholebody.kernels as kernels

    blocked = tmp_path / "site-packages"
    blocked.write_text("not a directory")
    user = tmp_path / "user-cache"
    monkeypatch.setattr(kernels, "_cache_bases", lambda py_file: [str(blocked / "sub"), str(user)])
    where = kernels.cache_directory()
    assert where is not None and where.is_dir()
    assert where.is_relative_to(user)
    monkeypatch.setattr(kernels, "_cache_bases", lambda py_file: [str(blocked / "sub")])
    assert kernels.cache_directory() is None  # nothing writable: compile in memory, no crash


STALE = """
import os, sys, numba, numpy as np
from wholebody.kernels import watch
cache = watch.pose_watch._cache
index = cache._cache_file._index_path
stale = index.replace("-" + cache._impl.locator.get_source_stamp()[:12], "")
assert stale != index
os.makedirs(os.path.dirname(stale), exist_ok=True)
with open(stale, "wb") as f:  # numba's index layout: its version, then (stamp, overloads)
    import pickle
    pickle.dump(numba.__version__, f)
    f.write(b"cwholebody.kernels.hqp_state\\nNoSuchType\\n.")  # a type since renamed
out = watch.pose_watch(np.zeros(60), np.zeros(1, np.int64), np.zeros(1, np.int64),
                       np.zeros(0, np.int64))
print(out)
"""


@pytest.mark.skipif(kernels.DISABLED, reason="uncompiled kernels have no cache")
def test_an_index_left_by_other_kernel_sources_is_never_opened(tmp_path):
    """numba unpickles a cache index before comparing its stamp: an index written for other
    sources that names a type since renamed raised AttributeError on the first call. The
    stamp is part of the entry's name, so such a file is never read."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-c", STALE], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "(False, False, 0.0)" in done.stdout
