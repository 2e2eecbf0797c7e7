"""The cascade's Python side: its workspace, its two drivers and the result.

With daqp the whole cascade is one kernel call (:func:`wholebody.kernels.hqp.cascade`, daqp
called from the kernel). With another engine the kernels run the cascade until a level needs
a QP and say so; here the level's engine solves it (with the same retries: 100 and 10000
times the Tikhonov term after a failure, the engine reset), the answer goes back to the
kernels, and so on until the tie-break and the result
(:class:`~wholebody.solvers.hqp.HierarchicalQPSolver` documents the method).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba
import numpy as np

from wholebody import kernels
from wholebody.kernels import control, hqp, hqp_state
from wholebody.kernels import layout as lay
from wholebody.kernels.evaluate import evaluate
from wholebody.solvers.level_report import LevelReport
from wholebody.solvers.plan import Arena, Plan, first_call
from wholebody.solvers.qp import QPStatus
from wholebody.solvers.result import SolverResult

if TYPE_CHECKING:
    from wholebody.solvers.hqp import HierarchicalQPSolver

__all__ = ["Workspace", "run"]

_FAILURE = {
    hqp_state.FAIL_DECOMPOSITION: "decomposition failed (LAPACK); level skipped",
    hqp_state.FAIL_STEP: "decomposition failed (non-finite step); level skipped",
}


class Workspace:
    """The cascade's state between its kernel calls, sized for one arena."""

    def __init__(self, arena: Arena) -> None:
        v = arena.view
        n = v(lay.F_BOX).shape[1]
        levels = v(lay.I_LEVEL)
        L = levels.shape[0]
        m_max = int(np.max(levels[:, 2] - levels[:, 0], initial=0))
        p_max = int(np.max(levels[:, 4] - levels[:, 3], initial=0))
        P = v(lay.F_C).shape[0]
        T, Pt = v(lay.I_TASK).shape[0], v(lay.I_INEQ).shape[0]
        nv = n + p_max
        rows = n + P + p_max
        shapes = {
            hqp_state.W_X: (n,),
            hqp_state.W_BOX: (4, n),
            hqp_state.W_Z: (n * n,),
            hqp_state.W_INH: (P, n),
            hqp_state.W_INHB: (2, P),
            hqp_state.W_XC: (n,),
            hqp_state.W_CV: (m_max + n,),  # (+ n: a damped level's damping rows)
            hqp_state.W_M: ((m_max + n) * n,),
            hqp_state.W_NULL: (n * n,),
            hqp_state.W_SCAL: (8,),
            hqp_state.W_H: (nv * nv,),
            hqp_state.W_G: (2, nv),
            hqp_state.W_QC: (rows * nv,),
            hqp_state.W_QB: (4, max(rows, nv)),
            hqp_state.W_Y: (2, max(n, m_max)),
            hqp_state.W_STATE: (hqp_state.S_WIDTH,),
            hqp_state.W_REPORT: (L, hqp_state.R_WIDTH),
            hqp_state.W_LIMITED: (T + Pt,),
        }
        self.f, self.i, self.h = lay.build(shapes, hqp_state.N_WFLOAT, hqp_state.N_WREGIONS)
        self._shapes = shapes
        self.arena = arena
        self.state = self.view(hqp_state.W_STATE)
        self.report = self.view(hqp_state.W_REPORT)
        self.limited = self.view(hqp_state.W_LIMITED)
        self.record = control.Arena(self.f, self.i, self.h)
        self._H, self._g = self.view(hqp_state.W_H), self.view(hqp_state.W_G)
        self._Q, self._qb = self.view(hqp_state.W_QC), self.view(hqp_state.W_QB)
        self._nv = nv

    def view(self, region: int) -> np.ndarray:
        arena = self.f if region < hqp_state.N_WFLOAT else self.i
        return lay.view(arena, self.h, region, self._shapes[region])

    def qp(self) -> tuple[np.ndarray, ...]:
        """The QP the kernels set up, as the engine takes it: ``H, g, C, lower, upper`` and
        the box ``lb, ub`` (None where the problem has none)."""
        st = self.state
        nv, rows, has_box = (
            int(st[hqp_state.S_NV]),
            int(st[hqp_state.S_NROWS]),
            st[hqp_state.S_HASBOX],
        )
        qb = self._qb
        lb = qb[2, :nv] if has_box else None
        ub = qb[3, :nv] if has_box else None
        H, Q = self._H[: nv * nv].reshape(nv, nv), self._Q[: rows * nv].reshape(rows, nv)
        return H, self._g[0, :nv], Q, qb[0, :rows], qb[1, :rows], lb, ub

    def padded(self, x: np.ndarray | None) -> np.ndarray:
        """An engine's answer as the kernels take it (zeros where there is none)."""
        out = np.zeros(self._nv)
        if x is not None:
            out[: x.shape[0]] = x
        return out


