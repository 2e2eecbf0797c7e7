"""The damped pseudo-inverse of one level on its free directions, in kernels: the linear
algebra of the projection backend (:mod:`wholebody.solvers.projection` documents the method).

A level's rows ``A`` act on the free directions the levels above leave (:data:`Free`): the
orthonormal basis ``Zb`` of them is either the columns ``Z`` (``is_mask`` False) or the
coordinate axes of the joints in ``mask`` (``is_mask``: while no direction but whole joints
was removed). :func:`level_step` takes the least-squares step ``Zb M^+_damped R`` of ``M = A
Zb`` by the cheapest route that is exact: a certified Cholesky of ``M M^T`` (no singular value
below the damping threshold: no damping, every direction used), the normal equations of a
tall well-conditioned ``M``, or else the eigen-decomposition of ``M M^T`` (the fast path) or
the SVD (in saturation), where the directions below the threshold are damped one by one and
those below the rank floor dropped; it returns what the level leaves free for the next.

After a certified Cholesky of ``M M^T = L L^T`` the free directions left are ``{Zb y : M y =
0}``, the complement of the orthonormal rows ``B = L^-1 M``: they are kept in that form, and
their basis (:func:`basis`, a QR factorisation) is built only for a level below that needs
one. A level whose rows are ``s I`` (objectives, or a posture task in a uniform metric) needs
only the projection ``F d = Zb (c - B^T B c)``, ``c = Zb^T d`` (:func:`project_free`).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.lapack import gesdd, potrf, syevd
from wholebody.kernels.linalg import (
    NORMAL_KAPPA,
    cholesky_inverse,
    combine,
    complement_solve,
    diagonal,
    fortran,
    frobenius2,
    gram_cols,
    gram_rows,
    mm,
    mtm,
    mtv,
    mv,
    normal_solve,
    null_basis,
    scatter_rows,
    trace,
)

__all__ = [
    "Free",
    "basis",
    "diagonal_step",
    "free_of",
    "free_rank",
    "identity_rows",
    "level_step",
    "lift",
    "project_free",
    "restrict",
    "row_norm2",
]

_EPS = 2.220446049250313e-16
FIXED = 1e-18  # F_jj at or below this: joint j does not move along the free directions
# par: the solver's settings
PAR_DAMPING, PAR_THRESHOLD, PAR_RANK, PAR_TOLERANCE, PAR_SATURATE = 0, 1, 2, 3, 4
PAR_WIDTH = 5

Free = namedtuple("Free", ["Z", "is_mask", "mask", "M", "H"])
"""The free directions the levels above leave: those of ``Zb``, the columns of ``Z`` (n x r)
or where ``is_mask`` the coordinate axes of the joints in ``mask`` (n entries either way),
less, where ``M`` (m x r) has rows, those ``Zb y`` with ``M y = 0``; ``H = L^-1`` (m x m,
Fortran-ordered) for the Cholesky factor ``M M^T = L L^T``, so that ``H M`` has orthonormal
rows."""


@kernel
def _damping(s: float, eps: float, lam: float) -> float:
    """``mu = (1 - (s / eps)^2) lambda_max^2`` where ``s < eps``, else 0."""
    x = s / eps
    return max(1.0 - x * x, 0.0) * lam * lam


@kernel
def _damped_solve(
    Vt: np.ndarray,
    U: np.ndarray,
    s: np.ndarray,
    squared: bool,
    keep: np.ndarray,
    R: np.ndarray,
    eps: float,
    lam: float,
) -> np.ndarray:
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
def _gram_step(
    M: np.ndarray, R: np.ndarray, tall: bool, exact: bool, eps: float, lam: float, rank_tol: float
) -> tuple[np.ndarray, np.ndarray]:
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
    E = fortran(gram_rows(M))
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
def _solve_ls(
    M: np.ndarray, R: np.ndarray, eps: float, lam: float, rank_tol: float
) -> tuple[np.ndarray, np.ndarray, int]:
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


@kernel
def free_of(Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> Free:
    """The free directions ``Zb`` (see :data:`Free`), nothing removed from them."""
    return Free(Z, is_mask, mask, np.zeros((0, 0)), np.zeros((0, 0)).T)


@kernel
def _basis_rank(Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> int:
    """How many directions ``Zb`` has: the mask's count, or Z's columns."""
    if not is_mask:
        return Z.shape[1]
    r = 0
    for j in range(mask.shape[0]):
        r += mask[j]
    return r


@kernel
def free_rank(free: Free) -> int:
    """How many free directions there are: those of ``Zb`` less the rows of ``M``."""
    return _basis_rank(free.Z, free.is_mask, free.mask) - free.M.shape[0]


@kernel
def restrict(A: np.ndarray, Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> np.ndarray:
    """``A Zb`` (m x r) for the orthonormal basis ``Zb`` of the free directions: the mask's
    columns of A in order, or ``A Z``."""
    if not is_mask:
        return mm(A, Z)
    m = A.shape[0]
    out = np.empty((m, _basis_rank(Z, is_mask, mask)))
    c = 0
    for j in range(mask.shape[0]):
        if mask[j]:
            for i in range(m):
                out[i, c] = A[i, j]
            c += 1
    return out


@kernel
def lift(Y: np.ndarray, Z: np.ndarray, is_mask: bool, mask: np.ndarray) -> np.ndarray:
    """``Zb Y`` (n x k) for coordinates ``Y`` (r x k) on the free directions: Y's rows
    placed at the mask's joints, or ``Z Y``."""
    if not is_mask:
        return mm(Z, Y)
    return scatter_rows(Y, mask)


