r"""The solvers' linear algebra: least squares with a rank rule, certified, on small dense
matrices.

Both Python references use it (:mod:`wholebody.solvers.projection` and the HQP's cascade,
:mod:`wholebody.solvers.cascade`); the compiled kernels (:mod:`wholebody.kernels.linalg`)
implement the same routines. Every routine makes one decision the solvers rely on, a
*rank*, and the fast routes are taken only where a certificate proves that the slow route
would decide the same.

Complete orthogonal decomposition (the HQP)
-------------------------------------------
:func:`cod` gives the minimum-norm least-squares step of a level in the free directions,
``y = M^+ c`` (plus the step to the minimum-norm point in the level's own null space), from a
QR with column pivoting of ``M^T`` (LAPACK ``dgeqp3`` + ``dorgqr``, cheaper than an SVD);
diagonal entries ``|R_ii| <= max(rtol |R_00|, floor)`` count as zero. A tall ``M`` (more rows
than free directions) that a certificate (:func:`rank_certificate`) proves to have full
column rank under that rule skips the pivoted QR: it is solved by its normal equations
(:func:`certified_normal_solve`, where ``kappa_F <= NORMAL_KAPPA``) or by ``dgels``.
:func:`null_space` is the basis of what a set of rows leaves free, by the same rule.

Certified Cholesky (the projection)
-----------------------------------
:func:`certified_gram` factors the Gram matrix ``G = B B^T`` (``B^T B`` for a tall ``B``) of a
level's rows by Cholesky, ``G = L L^T``, and keeps it only when ``lambda_min(G) >= eps^2``
is certain: then no direction needs damping and every direction counts, so
``B^+ r = B^T G^-1 r`` exactly. Otherwise :func:`damped_svd_solve` and
:func:`damped_gram_step` damp each singular direction below ``eps`` with the variable factor
``(1 - (s_i/eps)^2) lambda_max^2`` (:func:`variable_damping`) and decide the rank.

Normal equations
----------------
A tall ``M`` (m x n, full column rank) with the Cholesky factor of ``M^T M`` is solved by
``y = (M^T M)^-1 M^T c`` (:func:`normal_solve`), refined once where the condition bound
``kappa_F = ||R^-1||_F ||M||_F`` exceeds ``REFINE_KAPPA``: a few small products, where LAPACK's
QR routines spend their time in per-column BLAS calls.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack as _lapack

from wholebody._numeric import count_nonzero as _count_nonzero

__all__ = [
    "NORMAL_KAPPA",
    "REFINE_KAPPA",
    "Gram",
    "certified_gram",
    "certified_normal_solve",
    "cod",
    "damped_gram_step",
    "damped_svd_solve",
    "full_column_rank",
    "full_row_rank",
    "identity",
    "normal_solve",
    "null_space",
    "pivot_norm",
    "rank_certificate",
    "variable_damping",
]

NORMAL_KAPPA = 1e4
"""Largest condition bound ``kappa_F`` for which a solver may use a tall level's normal
equations (:func:`normal_solve`) instead of a QR or an SVD."""
REFINE_KAPPA = 1e3
"""Above this ``kappa_F``, :func:`normal_solve` refines its answer once."""
CERTIFY_MARGIN = 1e3
"""Safety factor of the rank certificates (against round-off in their own arithmetic)."""

_EPS = float(np.finfo(float).eps)

# LAPACK through scipy's thin wrappers (no argument checking of scipy.linalg's front ends)
_geqp3, _orgqr, _gels, _trtrs = (getattr(_lapack, f) for f in ("dgeqp3", "dorgqr", "dgels",
                                                                  "dtrtrs"))  # fmt: skip
_trtri, _potrf = _lapack.dtrtri, _lapack.dpotrf


# ------------------------------------------------------------------ normal equations
def normal_solve(M: np.ndarray, H: np.ndarray, c: np.ndarray, kappa2: float) -> np.ndarray:
    """The least-squares solution of a tall ``M`` (m x n, full column rank) from ``H`` with
    ``(M^T M)^-1 = H^T H`` (``H = L^-1`` for the Cholesky factor ``M^T M = L L^T``):
    ``y = H^T H M^T c`` (``c``: (m,) or (m, k)), refined once where ``kappa2``, the squared
    condition bound ``kappa_F^2`` of ``M``, exceeds ``REFINE_KAPPA^2``.

    Relative error: up to about ``kappa_F^2 eps`` unrefined, below 2.2e-10 for
    ``kappa_F <= 1e3``; refined, a few 1e-11 at worst (a QR reaches 1e-13), far below the
    solvers' tolerances of 1e-8 and up."""
    Ht, Mt = H.T, M.T
    y = Ht.dot(H.dot(Mt.dot(c)))
    if kappa2 > REFINE_KAPPA * REFINE_KAPPA:
        y += Ht.dot(H.dot(Mt.dot(c - M.dot(y))))
    return y


