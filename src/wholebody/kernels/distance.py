"""Signed distance between two convex primitives in kernels: sphere, capsule, box, cylinder.

A shape is a *core* swept by a ball of radius ``r``: a sphere is a point swept by its radius,
a capsule a segment (its z axis, ``[-h, h]``) swept by its radius, a box (half extents) and a
cylinder (radius, half length ``h`` along z) are their own cores (``r = 0``). The signed
distance of two shapes is that of their cores minus ``r_a + r_b``, with the same normal,
whether the cores are apart or not: the Minkowski difference of the shapes is that of the
cores inflated by a ball of radius ``r_a + r_b``. So:

- **two spheres or capsules**: the closest points of two segments, in closed form (exact;
  for parallel segments the middle of their overlap, so that the witness points slide
  smoothly);
- **a box or a cylinder in the pair**: GJK on the cores' support functions, run to the
  precision of double arithmetic (until the gap between its upper bound ``|v|`` and its lower
  bound ``v.w / |v|`` is below ``1e-15 |v| + 1e-14`` m, or a step no longer helps): exact on
  boxes, segments and points, which GJK finishes in a few steps; on a cylinder's curved side
  the witness points are support points along the normal, to GJK's precision (the supporting
  planes' gap, which the tests bound by 1e-9 m). Where the cores overlap or touch, EPA on the
  same support functions gives the penetration depth and normal (exact on boxes; within
  ``EPA_TOLERANCE`` on a cylinder, whose curved side EPA approximates by facets). Within
  ``NEAR`` of contact GJK's normal is the direction of a tiny gap, mostly rounding: EPA's
  facet normal is taken there when EPA's distance (a lower bound, from a supporting plane)
  meets GJK's.

Conventions are coal's: ``d`` (m) negative where the shapes overlap, witness points ``p_a``
on (or, overlapping, in) shape a and ``p_b`` on b with ``p_b - p_a = d n``, and ``n`` the unit
normal from a to b. Everything is computed in a's frame (b's pose relative to a's) and
returned in the world.

Sizes (m), per kind: sphere ``(r, 0, 0)``, capsule and cylinder ``(r, h, 0)``, box
``(hx, hy, hz)``, ``h`` being half lengths. A placement is 12 numbers: the rotation in
column-major order, then the translation (Pinocchio's ``SE3`` memory, as ``data.oMf``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from wholebody.kernels import kernel

__all__ = [
    "BOX",
    "CAPSULE",
    "CYLINDER",
    "EPA_TOLERANCE",
    "SPHERE",
    "Workspace",
    "shape_distance",
    "workspace",
]

SPHERE, CAPSULE, BOX, CYLINDER = 0, 1, 2, 3

GJK_ITERATIONS = 128
GJK_RELATIVE = 1e-15  # stop when the gap |v| - v.w/|v| (v.w/|v| <= d <= |v|) is below
GJK_ABSOLUTE = 1e-14  # m   GJK_RELATIVE |v| + GJK_ABSOLUTE (the rounding of v.w is ~1e-17 m)
_INSIDE = 1e-14  # m: the origin is in GJK's tetrahedron when this far inside each face
TOUCH = 1e-10  # m: cores closer than this are handed to EPA (a normal from their gap is noise)
NEAR = 1e-5  # m: cores closer than this get EPA's normal where EPA's facet is the closest one
EPA_VERTICES = 128
EPA_FACES = 2 * EPA_VERTICES + 4  # a closed triangulated polytope has 2 V - 4 faces
EPA_TOLERANCE = 1e-10  # m: stop when the support along the closest facet's normal is this close
_NEGLIGIBLE = 1e-12  # a barycentric weight below this drops its vertex from GJK's simplex
_FLAT = 1e-14  # sin^2 of a triangle's angle below which it has no plane to project on
_LINE = 1e-12  # 1 - cos^2 of the angle below which two segments count as parallel
_SEES = 1e-13  # m: a face sees EPA's new vertex beyond this (a cylinder's cap: coplanar points)
_SPREAD = 1e-10  # m: EPA's seed points closer than this to each other's hull are not new


class Workspace(NamedTuple):
    """Scratch of :func:`shape_distance`, made once per call of a caller (:func:`workspace`).
    Vertices are rows ``(w = a - b, a, b, lambda)`` in a's frame: a point of the Minkowski
    difference, the support points on a and on b that make it, a barycentric weight."""

    relative: np.ndarray  # (4, 3): b's rotation (rows 0-2) and position (row 3) in a's frame
    simplex: np.ndarray  # (4, 10): GJK's simplex
    saved: np.ndarray  # (4, 10): GJK's simplex before a step
    vertices: np.ndarray  # (EPA_VERTICES, 10): EPA's polytope
    faces: np.ndarray  # (EPA_FACES, 4): outward unit normal and distance from the origin
    face_vertices: np.ndarray  # (EPA_FACES, 4) int: three vertices (outward order), alive
    edges: np.ndarray  # (3 EPA_FACES, 2) int: the horizon of a new vertex
    candidate: np.ndarray  # (10,): EPA's answer for cores nearly in contact


@kernel
def workspace() -> Workspace:
    """A fresh :class:`Workspace`."""
    return Workspace(
        np.empty((4, 3)),
        np.empty((4, 10)),
        np.empty((4, 10)),
        np.empty((EPA_VERTICES, 10)),
        np.empty((EPA_FACES, 4)),
        np.empty((EPA_FACES, 4), dtype=np.int64),
        np.empty((3 * EPA_FACES, 2), dtype=np.int64),
        np.empty(10),
    )


@kernel
def _support(
    kind: int, size: np.ndarray, dx: float, dy: float, dz: float
) -> tuple[float, float, float]:
    """The point of a shape's core farthest along ``(dx, dy, dz)``, all in its own frame."""
    if kind == BOX:
        return (
            math.copysign(size[0], dx),
            math.copysign(size[1], dy),
            math.copysign(size[2], dz),
        )
    if kind == CYLINDER:
        rho = math.sqrt(dx * dx + dy * dy)
        z = math.copysign(size[1], dz)
        if rho > 0.0:
            return (size[0] * dx / rho, size[0] * dy / rho, z)
        return (0.0, 0.0, z)
    if kind == CAPSULE:
        return (0.0, 0.0, math.copysign(size[1], dz))
    return (0.0, 0.0, 0.0)


