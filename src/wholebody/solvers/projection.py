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

Singularity robustness: the pseudo-inverse is damped near singularities with the variable
damping of Chiaverini / Maciejewski, ``lambda^2 = (1 - (s_min/eps)^2) lambda_max^2`` when the
smallest singular value ``s_min < eps`` (else no damping), so away from singularities the
solution is the exact pseudo-inverse.

Bounds: **Saturation in the Null Space** (Flacco, De Luca, Khatib, IEEE T-RO 2015), written
with orthonormal bases. At each level, if ``u`` leaves the box, the most critical joint (the
one that limits the task scaling factor most) is saturated at its bound: its value is fixed,
the change is absorbed by the level's free null-space directions, and the level is re-solved
on the remaining free directions. The best task scaling factor ``s*`` seen so far is kept;
when the level runs out of free directions (``rank(A_k Z_free) <`` what the level needs),
its velocity is scaled by ``s*`` (status ``SCALED``). Saturated joints stay fixed for the
lower levels. As a last guard, a candidate that is still outside the box is moved along the
segment from the (feasible) solution of the higher levels, so the box always holds and the
result is never NaN.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from wholebody.errors import SolverError
from wholebody.robot import RobotState
from wholebody.solvers.base import Solver
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import Stack, StackProblem

__all__ = ["ProjectionSolver"]


@dataclass
class _Level:
    u: np.ndarray  # solution after this level
    P: np.ndarray  # projector onto the remaining null space
    scale: float
    saturated: np.ndarray  # boolean mask of joints fixed so far


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
    def _solve_ls(self, M: np.ndarray, r: np.ndarray,
                  damped: bool = True) -> tuple[np.ndarray, np.ndarray, int]:  # fmt: skip
        """Damped least-squares ``y = M^+_damped r``, the null-space basis of M and its rank."""
        n = M.shape[1]
        if M.shape[0] == 0 or n == 0:
            return np.zeros(n), np.eye(n), 0
        U, s, Vt = np.linalg.svd(M, full_matrices=True)
        smax = s[0] if s.size else 0.0
        rank = int(np.sum(s > self.rank_tolerance * max(1.0, smax)))
        smin = s[rank - 1] if rank else 0.0
        eps = self.singular_threshold
        lam2 = 0.0 if smin >= eps or not damped else (1.0 - (smin / eps) ** 2) * self.damping**2
        sr = s[:rank]
        inv = sr / (sr * sr + lam2)
        y = Vt[:rank].T @ (inv * (U[:, :rank].T @ r))
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

    def _level(self, lp, prev: _Level, lo: np.ndarray, hi: np.ndarray) -> _Level:
        A, b = lp.A, lp.b
        u0, P = prev.u, prev.P
        if A.shape[0] == 0:
            return prev
        if lp.identity_scale > 0:
            u = u0 + P @ (b / lp.identity_scale - u0)
            Pn = np.zeros_like(P)
        else:
            y, used = self._gram_step(A @ P, b - A @ u0)
            u, Pn = u0 + y, P - used
        if not self.saturate or _inside(u, lo, hi):
            return _Level(u, Pn, 1.0, prev.saturated)
        return self._saturate(A, b, prev, lo, hi)

    # ------------------------------------------------------------------ SNS
    def _saturate(self, A: np.ndarray, b: np.ndarray, prev: _Level, lo: np.ndarray,
                  hi: np.ndarray) -> _Level:  # fmt: skip
        """Saturation in the Null Space for one level (see the module docstring), on an
        orthonormal basis ``Z`` of the level's free directions."""
        u0, sat = prev.u, prev.saturated
        w, V = np.linalg.eigh(prev.P)
        Z = V[:, w > 0.5]
        _, _, needed = self._solve_ls(A @ Z, b - A @ u0)
        fixed = np.zeros_like(u0)  # values of the joints saturated at this level
        level_sat = np.zeros(u0.size, dtype=bool)
        best: tuple[float, np.ndarray, np.ndarray] | None = None
        for _ in range(u0.size + 1):
            # the directions of Z that keep the saturated joints still, and the move along Z
            # that brings the joints saturated at this level onto their bounds
            idx = np.flatnonzero(level_sat)
            if idx.size:
                y0, Ns, _ = self._solve_ls(Z[idx], fixed[idx] - u0[idx], damped=False)
                base, Zf = u0 + Z @ y0, Z @ Ns
            else:
                base, Zf = u0, Z
            M = A @ Zf
            ya, Nf, rank = self._solve_ls(M, b)  # the task's own contribution
            yr, _, _ = self._solve_ls(M, -A @ base)  # compensation of the base
            a = Zf @ ya
            rest = base + Zf @ yr
            s_max, critical = _scaling(a, rest, lo, hi, level_sat | sat)
            if best is None or s_max > best[0]:
                best = (s_max, rest + s_max * a, Zf @ Nf)
            cand = rest + a
            if _inside(cand, lo, hi):
                Zn = Zf @ Nf
                return _Level(cand, Zn @ Zn.T, 1.0, sat | level_sat)
            if rank < needed or critical < 0:
                break  # out of free directions: scale the level by the best factor found
            level_sat[critical] = True
            fixed[critical] = hi[critical] if cand[critical] > hi[critical] else lo[critical]
        s, u, Zn = best
        if not _inside(u, lo, hi):  # last guard: a feasible point on the segment from u0
            u = u0 + _segment(u0, u - u0, lo, hi) * (u - u0)
        return _Level(u, Zn @ Zn.T, s, sat | level_sat)

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
        u_start = np.clip(np.zeros(nu), lo, hi)  # 0 unless the box excludes it
        pinned = lo == hi if self.saturate else np.zeros(nu, dtype=bool)
        P0 = np.diag((~pinned).astype(float))
        state_k = _Level(u_start, P0, 1.0, pinned)
        scales = np.ones(len(problem.levels))
        for i, lp in enumerate(problem.levels):
            state_k = self._level(lp, state_k, lo, hi)
            scales[i] = state_k.scale
        u_s = state_k.u
        message = ""
        if not np.all(np.isfinite(u_s)):  # never NaN: fall back to the safe point
            u_s, message = u_start, "non-finite solution replaced by the box's closest point to 0"
        return self._result(problem, u_s, scales, time.perf_counter() - start, message)

    def _result(self, problem: StackProblem, u_s: np.ndarray, scales: np.ndarray, elapsed: float,
                message: str) -> SolverResult:  # fmt: skip
        lo, hi = problem.lower, problem.upper
        level_res = np.zeros(len(problem.levels))
        task_res: dict[str, float] = {}
        infeasible: list[tuple[str, str]] = []
        for i, lp in enumerate(problem.levels):
            if not lp.has_equalities:
                continue
            r = lp.A @ u_s - lp.b
            level_res[i] = float(np.linalg.norm(r))
            for name, sl in lp.task_rows.items():
                task_res[name] = float(np.linalg.norm(r[sl]))
                tol = self.tolerance * (1.0 + float(np.linalg.norm(lp.b[sl])))
                if name != "objectives" and task_res[name] > tol:
                    infeasible.append((lp.name, name))
        span = np.maximum(1.0, np.abs(lo) + np.abs(hi))
        finite = np.isfinite(lo) | np.isfinite(hi)
        at = finite & ((u_s - lo <= 1e-9 * span) | (hi - u_s <= 1e-9 * span))
        top = problem.levels[0].name if problem.levels else ""
        if any(level == top for level, _ in infeasible) and scales[0] >= 1.0:
            status = SolverStatus.INFEASIBLE
        elif np.any(scales < 1.0):
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