def certified_normal_solve(M: np.ndarray, c: np.ndarray, rtol: float, floor: float = 0.0
                           ) -> np.ndarray | None:  # fmt: skip
    """The least-squares solution of a tall ``M`` (m x r, m > r) by its normal equations,
    where they are accurate and the rank rule of :func:`cod` certainly finds full column
    rank; None otherwise (the caller then uses a QR of ``M``).

    Cholesky ``M^T M = U^T U`` (U is the R of ``M = Q R`` up to the signs of its rows) and
    ``U^-1``; ``kappa_F = ||U^-1||_F ||M||_F`` bounds the condition number of ``M`` from
    above. Certified by :func:`rank_certificate` (with ``U`` for ``R``), used only when
    ``kappa_F <= NORMAL_KAPPA`` and solved by :func:`normal_solve`: cheaper than ``dgels``
    with its certificate.
    """
    U, info = _potrf(M.T.dot(M))
    if info != 0:
        return None
    Ui, info = _trtri(U, lower=0)
    if info != 0:
        return None
    k2 = rank_certificate(M, Ui, rtol, floor)
    if k2 is None or not k2 <= NORMAL_KAPPA * NORMAL_KAPPA:
        return None
    return normal_solve(M, Ui.T, c, k2)  # (M^T M)^-1 = U^-1 U^-T


# ------------------------------------------------------------------ rank certificates
def rank_certificate(M: np.ndarray, Rinv: np.ndarray, rtol: float,
                     floor: float = 0.0) -> float | None:  # fmt: skip
    """``kappa_F^2 = ||R^-1||_F^2 ||M||_F^2`` when the rank rule of :func:`cod`
    (``|R_ii| > rtol |R_00|`` in the pivoted QR of ``M^T``) is certain to find full column
    rank for a tall ``M`` (m x r, m > r) with ``M^T M = R^T R`` (``Rinv = R^-1``), else None.

    In the pivoted QR of ``M^T`` (columns: the m rows of M), ``|R_ii|`` is the largest column
    norm of the trailing block, whose 2-norm is at least ``sigma_r(M)`` (a rank-i matrix is at
    least that far from ``M^T``), so ``|R_ii| >= sigma_r / sqrt(m)``; ``|R_00|`` is a column
    norm, at most ``||M||_F``; and ``sigma_r(M) = sigma_min(R) >= 1 / ||R^-1||_F``. Hence full
    rank when ``||R^-1||_F ||M||_F sqrt(m) rtol < 1``, here with the margin
    ``CERTIFY_MARGIN``; and every ``|R_ii| > floor`` when ``||R^-1||_F sqrt(m) floor < 1``.
    """
    fi = Rinv.ravel(order="K")
    fm = M.ravel(order="K")
    inv2 = fi.dot(fi)  # >= 1 / sigma_r^2
    k2 = inv2 * fm.dot(fm)
    m = M.shape[0]  # (m inv2 >= 1 / |R_ii|^2 for every pivot of the rule)
    margin = CERTIFY_MARGIN * rtol
    if k2 * m * margin * margin < 1.0 and inv2 * m * floor * floor < 1.0:
        return k2
    return None


def full_column_rank(M: np.ndarray, lqr: np.ndarray, rtol: float, floor: float = 0.0) -> bool:
    """Whether the rank rule of :func:`cod` is certain to find full column rank, from the
    unpivoted QR ``M = Q R`` in ``lqr`` (``dgels``'s output) of a tall ``M`` (m x r, m > r);
    see :func:`rank_certificate`."""
    r = M.shape[1]
    Rinv, info = _trtri(lqr[:r, :r], lower=0)
    return info == 0 and rank_certificate(M, Rinv, rtol, floor) is not None