@kernel
def basis(free: Free) -> Free:
    """The free directions as an orthonormal basis (or mask): ``Zb N``, ``N`` the null-space
    basis of ``M`` (where ``M`` has rows; else ``free`` itself)."""
    if free.M.shape[0] == 0:
        return free
    Z = lift(null_basis(free.M), free.Z, free.is_mask, free.mask)
    return free_of(Z, False, free.mask)


@kernel
def project_free(d: np.ndarray, free: Free) -> np.ndarray:
    """``F d``: ``d`` projected on the free directions, ``Zb Zb^T d`` less, where ``M`` has
    rows, ``Zb B^T B Zb^T d`` with ``B = H M`` (its rows orthonormal)."""
    Z, is_mask, mask, M, H = free.Z, free.is_mask, free.mask, free.M, free.H
    if M.shape[0] and free_rank(free) == 0:  # (the rows take every direction: exactly 0)
        return np.zeros(d.shape[0])
    if M.shape[0] == 0:
        if not is_mask:
            return mv(Z, mtv(Z, d))
        out = np.zeros(d.shape[0])
        for j in range(d.shape[0]):
            if mask[j]:
                out[j] = d[j]
        return out
    c = mtv(Z, d) if not is_mask else _gather(d, mask)
    for _ in range(2):  # twice: the computed B has orthonormal rows to kappa(M)^2 eps only
        t = mtv(H, mv(H, mv(M, c)))  # B^T B c = M^T H^T H M c
        c = combine(c, -1.0, mtv(M, t))
    return mv(Z, c) if not is_mask else _scatter(c, mask)


