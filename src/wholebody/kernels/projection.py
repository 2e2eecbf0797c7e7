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
from wholebody.kernels.lapack import gesdd, potrf, syevd
from wholebody.kernels.layout import fmat, fvec, imat, ivec
from wholebody.kernels.linalg import (
    NORMAL_KAPPA,
    cholesky_inverse,
    combine,
    dot,
    fortran,
    frobenius2,
    level_report,
    mm,
    mmt,
    mtm,
    mtv,
    mv,
    normal_solve,
    null_basis,
    scatter_rows,
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
def _damping(s: float, eps: float, lam: float) -> float:
    """``mu = (1 - (s / eps)^2) lambda_max^2`` where ``s < eps``, else 0."""
    x = s / eps
    return max(1.0 - x * x, 0.0) * lam * lam


@kernel
def _damped_solve(Vt: np.ndarray, U: np.ndarray, s: np.ndarray, squared: bool, keep: np.ndarray,
                  R: np.ndarray, eps: float, lam: float) -> np.ndarray:  # fmt: skip
    """``V_k diag(g) U_k^T R`` over the kept indices ``k`` (``keep``): the damped
    pseudo-inverse of ``M = U diag(sigma) V^T`` applied to ``R`` (m x c), with ``g = sigma /
    (sigma^2 + mu(sigma))``, or from eigenvalues ``s = sigma^2`` of ``M M^T`` (``squared``,
    ``Vt`` then holding ``M^T U`` transposed, so ``g = 1 / (s + mu(sqrt s))``)."""
    m, c = R.shape
    r = Vt.shape[1]
    Y = np.zeros((r, c))
    for k in range(s.shape[0]):
        if not keep[k]:
            continue
        if squared:
            g = 1.0 / (s[k] + _damping(math.sqrt(s[k]), eps, lam))
        else:
            g = s[k] / (s[k] * s[k] + _damping(s[k], eps, lam))
        for col in range(c):
            t = 0.0
            for i in range(m):
                t += U[i, k] * R[i, col]
            t *= g
            for j in range(r):
                Y[j, col] += Vt[k, j] * t
    return Y


@kernel
def _rows_not_kept(Vt: np.ndarray, keep: np.ndarray, count: int) -> np.ndarray:
    """The rows of ``Vt`` not in ``keep`` (``count`` of them), transposed: r x count."""
    out = np.zeros((Vt.shape[1], count))
    c = 0
    for k in range(Vt.shape[0]):
        if k < keep.shape[0] and keep[k]:
            continue
        for j in range(Vt.shape[1]):
            out[j, c] = Vt[k, j]
        c += 1
    return out


@kernel
def _gram_step(M: np.ndarray, R: np.ndarray, tall: bool, exact: bool, eps: float, lam: float,
               rank_tol: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The reference's ``_gram_step`` on ``M`` (m x r, the level's rows on its free
    directions): ``M^+_damped R`` (R: m x k) and a basis (r x .) of the directions it leaves
    unused, from the SVD of M where the reference's rows are tall (``tall``) or the
    eigen-decomposition of ``M M^T``, with its rank floors."""
    m, r = M.shape
    if tall:
        _, U, sv, Vt = gesdd(fortran(M), False)
        top = sv[0] ** 2 if sv.shape[0] else 0.0
        floor = (rank_tol * max(1.0, math.sqrt(top))) ** 2
        if not exact:
            floor = max(floor, 10.0 * m * _EPS * top)
        keep = np.zeros(sv.shape[0], np.bool_)
        kept = 0
        for k in range(sv.shape[0]):
            keep[k] = sv[k] * sv[k] > floor
            kept += keep[k]
        Y = _damped_solve(Vt, U, sv, False, keep, R, eps, lam)
        return Y, _rows_not_kept(Vt, keep, Vt.shape[0] - kept)
    E = fortran(mmt(M, M))
    _, w = syevd(E)
    top = max(w[-1], 0.0) if w.shape[0] else 0.0
    floor = max((rank_tol * max(1.0, math.sqrt(top))) ** 2, 10.0 * w.shape[0] * _EPS * top)
    keep = np.zeros(w.shape[0], np.bool_)
    kept = 0
    for k in range(w.shape[0]):
        keep[k] = w[k] > floor
        kept += keep[k]
    MtU = mtm(E, M)  # row k: (M^T u_k)^T
    Y = _damped_solve(MtU, E, w, True, keep, R, eps, lam)
    V_r = np.zeros((kept, r))  # orthonormal rows: the directions the level uses
    c = 0
    for k in range(w.shape[0]):
        if keep[k]:
            scale = 1.0 / math.sqrt(w[k])
            for j in range(r):
                V_r[c, j] = MtU[k, j] * scale
            c += 1
    return Y, null_basis(V_r)


@kernel
def _solve_ls(M: np.ndarray, R: np.ndarray, eps: float, lam: float,
              rank_tol: float) -> tuple[np.ndarray, np.ndarray, int]:  # fmt: skip
    """Damped least squares ``Y = M^+_damped R`` (R: m x 2), the null-space basis of M and
    its rank, from the SVD."""
    m, n = M.shape
    if m == 0 or n == 0:
        return np.zeros((n, R.shape[1])), np.eye(n), 0
    _, U, s, Vt = gesdd(fortran(M), True)
    smax = s[0] if s.shape[0] else 0.0
    keep = np.zeros(s.shape[0], np.bool_)
    rank = 0
    for k in range(s.shape[0]):
        keep[k] = s[k] > rank_tol * max(1.0, smax)
        rank += keep[k]
    for k in range(s.shape[0]):  # (the reference counts them and keeps the first rank)
        keep[k] = k < rank
    Y = _damped_solve(Vt, U, s, False, keep, R, eps, lam)
    return Y, _rows_not_kept(Vt, keep, n - rank), rank


# ---------------------------------------------------------------------- boxes
@kernel
def _inside(u: np.ndarray, lo_tol: np.ndarray, hi_tol: np.ndarray) -> bool:
    """Whether ``u`` lies in the tolerance-widened box (False for NaN)."""
    for k in range(u.shape[0]):
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
def _rank(Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> int:
    """How many free directions there are: the mask's count, or Z's columns."""
    if not is_mask:
        return Z.shape[1]
    r = 0
    for j in range(mask.shape[0]):
        r += mask[j]
    return r


@kernel
def _restrict(A: np.ndarray, Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> np.ndarray:
    """``A Zb`` (m x r) for the orthonormal basis ``Zb`` of the free directions: the mask's
    columns of A in order, or ``A Z``."""
    if not is_mask:
        return mm(A, Z)
    m = A.shape[0]
    out = np.empty((m, _rank(Z, is_mask, mask)))
    c = 0
    for j in range(mask.shape[0]):
        if mask[j]:
            for i in range(m):
                out[i, c] = A[i, j]
            c += 1
    return out


@kernel
def _lift(Y: np.ndarray, Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> np.ndarray:
    """``Zb Y`` (n x k) for coordinates ``Y`` (r x k) on the free directions: Y's rows
    placed at the mask's joints, or ``Z Y``."""
    if not is_mask:
        return mm(Z, Y)
    return scatter_rows(Y, mask)


@kernel
def _project_free(d: np.ndarray, Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> np.ndarray:
    """``Zb Zb^T d``: ``d`` projected on the free directions."""
    if not is_mask:
        return mv(Z, mtv(Z, d))
    out = np.zeros(d.shape[0])
    for j in range(d.shape[0]):
        if mask[j]:
            out[j] = d[j]
    return out


@kernel
def _row_norm2(Z: np.ndarray, j: int) -> float:
    """``|Z_j|^2``, row j's squared norm."""
    s = 0.0
    for k in range(Z.shape[1]):
        s += Z[j, k] * Z[j, k]
    return s


@kernel
def _zero_fixed_rows(Z: np.ndarray) -> np.ndarray:
    """``Z`` with the rows of joints that do not move (``|Z_j|^2 <= 1e-18``, rounding) set to
    exactly 0, as the reference's basis of the free directions."""
    out = Z
    for j in range(Z.shape[0]):
        if _row_norm2(Z, j) <= _FIXED:
            if out is Z:
                out = Z.copy()
            out[j, :] = 0.0
    return out


@kernel
def _deflate(Z: np.ndarray, j: int) -> np.ndarray:
    """The basis of ``{Z y : (Z y)_j = 0}`` (n x (r - 1)) by one Householder reflection of
    Z's coordinates: ``Z H`` without its first column, row j exactly zero. Its projector is
    the reference's rank-one update ``F - F e_j e_j^T F / F_jj``."""
    n, r = Z.shape
    v = np.empty(r)
    for k in range(r):
        v[k] = Z[j, k]
    norm = math.sqrt(dot(v, v))
    v[0] += norm if v[0] >= 0 else -norm
    c = 2.0 / dot(v, v)
    out = np.empty((n, r - 1))
    for i in range(n):
        if i == j:
            out[i, :] = 0.0
            continue
        t = 0.0
        for k in range(r):
            t += Z[i, k] * v[k]
        t *= c
        for k in range(1, r):
            out[i, k - 1] = Z[i, k] - t * v[k]
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
    fjj = _row_norm2(Z, j)
    if fjj <= _FIXED:  # |row j of an orthonormal basis| <= 1e-9: the joint cannot move
        return base, Z, mask
    z = np.empty(Z.shape[1])
    for k in range(Z.shape[1]):
        z[k] = Z[j, k]
    nb = combine(base, (value - base[j]) / fjj, mv(Z, z))
    nb[j] = value
    return nb, _deflate(Z, j), mask


# ---------------------------------------------------------------------- a level's step
@kernel
def _trace(G: np.ndarray) -> float:
    """``trace(G)``."""
    t = 0.0
    for k in range(G.shape[0]):
        t += G[k, k]
    return t


@kernel
def _certify_wide(M: np.ndarray, eps: float, rank_tol: float):
    """The reference's certificate of ``G = M M^T`` (m x m): ``(ok, L^-1)``."""
    dummy = np.zeros((0, 0)).T
    G = mmt(M, M)
    if G.shape[0] == 0 or eps * eps <= (rank_tol**2) * max(1.0, _trace(G)):
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
    G = mtm(M, M)
    ok, Linv = cholesky_inverse(G)
    if not ok or not _exceeds(G, Linv, eps):
        return False, dummy, 0.0
    k2 = frobenius2(Linv) * _trace(G)
    if k2 > NORMAL_KAPPA * NORMAL_KAPPA:
        return False, dummy, 0.0
    return True, Linv, k2


@kernel
def _exceeds(G: np.ndarray, Linv: np.ndarray, eps: float) -> bool:
    """``lambda_min(G) >= eps^2``: ``trace(G^-1) <= 1 / eps^2``, or else ``G - eps^2 I`` has a
    Cholesky factor (the reference's two tests)."""
    if frobenius2(Linv) * eps * eps <= 1.0:
        return True
    S = fortran(G)
    for k in range(S.shape[0]):
        S[k, k] -= eps**2
    return potrf(S, True) == 0


@kernel
def _step(A: np.ndarray, R: np.ndarray, Z: np.ndarray, is_mask: bool, mask: np.ndarray,
          par: np.ndarray, sns: bool):  # fmt: skip
    """A level's least-squares step on its free directions (``Z``, ``is_mask``, ``mask``:
    see :func:`_restrict`), ``Zb`` (n x r): ``(Y, M, Nf, route, rank)`` with ``Y = Zb
    M^+_damped R`` (``M = A Zb``, R: m x k), what :func:`_leftover` needs for the basis of
    the directions the level leaves free, and the rank the reference reports.

    The route is the reference's: its certified Cholesky where it certifies (``G = M M^T``,
    m <= r; ``M^T M`` when the level has more rows than nu and nothing is fixed), else its
    eigen-decomposition (``_gram_step``) or, in SNS (``sns``), its damped SVD
    (``_solve_ls``), each on ``M`` instead of ``A F`` (the same singular values and
    directions). Before those, where ``M`` is tall, a certificate on ``M^T M`` (no direction
    damped or dropped, well conditioned) takes the normal equations, which is what those
    routes then compute, at a fraction of the cost."""
    eps, lam, rank_tol = par[PAR_THRESHOLD], par[PAR_DAMPING], par[PAR_RANK]
    n, m = mask.shape[0], A.shape[0]
    r = _rank(Z, is_mask, mask)
    if r == 0:  # nothing left to move (the reference's routes all give 0)
        return np.zeros((n, R.shape[1])), np.zeros((m, 0)), np.zeros((0, 0)), ROUTE_ALL, 0
    M = _restrict(A, Z, is_mask, mask)
    if m <= n and m <= r:  # the reference certifies G = M M^T
        ok, Linv = _certify_wide(M, eps, rank_tol)
        if ok:
            Y = _lift(mtm(M, mtm(Linv, mm(Linv, R))), Z, is_mask, mask)
            return Y, M, np.zeros((0, 0)), ROUTE_WIDE, m
    top = frobenius2(M)
    tall_ref = m > n
    if sns:
        floor = (rank_tol**2) * max(1.0, top)
    else:
        floor = (rank_tol * max(1.0, math.sqrt(top))) ** 2
        if not (tall_ref and is_mask):
            floor = max(floor, 10.0 * m * _EPS * top)
    if sns and not is_mask:  # the reference's SVD takes a basis whose fixed rows are 0
        Z = _zero_fixed_rows(Z)
        M = mm(A, Z)
    if m > r or (tall_ref and r == n):  # (m <= r: M^T M singular, or M M^T certified)
        ok, Linv, k2 = _certify_tall(M, eps, floor)
        if ok:
            Y = _lift(normal_solve(M, Linv, R, k2), Z, is_mask, mask)
            return Y, M, np.zeros((0, 0)), ROUTE_ALL, r
    if sns:
        Y, Nf, rank = _solve_ls(M, R, eps, lam, rank_tol)
    else:
        Y, Nf = _gram_step(M, R, tall_ref, is_mask, eps, lam, rank_tol)
        rank = 0
    return _lift(Y, Z, is_mask, mask), M, _lift(Nf, Z, is_mask, mask), ROUTE_BASIS, rank


@kernel
def _leftover(Z: np.ndarray, is_mask: bool, mask: np.ndarray, M: np.ndarray, N: np.ndarray,
              route: int) -> np.ndarray:  # fmt: skip
    """The basis (n x .) of the free directions a level's step leaves (see :func:`_step`):
    those that ``M = A Zb`` does not move, none, or the given ``N``."""
    if route == ROUTE_WIDE:
        return _lift(null_basis(M), Z, is_mask, mask)
    if route == ROUTE_ALL:
        return np.zeros((mask.shape[0], 0))
    return N


# ---------------------------------------------------------------------- levels
@kernel
def _level(A, b, rs, ids, u0, Z, is_mask, mask, sat, lo, hi, lo_tol, hi_tol, need_next,
           saturate, par):  # fmt: skip
    """One level on top of the state of the levels above (the reference's ``_level``):
    ``(u, Z, is_mask, mask, saturated, scale)``."""
    n, m = u0.shape[0], A.shape[0]
    if m == 0:
        return u0, Z, is_mask, mask, sat, 1.0
    if rs != 1.0:  # damping decided independently of a common scale
        A = A * (1.0 / rs)
        b = b * (1.0 / rs)
    nothing = np.zeros(n, np.bool_)
    empty = np.zeros((n, 0))
    if ids > 0:
        d = np.empty(n)
        for j in range(n):
            d[j] = b[j] / ids - u0[j]
        u = combine(u0, 1.0, _project_free(d, Z, is_mask, mask))
        nZ, n_mask, n_free = empty, True, nothing
    else:
        Au = mv(A, u0)
        R = np.empty((m, 1))
        for k in range(m):
            R[k, 0] = b[k] - Au[k]
        Y, M, N, route, _ = _step(A, R, Z, is_mask, mask, par, False)
        u = combine(u0, 1.0, Y[:, 0])
        nZ = _leftover(Z, is_mask, mask, M, N, route) if need_next else empty
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
    best_Z, best_mask, best_M, best_N, best_route = Z, mask, A, Z, ROUTE_ALL
    R = np.empty((m, 2))
    for it in range(n + 1):
        Ab = mv(A, base)
        for k in range(m):
            R[k, 0] = b[k]
            R[k, 1] = -Ab[k]
        Y, M, N, route, rank = _step(A, R, Z, is_mask, mask, par, True)
        a, rest = Y[:, 0].copy(), combine(base, 1.0, Y[:, 1])
        if needed < 0:
            needed = rank
        s_max, critical = _scaling(a, rest, lo, hi, skip)
        if it == 0 or s_max > best_s:
            best_s, best_rest, best_a = s_max, rest, a
            best_Z, best_mask, best_M, best_N, best_route = Z, mask, M, N, route
        cand = combine(rest, 1.0, a)
        if _inside(cand, lo_tol, hi_tol):
            return cand, _leftover(Z, is_mask, mask, M, N, route), False, mask, skip, 1.0
        if rank < needed or critical < 0:
            break  # out of free directions: scale the level by the best factor found
        skip[critical] = True
        bound = hi[critical] if cand[critical] > hi[critical] else lo[critical]
        base, Z, mask = _fixed(critical, bound, base, Z, is_mask, mask)
    u = _guard(u0, combine(best_rest, best_s, best_a), lo, hi, lo_tol, hi_tol)
    nZ = _leftover(best_Z, is_mask, best_mask, best_M, best_N, best_route)
    return u, nZ, False, mask, skip, best_s


@kernel
def _guard(u0, u, lo, hi, lo_tol, hi_tol) -> np.ndarray:  # fmt: skip
    """``u``, or where it is outside the box (the last guard) the last point of the segment
    from ``u0`` towards it inside the tolerance-widened box, clipped to the box (the
    reference's guard)."""
    if _inside(u, lo_tol, hi_tol):
        return u
    d = combine(u, -1.0, u0)
    out = combine(u0, _segment(u0, d, lo_tol, hi_tol), d)
    for j in range(out.shape[0]):
        out[j] = min(max(out[j], lo[j]), hi[j])
    return out


@kernel
def _saturate_identity(b, s, u0, Z, is_mask, mask, sat, lo, hi, lo_tol, hi_tol):  # fmt: skip
    """SNS for a level of objectives only (rows ``s I``): its move is ``F b / s`` on the
    free directions ``F`` (the reference's ``_saturate_identity``, joints with ``F_jj <=
    1e-18`` held exactly); it leaves nothing free."""
    n = u0.shape[0]
    base = u0
    needed = _rank(Z, is_mask, mask)
    skip = sat.copy()
    best_s = -np.inf
    best_rest, best_a, best_none = u0, u0, False
    nothing = np.zeros(n, np.bool_)
    empty = np.zeros((n, 0))
    for it in range(n + 1):
        rank = _rank(Z, is_mask, mask)
        a = _project_free(b, Z, is_mask, mask)
        for j in range(n):
            a[j] *= 1.0 / s
        rest = combine(base, -1.0, _project_free(base, Z, is_mask, mask))
        if not is_mask:  # a joint the directions do not move stays: 0, not rounding
            for j in range(n):
                if _row_norm2(Z, j) <= _FIXED:
                    a[j], rest[j] = 0.0, base[j]
        s_max, critical = _scaling(a, rest, lo, hi, skip)
        if it == 0 or s_max > best_s:  # (rank > 0: the reference's P None, free none)
            best_s, best_rest, best_a, best_none = s_max, rest, a, rank > 0
        cand = combine(rest, 1.0, a)
        if _inside(cand, lo_tol, hi_tol):
            return cand, empty, rank > 0, nothing, skip, 1.0
        if rank < needed or critical < 0:
            break
        skip[critical] = True
        bound = hi[critical] if cand[critical] > hi[critical] else lo[critical]
        base, Z, mask = _fixed(critical, bound, base, Z, is_mask, mask)
    u = _guard(u0, combine(best_rest, best_s, best_a), lo, hi, lo_tol, hi_tol)
    return u, empty, best_none, nothing, skip, best_s


# ---------------------------------------------------------------------- the solve
@kernel
def project(
    f: np.ndarray, i: np.ndarray, h: np.ndarray, par: np.ndarray, anchor: np.ndarray
) -> None:
    """Solve the evaluated stack: ``F_U`` (scaled and actuated), per level its residual and
    scale factor, per task its residuals and whether it is met, the active bounds and the
    status (``I_OUT``, see :func:`_report`). ``anchor`` (scaled): the velocity SNS scales
    motions around."""
    box = fmat(f, h, lay.F_BOX)
    lo_box, hi_box = box[0], box[1]
    levels, lf = imat(i, h, lay.I_LEVEL), fmat(f, h, lay.F_LEVEL)
    A, b = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B)
    out, lev_out = ivec(i, h, lay.I_OUT), fmat(f, h, lay.F_LEVEL_OUT)
    n, L = lo_box.shape[0], levels.shape[0]
    out[:] = 0
    lev_out[:, 1] = 1.0
    for j in range(n):
        if not lo_box[j] <= hi_box[j]:  # NaN compares false; evaluate never crosses the box
            out[lay.OUT_FAILED], out[lay.OUT_MESSAGE] = 1, MESSAGE_EMPTY_BOX
            _report(f, i, h, np.zeros(n), par[PAR_TOLERANCE], np.zeros(n), False)
            return
    lo, hi = lo_box, hi_box
    wide_lo, wide_hi = _widened(lo, hi)
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
    u_free = u  # the box-free solution of every level (a new array: _level returns one)
    u_c = np.zeros(n)  # SNS runs for d = u - u_c from d = 0 (the reference's shift)
    sns = par[PAR_SATURATE] != 0.0 and not _inside(u, wide_lo, wide_hi)
    if sns:
        shifted = False
        for j in range(n):
            u_c[j] = min(max(anchor[j], lo_box[j]), hi_box[j])
            shifted = shifted or u_c[j] != 0.0
        if shifted:
            lo, hi = combine(lo_box, -1.0, u_c), combine(hi_box, -1.0, u_c)
            b = combine(b, -1.0, mv(A, u_c))
            wide_lo, wide_hi = _widened(lo, hi)
        u, Z, is_mask = np.zeros(n), np.zeros((n, 0)), True
        sat, free = np.empty(n, np.bool_), np.empty(n, np.bool_)
        for j in range(n):
            sat[j] = lo[j] == hi[j]
            free[j] = not sat[j]
        for k in range(L):
            r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_ROW_END]
            u, Z, is_mask, free, sat, s = _level(
                A[r0:r1], b[r0:r1], lf[k, lay.LEVEL_REFERENCE], lf[k, lay.LEVEL_IDENTITY], u,
                Z, is_mask, free, sat, lo, hi, wide_lo, wide_hi, k + 1 < L, True, par,
            )  # fmt: skip
            lev_out[k, 1] = s
    u = combine(u, 1.0, u_c)
    if not math.isfinite(dot(u, u)):
        for j in range(n):
            if not math.isfinite(u[j]):
                out[lay.OUT_FAILED], out[lay.OUT_MESSAGE] = 1, MESSAGE_NON_FINITE
                for m in range(n):
                    u[m] = min(max(0.0, lo_box[m]), hi_box[m])
                break
    _report(f, i, h, u, par[PAR_TOLERANCE], u_free, sns)


