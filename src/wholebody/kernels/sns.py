"""Saturation in the Null Space (Flacco, De Luca and Khatib, IEEE T-RO 2015) in kernels: one
level of the projection backend brought inside the box (:mod:`wholebody.solvers.projection`
documents the method).

While the level's candidate leaves the box, the most critical joint (the one that limits the
task scaling factor most) is saturated at its bound: ``base`` moves along the free directions
(minimum norm) to put it there, the directions that move it are removed (a rank-one deflation
of the basis, or a mask entry), and the level is solved again on what is left. The best task
scaling factor seen is kept; when the level runs out of directions its motion is scaled by it.
A last guard moves a candidate still outside the box along the segment from the (feasible)
solution of the levels above.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.linalg import combine, dot, mv
from wholebody.kernels.pinv import (
    FIXED,
    Free,
    basis,
    free_of,
    free_rank,
    level_step,
    project_free,
    row_norm2,
)

__all__ = ["Box", "inside", "saturate", "saturate_identity"]

Box = namedtuple("Box", ["lo", "hi", "lo_tol", "hi_tol"])
"""The box (scaled velocities) and its tolerance-widened form, for the inside test."""


@kernel
def inside(u: np.ndarray, lo_tol: np.ndarray, hi_tol: np.ndarray) -> bool:
    """Whether ``u`` lies in the tolerance-widened box (False for NaN)."""
    for k in range(u.shape[0]):
        if not (u[k] >= lo_tol[k] and u[k] <= hi_tol[k]):
            return False
    return True


@kernel
def _scaling(a: np.ndarray, rest: np.ndarray, box: Box, skip: np.ndarray) -> tuple[float, int]:
    """Largest ``s`` in [0, 1] with ``rest + s a`` in the box, and the joint that limits it
    (-1 if none); joints in ``skip`` are already saturated. 0 when ``rest`` itself is outside
    (no ``s`` puts every moving joint inside)."""
    lo, hi = box.lo, box.hi
    n = a.shape[0]
    if n == 0:
        return 1.0, -1
    s_max = np.inf
    critical = 0
    down = -np.inf
    for j in range(n):
        up_j, down_j = np.inf, -np.inf
        if (a[j] > 0 or a[j] < 0) and not skip[j]:
            towards, away = (hi[j], lo[j]) if a[j] > 0 else (lo[j], hi[j])
            up_j = (towards - rest[j]) / a[j]
            down_j = (away - rest[j]) / a[j]
        if up_j < s_max:
            s_max, critical = up_j, j
        if down_j > down or down_j != down_j:
            down = down_j
    if not s_max < np.inf:
        critical = -1
    if s_max < down or s_max < 0:
        return 0.0, critical
    return min(s_max, 1.0), critical


@kernel
def _segment(u0: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest ``t`` in [0, 1] with ``u0 + t d`` in the box."""
    if d.shape[0] == 0:
        return 1.0
    t = np.inf
    for j in range(d.shape[0]):
        if d[j] > 0:
            tj = (hi[j] - u0[j]) / d[j]
        elif d[j] < 0:
            tj = (lo[j] - u0[j]) / d[j]
        else:
            tj = np.inf
        if tj < t or tj != tj:
            t = tj
    return min(max(t, 0.0), 1.0)


@kernel
def _deflate(Z: np.ndarray, j: int) -> np.ndarray:
    """The basis of ``{Z y : (Z y)_j = 0}`` (n x (r - 1)) by one Householder reflection of
    Z's coordinates: ``Z H`` without its first column, row j exactly zero. Its projector is
    the rank-one update ``F - F e_j e_j^T F / F_jj`` of Z's."""
    n, r = Z.shape
    v = np.empty(r)
    for k in range(r):
        v[k] = Z[j, k]
    norm = math.sqrt(dot(v, v))
    v[0] += norm if v[0] >= 0 else -norm
    c = 2.0 / dot(v, v)
    out = np.empty((n, r - 1))
    for i in range(n):
        if i == j:
            out[i, :] = 0.0
            continue
        t = 0.0
        for k in range(r):
            t += Z[i, k] * v[k]
        t *= c
        for k in range(1, r):
            out[i, k - 1] = Z[i, k] - t * v[k]
    return out


@kernel
def _fixed(j: int, value: float, base: np.ndarray, free: Free) -> tuple[np.ndarray, Free]:
    """The free directions (a basis or mask) once joint j is saturated at ``value`` (new
    arrays): ``base`` moved along them (minimum norm) to put the joint there, and the
    directions that move it removed."""
    Z, mask = free.Z, free.mask
    if free.is_mask:
        if not mask[j]:
            return base, free
        nb = base.copy()
        nb[j] = value
        nm = mask.copy()
        nm[j] = False
        return nb, free_of(Z, True, nm)
    fjj = row_norm2(Z, j)
    if fjj <= FIXED:  # |row j of an orthonormal basis| <= 1e-9: the joint cannot move
        return base, free
    z = np.empty(Z.shape[1])
    for k in range(Z.shape[1]):
        z[k] = Z[j, k]
    nb = combine(base, (value - base[j]) / fjj, mv(Z, z))
    nb[j] = value
    return nb, free_of(_deflate(Z, j), False, mask)


