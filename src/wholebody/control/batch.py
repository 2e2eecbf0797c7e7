"""Many independent states of one stack in one kernel call per core: reachability maps, data
generation, sweeps of starting configurations.

:func:`solve_many` gives every state its own configuration and, for the pose tasks named in
``targets``, its own target pose; each runs ``steps`` control steps inside the kernel, each
step from the configuration the last one reached (the kernel computes the kinematics:
:mod:`wholebody.kernels.forward`), starting from the stack's current state (integrals, the
acceleration limits' memory, which it leaves unchanged). The states are split over threads,
each with its own copy of the stack's arenas; the kernels release the GIL, so the threads run
on every core at once.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from wholebody.errors import DimensionError, WholebodyError
from wholebody.kernels import control
from wholebody.kernels import layout as lay
from wholebody.kernels.evaluate import REF_WIDTH
from wholebody.kernels.rows import POSE_ERROR
from wholebody.solvers.plan import Plan
from wholebody.tasks.base import Task

if TYPE_CHECKING:
    from wholebody.control.controller import Controller

__all__ = ["BatchResult", "solve_many"]


@dataclass(frozen=True)
class BatchResult:
    """What :func:`solve_many` returns, one row per state.

    Attributes
    ----------
    u
        (N, nu) the last step's actuated velocity (rad/s, m/s).
    q
        (N, nq) the configuration the last step reached.
    status
        (N,) the last solve's :class:`~wholebody.solvers.SolverStatus` (as ints).
    errors
        Per pose task of the stack (by name), (N, 6): its error ``[p_d - p; log3(R_d R^T)]``
        (m, rad) at the last step's configuration (where its last rows were computed).
    """

    u: np.ndarray
    q: np.ndarray
    status: np.ndarray
    errors: dict[str, np.ndarray]


def solve_many(
    controller: Controller,
    Q: np.ndarray,
    targets: Mapping[Task, np.ndarray] | None = None,
    steps: int = 1,
    threads: int | None = None,
) -> BatchResult:
    """Solve the states ``Q`` (N, nq) of ``controller``'s stack (module docstring)."""
    robot, stack, solver = controller.robot, controller.stack, controller.solver
    Q = np.ascontiguousarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[1] != robot.nq or not np.isfinite(Q).all():
        raise DimensionError(
            f"Q must be N configurations of robot {robot.name!r} (N x "
            f"{robot.nq} finite numbers), got shape {Q.shape}"
        )
    if not (isinstance(steps, int) and steps >= 1):
        raise DimensionError(f"steps must be a whole number >= 1, got {steps!r}")
    n = Q.shape[0]
    plan = stack.plan()
    plan.sync(None, controller.dt)
    buffers = plan.step_buffers(0)
    if plan.python or not buffers.movable:
        raise WholebodyError(
            "solve_many needs a stack whose entries are all compiled (no "
            "entry written in Python, no damped task) and a robot whose joints "
            "the kernels move"
        )
    tasks = list(targets or {})
    refs = _references(plan, tasks, targets or {}, n)
    nF = plan.view(lay.F_PAR).size
    batch = control.Batch(
        Q,
        refs,
        np.zeros((n, robot.nu)),
        np.zeros((n, robot.nq)),
        np.zeros(n, dtype=np.int64),
        np.zeros((n, nF)),
    )
    threads = min(n, threads or os.cpu_count() or 1)
    # a call's states start from the memory its arena holds when called: one arena per call
    work = [
        (_copy(plan, tasks), _workspace(solver, plan), _kinematics(buffers))
        for _ in range(threads + (threads > 1))
    ]
    what = control.KINEMATICS | control.ADVANCE | control.INTEGRATE | control.RESET

    def one(k: int, rows: np.ndarray) -> None:
        if rows.size:
            part = control.Batch(*(a[int(rows[0]) : int(rows[-1]) + 1] for a in batch))
            arena, ws, kin = work[k]
            solver.kernel_run(arena, kin, part, steps, what, ws)

    if threads == 1:
        one(0, np.arange(n))
        return BatchResult(batch.U, batch.Q_next, batch.status, _errors(plan, batch.params))
    one(threads, np.arange(1))  # compiles (or loads) the kernel once, before the threads share it
    chunks = np.array_split(np.arange(1, n), threads)
    with ThreadPoolExecutor(threads - 1) as pool:  # the calling thread takes the first chunk
        others = [pool.submit(one, k, chunks[k]) for k in range(1, threads)]
        one(0, chunks[0])
        for done in others:
            done.result()
    return BatchResult(batch.U, batch.Q_next, batch.status, _errors(plan, batch.params))


def _references(
    plan: Plan, tasks: list[Task], targets: Mapping[Task, np.ndarray], n: int
) -> np.ndarray:
    """The targets as the kernel's reference samples (N, nR, REF_WIDTH): the pose row by row,
    a zero twist."""
    refs = np.zeros((n, len(tasks), REF_WIDTH))
    for r, task in enumerate(tasks):
        poses = np.asarray(targets[task], dtype=float)
        if poses.shape != (n, 4, 4) or not np.isfinite(poses).all():
            raise DimensionError(
                f"targets[{getattr(task, 'name', task)!r}] must be {n} finite "
                f"4x4 poses, got shape {poses.shape}"
            )
        refs[:, r, :16] = poses.reshape(n, 16)
    return refs


def _copy(plan: Plan, tasks: list[Task]) -> control.Arena:
    """A thread's copy of the plan's arenas, the targeted pose tasks following the batch's
    references (and no other)."""
    arena = control.Arena(plan.f.copy(), plan.i.copy(), plan.h)
    table = lay.view(arena.i, plan.h, lay.I_ENTRY, plan.view(lay.I_ENTRY).shape)
    table[:, lay.E_REF] = -1
    for r, task in enumerate(tasks):
        rows = [
            e
            for e, rec in enumerate(plan.records)
            if rec.entry is task and rec.packed is not None and rec.packed.kind == lay.KIND_POSE
        ]
        if not rows:
            raise WholebodyError(
                f"targets: {getattr(task, 'name', task)!r} is not a compiled pose task of the stack"
            )
        table[rows[0], lay.E_REF] = r
    return arena


def _workspace(solver: object, plan: Plan) -> control.Arena | None:
    """A thread's copy of the HQP's workspace (None for the projection)."""
    workspace = getattr(solver, "workspace", None)
    if workspace is None:
        return None
    ws = workspace(plan)
    return control.Arena(ws.f.copy(), ws.i.copy(), ws.h)


def _kinematics(buffers: object) -> control.Kinematics:
    """A thread's own kinematics buffers (the packed model shared)."""
    own = buffers.own  # type: ignore[attr-defined]
    return own._replace(
        J=np.zeros(own.J.shape[::-1]).T, oMf=own.oMf.copy(), oMi=own.oMi.copy(), v=own.v.copy()
    )


def _errors(plan: Plan, params: np.ndarray) -> dict[str, np.ndarray]:
    """Each compiled pose task's error (N, 6) from the states' parameter blocks."""
    table = plan.view(lay.I_ENTRY)
    out = {}
    for e, rec in enumerate(plan.records):
        if rec.packed is not None and rec.packed.kind == lay.KIND_POSE:
            f0 = int(table[e, lay.E_F0]) + POSE_ERROR
            out[rec.entry.name] = params[:, f0 : f0 + 6].copy()
    return out
