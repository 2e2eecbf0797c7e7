"""The paper's backend: pseudo-inverse with recursive null-space projection.

Without bounds, level by level (scaled coordinates ``u~``, see :mod:`.stack`)::

    u_0 = 0,  P_0 = I
    M_k = A_k P_{k-1}
    u_k = u_{k-1} + M_k^+_damped (b_k - A_k u_{k-1})
    P_k = P_{k-1} - M_k^+ M_k

``P`` is the orthogonal projector onto the directions that leave every higher level
unchanged: exact (undamped, with a rank threshold), computed from the eigen-decomposition of
the small Gram matrix ``M M^T`` (its eigenvalues are the squared singular values). A level
made only of objectives has rows ``s I``, so it is simply
``u_k = u_{k-1} + P (b/s - u_{k-1})``. With one level of tasks ``(J, v)`` and one level of
objectives, ``u = J+ v + N u0 = J+ v - k (I - J+ J) grad H``: the paper's
law. The plain pseudo-inverse is the same solver on a stack without the objective level.

Linear algebra: the Gram matrix ``G = M M^T`` is factored by Cholesky, ``G = L L^T``. When
``trace(G^-1) = ||L^-1||_F^2 <= 1 / eps^2`` its smallest eigenvalue is at least ``eps^2``: no
damping applies and every direction counts, so ``M^+ r = M^T G^-1 r`` and ``M^+ M = M^T G^-1 M``
exactly, from ``W = L^-1 M``. Otherwise (near a singularity) the eigen-decomposition (fast path)
or the SVD (saturation) decides damping and rank as described below.

Singularity robustness: the pseudo-inverse is damped near singularities with the variable
damping of Chiaverini / Maciejewski, ``lambda^2 = (1 - (s_min/eps)^2) lambda_max^2`` when the
smallest singular value ``s_min < eps`` (else no damping), so away from singularities the
solution is the exact pseudo-inverse.

Bounds: **Saturation in the Null Space** (Flacco, De Luca, Khatib, IEEE T-RO 2015), written
with orthogonal projectors. At each level, if ``u`` leaves the box, the most critical joint
(the one that limits the task scaling factor most) is saturated at its bound: its value is
fixed, the change is absorbed by the level's free null-space directions, and the level is
re-solved on the remaining free directions. The free directions are those of the projector
``F`` (initially the ``P`` of the higher levels); saturating joint j at value f is a rank-one
update, no factorisation::

    base <- base + F e_j (f - base_j) / F_jj,      F <- F - F e_j e_j^T F / F_jj

(skipped when ``F_jj`` is at rounding level: the joint does not move in those directions).
With ``B = A F`` (``F`` idempotent, so ``B B^T = A F A^T``), the level's move along the free
directions is ``B^T G^-1 r``; while no joint of the first level is saturated, ``F`` is a 0/1
diagonal and ``B`` is ``A`` with columns zeroed. A level made only of objectives (rows ``s I``)
needs no factorisation at all: its move is ``F (b/s - base)``. The best task scaling factor ``s*`` seen so far is kept;
when the level runs out of free directions (``rank(A_k Z_free) <`` what the level needs),
its velocity is scaled by ``s*`` (status ``SCALED``). Saturated joints stay fixed for the
lower levels. As a last guard, a candidate that is still outside the box is moved along the
segment from the (feasible) solution of the higher levels, so the box always holds and the
result is never NaN.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dpotrf, dtrtri

from wholebody.errors import SolverError
from wholebody.robot import RobotState
from wholebody.solvers.base import Solver
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import LevelProblem, Stack, StackProblem

__all__ = ["ProjectionSolver"]

_INSIDE_TOL = 1e-10
_FIXED = 1e-18  # F_jj at or below this: joint j does not move along the free directions


@dataclass
class _Level:
    """The solution after a level and the free directions left for the next ones: the
    projector ``P``, or, when ``P`` is None, the 0/1 diagonal ``diag(free)``."""

    u: np.ndarray  # solution after this level
    P: np.ndarray | None  # projector onto the remaining null space (None: diag(free))
    scale: float
    saturated: np.ndarray  # boolean mask of joints fixed so far
    free: np.ndarray | None = None  # when P is None

    def projector(self) -> np.ndarray:
        return np.diag(self.free.astype(float)) if self.P is None else self.P


@dataclass
class _Box:
    """The box and its tolerance-widened form for the inside test."""

    lo: np.ndarray
    hi: np.ndarray
    lo_tol: np.ndarray
    hi_tol: np.ndarray

    def inside(self, u: np.ndarray) -> bool:
        return bool((u >= self.lo_tol).all()) and bool((u <= self.hi_tol).all())


class _Gram:
    """``G = B B^T`` of a level's rows restricted to its free directions, certified well
    conditioned (see the module docstring); ``W = L^-1 B``, ``Linv = L^-1``."""

    __slots__ = ("B", "Linv", "W")

    def __init__(self, B: np.ndarray, Linv: np.ndarray, W: np.ndarray) -> None:
        self.B, self.Linv, self.W = B, Linv, W

    def solve(self, r: np.ndarray) -> np.ndarray:
        """``B^T G^-1 r`` (r: (m,) or (m, k))."""
        return self.W.T @ (self.Linv @ r)

    def used(self) -> np.ndarray:
        """``B^T G^-1 B``: the projector onto the directions the level uses."""
        return self.W.T @ self.W


class ProjectionSolver(Solver):
    """Damped pseudo-inverse + recursive null-space projection + SNS for the box.

    Parameters
    ----------
    damping
        ``lambda_max``: the largest damping, reached at a singularity.
    singular_threshold
        ``eps``: damping starts when the smallest singular value falls below it.
    rank_tolerance
        Singular values below ``rank_tolerance * max(1, s_max)`` count as zero for null
        spaces and ranks.
    tolerance
        A level's residual above ``tolerance * (1 + |b|)`` counts as not met.
    saturate
        Apply SNS. When False the bounds are not enforced (the textbook solution; used to
        show what the box costs, never in control).
    """

    name = "projection"

    def __init__(
        self,
        *,
        damping: float = 0.05,
        singular_threshold: float = 0.02,
        rank_tolerance: float = 1e-9,
        tolerance: float = 1e-6,
        saturate: bool = True,
    ) -> None:
        if damping < 0 or singular_threshold <= 0 or rank_tolerance <= 0 or tolerance <= 0:
            raise SolverError("ProjectionSolver: damping >= 0 and positive thresholds required")
        self.damping = damping
        self.singular_threshold = singular_threshold
        self.rank_tolerance = rank_tolerance
        self.tolerance = tolerance
        self.saturate = saturate

    # ------------------------------------------------------------------ linear algebra
    def _certified(self, B: np.ndarray) -> _Gram | None:
        """The Cholesky route for ``B`` (m x n) when ``B B^T`` is certified to need neither
        damping nor a rank decision (all singular values >= eps; see the module docstring),
        else None."""
        m = B.shape[0]
        if m == 0 or m > B.shape[1]:
            return None
        G = B @ B.T
        L, info = dpotrf(G, lower=1, clean=1)
        if info != 0:
            return None
        Linv, info = dtrtri(L, lower=1)
        if info != 0:
            return None
        flat = Linv.ravel()
        eps = self.singular_threshold
        # lambda_min(G) >= 1 / trace(G^-1) >= eps^2; and every eigenvalue is kept as a rank
        # (old rule: lambda > (rank_tolerance * max(1, s_max))^2, s_max^2 <= trace(G)).
        if float(flat @ flat) * eps * eps > 1.0:
            return None
        top = float(G.trace())
        if eps * eps <= (self.rank_tolerance**2) * max(1.0, top):
            return None
        return _Gram(B, Linv, Linv @ B)

    def _solve_ls(self, M: np.ndarray, r: np.ndarray,
                  damped: bool = True) -> tuple[np.ndarray, np.ndarray, int]:  # fmt: skip
        """Damped least-squares ``y = M^+_damped r`` (r: (m,) or (m, k)), the null-space basis
        of M and its rank, from the SVD."""
        n = M.shape[1]
        if M.shape[0] == 0 or n == 0:
            return np.zeros((n, *r.shape[1:])), np.eye(n), 0
        U, s, Vt = np.linalg.svd(M, full_matrices=True)
        smax = s[0] if s.size else 0.0
        rank = int(np.sum(s > self.rank_tolerance * max(1.0, smax)))
        smin = s[rank - 1] if rank else 0.0
        eps = self.singular_threshold
        lam2 = 0.0 if smin >= eps or not damped else (1.0 - (smin / eps) ** 2) * self.damping**2
        sr = s[:rank]
        inv = sr / (sr * sr + lam2)
        c = U[:, :rank].T @ r
        y = Vt[:rank].T @ (inv[:, None] * c if c.ndim == 2 else inv * c)
        return y, Vt[rank:].T, rank

    def _gram_step(self, M: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``M^+_damped r`` and the exact projector ``M^+ M`` (from the eigen-decomposition
        of ``M M^T``)."""
        lam, U = np.linalg.eigh(M @ M.T)
        top = lam[-1] if lam.size else 0.0
        keep = lam > (self.rank_tolerance * max(1.0, np.sqrt(max(top, 0.0)))) ** 2
        lam_r, U_r = lam[keep], U[:, keep]
        smin = np.sqrt(lam_r[0]) if lam_r.size else 0.0
        eps = self.singular_threshold
        mu = 0.0 if smin >= eps else (1.0 - (smin / eps) ** 2) * self.damping**2
        MtU = M.T @ U_r
        y = MtU @ ((U_r.T @ r) / (lam_r + mu))
        return y, (MtU / lam_r) @ MtU.T

    def _level(self, lp: LevelProblem, prev: _Level, box: _Box, need_next: bool) -> _Level:
        A, b = lp.A, lp.b
        u0 = prev.u
        if A.shape[0] == 0:
            return prev
        if lp.identity_scale > 0:
            if prev.P is None:
                u = u0 + (b / lp.identity_scale - u0) * prev.free
            else:
                u = u0 + prev.P @ (b / lp.identity_scale - u0)
            nxt = _Level(u, None, 1.0, prev.saturated, np.zeros(u0.size, dtype=bool))
        else:
            B = (A if prev.free.all() else A * prev.free) if prev.P is None else A @ prev.P
            r = b - A @ u0
            gram = self._certified(B)
            if gram is not None:
                u = u0 + gram.solve(r)
                Pn = None
                if need_next:
                    Pn = prev.projector() - gram.used()
            else:
                y, used = self._gram_step(B, r)
                u, Pn = u0 + y, prev.projector() - used
            nxt = _Level(u, Pn, 1.0, prev.saturated)
        if not self.saturate or box.inside(u):
            return nxt
        if lp.identity_scale > 0:
            return self._saturate_identity(lp, prev, box)
        return self._saturate(A, b, prev, box)

    # ------------------------------------------------------------------ SNS
    def _saturate(self, A: np.ndarray, b: np.ndarray, prev: _Level, box: _Box) -> _Level:
        """Saturation in the Null Space for one level of tasks (see the module docstring)."""
        lo, hi = box.lo, box.hi
        u0, sat = prev.u, prev.saturated
        free = _Free(prev, u0)
        needed = self._rank(A, free)
        level_sat = np.zeros(u0.size, dtype=bool)
        best: tuple[float, np.ndarray, object] | None = None
        for _ in range(u0.size + 1):
            base = free.base
            R = np.stack((b, -(A @ base)), axis=1)  # the task, and the compensation of base
            gram = self._certified(free.restrict(A))
            if gram is not None:
                Y = gram.solve(R)
                a, rest, rank, null = Y[:, 0], base + Y[:, 1], gram.B.shape[0], gram
            else:  # near a singularity or out of directions: the SVD decides
                Zf = free.basis()
                Yz, Nf, rank = self._solve_ls(A @ Zf, R)
                a, rest, null = Zf @ Yz[:, 0], base + Zf @ Yz[:, 1], Zf @ Nf
            s_max, critical = _scaling(a, rest, lo, hi, level_sat | sat)
            if best is None or s_max > best[0]:
                best = (s_max, rest + s_max * a, (free.copy(), null))
            cand = rest + a
            if box.inside(cand):
                return _Level(cand, _null_projector(free, null), 1.0, sat | level_sat)
            if rank < needed or critical < 0:
                break  # out of free directions: scale the level by the best factor found
            level_sat[critical] = True
            free.fix(critical, hi[critical] if cand[critical] > hi[critical] else lo[critical])
        s, u, (free_b, null_b) = best
        if not box.inside(u):  # last guard: a feasible point on the segment from u0
            u = u0 + _segment(u0, u - u0, lo, hi) * (u - u0)
        return _Level(u, _null_projector(free_b, null_b), s, sat | level_sat)

    def _rank(self, A: np.ndarray, free: _Free) -> int:
        """Rank of the level's rows on the free directions."""
        if self._certified(free.restrict(A)) is not None:
            return A.shape[0]
        Z = free.basis()
        return self._solve_ls(A @ Z, np.zeros(A.shape[0]))[2]

    def _saturate_identity(self, lp: LevelProblem, prev: _Level, box: _Box) -> _Level:
        """SNS for a level of objectives only (rows ``s I``): with ``F`` the free directions,
        the level's damped least-squares move is ``c F b`` and the compensation of ``base``
        ``-c s F base``, ``c = s / (s^2 + lambda^2)``; the rank is ``rank(F)``."""
        lo, hi = box.lo, box.hi
        u0, sat, b = prev.u, prev.saturated, lp.b
        s = lp.identity_scale
        free = _Free(prev, u0)
        eps = self.singular_threshold
        lam2 = 0.0 if s >= eps else (1.0 - (s / eps) ** 2) * self.damping**2
        c = s / (s * s + lam2) if s > self.rank_tolerance * max(1.0, s) else 0.0
        needed = free.rank() if c else 0
        level_sat = np.zeros(u0.size, dtype=bool)
        best: tuple[float, np.ndarray, np.ndarray | None] | None = None
        for _ in range(u0.size + 1):
            base = free.base
            rank = free.rank() if c else 0
            a = c * free.apply(b)
            rest = base - (c * s) * free.apply(base)
            s_max, critical = _scaling(a, rest, lo, hi, level_sat | sat)
            null = None if rank else free.matrix()  # what the level leaves free
            if best is None or s_max > best[0]:
                best = (s_max, rest + s_max * a, null)
            cand = rest + a
            if box.inside(cand):
                return _Level(cand, null, 1.0, sat | level_sat, _none(u0.size, null))
            if rank < needed or critical < 0:
                break
            level_sat[critical] = True
            free.fix(critical, hi[critical] if cand[critical] > hi[critical] else lo[critical])
        s_b, u, null = best
        if not box.inside(u):
            u = u0 + _segment(u0, u - u0, lo, hi) * (u - u0)
        return _Level(u, null, s_b, sat | level_sat, _none(u0.size, null))

    # ------------------------------------------------------------------ solve
    def solve(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        start = time.perf_counter()
        problem = stack.evaluate(state, dt)
        lo, hi = problem.lower, problem.upper
        for lp in problem.levels:
            if lp.C.shape[0]:
                raise SolverError(
                    f"ProjectionSolver: {lp.name} has inequality tasks "
                    f"({', '.join(lp.inequality_rows)}); use HierarchicalQPSolver for those"
                )
        nu = lo.size
        u_start = np.minimum(np.maximum(0.0, lo), hi)  # 0 unless the box excludes it
        pinned = lo == hi if self.saturate else np.zeros(nu, dtype=bool)
        box = _Box(lo, hi, lo - _INSIDE_TOL * (1 + np.abs(lo)), hi + _INSIDE_TOL * (1 + np.abs(hi)))
        state_k = _Level(u_start, None, 1.0, pinned, ~pinned)
        levels = problem.levels
        scales = np.ones(len(levels))
        for i, lp in enumerate(levels):
            state_k = self._level(lp, state_k, box, i + 1 < len(levels))
            scales[i] = state_k.scale
        u_s = state_k.u
        message = ""
        if not math.isfinite(u_s @ u_s) and not np.all(np.isfinite(u_s)):
            u_s, message = u_start, "non-finite solution replaced by the box's closest point to 0"
        return self._result(problem, u_s, scales, time.perf_counter() - start, message)

    def _result(self, problem: StackProblem, u_s: np.ndarray, scales: np.ndarray, elapsed: float,
                message: str) -> SolverResult:  # fmt: skip
        lo, hi = problem.lower, problem.upper
        levels = problem.levels
        level_res = np.zeros(len(levels))
        task_res: dict[str, float] = {}
        infeasible: list[tuple[str, str]] = []
        tol = self.tolerance
        for i, lp in enumerate(levels):
            if not lp.A.shape[0]:
                continue
            r = lp.A @ u_s - lp.b
            level_res[i] = math.sqrt(r @ r)
            b = lp.b
            for name, sl in lp.task_rows.items():
                rs = r[sl]
                res = task_res[name] = math.sqrt(rs @ rs)
                if name != "objectives":
                    bs = b[sl]
                    if res > tol * (1.0 + math.sqrt(bs @ bs)):
                        infeasible.append((lp.name, name))
        span = np.abs(lo)
        span += np.abs(hi)
        np.maximum(span, 1.0, out=span)
        span *= 1e-9
        at = (u_s - lo <= span) | (hi - u_s <= span)
        at &= np.isfinite(lo) | np.isfinite(hi)
        top = levels[0].name if levels else ""
        if scales[0] >= 1.0 and any(level == top for level, _ in infeasible):
            status = SolverStatus.INFEASIBLE
        elif (scales < 1.0).any():
            status = SolverStatus.SCALED
        elif at.any():
            status = SolverStatus.BOUNDS_ACTIVE
        else:
            status = SolverStatus.OK
        return SolverResult(
            u=problem.to_u(u_s),
            status=status,
            level_residuals=level_res,
            task_residuals=task_res,
            active_bounds=np.flatnonzero(at),
            scale=scales,
            infeasible=infeasible,
            solve_time=elapsed,
            message=message,
        )


class _Free:
    """The free directions of a level under SNS and the point ``base`` that puts the joints
    saturated so far on their bounds: a 0/1 mask while the directions are coordinate axes,
    else an orthogonal projector ``F`` (see the module docstring)."""

    __slots__ = ("F", "base", "mask")

    def __init__(self, prev: _Level, u0: np.ndarray) -> None:
        self.base = u0.copy()
        self.mask = None if prev.P is not None else prev.free.copy()
        self.F = prev.P

    def copy(self) -> _Free:
        other = _Free.__new__(_Free)
        other.base = self.base
        other.mask = None if self.mask is None else self.mask.copy()
        other.F = self.F
        return other

    def restrict(self, A: np.ndarray) -> np.ndarray:
        """``B = A F``."""
        if self.mask is None:
            return A @ self.F
        return A if self.mask.all() else A * self.mask

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``F x``."""
        return self.F @ x if self.mask is None else x * self.mask

    def matrix(self) -> np.ndarray:
        return np.diag(self.mask.astype(float)) if self.mask is not None else self.F

    def rank(self) -> int:
        if self.mask is not None:
            return int(np.count_nonzero(self.mask))
        return int(round(float(self.F.trace())))

    def basis(self) -> np.ndarray:
        """An orthonormal basis of the free directions (n x r)."""
        if self.mask is not None:
            return np.eye(self.mask.size)[:, self.mask]
        w, V = np.linalg.eigh(self.F)
        Z = V[:, w > 0.5]
        Z[self.F.diagonal() <= _FIXED] = 0.0  # |Z[j]|^2 = F_jj: exact zeros, not rounding
        return Z

    def fix(self, j: int, value: float) -> None:
        """Saturate joint j at ``value``: move ``base`` along the free directions (minimum
        norm) to put it there and remove the directions that move it."""
        if self.mask is not None:
            if self.mask[j]:
                self.base = self.base.copy()
                self.base[j] = value
                self.mask[j] = False
            return
        F = self.F
        fj = F[:, j]
        fjj = float(fj[j])
        if fjj <= _FIXED:  # |row j of an orthonormal basis| <= 1e-9: the joint cannot move
            return
        self.base = self.base + fj * ((value - self.base[j]) / fjj)
        self.base[j] = value
        self.F = F - np.outer(fj, fj / fjj)
        self.F[j] = 0.0  # exactly: joint j no longer moves
        self.F[:, j] = 0.0


def _null_projector(free: _Free, null: object) -> np.ndarray:
    """The projector onto what a level leaves free: from the certified Gram (``F - B^T G^-1
    B``) or an explicit basis ``Zn`` (``Zn Zn^T``)."""
    if isinstance(null, _Gram):
        return free.matrix() - null.used()
    return null @ null.T


def _none(n: int, null: np.ndarray | None) -> np.ndarray | None:
    """The ``free`` mask of a :class:`_Level` whose projector is ``null`` (None: zero)."""
    return np.zeros(n, dtype=bool) if null is None else None


def _scaling(a: np.ndarray, rest: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             skip: np.ndarray) -> tuple[float, int]:  # fmt: skip
    """Largest ``s`` in [0, 1] with ``rest + s a`` in the box (SNS task scaling factor), and the
    joint that limits it (-1 if none). Joints in ``skip`` are already saturated."""
    n = a.size
    if n == 0:
        return 1.0, -1
    pos = a > 0
    act = pos | (a < 0)
    act &= ~skip
    up = np.full(n, np.inf)
    down = np.full(n, -np.inf)
    np.divide(np.where(pos, hi, lo) - rest, a, out=up, where=act)
    np.divide(np.where(pos, lo, hi) - rest, a, out=down, where=act)
    critical = int(up.argmin())
    s_max = float(up[critical])
    if not s_max < np.inf:
        critical = -1
    if s_max < float(down.max()) or s_max < 0:  # rest itself is outside the box
        return 0.0, critical
    return min(s_max, 1.0), critical


def _segment(u0: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest ``t`` in [0, 1] with ``u0 + t d`` in the box (u0 inside it)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, (hi - u0) / d, np.where(d < 0, (lo - u0) / d, np.inf))
    return float(np.clip(np.min(t), 0.0, 1.0)) if t.size else 1.0