def full_row_rank(Nz: np.ndarray, rtol: float, floor: float) -> bool:
    """Whether ``Nz`` (q x r, q <= r) certainly has q singular values above
    ``max(rtol s_max, floor)``: with ``Nz Nz^T = L L^T``, ``sigma_min >= 1 / ||L^-1||_F`` and
    ``s_max <= ||Nz||_F``, so it does when ``||L^-1||_F ||Nz||_F rtol`` and
    ``||L^-1||_F floor`` are below 1, here with the margin ``CERTIFY_MARGIN``."""
    L, info = _potrf(Nz.dot(Nz.T), lower=1)
    if info != 0:
        return False
    Li, info = _trtri(L, lower=1)
    if info != 0:
        return False
    fi, fn = Li.ravel(), Nz.ravel()
    inv2 = fi.dot(fi)
    margin = CERTIFY_MARGIN * rtol
    return bool(inv2 * fn.dot(fn) * margin * margin < 1.0
                and inv2 * (CERTIFY_MARGIN * floor) ** 2 < 1.0)  # fmt: skip


# ------------------------------------------------------------------ complete orthogonal
def cod(
    M: np.ndarray, c: np.ndarray, t: np.ndarray, rtol: float, floor: float = 0.0
) -> tuple[int, np.ndarray, np.ndarray | None, float | None]:
    """Minimum-norm least squares with a rank threshold, by a complete orthogonal
    decomposition (LAPACK ``dgeqp3`` + ``dorgqr``).

    ``M^T P = Q R`` (QR with column pivoting of ``M^T``, Q square); the rank is the number of
    ``|R_ii| > max(rtol |R_00|, floor)`` (``floor``: the size below which a row of ``M`` is
    round-off, e.g. a level's rows projected on directions they do not move); ``Q_1`` spans
    ``M``'s row space and ``Q_2`` its null space. Returns
    ``(rank, y, Q_2 or None when rank = r, |R_00|)`` with ``y = Q_1 a - Q_2 Q_2^T t``, ``a`` the
    least-squares solution of ``R_1^T a = P^T c``: ``M y`` is the best fit of ``c``, and among
    the ``y`` that achieve it, ``t + y`` has the smallest norm. When ``M`` has full column
    rank (``rank = r < m``), ``y`` is its unique least-squares solution, solved by ``dgels``
    on ``M`` itself (no ``Q`` needed).

    A tall ``M`` (``m > r``) that is certified to have full column rank under the rule (see
    :func:`full_column_rank`) skips the pivoted QR: then ``|R_00|`` is returned as None (the
    caller computes it with :func:`pivot_norm` when it needs it). A well-conditioned one is
    solved by its normal equations (:func:`certified_normal_solve`), otherwise by ``dgels``.

    Raises :class:`numpy.linalg.LinAlgError` when LAPACK reports an error.
    """
    m, r = M.shape
    tall: np.ndarray | None = None  # M's least-squares solution when M is tall (m > r)
    if m > r > 0:
        certified, tall = _tall_least_squares(M, c, rtol, floor)
        if certified:
            return r, tall, None, None
    k = min(m, r)
    qr, jpvt, tau, _, info = _geqp3(M.T, lwork=8 * (m + 1))
    if info != 0:
        raise np.linalg.LinAlgError(f"dgeqp3 info {info}")
    smax, rank = _rank_rule(qr, k, rtol, floor)
    if rank == r and tall is not None:  # full column rank, more rows: the unique solution
        return rank, tall, None, smax  # (no dgels answer: an exactly singular R, path below)
    Q = _orthogonal_factor(qr, tau, k, r)
    y = _row_space_step(qr, jpvt, Q, c, rank, m, r)
    if rank == r:
        return rank, y, None, smax
    Q2 = Q[:, rank:]
    if _count_nonzero(t):  # (t = 0: nothing to remove, often at the first level)
        y -= Q2.dot(Q2.T.dot(t))
    return rank, y, Q2, smax


def _tall_least_squares(M: np.ndarray, c: np.ndarray, rtol: float,
                        floor: float) -> tuple[bool, np.ndarray | None]:  # fmt: skip
    """For a tall ``M`` (m > r): ``(True, y)`` when full column rank is certified (``y`` its
    least-squares solution, by the normal equations or ``dgels``), else ``(False, y)`` with
    ``dgels``'s answer (None if it failed), which :func:`cod` still uses when the pivoted QR
    finds full rank."""
    y = certified_normal_solve(M, c, rtol, floor)
    if y is not None:
        return True, y
    lqr, z, info = _gels(M, c)
    if info != 0:
        return False, None
    return full_column_rank(M, lqr, rtol, floor), z[: M.shape[1]]


