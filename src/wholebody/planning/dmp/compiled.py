"""The DMP's kernels (:mod:`wholebody.kernels.dmp`, :mod:`wholebody.kernels.potentials`):
loading them, and laying out a DMP's numbers for them.

**One implementation (decision).** :meth:`DMP.fit <wholebody.planning.dmp.DMP.fit>`,
:meth:`DMP.rollout <wholebody.planning.dmp.DMP.rollout>`, :class:`DMPStepper
<wholebody.planning.dmp.DMPStepper>`, :meth:`DMP.basis <wholebody.planning.dmp.DMP.basis>`
and the obstacles' forces run in numba kernels, and only there: the Python modules check
the arguments, lay out the kernels' buffers and wrap their results. With
``NUMBA_DISABLE_JIT=1`` the kernels run as plain Python, the same code. They compile on
first use, once per machine, and are cached (:func:`warmup`; :mod:`wholebody.kernels`).
numba is imported on that first use only, not with :mod:`wholebody.planning`.
"""

from __future__ import annotations

import threading
from types import ModuleType

import numpy as np

from wholebody.planning.dmp.config import DMPConfig

__all__ = ["arena", "as_buffer", "for_run", "kernels", "warmup"]

_KERNELS: ModuleType | None = None
_KERNELS_LOCK = threading.Lock()


def kernels() -> ModuleType:
    """:mod:`wholebody.kernels.dmp` (its ``potentials`` the force kernels), compiled or
    loaded from the cache on first use (:func:`warmup`)."""
    if _KERNELS is None:
        warmup()
    assert _KERNELS is not None
    return _KERNELS


def warmup() -> None:
    """Compile the DMP kernels now (once per machine; a notice on stderr says so while it
    takes long) or load them from numba's cache, by running a small fit, rollouts with and
    without obstacles, both kinds of steppers, the basis, the forces and the
    Savitzky-Golay filter. The first call of any of them does it anyway."""
    global _KERNELS
    from wholebody.kernels import DISABLED, compile_notice
    from wholebody.kernels import dmp as compiled

    with _KERNELS_LOCK:
        if _KERNELS is not None:
            return
        _KERNELS = compiled
        if DISABLED:  # NUMBA_DISABLE_JIT=1: nothing to compile
            return
        try:
            with compile_notice("the DMP kernels"):
                _exercise()
        except BaseException:
            _KERNELS = None
            raise


def _exercise() -> None:
    """Every kernel once, with the argument types of real use (see :func:`warmup`)."""
    from wholebody.planning.dmp.model import DMP
    from wholebody.planning.dmp.savgol import savitzky_golay
    from wholebody.planning.obstacles import DynamicPotential, StaticPotential, sphere

    t = np.linspace(0.0, 1.0, 12)
    dmp = DMP.fit(np.stack([t, t * t, np.sin(t)], axis=1), t, config=DMPConfig(n_basis=4))
    obstacles = (
        DynamicPotential(sphere([0.5, 0.3, 0.5], 0.1)),
        StaticPotential(sphere([2.0, 2.0, 2.0], 0.1)),
    )
    dmp.rollout(5)
    dmp.rollout(5, obstacles=obstacles)
    for pots in ((), obstacles):
        stepper = dmp.stepper(obstacles=pots)
        state = stepper.initial_state()
        stepper.step(state, 0.1, out=state)
        stepper.acceleration(state)
    dmp.forcing(t)
    obstacles[0].force(np.zeros(3), np.ones(3))
    savitzky_golay(np.stack([t, t * t], axis=1), 5, 2, 0.1)


def arena(cfg: DMPConfig, weights: np.ndarray) -> np.ndarray:
    """A DMP's arena for the kernels (:mod:`wholebody.kernels.dmp`): the configuration
    ``cfg`` and the ``weights`` (nb, d), without a run's start, goal, duration and
    integrator settings (:func:`for_run`)."""
    k = kernels()
    nb, d = weights.shape
    oc, oh, ow, osc = k.regions(d, nb)[2:]
    p = np.zeros(osc + nb + k.WORK * d)
    p[k.H_DIM], p[k.H_NB], p[k.H_K], p[k.H_D] = d, nb, cfg.K, cfg.D
    c, h = cfg.layout()
    p[oc:oh], p[oh:ow], p[ow:osc] = c, h, weights.ravel()
    return p


def for_run(
    p: np.ndarray,
    cfg: DMPConfig,
    start: np.ndarray,
    goal: np.ndarray,
    tau: float,
    tolerance: float,
    span: float,
) -> np.ndarray:
    """A copy of the arena ``p`` (:func:`arena`) for one run: ``start`` and ``goal`` (d,)
    m, the duration ``tau`` (s), the integrator's ``tolerance`` (m; inf: none) and the
    ``span`` (s) the run covers."""
    k = kernels()
    p = p.copy()
    p[k.H_TAU], p[k.H_TOL], p[k.H_SPAN] = tau, tolerance, span
    p[k.H_RATE] = float(cfg.alpha_s) / (cfg.phase_tau_ratio * tau)
    og, d = k.HEADER, start.shape[0]
    p[og : og + d], p[og + d : og + 2 * d] = goal, start
    return p


def as_buffer(a: object) -> np.ndarray:
    """``a`` as a C-ordered float64 array for the kernels (a copy only if it is not)."""
    return np.ascontiguousarray(a, dtype=np.float64)
