"""What the stall watch reads off a control step's outcome, in one call.

:class:`wholebody.control.StallRecovery` watches the pose tasks' error
``E = sum_t ||e_t||`` (m + rad) and needs, each step, whether a watched task was left unmet
and whether a watched reference moves. The kernel of a step wrote all three into the arena
already: each pose task's 6-D error and target twist in its parameter block
(:mod:`.rows`), each task's outcome in ``I_INFEASIBLE``. Reading them here costs one call
(well under a microsecond) instead of a numpy view per task and number.
"""

from __future__ import annotations

import math

import numpy as np

from wholebody.kernels import kernel
from wholebody.kernels.rows import POSE_ERROR, POSE_TWIST

__all__ = ["pose_watch"]


@kernel
def pose_watch(
    par: np.ndarray, starts: np.ndarray, flags: np.ndarray, tasks: np.ndarray
) -> tuple[bool, bool, float]:
    """``(unmet, moving, E)`` for the pose tasks whose parameter blocks start at ``starts``
    in ``par`` (the arena's ``F_PAR``) and whose outcomes are ``flags[tasks]`` (the arena's
    ``I_INFEASIBLE``, nonzero: unmet): whether one is unmet, whether one's target twist is not
    0, and the sum of their error norms ``E`` (m + rad, 1 m counting as 1 rad)."""
    unmet, moving, total = False, False, 0.0
    for t in range(tasks.shape[0]):
        unmet = unmet or flags[tasks[t]] != 0
    for s in range(starts.shape[0]):
        square = 0.0
        for k in range(6):
            e = par[starts[s] + POSE_ERROR + k]
            square += e * e
            moving = moving or par[starts[s] + POSE_TWIST + k] != 0.0
        total += math.sqrt(square)
    return unmet, moving, total
