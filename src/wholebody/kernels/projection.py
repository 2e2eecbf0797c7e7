"""The projection backend in kernels: damped pseudo-inverse, recursive null-space projection
and Saturation in the Null Space, on a compiled stack's arena.

The algorithm, its decisions and thresholds are those of the reference
:class:`wholebody.solvers.projection.ProjectionSolver` (read its module docstring for the
maths): the same certified Cholesky route, the same eigen-decomposition or SVD near
singularities, the same SNS iterations and task scaling. A level's state is ``(u, P, has_P,
free, saturated, scale)``: the solution so far, and the projector onto the directions left
free, ``P`` when ``has_P`` else the 0/1 diagonal ``diag(free)``. The free directions of an
SNS iteration are ``(base, mask, F, is_mask)``, the point that puts the saturated joints on
their bounds and the mask or projector of what still moves.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.lapack import geqrf, orgqr, potrf
from wholebody.kernels.layout import fmat, fvec, imat, ivec
from wholebody.kernels.linalg import (
    NORMAL_KAPPA,
    cholesky_inverse,
    frobenius2,
    level_report,
    normal_solve,
)

__all__ = ["PAR_WIDTH", "project"]

_INSIDE_TOL = 1e-10
_EPS = 2.220446049250313e-16
_FIXED = 1e-18  # F_jj at or below this: joint j does not move along the free directions
# par: the solver's settings
PAR_DAMPING, PAR_THRESHOLD, PAR_RANK, PAR_TOLERANCE, PAR_SATURATE = 0, 1, 2, 3, 4
PAR_WIDTH = 5
MESSAGE_EMPTY_BOX, MESSAGE_NON_FINITE = 1, 2  # I_OUT[OUT_MESSAGE]
ROUTE_WIDE, ROUTE_ALL, ROUTE_BASIS = 0, 1, 2  # what a step leaves free: see _leftover
STATUS_OK, STATUS_BOUNDS, STATUS_SCALED, STATUS_INFEASIBLE, STATUS_FAILED = 0, 1, 2, 3, 4


# ---------------------------------------------------------------------- linear algebra
@kernel
def _damping(s: np.ndarray, eps: float, lam: float) -> np.ndarray:
    """``mu_i = (1 - (s_i / eps)^2) lambda_max^2`` where ``s_i < eps``, else 0."""
    x = s * (1.0 / eps)
    x *= x
    return np.maximum(1.0 - x, 0.0) * lam**2


@kernel
def _gram_step(M: np.ndarray, R: np.ndarray, tall: bool, exact: bool, eps: float, lam: float,
               rank_tol: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The reference's ``_gram_step`` on ``M`` (m x r, the level's rows on its free
    directions): ``M^+_damped R`` (R: m x k) and a basis (r x .) of the directions it leaves
    unused, from the SVD of M where the reference's rows are tall (``tall``) or the
    eigen-decomposition of ``M M^T``, with its rank floors."""
    m = M.shape[0]
    if tall:
        U, sv, Vt = np.linalg.svd(M, full_matrices=False)
        top = sv[0] ** 2 if sv.size else 0.0
        floor = (rank_tol * max(1.0, math.sqrt(top))) ** 2
        if not exact:
            floor = max(floor, 10.0 * m * _EPS * top)
        keep = sv * sv > floor
        s_r = sv[keep]
        c = np.ascontiguousarray(U[:, keep].T).dot(R)
        gain = s_r / (s_r * s_r + _damping(s_r, eps, lam))
        for k in range(s_r.shape[0]):
            c[k] *= gain[k]
        Y = np.ascontiguousarray(Vt[keep].T).dot(c)
        return Y, np.ascontiguousarray(Vt[~keep].T)
    lam_all, U = np.linalg.eigh(M.dot(M.T))
    top = max(lam_all[-1], 0.0) if lam_all.size else 0.0
    floor = max((rank_tol * max(1.0, math.sqrt(top))) ** 2, 10.0 * lam_all.size * _EPS * top)
    keep = lam_all > floor
    lam_r = lam_all[keep]
    U_r = np.ascontiguousarray(U[:, keep])
    MtU = M.T.dot(U_r)
    c = U_r.T.dot(R)
    gain = 1.0 / (lam_r + _damping(np.sqrt(lam_r), eps, lam))
    for k in range(lam_r.shape[0]):
        c[k] *= gain[k]
    V_r = MtU / np.sqrt(lam_r)  # orthonormal: the directions the level uses
    return MtU.dot(c), _null_basis(np.ascontiguousarray(V_r.T))