def _inside(u: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float = 1e-10) -> bool:
    return bool(
        np.all(u >= lo - tol * (1 + np.abs(lo))) and np.all(u <= hi + tol * (1 + np.abs(hi)))
    )


def _scaling(a: np.ndarray, rest: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             skip: np.ndarray) -> tuple[float, int]:  # fmt: skip
    """Largest ``s`` in [0, 1] with ``rest + s a`` in the box (SNS task scaling factor), and the
    joint that limits it (-1 if none). Joints in ``skip`` are already saturated."""
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(a > 0, (hi - rest) / a, np.where(a < 0, (lo - rest) / a, np.inf))
        down = np.where(a > 0, (lo - rest) / a, np.where(a < 0, (hi - rest) / a, -np.inf))
    up = np.where(skip, np.inf, up)
    down = np.where(skip, -np.inf, down)
    s_max = float(np.min(up)) if up.size else np.inf
    critical = int(np.argmin(up)) if np.isfinite(s_max) else -1
    if s_max < float(np.max(down)) or s_max < 0:  # rest itself is outside the box
        return 0.0, critical
    return min(s_max, 1.0), critical


def _segment(u0: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest ``t`` in [0, 1] with ``u0 + t d`` in the box (u0 inside it)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, (hi - u0) / d, np.where(d < 0, (lo - u0) / d, np.inf))
    return float(np.clip(np.min(t), 0.0, 1.0)) if t.size else 1.0
