"""LAPACK inside kernels: the routines of ``scipy.linalg.cython_lapack``.

These are the same LAPACK routines, from the same library, that the reference
implementation calls through ``scipy.linalg.lapack``, with the same workspace sizes (a
workspace size can choose between LAPACK's blocked and unblocked code), so a kernel and the
reference make the same rank and pivot decisions. Compiled, a kernel calls them as external
C functions (their addresses are registered with LLVM under ``wholebody_d*`` names, so the
cached machine code refers to them by name); uncompiled (``NUMBA_DISABLE_JIT=1``) the same
calls go through ``ctypes``.

Matrices are **Fortran-ordered** (column-major) arrays, as LAPACK reads them: in a kernel,
``np.empty((n, m)).T`` is an m x n Fortran-ordered array, and a C-ordered (m, n) array is the
Fortran-ordered n x m transpose of itself. Every function returns LAPACK's ``info`` (0 on
success) and works in place.
"""

from __future__ import annotations

import ctypes

import llvmlite.binding as llvm
import numpy as np
from numba import types
from numba.extending import get_cython_function_address

from wholebody.kernels import DISABLED, kernel

__all__ = [
    "gels",
    "geqp3",
    "geqrf",
    "gesdd",
    "getrf",
    "getrs",
    "orgqr",
    "potrf",
    "syevd",
    "trtri",
    "trtrs",
    "trtrs_rows",
]

_ARGS = {
    "dpotrf": 5,
    "dtrtri": 6,
    "dtrtrs": 10,
    "dgeqp3": 9,
    "dgeqrf": 8,
    "dorgqr": 9,
    "dgels": 11,
    "dgesdd": 14,
    "dsyevd": 11,
    "dgetrf": 6,
    "dgetrs": 9,
}


def _external(name: str):
    """The LAPACK routine ``name`` as a callable taking pointers (integers)."""
    address = get_cython_function_address("scipy.linalg.cython_lapack", name)
    n = _ARGS[name]
    if DISABLED:
        return ctypes.CFUNCTYPE(None, *([ctypes.c_void_p] * n))(address)
    symbol = f"wholebody_{name}"
    llvm.add_symbol(symbol, address)
    return types.ExternalFunction(symbol, types.void(*([types.uintp] * n)))


_dpotrf = _external("dpotrf")
_dtrtri = _external("dtrtri")
_dtrtrs = _external("dtrtrs")
_dgeqp3 = _external("dgeqp3")
_dgeqrf = _external("dgeqrf")
_dorgqr = _external("dorgqr")
_dgels = _external("dgels")
_dgesdd = _external("dgesdd")
_dsyevd = _external("dsyevd")
_dgetrf = _external("dgetrf")
_dgetrs = _external("dgetrs")

_L, _U, _N, _T, _A, _S, _V = 76, 85, 78, 84, 65, 83, 86  # ord("L"), ord("U"), ...


@kernel
def potrf(a: np.ndarray, lower: bool) -> int:
    """Cholesky factor of the symmetric positive definite ``a`` (n x n, Fortran), in the
    triangle ``lower`` (``a = L L^T``) or upper (``a = U^T U``); the other triangle is zeroed."""
    n = a.shape[0]
    ch = np.empty(1, np.uint8)
    ch[0] = _L if lower else _U
    iv = np.empty(3, np.int32)
    iv[0] = n
    iv[1] = max(n, 1)
    iv[2] = 0
    _dpotrf(
        ch.ctypes.data, iv[0:].ctypes.data, a.ctypes.data, iv[1:].ctypes.data, iv[2:].ctypes.data
    )
    for j in range(n):
        for i in range(n):
            if (lower and i < j) or (not lower and i > j):
                a[i, j] = 0.0
    return int(iv[2])


