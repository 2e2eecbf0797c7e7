"""daqp inside kernels: one dense strictly convex QP solved by daqp's C entry point.

The problem, in daqp's own convention::

    minimise    1/2 x'H x + f'x
    subject to  blower <= [x[:ms]; A x] <= bupper

``H`` (n x n, symmetric positive definite), ``f`` (n), ``A`` ((m - ms) x n): the first
``ms`` bounds are simple bounds on ``x[0], ..., x[ms-1]``, the others bound the rows of
``A``. A bound at or beyond ``INF`` (``1e30``, or ``inf``) is absent.

:func:`solve` builds daqp's ``DAQPProblem``, ``DAQPSettings`` and ``DAQPResult`` structs in
small numpy buffers and calls ``daqp_quadprog`` (setup, solve and free, all in C: nothing
is kept between calls), from the very library that daqp's Python package loads, so a kernel
and ``daqp.solve`` give the same answer bit for bit. Compiled, the C functions are called as
external functions whose addresses are registered with LLVM under ``wholebody_daqp_*``
names (the cached machine code refers to them by name, as :mod:`wholebody.kernels.lapack`
does); uncompiled (``NUMBA_DISABLE_JIT=1``) the same calls go through ``ctypes``.

The struct layouts are those of daqp 0.11 (x86-64 / LP64: ``int`` 4 bytes, pointers and
``double`` 8, natural alignment); importing this module with another daqp raises
:class:`ImportError`. The offsets, in bytes:

``DAQPProblem`` (80 bytes)
    0 ``int n`` (variables), 4 ``int m`` (bounds in all), 8 ``int ms`` (simple bounds),
    16 ``double* H`` (n x n, row-major), 24 ``double* f``, 32 ``double* A`` ((m - ms) x n,
    row-major), 40 ``double* bupper`` (m), 48 ``double* blower`` (m), 56 ``int* sense``
    (m), 64 ``int* break_points`` (hierarchical QPs; NULL), 72 ``int nh`` (levels; 0),
    76 ``int problem_type`` (1: variational inequality; 0: QP).
``DAQPSettings`` (136 bytes)
    The fields of :data:`SETTING_NAMES` in that order, at :data:`_OFFSET`: doubles but for
    the ``int`` fields ``cycle_tol``, ``iter_limit``, ``eq_reduction`` and ``presolve``.
``DAQPResult`` (64 bytes)
    0 ``double* x`` (n, written by daqp), 8 ``double* lam`` (m, written by daqp), 16
    ``double fval``, 24 ``double soft_slack`` (largest violation of a soft bound), 32 ``int
    exitflag``, 36 ``int iter``, 40 ``int nodes``, 48 ``double solve_time`` (s), 56 ``double
    setup_time`` (s).

``sense`` (int32, one per bound) holds the flags below, or-ed. Supported here: 0 (an
inequality), ``ACTIVE`` (start with the bound in the working set; with ``LOWER`` its lower
side, else its upper), ``EQUALITY`` (``ACTIVE | IMMUTABLE``, with ``blower == bupper``: the
bound holds with equality and never leaves the working set) and ``SOFT`` (the bound may be
violated at the price ``s^2 / (2 rho_soft)`` for a violation ``s``; ``w_soft`` adds a linear
``w_soft s``). daqp does not write ``sense`` in this mode; its binary flag (16, mixed-integer
problems) and hierarchical mode are not offered here.

The multipliers ``lam`` (m) are daqp's: ``H x + f + [I_ms 0; A]' lam = 0`` at the solution,
``lam_i > 0`` where the upper bound ``i`` is active, ``< 0`` where the lower one is, 0 where
neither is.
"""

from __future__ import annotations

import ctypes
import importlib.metadata
import importlib.util

import llvmlite.binding as llvm
import numpy as np
from numba import types

from wholebody.kernels import DISABLED, kernel

__all__ = [
    "ACTIVE",
    "BAD_INPUT",
    "CYCLE",
    "EQUALITY",
    "IMMUTABLE",
    "INF",
    "INFEASIBLE",
    "ITERLIMIT",
    "LOWER",
    "N_SETTINGS",
    "OPTIMAL",
    "OPTIMAL_INEXACT",
    "SETTING_NAMES",
    "SOFT",
    "SOFT_OPTIMAL",
    "TIMELIMIT",
    "default_settings",
    "read_settings",
    "settings",
    "solve",
]


def _check_version() -> str:
    """The path of daqp's extension module, after checking that it is daqp 0.11 (the
    struct layouts above are that version's)."""
    try:
        version = importlib.metadata.version("daqp")
    except importlib.metadata.PackageNotFoundError:
        raise ImportError("wholebody.kernels.daqp needs the daqp package (0.11)") from None
    if tuple(int(p) for p in version.split(".")[:2] if p.isdigit()) != (0, 11):
        raise ImportError(
            f"wholebody.kernels.daqp is written for daqp 0.11 (its C struct layouts); daqp "
            f"{version} is installed: pip install 'daqp>=0.11,<0.12'"
        )
    spec = importlib.util.find_spec("daqp")
    if spec is None or spec.origin is None:
        raise ImportError("wholebody.kernels.daqp: daqp's extension module was not found")
    return spec.origin


