"""A rolled-out DMP: its samples in time, as both integrators return them.

Velocities ``x' = v / tau`` and accelerations ``x'' = v' / tau`` are those of the model at
the samples (the integrator's state and derivative), not finite differences of the
positions: a trajectory built on the rollout (:class:`~wholebody.planning.dmp.DMPTrajectory`)
interpolates all three.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DMPRollout", "rollout_result"]


@dataclass(frozen=True)
class DMPRollout:
    """A rolled-out DMP: ``N`` samples on ``[0, duration]``.

    Attributes
    ----------
    times
        (N,) s, from 0 to ``duration``.
    positions, velocities, accelerations
        (N, d) in m, m/s, m/s^2 (``x``, ``x'``, ``x''``).
    phase
        (N,) the phase ``s(t)``.
    start, goal
        (d,) ``x0`` and ``g`` used.
    duration
        ``T``, s.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    phase: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    duration: float


def rollout_result(
    times: np.ndarray,
    phase: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    x0: np.ndarray,
    g: np.ndarray,
    T: float,
) -> DMPRollout:
    """A :class:`DMPRollout` (``v``, ``a``: the velocities and accelerations x', x'')."""
    return DMPRollout(times=times, positions=x, velocities=v, accelerations=a, phase=phase,
                      start=x0.copy(), goal=g.copy(), duration=T)  # fmt: skip
