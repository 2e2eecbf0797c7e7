r"""Joint position limits as acceleration bounds, with braking.

At the torque level a joint cannot stop at once: a bound on the next velocity alone lets a
joint arrive at its position limit too fast to stop. For an entry ``u_i`` of the actuated
velocity at position ``q_i`` with limits ``[lo_i, hi_i]``, the acceleration ``a_i`` of a
step of ``dt`` seconds is bounded so that after the step the joint can still stop before
the limit while decelerating at ``braking`` (rad/s^2, m/s^2):

.. math::

    d = hi - q - u\,dt, \qquad
    a \le \min\!\Big(\frac{2 d}{dt^2},\; \frac{\sqrt{2\,b\,\max(d, 0)} - u}{dt}\Big)

and symmetrically at ``lo``. The first bound keeps the next position inside; the second is
the viability bound ``u'^2 \le 2 b d`` on the next velocity ``u' = u + a dt`` (the distance
travelled during the step counted at the current velocity).
"""

from __future__ import annotations

import numpy as np

__all__ = ["braking_bounds"]


def braking_bounds(
    q: np.ndarray,
    u: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    dt: float,
    braking: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The bounds ``(a_lo, a_hi)`` of the module docstring per entry (``-inf``/``inf`` where
    the entry has no limit on that side); ``q``, ``u``, ``lower``, ``upper`` per entry of
    ``u``."""
    with np.errstate(invalid="ignore"):
        up = upper - q - u * dt
        down = q - lower + u * dt  # (the distance to the lower limit after the step, > 0 inside)
        a_hi = np.minimum(2.0 * up / dt**2, (np.sqrt(2.0 * braking * np.maximum(up, 0.0)) - u) / dt)
        a_lo = np.maximum(
            -2.0 * down / dt**2, (-np.sqrt(2.0 * braking * np.maximum(down, 0.0)) - u) / dt
        )
    a_hi = np.where(np.isfinite(upper), a_hi, np.inf)
    a_lo = np.where(np.isfinite(lower), a_lo, -np.inf)
    return a_lo, a_hi
