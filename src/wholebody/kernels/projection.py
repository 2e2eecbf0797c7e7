"""The projection backend in kernels: damped pseudo-inverse, recursive null-space projection,
Saturation in the Null Space, and inequality rows held by an active set, on a compiled stack's
arena (:mod:`wholebody.solvers.projection` documents the method).

A pass runs the levels in order, each on the free directions the levels above leave
(:mod:`~wholebody.kernels.pinv`), and, where the box must be enforced, saturates it
(:mod:`~wholebody.kernels.sns`). The box-free pass comes first: when its solution is inside
the box it is the answer; otherwise SNS runs from the start for ``d = u - u_c``, ``u_c`` the
box's point closest to rest. This is done in the box of every limit but the acceleration
limits; where that solution ``u*`` leaves the acceleration window, a second SNS pass from the
last velocity asks each level for its demand at the scale that box gave it, then for ``u*`` in
what they leave free
(:mod:`wholebody.solvers.projection`, "Acceleration limits"). Inequality rows of the stack are
held above every level: the rows the solution violates become equality rows at their bound in
a first level, and the stack is solved again, until none is violated.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.layout import fmat, fvec, imat, ivec
from wholebody.kernels.linalg import combine, dot, level_report, mv
from wholebody.kernels.pinv import (
    PAR_SATURATE,
    PAR_TOLERANCE,
    PAR_WIDTH,
    Free,
    basis,
    diagonal_step,
    free_of,
    free_rank,
    identity_rows,
    level_step,
    project_free,
)
from wholebody.kernels.sns import Box, inside, saturate, saturate_identity

__all__ = ["MESSAGE_EMPTY_BOX", "MESSAGE_NON_FINITE", "PAR_WIDTH", "project"]

_INSIDE_TOL = 1e-10
MESSAGE_EMPTY_BOX, MESSAGE_NON_FINITE = 1, 2  # I_OUT[OUT_MESSAGE]
STATUS_OK, STATUS_BOUNDS, STATUS_SCALED, STATUS_INFEASIBLE, STATUS_FAILED = 0, 1, 2, 3, 4

Rows = namedtuple("Rows", ["A", "b", "reference", "identity"])
"""A level's rows ``A u~ = b``, the scale its damping is decided on (the lightest task's
``sqrt(w)``) and, for a level of objectives only, the scale ``s`` of its rows ``s I`` (else
0)."""


@kernel
def _level(
    rows: Rows, u0: np.ndarray, free: Free, sat: np.ndarray, box: Box, sns: bool, par: np.ndarray
):
    """One level on top of the levels above (their solution ``u0``, the free directions and
    the joints saturated so far): ``(u, free left, saturated, scale)``. A level of rows ``s I``
    (objectives, or tasks certified so by :func:`identity_rows`) moves by ``F (b / s - u0)``
    and leaves nothing free; any other level takes :func:`level_step` on a basis of ``F``."""
    A, b, ids = rows.A, rows.b, rows.identity
    n, m = u0.shape[0], A.shape[0]
    if m == 0:
        return u0, free, sat, 1.0
    scale = 1.0 / rows.reference  # damping decided independently of a common scale
    s = ids if ids > 0 else identity_rows(A, scale, par)
    if scale != 1.0:
        b = b * scale
        A = A * scale if s == 0.0 else A  # (rows s I: scaled only if saturate needs them)
    if s > 0:
        d = np.empty(n)
        for j in range(n):
            d[j] = b[j] / s - u0[j]
        u = combine(u0, 1.0, project_free(d, free))
        left = free_of(np.zeros((n, 0)), ids > 0, np.zeros(n, np.bool_))
    else:
        Au = mv(A, u0)
        R = np.empty((m, 1))
        for k in range(m):
            R[k, 0] = b[k] - Au[k]
        ok, dx = diagonal_step(A, R[:, 0], free, par)
        if ok:  # (a posture below a certified level: no basis needed)
            u, left = combine(u0, 1.0, dx), free_of(np.zeros((n, 0)), False, free.mask)
        else:
            Y, left, _ = level_step(A, R, basis(free), par, False)
            u = combine(u0, 1.0, Y[:, 0])
    if not sns or inside(u, box.lo_tol, box.hi_tol):
        return u, left, sat, 1.0
    if ids > 0:
        return saturate_identity(b, ids, u0, free, sat, box)
    if s > 0 and scale != 1.0:
        A = A * scale
    return saturate(A, b, u0, free, sat, box, par)


@kernel
def _widened(lo: np.ndarray, hi: np.ndarray) -> Box:
    """The box and its form widened by the tolerance of the inside test."""
    n = lo.shape[0]
    wide_lo, wide_hi = np.empty(n), np.empty(n)
    for j in range(n):
        wide_lo[j] = lo[j] - _INSIDE_TOL * (abs(lo[j]) + 1.0)
        wide_hi[j] = hi[j] + _INSIDE_TOL * (abs(hi[j]) + 1.0)
    return Box(lo, hi, wide_lo, wide_hi)


@kernel
def _pass(
    f: np.ndarray,
    i: np.ndarray,
    h: np.ndarray,
    held: Rows,
    box: Box,
    u_c: np.ndarray,
    sns: bool,
    goal: np.ndarray,
    par: np.ndarray,
) -> np.ndarray:
    """One pass over the held rows' level (if any) and the stack's levels, for ``d = u - u_c``
    (right-hand sides shifted by ``A u_c``): box-free, or with SNS (``sns``; the levels'
    scale factors into ``F_LEVEL_OUT``). With a ``goal`` velocity (else empty), the solution
    in the other limits' box whose scale factors ``F_LEVEL_OUT`` holds, each level asks for its
    own demand times its scale factor there (what that box could deliver, in the level's own
    direction), and a last level for ``goal`` itself takes what the levels leave free.
    Returns ``d``."""
    levels, lf = imat(i, h, lay.I_LEVEL), fmat(f, h, lay.F_LEVEL)
    A, b = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B)
    lev_out = fmat(f, h, lay.F_LEVEL_OUT)
    n, L = u_c.shape[0], levels.shape[0]
    u = np.zeros(n)
    sat = np.zeros(n, np.bool_)
    mask = np.ones(n, np.bool_)
    if sns:
        for j in range(n):
            sat[j] = box.lo[j] == box.hi[j]
            mask[j] = not sat[j]
    free = free_of(np.zeros((n, 0)), True, mask)
    first = -1 if held.A.shape[0] else 0
    to_goal = combine(goal, -1.0, u_c) if goal.shape[0] else goal
    for k in range(first, L):
        if k < 0:
            rows = Rows(held.A, combine(held.b, -1.0, mv(held.A, u_c)), 1.0, 0.0)
        else:
            r0, r1 = levels[k, lay.LEVEL_ROW0], levels[k, lay.LEVEL_ROW_END]
            if goal.shape[0]:  # its own demand, at the scale the other limits allowed
                bk = combine(b[r0:r1] * lev_out[k, 1], -1.0, mv(A[r0:r1], u_c))
            else:
                bk = combine(b[r0:r1], -1.0, mv(A[r0:r1], u_c)) if sns else b[r0:r1]
            rows = Rows(A[r0:r1], bk, lf[k, lay.LEVEL_REFERENCE], lf[k, lay.LEVEL_IDENTITY])
        u, free, sat, s = _level(rows, u, free, sat, box, sns, par)
        if sns and k >= 0:
            lev_out[k, 1] = s
    if goal.shape[0] and free_rank(free) > 0:
        u, free, sat, s = _level(
            Rows(np.zeros((n, 0)), to_goal, 1.0, 1.0), u, free, sat, box, sns, par
        )
    return u


@kernel
def _solve(f: np.ndarray, i: np.ndarray, h: np.ndarray, held: Rows, par: np.ndarray):
    """The stack (with the held rows on top) in the box. First in the box of every limit but
    the acceleration limits (:func:`_solve_in`): ``u*``. Where acceleration limits leave
    ``u*`` out of reach, the levels are solved again from the last velocity, with SNS in the
    whole box, each asking for its demand times the scale factor the first box gave it (a
    demand that box could deliver), then ``u*`` in the directions left free (:func:`_pass`
    with a goal). ``(u, u_free, sns)``."""
    box = fmat(f, h, lay.F_BOX)
    fmat(f, h, lay.F_LEVEL_OUT)[:, 1] = 1.0
    goal, u_free, sns = _solve_in(f, i, h, held, box[2], box[3], par)
    lo, hi = box[0], box[1]
    wide = _widened(lo, hi)
    if par[PAR_SATURATE] == 0.0 or inside(goal, wide.lo_tol, wide.hi_tol):
        return goal, u_free, sns
    anchor = fvec(f, h, lay.F_ANCHOR)
    n = lo.shape[0]
    u_c = np.empty(n)  # from the box's point closest to the last velocity
    for j in range(n):
        u_c[j] = min(max(anchor[j], lo[j]), hi[j])
    shifted = _widened(combine(lo, -1.0, u_c), combine(hi, -1.0, u_c))
    d = _pass(f, i, h, held, shifted, u_c, True, goal, par)
    return combine(d, 1.0, u_c), u_free, True


@kernel
def _solve_in(
    f: np.ndarray,
    i: np.ndarray,
    h: np.ndarray,
    held: Rows,
    lo: np.ndarray,
    hi: np.ndarray,
    par: np.ndarray,
):
    """The stack in the box ``lo, hi``: the box-free pass, then SNS from the box's point
    closest to rest where its solution leaves the box. ``(u, u_free, sns)``."""
    n = lo.shape[0]
    wide = _widened(lo, hi)
    none = np.zeros(0)
    u_free = _pass(f, i, h, held, wide, np.zeros(n), False, none, par)
    if par[PAR_SATURATE] == 0.0 or inside(u_free, wide.lo_tol, wide.hi_tol):
        return u_free, u_free, False
    u_c = np.empty(n)  # SNS for d = u - u_c from d = 0, u_c the box's point closest to rest
    for j in range(n):
        u_c[j] = min(max(0.0, lo[j]), hi[j])
    shifted = _widened(combine(lo, -1.0, u_c), combine(hi, -1.0, u_c))
    d = _pass(f, i, h, held, shifted, u_c, True, none, par)
    return combine(d, 1.0, u_c), u_free, True


@kernel
def _violated(
    C: np.ndarray, cb: np.ndarray, u: np.ndarray, held: np.ndarray, value: np.ndarray, tol: float
) -> bool:
    """Hold the inequality rows ``u`` violates beyond ``tol (1 + |bound|)`` that are not held
    yet, at the bound they cross (``value``); whether there was one. Rows with no finite bound
    are never held."""
    some = False
    for r in range(C.shape[0]):
        lo, hi = cb[0, r], cb[1, r]
        if held[r] or not (math.isfinite(lo) or math.isfinite(hi)):
            continue
        cu = dot(C[r], u)
        if not (lo - tol * (1.0 + abs(lo)) <= cu <= hi + tol * (1.0 + abs(hi))):
            held[r] = 1
            value[r] = lo if cu < lo else hi
            some = True
    return some


@kernel
def _held_rows(C: np.ndarray, held: np.ndarray, value: np.ndarray) -> Rows:
    """The held rows as a level: ``C_r u = value_r``, in row order."""
    count = 0
    for r in range(C.shape[0]):
        count += held[r] != 0
    A = np.empty((count, C.shape[1]))
    b = np.empty(count)
    k = 0
    for r in range(C.shape[0]):
        if held[r]:
            A[k], b[k] = C[r], value[r]
            k += 1
    return Rows(A, b, 1.0, 0.0)


@kernel
def project(f: np.ndarray, i: np.ndarray, h: np.ndarray, par: np.ndarray) -> None:
    """Solve the evaluated stack: ``F_U`` (scaled and actuated), per level its residual and
    scale factor, per task its residuals and whether it is met, the held inequality rows
    (``I_HELD``), the active bounds and the status (``I_OUT``, see :func:`_report`)."""
    box = fmat(f, h, lay.F_BOX)
    out = ivec(i, h, lay.I_OUT)
    C, cb = fmat(f, h, lay.F_C), fmat(f, h, lay.F_CB)
    held = ivec(i, h, lay.I_HELD)
    n, P = box.shape[1], C.shape[0]
    out[:] = 0
    held[:] = 0
    tol = par[PAR_TOLERANCE]
    for j in range(n):
        if not box[0, j] <= box[1, j]:  # NaN compares false; evaluate never crosses the box
            out[lay.OUT_FAILED], out[lay.OUT_MESSAGE] = 1, MESSAGE_EMPTY_BOX
            fmat(f, h, lay.F_LEVEL_OUT)[:, 1] = 1.0
            _report(f, i, h, np.zeros(n), tol, np.zeros(n), False, np.zeros(0))
            return
    value = np.zeros(P)
    u, u_free, sns = _solve(f, i, h, _held_rows(C, held, value), par)
    for it in range(P):
        if not _violated(C, cb, u, held, value, tol):
            break
        if it == 0:  # which tasks were unmet before any row was held (for the message)
            _report(f, i, h, u, tol, u_free, sns, value)
            ivec(i, h, lay.I_UNMET0)[:] = ivec(i, h, lay.I_INFEASIBLE)
        u, u_free, sns = _solve(f, i, h, _held_rows(C, held, value), par)
    if not math.isfinite(dot(u, u)):
        for j in range(n):
            if not math.isfinite(u[j]):
                out[lay.OUT_FAILED], out[lay.OUT_MESSAGE] = 1, MESSAGE_NON_FINITE
                for m in range(n):
                    u[m] = min(max(0.0, box[0, m]), box[1, m])
                break
    _report(f, i, h, u, tol, u_free, sns, value)


@kernel
def _held_unmet(
    C: np.ndarray, held: np.ndarray, value: np.ndarray, u: np.ndarray, tol: float
) -> bool:
    """Mark the held rows that miss their bound by more than ``tol (1 + |bound|)`` (the box
    kept them from it) HELD_UNMET, the others HELD_MET; whether there is one."""
    some = False
    for r in range(C.shape[0]):
        if held[r]:
            unmet = abs(dot(C[r], u) - value[r]) > tol * (1.0 + abs(value[r]))
            held[r] = lay.HELD_UNMET if unmet else lay.HELD_MET
            some = some or unmet
    return some


@kernel
def _report(
    f: np.ndarray,
    i: np.ndarray,
    h: np.ndarray,
    u: np.ndarray,
    tol: float,
    u_free: np.ndarray,
    sns: bool,
    value: np.ndarray,
) -> None:
    """Residuals, met tasks, active bounds and status at the scaled solution ``u``.

    INFEASIBLE when a task of the first level is unmet, or a held inequality row is
    (``I_HELD``), or (without held rows) when SNS ran and the box raised a task's weighted
    residual above that at the box-free solution ``u_free`` by more than ``tol (1 + ||b_t||)``
    (with held rows that reads BOUNDS_ACTIVE: the held rows took the freedom); else SCALED
    when a level was scaled; else BOUNDS_ACTIVE when an entry of ``u`` is on a bound.
    """
    box, D = fmat(f, h, lay.F_BOX), fmat(f, h, lay.F_METRIC)[0]
    lo, hi = box[0], box[1]
    levels, tasks = imat(i, h, lay.I_LEVEL), imat(i, h, lay.I_TASK)
    A, b, rows = fmat(f, h, lay.F_A), fvec(f, h, lay.F_B), fmat(f, h, lay.F_ROW)
    out, lev_out = ivec(i, h, lay.I_OUT), fmat(f, h, lay.F_LEVEL_OUT)
    res = fmat(f, h, lay.F_TASK_RES)
    infeasible, active = ivec(i, h, lay.I_INFEASIBLE), ivec(i, h, lay.I_ACTIVE)
    held = ivec(i, h, lay.I_HELD)
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
            lev_out[k, 0] = level_report(
                A[r0:r1], b[r0:r1], rows[1, r0:r1], u, tasks[t0:t1], r0, res[t0:t1]
            )
            if sns:
                level_report(
                    A[r0:r1], b[r0:r1], rows[1, r0:r1], u_free, tasks[t0:t1], r0, free_res[t0:t1]
                )
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
    some_held = False
    for r in range(held.shape[0]):
        some_held = some_held or held[r] != 0
    held_unmet = some_held and _held_unmet(fmat(f, h, lay.F_C), held, value, u, tol)
    out[lay.OUT_STATUS] = _status(
        out[lay.OUT_FAILED] != 0,
        top_unmet or held_unmet,
        limited,
        some_held,
        _any_below_one(lev_out[:, 1]),
        any_active,
    )


@kernel
def _status(
    failed: bool, unmet: bool, limited: bool, held: bool, scaled: bool, active: bool
) -> int:
    """The status (:func:`_report`): FAILED; INFEASIBLE where a task of the first level or a
    held row is unmet, or the box limited a task (BOUNDS_ACTIVE with rows held: they took
    the freedom); SCALED; BOUNDS_ACTIVE; OK."""
    if failed:
        return STATUS_FAILED
    if unmet:
        return STATUS_INFEASIBLE
    if limited:
        return STATUS_BOUNDS if held else STATUS_INFEASIBLE
    if scaled:
        return STATUS_SCALED
    return STATUS_BOUNDS if active else STATUS_OK


@kernel
def _any_below_one(x: np.ndarray) -> bool:
    """Whether some ``x_k < 1``."""
    for k in range(x.shape[0]):
        if x[k] < 1.0:
            return True
    return False
