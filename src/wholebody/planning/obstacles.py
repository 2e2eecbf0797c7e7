"""Volumetric obstacles for DMPs: superquadric isopotentials and their repulsive potentials.

After Ginesi, Meli, Calanca, Dall'Alba, Sansonetto, Fiorini, "Dynamic Movement Primitives:
Volumetric Obstacle Avoidance", ICAR 2019 (ref. [23] of Niu et al. 2024).

**Isopotential.** An obstacle is a superquadric with centre ``c`` and rotation ``R`` (its axes
in world coordinates). In its own frame ``p = R^T (x - c)``, with ``u_k = p_k / f_k``::

    C(x) = (u1^(2n) + u2^(2n))^(m/n) + u3^(2m) - 1

(``u^(2n)`` meaning ``|u|^(2n)``). ``C < 0`` inside, ``C = 0`` on the surface, ``C > 0`` outside.
``n = m = 1`` is an ellipsoid with semi-axes ``f``; large ``n`` gives a square cross-section,
large ``m`` flat ends. ``1 <= n, m <= 32``, and ``m > 1`` unless ``n = 1``, so that ``C`` is twice
continuously differentiable (with ``m = 1 < n`` its Hessian jumps on the third axis). With
``a = u1^2``, ``b = u2^2``, ``q = a^n + b^n`` the derivatives in ``u`` are::

    dC/du1 = 2m q^(m/n-1) a^(n-1) u1          dC/du3 = 2m (u3^2)^(m-1) u3
    d2C/du1^2 = 2m q^(m/n-2) a^(n-1) (2(m-n) a^n + (2n-1) q)
    d2C/du1du2 = 4m (m-n) q^(m/n-2) a^(n-1) b^(n-1) u1 u2
    d2C/du3^2 = 2m (2m-1) (u3^2)^(m-1)

(``u2`` likewise), then ``g = grad_p C = diag(1/f) dC/du``, ``H = diag(1/f) d2C/du2 diag(1/f)``
and in world axes ``grad_x C = R g``, ``hess_x C = R H R^T``.

**Dynamic potential** (the paper's eq. for ``U(x, v)``), with ``theta`` the angle between the
velocity and ``grad C``::

    U = lambda (-cos theta)^beta |v| / C^eta    if theta in (pi/2, pi], else 0.

Its exact gradient (derived here, valid for every ``eta``; the public reference code drops
the factor ``eta`` of the second term, so it is right only for ``eta = 1``). In the obstacle's
frame, with ``w = R^T v``, ``k = -cos theta = -(w.g) / (|w| |g|) > 0`` and the part of ``w``
orthogonal to ``g``, ``w_perp = w - (w.g) g / |g|^2``::

    grad_p k = -H w_perp / (|w| |g|)
    phi = -grad_x U = R lambda C^-eta k^(beta-1) [ (beta / |g|) H w_perp + eta k |w| g / C ]

The second term pushes along the outward normal, the first steers the velocity around the
obstacle. ``beta >= 1`` keeps the force bounded as ``theta -> pi/2`` (``k^(beta-1)``);
``beta > 1`` also makes it continuous there.

**Static potential** (same paper): ``U = A exp(-eta C) / C``, ``phi = A exp(-eta C)
(eta / C + 1 / C^2) grad_x C``.

**Inside the obstacle.** ``C`` is saturated at a floor ``C_min > 0`` (default ``1e-3``, a
few hundredths of a millimetre outside a 5 cm obstacle): both potentials use
``max(C, C_min)``, so they are bounded, and the forces are the exact gradients of these
saturated potentials -- below the floor the ``C``-derivative terms vanish, leaving the
dynamic potential's steering term and no static force. Forces are therefore finite
everywhere (never NaN or inf); the centre, where ``grad C = 0`` and ``theta`` is undefined,
gives zero. The planner is meant to keep the path out of this region with a safety margin,
not to rescue a path that entered it.

``v`` is the DMP's velocity state ``tau x'`` (m) in :mod:`wholebody.planning.dmp`, which makes
the avoided path independent of the movement's duration.

**Settings for the paper's scene** (two cylinders r = 4 cm, h = 20 cm, the hand's straight
demonstration passing 5 mm off the first one's axis; tests/test_obstacles.py): reserved
space (``margin``) 2 cm, ``lambda = 10``, ``beta = 2``, ``eta = 2``, exponent ``m = 4``, with
which the path is converged under step refinement, clears both cylinders and reaches the
goal. Weak steering (small ``lambda``, ``beta = 1``, ``eta <= 1``) lets the hand stall
head-on in front of the cylinder and slip round it: there the force switches on and off
with the sign of ``cos theta``, and the path depends on the step size.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_array, as_positive, as_rotation, as_vector

__all__ = [
    "DynamicPotential",
    "Potential",
    "StaticPotential",
    "Superquadric",
    "box",
    "box_distance",
    "cylinder",
    "cylinder_distance",
    "make_point_force",
    "sphere",
    "sphere_distance",
    "total_force",
]

MAX_EXPONENT = 32.0
"""Largest superquadric exponent: ``|u|^(2 * 32)`` overflows only beyond ``6.5e4`` semi-axes
from the centre (a 4 cm obstacle 2.6 km away); steeper shapes would give inf and NaN forces
within reach."""

_Q_FLOOR = 1e-150
"""Floor of ``q = a^n + b^n`` on the obstacle's axis, where ``q^(m/n-2)`` would be infinite."""

