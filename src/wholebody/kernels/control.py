"""Whole control steps in one kernel call: rows, solve, integrals and limits' memory, the
integration of ``q``, for one state or many.

:func:`projection_run` and :func:`hqp_run` take the compiled stack's arena, the kinematics'
buffers and a batch: ``N`` configurations ``Q`` (N, nq), their references' samples ``refs``
(N, nR, REF_WIDTH), and receive the actuated velocities ``U`` (N, nu) and the configurations
reached ``Q_next`` (N, nq). What a call does is the bits of ``what``:

``KINEMATICS``
    compute the frame placements and joint Jacobians from ``q`` (:mod:`.forward`) instead of
    reading Pinocchio's (the caller then ran ``computeJointJacobians`` and
    ``updateFramePlacements`` into the arrays it passes);
``ADVANCE``
    after the solve, the anti-windup flags, the pose tasks' integrals and the acceleration
    limits' memory (:mod:`.advance`);
``INTEGRATE``
    ``q_next = q (+) A u dt`` on the configuration manifold (:mod:`.forward`);
``RESET``
    every state starts from the entries' parameters and state as they were at the call
    (independent states: a batch);

and ``steps`` control steps are run for each state, each from the configuration the last one
reached (``KINEMATICS`` and ``INTEGRATE``: a closed-loop run inside the kernel). A state whose
configuration is not finite is skipped: nothing is written for it but its status,
``NOT_FINITE``. The arena holds the last state's outcome. The kernels release the GIL:
threads may run them at once on copies of the arena
(:meth:`wholebody.control.Controller.step_many`).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.advance import ADVANCE_FLAGS, ADVANCE_MEMORY, ADVANCE_TASKS, advance
from wholebody.kernels.evaluate import evaluate
from wholebody.kernels.forward import forward_kinematics, integrate, model_velocity
from wholebody.kernels.hqp import cascade
from wholebody.kernels.layout import fmat, fvec, imat, ivec
from wholebody.kernels.linalg import finite1
from wholebody.kernels.projection import project

__all__ = [
    "ADVANCE",
    "INTEGRATE",
    "KINEMATICS",
    "NOT_FINITE",
    "RESET",
    "Arena",
    "Batch",
    "Kinematics",
    "after",
    "hqp_run",
    "kinematics",
    "projection_run",
]

KINEMATICS, ADVANCE, INTEGRATE, RESET = 1, 2, 4, 8
NOT_FINITE = -1  # a state's status when its configuration is not finite (nothing else written)

Arena = namedtuple("Arena", ["f", "i", "h"])
"""A compiled stack's arenas and header (:mod:`wholebody.kernels.layout`), or a workspace's."""

Kinematics = namedtuple("Kinematics", ["model_i", "model_f", "J", "oMf", "oMi", "v"])
"""The packed model (:func:`wholebody.robot.compiled.pack_model`) and the buffers the
kinematics are read from or computed into: ``J`` (6 x nv, Fortran-ordered), ``oMf``
(nframes, 12), ``oMi`` (njoints, 12), ``v`` (nv, scratch: the model velocity)."""

Batch = namedtuple("Batch", ["Q", "refs", "U", "Q_next", "status", "params"])
"""The states in, and out per state: the command, the configuration reached, the solve's
status and the entries' parameter blocks after the last step (``F_PAR``: a pose task's error
and integral, ...)."""


@kernel
def after(a: Arena, kin: Kinematics, q: np.ndarray, q_next: np.ndarray, what: int) -> None:
    """After the solve: the entries' step (``ADVANCE``) and the integration (``INTEGRATE``)."""
    dt = fvec(a.f, a.h, lay.F_SCALARS)[0]
    if what & ADVANCE:
        advance(a.f, a.i, a.h, dt, ADVANCE_FLAGS | ADVANCE_TASKS | ADVANCE_MEMORY)
    if what & INTEGRATE:
        act = imat(a.i, a.h, lay.I_ACT)
        u = fmat(a.f, a.h, lay.F_U)[1]
        model_velocity(act[0], act[1], fvec(a.f, a.h, lay.F_ACT_A), u, kin.v)
        integrate(kin.model_i, q, kin.v, dt, q_next)


@kernel
def _begin(a: Arena, saved: np.ndarray, what: int) -> None:
    """A state's start: the entries' parameters as they were at the call (``RESET``)."""
    if what & RESET:
        fvec(a.f, a.h, lay.F_PAR)[:] = saved


@kernel
def kinematics(kin: Kinematics, q: np.ndarray, what: int) -> None:
    """The kinematics of ``q`` where the kernel computes them (``KINEMATICS``)."""
    if what & KINEMATICS:
        forward_kinematics(kin.model_i, kin.model_f, q, kin.oMi, kin.oMf, kin.J)


@kernel
def _out(a: Arena, batch: Batch, s: int, q: np.ndarray) -> None:
    """State ``s``'s outcome into the batch's outputs."""
    batch.U[s] = fmat(a.f, a.h, lay.F_U)[1]
    batch.Q_next[s] = q
    batch.status[s] = ivec(a.i, a.h, lay.I_OUT)[lay.OUT_STATUS]
    batch.params[s] = fvec(a.f, a.h, lay.F_PAR)


@kernel
def projection_run(
    a: Arena, kin: Kinematics, batch: Batch, par: np.ndarray, steps: int, what: int
) -> None:
    """The projection backend over a batch (module docstring); ``par``: its settings."""
    saved = fvec(a.f, a.h, lay.F_PAR).copy() if what & RESET else np.empty(0)
    q = np.empty(batch.Q.shape[1])
    q_next = np.empty(batch.Q.shape[1])
    for s in range(batch.Q.shape[0]):
        if not finite1(batch.Q[s]):
            batch.status[s] = NOT_FINITE
            continue
        _begin(a, saved, what)
        q[:] = batch.Q[s]
        for k in range(steps):
            if k:
                q[:] = q_next
            kinematics(kin, q, what)
            evaluate(a.f, a.i, a.h, kin.J, kin.oMf, q, batch.refs[s])
            project(a.f, a.i, a.h, par)
            after(a, kin, q, q_next, what)
        _out(a, batch, s, q_next if what & INTEGRATE else q)


@kernel
def hqp_run(
    a: Arena,
    w: Arena,
    kin: Kinematics,
    batch: Batch,
    par: np.ndarray,
    settings: np.ndarray,
    steps: int,
    what: int,
) -> None:
    """The hierarchical QP over a batch (module docstring), daqp solving its QPs; ``w``: the
    cascade's workspace, ``par``, ``settings``: its and daqp's settings."""
    saved = fvec(a.f, a.h, lay.F_PAR).copy() if what & RESET else np.empty(0)
    q = np.empty(batch.Q.shape[1])
    q_next = np.empty(batch.Q.shape[1])
    for s in range(batch.Q.shape[0]):
        if not finite1(batch.Q[s]):
            batch.status[s] = NOT_FINITE
            continue
        _begin(a, saved, what)
        q[:] = batch.Q[s]
        for k in range(steps):
            if k:
                q[:] = q_next
            kinematics(kin, q, what)
            evaluate(a.f, a.i, a.h, kin.J, kin.oMf, q, batch.refs[s])
            cascade(a.f, a.i, a.h, w.f, w.i, w.h, par, settings)
            after(a, kin, q, q_next, what)
        _out(a, batch, s, q_next if what & INTEGRATE else q)
