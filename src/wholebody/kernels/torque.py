r"""The torque level's step in kernels: the stack's rows a moment ahead (:func:`ahead`), its
problem written into a cascade's arena (:func:`assemble`), the weighted mode's single QP
(:func:`weighted_qp`), and the torques and excesses of an answer (:func:`outcome`).
:mod:`wholebody.dynamics.solver` states the problem and lays the arena out; this module
computes it.

The unknowns are ``x~ = [a, f / s_f]`` (``nu + nw``; ``s_f`` the robot's weight, N). The
arena's levels, each of a kind (``spec``, made with the layout):

``LEVEL_EOM``
    The unactuated equations of motion ``[S M A, -S J_w^T s_f] x~ = -S h`` (rows over
    ``s_f``; ``S`` selects the entries of ``u`` that move a floating base).
``LEVEL_CONTACTS``
    The contact-level equality rows ``[E_dv A, E_f] x~ = e`` (each contact's acceleration, a
    carried object's equations), and as inequality rows of unit norm the wrench rows and the
    torque limits ``|A_d^T (M A a + h - J_w^T f)| <= effort_d``.
``LEVEL_TARGETS``
    The wrench targets ``T x~ = t``.
``LEVEL_STACK``
    One level of the stack in acceleration form, or (plan level -1) all of them, level ``k``'s
    rows times ``w_k``; its rows divided by ``max(1, ||b||)``, then (its flag) the contacts'
    internal-wrench rows times ``wrench_regularization`` below them.
``LEVEL_QUIET``
    The quiet rows ``R f -> 0``.

A stack row ``A u~ = b`` at ``q`` (the plan's scaled rows, ``u = D u~``) becomes ``(A / D) a =
K_d (b - A u~) + (b - b_last) / dt - (A(q (+) eps u) - A(q)) u~ / eps``; an inequality row
``l <= C u~' <= h`` on the next velocity bounds ``(C / D) a`` between ``(l - C u~) / dt`` and
``(h - C u~) / dt``, less the same forward difference.

Joint position limits bound the acceleration with braking (:func:`braking`): for an entry at
``q`` with velocity ``u`` and limits ``[lo, hi]``, ``d = hi - q - u dt`` and

.. math::

    a \le \min\!\Big(\frac{2 d}{dt^2},\; \frac{\sqrt{2\,b\,\max(d, 0)} - u}{dt}\Big)

(symmetrically at ``lo``): the next position stays inside, and the next velocity ``u' = u +
a dt`` keeps ``u'^2 <= 2 b d``: the joint can still stop before its limit decelerating at
``b`` (``braking``, rad/s^2 or m/s^2).

The actuation ``A`` (nv x nu) is taken by its non-zero entries ``A[act_j[e], act_k[e]] =
act_a[e]`` (:class:`wholebody.robot.compiled.RobotKinematics`): a floating base's or a
wheeled base's ``A`` is nearly an identity, and ``M A`` or ``A^T M A`` as dense products
would cost more than the rest of the step.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import daqp, kernel
from wholebody.kernels import layout as lay
from wholebody.kernels.contacts import twists
from wholebody.kernels.evaluate import REF_WIDTH, evaluate
from wholebody.kernels.forward import forward_kinematics, integrate, model_velocity
from wholebody.kernels.lapack import potrf, syevd, trtrs, trtrs_rows
from wholebody.kernels.linalg import (
    cholesky_inverse,
    fortran,
    frobenius2,
    gram_solve,
    mm,
    mmt,
    mtm,
    trace,
)

__all__ = [
    "ahead",
    "assemble",
    "braking",
    "internal_rows",
    "outcome",
    "rows_times",
    "weighted_qp",
]

# par: the step's numbers (float64)
P_DT, P_EPS, P_KD, P_FS, P_BRAKING, P_REGULARIZATION = 0, 1, 2, 3, 4, 5
P_FEEDFORWARD, P_ACCELERATION = 6, 7  # 1.0 where the rate of b / the acceleration limits apply
P_WIDTH = 8
# spec (L, 3): per arena level its kind, the plan level (LEVEL_STACK; -1: all, weighted), and
# whether the internal-wrench rows close it
LEVEL_EOM, LEVEL_CONTACTS, LEVEL_TARGETS, LEVEL_STACK, LEVEL_QUIET = 0, 1, 2, 3, 4
INF = 1e30  # daqp's "no bound"
SCHUR_KAPPA2 = 1e16
"""The largest squared Frobenius condition of the Schur complement ``E H^-1 E^T`` that the
weighted QP's warm start solves with (a standing TALOS's is about 1e11: the floating base's
directions cost nothing but the ``1e-9`` regularisation); beyond it, daqp."""


@kernel
def braking(
    q: float, u: float, lower: float, upper: float, dt: float, b: float
) -> tuple[float, float]:
    """The acceleration bounds of one entry (module docstring; ``-inf``/``inf`` on a side
    without a limit)."""
    a_lo, a_hi = -math.inf, math.inf
    if math.isfinite(upper):
        up = upper - q - u * dt
        a_hi = min(2.0 * up / (dt * dt), (math.sqrt(2.0 * b * max(up, 0.0)) - u) / dt)
    if math.isfinite(lower):
        down = q - lower + u * dt
        a_lo = max(-2.0 * down / (dt * dt), (-math.sqrt(2.0 * b * max(down, 0.0)) - u) / dt)
    return a_lo, a_hi


@kernel
def _eigen_pinv(S: np.ndarray) -> np.ndarray:
    """The pseudo-inverse of the symmetric ``S`` (Fortran; overwritten) by its eigenvalues,
    those at or below ``1e-12`` of the largest dropped."""
    info, w = syevd(S)  # (S now holds the eigenvectors)
    m = w.shape[0]
    pinv = np.zeros((m, m))
    for e in range(m):
        if info == 0 and w[e] > 1e-12 * max(w[m - 1], 0.0):
            for r in range(m):
                for c in range(m):
                    pinv[r, c] += S[r, e] * S[c, e] / w[e]
    return pinv


@kernel
def internal_rows(G: np.ndarray, W_inv: np.ndarray, L_t: np.ndarray) -> np.ndarray:
    """``L^T P`` with ``P = I - W^-1 G^T (G W^-1 G^T)^+ G`` (nc x nc): the contacts' wrenches
    ``f`` less the quietest ones (in the metric ``W = L L^T``) with the same sum ``G f`` about
    the world's origin. The inverse by Cholesky where ``G W^-1 G^T`` is well conditioned, else
    its pseudo-inverse by eigenvalues (``G`` may lack rank: a single point contact)."""
    WG = mmt(W_inv, G)  # (nc, 6)
    S = mm(G, WG)
    ok, X = cholesky_inverse(S)
    conditioned = ok and frobenius2(X) * trace(S) < 1e8  # then S^-1 = X^T X
    pinv = mtm(X, X) if conditioned else _eigen_pinv(fortran(S))
    P = -mm(WG, mm(pinv, G))
    for r in range(P.shape[0]):
        P[r, r] += 1.0
    return mm(L_t, P)


@kernel
def _drives(
    M: np.ndarray,
    nle: np.ndarray,
    rotor: np.ndarray,
    friction: np.ndarray,
    u: np.ndarray,
    act: tuple,
) -> None:
    """``M`` symmetric from its upper triangle with the drives' rotor inertia on its
    diagonal, and ``h += d v`` (``v = A u``), in place."""
    for r in range(M.shape[0]):
        for c in range(r):
            M[r, c] = M[c, r]
        M[r, r] += rotor[r]
    v = np.empty(M.shape[0])
    model_velocity(act[0], act[1], act[2], u, v)
    for r in range(v.shape[0]):
        nle[r] += friction[r] * v[r]


@kernel
def _act_right(X: np.ndarray, act: tuple, nu: int) -> np.ndarray:
    """``X A`` (rows of X over the model's velocities -> over ``u``)."""
    act_k, act_j, act_a = act
    out = np.zeros((X.shape[0], nu))
    for e in range(act_a.shape[0]):
        j, k, a = act_j[e], act_k[e], act_a[e]
        for r in range(X.shape[0]):
            out[r, k] += X[r, j] * a
    return out


@kernel
def _act_left(v: np.ndarray, act: tuple, nu: int) -> np.ndarray:
    """``A^T v``."""
    act_k, act_j, act_a = act
    out = np.zeros(nu)
    for e in range(act_a.shape[0]):
        out[act_k[e]] += act_a[e] * v[act_j[e]]
    return out


@kernel
def _generalised_rows(
    out: np.ndarray, entries: np.ndarray, AMA: np.ndarray, JA: np.ndarray, fs: float
) -> None:
    """Row ``t`` of ``out`` (over ``x~``): the entry ``entries[t]`` of ``A^T (M A a - J_w^T
    f)``, i.e. ``[(A^T M A)_j, -(J_w A)_j^T s_f]``."""
    nu = AMA.shape[1]
    for t in range(entries.shape[0]):
        j = entries[t]
        out[t, :nu] = AMA[j]
        for w in range(JA.shape[0]):
            out[t, nu + w] = -JA[w, j] * fs


@kernel
def _unit_rows(C: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Each row and its bounds divided by the row's norm (the cascade's tolerances are then
    the same for every row)."""
    for r in range(C.shape[0]):
        norm = math.sqrt(C[r] @ C[r])
        if norm > 0.0:
            C[r] /= norm
            lo[r] /= norm
            hi[r] /= norm


@kernel
def _stack_rows(
    A: np.ndarray,
    b: np.ndarray,
    unweight: np.ndarray,
    r: int,
    plan: tuple,
    k: int,
    weight: float,
    u: np.ndarray,
    ahead: np.ndarray,
    last_b: np.ndarray,
    par: np.ndarray,
) -> int:
    """Plan level ``k``'s rows in acceleration form, times ``weight``, into ``A`` (columns of
    ``a``), ``b`` and ``unweight`` from row ``r``; the next free row."""
    pf, pi, ph = plan
    PA, Pb = lay.fmat(pf, ph, lay.F_A), lay.fvec(pf, ph, lay.F_B)
    D, rw = lay.fmat(pf, ph, lay.F_METRIC)[0], lay.fmat(pf, ph, lay.F_ROW)[1]
    row0, row_end = lay.imat(pi, ph, lay.I_LEVEL)[k, 0], lay.imat(pi, ph, lay.I_LEVEL)[k, 2]
    dt, eps, kd = par[P_DT], par[P_EPS], par[P_KD]
    for j in range(row0, row_end):
        Au = 0.0
        for c in range(D.shape[0]):
            Au += PA[j, c] * (u[c] / D[c])
            A[r, c] = weight * PA[j, c] / D[c]
        bj = kd * (Pb[j] - Au)
        if par[P_FEEDFORWARD] > 0.0:
            bj += (Pb[j] - last_b[j]) / dt
        if eps > 0.0:
            bj -= (ahead[j] - Au) / eps
        b[r] = weight * bj
        unweight[r] = rw[j] / weight if weight > 0.0 else rw[j]
        r += 1
    return r


@kernel
def _stack_bounds(
    C: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    p: int,
    plan: tuple,
    k: int,
    u: np.ndarray,
    ahead: np.ndarray,
    par: np.ndarray,
) -> int:
    """Plan level ``k``'s inequality rows on the next velocity as bounds on ``a``, into
    ``C``, ``lo``, ``hi`` from row ``p``; the next free row."""
    pf, pi, ph = plan
    PC, CB = lay.fmat(pf, ph, lay.F_C), lay.fmat(pf, ph, lay.F_CB)
    D, K = lay.fmat(pf, ph, lay.F_METRIC)[0], lay.fvec(pf, ph, lay.F_B).shape[0]
    ineq0, ineq_end = lay.imat(pi, ph, lay.I_LEVEL)[k, 3], lay.imat(pi, ph, lay.I_LEVEL)[k, 4]
    dt, eps = par[P_DT], par[P_EPS]
    for j in range(ineq0, ineq_end):
        Cu = 0.0
        for c in range(D.shape[0]):
            Cu += PC[j, c] * (u[c] / D[c])
            C[p, c] = PC[j, c] / D[c]
        drift = (ahead[K + j] - Cu) / eps if eps > 0.0 else 0.0
        lo[p] = (CB[0, j] - Cu) / dt - drift
        hi[p] = (CB[1, j] - Cu) / dt - drift
        p += 1
    return p


@kernel
def _stack_level(
    arena: tuple,
    lv: int,
    plan: tuple,
    k: int,
    state: tuple,
    par: np.ndarray,
    internal: np.ndarray,
    with_internal: int,
) -> None:
    """Arena level ``lv``: plan level ``k`` (or every level, each times its weight, where
    ``k < 0``), padded, then the internal-wrench rows where ``with_internal``; ``state``:
    ``(u, ahead, last_b, weights)`` as :func:`assemble` takes them."""
    u, ahead, last_b, weights = state
    f, i, h = arena
    pf, pi, ph = plan
    A, b, C = lay.fmat(f, h, lay.F_A), lay.fvec(f, h, lay.F_B), lay.fmat(f, h, lay.F_C)
    CB, unweight = lay.fmat(f, h, lay.F_CB), lay.fmat(f, h, lay.F_ROW)[1]
    levels, lf = lay.imat(i, h, lay.I_LEVEL), lay.fmat(f, h, lay.F_LEVEL)
    r0, r, p = levels[lv, 0], levels[lv, 0], levels[lv, 3]
    ks = np.arange(lay.imat(pi, ph, lay.I_LEVEL).shape[0]) if k < 0 else np.array([k])
    for kk in ks:
        w = weights[kk] if k < 0 else 1.0
        r = _stack_rows(A, b, unweight, r, plan, kk, w, u, ahead, last_b, par)
        p = _stack_bounds(C, CB[0], CB[1], p, plan, kk, u, ahead, par)
    norm = 0.0
    for t in range(r0, r):
        norm += b[t] * b[t]
    s = 1.0 / max(1.0, math.sqrt(norm))  # the same optimum, a residual of order 1 at most
    for t in range(r0, r):
        A[t] *= s
        b[t] *= s
        unweight[t] /= s
    ref = lay.fmat(pf, ph, lay.F_LEVEL)[k, lay.LEVEL_REFERENCE] if k >= 0 else 1.0
    lf[lv, lay.LEVEL_REFERENCE] = ref * s
    if with_internal:
        reg, nu = par[P_REGULARIZATION], A.shape[1] - internal.shape[1]
        for t in range(internal.shape[0]):
            A[r + t, nu:] = reg * internal[t]
            b[r + t] = 0.0
            unweight[r + t] = 1.0 / reg


@kernel
def _box(
    arena: tuple,
    plan: tuple,
    u: np.ndarray,
    qj: np.ndarray,
    limits: np.ndarray,
    unactuated: np.ndarray,
    par: np.ndarray,
) -> None:
    """The bounds on ``x~``: for ``a`` the stack's box on the next velocity, braking before
    the joint position limits, the acceleration limits (``limits``: lower and upper position
    limits, acceleration limits; crossed bounds meet half-way), a floating base's six free;
    the wrenches free. And the metric: 1 for ``a``, ``s_f`` for the wrenches."""
    f, _, h = arena
    pf, _, ph = plan
    box, metric = lay.fmat(f, h, lay.F_BOX), lay.fmat(f, h, lay.F_METRIC)
    D, pbox = lay.fmat(pf, ph, lay.F_METRIC)[0], lay.fmat(pf, ph, lay.F_BOX)
    dt, nu, fs = par[P_DT], D.shape[0], par[P_FS]
    box[0], box[1] = -math.inf, math.inf
    metric[0], metric[1] = fs, fs * fs
    for j in range(nu):
        lo, hi = (D[j] * pbox[0, j] - u[j]) / dt, (D[j] * pbox[1, j] - u[j]) / dt
        b_lo, b_hi = braking(qj[j], u[j], limits[0, j], limits[1, j], dt, par[P_BRAKING])
        lo, hi = max(lo, b_lo), min(hi, b_hi)
        if par[P_ACCELERATION] > 0.0:
            lo, hi = max(lo, -limits[2, j]), min(hi, limits[2, j])
        if lo > hi:
            lo = hi = 0.5 * (lo + hi)
        box[0, j], box[1, j] = lo, hi
        metric[0, j] = metric[1, j] = 1.0
    for j in unactuated:
        box[0, j], box[1, j] = -math.inf, math.inf
    box[2], box[3] = box[0], box[1]


@kernel
def _contact_level(
    arena: tuple,
    lv: int,
    AMA: np.ndarray,
    JA: np.ndarray,
    hA: np.ndarray,
    model: tuple,
    contact: tuple,
    fs: float,
) -> None:
    """Arena level ``lv``: the contact-level equalities, the wrench rows and the torque
    limits (module docstring)."""
    f, i, h = arena
    act, driven, effort = model
    eq_dv, eq_f, eq_b, cf, cf_lo, cf_hi = contact
    A, b, C = lay.fmat(f, h, lay.F_A), lay.fvec(f, h, lay.F_B), lay.fmat(f, h, lay.F_C)
    CB, levels = lay.fmat(f, h, lay.F_CB), lay.imat(i, h, lay.I_LEVEL)
    nu = AMA.shape[1]
    r, p0, p1 = levels[lv, 0], levels[lv, 3], levels[lv, 4]
    EA = _act_right(eq_dv, act, nu)
    for t in range(eq_b.shape[0]):
        A[r + t, :nu] = EA[t]
        A[r + t, nu:] = eq_f[t]
        b[r + t] = eq_b[t]
    m = cf.shape[0]
    for t in range(m):
        C[p0 + t, nu:] = cf[t]
        CB[0, p0 + t], CB[1, p0 + t] = cf_lo[t], cf_hi[t]
    _generalised_rows(C[p0 + m : p1], driven, AMA, JA, fs)
    for t in range(driven.shape[0]):
        j = driven[t]
        CB[0, p0 + m + t] = -effort[j] - hA[j]
        CB[1, p0 + m + t] = effort[j] - hA[j]
    _unit_rows(C[p0:p1], CB[0, p0:p1], CB[1, p0:p1])


@kernel
def ahead(
    plan: tuple,
    kin: tuple,
    contacts: tuple,
    q: np.ndarray,
    u: np.ndarray,
    eps: float,
    out: np.ndarray,
) -> None:
    """The first half of the forward difference that gives ``Jdot u``: the stack's rows
    evaluated at ``q (+) eps A u`` on the kernels' own kinematics (:mod:`.forward`), and
    their products ``[A u~, C u~]`` (K + P, ``u~ = u / D``) into ``out``; and the contacts'
    velocities there. ``plan`` ``(f, i, h)``: a stack's arena whose entries are all compiled,
    synced for the step (its rows are overwritten: evaluate it at ``q`` next); ``kin``
    ``(model_i, model_f, J, oMf, oMi, v)``: :class:`wholebody.kernels.control.Kinematics`;
    ``contacts`` ``(table, support, twists)``: the contacts and their velocities' buffer
    (:func:`wholebody.kernels.contacts.twists`)."""
    f, i, h = plan
    model_i, model_f, J, oMf, oMi, v = kin
    act = lay.imat(i, h, lay.I_ACT)
    model_velocity(act[0], act[1], lay.fvec(f, h, lay.F_ACT_A), u, v)
    q_ahead = np.empty(q.shape[0])
    integrate(model_i, q, v, eps, q_ahead)
    forward_kinematics(model_i, model_f, q_ahead, oMi, oMf, J)
    evaluate(f, i, h, J, oMf, q_ahead, np.zeros((0, REF_WIDTH)))
    table, support, twist = contacts
    twists(J, oMf, table, support, v, twist)
    rows_times(plan, u, out)


@kernel
def rows_times(plan: tuple, u: np.ndarray, out: np.ndarray) -> None:
    """A stack's evaluated rows times ``u~ = u / D``: ``[A u~, C u~]`` (K + P) into ``out``
    (``plan``: its arena ``(f, i, h)``)."""
    f, _, h = plan
    A, C = lay.fmat(f, h, lay.F_A), lay.fmat(f, h, lay.F_C)
    u_s = u / lay.fmat(f, h, lay.F_METRIC)[0]
    K = A.shape[0]
    for r in range(K):
        out[r] = A[r] @ u_s
    for r in range(C.shape[0]):
        out[K + r] = C[r] @ u_s


@kernel
def assemble(
    arena: tuple,
    spec: np.ndarray,
    plan: tuple,
    par: np.ndarray,
    state: tuple,
    model: tuple,
    dynamics: tuple,
    contact: tuple,
    extra: tuple,
) -> None:
    """Write the step's problem (module docstring) into the cascade's ``arena`` ``(f, i,
    h)``, laid out as ``spec`` says, from the stack's ``plan`` ``(f, i, h)`` evaluated at
    ``q``.

    ``state``: ``u`` (nu), the joint positions ``qj`` (nu), ``ahead`` (K + P: the plan's
    ``A u~`` and ``C u~`` at ``q (+) eps u``; unread at rest, ``eps = 0``), ``last_b`` (K:
    the last step's ``b``), the stack's level weights. ``model``: the actuation's non-zero
    entries ``act = (act_k, act_j, act_a)`` (module docstring), the driven
    entries, the torque limits (nu), the unactuated entries, ``limits`` (3 x nu: position
    limits, acceleration limits). ``dynamics``: Pinocchio's ``M`` (nv x nv, its upper
    triangle read) and ``h`` (nv), the wrenches' Jacobians ``J_w`` (nw x nv), the drives'
    rotor inertia and viscous friction (nv); ``M`` is made symmetric with the rotor inertia
    on its diagonal and ``h`` takes the friction ``d v``, in place. ``contact``: the
    contact-level equality rows ``eq_dv`` (over ``dv``), ``eq_f`` (over ``f / s_f``),
    ``eq_b``, the wrench rows ``cf`` (over ``f / s_f``), ``cf_lo``, ``cf_hi``. ``extra``:
    the wrench targets' rows and right-hand sides, the internal-wrench rows (over the
    wrenches; the contacts' block written here, :func:`internal_rows`), the quiet rows, and
    for the contacts ``G``, ``W^-1`` and ``L^T``."""
    f, i, h = arena
    u, qj, ahead, last_b, weights = state
    act, driven, effort, unactuated, limits = model
    M, nle, Jw, rotor, friction = dynamics
    _drives(M, nle, rotor, friction, u, act)
    targets, target_b, internal, quiet, G, W_inv, L_t = extra
    nc = G.shape[1]
    if nc:
        internal[:nc, :nc] = internal_rows(G, W_inv, L_t)
    nu, fs = u.shape[0], par[P_FS]
    A, b, C = lay.fmat(f, h, lay.F_A), lay.fvec(f, h, lay.F_B), lay.fmat(f, h, lay.F_C)
    levels, lf = lay.imat(i, h, lay.I_LEVEL), lay.fmat(f, h, lay.F_LEVEL)
    A[:] = 0.0
    C[:] = 0.0
    lay.fmat(f, h, lay.F_ROW)[1] = 1.0
    lf[:, lay.LEVEL_IDENTITY] = 0.0
    lf[:, lay.LEVEL_REFERENCE] = 1.0
    MA, JA = _act_right(M, act, nu), _act_right(Jw, act, nu)
    AMA, hA = _act_right(MA.T.copy(), act, nu), _act_left(nle, act, nu)  # (M symmetric)
    for lv in range(spec.shape[0]):
        kind, r = spec[lv, 0], levels[lv, 0]
        if kind == LEVEL_EOM:
            _generalised_rows(A[r : r + unactuated.shape[0]], unactuated, AMA, JA, fs)
            for t in range(unactuated.shape[0]):
                A[r + t] /= fs
                b[r + t] = -hA[unactuated[t]] / fs
        elif kind == LEVEL_CONTACTS:
            _contact_level(arena, lv, AMA, JA, hA, (act, driven, effort), contact, fs)
        elif kind == LEVEL_TARGETS:
            for t in range(target_b.shape[0]):
                A[r + t, nu:] = targets[t]
                b[r + t] = target_b[t]
        elif kind == LEVEL_STACK:
            stack_state = (u, ahead, last_b, weights)
            _stack_level(arena, lv, plan, spec[lv, 1], stack_state, par, internal, spec[lv, 2])
        else:
            for t in range(quiet.shape[0]):
                A[r + t, nu:] = quiet[t]
                b[r + t] = 0.0
    _box(arena, plan, u, qj, limits, unactuated, par)


@kernel
def _accumulate(H: np.ndarray, g: np.ndarray, A: np.ndarray, b: np.ndarray, w2: float) -> None:
    """``H += w2 A^T A``, ``g -= w2 A^T b``, row by row over each row's non-zero entries
    (a posture's rows have one, the wrench rows none over ``a``)."""
    n = A.shape[1]
    nz = np.empty(n, np.int64)
    for r in range(A.shape[0]):
        m = 0
        for c in range(n):
            if A[r, c] != 0.0:
                nz[m] = c
                m += 1
        for s in range(m):
            c1 = nz[s]
            a1 = w2 * A[r, c1]
            g[c1] -= a1 * b[r]
            for t in range(m):
                H[c1, nz[t]] += a1 * A[r, nz[t]]


@kernel
def _qp_constraints(arena: tuple, n_eq: int, keep: np.ndarray) -> tuple:
    """daqp's constraints: the box as simple bounds, then the first ``n_eq`` equality rows
    held exactly, then the inequality rows where ``keep``: ``(rows, upper, lower, sense)``."""
    f, _, h = arena
    A, b, C = lay.fmat(f, h, lay.F_A), lay.fvec(f, h, lay.F_B), lay.fmat(f, h, lay.F_C)
    CB, box = lay.fmat(f, h, lay.F_CB), lay.fmat(f, h, lay.F_BOX)
    n, kept = A.shape[1], np.flatnonzero(keep)
    m = n + n_eq + kept.shape[0]
    rows = np.empty((n_eq + kept.shape[0], n))
    upper, lower, sense = np.empty(m), np.empty(m), np.zeros(m, np.int32)
    for c in range(n):
        lower[c], upper[c] = max(box[0, c], -INF), min(box[1, c], INF)
    for t in range(n_eq):
        rows[t] = A[t]
        lower[n + t] = upper[n + t] = b[t]
        sense[n + t] = daqp.EQUALITY
    for k in range(kept.shape[0]):
        t, r = kept[k], n + n_eq + k
        rows[n_eq + k] = C[t]
        lower[r], upper[r] = max(CB[0, t], -INF), min(CB[1, t], INF)
    return rows, upper, lower, sense


@kernel
def _within(s: float, low: float, high: float) -> bool:
    """Whether ``low <= s <= high`` to 1e-12 relative (a bound's tolerance)."""
    return low - 1e-12 * (1.0 + abs(low)) <= s <= high + 1e-12 * (1.0 + abs(high))


@kernel
def _held(C: np.ndarray, CB: np.ndarray, x: np.ndarray, first: int, last: int) -> bool:
    """Whether ``x`` keeps the inequality rows ``first:last`` (unit rows; :func:`_within`)."""
    for t in range(first, last):
        if not _within(C[t] @ x, CB[0, t], CB[1, t]):
            return False
    return True


@kernel
def _equality_optimum(
    H: np.ndarray, g: np.ndarray, E: np.ndarray, e: np.ndarray, x: np.ndarray, mu: np.ndarray
) -> bool:
    """``x = argmin 1/2 x'H x + g'x`` subject to ``E x = e`` alone, into ``x``, and its
    multipliers ``mu`` (``H x + g + E^T mu = 0``, daqp's sign), by the Schur complement: with
    ``H = L L^T``, ``Y = L^-1 E^T`` and ``z = L^-1 g``, ``(Y^T Y) mu = -(e + Y^T z)`` and
    ``x = -L^-T (z + Y mu)``, refined twice on the residual ``e - E x``. False where ``H`` or
    ``Y^T Y`` has no Cholesky factor, the latter's squared Frobenius condition exceeds
    :data:`SCHUR_KAPPA2`, or ``E x = e`` is not met to 1e-12 relative (dependent rows)."""
    L = H.copy().T  # (H is symmetric: its copy, read column-major, is H)
    if potrf(L, True) != 0:
        return False
    Y, z = E.copy(), g.copy()  # row k of Y: L^-1 E[k]; z = L^-1 g
    trtrs_rows(L, Y, True, False)
    trtrs(L, z, True, False)
    S = Y @ Y.T
    ok, X = cholesky_inverse(S)
    if not (ok and frobenius2(X) * trace(S) <= SCHUR_KAPPA2):
        return False
    r = -(e + Y @ z)
    for k in range(3):  # the solve, then two refinements on the residual e - E x
        step = gram_solve(X, r)
        w = Y.T @ step
        if k:
            trtrs(L, w, True, True)
            x += w  # x + H^-1 E^T S^-1 r: the multipliers change by -S^-1 r
            mu -= step
        else:
            w += z
            trtrs(L, w, True, True)
            x[:] = -w
            mu[:] = step
        r = e - E @ x
    return bool(np.all(np.abs(r) <= 1e-12 * (1.0 + np.abs(e))))


@kernel
def _working_set(
    arena: tuple, n_eq: int, active: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The equality rows of the working set ``active`` (per bound, the box's ``n`` then the
    inequality rows: 1 at its upper side, -1 at its lower, 0 free): the arena's first
    ``n_eq`` equality rows, then each active bound held at its side; ``(E, e, which)``,
    ``which`` the bounds' indices."""
    f, _, h = arena
    A, b, C = lay.fmat(f, h, lay.F_A), lay.fvec(f, h, lay.F_B), lay.fmat(f, h, lay.F_C)
    CB, box = lay.fmat(f, h, lay.F_CB), lay.fmat(f, h, lay.F_BOX)
    n = A.shape[1]
    which = np.flatnonzero(active)
    E, e = np.zeros((n_eq + which.shape[0], n)), np.empty(n_eq + which.shape[0])
    E[:n_eq], e[:n_eq] = A[:n_eq], b[:n_eq]
    for k in range(which.shape[0]):
        t, side = which[k], 1 if active[which[k]] > 0 else 0
        if t < n:
            E[n_eq + k, t], e[n_eq + k] = 1.0, box[side, t]
        else:
            E[n_eq + k], e[n_eq + k] = C[t - n], CB[side, t - n]
    return E, e, which


@kernel
def _feasible(arena: tuple, x: np.ndarray) -> bool:
    """Whether ``x`` keeps the arena's box and every inequality row (:func:`_within`)."""
    f, _, h = arena
    box = lay.fmat(f, h, lay.F_BOX)
    for c in range(x.shape[0]):
        if not _within(x[c], box[0, c], box[1, c]):
            return False
    C = lay.fmat(f, h, lay.F_C)
    return _held(C, lay.fmat(f, h, lay.F_CB), x, 0, C.shape[0])


@kernel
def _warm(
    arena: tuple, H: np.ndarray, g: np.ndarray, n_eq: int, active: np.ndarray, x: np.ndarray
) -> tuple[bool, bool]:
    """The QP solved on the last step's working set ``active``: ``(solved, bounded)``.
    Solved where the working set's equality optimum (:func:`_equality_optimum`) keeps every
    other bound and each active bound's multiplier has its side's sign (the KKT conditions:
    then it is the QP's optimum); bounded where an active bound has a multiplier."""
    E, e, which = _working_set(arena, n_eq, active)
    mu = np.empty(e.shape[0])
    if not np.isfinite(e).all():  # (a side without a bound: not a working set)
        return False, False
    if not (_equality_optimum(H, g, E, e, x, mu) and _feasible(arena, x)):
        return False, False
    bounded = False
    for k in range(which.shape[0]):
        m = mu[n_eq + k] * active[which[k]]
        if m < -1e-12:
            return False, False
        bounded = bounded or m > 0.0
    return True, bounded


@kernel
def weighted_qp(
    arena: tuple,
    spec: np.ndarray,
    hard: int,
    quiet_weight: float,
    deferred: np.ndarray,
    settings: np.ndarray,
    active: np.ndarray,
    x: np.ndarray,
) -> tuple[int, bool]:
    """The weighted mode's problem as one QP solved by daqp: the arena's first ``hard``
    levels' equality rows held exactly, every level's inequality rows and the box as bounds,
    and the least squares of the other levels' rows (the quiet level's times
    ``quiet_weight``) plus ``1e-9 ||x~||^2`` (strictly convex). The last step's working set
    ``active`` (n + the inequality rows: 1 at the upper side, -1 at the lower, 0 free; kept
    up to date here) is tried first (:func:`_warm`): where it satisfies the KKT conditions it
    gives the optimum without daqp (a standing robot's usual step). The inequality rows
    ``deferred[0]:deferred[1]`` (the torque limits, seldom active) are left out of a first
    solve and added for a second only where its answer breaks one: the same answer, a
    smaller QP. ``(exitflag, bounded)``: daqp's exit flag, and whether a bound is active
    with a multiplier (the tasks gave way to it); the answer (``x~``) in ``x``."""
    f, i, h = arena
    A, b, C = lay.fmat(f, h, lay.F_A), lay.fvec(f, h, lay.F_B), lay.fmat(f, h, lay.F_C)
    CB, levels = lay.fmat(f, h, lay.F_CB), lay.imat(i, h, lay.I_LEVEL)
    n = A.shape[1]
    H, g = np.zeros((n, n)), np.zeros(n)
    for lv in range(hard, levels.shape[0]):
        w = quiet_weight if spec[lv, 0] == LEVEL_QUIET else 1.0
        r0, r1 = levels[lv, 0], levels[lv, 2]
        _accumulate(H, g, A[r0:r1], b[r0:r1], w * w)
    for c in range(n):
        H[c, c] += 1e-9
    n_eq = levels[hard - 1, 2] if hard > 0 else 0
    solved, bounded = _warm(arena, H, g, n_eq, active, x)
    if solved:
        return daqp.OPTIMAL, bounded
    keep = np.ones(C.shape[0], np.bool_)
    keep[deferred[0] : deferred[1]] = False
    for _ in range(2):
        rows, upper, lower, sense = _qp_constraints(arena, n_eq, keep)
        lam = np.empty(sense.shape[0])
        flag, _ = daqp.solve(H, g, rows, upper, lower, sense, settings, x, lam)
        if flag <= 0 or keep.all() or _held(C, CB, x, deferred[0], deferred[1]):
            break
        keep[:] = True
    active[:] = 0
    if flag > 0:
        kept = np.flatnonzero(keep)
        for t in range(sense.shape[0]):
            if sense[t] == 0 and lam[t] != 0.0:
                side = 1 if lam[t] > 0.0 else -1
                active[t if t < n else n + kept[t - n - n_eq]] = side
                bounded = True
    return flag, bounded


@kernel
def outcome(
    x: np.ndarray,
    model: tuple,
    dynamics: tuple,
    cf: np.ndarray,
    cf_lo: np.ndarray,
    cf_hi: np.ndarray,
    owner: np.ndarray,
    out: tuple,
) -> None:
    """The torques of the answer ``x = [a, f]`` (real units) and how far it exceeds each
    bound: into ``out`` = ``(dv, Q, tau, excess)``, ``dv = A a``, ``Q = M dv + h - J_w^T f``,
    ``tau = A^T Q``; ``excess`` per owner of the wrench rows ``cf`` (over ``f / s_f``; row
    ``t`` belongs to ``owner[t]``), then the torque limits, then the equations of motion
    (``|Q|`` on the velocities a floating base's entries move: ``eom`` rows)."""
    act, driven, effort, eom, fs = model
    M, nle, Jw = dynamics
    dv, Q, tau, excess = out
    nu, nw = tau.shape[0], Jw.shape[0]
    model_velocity(act[0], act[1], act[2], x[:nu], dv)
    for r in range(Q.shape[0]):
        Q[r] = M[r] @ dv + nle[r]
        for w in range(nw):
            Q[r] -= Jw[w, r] * x[nu + w]
    tau[:] = _act_left(Q, act, nu)
    excess[:] = 0.0
    for t in range(cf.shape[0]):
        s = 0.0
        for w in range(nw):
            s += cf[t, w] * x[nu + w] / fs
        excess[owner[t]] = max(excess[owner[t]], cf_lo[t] - s, s - cf_hi[t])
    k = excess.shape[0] - 2
    for j in driven:
        excess[k] = max(excess[k], abs(tau[j]) - effort[j])
    for r in eom:
        excess[k + 1] = max(excess[k + 1], abs(Q[r]))