PointForce = Callable[[float, float, float, float, float, float], tuple[float, float, float]]
"""``(x1, x2, x3, v1, v2, v3) -> (phi1, phi2, phi3)``: the force at one point, scalar code."""


@dataclass(frozen=True, eq=False)
class Superquadric:
    """The isopotential ``C(x)`` of a superquadric obstacle (see the module docstring).

    Attributes
    ----------
    center
        Centre ``c`` (3,), m, world frame.
    rotation
        ``R`` (3, 3): the obstacle's axes in world coordinates (``p = R^T (x - c)``).
    semi_axes
        ``f`` (3,), m, > 0: the surface crosses the obstacle's axes at ``+-f_k``.
    n, m
        Exponents in [1, 32]: ``n`` shapes the cross-section in the (1, 2) plane, ``m`` the
        ends along axis 3.
    """

    center: np.ndarray
    rotation: np.ndarray
    semi_axes: np.ndarray
    n: float = 1.0
    m: float = 1.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "center", as_vector(self.center, 3, "Superquadric: center").copy())
        set_(self, "rotation", as_rotation(self.rotation, "Superquadric: rotation").copy())
        f = as_vector(self.semi_axes, 3, "Superquadric: semi_axes").copy()
        if np.any(f <= 0.0):
            raise DimensionError(f"Superquadric: semi_axes must be > 0 m, got {f}")
        set_(self, "semi_axes", f)
        for name in ("n", "m"):
            value = float(getattr(self, name))
            if not 1.0 <= value <= MAX_EXPONENT:
                raise DimensionError(
                    f"Superquadric: exponent {name} must be in [1, {MAX_EXPONENT:g}] (>= 1: C "
                    f"twice differentiable; <= {MAX_EXPONENT:g}: |u|^(2 {name}) stays finite "
                    f"up to 6e4 semi-axes away), got {value}"
                )
            set_(self, name, value)
        if self.m == 1.0 and self.n != 1.0:
            raise DimensionError(
                f"Superquadric: m = 1 needs n = 1 (C is not twice differentiable on the third "
                f"axis otherwise), got n = {self.n}"
            )

    def local(self, x: np.ndarray) -> np.ndarray:
        """Points ``x`` (..., 3) in the obstacle's frame, ``R^T (x - c)``."""
        return (np.asarray(x, dtype=float) - self.center) @ self.rotation

    def isopotential(self, x: np.ndarray) -> np.ndarray:
        """``C(x)`` (...,) of world points ``x`` (..., 3)."""
        return self._local_terms(self.local(x), hessian=False)[0]

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """``grad_x C`` (..., 3), world axes, 1/m."""
        return self._local_terms(self.local(x), hessian=False)[1] @ self.rotation.T

    def hessian(self, x: np.ndarray) -> np.ndarray:
        """``hess_x C`` (..., 3, 3), world axes, 1/m^2."""
        H = self._local_terms(self.local(x), hessian=True)[2]
        return self.rotation @ H @ self.rotation.T

    def _local_terms(
        self, p: np.ndarray, hessian: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``C``, ``g = grad_p C`` (..., 3) and, if asked, ``H = hess_p C`` (..., 3, 3)."""
        n, m = self.n, self.m
        inv = 1.0 / self.semi_axes
        u = p * inv
        a, b, c = u[..., 0] ** 2, u[..., 1] ** 2, u[..., 2] ** 2
        an, bn = a**n, b**n
        q = np.maximum(an + bn, _Q_FLOOR)
        qm = q ** (m / n)
        cm1 = c ** (m - 1.0)
        C = qm + c * cm1 - 1.0
        an1, bn1 = a ** (n - 1.0), b ** (n - 1.0)
        t = 2.0 * m * qm / q  # 2m q^(m/n-1)
        g = np.empty(p.shape)
        g[..., 0] = t * an1 * u[..., 0] * inv[0]
        g[..., 1] = t * bn1 * u[..., 1] * inv[1]
        g[..., 2] = 2.0 * m * cm1 * u[..., 2] * inv[2]
        if not hessian:
            return C, g, None
        h = t / q  # 2m q^(m/n-2)
        H = np.zeros((*p.shape, 3))
        H[..., 0, 0] = h * an1 * (2.0 * (m - n) * an + (2.0 * n - 1.0) * q) * inv[0] ** 2
        H[..., 1, 1] = h * bn1 * (2.0 * (m - n) * bn + (2.0 * n - 1.0) * q) * inv[1] ** 2
        h12 = 2.0 * (m - n) * h * an1 * bn1 * u[..., 0] * u[..., 1] * inv[0] * inv[1]
        H[..., 0, 1] = h12
        H[..., 1, 0] = h12
        H[..., 2, 2] = 2.0 * m * (2.0 * m - 1.0) * cm1 * inv[2] ** 2
        return C, g, H

    def _params(self) -> tuple[float, ...]:
        """Flat parameters for the scalar kernels: c, R (row-major), 1/f, n, m."""
        return (
            *self.center.tolist(),
            *self.rotation.ravel().tolist(),
            *(1.0 / self.semi_axes).tolist(),
            self.n,
            self.m,
        )


# --------------------------------------------------------------------------------------
# Presets


def _axis_rotation(axis: np.ndarray) -> np.ndarray:
    """A rotation whose third column is the unit vector along ``axis``."""
    z = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _orientation(rotation: object, axis: object, name: str) -> np.ndarray:
    if rotation is not None and axis is not None:
        raise DimensionError(f"{name}: give either rotation or axis, not both")
    if rotation is not None:
        return as_rotation(rotation, f"{name}: rotation")
    if axis is not None:
        ax = as_vector(axis, 3, f"{name}: axis")
        if np.linalg.norm(ax) < 1e-12:
            raise DimensionError(f"{name}: axis must be a non-zero vector")
        return _axis_rotation(ax)
    return np.eye(3)


def _margin(margin: float, name: str) -> float:
    value = float(margin)
    if not math.isfinite(value) or value < 0.0:
        raise DimensionError(f"{name}: margin must be a finite number >= 0 m, got {margin}")
    return value


def sphere(center: np.ndarray, radius: float, *, margin: float = 0.0) -> Superquadric:
    """A sphere of ``radius + margin`` (m): ``n = m = 1``, ``f = (r, r, r)``, exact."""
    r = as_positive(radius, "sphere: radius") + _margin(margin, "sphere")
    return Superquadric(center, np.eye(3), np.full(3, r), 1.0, 1.0)


def cylinder(
    center: np.ndarray,
    radius: float,
    height: float,
    *,
    axis: np.ndarray | None = None,
    rotation: np.ndarray | None = None,
    margin: float = 0.0,
    exponent: float = 4.0,
) -> Superquadric:
    """The superquadric enclosing a solid cylinder grown by ``margin``.

    A circular cross-section (``n = 1``) and flat-ish ends (``m = exponent``). With
    ``r = radius + margin`` and ``L = height / 2 + margin``, the semi-axes are
    ``f = k (r, r, L)``, ``k = 2^(1 / (2m))``, the smallest uniform scale that puts the rim
    ``(r, L)`` on the surface, so the whole grown cylinder is inside (``k = 1.09`` for
    ``m = 4``).

    Parameters
    ----------
    center
        Centre of the cylinder (3,), m (the middle of its axis).
    radius, height
        m, > 0.
    axis, rotation
        Direction of the cylinder's axis (3,), or a rotation whose third column is that
        axis; default world z.
    margin
        Safety distance added all round, m (>= 0).
    exponent
        ``m`` in [1, 32]; larger is tighter at the ends and steeper.
    """
    R = _orientation(rotation, axis, "cylinder")
    mg = _margin(margin, "cylinder")
    r = as_positive(radius, "cylinder: radius") + mg
    half = 0.5 * as_positive(height, "cylinder: height") + mg
    m = float(exponent)
    if not 1.0 <= m <= MAX_EXPONENT:
        raise DimensionError(f"cylinder: exponent must be in [1, {MAX_EXPONENT:g}], got {exponent}")
    k = 2.0 ** (1.0 / (2.0 * m))
    return Superquadric(center, R, k * np.array([r, r, half]), 1.0, m)


def box(
    center: np.ndarray,
    size: np.ndarray,
    *,
    rotation: np.ndarray | None = None,
    margin: float = 0.0,
    exponent: float = 4.0,
) -> Superquadric:
    """The superquadric enclosing a box grown by ``margin``.

    ``n = m = exponent``; with half-sizes ``d = size / 2 + margin`` the semi-axes are
    ``f = k d``, ``k = 3^(1 / (2 exponent))``, which puts the corners on the surface
    (``k = 1.15`` for exponent 4).

    Parameters
    ----------
    center
        Centre (3,), m.
    size
        Edge lengths along the box's axes (3,), m, > 0.
    rotation
        The box's axes in world coordinates; default identity.
    margin
        Safety distance added all round, m (>= 0).
    exponent
        ``n = m`` in [1, 32]; larger is tighter and steeper.
    """
    R = _orientation(rotation, None, "box")
    sz = as_vector(size, 3, "box: size")
    if np.any(sz <= 0.0):
        raise DimensionError(f"box: size must be > 0 m on every axis, got {sz}")
    e = float(exponent)
    if not 1.0 <= e <= MAX_EXPONENT:
        raise DimensionError(f"box: exponent must be in [1, {MAX_EXPONENT:g}], got {exponent}")
    half = 0.5 * sz + _margin(margin, "box")
    k = 3.0 ** (1.0 / (2.0 * e))
    return Superquadric(center, R, k * half, e, e)


# --------------------------------------------------------------------------------------
# Exact distances to the solids (for clearance metrics, independent of the isopotential)


def _local_points(points: np.ndarray, center: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    x = np.asarray(points, dtype=float)
    return (x - np.asarray(center, dtype=float)) @ np.asarray(rotation, dtype=float)


def sphere_distance(points: np.ndarray, center: np.ndarray, radius: float) -> np.ndarray:
    """Euclidean distance (...,) from ``points`` (..., 3) to a solid sphere (0 inside), m."""
    d = np.linalg.norm(np.asarray(points, dtype=float) - np.asarray(center, dtype=float), axis=-1)
    return np.maximum(d - float(radius), 0.0)


def cylinder_distance(
    points: np.ndarray,
    center: np.ndarray,
    radius: float,
    height: float,
    rotation: np.ndarray | None = None,
) -> np.ndarray:
    """Euclidean distance (...,) from ``points`` (..., 3) to a solid cylinder (0 inside), m.

    ``rotation``'s third column is the cylinder's axis (default world z).
    """
    R = np.eye(3) if rotation is None else rotation
    p = _local_points(points, center, R)
    dr = np.maximum(np.hypot(p[..., 0], p[..., 1]) - float(radius), 0.0)
    dz = np.maximum(np.abs(p[..., 2]) - 0.5 * float(height), 0.0)
    return np.hypot(dr, dz)


def box_distance(
    points: np.ndarray, center: np.ndarray, size: np.ndarray, rotation: np.ndarray | None = None
) -> np.ndarray:
    """Euclidean distance (...,) from ``points`` (..., 3) to a solid box (0 inside), m."""
    R = np.eye(3) if rotation is None else rotation
    p = _local_points(points, center, R)
    excess = np.maximum(np.abs(p) - 0.5 * np.asarray(size, dtype=float), 0.0)
    return np.linalg.norm(excess, axis=-1)


# --------------------------------------------------------------------------------------
# Potentials


@runtime_checkable
class Potential(Protocol):
    """A repulsive potential ``U(x, v)`` with its force ``phi = -grad_x U``."""

    def potential(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``U`` (N,) at points ``x`` (N, 3) moving with ``v`` (N, 3)."""
        ...

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``phi = -grad_x U`` (N, 3)."""
        ...

    def point_force(self) -> PointForce:
        """The same force at one point, as a scalar closure (fast inside integrators)."""
        ...


def _floor(value: float) -> float:
    return as_positive(value, "potential: floor")


def _pair(x: np.ndarray, v: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray, bool]:
    xa = np.asarray(x, dtype=float)
    single = xa.ndim == 1
    xa = as_array(np.atleast_2d(xa), (None, 3), f"{name}: x")
    va = as_array(np.atleast_2d(np.asarray(v, dtype=float)), (None, 3), f"{name}: v")
    if va.shape != xa.shape:
        raise DimensionError(
            f"{name}: x and v must have the same shape, got {xa.shape}, {va.shape}"
        )
    return xa, va, single


class DynamicPotential:
    """``U = lambda (-cos theta)^beta |v| / C^eta`` for ``theta > pi/2`` (module docstring).

    The defaults (``lambda = 10``, ``beta = 2``, ``eta = 2``) are those tuned on the paper's
    two-cylinder scene, with a 2 cm margin on the obstacles.

    Parameters
    ----------
    shape
        The obstacle's isopotential.
    gain
        ``lambda`` > 0, m: ``|v|`` is in m (the DMP's ``tau x'``) and ``C`` is dimensionless, so
        ``phi`` is in m, the unit of the DMP's transformation system.
    beta
        ``beta >= 1``; 2 (default) makes the force continuous where ``theta`` crosses pi/2.
    eta
        ``eta > 0``: decay with ``C``.
    floor
        ``C_min`` > 0, the saturation of ``C`` inside and near the surface.
    """

    def __init__(
        self,
        shape: Superquadric,
        gain: float = 10.0,
        beta: float = 2.0,
        eta: float = 2.0,
        floor: float = 1e-3,
    ) -> None:
        if not isinstance(shape, Superquadric):
            raise DimensionError(f"DynamicPotential: shape must be a Superquadric, got {shape!r}")
        self.shape = shape
        self.gain = as_positive(gain, "DynamicPotential: gain")
        self.beta = as_positive(beta, "DynamicPotential: beta")
        if self.beta < 1.0:
            raise DimensionError(
                f"DynamicPotential: beta must be >= 1 (bounded force), got {self.beta}"
            )
        self.eta = as_positive(eta, "DynamicPotential: eta")
        self.floor = _floor(floor)

    def _terms(self, x: np.ndarray, v: np.ndarray, hessian: bool) -> dict[str, np.ndarray]:
        shape = self.shape
        R = shape.rotation
        p = (x - shape.center) @ R
        w = v @ R
        C, g, H = shape._local_terms(p, hessian)
        wg = np.einsum("ij,ij->i", w, g)
        gn = np.linalg.norm(g, axis=1)
        wn = np.linalg.norm(w, axis=1)
        active = (wg < 0.0) & (gn > 0.0) & (wn > 0.0)
        k = np.where(active, -wg / np.where(active, wn * gn, 1.0), 0.0)
        Cs = np.maximum(C, self.floor)
        return {"w": w, "C": C, "Cs": Cs, "g": g, "H": H, "wg": wg, "gn": gn, "wn": wn,
                "k": k, "active": active}  # fmt: skip

    def potential(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``U`` (N,) (or a scalar for one point) at ``x`` (N, 3) moving with ``v`` (N, 3)."""
        xa, va, single = _pair(x, v, "DynamicPotential.potential")
        t = self._terms(xa, va, hessian=False)
        U = np.where(t["active"], self.gain * t["k"] ** self.beta * t["wn"] / t["Cs"] ** self.eta,
                     0.0)  # fmt: skip
        return U[0] if single else U

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``phi = -grad_x U`` (N, 3) (or (3,) for one point), world axes."""
        xa, va, single = _pair(x, v, "DynamicPotential.force")
        t = self._terms(xa, va, hessian=True)
        act = t["active"]
        gn = np.where(act, t["gn"], 1.0)
        g, w, k, Cs = t["g"], t["w"], t["k"], t["Cs"]
        w_perp = w - (t["wg"] / gn**2)[:, None] * g
        Hw = np.einsum("nij,nj->ni", t["H"], w_perp)
        coef = self.gain * Cs ** (-self.eta) * np.where(act, k, 1.0) ** (self.beta - 1.0)
        radial = np.where(t["C"] > self.floor, self.eta * k * t["wn"] / Cs, 0.0)
        local = coef[:, None] * ((self.beta / gn)[:, None] * Hw + radial[:, None] * g)
        local[~act] = 0.0
        phi = local @ self.shape.rotation.T
        return phi[0] if single else phi

    def point_force(self) -> PointForce:
        """Scalar closure of :meth:`force` for one point (same formulas, Python floats)."""
        cx, cy, cz, r00, r01, r02, r10, r11, r12, r20, r21, r22, i1, i2, i3, n, m = (
            self.shape._params()
        )
        lam, beta, eta, floor = self.gain, self.beta, self.eta, self.floor
        mn = m / n
        n1, m1 = n - 1.0, m - 1.0
        two_m = 2.0 * m
        hd = 2.0 * (m - n)
        n2 = 2.0 * n - 1.0
        h33 = 2.0 * m * (2.0 * m - 1.0) * i3 * i3
        b1 = beta - 1.0
        sqrt = math.sqrt
        round_section = n == 1.0
        aligned = bool(np.array_equal(self.shape.rotation, np.eye(3)))

        def force(
            x1: float, x2: float, x3: float, v1: float, v2: float, v3: float
        ) -> tuple[float, float, float]:
            d1, d2, d3 = x1 - cx, x2 - cy, x3 - cz
            if aligned:  # R = I: skip the rotations
                u1, u2, u3 = d1 * i1, d2 * i2, d3 * i3
                w1, w2, w3 = v1, v2, v3
            else:
                u1 = (r00 * d1 + r10 * d2 + r20 * d3) * i1
                u2 = (r01 * d1 + r11 * d2 + r21 * d3) * i2
                u3 = (r02 * d1 + r12 * d2 + r22 * d3) * i3
                w1 = r00 * v1 + r10 * v2 + r20 * v3
                w2 = r01 * v1 + r11 * v2 + r21 * v3
                w3 = r02 * v1 + r12 * v2 + r22 * v3
            a, b, c = u1 * u1, u2 * u2, u3 * u3
            cm1 = c**m1
            if round_section:  # n = 1: skip two powers
                an1 = bn1 = 1.0
                an, bn = a, b
            else:
                an1, bn1 = a**n1, b**n1
                an, bn = an1 * a, bn1 * b
            q = an + bn
            if q < _Q_FLOOR:
                q = _Q_FLOOR
            qm = q**mn
            t = two_m * qm / q
            g1 = t * an1 * u1 * i1
            g2 = t * bn1 * u2 * i2
            g3 = two_m * cm1 * u3 * i3
            wg = w1 * g1 + w2 * g2 + w3 * g3
            if wg >= 0.0:
                return 0.0, 0.0, 0.0
            gg = g1 * g1 + g2 * g2 + g3 * g3
            ww = w1 * w1 + w2 * w2 + w3 * w3
            if gg == 0.0 or ww == 0.0:
                return 0.0, 0.0, 0.0
            gn, wn = sqrt(gg), sqrt(ww)
            k = -wg / (wn * gn)
            iso = qm + c * cm1 - 1.0
            Cs = iso if iso > floor else floor
            h = t / q
            H11 = h * an1 * (hd * an + n2 * q) * i1 * i1
            H22 = h * bn1 * (hd * bn + n2 * q) * i2 * i2
            H12 = hd * h * an1 * bn1 * u1 * u2 * i1 * i2
            r = wg / gg
            p1, p2, p3 = w1 - r * g1, w2 - r * g2, w3 - r * g3
            coef = lam * Cs**-eta * k**b1
            sa = coef * beta / gn
            sb = coef * eta * k * wn / Cs if iso > floor else 0.0
            f1 = sa * (H11 * p1 + H12 * p2) + sb * g1
            f2 = sa * (H12 * p1 + H22 * p2) + sb * g2
            f3 = sa * h33 * cm1 * p3 + sb * g3
            if aligned:
                return f1, f2, f3
            return (
                r00 * f1 + r01 * f2 + r02 * f3,
                r10 * f1 + r11 * f2 + r12 * f3,
                r20 * f1 + r21 * f2 + r22 * f3,
            )

        return force


class StaticPotential:
    """``U = A exp(-eta C) / C`` (Ginesi et al. 2019), independent of the velocity.

    ``phi = A exp(-eta C) (eta / C + 1 / C^2) grad_x C``; ``C`` saturated at ``floor`` as for
    :class:`DynamicPotential` (so no force where ``C < floor``).

    Parameters
    ----------
    shape
        The obstacle's isopotential.
    gain
        ``A`` > 0.
    eta
        ``eta`` > 0.
    floor
        ``C_min`` > 0.
    """

    def __init__(
        self, shape: Superquadric, gain: float = 1.0, eta: float = 1.0, floor: float = 1e-3
    ) -> None:
        if not isinstance(shape, Superquadric):
            raise DimensionError(f"StaticPotential: shape must be a Superquadric, got {shape!r}")
        self.shape = shape
        self.gain = as_positive(gain, "StaticPotential: gain")
        self.eta = as_positive(eta, "StaticPotential: eta")
        self.floor = _floor(floor)

    def potential(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """``U`` (N,) at ``x`` (N, 3) (or a scalar for one point); ``v`` is ignored."""
        xa = np.asarray(x, dtype=float)
        single = xa.ndim == 1
        xa = as_array(np.atleast_2d(xa), (None, 3), "StaticPotential.potential: x")
        Cs = np.maximum(self.shape.isopotential(xa), self.floor)
        U = self.gain * np.exp(-self.eta * Cs) / Cs
        return U[0] if single else U

    def force(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """``phi = -grad_x U`` (N, 3) (or (3,) for one point), world axes."""
        xa = np.asarray(x, dtype=float)
        single = xa.ndim == 1
        xa = as_array(np.atleast_2d(xa), (None, 3), "StaticPotential.force: x")
        shape = self.shape
        iso, g, _ = shape._local_terms(shape.local(xa), hessian=False)
        Cs = np.maximum(iso, self.floor)
        s = self.gain * np.exp(-self.eta * Cs) * (self.eta / Cs + 1.0 / Cs**2)
        s = np.where(iso > self.floor, s, 0.0)
        phi = (s[:, None] * g) @ shape.rotation.T
        return phi[0] if single else phi

    def point_force(self) -> PointForce:
        """Scalar closure of :meth:`force` (the velocity arguments are ignored)."""
        cx, cy, cz, r00, r01, r02, r10, r11, r12, r20, r21, r22, i1, i2, i3, n, m = (
            self.shape._params()
        )
        A, eta, floor = self.gain, self.eta, self.floor
        mn, n1, m1, two_m = m / n, n - 1.0, m - 1.0, 2.0 * m
        exp = math.exp

        def force(
            x1: float, x2: float, x3: float, v1: float, v2: float, v3: float
        ) -> tuple[float, float, float]:
            d1, d2, d3 = x1 - cx, x2 - cy, x3 - cz
            u1 = (r00 * d1 + r10 * d2 + r20 * d3) * i1
            u2 = (r01 * d1 + r11 * d2 + r21 * d3) * i2
            u3 = (r02 * d1 + r12 * d2 + r22 * d3) * i3
            a, b, c = u1 * u1, u2 * u2, u3 * u3
            an1, bn1, cm1 = a**n1, b**n1, c**m1
            q = an1 * a + bn1 * b
            if q < _Q_FLOOR:
                q = _Q_FLOOR
            qm = q**mn
            iso = qm + c * cm1 - 1.0
            if iso <= floor:
                return 0.0, 0.0, 0.0
            t = two_m * qm / q
            s = A * exp(-eta * iso) * (eta / iso + 1.0 / (iso * iso))
            f1 = s * t * an1 * u1 * i1
            f2 = s * t * bn1 * u2 * i2
            f3 = s * two_m * cm1 * u3 * i3
            return (
                r00 * f1 + r01 * f2 + r02 * f3,
                r10 * f1 + r11 * f2 + r12 * f3,
                r20 * f1 + r21 * f2 + r22 * f3,
            )

        return force


def total_force(potentials: Sequence[Potential], x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Sum of the forces of several potentials at ``x`` (N, 3) with velocity ``v`` (N, 3)."""
    xa = np.asarray(x, dtype=float)
    out = np.zeros(xa.shape)
    for pot in potentials:
        out = out + pot.force(xa, v)
    return out


def make_point_force(potentials: Sequence[Potential]) -> PointForce | None:
    """One scalar closure summing the forces of ``potentials`` (``None`` if there are none)."""
    for p in potentials:
        if not callable(getattr(p, "point_force", None)):
            raise DimensionError(
                "obstacles are repulsive potentials: wrap each shape in one, e.g. "
                f"DynamicPotential(cylinder(center, radius, height)); got a {type(p).__name__}"
            )
    kernels = [p.point_force() for p in potentials]
    if not kernels:
        return None
    if len(kernels) == 1:
        return kernels[0]
    if len(kernels) == 2:  # the common case, without the loop's overhead
        first, second = kernels

        def pair(
            x1: float, x2: float, x3: float, v1: float, v2: float, v3: float
        ) -> tuple[float, float, float]:
            a1, a2, a3 = first(x1, x2, x3, v1, v2, v3)
            b1, b2, b3 = second(x1, x2, x3, v1, v2, v3)
            return a1 + b1, a2 + b2, a3 + b3

        return pair

    def force(
        x1: float, x2: float, x3: float, v1: float, v2: float, v3: float
    ) -> tuple[float, float, float]:
        f1 = f2 = f3 = 0.0
        for kern in kernels:
            a, b, c = kern(x1, x2, x3, v1, v2, v3)
            f1 += a
            f2 += b
            f3 += c
        return f1, f2, f3

    return force


def _kernel_row(potential: object) -> np.ndarray | None:
    """``potential`` as a row of the compiled force (:func:`kernel_rows`), or None."""
    cls = type(potential)
    own = getattr(cls, "point_force", None)
    if own is DynamicPotential.point_force:
        static, beta = False, float(potential.beta)  # type: ignore[attr-defined]
    elif own is StaticPotential.point_force:
        static, beta = True, 1.0  # unused by the static force
    else:
        return None
    shape = getattr(potential, "shape", None)
    if not isinstance(shape, Superquadric) or type(shape)._params is not Superquadric._params:
        return None
    from wholebody.kernels.dmp import obstacle_row  # numba loads on first use only

    gain, eta, floor = (float(getattr(potential, a)) for a in ("gain", "eta", "floor"))
    return obstacle_row(static, shape._params(), gain, beta, eta, floor)


def kernel_rows(potentials: Sequence[object]) -> np.ndarray | None:
    """The parameters of ``potentials`` for the compiled integrator (one row each, see
    :mod:`wholebody.kernels.dmp`), or None when one of them is not a potential the kernels
    compute: a user-written :class:`Potential`, or a subclass with its own ``point_force``.
    The planner then integrates with the Python closures of :func:`make_point_force`
    (slower, the same answers)."""
    rows = []
    for p in potentials:
        row = _kernel_row(p)
        if row is None:
            return None
        rows.append(row)
    return np.array(rows) if rows else None