def _rank_rule(qr: np.ndarray, k: int, rtol: float, floor: float) -> tuple[float, int]:
    """``(|R_00|, rank)`` from the diagonal of the pivoted QR (its first ``k`` entries): the
    number of ``|R_ii| > max(rtol |R_00|, floor)``, 0 when ``|R_00| <= floor``."""
    if not k:
        return 0.0, 0
    diag = qr.diagonal()[:k].tolist()
    smax = abs(diag[0])
    if not smax > floor:
        return smax, 0
    thr = max(rtol * smax, floor)
    rank = 0
    for v in diag:  # |R_ii| is non-increasing, but count every one like the rule
        if abs(v) > thr:
            rank += 1
    return smax, rank


def _orthogonal_factor(qr: np.ndarray, tau: np.ndarray, k: int, r: int) -> np.ndarray:
    """The square ``Q`` (r x r) of the pivoted QR of ``M^T`` from ``dgeqp3``'s reflectors."""
    if k < r:
        a = np.zeros((r, r), order="F")
        a[:, :k] = qr[:, :k]
        Q, _, info = _orgqr(a, tau[:k], lwork=8 * r, overwrite_a=1)  # a is ours
    else:
        Q, _, info = _orgqr(qr[:, :r], tau[:k], lwork=8 * r)
    if info != 0:
        raise np.linalg.LinAlgError(f"dorgqr info {info}")
    return Q


def _row_space_step(qr: np.ndarray, jpvt: np.ndarray, Q: np.ndarray, c: np.ndarray,
                    rank: int, m: int, r: int) -> np.ndarray:  # fmt: skip
    """``y = Q_1 a``, ``a`` the least-squares solution of ``R_1^T a = P^T c`` (triangular when
    the rank is the number of rows ``m``, else lower-trapezoidal, by ``dgels``)."""
    if not rank:
        return np.zeros(r)
    cp = c.take(jpvt - 1)
    if rank == m:  # R_11^T a = P^T c, triangular
        z, info = _trtrs(qr[:rank, :rank], cp, lower=0, trans=1)
    else:  # (m x rank) lower-trapezoidal least squares
        R1t = qr[:rank].T * _lower_mask(m, rank)
        _, z, info = _gels(R1t, cp)
        z = z[:rank]
    if info != 0:
        raise np.linalg.LinAlgError(f"triangular solve info {info}")
    return Q[:, :rank].dot(z)


def pivot_norm(M: np.ndarray) -> float:
    """``|R_00|`` of the pivoted QR of ``M^T`` (what :func:`cod` returns as its last value),
    the largest row norm of ``M``."""
    if not min(M.shape):
        return 0.0
    qr, _, _, _, info = _geqp3(M.T, lwork=8 * (M.shape[0] + 1))
    if info != 0:
        return 0.0
    return abs(float(qr[0, 0]))


def null_space(Nz: np.ndarray, Z: np.ndarray | None, rank_tolerance: float,
               floor: float = 0.0) -> np.ndarray:  # fmt: skip
    """Basis of ``{Z y : Nz y = 0}`` (``Z = None``: the identity); singular values at most
    ``max(rank_tolerance s_max, floor)`` count as zero (``floor``: the size of a row of
    ``Nz`` that is round-off, a constraint on directions it does not move).

    Where that rule certainly keeps every row (:func:`full_row_rank`), the basis is the
    complement of the rows from the complete QR of ``Nz^T``, the same subspace as the SVD's
    at a fraction of its cost."""
    q, r = Nz.shape
    if 0 < q <= r and full_row_rank(Nz, rank_tolerance, floor):
        V2 = np.linalg.qr(Nz.T, mode="complete")[0][:, q:]
        return V2 if Z is None else Z.dot(V2)
    _, S, Vt = np.linalg.svd(Nz, full_matrices=True)
    thr = max(rank_tolerance * S[0], floor) if S.size else 0.0
    rank = int(np.count_nonzero(thr < S)) if S.size and S[0] > floor else 0
    V2 = Vt[rank:].T
    return V2 if Z is None else Z.dot(V2)


_MASKS: dict[tuple[int, int], np.ndarray] = {}


def _lower_mask(m: int, k: int) -> np.ndarray:
    """Cached ``(m, k)`` lower-trapezoidal mask of ones."""
    mask = _MASKS.get((m, k))
    if mask is None:
        mask = _MASKS[(m, k)] = np.tril(np.ones((m, k)))
    return mask