@kernel
def _gather(d: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The entries of ``d`` where ``mask``, in order."""
    count = 0
    for j in range(mask.shape[0]):
        count += mask[j]
    out = np.empty(count)
    c = 0
    for j in range(mask.shape[0]):
        if mask[j]:
            out[c] = d[j]
            c += 1
    return out


@kernel
def _scatter(c: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_gather`, zeros elsewhere."""
    out = np.zeros(mask.shape[0])
    k = 0
    for j in range(mask.shape[0]):
        if mask[j]:
            out[j] = c[k]
            k += 1
    return out


@kernel
def row_norm2(Z: np.ndarray, j: int) -> float:
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
        if row_norm2(Z, j) <= FIXED:
            if out is Z:
                out = Z.copy()
            out[j, :] = 0.0
    return out


@kernel
def _certify_wide(M: np.ndarray, eps: float, rank_tol: float):
    """The reference's certificate of ``G = M M^T`` (m x m): ``(ok, L^-1)``."""
    dummy = np.zeros((0, 0)).T
    G = gram_rows(M)
    if G.shape[0] == 0 or eps * eps <= (rank_tol**2) * max(1.0, trace(G)):
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
    G = gram_cols(M)
    ok, Linv = cholesky_inverse(G)
    if not ok or not _exceeds(G, Linv, eps):
        return False, dummy, 0.0
    k2 = frobenius2(Linv) * trace(G)
    if k2 > NORMAL_KAPPA * NORMAL_KAPPA:
        return False, dummy, 0.0
    return True, Linv, k2


@kernel
def _exceeds(G: np.ndarray, Linv: np.ndarray, eps: float) -> bool:
    """``lambda_min(G) >= eps^2``: ``tr(G^-1) <= 1 / eps^2``, or else ``G - eps^2 I`` has a
    Cholesky factor (the reference's two tests)."""
    if frobenius2(Linv) * eps * eps <= 1.0:
        return True
    S = fortran(G)
    for k in range(S.shape[0]):
        S[k, k] -= eps**2
    return potrf(S, True) == 0


@kernel
def level_step(A: np.ndarray, R: np.ndarray, free: Free, par: np.ndarray, sns: bool):
    """A level's least-squares step on its free directions (``free``: a basis or mask, see
    :func:`basis`), ``Zb`` (n x r): ``(Y, left, rank)`` with ``Y = Zb M^+_damped R`` (``M =
    A Zb``, R: m x k), the free directions the level leaves (a complement after the certified
    Cholesky of ``M M^T``, none after the normal equations, else the basis of the directions
    unused) and the rank the reference reports.

    The route is the reference's: its certified Cholesky where it certifies (``G = M M^T``,
    m <= r; ``M^T M`` when the level has more rows than nu and nothing is fixed), else its
    eigen-decomposition (``_gram_step``) or, in SNS (``sns``), its damped SVD
    (``_solve_ls``), each on ``M`` instead of ``A F`` (the same singular values and
    directions). Before those, where ``M`` is tall, a certificate on ``M^T M`` (no direction
    damped or dropped, well conditioned) takes the normal equations, which is what those
    routes then compute, at a fraction of the cost."""
    eps, lam, rank_tol = par[PAR_THRESHOLD], par[PAR_DAMPING], par[PAR_RANK]
    Z, is_mask, mask = free.Z, free.is_mask, free.mask
    n, m = mask.shape[0], A.shape[0]
    r = free_rank(free)
    if r == 0:  # nothing left to move (the reference's routes all give 0)
        return np.zeros((n, R.shape[1])), _none(mask), 0
    M = restrict(A, Z, is_mask, mask)
    if m <= n and m <= r:  # the reference certifies G = M M^T
        ok, Linv = _certify_wide(M, eps, rank_tol)
        if ok:
            Y = lift(mtm(M, mtm(Linv, mm(Linv, R))), Z, is_mask, mask)
            return Y, Free(Z, is_mask, mask, M, Linv), m
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
            return lift(normal_solve(M, Linv, R, k2), Z, is_mask, mask), _none(mask), r
    if sns:
        Y, Nf, rank = _solve_ls(M, R, eps, lam, rank_tol)
    else:
        Y, Nf = _gram_step(M, R, tall_ref, is_mask, eps, lam, rank_tol)
        rank = 0
    left = free_of(lift(Nf, Z, is_mask, mask), False, mask)
    return lift(Y, Z, is_mask, mask), left, rank


@kernel
def diagonal_step(A: np.ndarray, c: np.ndarray, free: Free, par: np.ndarray):
    """A diagonal level (n x n: a posture in its metric) on the free directions a certified
    level left (``M`` with rows, ``Zb`` the mask's axes): ``(ok, dx)``, the least-squares step
    ``dx`` (n) for the right-hand side ``c`` by
    :func:`~wholebody.kernels.linalg.complement_solve`, without the basis :func:`level_step`
    would build. Ok only where :func:`level_step`'s certificate of the normal equations holds
    for it (on the free directions ``A Zb N`` has singular values in ``[min |a|, max |a|]``
    over the mask: no direction damped or dropped, ``kappa_F <= NORMAL_KAPPA``), so that the
    step is the one it computes."""
    is_mask, mask, M = free.is_mask, free.mask, free.M
    n = mask.shape[0]
    r = free_rank(free)
    dx = np.zeros(n)
    if not is_mask or M.shape[0] == 0 or r == 0 or A.shape[0] != n:
        return False, dx
    ok, diag = diagonal(A)
    if not ok:
        return False, dx
    a, cm = _gather(diag, mask), _gather(c, mask)
    top, amin2 = 0.0, math.inf
    for k in range(a.shape[0]):
        top, amin2 = top + a[k] * a[k], min(amin2, a[k] * a[k])
    eps, rank_tol = par[PAR_THRESHOLD], par[PAR_RANK]
    floor = max((rank_tol * max(1.0, math.sqrt(top))) ** 2, 10.0 * n * _EPS * top)
    kappa2 = r * r * top / amin2 if amin2 > 0 else math.inf
    if not (amin2 >= eps * eps > floor and kappa2 <= NORMAL_KAPPA * NORMAL_KAPPA):
        return False, dx
    ok, step = complement_solve(M, a, cm)
    return ok, _scatter(step, mask)


@kernel
def _none(mask: np.ndarray) -> Free:
    """No free direction (an empty basis)."""
    return free_of(np.zeros((mask.shape[0], 0)), False, mask)


@kernel
def identity_rows(A: np.ndarray, scale: float, par: np.ndarray) -> float:
    """``s`` where the rows ``scale A`` are ``s I`` (n x n) and every certificate of
    :func:`level_step` holds for them on any free directions by a margin of 2 (on ``r <= n``
    orthonormal directions ``M = s Zb``, all singular values ``s``: ``s^2 >= 2 eps^2``, ``eps^2
    > 2 floor``, ``kappa_F^2 = r^2 <= NORMAL_KAPPA^2``), else 0. Such a level is solved
    without damping on all its free directions, ``Zb (s Zb)^+ R = F R / s``, and leaves none:
    the step of an objectives' level (a posture task in a uniform metric)."""
    n = A.shape[1]
    if A.shape[0] != n or n == 0 or n > NORMAL_KAPPA:
        return 0.0
    ok, a = diagonal(A)  # (A itself a I: then scale A is s I)
    for i in range(n):
        ok = ok and a[i] == a[0]
    if not ok:
        return 0.0
    s = scale * a[0]
    eps, rank_tol = par[PAR_THRESHOLD], par[PAR_RANK]
    floor = max((rank_tol * max(1.0, s * math.sqrt(n))) ** 2, 10.0 * n * n * _EPS * s * s)
    if not (0.0 < s < math.inf and s * s >= 2.0 * eps * eps and eps * eps > 2.0 * floor):
        return 0.0
    return s