@kernel
def _vertex(
    ka: int,
    sa: np.ndarray,
    kb: int,
    sb: np.ndarray,
    B: np.ndarray,
    dx: float,
    dy: float,
    dz: float,
    V: np.ndarray,
    i: int,
) -> None:
    """Row ``i`` of ``V``: the point of the cores' Minkowski difference ``a - b`` farthest
    along ``(dx, dy, dz)`` (a's frame), with its ``a`` and ``b``; ``B`` b's pose in a's
    frame (:class:`Workspace` ``relative``)."""
    ax, ay, az = _support(ka, sa, dx, dy, dz)
    ex = -(B[0, 0] * dx + B[1, 0] * dy + B[2, 0] * dz)  # -d in b's frame
    ey = -(B[0, 1] * dx + B[1, 1] * dy + B[2, 1] * dz)
    ez = -(B[0, 2] * dx + B[1, 2] * dy + B[2, 2] * dz)
    sx, sy, sz = _support(kb, sb, ex, ey, ez)
    bx = B[0, 0] * sx + B[0, 1] * sy + B[0, 2] * sz + B[3, 0]
    by = B[1, 0] * sx + B[1, 1] * sy + B[1, 2] * sz + B[3, 1]
    bz = B[2, 0] * sx + B[2, 1] * sy + B[2, 2] * sz + B[3, 2]
    V[i, 0], V[i, 1], V[i, 2] = ax - bx, ay - by, az - bz
    V[i, 3], V[i, 4], V[i, 5] = ax, ay, az
    V[i, 6], V[i, 7], V[i, 8] = bx, by, bz


