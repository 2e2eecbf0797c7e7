"""Compiled or reference: which implementation a DMP's fit, rollout and stepper run.

**Compiled kernels (decision).** :meth:`DMP.fit <wholebody.planning.dmp.DMP.fit>`,
:meth:`DMP.rollout <wholebody.planning.dmp.DMP.rollout>` and
:class:`~wholebody.planning.dmp.DMPStepper` run in numba kernels
(:mod:`wholebody.kernels.dmp`): the same formulas in the same order, the same adaptive step
control, so the compiled path is the reference's to rounding, with the same substep count in
every interval, at a fraction of its cost. The reference's cost is Python arithmetic (the
obstacle force, evaluated some thousands of times per rollout) and numpy's per-call overhead
on small arrays; the kernels evaluate the basis functions' exponentials with a vectorised
polynomial, the Savitzky-Golay filter as a banded correlation and the linear recurrence as a
loop.

The potentials of :mod:`~wholebody.planning.obstacles` are computed in the kernels from their
parameters; a rollout with any other :class:`~wholebody.planning.obstacles.Potential` (a
user's ``point_force``) runs the Python integrator
(:class:`~wholebody.planning.dmp.adaptive.ObstacleIntegrator`), as does a step of states
that are not float64 arrays. The Python code of :mod:`wholebody.planning.dmp` is the
reference: inside :func:`reference_implementation` everything runs it (tests and
``benchmarks/dmp.py`` compare the two). The kernels compile on first use, once per machine
(:func:`warmup`).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from contextvars import ContextVar
from types import ModuleType

import numpy as np

__all__ = ["as_buffer", "kernels", "reference_implementation", "warmup"]

_REFERENCE: ContextVar[bool] = ContextVar("wholebody_dmp_reference", default=False)
_KERNELS: ModuleType | None = None
_KERNELS_LOCK = threading.Lock()


@contextlib.contextmanager
def reference_implementation(enabled: bool = True) -> Iterator[None]:
    """Inside the block, :meth:`DMP.fit`, :meth:`DMP.rollout` and the :class:`DMPStepper` s
    constructed there run the Python reference implementation instead of the compiled
    kernels (:mod:`wholebody.kernels.dmp`); ``enabled=False`` asks for the kernels again. For
    tests and benchmarks that compare the two (they give the same paths to rounding and take
    the same substep decisions). The switch is a context variable: it holds for the current
    thread or task only."""
    token = _REFERENCE.set(bool(enabled))
    try:
        yield
    finally:
        _REFERENCE.reset(token)


def kernels() -> ModuleType | None:
    """The compiled kernels (compiled or loaded on first use), or None inside
    :func:`reference_implementation`."""
    if _REFERENCE.get():
        return None
    if _KERNELS is None:
        warmup()
    return _KERNELS


def warmup() -> None:
    """Compile the DMP kernels now (once per machine; a notice on stderr says so while it
    takes long) or load them from numba's cache, by running a small fit, rollouts with and
    without obstacles and both steppers. The first compiled call does it anyway."""
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
            with compile_notice("the DMP kernels"), reference_implementation(False):
                _exercise()
        except BaseException:
            _KERNELS = None
            raise


def _exercise() -> None:
    """Every kernel once, with the argument types of real use (see :func:`warmup`)."""
    from wholebody.planning.dmp.config import DMPConfig
    from wholebody.planning.dmp.model import DMP
    from wholebody.planning.obstacles import DynamicPotential, StaticPotential, sphere

    t = np.linspace(0.0, 1.0, 12)
    dmp = DMP.fit(np.stack([t, t * t, np.sin(t)], axis=1), t, config=DMPConfig(n_basis=4))
    obstacles = (DynamicPotential(sphere([0.5, 0.3, 0.5], 0.1)),
                 StaticPotential(sphere([2.0, 2.0, 2.0], 0.1)))  # fmt: skip
    dmp.rollout(5)
    dmp.rollout(5, obstacles=obstacles)
    for pots in ((), obstacles):
        stepper = dmp.stepper(obstacles=pots)
        state = stepper.initial_state()
        stepper.step(state, 0.1, out=state)


def as_buffer(a: object) -> np.ndarray:
    """``a`` as a C-ordered float64 array for the kernels (a copy only if it is not)."""
    return np.ascontiguousarray(a, dtype=np.float64)
