"""After a solve, in kernels: which tasks the bounds limited (their anti-windup), the pose
tasks' integrals and the acceleration limits' memory.

A task is *saturated* (its integral must not wind up) when the hard constraints limited it in
the solve: its level's motion was scaled (``F_LEVEL_OUT[:, 1] < 1``, projection), or it is
reported unmet (``I_INFEASIBLE``), or a bound is active (``I_ACTIVE``) on an entry of ``u``
that its rows move (a column of its scaled rows above ``1e-12`` of their largest entry: a
joint no task row uses may rest on its limit without stopping any integral). The flags go to
``I_SATURATED``; Python tasks read them there (:meth:`wholebody.solvers.plan.Plan.advance_python`).
"""

from __future__ import annotations

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.layout import fmat, fvec, imat, ivec
from wholebody.kernels.rows import advance_integral

__all__ = ["ADVANCE_FLAGS", "ADVANCE_MEMORY", "ADVANCE_TASKS", "advance", "advance_entries"]

_ZERO_COLUMN = 1e-12
# what advance() does (bits): compute the flags from the outcome regions, advance the compiled
# tasks' integrals with the flags, keep u in the compiled limits' memory
ADVANCE_FLAGS, ADVANCE_TASKS, ADVANCE_MEMORY = 1, 2, 4


@kernel
def saturation_flags(f: np.ndarray, i: np.ndarray, h: np.ndarray) -> None:
    """Each equality task's anti-windup flag from the solve's outcome (module docstring)."""
    tasks, A = imat(i, h, lay.I_TASK), fmat(f, h, lay.F_A)
    scale = fmat(f, h, lay.F_LEVEL_OUT)
    unmet, active = ivec(i, h, lay.I_INFEASIBLE), ivec(i, h, lay.I_ACTIVE)
    flags = ivec(i, h, lay.I_SATURATED)
    nu = A.shape[1]
    for t in range(tasks.shape[0]):
        level, r0, r1 = tasks[t, 0], tasks[t, 1], tasks[t, 2]
        flags[t] = scale[level, 1] < 1.0 or unmet[t] != 0
        if flags[t] or r1 == r0:
            continue
        size = 0.0
        for r in range(r0, r1):
            for j in range(nu):
                size = max(size, abs(A[r, j]))
        for j in range(nu):
            if active[j]:
                for r in range(r0, r1):
                    if abs(A[r, j]) > _ZERO_COLUMN * size:
                        flags[t] = 1
                        break


@kernel
def advance_entries(
    f: np.ndarray, i: np.ndarray, h: np.ndarray, dt: float, u: np.ndarray, what: int
) -> None:
    """The compiled entries' step after a solve: the pose tasks' integrals (ADVANCE_TASKS,
    with the flags of ``I_SATURATED``) and the acceleration limits' memory (ADVANCE_MEMORY:
    ``u``, rad/s and m/s)."""
    entries, flags = imat(i, h, lay.I_ENTRY), ivec(i, h, lay.I_SATURATED)
    par = fvec(f, h, lay.F_PAR)
    for e in range(entries.shape[0]):
        kind = entries[e, lay.E_KIND]
        f0, fn = entries[e, lay.E_F0], entries[e, lay.E_FN]
        if kind == lay.KIND_POSE and what & ADVANCE_TASKS:
            advance_integral(par[f0 : f0 + fn], flags[entries[e, lay.E_SLOT]] != 0, dt)
        elif kind == lay.KIND_ACCELERATION and what & ADVANCE_MEMORY:
            nu = u.shape[0]
            block = par[f0 : f0 + fn]
            for j in range(nu):
                block[3 * nu + j] = u[j]


@kernel
def advance(f: np.ndarray, i: np.ndarray, h: np.ndarray, dt: float, what: int) -> None:
    """After a solve (its outcome in the arena): the flags (ADVANCE_FLAGS), then
    :func:`advance_entries` with the solution's ``u``."""
    if what & ADVANCE_FLAGS:
        saturation_flags(f, i, h)
    advance_entries(f, i, h, dt, fmat(f, h, lay.F_U)[1], what)