@kernel
def _edge(S: np.ndarray, i: int, j: int) -> tuple[float, float]:
    """The point of the segment ``S[i], S[j]`` closest to the origin: its squared norm and
    its parameter ``s`` (the point is ``(1 - s) S[i] + s S[j]``)."""
    ex, ey, ez = S[j, 0] - S[i, 0], S[j, 1] - S[i, 1], S[j, 2] - S[i, 2]
    ee = ex * ex + ey * ey + ez * ez
    s = -(S[i, 0] * ex + S[i, 1] * ey + S[i, 2] * ez) / ee if ee > 0.0 else 0.0
    s = min(max(s, 0.0), 1.0)
    px, py, pz = S[i, 0] + s * ex, S[i, 1] + s * ey, S[i, 2] + s * ez
    return px * px + py * py + pz * pz, s


@kernel
def _triangle(S: np.ndarray, i: int, j: int, k: int) -> tuple[float, float, float, float]:
    """The point of the triangle ``S[i], S[j], S[k]`` closest to the origin: its squared
    norm and barycentric weights. The origin's projection on the plane where it falls inside
    (weights from the areas it cuts, accurate on small triangles), else the closest point of
    the closest edge (also for a triangle too thin to have a plane)."""
    ax, ay, az = S[i, 0], S[i, 1], S[i, 2]
    bx, by, bz = S[j, 0], S[j, 1], S[j, 2]
    cx, cy, cz = S[k, 0], S[k, 1], S[k, 2]
    ux, uy, uz = bx - ax, by - ay, bz - az
    vx, vy, vz = cx - ax, cy - ay, cz - az
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    nn = nx * nx + ny * ny + nz * nz
    if nn > _FLAT * (ux * ux + uy * uy + uz * uz) * (vx * vx + vy * vy + vz * vz):
        la = nx * (by * cz - bz * cy) + ny * (bz * cx - bx * cz) + nz * (bx * cy - by * cx)
        lb = nx * (cy * az - cz * ay) + ny * (cz * ax - cx * az) + nz * (cx * ay - cy * ax)
        lc = nx * (ay * bz - az * by) + ny * (az * bx - ax * bz) + nz * (ax * by - ay * bx)
        if la >= 0.0 and lb >= 0.0 and lc >= 0.0:  # weights summing to 1 to rounding
            h = nx * ax + ny * ay + nz * az
            total = la + lb + lc
            return h * h / nn, la / total, lb / total, lc / total
    best, wa, wb, wc = math.inf, 0.0, 0.0, 0.0
    for e in range(3):  # one call site: each inlined copy costs compile time
        p, q = (i, j) if e == 0 else ((i, k) if e == 1 else (j, k))
        d2, t = _edge(S, p, q)
        if d2 < best:
            best = d2
            if e == 0:
                wa, wb, wc = 1.0 - t, t, 0.0
            elif e == 1:
                wa, wb, wc = 1.0 - t, 0.0, t
            else:
                wa, wb, wc = 0.0, 1.0 - t, t
    return best, wa, wb, wc


