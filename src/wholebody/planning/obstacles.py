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

**One implementation of the force.** The forces are computed by the kernel
:func:`wholebody.kernels.potentials.force`, which the DMP integrator evaluates at every RK4
stage; :meth:`DynamicPotential.force`, :meth:`StaticPotential.force` and :func:`total_force`
call it for many points at once. :meth:`~DynamicPotential.potential` stays vectorised numpy
(for plots and checks: the tests hold the force against its finite differences).

**Supported potentials (decision).** A DMP avoids obstacles given as
:class:`DynamicPotential` or :class:`StaticPotential` of a :class:`Superquadric` (``sphere``,
``cylinder``, ``box`` or any superquadric at any pose); several potentials add their forces.
Anything else is refused with a :class:`~wholebody.errors.DimensionError` that says so
(:func:`potential_rows`), as is a subclass with its own ``force()`` or ``potential()``: the
integrator is compiled and computes these potentials from their parameters, so it could not
honour an override, and a Python callback at every stage would bring back a second,
fifty times slower integrator. A subclass that only adds attributes (a name, say) is
accepted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeAlias

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
    "potential_rows",
    "sphere",
    "sphere_distance",
    "total_force",
]

MAX_EXPONENT = 32.0
"""Largest superquadric exponent: ``|u|^(2 * 32)`` overflows only beyond ``6.5e4`` semi-axes
from the centre (a 4 cm obstacle 2.6 km away); steeper shapes would give inf and NaN forces
within reach."""

_Q_FLOOR = 1e-150
"""Floor of ``q = a^n + b^n`` on the obstacle's axis, where ``q^(m/n-2)`` would be infinite
(the same as the force kernel's)."""


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


def _forces(rows: np.ndarray, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The summed force (N, 3) of the kernel ``rows`` at ``x`` moving with ``v`` (N, 3), by
    :func:`wholebody.kernels.potentials.forces`."""
    from wholebody.planning.dmp.compiled import as_buffer, kernels

    out = np.empty(x.shape)
    kernels().potentials.forces(rows, as_buffer(x), as_buffer(v), out)
    return out


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

    def potential(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``U`` (N,) (or a scalar for one point) at ``x`` (N, 3) moving with ``v`` (N, 3)."""
        xa, va, single = _pair(x, v, "DynamicPotential.potential")
        shape = self.shape
        w = va @ shape.rotation
        C, g, _ = shape._local_terms(shape.local(xa), hessian=False)
        wg = np.einsum("ij,ij->i", w, g)
        gn = np.linalg.norm(g, axis=1)
        wn = np.linalg.norm(w, axis=1)
        active = (wg < 0.0) & (gn > 0.0) & (wn > 0.0)
        k = np.where(active, -wg / np.where(active, wn * gn, 1.0), 0.0)
        Cs = np.maximum(C, self.floor)
        U = np.where(active, self.gain * k**self.beta * wn / Cs**self.eta, 0.0)
        return U[0] if single else U

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``phi = -grad_x U`` (N, 3) (or (3,) for one point), world axes, m: the DMP
        integrator's force (module docstring)."""
        xa, va, single = _pair(x, v, "DynamicPotential.force")
        phi = _forces(self._row()[None], xa, va)
        return phi[0] if single else phi

    def _row(self) -> np.ndarray:
        """This potential's row of the force kernel (:mod:`wholebody.kernels.potentials`)."""
        return _row(False, self.shape, self.gain, self.beta, self.eta, self.floor)


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
        """``phi = -grad_x U`` (N, 3) (or (3,) for one point), world axes, m; ``v`` is
        ignored."""
        xa = np.asarray(x, dtype=float)
        single = xa.ndim == 1
        xa = as_array(np.atleast_2d(xa), (None, 3), "StaticPotential.force: x")
        phi = _forces(self._row()[None], xa, np.zeros(xa.shape))
        return phi[0] if single else phi

    def _row(self) -> np.ndarray:
        """This potential's row of the force kernel (:mod:`wholebody.kernels.potentials`)."""
        return _row(True, self.shape, self.gain, 1.0, self.eta, self.floor)


Potential: TypeAlias = DynamicPotential | StaticPotential
"""A repulsive potential the DMP integrator computes (module docstring)."""


def _row(
    static: bool, shape: Superquadric, gain: float, beta: float, eta: float, floor: float
) -> np.ndarray:
    """A potential's row of the force kernel (:func:`wholebody.kernels.potentials.row`)."""
    from wholebody.planning.dmp.compiled import kernels

    return kernels().potentials.row(
        static,
        shape.center,
        shape.rotation,
        shape.semi_axes,
        (shape.n, shape.m),
        gain,
        beta,
        eta,
        floor,
    )


def total_force(potentials: Sequence[Potential], x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Sum of the forces (N, 3) m (or (3,) for one point) of several potentials at ``x``
    (N, 3) m with velocity ``v`` (N, 3) m (the DMP's ``tau x'``)."""
    xa, va, single = _pair(x, v, "total_force")
    phi = _forces(potential_rows(potentials, "total_force"), xa, va)
    return phi[0] if single else phi


_NO_ROWS: np.ndarray | None = None
_OWN = {
    DynamicPotential: (DynamicPotential.force, DynamicPotential.potential),
    StaticPotential: (StaticPotential.force, StaticPotential.potential),
}


def _supported(p: object) -> bool:
    """Whether the kernels compute ``p``: a potential of this module (or a subclass that
    keeps its ``force`` and ``potential``) of a superquadric."""
    for base, methods in _OWN.items():
        if isinstance(p, base):
            own = (type(p).force, type(p).potential)
            shape = getattr(p, "shape", None)
            return own == methods and type(shape) is Superquadric
    return False


def potential_rows(potentials: Sequence[object], where: str = "DMP") -> np.ndarray:
    """The rows (n, ``ROW``) of the force kernel (:mod:`wholebody.kernels.potentials`) for
    ``potentials``, (0, ``ROW``) for none. Raises :class:`~wholebody.errors.DimensionError`
    for anything the kernels do not compute (module docstring); ``where`` names the caller
    in the message."""
    global _NO_ROWS
    if not potentials and _NO_ROWS is not None:
        return _NO_ROWS
    from wholebody.planning.dmp.compiled import kernels

    rows = []
    for p in potentials:
        if isinstance(p, Superquadric):
            raise DimensionError(
                f"{where}: obstacles are repulsive potentials: wrap each shape in one, e.g. "
                "DynamicPotential(cylinder(center, radius, height)); got a Superquadric"
            )
        if not _supported(p):
            raise DimensionError(
                f"{where}: obstacles must be DynamicPotential or StaticPotential of a "
                "Superquadric (sphere, cylinder, box or Superquadric(...)), and a subclass "
                "may not override force() or potential(): the compiled integrator computes "
                f"these potentials from their parameters; got a {type(p).__name__}. Combine "
                "several potentials for other shapes."
            )
        rows.append(p._row())  # type: ignore[attr-defined]
    out = np.array(rows).reshape(len(rows), kernels().potentials.ROW)
    if not rows:
        _NO_ROWS = out  # (0, ROW): nothing to write, shared by every call without potentials
    return out