_LIB = ctypes.CDLL(_check_version())


def external_function(name: str, restype: types.Type, *args: types.Type):
    """daqp's C function ``name`` as a callable: an external function registered under
    ``wholebody_<name>`` when compiled, its ctypes twin when not (``uintp`` is a pointer)."""
    address = ctypes.cast(getattr(_LIB, name), ctypes.c_void_p).value
    if DISABLED:
        c = {types.uintp: ctypes.c_void_p, types.int32: ctypes.c_int, types.void: None}
        return ctypes.CFUNCTYPE(c[restype], *(c[a] for a in args))(address)
    symbol = f"wholebody_{name}"
    llvm.add_symbol(symbol, address)
    return types.ExternalFunction(symbol, restype(*args))


_P = types.uintp
# void daqp_quadprog(DAQPResult* res, DAQPProblem* qp, DAQPSettings* settings)
_quadprog = external_function("daqp_quadprog", types.void, _P, _P, _P)
# void daqp_default_settings(DAQPSettings* settings)
_default_settings = external_function("daqp_default_settings", types.void, _P)

# ------------------------------------------------------------------ constants.h, daqp 0.11
INF = 1e30  # DAQP_INF: a bound at or beyond it is absent

# sense flags
ACTIVE = 1  # DAQP_ACTIVE: in the (initial) working set
LOWER = 2  # DAQP_LOWER: ... at its lower side
IMMUTABLE = 4  # DAQP_IMMUTABLE: never leaves (or enters) the working set
SOFT = 8  # DAQP_SOFT: may be violated, at a price (rho_soft, w_soft)
EQUALITY = ACTIVE | IMMUTABLE  # an equality: blower == bupper, always active

# exit flags (daqp's, and one of this module)
OPTIMAL_INEXACT = 4  # optimal, found with rounding-level tolerances; a bound violated > primal_tol
SOFT_OPTIMAL = 2  # optimal, with soft bounds violated
OPTIMAL = 1  # optimal
INFEASIBLE = -1  # the hard bounds are inconsistent
CYCLE = -2  # the working set cycled
UNBOUNDED = -3  # unbounded below (H not positive definite)
ITERLIMIT = -4  # iter_limit reached; x is daqp's last iterate
NONCONVEX = -5  # H is not positive (semi)definite
OVERDETERMINED_INITIAL = -6  # the initial working set (sense) has more rows than variables
TIMELIMIT = -7  # time_limit (s) reached
# (daqp's 3 and 5 concern hierarchical and mixed-integer problems, -8 problems it does not
# support: none arise here)
BAD_INPUT = -100  # (this module) shapes or strides wrong: daqp was not called

# ------------------------------------------------------------------ settings
SETTING_NAMES = (
    "primal_tol",
    "dual_tol",
    "zero_tol",
    "pivot_tol",
    "progress_tol",
    "cycle_tol",
    "iter_limit",
    "fval_bound",
    "eps_prox",
    "eta_prox",
    "rho_soft",
    "rel_subopt",
    "abs_subopt",
    "sing_tol",
    "refactor_tol",
    "time_limit",
    "w_soft",
    "eq_reduction",
    "presolve",
)
"""The fields of ``DAQPSettings``, in struct order: the entries of a settings array."""
N_SETTINGS = len(SETTING_NAMES)
PRIMAL_TOL, DUAL_TOL, ZERO_TOL, PIVOT_TOL, PROGRESS_TOL, CYCLE_TOL, ITER_LIMIT = range(7)
FVAL_BOUND, EPS_PROX, ETA_PROX, RHO_SOFT, REL_SUBOPT, ABS_SUBOPT, SING_TOL = range(7, 14)
REFACTOR_TOL, TIME_LIMIT, W_SOFT, EQ_REDUCTION, PRESOLVE = range(14, 19)
_OFFSET = np.array([0, 8, 16, 24, 32, 40, 44, 48, 56, 64, 72, 80, 88, 96, 104, 112, 120, 128, 132])
_IS_INT = np.array(
    [k in (CYCLE_TOL, ITER_LIMIT, EQ_REDUCTION, PRESOLVE) for k in range(N_SETTINGS)]
)
_WORDS_PROBLEM, _WORDS_SETTINGS, _WORDS_RESULT = 10, 17, 8  # struct sizes / 8


def settings(**values: float) -> np.ndarray:
    """A settings array (float64, :data:`N_SETTINGS`) for :func:`solve`: the given
    ``DAQPSettings`` fields (names of :data:`SETTING_NAMES`, e.g. ``primal_tol=1e-9,
    iter_limit=2000``), NaN for the others, which keep daqp's defaults."""
    unknown = sorted(set(values) - set(SETTING_NAMES))
    if unknown:
        raise ValueError(
            f"daqp settings: unknown {', '.join(unknown)}; known: {', '.join(SETTING_NAMES)}"
        )
    out = np.full(N_SETTINGS, np.nan)
    for name, value in values.items():
        out[SETTING_NAMES.index(name)] = value
    return out


