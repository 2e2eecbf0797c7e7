"""A hand trajectory from a DMP: the position DMP's rollout plus a slerp of the orientation.

**Position.** The 3-D position DMP is rolled out densely and sampled in between by quintic
Hermite interpolation of the rollout's positions, velocities and accelerations: C2, and exact
at the samples. On the interval ``[t_k, t_k + h]``, with ``u = (t - t_k) / h``, the
polynomial ``p(u) = sum_j a_j u^j`` has ``a_0 = p_k``, ``a_1 = h v_k``, ``a_2 = h^2 a_k / 2``
and ``a_3..a_5`` from the same three values at ``u = 1``.

**Orientation.** A slerp from the start to the goal rotation whose progress is the
minimum-jerk polynomial ``sigma`` of the normalised phase time
``xi = ln(s) / ln(phase_end) = t / T``: zero angular velocity and acceleration at both ends,
exactly the goal rotation at ``T``, and the exact angular velocity
``sigma'(t) R0 Log(R0^T R1)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_pose, as_positive
from wholebody.planning.dmp.model import DMP
from wholebody.planning.obstacles import Potential
from wholebody.planning.rotations import Slerp
from wholebody.planning.trajectory import Trajectory, TrajectoryArrays, minimum_jerk_scaling

__all__ = ["DMPTrajectory"]

_POWERS = np.arange(6.0)  # the quintic's exponents


class DMPTrajectory(Trajectory):
    """A hand trajectory: a 3-D position DMP plus a slerp of the orientation.

    The position DMP is rolled out densely (``samples``) and sampled in between by quintic
    Hermite interpolation of the rollout's positions, velocities and accelerations (C2, exact
    at the samples). The orientation goes from the start to the goal rotation with the
    minimum-jerk progress of the normalised phase time (module docstring).

    Parameters
    ----------
    dmp
        A 3-D :class:`DMP`.
    start_pose, goal_pose
        4x4 world poses; their positions are the DMP's ``x0`` and ``g``.
    duration
        ``T`` s; default the demonstration's.
    obstacles
        Repulsive potentials for the position DMP.
    samples
        Rollout samples; default one per 10 ms, at least 160.

    Notes
    -----
    ``end_pose`` is the rollout's final position (a small fraction of a millimetre from the
    goal: :mod:`~wholebody.planning.dmp.config`) with the goal rotation: chain a
    :class:`~wholebody.planning.trajectory.HoldTrajectory` at ``end_pose``, not at the goal.
    """

    def __init__(
        self,
        dmp: DMP,
        start_pose: np.ndarray,
        goal_pose: np.ndarray,
        duration: float | None = None,
        *,
        obstacles: Sequence[Potential] = (),
        samples: int | None = None,
    ) -> None:
        if dmp.dim != 3:
            raise DimensionError(f"DMPTrajectory: needs a 3-D position DMP, got {dmp.dim}-D")
        T0 = as_pose(start_pose, "DMPTrajectory: start_pose")
        T1 = as_pose(goal_pose, "DMPTrajectory: goal_pose")
        T = dmp.duration if duration is None else as_positive(duration, "DMPTrajectory: duration")
        n = max(160, math.ceil(T / 0.01) + 1) if samples is None else int(samples)
        self.rollout = dmp.rollout(
            n, duration=T, start=T0[:3, 3], goal=T1[:3, 3], obstacles=obstacles
        )
        self._duration = T
        self._R0, self._R1 = T0[:3, :3].copy(), T1[:3, :3].copy()
        self._slerp = Slerp(self._R0, self._R1)
        # Quintic Hermite coefficients per interval, in u = (t - t_k) / h.
        r = self.rollout
        h = T / (n - 1)
        self._h = h
        p0, p1 = r.positions[:-1], r.positions[1:]
        v0, v1 = h * r.velocities[:-1], h * r.velocities[1:]
        a0, a1 = h * h * r.accelerations[:-1], h * h * r.accelerations[1:]
        dp = p1 - p0
        self._coef = np.stack(
            [
                p0,
                v0,
                0.5 * a0,
                10.0 * dp - 6.0 * v0 - 4.0 * v1 - 1.5 * a0 + 0.5 * a1,
                -15.0 * dp + 8.0 * v0 + 7.0 * v1 + 1.5 * a0 - a1,
                6.0 * dp - 3.0 * v0 - 3.0 * v1 - 0.5 * a0 + 0.5 * a1,
            ],
            axis=1,
        )  # (n-1, 6, 3)
        # (6, 18): [u^j] -> [u^j | d/dt | d2/dt2] of the polynomial's basis, t = t_k + u h
        self._shift = np.zeros((6, 18))
        for j in range(6):
            self._shift[j, j] = 1.0
            if j + 1 < 6:
                self._shift[j, 6 + j + 1] = (j + 1) / h
            if j + 2 < 6:
                self._shift[j, 12 + j + 2] = (j + 2) * (j + 1) / (h * h)

    @property
    def duration(self) -> float:
        return self._duration

    @property
    def start_pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self._R0, self.rollout.positions[0]
        return T

    @property
    def end_pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self._R1, self.rollout.positions[-1]
        return T

    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        h, T = self._h, self._duration
        x = times / h
        k = x.astype(np.intp)  # the interval (times are in [0, T])
        np.minimum(k, self._coef.shape[0] - 1, out=k)
        u = x - k
        # rows [u^j], [j u^(j-1) / h], [j (j-1) u^(j-2) / h^2] in one product with the constant
        # shift-and-scale matrix, then all three against the interval's coefficients
        weights = (u[:, None] ** _POWERS).dot(self._shift).reshape(-1, 3, 6)
        pva = np.matmul(weights, self._coef[k])  # (N, 3, 3): position, velocity, acceleration
        sig, dsig, ddsig = minimum_jerk_scaling(times / T)
        R, axis = self._slerp(sig)
        return TrajectoryArrays(
            times=times,
            positions=pva[:, 0],
            rotations=R,
            linear_velocities=pva[:, 1],
            angular_velocities=(dsig / T)[:, None] * axis,
            linear_accelerations=pva[:, 2],
            angular_accelerations=(ddsig / T**2)[:, None] * axis,
        )