@kernel
def trtri(a: np.ndarray, lower: bool) -> int:
    """Inverse of the triangular ``a`` (n x n, Fortran; non-unit diagonal), in place."""
    n = a.shape[0]
    ch = np.empty(2, np.uint8)
    ch[0] = _L if lower else _U
    ch[1] = _N
    iv = np.empty(3, np.int32)
    iv[0] = n
    iv[1] = max(n, 1)
    iv[2] = 0
    _dtrtri(
        ch[0:].ctypes.data,
        ch[1:].ctypes.data,
        iv[0:].ctypes.data,
        a.ctypes.data,
        iv[1:].ctypes.data,
        iv[2:].ctypes.data,
    )
    return int(iv[2])


@kernel
def trtrs(a: np.ndarray, b: np.ndarray, lower: bool, transpose: bool) -> int:
    """Solve ``op(a) x = b`` for the triangular ``a`` (n x n: a Fortran array or a block of
    one, column stride ``lda``), ``op`` the transpose if ``transpose``; ``b`` (n,) is
    overwritten with ``x``."""
    return _trtrs(a, b, b.shape[0], 1, lower, transpose)


@kernel
def trtrs_rows(a: np.ndarray, B: np.ndarray, lower: bool, transpose: bool) -> int:
    """Solve ``op(a) x = b`` for every row ``b`` of the C-ordered ``B`` (m, n) at once (one
    LAPACK call with ``m`` right-hand sides: ``B``'s memory is the Fortran n x m ``B^T``),
    each row overwritten with its ``x``; ``a`` as in :func:`trtrs`."""
    return _trtrs(a, B, B.shape[1], B.shape[0], lower, transpose)