# ------------------------------------------------------------------ damped least squares
class Gram:
    """The Gram matrix ``G`` of a level's rows restricted to its free directions, ``B``
    (m x n), certified well conditioned (:func:`certified_gram`): ``G = B B^T`` when
    ``m <= n`` (``W = L^-1 B``), ``G = B^T B`` when B is tall (``m > n``, full column rank;
    ``W`` None); ``L`` its Cholesky factor, ``Linv = L^-1``; ``rank`` = min(m, n)."""

    __slots__ = ("B", "Linv", "W", "kappa2", "rank")

    def __init__(self, B: np.ndarray, Linv: np.ndarray, W: np.ndarray | None,
                 kappa2: float = 0.0) -> None:  # fmt: skip
        self.B, self.Linv, self.W, self.kappa2 = B, Linv, W, kappa2
        self.rank = min(B.shape)

    def solve(self, r: np.ndarray) -> np.ndarray:
        """``B^+ r`` (r: (m,) or (m, k)): ``B^T G^-1 r``, or for a tall B its least-squares
        solution ``G^-1 B^T r`` (:func:`normal_solve`)."""
        if self.W is not None:
            return self.W.T.dot(self.Linv.dot(r))
        return normal_solve(self.B, self.Linv, r, self.kappa2)

    def used(self) -> np.ndarray:
        """``B^+ B``: the projector onto the directions the level uses (all of them when B is
        tall)."""
        if self.W is None:
            return identity(self.B.shape[1])
        return self.W.T.dot(self.W)


def certified_gram(B: np.ndarray, eps: float, rank_tolerance: float) -> Gram | None:
    """The Cholesky route for ``B`` (m x n) when its Gram matrix ``G`` (``B B^T``, or
    ``B^T B`` for a tall B) is certified to need neither damping nor a rank decision, else
    None.

    ``G = L L^T``; ``lambda_min(G) >= eps^2`` because ``trace(G^-1) = ||L^-1||_F^2 <= 1/eps^2``
    or, where that bound is too loose, because ``G - eps^2 I`` has a Cholesky factor too
    (exact up to rounding, where the damping is 0 anyway); and every eigenvalue counts as a
    rank (``eps > rank_tolerance max(1, sqrt(trace(G)))``). Then ``B^+ r = B^T G^-1 r`` and
    ``B^+ B = B^T G^-1 B`` exactly, from ``W = L^-1 B``. A tall B must also have
    ``kappa_F = sqrt(trace(G) trace(G^-1)) <= NORMAL_KAPPA`` (its normal equations lose
    ``kappa^2 eps``; refined once above ``REFINE_KAPPA``)."""
    m, n = B.shape
    if m == 0:
        return None
    tall = m > n
    G = B.T.dot(B) if tall else B.dot(B.T)
    top = float(G.trace())
    # every eigenvalue is kept as a rank (rule: lambda > (rank_tolerance max(1, s_max))^2,
    # s_max^2 <= trace(G))
    if eps * eps <= (rank_tolerance**2) * max(1.0, top):
        return None
    L, info = _potrf(G, lower=1, clean=1)
    if info != 0:
        return None
    Linv, info = _trtri(L, lower=1)
    if info != 0:
        return None
    flat = Linv.ravel()
    inv = float(flat.dot(flat))  # trace(G^-1) >= 1 / lambda_min(G)
    if inv * eps * eps > 1.0:  # the bound does not settle it: the exact test
        G -= _shift(G.shape[0], eps)  # G - eps^2 I (G is not needed any more)
        if _potrf(G, lower=1, clean=0, overwrite_a=1)[1] != 0:  # lambda_min(G) < eps^2
            return None
    if tall:
        k2 = inv * top  # kappa_F^2 = trace(G^-1) trace(G)
        if k2 > NORMAL_KAPPA * NORMAL_KAPPA:
            return None
        return Gram(B, Linv, None, k2)
    return Gram(B, Linv, Linv.dot(B))


def variable_damping(s: np.ndarray, eps: float, lambda_max: float) -> np.ndarray:
    """The damping ``mu_i = (1 - (s_i / eps)^2) lambda_max^2`` of each direction whose
    singular value ``s_i`` is below ``eps``, 0 for the others (Chiaverini's variable factor,
    direction by direction)."""
    x = s * (1.0 / eps)
    x *= x
    np.subtract(1.0, x, out=x)
    np.maximum(x, 0.0, out=x)
    x *= lambda_max**2
    return x


