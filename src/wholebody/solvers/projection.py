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

Linear algebra (:mod:`wholebody.solvers.linalg`): where the Gram matrix of a level's rows is
certified to have no eigenvalue below ``eps^2`` (a Cholesky factor, and a bound or a second
factor of ``G - eps^2 I``; :func:`~wholebody.solvers.linalg.certified_gram`), no damping
applies and every direction counts: ``M^+ r = M^T G^-1 r`` and ``M^+ M = M^T G^-1 M``
exactly, or, for a level with more rows than columns (a weighted sum of tasks), its
well-conditioned normal equations. Otherwise (near a singularity) the eigen-decomposition
(fast path) or the SVD (saturation) decides damping and rank as described below.

Singularity robustness: each singular direction of a level whose singular value ``s_i`` is
below ``eps`` is damped with the variable damping ``lambda_i^2 = (1 - (s_i/eps)^2)
lambda_max^2`` (Chiaverini's variable factor, applied direction by direction as in the
numerical filtering of Maciejewski and Klein), the others not at all: away from singularities
the solution is the exact pseudo-inverse, and near one only the nearly singular directions
are damped. Damping every direction by the smallest singular value's factor would also damp
a level's well-conditioned tasks whenever it holds a low-weight regulariser, whose singular
values are small by its weight, not by the kinematics.

Units of ``eps``: the singular values are those of the level's rows divided by
``reference_scale = sqrt(w_min)``, the smallest positive task weight of the level
(:class:`~wholebody.solvers.stack.LevelProblem`), in the metric's scaled velocities ``u~``.
So a weight common to a level's tasks changes nothing, and a heavier task never makes a
lighter one count as singular. The price: in a level that also holds a light regulariser (a
posture task of weight 1e-5 beside the hands), a task's singular directions are measured
against that regulariser, and it is the regulariser, as in any weighted least squares, that
bounds the velocity near the task's singularity; put singular-prone tasks in a level of their
own, as the paper's stack does, for the damping proper. The metric is not normalised: ``eps``
is in the units of ``u~ = W^(1/2) u``, and a uniform metric ``c I`` moves the threshold on the
task's own singular values to ``eps sqrt(c)`` (the damping of a weighted norm, like
``lambda``).

Bounds: the unsaturated solution of the whole stack is computed first and returned when it is
inside the box. Otherwise: **Saturation in the Null Space** (Flacco, De Luca, Khatib, IEEE
T-RO 2015), from the start, written with orthogonal projectors. At each level, if ``u``
leaves the box, the most critical joint (the one that limits the task scaling factor most)
is saturated at its bound: its value is fixed, the change is absorbed by the level's free
null-space directions, and the level is re-solved on the remaining free directions. The free
directions are those of the projector ``F`` (initially the ``P`` of the higher levels);
saturating joint j at value f is a rank-one update, no factorisation::

    base <- base + F e_j (f - base_j) / F_jj,      F <- F - F e_j e_j^T F / F_jj

(skipped when ``F_jj`` is at rounding level: the joint does not move in those directions).
With ``B = A F`` (``F`` idempotent, so ``B B^T = A F A^T``), the level's move along the free
directions is ``B^T G^-1 r``; while no joint of the first level is saturated, ``F`` is a 0/1
diagonal and ``B`` is ``A`` with columns zeroed. A level made only of objectives (rows ``s I``)
needs no factorisation at all: its move is ``F (b/s - base)``. The best task scaling factor
``s*`` seen so far is kept; when the level runs out of free directions
(``rank(A_k Z_free) <`` what the level needs), its velocity is scaled by ``s*``
(``scale``). Saturated joints stay fixed for the lower levels. As a last guard, a candidate
that is still outside the box is moved along the segment from the (feasible) solution of the
higher levels, so the box always holds and the result is never NaN.

Cost: every factorisation of an SNS iteration is also its rank test (the rank the level needs
is that of the first iteration), a snapshot of the free directions is a reference (they are
never modified in place) and the scaling factor is one pass over the stacked bounds.

Inequality rows (e.g. :class:`~wholebody.tasks.CollisionAvoidance`) are held above every
level by an active set (:mod:`~wholebody.solvers.active_rows`: the rows the solution
violates become equality rows of a new first level, and the stack is solved again), on the
reference path.