@kernel
def _trtrs(a: np.ndarray, b: np.ndarray, n: int, nrhs: int, lower: bool, transpose: bool) -> int:
    """``dtrtrs`` on ``a`` for the ``nrhs`` right-hand sides of ``n`` entries stored one
    after the other from ``b``'s first entry."""
    ch = np.empty(3, np.uint8)
    ch[0] = _L if lower else _U
    ch[1] = _T if transpose else _N
    ch[2] = _N
    iv = np.empty(5, np.int32)
    iv[0] = n
    iv[1] = nrhs
    iv[2] = max(a.strides[1] // 8, 1)
    iv[3] = max(n, 1)
    iv[4] = 0
    _dtrtrs(
        ch[0:].ctypes.data,
        ch[1:].ctypes.data,
        ch[2:].ctypes.data,
        iv[0:].ctypes.data,
        iv[1:].ctypes.data,
        a.ctypes.data,
        iv[2:].ctypes.data,
        b.ctypes.data,
        iv[3:].ctypes.data,
        iv[4:].ctypes.data,
    )
    return int(iv[4])


@kernel
def geqp3(a: np.ndarray, jpvt: np.ndarray, tau: np.ndarray) -> int:
    """QR with column pivoting of ``a`` (m x n, Fortran) in place: ``a P = Q R``, the
    pivots (1-based, int32) in ``jpvt`` (every column free: it is zeroed first), the
    reflectors' factors in ``tau`` (min(m, n)). Workspace ``8 (n + 1)``, as the reference."""
    m, n = a.shape
    lwork = 8 * (n + 1)
    work = np.empty(lwork)
    jpvt[:] = 0
    iv = np.empty(5, np.int32)
    iv[0] = m
    iv[1] = n
    iv[2] = max(m, 1)
    iv[3] = lwork
    iv[4] = 0
    _dgeqp3(
        iv[0:].ctypes.data,
        iv[1:].ctypes.data,
        a.ctypes.data,
        iv[2:].ctypes.data,
        jpvt.ctypes.data,
        tau.ctypes.data,
        work.ctypes.data,
        iv[3:].ctypes.data,
        iv[4:].ctypes.data,
    )
    return int(iv[4])


@kernel
def geqrf(a: np.ndarray, tau: np.ndarray) -> int:
    """QR factorisation ``a = Q R`` of ``a`` (m x n, Fortran) in place, the reflectors'
    factors in ``tau`` (min(m, n)); workspace ``max(3 n, 1)``."""
    m, n = a.shape
    lwork = max(3 * n, 1)
    work = np.empty(lwork)
    iv = np.empty(5, np.int32)
    iv[0] = m
    iv[1] = n
    iv[2] = max(m, 1)
    iv[3] = lwork
    iv[4] = 0
    _dgeqrf(
        iv[0:].ctypes.data,
        iv[1:].ctypes.data,
        a.ctypes.data,
        iv[2:].ctypes.data,
        tau.ctypes.data,
        work.ctypes.data,
        iv[3:].ctypes.data,
        iv[4:].ctypes.data,
    )
    return int(iv[4])


@kernel
def orgqr(a: np.ndarray, tau: np.ndarray, k: int, lwork: int) -> int:
    """The m x n matrix Q with orthonormal columns from the first ``k`` reflectors of a QR
    factorisation stored in ``a`` (m x n, Fortran), in place; workspace ``lwork``."""
    m, n = a.shape
    lwork = max(lwork, max(n, 1))
    work = np.empty(lwork)
    iv = np.empty(6, np.int32)
    iv[0] = m
    iv[1] = n
    iv[2] = k
    iv[3] = max(m, 1)
    iv[4] = lwork
    iv[5] = 0
    _dorgqr(
        iv[0:].ctypes.data,
        iv[1:].ctypes.data,
        iv[2:].ctypes.data,
        a.ctypes.data,
        iv[3:].ctypes.data,
        tau.ctypes.data,
        work.ctypes.data,
        iv[4:].ctypes.data,
        iv[5:].ctypes.data,
    )
    return int(iv[5])


@kernel
def gels(a: np.ndarray, b: np.ndarray) -> int:
    """Least squares ``min ||a x - b||`` for a full-rank ``a`` (m x n, Fortran) by its QR
    factorisation (overwritten into ``a``); ``b`` (max(m, n),) is overwritten, its first n
    entries with ``x``. Workspace ``max(min(m, n) + max(min(m, n), 1), 1)``, as the
    reference."""
    m, n = a.shape
    mn = min(m, n)
    lwork = max(mn + max(mn, 1), 1)
    work = np.empty(lwork)
    ch = np.empty(1, np.uint8)
    ch[0] = _N
    iv = np.empty(7, np.int32)
    iv[0] = m
    iv[1] = n
    iv[2] = 1
    iv[3] = max(m, 1)
    iv[4] = max(b.shape[0], 1)
    iv[5] = lwork
    iv[6] = 0
    _dgels(
        ch.ctypes.data,
        iv[0:].ctypes.data,
        iv[1:].ctypes.data,
        iv[2:].ctypes.data,
        a.ctypes.data,
        iv[3:].ctypes.data,
        b.ctypes.data,
        iv[4:].ctypes.data,
        work.ctypes.data,
        iv[5:].ctypes.data,
        iv[6:].ctypes.data,
    )
    return int(iv[6])


@kernel
def gesdd(a: np.ndarray, full: bool) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """The singular value decomposition ``a = U diag(s) V^T`` of ``a`` (m x n, Fortran; it is
    destroyed) by divide and conquer, as ``numpy.linalg.svd``: ``(info, U, s, Vt)``, U and
    Vt Fortran-ordered, m x m and n x n when ``full`` else m x k and k x n (k = min(m, n))."""
    m, n = a.shape
    k = min(m, n)
    mu, nv = (m, n) if full else (k, k)
    U = np.zeros((mu, m)).T
    Vt = np.zeros((n, nv)).T
    s = np.zeros(max(k, 1))
    lwork = 4 * k * k + 7 * k + max(m, n) + 1
    work = np.empty(lwork)
    iwork = np.empty(max(8 * k, 1), np.int32)
    ch = np.empty(1, np.uint8)
    ch[0] = _A if full else _S
    iv = np.empty(7, np.int32)
    iv[0] = m
    iv[1] = n
    iv[2] = max(m, 1)
    iv[3] = max(m, 1)
    iv[4] = max(nv, 1)
    iv[5] = lwork
    iv[6] = 0
    if k:
        _dgesdd(
            ch.ctypes.data,
            iv[0:].ctypes.data,
            iv[1:].ctypes.data,
            a.ctypes.data,
            iv[2:].ctypes.data,
            s.ctypes.data,
            U.ctypes.data,
            iv[3:].ctypes.data,
            Vt.ctypes.data,
            iv[4:].ctypes.data,
            work.ctypes.data,
            iv[5:].ctypes.data,
            iwork.ctypes.data,
            iv[6:].ctypes.data,
        )
    else:  # nothing to decompose: identities of the requested shapes
        for j in range(min(mu, m)):
            U[j, j] = 1.0
        for j in range(min(nv, n)):
            Vt[j, j] = 1.0
    return int(iv[6]), U, s[:k], Vt


@kernel
def syevd(a: np.ndarray) -> tuple[int, np.ndarray]:
    """Eigen-decomposition of the symmetric ``a`` (n x n, Fortran; its lower triangle is read
    and it is overwritten with the eigenvectors, in columns) by divide and conquer, as
    ``numpy.linalg.eigh``: ``(info, w)``, the eigenvalues ascending."""
    n = a.shape[0]
    w = np.zeros(max(n, 1))
    lwork = 1 + 6 * n + 2 * n * n
    liwork = 3 + 5 * n
    work = np.empty(lwork)
    iwork = np.empty(liwork, np.int32)
    ch = np.empty(2, np.uint8)
    ch[0] = _V
    ch[1] = _L
    iv = np.empty(5, np.int32)
    iv[0] = n
    iv[1] = max(n, 1)
    iv[2] = lwork
    iv[3] = liwork
    iv[4] = 0
    if n:
        _dsyevd(
            ch[0:].ctypes.data,
            ch[1:].ctypes.data,
            iv[0:].ctypes.data,
            a.ctypes.data,
            iv[1:].ctypes.data,
            w.ctypes.data,
            work.ctypes.data,
            iv[2:].ctypes.data,
            iwork.ctypes.data,
            iv[3:].ctypes.data,
            iv[4:].ctypes.data,
        )
    return int(iv[4]), w[:n]


@kernel
def getrf(a: np.ndarray, ipiv: np.ndarray) -> int:
    """LU factorisation with partial pivoting ``P a = L U`` of ``a`` (n x n, Fortran) in
    place, the pivots (1-based, int32) in ``ipiv`` (n)."""
    n = a.shape[0]
    iv = np.empty(3, np.int32)
    iv[0] = n
    iv[1] = max(n, 1)
    iv[2] = 0
    _dgetrf(
        iv[0:].ctypes.data,
        iv[0:].ctypes.data,
        a.ctypes.data,
        iv[1:].ctypes.data,
        ipiv.ctypes.data,
        iv[2:].ctypes.data,
    )
    return int(iv[2])


@kernel
def getrs(lu: np.ndarray, ipiv: np.ndarray, b: np.ndarray) -> int:
    """Solve ``a x = b`` from :func:`getrf`'s factorisation of ``a``; ``b`` (n x k, Fortran)
    is overwritten with ``x``."""
    n, k = b.shape
    ch = np.empty(1, np.uint8)
    ch[0] = _N
    iv = np.empty(5, np.int32)
    iv[0] = n
    iv[1] = k
    iv[2] = max(n, 1)
    iv[3] = max(n, 1)
    iv[4] = 0
    _dgetrs(
        ch.ctypes.data,
        iv[0:].ctypes.data,
        iv[1:].ctypes.data,
        lu.ctypes.data,
        iv[2:].ctypes.data,
        ipiv.ctypes.data,
        b.ctypes.data,
        iv[3:].ctypes.data,
        iv[4:].ctypes.data,
    )
    return int(iv[4])