@kernel
def _closest(S: np.ndarray, n: int) -> int:
    """Reduce the simplex ``S[:n]`` to the smallest face holding its point closest to the
    origin, with the barycentric weights in column 9; returns its size (4: the origin is
    inside the tetrahedron)."""
    if n == 1:
        S[0, 9] = 1.0
        return 1
    if n == 2:
        _, s = _edge(S, 0, 1)
        S[0, 9], S[1, 9] = 1.0 - s, s
    else:
        if n == 4:
            inside = True  # the origin inside every face's plane, each vertex clear of the
            for f in range(4):  # plane of the face opposite it (no verdict on a flat one)
                i, j, k = (f + 1) % 4, (f + 2) % 4, (f + 3) % 4
                ux, uy, uz = S[j, 0] - S[i, 0], S[j, 1] - S[i, 1], S[j, 2] - S[i, 2]
                vx, vy, vz = S[k, 0] - S[i, 0], S[k, 1] - S[i, 1], S[k, 2] - S[i, 2]
                nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
                norm = math.sqrt(nx * nx + ny * ny + nz * nz)
                origin = -(nx * S[i, 0] + ny * S[i, 1] + nz * S[i, 2])
                other = nx * (S[f, 0] - S[i, 0]) + ny * (S[f, 1] - S[i, 1])
                other += nz * (S[f, 2] - S[i, 2])
                if other < 0.0:
                    origin, other = -origin, -other
                inside = inside and origin > _INSIDE * norm and other > _SPREAD * norm
            if inside:
                return 4
        best = math.inf  # the triangle, or the closest of the tetrahedron's faces (whatever
        for f in range(1 if n == 3 else 4):  # the signs say on a nearly flat tetrahedron)
            i, j, k = (0, 1, 2) if n == 3 else ((f + 1) % 4, (f + 2) % 4, (f + 3) % 4)
            d2, li, lj, lk = _triangle(S, i, j, k)
            if d2 < best:
                best = d2
                S[i, 9], S[j, 9], S[k, 9] = li, lj, lk
                if n == 4:
                    S[f, 9] = 0.0
    m, total = 0, 0.0
    for i in range(n):  # a weight at rounding level is a vertex that does not count
        if S[i, 9] > _NEGLIGIBLE:
            if m != i:
                for c in range(10):
                    S[m, c] = S[i, c]
            total += S[m, 9]
            m += 1
    for i in range(m):
        S[i, 9] /= total
    return m


@kernel
def _gjk(
    ka: int, sa: np.ndarray, kb: int, sb: np.ndarray, B: np.ndarray, far: float, ws: Workspace
) -> tuple[float, int, float]:
    """GJK on the cores: the distance between them (an upper bound: the norm of a point of
    their difference), the size of the final simplex ``ws.simplex`` (its weights give the
    witness points) and the best lower bound met on the way (``v.w / |v|``); size 4 or a
    distance of 0 where they overlap, ``inf`` as soon as they are certainly farther apart
    than ``far``. Where a step makes no progress (rounding) the simplex before it is kept."""
    S, saved = ws.simplex, ws.saved
    vx, vy, vz = -B[3, 0], -B[3, 1], -B[3, 2]  # from b's origin to a's: a first direction
    if vx == 0.0 and vy == 0.0 and vz == 0.0:
        vx = 1.0
    vv = math.inf  # |v|^2 once v is a point of the difference
    lower = -math.inf
    n = 0
    for _ in range(GJK_ITERATIONS):
        _vertex(ka, sa, kb, sb, B, -vx, -vy, -vz, S, n)
        vw = vx * S[n, 0] + vy * S[n, 1] + vz * S[n, 2]
        norm = math.sqrt(vx * vx + vy * vy + vz * vz)
        lower = max(lower, vw / norm)  # every point x of the difference has |x| >= v.x/|v|
        if lower > far:
            return math.inf, n, lower
        if n > 0 and vv - vw <= GJK_RELATIVE * vv + GJK_ABSOLUTE * math.sqrt(vv):
            break
        for i in range(n):  # (element loops: a slice copy compiles its error messages)
            for c in range(10):
                saved[i, c] = S[i, c]
        m = _closest(S, n + 1)
        if m == 4:
            return 0.0, m, lower
        vx = vy = vz = 0.0
        for i in range(m):
            vx += S[i, 9] * S[i, 0]
            vy += S[i, 9] * S[i, 1]
            vz += S[i, 9] * S[i, 2]
        now = vx * vx + vy * vy + vz * vz
        if now >= vv:  # no progress: the precision of the arithmetic is reached
            for i in range(n):
                for c in range(10):
                    S[i, c] = saved[i, c]
            break
        vv, n = now, m
        if now == 0.0:
            break
    return math.sqrt(vv), n, lower