@kernel
def _solve_ls(M: np.ndarray, R: np.ndarray, eps: float, lam: float,
              rank_tol: float) -> tuple[np.ndarray, np.ndarray, int]:  # fmt: skip
    """Damped least squares ``Y = M^+_damped R`` (R: m x 2), the null-space basis of M and
    its rank, from the SVD."""
    m, n = M.shape
    if m == 0 or n == 0:
        return np.zeros((n, R.shape[1])), np.eye(n), 0
    U, s, Vt = np.linalg.svd(M, full_matrices=True)
    smax = s[0] if s.size else 0.0
    rank = 0
    for v in s:
        if v > rank_tol * max(1.0, smax):
            rank += 1
    sr = s[:rank]
    inv = sr / (sr * sr + _damping(sr, eps, lam))
    c = np.ascontiguousarray(U[:, :rank].T).dot(R)
    for k in range(rank):
        c[k] *= inv[k]
    Y = np.ascontiguousarray(Vt[:rank].T).dot(c)
    return Y, np.ascontiguousarray(Vt[rank:].T), rank


# ---------------------------------------------------------------------- boxes
@kernel
def _inside(u: np.ndarray, lo_tol: np.ndarray, hi_tol: np.ndarray) -> bool:
    """Whether ``u`` lies in the tolerance-widened box (False for NaN)."""
    for k in range(u.shape[0]):  # noqa: SIM110 (a loop, for numba)
        if not (u[k] >= lo_tol[k] and u[k] <= hi_tol[k]):
            return False
    return True


@kernel
def _scaling(a: np.ndarray, rest: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             skip: np.ndarray) -> tuple[float, int]:  # fmt: skip
    """Largest ``s`` in [0, 1] with ``rest + s a`` in the box and the joint that limits it
    (-1 if none); joints in ``skip`` are already saturated (the reference's ``_scaling``)."""
    n = a.shape[0]
    if n == 0:
        return 1.0, -1
    s_max = np.inf
    critical = 0
    down = -np.inf
    for j in range(n):
        up_j, down_j = np.inf, -np.inf
        if (a[j] > 0 or a[j] < 0) and not skip[j]:
            towards, away = (hi[j], lo[j]) if a[j] > 0 else (lo[j], hi[j])
            up_j = (towards - rest[j]) / a[j]
            down_j = (away - rest[j]) / a[j]
        if up_j < s_max:
            s_max, critical = up_j, j
        if down_j > down or down_j != down_j:
            down = down_j
    if not s_max < np.inf:
        critical = -1
    if s_max < down or s_max < 0:
        return 0.0, critical
    return min(s_max, 1.0), critical


