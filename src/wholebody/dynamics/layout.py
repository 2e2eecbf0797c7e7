"""The shape of one torque-level problem (:class:`Layout`): its levels with their rows'
names, the cascade's arena laid out for them, and the buffers that Python fills each step
and the kernels (:mod:`wholebody.kernels.torque`) read. A solver makes a new one whenever
the stack's plan, the contacts, the carried objects or the wrench targets change."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg

from wholebody.dynamics.carry import GraspRows
from wholebody.errors import ConfigError
from wholebody.kernels import torque
from wholebody.solvers.plan import Plan, ProblemArena
from wholebody.solvers.stack import OBJECTIVES, LevelProblem, StackProblem

if TYPE_CHECKING:
    from wholebody.dynamics.solver import DynamicsSolver

__all__ = ["Layout"]

QUIET_EPS = 1e-6
"""The quiet rows' metric ``W = R^T R + eps I`` (its inverse and factor give the internal
wrenches' rows)."""
INTERNAL = "internal wrenches (regularisation)"


def _level(name: str, m: int, c: int, n: int, rows: dict, irows: dict) -> LevelProblem:
    """A level of ``m`` equality and ``c`` inequality rows over ``n`` unknowns (numbers
    written by the kernels)."""
    return LevelProblem(
        name, np.zeros((m, n)), np.zeros(m), np.zeros((c, n)), np.zeros(c), np.zeros(c), rows, irows
    )


def _named(parts: list[tuple[str, int]]) -> tuple[dict[str, slice], int]:
    """Consecutive named row blocks: ``{name: slice}`` and the total."""
    out, k = {}, 0
    for name, m in parts:
        out[name] = slice(k, k + m)
        k += m
    return out, k


