"""The DMP's integrator: RK4 substeps, adaptive when there are obstacles.

One integrator (:func:`wholebody.kernels.dmp.integrate`) serves :meth:`DMP.rollout
<wholebody.planning.dmp.DMP.rollout>` and :class:`~wholebody.planning.dmp.DMPStepper`, with
and without obstacles. It integrates the state ``y = (x, v)``, ``v = tau x'`` (m), of ::

    tau x' = v,    tau v' = b(t) - K x - D v + phi(x, v),    b = K (g - (g - x0) s + f(s))

(:mod:`wholebody.planning.dmp`) with the phase known in closed form, over sample intervals
``[t, t + h]`` (a rollout's, or an online step's ``dt``), each split into ``m`` equal
classical RK4 substeps of ``hs = h / m``.

**Without obstacles** the system is linear and ``m`` is fixed: the fewest substeps with
``|lambda_max| hs / tau <= 0.25`` (:func:`linear_substeps`; one for the paper's 160
samples), stable and accurate however coarse the sampling.

**With obstacles** (3-D) the repulsive term switches on and grows steeply within a few
millimetres of an obstacle, and one RK4 step per interval misses the converged path by
centimetres, so ``m`` adapts:

* *Error estimate.* The embedded third-order FSAL solution
  ``y* = y + hs (k1/6 + k2/3 + k3/3 + k5/6)``, ``k5 = F(t + hs, y+)``, differs from the RK4
  solution ``y+`` by ``|y+ - y*| = hs/6 |k4 - k5|`` (max over the components of ``y``, m).
  ``k5`` is the next substep's ``k1``, so the estimate costs nothing.
* *Step control.* The estimate is O(hs^4), so the substep that would just meet the tolerance
  is ``hs (tol / err)^(1/4)``: an interval whose estimate exceeds ``tol`` is redone with that
  many substeps over 0.8 (at least one more, at most ``max_substeps``), and the next
  interval starts from the count the last estimate asks for (at least half the last one).
  Far from obstacles one substep per interval suffices; near an obstacle the steps shrink.
* *Failure.* An interval that still misses the tolerance with ``max_substeps`` substeps is
  accepted within ``ACCEPT_AT_LIMIT`` (10) times the tolerance -- a force that jumps
  (``beta = 1``) makes the estimate fall only in proportion to the substep while the path
  stays close -- and raises :class:`~wholebody.errors.IntegrationError` beyond (a step that
  jumped a steep obstacle's shell gives estimates of metres), or as soon as the state is
  not finite after ``max_substeps`` tries.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from wholebody.errors import DimensionError, IntegrationError
from wholebody.planning._checks import as_positive
from wholebody.planning.dmp.compiled import kernels
from wholebody.planning.dmp.config import DMPConfig
from wholebody.planning.dmp.rollout import DMPRollout

if TYPE_CHECKING:
    from wholebody.planning.dmp.model import DMP

__all__ = [
    "check_max_substeps",
    "check_tolerance",
    "control",
    "linear_substeps",
    "rollout",
    "run",
]

_LINEAR_STEP = 0.25  # largest |lambda| hs / tau of a linear RK4 substep (stable below 2.78)


def check_tolerance(value: float) -> float:
    """A positive tolerance (m); ``inf`` turns the error control off (fixed substeps)."""
    if value == math.inf:
        return math.inf
    return as_positive(value, "DMP: tolerance")


def check_max_substeps(value: int) -> int:
    """The most substeps per interval, an integer >= 1."""
    m = int(value)
    if m != value or m < 1:
        raise DimensionError(f"DMP: max_substeps must be an integer >= 1, got {value}")
    return m


def linear_substeps(cfg: DMPConfig, r: float) -> int:
    """RK4 substeps per interval of ``r = h / tau`` for the linear DMP ``z' = A z / tau``:
    ``|lambda_max(A)| r / m <= 0.25`` (one for the paper's 160 samples: 0.2)."""
    K, D = cfg.K, cfg.D
    rho = 0.5 * (D + math.sqrt(D * D - 4.0 * K)) if D * D >= 4.0 * K else math.sqrt(K)
    return max(1, math.ceil(rho * r / _LINEAR_STEP - 1e-12))


def control(top: int, first: int, intervals: int) -> np.ndarray:
    """The integrator's control array (:mod:`wholebody.kernels.dmp`): at most ``top``
    substeps per interval, ``first`` for the first, room for ``intervals`` counts."""
    k = kernels()
    ctl = np.zeros(k.CONTROL + intervals, dtype=np.int64)
    ctl[k.C_TOP], ctl[k.C_NEXT] = top, first
    return ctl


def run(
    p: np.ndarray, obs: np.ndarray, ctl: np.ndarray, clock: np.ndarray, Y: np.ndarray, what: str
) -> None:
    """:func:`wholebody.kernels.dmp.integrate`; raises its failure (with obstacles only) as
    an :class:`IntegrationError` naming ``what`` ran."""
    k = kernels()
    if k.integrate(p, obs, ctl, clock, Y) == 0:
        return
    err, m, tol = float(p[k.H_ERR]), int(ctl[k.C_LAST]), float(p[k.H_TOL])
    if err < math.inf:
        detail = f"local error {err:.3g} m, above {k.ACCEPT_AT_LIMIT:g} x the tolerance {tol:g} m,"
    else:
        detail = "a non-finite state"
    raise IntegrationError(
        f"{what}: {detail} with {m} substeps in the interval from t = "
        f"{clock[0, ctl[k.C_FAILED]]:.4g} s: the path is not resolved there; raise "
        "max_substeps (a force that jumps, beta = 1, needs many), or tighten the tolerance "
        "so that the steps shrink before a steep obstacle is reached"
    )


def rollout(
    dmp: DMP,
    N: int,
    x0: np.ndarray,
    g: np.ndarray,
    T: float,
    obs: np.ndarray,
    tolerance: float,
    max_substeps: int,
) -> tuple[DMPRollout, np.ndarray, int]:
    """:meth:`DMP.rollout <wholebody.planning.dmp.DMP.rollout>`: ``N`` samples from rest at
    ``x0`` (m) to ``g`` over ``T`` s, with the potentials' kernel rows ``obs`` (n,
    ``ROW``; :func:`~wholebody.planning.obstacles.potential_rows`). Also returns the substeps
    of each sample interval (N - 1,) and the number of derivative evaluations: the step
    control's decisions."""
    if len(obs):
        tol, top = check_tolerance(tolerance), check_max_substeps(max_substeps)
        first = top if tol == math.inf else 1
    else:
        tol, top = math.inf, linear_substeps(dmp.config, 1.0 / (N - 1))
        first = top
    p = dmp._run(x0, g, T, tol, T)
    ctl = control(top, first, N - 1)
    clock, Y = np.empty((2, N)), np.empty((3, N, dmp.dim))
    clock[0, 0], clock[1, 0] = 0.0, 1.0
    Y[0, 0], Y[1, 0] = x0, 0.0
    run(p, obs, ctl, clock, Y, "DMP obstacle rollout")
    result = DMPRollout(
        times=clock[0],
        positions=Y[0],
        velocities=Y[1],
        accelerations=Y[2],
        phase=clock[1],
        start=x0.copy(),
        goal=g.copy(),
        duration=T,
    )
    k = kernels()
    return result, ctl[k.CONTROL :], int(ctl[k.C_EVALS])