@kernel
def _segments(
    ka: int, sa: np.ndarray, kb: int, sb: np.ndarray, B: np.ndarray, out: np.ndarray
) -> None:
    """The cores of two spheres or capsules (a point or a segment along z each): their
    distance, closest points and normal into ``out`` (a's frame), in closed form (Ericson's
    clamped line parameters)."""
    ha = sa[1] if ka == CAPSULE else 0.0
    hb = sb[1] if kb == CAPSULE else 0.0
    ex, ey, ez = B[0, 2], B[1, 2], B[2, 2]  # b's axis
    tx, ty, tz = B[3, 0], B[3, 1], B[3, 2]
    te = tx * ex + ty * ey + tz * ez
    c = ez
    den = 1.0 - c * c
    if den > _LINE:
        s = (tz - te * c) / den
    else:  # parallel: the middle of the overlap of a's segment and b's projected on it
        lo, hi = max(-ha, tz - hb * abs(c)), min(ha, tz + hb * abs(c))
        s = 0.5 * (lo + hi)
    s = min(max(s, -ha), ha)
    u = min(max(s * c - te, -hb), hb)
    s = min(max(tz + u * c, -ha), ha)
    bx, by, bz = tx + u * ex, ty + u * ey, tz + u * ez
    gx, gy, gz = bx, by, bz - s
    dc = math.sqrt(gx * gx + gy * gy + gz * gz)
    if dc > 0.0:
        nx, ny, nz = gx / dc, gy / dc, gz / dc
    elif ha > 0.0 and hb > 0.0 and den > _LINE:  # crossing segments: across both
        r = math.sqrt(ex * ex + ey * ey)
        nx, ny, nz = -ey / r, ex / r, 0.0
    elif ha > 0.0:  # a point on a's segment: any direction across it
        nx, ny, nz = 1.0, 0.0, 0.0
    elif hb > 0.0:
        r = math.sqrt(ex * ex + ez * ez)
        nx, ny, nz = ez / r, 0.0, -ex / r
        if r == 0.0:
            nx, ny, nz = 1.0, 0.0, 0.0
    else:  # concentric spheres
        nx, ny, nz = 0.0, 0.0, 1.0
    out[0] = dc
    out[1], out[2], out[3] = 0.0, 0.0, s
    out[4], out[5], out[6] = bx, by, bz
    out[7], out[8], out[9] = nx, ny, nz


@kernel
def _face(V: np.ndarray, F: np.ndarray, FI: np.ndarray, f: int, i: int, j: int, k: int) -> None:
    """EPA's face ``f`` on the vertices ``i, j, k`` (outward counter-clockwise): its unit
    normal and distance from the origin (``inf``, never the closest, when degenerate)."""
    ux, uy, uz = V[j, 0] - V[i, 0], V[j, 1] - V[i, 1], V[j, 2] - V[i, 2]
    vx, vy, vz = V[k, 0] - V[i, 0], V[k, 1] - V[i, 1], V[k, 2] - V[i, 2]
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    FI[f, 0], FI[f, 1], FI[f, 2], FI[f, 3] = i, j, k, 1
    if norm > 0.0:
        F[f, 0], F[f, 1], F[f, 2] = nx / norm, ny / norm, nz / norm
        F[f, 3] = (nx * V[i, 0] + ny * V[i, 1] + nz * V[i, 2]) / norm
    else:
        F[f, 0] = F[f, 1] = F[f, 2] = 0.0
        F[f, 3] = math.inf