@kernel
def _guard(u0: np.ndarray, u: np.ndarray, box: Box) -> np.ndarray:
    """``u``, or where it is outside the box (the last guard) the last point of the segment
    from ``u0`` towards it inside the tolerance-widened box, clipped to the box."""
    if inside(u, box.lo_tol, box.hi_tol):
        return u
    d = combine(u, -1.0, u0)
    out = combine(u0, _segment(u0, d, box.lo_tol, box.hi_tol), d)
    for j in range(out.shape[0]):
        out[j] = min(max(out[j], box.lo[j]), box.hi[j])
    return out


@kernel
def saturate(
    A: np.ndarray,
    b: np.ndarray,
    u0: np.ndarray,
    free: Free,
    sat: np.ndarray,
    box: Box,
    par: np.ndarray,
):
    """SNS for one level of tasks (rows ``A u = b``) on top of ``u0`` and the free directions
    the levels above leave: ``(u, free left, saturated joints, scale)``. The rank the level
    needs is that of its first factorisation."""
    n, m = u0.shape[0], A.shape[0]
    free = basis(free)
    base = u0
    needed = -1
    skip = sat.copy()
    best_s = -np.inf
    best_rest, best_a, best_left = u0, u0, free
    R = np.empty((m, 2))
    for it in range(n + 1):
        Ab = mv(A, base)
        for k in range(m):
            R[k, 0] = b[k]
            R[k, 1] = -Ab[k]
        Y, left, r = level_step(A, R, free, par, True)
        a, rest = Y[:, 0].copy(), combine(base, 1.0, Y[:, 1])
        if needed < 0:
            needed = r
        s_max, critical = _scaling(a, rest, box, skip)
        if it == 0 or s_max > best_s:
            best_s, best_rest, best_a, best_left = s_max, rest, a, left
        cand = combine(rest, 1.0, a)
        if inside(cand, box.lo_tol, box.hi_tol):
            return cand, left, skip, 1.0
        if r < needed or critical < 0:
            break  # out of free directions: scale the level by the best factor found
        skip[critical] = True
        bound = box.hi[critical] if cand[critical] > box.hi[critical] else box.lo[critical]
        base, free = _fixed(critical, bound, base, free)
    u = _guard(u0, combine(best_rest, best_s, best_a), box)
    return u, best_left, skip, best_s


@kernel
def saturate_identity(
    b: np.ndarray, s: float, u0: np.ndarray, free: Free, sat: np.ndarray, box: Box
):
    """SNS for a level of objectives only (rows ``s I``): its move is ``F b / s`` on the
    free directions ``F`` (joints with ``F_jj <= 1e-18`` held exactly); it leaves nothing
    free: ``(u, free left, saturated joints, scale)``."""
    n = u0.shape[0]
    free = basis(free)
    base = u0
    needed = free_rank(free)
    skip = sat.copy()
    best_s = -np.inf
    best_rest, best_a, best_none = u0, u0, False
    for it in range(n + 1):
        r = free_rank(free)
        a = project_free(b, free)
        for j in range(n):
            a[j] *= 1.0 / s
        rest = combine(base, -1.0, project_free(base, free))
        if not free.is_mask:  # a joint the directions do not move stays: 0, not rounding
            for j in range(n):
                if row_norm2(free.Z, j) <= FIXED:
                    a[j], rest[j] = 0.0, base[j]
        s_max, critical = _scaling(a, rest, box, skip)
        if it == 0 or s_max > best_s:
            best_s, best_rest, best_a, best_none = s_max, rest, a, r > 0
        cand = combine(rest, 1.0, a)
        if inside(cand, box.lo_tol, box.hi_tol):
            return cand, _nothing(n, r > 0), skip, 1.0
        if r < needed or critical < 0:
            break
        skip[critical] = True
        bound = box.hi[critical] if cand[critical] > box.hi[critical] else box.lo[critical]
        base, free = _fixed(critical, bound, base, free)
    u = _guard(u0, combine(best_rest, best_s, best_a), box)
    return u, _nothing(n, best_none), skip, best_s


@kernel
def _nothing(n: int, is_mask: bool) -> Free:
    """No free direction left: an empty mask (``is_mask``) or an empty basis."""
    return free_of(np.zeros((n, 0)), is_mask, np.zeros(n, np.bool_))