@kernel
def _widened(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box widened by the tolerance of :func:`_inside`."""
    n = lo.shape[0]
    wide_lo, wide_hi = np.empty(n), np.empty(n)
    for j in range(n):
        wide_lo[j] = lo[j] - _INSIDE_TOL * (abs(lo[j]) + 1.0)
        wide_hi[j] = hi[j] + _INSIDE_TOL * (abs(hi[j]) + 1.0)
    return wide_lo, wide_hi


@kernel
def _report(f: np.ndarray, i: np.ndarray, h: np.ndarray, u: np.ndarray, tol: float,
            u_free: np.ndarray, sns: bool) -> None:  # fmt: skip
    """Residuals, met tasks, active bounds and status at the scaled solution ``u``; with
    ``sns`` (the box-free solution ``u_free`` left the box), a task whose weighted residual
    the box raised above that at ``u_free`` by more than ``tol (1 + ||b_t||)`` makes the
    status INFEASIBLE, as the first level unmet does (the reference's ``_result``)."""
    box, D = fmat(f, h, lay.F_BOX), fmat(f, h, lay.F_METRIC)[0]
    lo, hi = box[0], box[1]
    levels, tasks = imat(i, h, lay.I_LEVEL), imat(i, h, lay.I_TASK)
    A, b, rows = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B), fmat(f, h, lay.F_ROW)
    out, lev_out = ivec(i, h, lay.I_OUT), fmat(f, h, lay.F_LEVEL_OUT)
    res = fmat(f, h, lay.F_TASK_RES)
    infeasible, active = ivec(i, h, lay.I_INFEASIBLE), ivec(i, h, lay.I_ACTIVE)
    U = fmat(f, h, lay.F_U)
    n = u.shape[0]
    for j in range(n):
        U[0, j] = u[j]
        U[1, j] = D[j] * u[j]
    top_unmet = limited = False
    free_res = np.empty((tasks.shape[0] if sns else 0, 3))
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
            if sns:
                level_report(A[r0:r1], b[r0:r1], rows[1, r0:r1], u_free, tasks[t0:t1], r0,
                             free_res[t0:t1])  # fmt: skip
        for t in range(t0, t1):
            met = res[t, 0] <= tol * (1.0 + res[t, 2])  # (a NaN residual is not met)
            infeasible[t] = 0 if met or tasks[t, 2] == tasks[t, 1] else 1
            if infeasible[t] and k == 0:
                top_unmet = True
            if infeasible[t] and sns and res[t, 0] - free_res[t, 0] > tol * (1.0 + res[t, 2]):
                limited = True
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
    elif top_unmet or limited:
        status = STATUS_INFEASIBLE
    elif _any_below_one(scales):
        status = STATUS_SCALED
    elif any_active:
        status = STATUS_BOUNDS
    else:
        status = STATUS_OK
    out[lay.OUT_STATUS] = status


@kernel
def _any_below_one(x: np.ndarray) -> bool:
    """Whether some ``x_k < 1``."""
    for k in range(x.shape[0]):
        if x[k] < 1.0:
            return True
    return False