@kernel
def _tetrahedron(
    ka: int, sa: np.ndarray, kb: int, sb: np.ndarray, B: np.ndarray, V: np.ndarray, n: int
) -> int:
    """Grow GJK's simplex ``V[:n]`` (the origin in it or on it) into a tetrahedron with
    support points in new directions; returns its size (below 4 where the difference of the
    cores is flat)."""
    tries = 0
    while n < 4 and tries < 6:
        if n == 1:
            dx, dy, dz = 0.0, 0.0, 0.0
            if tries < 2:
                dx = 1.0
            elif tries < 4:
                dy = 1.0
            else:
                dz = 1.0
        else:
            ux, uy, uz = V[1, 0] - V[0, 0], V[1, 1] - V[0, 1], V[1, 2] - V[0, 2]
            if n == 2:  # across the segment, about the axis it is least along, then the others
                ax, ay, az = abs(ux), abs(uy), abs(uz)
                least = 0 if ax <= ay and ax <= az else (1 if ay <= az else 2)
                axis = (least + tries // 2) % 3
                ex, ey, ez = 0.0, 0.0, 0.0
                if axis == 0:
                    ex = 1.0
                elif axis == 1:
                    ey = 1.0
                else:
                    ez = 1.0
            else:
                ex, ey, ez = V[2, 0] - V[0, 0], V[2, 1] - V[0, 1], V[2, 2] - V[0, 2]
            dx, dy, dz = uy * ez - uz * ey, uz * ex - ux * ez, ux * ey - uy * ex
        if tries % 2:
            dx, dy, dz = -dx, -dy, -dz
        _vertex(ka, sa, kb, sb, B, dx, dy, dz, V, n)
        gx, gy, gz = V[n, 0] - V[0, 0], V[n, 1] - V[0, 1], V[n, 2] - V[0, 2]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        new = norm > 0.0 and (gx * dx + gy * dy + gz * dz) / norm > _SPREAD
        if n == 1:
            new = gx * gx + gy * gy + gz * gz > _SPREAD * _SPREAD
        if new:
            n += 1
            tries = 0
        else:
            tries += 1
    return n


@kernel
def _expand(V: np.ndarray, F: np.ndarray, FI: np.ndarray, E: np.ndarray, nf: int, nv: int) -> int:
    """Add EPA's vertex ``nv``: remove the faces it sees, join it to their horizon (their
    edges, each shared one cancelled) with a face per edge in the first free slots; returns
    the number of slots used (-1: out of room)."""
    ne = 0
    for g in range(nf):
        i = FI[g, 0]
        seen = F[g, 0] * (V[nv, 0] - V[i, 0]) + F[g, 1] * (V[nv, 1] - V[i, 1])
        if FI[g, 3] and seen + F[g, 2] * (V[nv, 2] - V[i, 2]) > _SEES:
            FI[g, 3] = 0
            for e in range(3):
                p, q = FI[g, e], FI[g, (e + 1) % 3]
                shared = -1
                for h in range(ne):
                    if E[h, 0] == q and E[h, 1] == p:
                        shared = h
                if shared >= 0:
                    ne -= 1
                    E[shared, 0], E[shared, 1] = E[ne, 0], E[ne, 1]
                else:
                    E[ne, 0], E[ne, 1] = p, q
                    ne += 1
    slot = 0
    for h in range(ne):
        while slot < nf and FI[slot, 3]:
            slot += 1
        if slot == F.shape[0]:
            return -1
        if slot == nf:
            nf += 1
        _face(V, F, FI, slot, E[h, 0], E[h, 1], nv)
    return nf


@kernel
def _polytope(
    ka: int, sa: np.ndarray, kb: int, sb: np.ndarray, B: np.ndarray, ws: Workspace
) -> tuple[int, float]:
    """EPA's expansion from the tetrahedron ``ws.vertices[:4]``: the polytope grows towards
    its face closest to the origin until the support along that face's normal is within
    ``EPA_TOLERANCE`` of it (exact on boxes); returns that face and its distance from the
    origin (face -1: every face degenerate)."""
    V, F, FI, E = ws.vertices, ws.faces, ws.face_vertices, ws.edges
    for f in range(4):  # the face opposite vertex f, turned outwards
        i, j, k = (f + 1) % 4, (f + 2) % 4, (f + 3) % 4
        _face(V, F, FI, f, i, j, k)
        side = F[f, 0] * (V[f, 0] - V[i, 0]) + F[f, 1] * (V[f, 1] - V[i, 1])
        if side + F[f, 2] * (V[f, 2] - V[i, 2]) > 0.0:
            _face(V, F, FI, f, i, k, j)
    nf, nv = 4, 4
    while True:
        f, best = -1, math.inf
        for g in range(nf):
            if FI[g, 3] and F[g, 3] < best:
                f, best = g, F[g, 3]
        if f < 0:
            return f, best
        _vertex(ka, sa, kb, sb, B, F[f, 0], F[f, 1], F[f, 2], V, nv)
        reach = F[f, 0] * V[nv, 0] + F[f, 1] * V[nv, 1] + F[f, 2] * V[nv, 2]
        if reach - best <= EPA_TOLERANCE or nv + 1 == V.shape[0]:
            return f, best
        nf = _expand(V, F, FI, E, nf, nv)
        if nf < 0:  # out of room (rounding made the polytope non-convex): the best so far
            return f, best
        nv += 1


@kernel
def _epa(
    ka: int,
    sa: np.ndarray,
    kb: int,
    sb: np.ndarray,
    B: np.ndarray,
    ws: Workspace,
    n: int,
    out: np.ndarray,
) -> None:
    """EPA from GJK's simplex (``ws.simplex[:n]``, the origin in it or on it): the cores'
    signed distance (minus the penetration depth), witness points and normal into ``out``
    (a's frame), from the closest face of the grown polytope."""
    V, F, FI = ws.vertices, ws.faces, ws.face_vertices
    for i in range(n):
        for c in range(10):
            V[i, c] = ws.simplex[i, c]
    f, best = -1, 0.0
    if _tetrahedron(ka, sa, kb, sb, B, V, n) == 4:
        f, best = _polytope(ka, sa, kb, sb, B, ws)
    if f < 0:  # a flat difference (a degenerate core): depth 0 across it
        out[0] = 0.0
        for c in range(6):
            out[1 + c] = V[0, 3 + c]
        out[7], out[8], out[9] = 0.0, 0.0, 1.0
        return
    nx, ny, nz = F[f, 0], F[f, 1], F[f, 2]
    i, j, k = FI[f, 0], FI[f, 1], FI[f, 2]
    px, py, pz = best * nx, best * ny, best * nz  # the origin's projection on the face
    ux, uy, uz = V[i, 0] - px, V[i, 1] - py, V[i, 2] - pz
    vx, vy, vz = V[j, 0] - px, V[j, 1] - py, V[j, 2] - pz
    wx, wy, wz = V[k, 0] - px, V[k, 1] - py, V[k, 2] - pz
    li = nx * (vy * wz - vz * wy) + ny * (vz * wx - vx * wz) + nz * (vx * wy - vy * wx)
    lj = nx * (wy * uz - wz * uy) + ny * (wz * ux - wx * uz) + nz * (wx * uy - wy * ux)
    lk = nx * (uy * vz - uz * vy) + ny * (uz * vx - ux * vz) + nz * (ux * vy - uy * vx)
    total = li + lj + lk
    out[0] = -best
    for c in range(3):
        out[1 + c] = (li * V[i, 3 + c] + lj * V[j, 3 + c] + lk * V[k, 3 + c]) / total
        out[4 + c] = (li * V[i, 6 + c] + lj * V[j, 6 + c] + lk * V[k, 6 + c]) / total
    out[7], out[8], out[9] = nx, ny, nz


@kernel
def _cores(
    ka: int,
    sa: np.ndarray,
    kb: int,
    sb: np.ndarray,
    B: np.ndarray,
    far: float,
    ws: Workspace,
    out: np.ndarray,
) -> None:
    """The cores' distance, witness points and normal into ``out`` (a's frame; ``inf`` past
    ``far``): GJK's, or EPA's where they overlap or touch. Within NEAR of contact GJK's
    normal is the direction of a tiny gap, and its bounds may not have met (it creeps onto a
    contact of curved shapes): EPA's facet then, where its distance (a lower bound, from a
    supporting plane) meets GJK's upper bound or beats GJK's lower one."""
    S = ws.simplex
    dc, n, lower = _gjk(ka, sa, kb, sb, B, far, ws)
    if dc == math.inf:
        out[0] = math.inf
        return
    overlap = n == 4 or dc <= TOUCH
    if not overlap:
        out[0] = dc
        for c in range(3):
            out[1 + c] = out[4 + c] = 0.0
            for i in range(n):
                out[1 + c] += S[i, 9] * S[i, 3 + c]
                out[4 + c] += S[i, 9] * S[i, 6 + c]
        for c in range(3):
            out[7 + c] = (out[4 + c] - out[1 + c]) / dc
    if overlap or dc <= NEAR:  # one call site: each inlined copy of EPA costs compile time
        near = out if overlap else ws.candidate
        _epa(ka, sa, kb, sb, B, ws, n, near)
        met = near[0] >= dc - 2.0 * EPA_TOLERANCE
        if not overlap and (met or (dc - lower > 2.0 * EPA_TOLERANCE and near[0] > lower)):
            for c in range(10):
                out[c] = near[c]


@kernel
def shape_distance(
    ka: int,
    sa: np.ndarray,
    Ma: np.ndarray,
    kb: int,
    sb: np.ndarray,
    Mb: np.ndarray,
    far: float,
    ws: Workspace,
    out: np.ndarray,
) -> None:
    """The signed distance of shape a (kind ``ka``, sizes ``sa``, world placement ``Ma``) and
    shape b, into ``out`` (10,): ``d`` (m), ``p_a``, ``p_b`` (world, m) and the unit normal
    ``n`` from a to b (world); ``d = inf`` (the rest unset) where the shapes are certainly
    farther apart than ``far`` (m), found before the exact distance is."""
    B = ws.relative  # b in a's frame: R = Ra^T Rb, t = Ra^T (tb - ta)
    for i in range(3):
        for c in range(3):
            B[i, c] = Ma[3 * i] * Mb[3 * c] + Ma[3 * i + 1] * Mb[3 * c + 1]
            B[i, c] += Ma[3 * i + 2] * Mb[3 * c + 2]
    for i in range(3):
        B[3, i] = Ma[3 * i] * (Mb[9] - Ma[9]) + Ma[3 * i + 1] * (Mb[10] - Ma[10])
        B[3, i] += Ma[3 * i + 2] * (Mb[11] - Ma[11])
    ra = sa[0] if ka <= CAPSULE else 0.0  # a sphere's or a capsule's radius sweeps its core
    rb = sb[0] if kb <= CAPSULE else 0.0
    if ka <= CAPSULE and kb <= CAPSULE:
        _segments(ka, sa, kb, sb, B, out)
    else:
        _cores(ka, sa, kb, sb, B, far + ra + rb, ws, out)
        if out[0] == math.inf:
            return
    out[0] -= ra + rb
    for c in range(3):  # the cores' points moved out to the surfaces
        out[1 + c] += ra * out[7 + c]
        out[4 + c] -= rb * out[7 + c]
    for k in (1, 4, 7):  # to the world
        x, y, z = out[k], out[k + 1], out[k + 2]
        for i in range(3):
            out[k + i] = Ma[i] * x + Ma[3 + i] * y + Ma[6 + i] * z
            if k < 7:
                out[k + i] += Ma[9 + i]