class Layout:
    """The levels, the arena and the step's buffers of one problem shape (module docstring).

    Built from the solver's contacts and carried objects, the stack's ``plan`` (evaluated)
    and the first step's ``grasps`` rows (their counts)."""

    level_weights = np.ones(0)
    """The stack's levels' weights (weighted mode)."""

    def __init__(
        self,
        solver: DynamicsSolver,
        plan: Plan,
        grasps: list[GraspRows],
    ) -> None:
        self.nu = nu = solver.robot.nu
        nv = solver.robot.model.nv
        self.nc = nc = sum(c.size for c in solver.contacts)
        self.nw = nw = nc + sum(o.size for o in solver.objects)
        self.n = n = nu + nw
        self.key = solver.layout_key(plan)
        self._refs = (plan, list(solver.contacts), list(solver.objects))  # (ids stay valid)
        fs = solver.force_scale
        # the contact level: equality rows, wrench rows (contacts' constant), torque limits
        eq = [(f"contact {c.frame}", c.size) for c in solver.contacts]
        bounds = [c.wrench_bounds for c in solver.contacts]
        ineq = [
            (f"wrench {c.frame}", b[0].shape[0])
            for c, b in zip(solver.contacts, bounds, strict=True)
        ]
        self.owner = [k for k, (C, _, _) in enumerate(bounds) for _ in range(C.shape[0])]
        for k, (o, g) in enumerate(zip(solver.objects, grasps, strict=True)):
            eq.append((f"carry {o.name}", 6))
            if g.K.shape[0]:
                eq.append((f"closure {o.name}", g.K.shape[0]))
            if o.squeeze is not None:
                eq.append((f"squeeze {o.name}", 1))
            if g.C.shape[0]:
                ineq.append((f"grasp {o.name}", g.C.shape[0]))
                self.owner += [len(bounds) + k] * g.C.shape[0]
        eq_rows, m_e = _named(eq)
        m_c = sum(m for _, m in ineq)
        ineq.append(("torque limits", solver.driven.size))
        self.deferred = np.array([m_c, m_c + solver.driven.size], dtype=np.int64)
        """The torque limits' inequality rows in the arena (the weighted QP adds them only
        where its answer without them breaks one)."""
        ineq_rows, m_i = _named(ineq)
        self.Jw = np.zeros((nw, nv))
        self.eq_dv, self.eq_f, self.eq_b = np.zeros((m_e, nv)), np.zeros((m_e, nw)), np.zeros(m_e)
        self.cf, self.cf_lo, self.cf_hi = np.zeros((m_c, nw)), np.zeros(m_c), np.zeros(m_c)
        self.owner = np.array(self.owner, dtype=np.int64)
        self.G = np.zeros((6, nc))
        self.internal = np.zeros((nw, nw))
        p = col = 0
        for c, (C, lower, upper) in zip(solver.contacts, bounds, strict=True):  # constant
            self.cf[p : p + C.shape[0], col : col + c.size] = C * fs
            self.cf_lo[p : p + C.shape[0]], self.cf_hi[p : p + C.shape[0]] = lower, upper
            p, col = p + C.shape[0], col + c.size
        self.cf_lo[p:], self.cf_hi[p:] = -np.inf, 0.0  # a grasp's friction rows: C f <= 0
        self._quiet_rows(solver)
        self._targets(solver)
        levels, spec = [], []
        if solver.unactuated.size:
            name = "equations of motion"
            m = solver.unactuated.size
            levels.append(_level(name, m, 0, n, {name: slice(0, m)}, {}))
            spec.append((torque.LEVEL_EOM, 0, 0))
        levels.append(_level("contacts and actuators", m_e, m_i, n, eq_rows, ineq_rows))
        spec.append((torque.LEVEL_CONTACTS, 0, 0))
        if self.target_b.size:
            levels.append(_level("wrench targets", self.target_b.size, 0, n, self.target_names, {}))
            spec.append((torque.LEVEL_TARGETS, 0, 0))
        self.hard = len(levels)
        self.active = np.zeros(n + m_i, dtype=np.int64)
        """The weighted QP's working set, carried from step to step
        (:func:`~wholebody.kernels.torque.weighted_qp`)."""
        for level, row in self._stack_levels(solver, plan.problem(), n):
            levels.append(level)
            spec.append(row)
        if nw:
            name = "contact wrenches"
            m_q = self.quiet.shape[0]
            levels.append(_level(name, m_q, 0, n, {name: slice(0, m_q)}, {}))
            spec.append((torque.LEVEL_QUIET, 0, 0))
        self.spec = np.array(spec, dtype=np.int64)
        bounds = np.zeros(n)
        self.arena = ProblemArena(StackProblem(levels, bounds, bounds, np.ones(n), {}))

    def _quiet_rows(self, solver: DynamicsSolver) -> None:
        """The quiet rows (each contact's :meth:`~wholebody.dynamics.contacts.Contact.quiet`
        rows ``R``, a carried object's whole wrenches), and for the contacts the metric
        ``W = R^T R + eps I``'s inverse and Cholesky factor (transposed)."""
        R = [c.quiet() for c in solver.contacts]
        Rc = scipy.linalg.block_diag(*R) if R else np.zeros((0, 0))
        W = Rc.T @ Rc + QUIET_EPS * np.eye(self.nc)
        quiet = scipy.linalg.block_diag(Rc, *(np.eye(o.size) for o in solver.objects))
        self.quiet = quiet if self.nw else np.zeros((0, 0))
        self.W_inv, self.L_t = np.linalg.inv(W), np.linalg.cholesky(W).T

    def _targets(self, solver: DynamicsSolver) -> None:
        """The wrench targets' rows (a unit entry per held wrench entry) and names."""
        rows, names, col = [], [], 0
        for c in solver.contacts:
            if c.wrench_target is not None:
                held = np.flatnonzero(np.isfinite(c.wrench_target))
                block = np.zeros((held.size, self.nw))
                block[np.arange(held.size), col + held] = 1.0
                rows.append(block)
                names.append((f"wrench target {c.frame}", held.size))
            col += c.size
        self.targets = np.vstack(rows) if rows else np.zeros((0, self.nw))
        self.target_b = np.zeros(self.targets.shape[0])
        self.target_names, _ = _named(names)

    def _stack_levels(
        self, solver: DynamicsSolver, problem: StackProblem, n: int
    ) -> list[tuple[LevelProblem, tuple[int, int, int]]]:
        """The stack's levels (strict: one arena level each; weighted: one for all, with
        its rows' names), each with its ``spec`` row."""
        regularised = solver.wrench_regularization > 0.0 and self.nw > 0
        if solver.mode == "strict":
            out = []
            for k, lp in enumerate(problem.levels):
                m, c = lp.A.shape[0], lp.C.shape[0]
                internal = regularised and m > 0 and OBJECTIVES not in lp.task_rows
                rows = dict(lp.task_rows)
                if internal:
                    rows[INTERNAL] = slice(m, m + self.nw)
                level = _level(lp.name, m + self.nw * internal, c, n, rows, lp.inequality_rows)
                out.append((level, (torque.LEVEL_STACK, k, int(internal))))
            return out
        weights = solver.level_weights or [1.0] * len(problem.levels)
        if len(weights) != len(problem.levels):
            raise ConfigError(
                f"DynamicsSolver: {len(weights)} level_weights for {len(problem.levels)} levels"
            )
        self.level_weights = np.array(weights, dtype=float)
        rows, irows, k, c = {}, {}, 0, 0
        for lp in problem.levels:
            for name, sl in lp.task_rows.items():
                key = f"{OBJECTIVES} ({lp.name})" if name == OBJECTIVES else name
                rows[key] = slice(k + sl.start, k + sl.stop)
            for name, sl in lp.inequality_rows.items():
                irows[name] = slice(c + sl.start, c + sl.stop)
            k, c = k + lp.A.shape[0], c + lp.C.shape[0]
        internal = regularised and k > 0
        if internal:
            rows[INTERNAL] = slice(k, k + self.nw)
        level = _level("tasks", k + self.nw * internal, c, n, rows, irows)
        return [(level, (torque.LEVEL_STACK, -1, int(internal)))]

    def fill(self, solver: DynamicsSolver, grasps: list[GraspRows]) -> None:
        """The step's rows into the buffers that the contacts' kernel does not write
        (:func:`wholebody.kernels.contacts.contact_rows`): the grasps' rows and the wrench
        targets."""
        fs, r, col = solver.force_scale, self.nc, self.nc
        p = self.cf.shape[0] - sum(g.C.shape[0] for g in grasps)
        for o, g in zip(solver.objects, grasps, strict=True):
            r, p = self._grasp(o.size, o.squeeze, g, r, p, col, fs)
            col += o.size
        k = 0
        for c in solver.contacts:
            if c.wrench_target is not None:
                held = c.wrench_target[np.isfinite(c.wrench_target)]
                self.target_b[k : k + held.size] = held / fs
                k += held.size

    def _grasp(
        self, size: int, squeeze: float | None, g: GraspRows, r: int, p: int, col: int, fs: float
    ) -> tuple[int, int]:
        """A carried object's rows (its equations over ``s_f``, the closure, the squeeze,
        the friction rows, the internal part of its hands' wrenches); the next free rows."""
        cols = slice(col, col + size)
        self.Jw[cols] = np.vstack(g.jacobians)
        self.eq_dv[r : r + 6] = g.E_dv / fs
        self.eq_f[r : r + 6, cols] = g.E_f
        self.eq_b[r : r + 6] = g.e / fs
        r += 6
        m = g.K.shape[0]
        self.eq_dv[r : r + m], self.eq_b[r : r + m] = g.K, g.k
        r += m
        if squeeze is not None:
            self.eq_f[r, cols], self.eq_b[r] = g.squeeze, squeeze / fs
            r += 1
        m = g.C.shape[0]
        self.cf[p : p + m, cols] = g.C * fs
        self.internal[cols, cols] = np.eye(size) - np.linalg.pinv(g.E_f) @ g.E_f
        return r, p + m