@kernel
def fill_settings(buf: np.ndarray, values: np.ndarray) -> None:
    """daqp's default settings into the struct ``buf``, then the non-NaN ``values``."""
    _default_settings(buf.ctypes.data)
    d, i = buf.view(np.float64), buf.view(np.int32)
    for k in range(N_SETTINGS):
        v = values[k]
        if v == v:  # not NaN
            if _IS_INT[k]:
                i[_OFFSET[k] // 4] = np.int32(v)
            else:
                d[_OFFSET[k] // 8] = v


@kernel
def read_settings(values: np.ndarray, out: np.ndarray) -> None:
    """The settings :func:`solve` hands daqp for the settings array ``values``: daqp's
    defaults (``daqp_default_settings``) with ``values`` applied, read back from the struct
    into ``out`` (N_SETTINGS)."""
    buf = np.zeros(_WORDS_SETTINGS, np.int64)
    fill_settings(buf, values)
    d, i = buf.view(np.float64), buf.view(np.int32)
    for k in range(N_SETTINGS):
        out[k] = i[_OFFSET[k] // 4] if _IS_INT[k] else d[_OFFSET[k] // 8]


def default_settings() -> dict[str, float]:
    """daqp's default settings, by name (see :func:`read_settings`)."""
    out = np.empty(N_SETTINGS)
    read_settings(settings(), out)
    return dict(zip(SETTING_NAMES, out.tolist(), strict=True))


@kernel
def _shapes_ok(
    H: np.ndarray,
    f: np.ndarray,
    A: np.ndarray,
    bu: np.ndarray,
    bl: np.ndarray,
    sense: np.ndarray,
    values: np.ndarray,
    x: np.ndarray,
    lam: np.ndarray,
) -> bool:
    """Whether the arrays have :func:`solve`'s shapes and are contiguous (C order)."""
    n, m, rows = f.shape[0], bu.shape[0], A.shape[0]
    ok = H.shape[0] == n and H.shape[1] == n and A.shape[1] == n and x.shape[0] == n
    ok = ok and rows <= m and bl.shape[0] == m and sense.shape[0] == m and lam.shape[0] == m
    ok = ok and values.shape[0] == N_SETTINGS
    if n:
        ok = ok and H.strides[0] == 8 * n and H.strides[1] == 8
        ok = ok and f.strides[0] == 8 and x.strides[0] == 8
    if rows:
        ok = ok and A.strides[0] == 8 * n and A.strides[1] == 8
    if m:
        ok = ok and bu.strides[0] == 8 and bl.strides[0] == 8 and lam.strides[0] == 8
        ok = ok and sense.strides[0] == 4
    return ok


@kernel
def solve(
    H: np.ndarray,
    f: np.ndarray,
    A: np.ndarray,
    bupper: np.ndarray,
    blower: np.ndarray,
    sense: np.ndarray,
    settings: np.ndarray,
    x: np.ndarray,
    lam: np.ndarray,
) -> tuple[int, int]:
    """Solve the QP of the module docstring with ``daqp_quadprog``: ``(exitflag, iterations)``.

    ``H`` (n x n), ``f`` (n), ``A`` ((m - ms) x n; ms = m - A.shape[0]), ``bupper``,
    ``blower`` (m), ``sense`` (int32, m; read only), ``settings`` (:func:`settings`) are read;
    the solution goes into ``x`` (n) and the multipliers into ``lam`` (m). All contiguous,
    float64 but ``sense``. ``x`` holds the solution for a positive exit flag and daqp's last
    iterate for ``ITERLIMIT``; ``lam`` is written for a positive exit flag only. Both are NaN
    where daqp wrote nothing (a failed setup, or ``BAD_INPUT``: wrong shapes or strides)."""
    x[:] = np.nan
    lam[:] = np.nan
    if not _shapes_ok(H, f, A, bupper, blower, sense, settings, x, lam):
        return BAD_INPUT, 0
    qp = np.zeros(_WORDS_PROBLEM, np.int64)
    qi = qp.view(np.int32)
    qi[0] = f.shape[0]
    qi[1] = bupper.shape[0]
    qi[2] = bupper.shape[0] - A.shape[0]
    qp[2] = H.ctypes.data
    qp[3] = f.ctypes.data
    qp[4] = A.ctypes.data
    qp[5] = bupper.ctypes.data
    qp[6] = blower.ctypes.data
    qp[7] = sense.ctypes.data  # (break_points NULL, nh 0, problem_type 0: a QP)
    st = np.zeros(_WORDS_SETTINGS, np.int64)
    fill_settings(st, settings)
    res = np.zeros(_WORDS_RESULT, np.int64)
    res[0] = x.ctypes.data
    res[1] = lam.ctypes.data
    _quadprog(res.ctypes.data, qp.ctypes.data, st.ctypes.data)
    ri = res.view(np.int32)
    return int(ri[8]), int(ri[9])