@kernel
def _segment(u0: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest ``t`` in [0, 1] with ``u0 + t d`` in the box."""
    if d.shape[0] == 0:
        return 1.0
    t = np.inf
    for j in range(d.shape[0]):
        if d[j] > 0:
            tj = (hi[j] - u0[j]) / d[j]
        elif d[j] < 0:
            tj = (lo[j] - u0[j]) / d[j]
        else:
            tj = np.inf
        if tj < t or tj != tj:
            t = tj
    return min(max(t, 0.0), 1.0)


# ---------------------------------------------------------------------- free directions
@kernel
def _basis(Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> np.ndarray:
    """An orthonormal basis (n x r) of the free directions: the mask's coordinate axes, or
    ``Z`` itself."""
    if not is_mask:
        return Z
    n = mask.shape[0]
    out = np.zeros((n, int(np.sum(mask))))
    c = 0
    for j in range(n):
        if mask[j]:
            out[j, c] = 1.0
            c += 1
    return out


@kernel
def _zero_fixed_rows(Z: np.ndarray) -> np.ndarray:
    """``Z`` with the rows of joints that do not move (``|Z_j|^2 <= 1e-18``, rounding) set to
    exactly 0, as the reference's basis of the free directions."""
    out = Z
    for j in range(Z.shape[0]):
        if Z[j].dot(Z[j]) <= _FIXED:
            if out is Z:
                out = Z.copy()
            out[j] = 0.0
    return out


@kernel
def _null_basis(M: np.ndarray) -> np.ndarray:
    """An orthonormal basis (r x (r - m)) of the null space of ``M`` (m x r) of full row rank
    m <= r: the last columns of the complete Q of ``M^T = Q R``."""
    m, r = M.shape
    a = np.zeros((r, r)).T  # Fortran-ordered: M^T in the first m columns, then Q
    a[:, :m] = M.T
    tau = np.zeros(max(m, 1))
    if m:
        geqrf(a[:, :m], tau[:m])
    orgqr(a, tau, m, 8 * r)
    return np.ascontiguousarray(a[:, m:])


@kernel
def _deflate(Z: np.ndarray, j: int) -> np.ndarray:
    """The basis of ``{Z y : (Z y)_j = 0}`` (n x (r - 1)) by one Householder reflection of
    Z's coordinates: ``Z H`` without its first column, row j exactly zero. Its projector is
    the reference's rank-one update ``F - F e_j e_j^T F / F_jj``."""
    v = Z[j].copy()
    norm = math.sqrt(v.dot(v))
    v[0] += norm if v[0] >= 0 else -norm
    vv = v.dot(v)
    ZH = Z - np.outer(Z.dot(v), v * (2.0 / vv))
    out = np.ascontiguousarray(ZH[:, 1:])
    out[j] = 0.0
    return out


@kernel
def _fixed(j: int, value: float, base: np.ndarray, Z: np.ndarray, is_mask: bool,
           mask: np.ndarray):  # fmt: skip
    """The free directions once joint j is saturated at ``value`` (new arrays): ``base``
    moved along them (minimum norm) to put the joint there, and the directions that move it
    removed: ``(base, Z, mask)``."""
    if is_mask:
        if not mask[j]:
            return base, Z, mask
        nb = base.copy()
        nb[j] = value
        nm = mask.copy()
        nm[j] = False
        return nb, Z, nm
    z = Z[j]
    fjj = z.dot(z)
    if fjj <= _FIXED:  # |row j of an orthonormal basis| <= 1e-9: the joint cannot move
        return base, Z, mask
    nb = base + Z.dot(z) * ((value - base[j]) / fjj)
    nb[j] = value
    return nb, _deflate(Z, j), mask


# ---------------------------------------------------------------------- a level's step
@kernel
def _certify_wide(M: np.ndarray, eps: float, rank_tol: float):
    """The reference's certificate of ``G = M M^T`` (m x m): ``(ok, L^-1)``."""
    dummy = np.zeros((0, 0)).T
    G = M.dot(M.T)
    top = 0.0
    for k in range(G.shape[0]):
        top += G[k, k]
    if G.shape[0] == 0 or eps * eps <= (rank_tol**2) * max(1.0, top):
        return False, dummy
    ok, Linv = cholesky_inverse(G)
    if not ok or not _exceeds(G, Linv, eps):
        return False, dummy
    return True, Linv


@kernel
def _certify_tall(M: np.ndarray, eps: float, floor: float):
    """A certificate that the tall ``M`` (m x r, m >= r) has ``lambda_min(M^T M) >= eps^2 >
    floor`` and ``kappa_F <= NORMAL_KAPPA``: ``(ok, L^-1, kappa_F^2)``; then no direction is
    damped or dropped, and its normal equations are accurate."""
    dummy = np.zeros((0, 0)).T
    if M.shape[1] == 0 or not eps * eps > floor:
        return False, dummy, 0.0
    G = M.T.dot(M)
    top = 0.0
    for k in range(G.shape[0]):
        top += G[k, k]
    ok, Linv = cholesky_inverse(G)
    if not ok or not _exceeds(G, Linv, eps):
        return False, dummy, 0.0
    k2 = frobenius2(Linv) * top
    if k2 > NORMAL_KAPPA * NORMAL_KAPPA:
        return False, dummy, 0.0
    return True, Linv, k2


@kernel
def _exceeds(G: np.ndarray, Linv: np.ndarray, eps: float) -> bool:
    """``lambda_min(G) >= eps^2``: ``trace(G^-1) <= 1 / eps^2``, or else ``G - eps^2 I`` has a
    Cholesky factor (the reference's two tests)."""
    if frobenius2(Linv) * eps * eps <= 1.0:
        return True
    S = np.asfortranarray(G)
    for k in range(S.shape[0]):
        S[k, k] -= eps**2
    return potrf(S, True) == 0


@kernel
def _step(A: np.ndarray, R: np.ndarray, Zb: np.ndarray, is_mask: bool, par: np.ndarray,
          sns: bool):  # fmt: skip
    """A level's least-squares step on its free directions ``Zb`` (n x r):
    ``(Y, M, Nf, route, rank)`` with ``Y = Zb M^+_damped R`` (``M = A Zb``, R: m x k), what
    :func:`_leftover` needs for the basis of the directions the level leaves free, and the
    rank the reference reports.

    The route is the reference's: its certified Cholesky where it certifies (``G = M M^T``,
    m <= r; ``M^T M`` when the level has more rows than nu and nothing is fixed), else its
    eigen-decomposition (``_gram_step``) or, in SNS (``sns``), its damped SVD
    (``_solve_ls``), each on ``M`` instead of ``A F`` (the same singular values and
    directions). Before those, where ``M`` is tall, a certificate on ``M^T M`` (no direction
    damped or dropped, well conditioned) takes the normal equations, which is what those
    routes then compute, at a fraction of the cost."""
    eps, lam, rank_tol = par[PAR_THRESHOLD], par[PAR_DAMPING], par[PAR_RANK]
    n, r = Zb.shape
    m = A.shape[0]
    if r == 0:  # nothing left to move (the reference's routes all give 0)
        return np.zeros((n, R.shape[1])), np.zeros((m, 0)), np.zeros((0, 0)), ROUTE_ALL, 0
    M = A.dot(Zb)
    if m <= n and m <= r:  # the reference certifies G = M M^T
        ok, Linv = _certify_wide(M, eps, rank_tol)
        if ok:
            Y = Zb.dot(M.T.dot(Linv.T.dot(Linv.dot(R))))
            return Y, M, np.zeros((0, 0)), ROUTE_WIDE, m
    top = 0.0
    for v in M.ravel():
        top += v * v
    tall_ref = m > n
    if sns:
        floor = (rank_tol**2) * max(1.0, top)
    else:
        floor = (rank_tol * max(1.0, math.sqrt(top))) ** 2
        if not (tall_ref and is_mask):
            floor = max(floor, 10.0 * m * _EPS * top)
    if sns:  # the reference's SVD takes a basis whose rows of fixed joints are exactly 0
        Zb = _zero_fixed_rows(Zb)
        M = A.dot(Zb)
    if m > r or (tall_ref and r == n):  # (m <= r: M^T M singular, or M M^T certified)
        ok, Linv, k2 = _certify_tall(M, eps, floor)
        if ok:
            return Zb.dot(normal_solve(M, Linv, R, k2)), M, np.zeros((0, 0)), ROUTE_ALL, r
    if sns:
        Y, Nf, rank = _solve_ls(M, R, eps, lam, rank_tol)
    else:
        Y, Nf = _gram_step(M, R, tall_ref, is_mask, eps, lam, rank_tol)
        rank = 0
    return Zb.dot(Y), M, Zb.dot(Nf), ROUTE_BASIS, rank


@kernel
def _leftover(Zb: np.ndarray, M: np.ndarray, N: np.ndarray, route: int) -> np.ndarray:
    """The basis (n x .) of the free directions a level's step leaves (see :func:`_step`):
    those of ``Zb`` that ``M = A Zb`` does not move, none, or the given ``N``."""
    if route == ROUTE_WIDE:
        return Zb.dot(_null_basis(M))
    if route == ROUTE_ALL:
        return np.zeros((Zb.shape[0], 0))
    return N


# ---------------------------------------------------------------------- levels
@kernel
def _level(A, b, rs, ids, u0, Z, is_mask, mask, sat, lo, hi, lo_tol, hi_tol, need_next,
           saturate, par):  # fmt: skip
    """One level on top of the state of the levels above (the reference's ``_level``):
    ``(u, Z, is_mask, mask, saturated, scale)``."""
    n = u0.shape[0]
    if A.shape[0] == 0:
        return u0, Z, is_mask, mask, sat, 1.0
    if rs != 1.0:  # damping decided independently of a common scale
        c = 1.0 / rs
        A, b = A * c, b * c
    nothing = np.zeros(n, np.bool_)
    empty = np.zeros((n, 0))
    Zb = _basis(Z, is_mask, mask)
    if ids > 0:
        d = b / ids - u0
        u = u0 + Zb.dot(Zb.T.dot(d))
        nZ, n_mask, n_free = empty, True, nothing
    else:
        R = (b - A.dot(u0)).reshape((A.shape[0], 1))
        Y, M, N, route, _ = _step(A, R, Zb, is_mask, par, False)
        u = u0 + Y[:, 0]
        nZ = _leftover(Zb, M, N, route) if need_next else empty
        n_mask, n_free = False, nothing
    if not saturate or _inside(u, lo_tol, hi_tol):
        return u, nZ, n_mask, n_free, sat, 1.0
    if ids > 0:
        return _saturate_identity(b, ids, u0, Z, is_mask, mask, sat, lo, hi, lo_tol, hi_tol)
    return _saturate(A, b, u0, Z, is_mask, mask, sat, lo, hi, lo_tol, hi_tol, par)


@kernel
def _saturate(A, b, u0, Z, is_mask, mask, sat, lo, hi, lo_tol, hi_tol, par):  # fmt: skip
    """Saturation in the Null Space for one level of tasks (the reference's ``_saturate``):
    the most critical joint saturated until the level fits or runs out of directions."""
    n, m = u0.shape[0], A.shape[0]
    base = u0
    needed = -1
    skip = sat.copy()
    best_s = -np.inf
    best_rest, best_a = u0, u0
    best_Zb, best_M, best_N, best_route = Z, A, Z, ROUTE_ALL
    R = np.empty((m, 2))
    R[:, 0] = b
    for it in range(n + 1):
        R[:, 1] = -A.dot(base)
        Zb = _basis(Z, is_mask, mask)
        Y, M, N, route, rank = _step(A, R, Zb, is_mask, par, True)
        a, rest = Y[:, 0].copy(), base + Y[:, 1]
        if needed < 0:
            needed = rank
        s_max, critical = _scaling(a, rest, lo, hi, skip)
        if it == 0 or s_max > best_s:
            best_s, best_rest, best_a = s_max, rest, a
            best_Zb, best_M, best_N, best_route = Zb, M, N, route
        cand = rest + a
        if _inside(cand, lo_tol, hi_tol):
            return cand, _leftover(Zb, M, N, route), False, mask, skip, 1.0
        if rank < needed or critical < 0:
            break  # out of free directions: scale the level by the best factor found
        skip[critical] = True
        bound = hi[critical] if cand[critical] > hi[critical] else lo[critical]
        base, Z, mask = _fixed(critical, bound, base, Z, is_mask, mask)
    u = best_rest + best_s * best_a
    if not _inside(u, lo_tol, hi_tol):  # last guard: a feasible point on the segment from u0
        u = u0 + _segment(u0, u - u0, lo, hi) * (u - u0)
    return u, _leftover(best_Zb, best_M, best_N, best_route), False, mask, skip, best_s


@kernel
def _saturate_identity(b, s, u0, Z, is_mask, mask, sat, lo, hi, lo_tol, hi_tol):  # fmt: skip
    """SNS for a level of objectives only (rows ``s I``): its move is ``F b / s`` on the
    free directions ``F`` (the reference's ``_saturate_identity``); it leaves nothing free."""
    n = u0.shape[0]
    base = u0
    c = 1.0 / s
    Zb = _basis(Z, is_mask, mask)
    needed = Zb.shape[1]
    skip = sat.copy()
    best_s = -np.inf
    best_rest, best_a, best_none = u0, u0, False
    nothing = np.zeros(n, np.bool_)
    empty = np.zeros((n, 0))
    for it in range(n + 1):
        rank = Zb.shape[1]
        a = c * Zb.dot(Zb.T.dot(b))
        rest = base - Zb.dot(Zb.T.dot(base))
        s_max, critical = _scaling(a, rest, lo, hi, skip)
        if it == 0 or s_max > best_s:  # (rank > 0: the reference's P None, free none)
            best_s, best_rest, best_a, best_none = s_max, rest, a, rank > 0
        cand = rest + a
        if _inside(cand, lo_tol, hi_tol):
            return cand, empty, rank > 0, nothing, skip, 1.0
        if rank < needed or critical < 0:
            break
        skip[critical] = True
        bound = hi[critical] if cand[critical] > hi[critical] else lo[critical]
        base, Z, mask = _fixed(critical, bound, base, Z, is_mask, mask)
        Zb = _basis(Z, is_mask, mask)
    u = best_rest + best_s * best_a
    if not _inside(u, lo_tol, hi_tol):
        u = u0 + _segment(u0, u - u0, lo, hi) * (u - u0)
    return u, empty, best_none, nothing, skip, best_s


# ---------------------------------------------------------------------- the solve
@kernel
def project(f: np.ndarray, i: np.ndarray, h: np.ndarray, par: np.ndarray) -> None:
    """Solve the evaluated stack: ``F_U`` (scaled and actuated), per level its residual and
    scale factor, per task its residuals and whether it is met, the active bounds and the
    status (``I_OUT``)."""
    box = fmat(f, h, lay.F_BOX)
    lo, hi = box[0], box[1]
    levels, lf = imat(i, h, lay.I_LEVEL), fmat(f, h, lay.F_LEVEL)
    A, b = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B)
    out, lev_out = ivec(i, h, lay.I_OUT), fmat(f, h, lay.F_LEVEL_OUT)
    n, L = lo.shape[0], levels.shape[0]
    out[:] = 0
    lev_out[:, 1] = 1.0
    for j in range(n):
        if not lo[j] <= hi[j]:  # NaN compares false; evaluate never crosses the box
            out[lay.OUT_FAILED], out[lay.OUT_MESSAGE] = 1, MESSAGE_EMPTY_BOX
            _report(f, i, h, np.zeros(n), par[PAR_TOLERANCE])
            return
    u_start = np.minimum(np.maximum(0.0, lo), hi)
    wide_lo = lo - _INSIDE_TOL * (np.abs(lo) + 1.0)
    wide_hi = hi + _INSIDE_TOL * (np.abs(hi) + 1.0)
    u = np.zeros(n)
    Z = np.zeros((n, 0))
    is_mask = True
    free = np.ones(n, np.bool_)
    sat = np.zeros(n, np.bool_)
    for k in range(L):
        r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_ROW_END]
        u, Z, is_mask, free, sat, _ = _level(
            A[r0:r1], b[r0:r1], lf[k, lay.LEVEL_REFERENCE], lf[k, lay.LEVEL_IDENTITY], u, Z,
            is_mask, free, sat, lo, hi, wide_lo, wide_hi, k + 1 < L, False, par,
        )  # fmt: skip
    if par[PAR_SATURATE] != 0.0 and not _inside(u, wide_lo, wide_hi):
        sat = lo == hi
        u, Z, is_mask, free = u_start.copy(), np.zeros((n, 0)), True, ~sat
        for k in range(L):
            r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_ROW_END]
            u, Z, is_mask, free, sat, s = _level(
                A[r0:r1], b[r0:r1], lf[k, lay.LEVEL_REFERENCE], lf[k, lay.LEVEL_IDENTITY], u,
                Z, is_mask, free, sat, lo, hi, wide_lo, wide_hi, k + 1 < L, True, par,
            )  # fmt: skip
            lev_out[k, 1] = s
    if not math.isfinite(u.dot(u)) and not np.all(np.isfinite(u)):
        out[lay.OUT_FAILED], out[lay.OUT_MESSAGE] = 1, MESSAGE_NON_FINITE
        u = u_start
    _report(f, i, h, u, par[PAR_TOLERANCE])