def _solve(engine, ws: Workspace) -> tuple[object, bool]:
    sol = engine.solve(*ws.qp())
    return sol, sol.status <= QPStatus.INACCURATE and bool(np.all(np.isfinite(sol.x)))


def run(solver: HierarchicalQPSolver, arena: Arena, ws: Workspace) -> None:
    """The cascade on the evaluated ``arena`` (see the module docstring); its outcome is in
    the arena and the workspace."""
    if solver.in_kernel:
        first_call(
            "hqp",
            "the hierarchical QP kernels",
            hqp.cascade,
            arena.f,
            arena.i,
            arena.h,
            ws.f,
            ws.i,
            ws.h,
            solver.parameters(),
            solver._daqp_settings,
        )
    elif _READY:
        _cascade(solver, arena, ws)
    else:
        first_call("hqp stages", "the hierarchical QP kernels", _compile_then, solver, arena, ws)


def run_steps(
    solver: HierarchicalQPSolver,
    plan: Plan,
    ws: Workspace,
    kinematics: control.Kinematics,
    batch: control.Batch,
    steps: int,
    what: int,
) -> None:
    """Whole steps on the synced ``plan`` (:mod:`wholebody.kernels.control`): one kernel
    call with daqp; with another engine one state and one step, the engine's QPs between the
    kernel stages."""
    arena = plan.step_buffers(batch.refs.shape[1]).arena
    if solver.in_kernel or batch.Q.shape[0] != 1 or steps != 1:
        solver.kernel_run(arena, kinematics, batch, steps, what, ws.record)  # (daqp only)
        return
    q = batch.Q[0]
    if not math.isfinite(q.dot(q)):  # (as the kernels do)
        batch.status[0] = control.NOT_FINITE
        return
    if what & control.KINEMATICS:
        first_call("kinematics", "the control kernels", control.kinematics, kinematics, q, what)
    first_call(
        "evaluate",
        "the control kernels",
        evaluate,
        plan.f,
        plan.i,
        plan.h,
        kinematics.J,
        kinematics.oMf,
        q,
        batch.refs[0],
    )
    run(solver, plan, ws)
    first_call(
        "after", "the control kernels", control.after, arena, kinematics, q, batch.Q_next[0], what
    )
    batch.U[0] = plan.view(lay.F_U)[1]
    if not what & control.INTEGRATE:
        batch.Q_next[0] = q
    batch.status[0] = plan.view(lay.I_OUT)[lay.OUT_STATUS]
    batch.params[0] = plan.view(lay.F_PAR)


_READY = False  # whether every stage is compiled in this process


def _compile_then(solver: HierarchicalQPSolver, arena: Arena, ws: Workspace) -> None:
    """The first cascade of a process: every stage compiled (or loaded from the cache)
    first, so that no later step pays for a stage this one did not need."""
    global _READY
    if not kernels.DISABLED:
        a = (arena.f, arena.i, arena.h, ws.f, ws.i, ws.h, solver.parameters())
        sol, w = ws.padded(None), (ws.f, ws.i, ws.h)
        stages = (
            (hqp.begin, a),
            (hqp.advance, a),
            (hqp.finish, a),
            (hqp.after_qp, (*a, sol, True)),
            (hqp.proximal, (*a, sol, True)),
            (hqp.tie_done, (*w, sol, True)),
            (hqp.bump, (*w, 1)),
        )
        for stage, args in stages:
            stage.compile(tuple(numba.typeof(v) for v in args))
    _READY = True
    _cascade(solver, arena, ws)


def _cascade(solver: HierarchicalQPSolver, arena: Arena, ws: Workspace) -> None:
    """The cascade's stages driven from Python, the QPs solved by the solver's engine."""
    a = (arena.f, arena.i, arena.h, ws.f, ws.i, ws.h, solver.parameters())
    code = hqp.begin(*a)
    report = ws.report
    L = report.shape[0]
    while code != hqp.DONE:
        if code == hqp.NEXT:
            code = hqp.advance(*a)
            continue
        k = int(ws.state[hqp_state.S_K])
        if code == hqp.NEED_TIE:
            sol, ok = _solve(solver.engine(L), ws)
            ws.state[hqp_state.S_TIESTATUS] = int(sol.status)
            code = hqp.tie_done(ws.f, ws.i, ws.h, ws.padded(sol.x if ok else None), ok)
            continue
        engine = solver.engine(k)
        if code == hqp.NEED_QP:
            for attempt in range(3):
                if attempt:  # ill-conditioned and degenerate: retry cold, 100x more Tikhonov
                    engine.reset()
                    hqp.bump(ws.f, ws.i, ws.h, attempt)
                    report[k, hqp_state.R_RETRIES] += 1
                sol, ok = _solve(engine, ws)
                report[k, hqp_state.R_STATUS] = int(sol.status)
                report[k, hqp_state.R_ITER] += sol.iterations
                if ok:
                    break
            code = hqp.after_qp(*a, ws.padded(sol.x if ok else None), ok)
        else:  # NEED_PROXIMAL
            sol, ok = _solve(engine, ws)
            report[k, hqp_state.R_ITER] += sol.iterations
            code = hqp.proximal(*a, ws.padded(sol.x if ok else None), ok)
    hqp.finish(*a)