def damped_svd_solve(M: np.ndarray, r: np.ndarray, eps: float, lambda_max: float,
                     rank_tolerance: float, damped: bool = True,
                     ) -> tuple[np.ndarray, np.ndarray, int]:  # fmt: skip
    """Damped least squares ``y = M^+_damped r`` (r: (m,) or (m, k)), the null-space basis
    of M and its rank, from the SVD; singular values at most
    ``rank_tolerance max(1, s_max)`` count as zero."""
    n = M.shape[1]
    if M.shape[0] == 0 or n == 0:
        return np.zeros((n, *r.shape[1:])), np.eye(n), 0
    U, s, Vt = np.linalg.svd(M, full_matrices=True)
    smax = s[0] if s.size else 0.0
    rank = int(np.sum(s > rank_tolerance * max(1.0, smax)))
    sr = s[:rank]
    inv = sr / (sr * sr + variable_damping(sr, eps, lambda_max)) if damped else 1.0 / sr
    c = U[:, :rank].T @ r
    y = Vt[:rank].T @ (inv[:, None] * c if c.ndim == 2 else inv * c)
    return y, Vt[rank:].T, rank


def damped_gram_step(M: np.ndarray, r: np.ndarray, eps: float, lambda_max: float,
                     rank_tolerance: float, exact: bool = False,
                     ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``M^+_damped r`` and the exact projector ``M^+ M`` (from the eigen-decomposition
    of ``M M^T``, or the SVD of a tall M).

    An eigenvalue of ``M M^T`` counts as zero below the rank tolerance or below the
    eigen-solver's round-off, ``10 m eps_mach lambda_max``, whichever is larger: a level
    with more rows than columns (``m > n``) has ``m - n`` exact zeros that come out as
    +-1e-16, and counting them as directions would put round-off into the projector.

    A tall M goes through its own SVD instead (n x n work, not m x m), with the same
    rule on ``s^2``; except where ``exact`` says that M's columns are the level's rows
    themselves (no computed projector of the levels above): there only the rank tolerance
    applies, because ``M M^T`` squares the condition number and the round-off floor would
    drop genuine directions of an ill-conditioned level. Below a computed projector the
    floor stays: its round-off leaves tiny singular values in M where 0 is exact, which
    would otherwise count as directions of the level."""
    m, n = M.shape
    if m > n:
        U, sv, Vt = np.linalg.svd(M, full_matrices=False)
        top = float(sv[0]) ** 2 if n else 0.0
        floor = (rank_tolerance * max(1.0, math.sqrt(top))) ** 2
        if not exact:
            floor = max(floor, 10.0 * m * _EPS * top)
        keep = sv * sv > floor
        s_r = sv[keep]
        V_r = Vt[keep].T
        damping = variable_damping(s_r, eps, lambda_max)
        return (V_r.dot((U[:, keep].T.dot(r)) * (s_r / (s_r * s_r + damping))),
                V_r.dot(V_r.T))  # fmt: skip
    lam, U = np.linalg.eigh(M @ M.T)
    top = max(float(lam[-1]), 0.0) if lam.size else 0.0
    floor = max((rank_tolerance * max(1.0, math.sqrt(top))) ** 2,
                10.0 * lam.size * _EPS * top)  # fmt: skip
    keep = lam > floor
    lam_r, U_r = lam[keep], U[:, keep]
    MtU = M.T @ U_r
    y = MtU @ ((U_r.T @ r) / (lam_r + variable_damping(np.sqrt(lam_r), eps, lambda_max)))
    return y, (MtU / lam_r) @ MtU.T


_EYES: dict[int, np.ndarray] = {}
_SHIFTS: dict[tuple[int, float], np.ndarray] = {}


def identity(n: int) -> np.ndarray:
    """The identity (n x n), cached, read-only."""
    eye = _EYES.get(n)
    if eye is None:
        eye = _EYES[n] = np.eye(n)
        eye.setflags(write=False)
    return eye


def _shift(k: int, eps: float) -> np.ndarray:
    """``eps^2 I`` (k x k), cached per size and threshold, read-only."""
    key = (k, eps)
    shift = _SHIFTS.get(key)
    if shift is None:
        shift = _SHIFTS[key] = eps**2 * np.eye(k)
        shift.setflags(write=False)
    return shift