@kernel
def _report(f: np.ndarray, i: np.ndarray, h: np.ndarray, u: np.ndarray, tol: float) -> None:
    """Residuals, met tasks, active bounds and status at the scaled solution ``u``."""
    box, D = fmat(f, h, lay.F_BOX), fmat(f, h, lay.F_METRIC)[0]
    lo, hi = box[0], box[1]
    levels, tasks = imat(i, h, lay.I_LEVEL), imat(i, h, lay.I_TASK)
    A, b, rows = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B), fmat(f, h, lay.F_ROW)
    out, lev_out = ivec(i, h, lay.I_OUT), fmat(f, h, lay.F_LEVEL_OUT)
    res = fmat(f, h, lay.F_TASK_RES)
    infeasible, active = ivec(i, h, lay.I_INFEASIBLE), ivec(i, h, lay.I_ACTIVE)
    U = fmat(f, h, lay.F_U)
    n = u.shape[0]
    U[0] = u
    U[1] = D * u
    top_unmet = False
    t0 = 0
    for k in range(levels.shape[0]):
        r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_ROW_END]
        t1 = t0
        while t1 < tasks.shape[0] and tasks[t1, 0] == k:
            t1 += 1
        lev_out[k, 0] = 0.0
        if r1 > r0:
            lev_out[k, 0] = level_report(A[r0:r1], b[r0:r1], rows[1, r0:r1], u, tasks[t0:t1],
                                         r0, res[t0:t1])  # fmt: skip
        for t in range(t0, t1):
            met = res[t, 0] <= tol * (1.0 + res[t, 2])  # (a NaN residual is not met)
            infeasible[t] = 0 if met or tasks[t, 2] == tasks[t, 1] else 1
            if infeasible[t] and k == 0:
                top_unmet = True
        t0 = t1
    any_active = False
    for j in range(n):
        at = (u[j] - lo[j] <= 1e-9 * max(abs(lo[j]), 1.0) and math.isfinite(lo[j])) or (
            hi[j] - u[j] <= 1e-9 * max(abs(hi[j]), 1.0) and math.isfinite(hi[j])
        )
        active[j] = at
        any_active = any_active or at
    scales = lev_out[:, 1]
    if out[lay.OUT_FAILED]:
        status = STATUS_FAILED
    elif scales.shape[0] and scales[0] >= 1.0 and top_unmet:
        status = STATUS_INFEASIBLE
    elif np.any(scales < 1.0):
        status = STATUS_SCALED
    elif any_active:
        status = STATUS_BOUNDS
    else:
        status = STATUS_OK
    out[lay.OUT_STATUS] = status