def result(solver: HierarchicalQPSolver, arena: Arena, ws: Workspace) -> SolverResult:
    """The outcome as a :class:`SolverResult`, with the engine's iterations, failures,
    infeasible tasks and a clip beyond the relaxation in the message."""
    out = arena.result(0.0, scale=False)
    failures = _failures(solver, arena, ws)
    extra = _inequality_infeasible(arena, ws)
    out.infeasible += extra
    report = ws.report
    names = arena.level_names
    qps = [
        f"{names[k]}: {int(report[k, hqp_state.R_ITER])} it"
        for k in range(len(names))
        if report[k, hqp_state.R_QP]
    ]
    msg = [f"{solver.engine_name}: " + ("; ".join(qps) if qps else "no QP needed"), *failures]
    if out.infeasible:
        msg.append("infeasible: " + ", ".join(f"{lv}/{t}" for lv, t in out.infeasible))
    clip = float(ws.view(hqp_state.W_SCAL)[hqp_state.C_CLIP])
    if clip > 10 * solver.bound_relaxation:
        msg.append(f"clipped u by {clip:.2e} (scaled units) to the box")
    out.message = "; ".join(msg)
    return out


def _limited_names(arena: Arena, ws: Workspace, k: int) -> list[str]:
    """The tasks the box limited at level k, the inequality tasks it leaves violated, or the
    tasks with non-finite rows of a level skipped for them."""
    limited, report = ws.limited, ws.report
    T = len(arena.task_names)
    tasks = arena.view(lay.I_TASK)
    names = [arena.task_names[t] for t in range(T) if tasks[t, 0] == k and limited[t]]
    if report[k, hqp_state.R_OBJBAD]:
        names.append("objectives")
    names += [
        row[3] for j, row in enumerate(arena.inequality_rows) if row[0] == k and limited[T + j]
    ]
    if report[k, hqp_state.R_FAIL] == hqp_state.FAIL_NONFINITE and not names:
        names = [arena.level_names[k]]
    return names


def _inequality_infeasible(arena: Arena, ws: Workspace) -> list[tuple[str, str]]:
    """Inequality tasks left violated, and those of a skipped level: per level, a skipped
    level's other inequality tasks first, then those violated or with non-finite rows."""
    out: list[tuple[str, str]] = []
    T = len(arena.task_names)
    for k, level in enumerate(arena.level_names):
        rows = [(j, row[3]) for j, row in enumerate(arena.inequality_rows) if row[0] == k]
        if ws.report[k, hqp_state.R_FAILED]:
            out += [(level, name) for j, name in rows if not ws.limited[T + j]]
        out += [(level, name) for j, name in rows if ws.limited[T + j]]
    return out


def _failures(solver: HierarchicalQPSolver, arena: Arena, ws: Workspace) -> list[str]:
    st, report = ws.state, ws.report
    out = []
    if st[hqp_state.S_BOXBAD]:
        out.append("the box is empty or not a number (NaN bounds): u = 0")
    for k, level in enumerate(arena.level_names):
        code = int(report[k, hqp_state.R_FAIL])
        if code == hqp_state.FAIL_NONFINITE:
            bad = ", ".join(_limited_names(arena, ws, k))
            out.append(f"{level}: non-finite rows from {bad}; level skipped")
        elif code == hqp_state.FAIL_ENGINE:
            status = QPStatus(int(report[k, hqp_state.R_STATUS])).name.lower()
            out.append(f"{level}: {status} ({solver.engine_name}); level left unsolved")
        elif code:
            out.append(f"{level}: {_FAILURE[code]}")
    if st[hqp_state.S_TIEFAIL]:
        status = QPStatus(int(st[hqp_state.S_TIESTATUS])).name.lower()
        out.append(
            f"minimum-norm tie-break: {status} ({solver.engine_name}); kept the last level's answer"
        )
    return out


def reports(arena: Arena, ws: Workspace) -> list[LevelReport]:
    """The per-level reports of the last solve."""
    report = ws.report
    residuals = arena.view(lay.F_LEVEL_OUT)[:, 0]
    out = []
    for k, name in enumerate(arena.level_names):
        row = report[k].tolist()
        qp = bool(row[hqp_state.R_QP])
        out.append(
            LevelReport(
                name,
                free=row[hqp_state.R_FREE],
                rank=row[hqp_state.R_RANK],
                qp=qp,
                engine_status=QPStatus(row[hqp_state.R_STATUS]) if qp else None,
                iterations=row[hqp_state.R_ITER],
                residual=float(residuals[k]),
                retries=row[hqp_state.R_RETRIES],
                limited=_limited_names(arena, ws, k),
                failed=bool(row[hqp_state.R_FAILED]),
                damped=bool(row[hqp_state.R_DAMPED]),
            )
        )
    return out
