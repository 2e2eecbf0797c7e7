"""Dynamic Movement Primitives in the goal-shift form of Niu et al. 2024, Section 3.

**Equations** (any dimension ``d``; ``K``, ``D`` scalars, the same for every dimension)::

    tau v' = K (g - x) - D v - K (g - x0) s + K f(s) + phi(x, v)
    tau x' = v
    tau_s s' = -alpha_s s,        s(0) = 1
    f(s)   = s sum_i w_i psi_i(s) / sum_i psi_i(s),     psi_i(s) = exp(-h_i (s - c_i)^2)

``x`` is the position (m), ``v = tau x'`` the DMP's velocity state (m), ``x0`` the start, ``g``
the goal, ``phi`` an optional repulsive term (:mod:`wholebody.planning.obstacles`), ``tau = T``
the movement's duration (s). Defaults: ``K = 1050``, ``D = 2 sqrt(K)`` (critically damped),
``alpha_s = 4``, 50 basis functions. The phase runs on its own time constant ``tau_s`` so
that a moved goal is reached (:mod:`~.config`).

One concept per module:

* :mod:`~.config` -- :class:`DMPConfig`: the hyper-parameters, the phase's time constant and
  the basis layout.
* :mod:`~.model` -- :class:`DMP`: the forcing term and its fit from one demonstration.
* :mod:`~.savgol` -- the Savitzky-Golay filter the fit differentiates the demonstration with.
* :mod:`~.rollout` -- :class:`DMPRollout`, the samples a rollout returns.
* :mod:`~.integrator` -- the rollout: RK4 substeps, adaptive with obstacles.
* :mod:`~.stepper` -- :class:`DMPStepper` and :class:`DMPState`: the same integrator online.
* :mod:`~.trajectory` -- :class:`DMPTrajectory`: a hand pose trajectory (DMP position plus
  slerp orientation).
* :mod:`~.compiled` -- the kernels that implement all of it (:mod:`wholebody.kernels.dmp`):
  loading them (:func:`warmup`) and laying out their buffers.
"""

from __future__ import annotations

from wholebody.planning.dmp.compiled import warmup
from wholebody.planning.dmp.config import DMPConfig
from wholebody.planning.dmp.model import DMP
from wholebody.planning.dmp.rollout import DMPRollout
from wholebody.planning.dmp.savgol import savitzky_golay
from wholebody.planning.dmp.stepper import DMPState, DMPStepper
from wholebody.planning.dmp.trajectory import DMPTrajectory

__all__ = [
    "DMP",
    "DMPConfig",
    "DMPRollout",
    "DMPState",
    "DMPStepper",
    "DMPTrajectory",
    "savitzky_golay",
    "warmup",
]
