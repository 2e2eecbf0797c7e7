"""Collision rows in kernels: the checked pairs closer than a distance, closest first, and
the velocity-damper row of each (:mod:`wholebody.tasks.collision`).

For a pair at signed distance ``d`` with witness points ``p_a``, ``p_b`` and unit normal ``n``
from a to b (:mod:`wholebody.kernels.distance`), moving the robot at ``u`` changes the
distance at::

    d' = n^T (J_b(p_b) - J_a(p_a)) u,   J(p)[:, j] = v_j + w_j x p  (j a column moving the shape)

with ``(v_j, w_j)`` column j of Pinocchio's ``data.J`` (WORLD convention: spatial velocity at
the world origin), ``J(p)`` the world-aligned Jacobian of the point p fixed to the shape's
frame, in actuated columns through the actuation entries, as
:func:`wholebody.kernels.kinematics.frame_kinematics`; an obstacle's is zero. A column that
moves both shapes adds ``w_j . ((p_b - p_a) x n) = 0`` (``p_b - p_a = d n``) and is skipped.

**The packed model** (:class:`PackedCollision`, made once by
:attr:`wholebody.collision.CollisionModel.packed`): per shape its kind, the frame it is fixed
to and its placement there (``oMf[frame] * local``; the world for an obstacle), its sizes and
a bounding sphere; per pair the two shapes and, for a pair the kernel does not compute (a
mesh: coal does, in Python, before the call), its row in ``external``.

**Broad phase**: a pair whose bounding spheres are farther apart than ``within`` costs one
distance between two centres; GJK stops as soon as its lower bound passes ``within``.

The damper's bound on each row (:class:`~wholebody.tasks.CollisionAvoidance`) is the
caller's: it needs only the distances written here.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.distance import shape_distance, workspace

__all__ = [
    "CENTRE",
    "EXTERNAL",
    "LOCAL",
    "RADIUS",
    "RESULT_WIDTH",
    "SHAPE_WIDTH",
    "SIZE",
    "PackedCollision",
    "collision_entry",
    "collision_rows",
    "nearest_pairs",
    "pair_rows",
]

EXTERNAL = 4  # a shape kind the kernel leaves to coal (meshes, ...): its pairs come in external

# PackedCollision.shapes columns
LOCAL = 0  # (12,): placement in its frame, rotation column-major then translation (m)
SIZE = 12  # (3,): sizes (m), see wholebody.kernels.distance
CENTRE = 15  # (3,): bounding sphere's centre in the shape's own axes (m)
RADIUS = 18  # bounding sphere's radius (m)
SHAPE_WIDTH = 19

RESULT_WIDTH = 10  # a pair's d (m), p_a, p_b (world, m), n (world)
_SLACK = 1e-9  # m: the broad phase keeps pairs this much beyond ``within`` (rounding)


class PackedCollision(NamedTuple):
    """A collision model as the kernels read it (module docstring); S shapes, P pairs, E
    actuation entries."""

    shapes: np.ndarray  # (S, SHAPE_WIDTH): local placement, sizes, bounding sphere
    kinds: np.ndarray  # (S, 2) int: kind (distance.SPHERE, ... or EXTERNAL), frame (-1: world)
    support: np.ndarray  # (S, nv) int: 1 where the velocity coordinate moves the shape
    pairs: np.ndarray  # (P, 3) int: shape a, shape b, row in external (-1: computed here)
    act: np.ndarray  # (2, E) int: actuation entries' column k of u, row j of v
    act_a: np.ndarray  # (E,): their values (v = A u)


@kernel
def _placements(oMf: np.ndarray, model: PackedCollision, world: np.ndarray) -> None:
    """Each shape's world placement (12) and bounding sphere's world centre (3) into
    ``world`` (S, 15)."""
    shapes, kinds = model.shapes, model.kinds
    for s in range(shapes.shape[0]):
        L = shapes[s]
        f = kinds[s, 1]
        if f < 0:
            for c in range(12):  # (element loops: a slice copy compiles its error messages)
                world[s, c] = L[c]
        else:
            M = oMf[f]
            for c in range(4):  # the rotation's columns, then the translation
                for i in range(3):
                    x = M[i] * L[3 * c] + M[3 + i] * L[3 * c + 1] + M[6 + i] * L[3 * c + 2]
                    world[s, 3 * c + i] = x + M[9 + i] if c == 3 else x
        W = world[s]
        for i in range(3):
            x = W[i] * L[CENTRE] + W[3 + i] * L[CENTRE + 1] + W[6 + i] * L[CENTRE + 2]
            world[s, 12 + i] = x + W[9 + i]


@kernel
def nearest_pairs(
    oMf: np.ndarray,
    model: PackedCollision,
    external: np.ndarray,
    within: float,
    found: np.ndarray,
    index: np.ndarray,
) -> tuple[int, int]:
    """The pairs closer than ``within`` (m), closest first (ties in pair order), at most
    ``found.shape[0]`` of them: each one's ``d, p_a, p_b, n`` into ``found`` (rows of
    RESULT_WIDTH) and its pair into ``index``. ``oMf`` the frame placements (nframes, 12);
    ``external`` (rows of RESULT_WIDTH) the results of the pairs computed outside, ``d = inf``
    for those certainly farther than ``within``. Returns ``(written, within)``: how many
    rows were written and how many pairs are closer than ``within`` (more than written when
    ``found`` is too short)."""
    shapes, kinds, pairs = model.shapes, model.kinds, model.pairs
    world = np.empty((shapes.shape[0], 15))
    _placements(oMf, model, world)
    ws = workspace()
    out = np.empty(RESULT_WIDTH)
    cap = found.shape[0]
    n = near = 0
    for p in range(pairs.shape[0]):
        a, b, slot = pairs[p, 0], pairs[p, 1], pairs[p, 2]
        gx = world[b, 12] - world[a, 12]
        gy = world[b, 13] - world[a, 13]
        gz = world[b, 14] - world[a, 14]
        gap = math.sqrt(gx * gx + gy * gy + gz * gz) - shapes[a, RADIUS] - shapes[b, RADIUS]
        if not gap < within + _SLACK:
            continue
        if slot >= 0:
            for c in range(RESULT_WIDTH):
                out[c] = external[slot, c]
        else:
            sa, sb = shapes[a, SIZE : SIZE + 3], shapes[b, SIZE : SIZE + 3]
            shape_distance(kinds[a, 0], sa, world[a], kinds[b, 0], sb, world[b], within, ws, out)
        d = out[0]
        if not d < within:
            continue
        near += 1
        if n < cap:
            r = n
            n += 1
        elif cap > 0 and d < found[cap - 1, 0]:
            r = cap - 1
        else:
            continue
        while r > 0 and found[r - 1, 0] > d:  # insertion: keep the rows sorted
            for c in range(RESULT_WIDTH):
                found[r, c] = found[r - 1, c]
            index[r] = index[r - 1]
            r -= 1
        for c in range(RESULT_WIDTH):
            found[r, c] = out[c]
        index[r] = p
    return n, near


@kernel
def pair_rows(
    J: np.ndarray,
    model: PackedCollision,
    found: np.ndarray,
    index: np.ndarray,
    n: int,
    rows: np.ndarray,
) -> None:
    """The rows ``n^T (J_b(p_b) - J_a(p_a))`` (nu,) of the first ``n`` pairs of ``found``
    and ``index`` (:func:`nearest_pairs`) into ``rows``; ``J`` is ``data.J`` (6 x nv)."""
    support, pairs, act, act_a = model.support, model.pairs, model.act, model.act_a
    for r in range(n):
        a, b = pairs[index[r], 0], pairs[index[r], 1]
        R = found[r]
        nx, ny, nz = R[7], R[8], R[9]
        # n . (w x p) = w . (p x n)
        ax, ay, az = R[2] * nz - R[3] * ny, R[3] * nx - R[1] * nz, R[1] * ny - R[2] * nx
        bx, by, bz = R[5] * nz - R[6] * ny, R[6] * nx - R[4] * nz, R[4] * ny - R[5] * nx
        for k in range(rows.shape[1]):
            rows[r, k] = 0.0
        for e in range(act.shape[1]):
            j = act[1, e]
            on_a, on_b = support[a, j], support[b, j]
            if on_a == on_b:
                continue
            rate = nx * J[0, j] + ny * J[1, j] + nz * J[2, j]
            if on_b:
                rate += J[3, j] * bx + J[4, j] * by + J[5, j] * bz
            else:
                rate = -(rate + J[3, j] * ax + J[4, j] * ay + J[5, j] * az)
            rows[r, act[0, e]] += act_a[e] * rate


@kernel
def collision_rows(
    J: np.ndarray,
    oMf: np.ndarray,
    model: PackedCollision,
    external: np.ndarray,
    within: float,
    rows: np.ndarray,
    found: np.ndarray,
    index: np.ndarray,
) -> tuple[int, int]:
    """The pairs closer than ``within`` (m), closest first, at most ``max_rows =
    rows.shape[0]`` of them: their rows (max_rows x nu), results (``d, p_a, p_b, n`` into
    ``found``, at least max_rows x RESULT_WIDTH) and pair indices (``index``, at least
    max_rows) (:func:`nearest_pairs`, :func:`pair_rows`); ``J`` is ``data.J`` (6 x nv), ``oMf``
    the frame placements (nframes, 12), ``external`` the pairs computed outside
    (:meth:`wholebody.collision.CollisionModel.external`; (0, RESULT_WIDTH) without meshes).
    Returns ``(written, within)``: within > written tells that max_rows was too small."""
    n, near = nearest_pairs(oMf, model, external, within, found[: rows.shape[0]], index)
    pair_rows(J, model, found, index, n, rows)
    return n, near


# the block of a compiled CollisionAvoidance (floats): safety, influence (m), approach speed
# (m/s), rows written and pairs within (out), then per row its pair's result (RESULT_WIDTH,
# out) and the pair's index (out), then the shapes (S x SHAPE_WIDTH); its integers: S, P, the
# kinds (S x 2), the support (S x nv), the pairs (P x 3)
CA_SAFETY, CA_INFLUENCE, CA_SPEED, CA_WRITTEN, CA_WITHIN = 0, 1, 2, 3, 4
CA_HEAD = 5


@kernel
def collision_entry(
    J: np.ndarray,
    oMf: np.ndarray,
    par: np.ndarray,
    ints: np.ndarray,
    act: np.ndarray,
    act_a: np.ndarray,
    C: np.ndarray,
    cb: np.ndarray,
) -> None:
    """A compiled :class:`~wholebody.tasks.CollisionAvoidance`'s rows ``C`` (max_rows x nu,
    unscaled) and bounds ``cb`` (2 x max_rows) from its blocks (above): the velocity damper
    ``d' >= -speed (d - safety) / (influence - safety)`` on the closest pairs within the
    influence, the rows left over inactive (``-inf <= 0 u <= inf``)."""
    m, nv = C.shape[0], J.shape[1]
    S, P = ints[0], ints[1]
    kinds = ints[2 : 2 + 2 * S].reshape((S, 2))
    support = ints[2 + 2 * S : 2 + 2 * S + S * nv].reshape((S, nv))
    pairs = ints[2 + 2 * S + S * nv : 2 + 2 * S + S * nv + 3 * P].reshape((P, 3))
    found = par[CA_HEAD : CA_HEAD + m * RESULT_WIDTH].reshape((m, RESULT_WIDTH))
    at = CA_HEAD + m * RESULT_WIDTH
    shapes = par[at + m : at + m + S * SHAPE_WIDTH].reshape((S, SHAPE_WIDTH))
    model = PackedCollision(shapes, kinds, support, pairs, act, act_a)
    index = np.zeros(m, np.int64)
    safety, influence, speed = par[CA_SAFETY], par[CA_INFLUENCE], par[CA_SPEED]
    n, near = collision_rows(J, oMf, model, np.zeros((0, RESULT_WIDTH)), influence, C, found, index)
    par[CA_WRITTEN], par[CA_WITHIN] = n, near
    for r in range(m):
        par[at + r] = index[r] if r < n else -1.0
        cb[1, r] = np.inf
        if r < n:
            cb[0, r] = -speed * (found[r, 0] - safety) / (influence - safety)
        else:
            cb[0, r] = -np.inf
            C[r, :] = 0.0