Reporting: ``infeasible`` lists every equality task whose weighted residual exceeds
``tolerance * (1 + ||v||)``, as the HQP's. The status has the HQP's meaning
(:class:`~wholebody.solvers.SolverStatus`): INFEASIBLE when a task of the first level is
unmet, or when SNS ran and the box raised a task's residual above its residual at the
box-free solution (the unsaturated pass, the best the higher levels leave it) by more than
that tolerance, whatever its level; else SCALED when a level was scaled (in practice an
objectives' level, whose rows are no task); else BOUNDS_ACTIVE when some entry of ``u`` is
on a bound.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from wholebody._numeric import count_nonzero as _count
from wholebody.errors import DimensionError, SolverError
from wholebody.kernels import layout as lay
from wholebody.kernels import projection as kernel
from wholebody.kernels.evaluate import evaluate
from wholebody.robot import RobotState
from wholebody.solvers.active_rows import solve_with_inequalities
from wholebody.solvers.base import Solver
from wholebody.solvers.linalg import (
    Gram,
    certified_gram,
    damped_gram_step,
    damped_svd_solve,
    identity,
)
from wholebody.solvers.plan import ProblemArena, first_call
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import LevelProblem, Stack, StackProblem

__all__ = ["ProjectionSolver"]

_INSIDE_TOL = 1e-10
_WIDEN = np.array([[-_INSIDE_TOL], [_INSIDE_TOL]])
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
        return _diag(self.free) if self.P is None else self.P


@dataclass
class _Box:
    """The box and its tolerance-widened form for the inside test."""

    lo: np.ndarray
    hi: np.ndarray
    lo_tol: np.ndarray
    hi_tol: np.ndarray
    lo_hi: np.ndarray  # [lo; hi] (2, n)
    _no_limit: np.ndarray | None = None

    @classmethod
    def of(cls, lo: np.ndarray, hi: np.ndarray) -> _Box:
        """The box ``[lo, hi]``; the inside test widens it by ``_INSIDE_TOL (1 + |bound|)``."""
        lo_hi = np.array([lo, hi])
        wide = np.abs(lo_hi)
        wide += 1.0
        wide *= _WIDEN  # -TOL (1 + |lo|), +TOL (1 + |hi|)
        wide += lo_hi
        return cls(lo, hi, wide[0], wide[1], lo_hi)

    @property
    def hi_lo(self) -> np.ndarray:
        """``[hi; lo]`` (2, n), for :func:`_scaling`."""
        return self.lo_hi[::-1]

    @property
    def no_limit(self) -> np.ndarray:
        """``[inf; -inf]`` (2, n)."""
        if self._no_limit is None:
            self._no_limit = np.full((2, self.lo.size), np.inf)
            self._no_limit[1] = -np.inf
        return self._no_limit

    def inside(self, u: np.ndarray) -> bool:
        n = u.size
        return _count(u >= self.lo_tol) == n and _count(u <= self.hi_tol) == n


class ProjectionSolver(Solver):
    """Damped pseudo-inverse + recursive null-space projection + SNS for the box.

    Parameters
    ----------
    damping
        ``lambda_max``: the largest damping, reached at a singularity.
    singular_threshold
        ``eps``: a singular direction is damped when its singular value is below it (in the
        units of the level's lightest task and the metric's scaled velocities, see the module
        docstring).
    rank_tolerance
        Singular values below ``rank_tolerance * max(1, s_max)`` count as zero for null
        spaces and ranks.
    tolerance
        A level's residual above ``tolerance * (1 + |b|)`` counts as not met.
    saturate
        Apply SNS. When False the bounds are not enforced (the textbook solution; used to
        show what the box costs, never in control).
    compiled
        Solve with the compiled core (:mod:`wholebody.kernels.projection`, the default), or,
        with False, with this module's Python implementation, the reference the kernels are
        tested against (same decisions, to rounding).
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
        compiled: bool = True,
    ) -> None:
        values = (damping, singular_threshold, rank_tolerance, tolerance)
        if not (all(math.isfinite(v) for v in values) and damping >= 0 and singular_threshold > 0
                and rank_tolerance > 0 and tolerance > 0):  # fmt: skip
            raise SolverError(
                "ProjectionSolver: damping >= 0 and positive thresholds required, all finite; "
                f"got damping={damping}, singular_threshold={singular_threshold}, "
                f"rank_tolerance={rank_tolerance}, tolerance={tolerance}"
            )
        self.damping = damping
        self.singular_threshold = singular_threshold
        self.rank_tolerance = rank_tolerance
        self.tolerance = tolerance
        self.saturate = saturate
        self.compiled = compiled
        self._par = np.zeros(kernel.PAR_WIDTH)

    def _level(self, lp: LevelProblem, prev: _Level, box: _Box, need_next: bool,
               saturate: bool) -> _Level:  # fmt: skip
        A, b = lp.A, lp.b
        u0 = prev.u
        if A.shape[0] == 0:
            return prev
        if lp.reference_scale != 1.0:  # damping decided independently of a common scale
            c = 1.0 / lp.reference_scale
            A, b = A * c, b * c
        if lp.identity_scale > 0:
            if prev.P is None:
                u = u0 + (b / lp.identity_scale - u0) * prev.free
            else:
                u = u0 + prev.P.dot(b / lp.identity_scale - u0)
            nxt = _Level(u, None, 1.0, prev.saturated, np.zeros(u0.size, dtype=bool))
        else:
            B = (
                (A if _count(prev.free) == prev.free.size else A * prev.free)
                if prev.P is None
                else A.dot(prev.P)
            )
            r = b - A.dot(u0)
            gram = certified_gram(B, self.singular_threshold, self.rank_tolerance)
            if gram is not None:
                u = u0 + gram.solve(r)
                Pn = None
                if need_next:
                    Pn = prev.projector() - gram.used()
            else:
                y, used = damped_gram_step(B, r, self.singular_threshold, self.damping,
                                           self.rank_tolerance, prev.P is None)  # fmt: skip
                u, Pn = u0 + y, prev.projector() - used
            nxt = _Level(u, Pn, 1.0, prev.saturated)
        if not saturate or box.inside(u):
            return nxt
        if lp.identity_scale > 0:
            return self._saturate_identity(lp, prev, box)
        return self._saturate(A, b, prev, box)

    # ------------------------------------------------------------------ SNS
    def _saturate(self, A: np.ndarray, b: np.ndarray, prev: _Level, box: _Box) -> _Level:
        """Saturation in the Null Space for one level of tasks (see the module docstring).

        The rank the level needs is its rank on the free directions before any saturation:
        that of the first iteration's factorisation (certified Cholesky, or SVD).
        """
        lo, hi = box.lo, box.hi
        u0, sat = prev.u, prev.saturated
        free = _Free(prev, u0)
        needed = -1
        skip = sat.copy()  # saturated so far: at this level or above
        best: tuple[float, np.ndarray, np.ndarray, _Free, object] | None = None
        R = np.empty((A.shape[0], 2))  # the task, and the compensation of base
        R[:, 0] = b
        Rc = R[:, 1]
        for _ in range(u0.size + 1):
            base = free.base
            Rc[:] = -A.dot(base)
            gram = certified_gram(free.restrict(A), self.singular_threshold, self.rank_tolerance)
            if gram is not None:
                Y = gram.solve(R)
                a, rest, rank, null = Y[:, 0], base + Y[:, 1], gram.rank, gram
            else:  # near a singularity or out of directions: the SVD decides
                Zf = free.basis()
                Yz, Nf, rank = damped_svd_solve(A.dot(Zf), R, self.singular_threshold,
                                                self.damping, self.rank_tolerance)  # fmt: skip
                a, rest, null = Zf.dot(Yz[:, 0]), base + Zf.dot(Yz[:, 1]), Zf.dot(Nf)
            if needed < 0:
                needed = rank
            s_max, critical = _scaling(a, rest, box, skip)
            if best is None or s_max > best[0]:
                best = (s_max, rest, a, free, null)
            cand = rest + a
            if box.inside(cand):
                return _Level(cand, _null_projector(free, null), 1.0, skip)
            if rank < needed or critical < 0:
                break  # out of free directions: scale the level by the best factor found
            skip[critical] = True
            bound = hi[critical] if cand[critical] > hi[critical] else lo[critical]
            free = free.fixed(critical, bound)
        s, rest, a, free_b, null_b = best
        u = rest + s * a
        if not box.inside(u):  # last guard: a feasible point on the segment from u0
            u = np.clip(u0 + _segment(u0, u - u0, box.lo_tol, box.hi_tol) * (u - u0), lo, hi)
        return _Level(u, _null_projector(free_b, null_b), s, skip)

    def _saturate_identity(self, lp: LevelProblem, prev: _Level, box: _Box) -> _Level:
        """SNS for a level of objectives only (rows ``s I``, ``s > 0``): with ``F`` the free
        directions, the level's move is ``F b / s`` and the compensation of ``base``
        ``-F base`` (no damping: ``s I`` is never singular, and without bounds the move is
        the same ``F (b/s - base)``); the rank is ``rank(F)``. A joint the free directions do
        not move (``F_jj <= 1e-18``) has both exactly 0, not rounding: otherwise a motion of
        1e-15 could pick it as the critical joint and decide the scale."""
        lo, hi = box.lo, box.hi
        u0, sat, b = prev.u, prev.saturated, lp.b
        s = lp.identity_scale
        free = _Free(prev, u0)
        c = 1.0 / s
        needed = free.rank()
        skip = sat.copy()  # saturated so far: at this level or above
        best: tuple[float, np.ndarray, np.ndarray, np.ndarray | None] | None = None
        for _ in range(u0.size + 1):
            base = free.base
            rank = free.rank()
            a = c * free.apply(b)
            rest = base - free.apply(base)
            if free.F is not None:
                stuck = free.F.diagonal() <= _FIXED
                a[stuck] = 0.0
                rest[stuck] = base[stuck]
            s_max, critical = _scaling(a, rest, box, skip)
            null = None if rank else free.matrix()  # what the level leaves free
            if best is None or s_max > best[0]:
                best = (s_max, rest, a, null)
            cand = rest + a
            if box.inside(cand):
                return _Level(cand, null, 1.0, skip, _none(u0.size, null))
            if rank < needed or critical < 0:
                break
            skip[critical] = True
            free = free.fixed(
                critical, hi[critical] if cand[critical] > hi[critical] else lo[critical]
            )
        s_b, rest, a, null = best
        u = rest + s_b * a
        if not box.inside(u):
            u = np.clip(u0 + _segment(u0, u - u0, box.lo_tol, box.hi_tol) * (u - u0), lo, hi)
        return _Level(u, null, s_b, skip, _none(u0.size, null))

    # ------------------------------------------------------------------ solve
    def solve(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        if self.compiled:
            result = self._solve_compiled(stack, state, dt)
        else:
            start = time.perf_counter()
            result = self._solve_reference(stack.evaluate(state, dt, compiled=False))
            result.solve_time = time.perf_counter() - start
        if "held inequality rows" in result.message:
            result.message = _row_names(result.message, stack)
        return result

    def solve_problem(self, problem: StackProblem) -> SolverResult:
        """Solve an evaluated stack (rows in scaled coordinates, e.g. ``stack.evaluate()``'s
        or a synthetic one): with the kernels, or with ``compiled=False`` the reference."""
        if not self.compiled:
            return self._solve_reference(problem)
        if any(lp.C.shape[0] for lp in problem.levels):
            return self._solve_reference(problem)
        start = time.perf_counter()
        arena = ProblemArena(problem)
        self._set_par()
        first_call("projection problem", "the projection kernels", kernel.project, arena.f,
                   arena.i, arena.h, self._par, _anchor(problem.anchor, problem.lower))  # fmt: skip
        code = int(arena.view(lay.I_OUT)[lay.OUT_MESSAGE])
        return arena.result(time.perf_counter() - start, _MESSAGES[code])

    def _set_par(self) -> None:
        self._par[:] = (self.damping, self.singular_threshold, self.rank_tolerance,
                        self.tolerance, bool(self.saturate))  # fmt: skip

    def _solve_reference(self, problem: StackProblem) -> SolverResult:
        """The Python implementation, the reference of the kernels; inequality rows by the
        active set of :mod:`~wholebody.solvers.active_rows`."""
        if any(lp.C.shape[0] for lp in problem.levels):
            start = time.perf_counter()
            result = solve_with_inequalities(problem, self._solve_equalities, self.tolerance)
            result.solve_time = time.perf_counter() - start
            return result
        return self._solve_equalities(problem)

    def _solve_equalities(self, problem: StackProblem) -> SolverResult:
        start = time.perf_counter()
        lo, hi = problem.lower, problem.upper
        nu = lo.size
        if _count(lo <= hi) != nu:  # NaN compares false; Stack.evaluate never crosses the box
            message = _EMPTY_BOX
            return self._result(problem, np.zeros(nu), np.ones(len(problem.levels)),
                                time.perf_counter() - start, message, failed=True)  # fmt: skip
        levels = problem.levels
        box = _Box.of(lo, hi)
        scales = np.empty(len(levels))
        scales.fill(1.0)
        # The unsaturated solution of the whole stack first: when it is inside the box it is
        # the answer (every level met as without bounds). Only otherwise does SNS run, from
        # the start: saturating a level whose own candidate leaves the box, while the lower
        # levels would have brought the sum back inside, would trade a higher level's
        # freedom for nothing and makes the motion chatter between the two solutions.
        free = np.zeros(nu, dtype=bool)
        state_k = _Level(np.zeros(nu), None, 1.0, free, ~free)
        for i, lp in enumerate(levels):
            state_k = self._level(lp, state_k, box, i + 1 < len(levels), False)
        u_c = np.zeros(nu)
        u_free = None  # the box-free solution, when it leaves the box
        if self.saturate and not box.inside(state_k.u):
            u_free = state_k.u
            # SNS for d = u - u_c from d = 0, u_c the box's point closest to the anchor (0,
            # or the last velocity with acceleration limits), so that the search starts
            # inside the box it saturates against and a scaled level slows its change of
            # velocity rather than the velocity itself
            anchor = 0.0 if problem.anchor is None else problem.anchor
            u_c = np.minimum(np.maximum(anchor, lo), hi)
            if _count(u_c != 0.0):
                levels = [replace(lp, b=lp.b - lp.A.dot(u_c)) for lp in levels]
                box = _Box.of(lo - u_c, hi - u_c)
            pinned = lo == hi
            state_k = _Level(np.zeros(nu), None, 1.0, pinned, ~pinned)
            for i, lp in enumerate(levels):
                state_k = self._level(lp, state_k, box, i + 1 < len(levels), True)
                scales[i] = state_k.scale
        u_s = state_k.u + u_c
        if not math.isfinite(u_s.dot(u_s)) and not np.all(np.isfinite(u_s)):
            message = _NON_FINITE
            u_start = np.minimum(np.maximum(0.0, lo), hi)
            return self._result(problem, u_start, scales, time.perf_counter() - start, message,
                                failed=True)  # fmt: skip
        return self._result(problem, u_s, scales, time.perf_counter() - start, "", u_free=u_free)

    def _solve_compiled(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        start = time.perf_counter()
        if not dt > 0:
            raise DimensionError(f"control step dt must be > 0 s, got {dt}")
        plan = stack.plan()
        if plan.P:  # inequality rows: the reference path (module docstring, "Inequality rows")
            result = self._solve_reference(stack.evaluate(state, dt, compiled=False))
            result.solve_time = time.perf_counter() - start
            return result
        plan.sync(state, dt)
        if plan.stale:  # an arm energy's stiffness was replaced: lay the stack out anew
            plan = stack.plan()
            plan.sync(state, dt)
        self._set_par()
        first_call("evaluate", "the control kernels", evaluate, *plan.kernel_args(state))
        plan.written(state)
        anchor = _anchor(stack.anchor, plan.view(lay.F_BOX)[0])
        first_call("projection", "the projection kernels", kernel.project, plan.f, plan.i,
                   plan.h, self._par, anchor)  # fmt: skip
        code = int(plan.view(lay.I_OUT)[lay.OUT_MESSAGE])
        return plan.result(time.perf_counter() - start, _MESSAGES[code])

    def _result(self, problem: StackProblem, u_s: np.ndarray, scales: np.ndarray, elapsed: float,
                message: str, failed: bool = False, u_free: np.ndarray | None = None,
                ) -> SolverResult:  # fmt: skip
        """The result at ``u_s``. Status (one meaning with the HQP's): INFEASIBLE when a task
        of the first level is unmet or the box raised a task's residual above its box-free
        one (at ``u_free``, the solution without the box, given when SNS ran) by more than
        the tolerance; else SCALED when a level's motion was scaled; else BOUNDS_ACTIVE when
        an entry of ``u`` is on a bound."""
        lo, hi = problem.lower, problem.upper
        levels = problem.levels
        level_res, task_res, infeasible = problem.residuals(u_s, self.tolerance)
        # on a bound: within 1e-9 of it, relative to its size (an infinite side never is)
        near_lo = np.abs(lo)
        np.maximum(near_lo, 1.0, out=near_lo)
        near_hi = np.abs(hi)
        np.maximum(near_hi, 1.0, out=near_hi)
        at = (u_s - lo <= 1e-9 * near_lo) & np.isfinite(lo)
        at |= (hi - u_s <= 1e-9 * near_hi) & np.isfinite(hi)
        top = levels[0].name if levels else ""
        if failed:
            status = SolverStatus.FAILED
        elif any(level == top for level, _ in infeasible) or (
            u_free is not None and infeasible and _box_limited(problem, u_s, u_free, self.tolerance)
        ):
            status = SolverStatus.INFEASIBLE
        elif _count(scales < 1.0):
            status = SolverStatus.SCALED
        elif _count(at):
            status = SolverStatus.BOUNDS_ACTIVE
        else:
            status = SolverStatus.OK
        return SolverResult(
            u=problem.to_u(u_s),
            status=status,
            level_residuals=level_res,
            task_residuals=task_res,
            active_bounds=at.nonzero()[0],
            scale=scales,
            infeasible=infeasible,
            solve_time=elapsed,
            message=message,
        )


_EMPTY_BOX = "the box is empty or not a number (NaN bounds): u = 0"
_NON_FINITE = "non-finite solution replaced by the box's closest point to 0"
_MESSAGES = {0: "", kernel.MESSAGE_EMPTY_BOX: _EMPTY_BOX, kernel.MESSAGE_NON_FINITE: _NON_FINITE}


def _box_limited(problem: StackProblem, u: np.ndarray, u_free: np.ndarray, tol: float) -> bool:
    """Whether the box raised some task's weighted residual at ``u`` above that at the
    box-free solution ``u_free`` by more than ``tol (1 + ||b_t||)``: the HQP's test of a
    task the box limited. At ``u_free`` each level has the best residual the levels above
    leave it; where SNS kept those levels' residuals, the optimal set they leave is the same
    at ``u``, and where it did not, a level above is limited itself."""
    for lev in problem.levels:
        if not lev.A.shape[0]:
            continue
        _, tasks = lev.residual_report(u)
        _, free = lev.residual_report(u_free)
        for (_, r, _, b), (_, r0, _, _) in zip(tasks, free, strict=True):
            if r - r0 > tol * (1.0 + b):
                return True
    return False


def _row_names(message: str, stack: Stack) -> str:
    """``task[k]`` in a message followed by the row's own name where the inequality task
    gives one (``row_names()``: a collision pair)."""
    for level in stack.levels:
        for task in level.inequalities:
            names = task.row_names() if callable(getattr(task, "row_names", None)) else []
            for k, name in enumerate(names):
                if name:
                    message = message.replace(f"{task.name}[{k}]", f"{task.name}[{k}] {name}")
    return message


def _anchor(anchor: np.ndarray | None, like: np.ndarray) -> np.ndarray:
    """The kernel's anchor: the given one, or zeros."""
    return np.zeros(like.shape[0]) if anchor is None else anchor


class _Free:
    """The free directions of a level under SNS and the point ``base`` that puts the joints
    saturated so far on their bounds: a 0/1 mask while the directions are coordinate axes,
    else an orthogonal projector ``F`` (see the module docstring). Never modified once
    made (:meth:`fixed` returns a new one), so a snapshot is a reference."""

    __slots__ = ("F", "base", "mask")

    def __init__(self, prev: _Level, u0: np.ndarray) -> None:
        self.base = u0
        self.mask = None if prev.P is not None else prev.free
        self.F = prev.P

    def restrict(self, A: np.ndarray) -> np.ndarray:
        """``B = A F``."""
        if self.mask is None:
            return A.dot(self.F)
        return A if _count(self.mask) == self.mask.size else A * self.mask

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``F x``."""
        return self.F.dot(x) if self.mask is None else x * self.mask

    def matrix(self) -> np.ndarray:
        return _diag(self.mask) if self.mask is not None else self.F

    def rank(self) -> int:
        if self.mask is not None:
            return int(np.count_nonzero(self.mask))
        return round(float(self.F.trace()))

    def basis(self) -> np.ndarray:
        """An orthonormal basis of the free directions (n x r)."""
        if self.mask is not None:
            return np.eye(self.mask.size)[:, self.mask]
        w, V = np.linalg.eigh(self.F)
        Z = V[:, w > 0.5]
        Z[self.F.diagonal() <= _FIXED] = 0.0  # |Z[j]|^2 = F_jj: exact zeros, not rounding
        return Z

    def fixed(self, j: int, value: float) -> _Free:
        """The free directions once joint j is saturated at ``value`` (a new object; this
        one is left as it is): ``base`` moves along the free directions (minimum norm) to
        put the joint there and the directions that move it are removed."""
        other = _Free.__new__(_Free)
        if self.mask is not None:
            other.F = None
            if not self.mask[j]:
                other.base, other.mask = self.base, self.mask
                return other
            other.base = self.base.copy()
            other.base[j] = value
            other.mask = self.mask.copy()
            other.mask[j] = False
            return other
        F = self.F
        fj = F[:, j]
        fjj = float(fj[j])
        if fjj <= _FIXED:  # |row j of an orthonormal basis| <= 1e-9: the joint cannot move
            return self
        other.mask = None
        other.base = self.base + fj * ((value - self.base[j]) / fjj)
        other.base[j] = value
        other.F = F - np.outer(fj, fj / fjj)
        other.F[j] = 0.0  # exactly: joint j no longer moves
        other.F[:, j] = 0.0
        return other


def _null_projector(free: _Free, null: object) -> np.ndarray:
    """The projector onto what a level leaves free: from the certified Gram (``F - B^T G^-1
    B``) or an explicit basis ``Zn`` (``Zn Zn^T``)."""
    if isinstance(null, Gram):
        return free.matrix() - null.used()
    return null @ null.T


def _diag(mask: np.ndarray) -> np.ndarray:
    """``diag(mask)`` as floats (a fresh array): the identity times the 0/1 mask, column by
    column (exact: every entry is 1 * m_j or 0 * m_j)."""
    return identity(mask.size) * mask


def _none(n: int, null: np.ndarray | None) -> np.ndarray | None:
    """The ``free`` mask of a :class:`_Level` whose projector is ``null`` (None: zero)."""
    return np.zeros(n, dtype=bool) if null is None else None


def _scaling(a: np.ndarray, rest: np.ndarray, box: _Box, skip: np.ndarray) -> tuple[float, int]:
    """Largest ``s`` in [0, 1] with ``rest + s a`` in the box (SNS task scaling factor), and the
    joint that limits it (-1 if none). Joints in ``skip`` are already saturated.

    Per moving joint j (``a_j != 0``, not in ``skip``), ``rest_j + s a_j`` leaves the box at
    ``up_j = (bound_j - rest_j) / a_j`` with the bound it moves towards (hi if ``a_j > 0``) and
    enters it at ``down_j`` (the other bound); both rows are computed in one pass over the
    stacked bounds ``[hi; lo]`` / ``[lo; hi]``.
    """
    n = a.size
    if n == 0:
        return 1.0, -1
    pos = a > 0
    act = a < 0
    act |= pos
    act &= ~skip
    num = box.lo_hi.copy()  # [bound towards; bound away], (2, n)
    np.copyto(num, box.hi_lo, where=pos)
    num -= rest
    t = box.no_limit.copy()  # [inf; -inf]: joints that do not move never limit s
    np.divide(num, a, out=t, where=act)
    up, down = t
    critical = int(up.argmin())
    s_max = float(up[critical])
    if not s_max < np.inf:
        critical = -1
    if s_max < float(np.maximum.reduce(down)) or s_max < 0:  # rest itself is outside the box
        return 0.0, critical
    return min(s_max, 1.0), critical


def _segment(u0: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest ``t`` in [0, 1] with ``u0 + t d`` in the box ``[lo, hi]`` (u0 inside it). The
    solver passes the tolerance-widened box of its inside test, then clips the point to the
    exact box: a joint on its bound that rounding moves outwards by 1e-16 must not stop the
    whole segment at t = 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, (hi - u0) / d, np.where(d < 0, (lo - u0) / d, np.inf))
    return float(np.clip(np.min(t), 0.0, 1.0)) if t.size else 1.0
