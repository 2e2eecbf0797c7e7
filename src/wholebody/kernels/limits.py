"""Limits in kernels: the boxes on the actuated velocity ``u`` for one control step of ``dt``
seconds, each from its limit's parameter block (the maths is documented with the limits,
:mod:`wholebody.tasks.limits`).

Blocks (floats, ``nu`` entries each): position limits ``lower, upper`` (rad, m; the margins
applied) and ``gain``; velocity limits ``upper`` (rad/s, m/s); acceleration limits ``amax``
(rad/s^2, m/s^2), the position range ``lo, hi`` and the velocity of the last step ``previous``
(rad/s, m/s: the limit's memory, written after each step), with an integer block marking the
joints that have a position range.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel

__all__ = ["acceleration_box", "position_box", "velocity_box"]


@kernel
def position_box(
    positions: np.ndarray, par: np.ndarray, dt: float, lo: np.ndarray, hi: np.ndarray
) -> None:
    """Joint position limits as velocity bounds: ``lo = gain (lower - q) / dt`` and
    ``hi = gain (upper - q) / dt`` (infinite where the limit is)."""
    nu = positions.shape[0]
    k = par[2 * nu] / dt
    for j in range(nu):
        lo[j] = (par[j] - positions[j]) * k
        hi[j] = (par[nu + j] - positions[j]) * k


@kernel
def velocity_box(par: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """``|u| <= upper``."""
    for j in range(lo.shape[0]):
        hi[j] = par[j]
        lo[j] = -par[j]


@kernel
def braking_speed(d: float, a: float, dt: float) -> float:
    """The speed from which braking at ``a`` per step stops within ``d``:
    ``a dt (sqrt(1 + 2 d / (a dt^2)) - 1)`` (rad/s, m/s)."""
    adt = a * dt
    return adt * (math.sqrt(1.0 + 2.0 * d / (adt * dt)) - 1.0)


@kernel
def acceleration_box(
    positions: np.ndarray,
    par: np.ndarray,
    limited: np.ndarray,
    dt: float,
    lo: np.ndarray,
    hi: np.ndarray,
) -> None:
    """``|u - previous| <= amax dt``, and towards a position limit at distance ``d`` at most
    the braking speed of ``d``."""
    nu = positions.shape[0]
    for j in range(nu):
        a = par[j]
        prev = par[3 * nu + j]
        lo[j] = prev - a * dt
        hi[j] = prev + a * dt
        if limited[j]:
            q = positions[j]
            to_hi = max(par[2 * nu + j] - q, 0.0)
            to_lo = max(q - par[nu + j], 0.0)
            hi[j] = min(hi[j], braking_speed(to_hi, a, dt))
            lo[j] = max(lo[j], -braking_speed(to_lo, a, dt))
