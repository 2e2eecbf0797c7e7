"""A rolled-out DMP: its samples in time, as the integrator returns them.

Velocities ``x' = v / tau`` and accelerations ``x'' = v' / tau`` are those of the model at
the samples (the integrator's state and derivative), not finite differences of the
positions: a trajectory built on the rollout (:class:`~wholebody.planning.dmp.DMPTrajectory`)
interpolates all three.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DMPRollout"]


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
