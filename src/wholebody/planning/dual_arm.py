"""Dual-arm coordination: the secondary hand's trajectory from the primary's (closed chain).

While both hands hold an object rigidly, with fixed grasp transforms ``T_PO`` (object in the
primary hand's frame) and ``T_SO`` (object in the secondary hand's frame),

    T_W_P T_PO = T_W_O = T_W_S T_SO     =>     T_W_S = T_W_P T_PS,   T_PS = T_PO T_SO^-1.

``T_PS`` is constant, so the secondary hand moves as a point of the primary hand's rigid
body. With ``r = p_S - p_P = R_P p_PS`` (world axes) and the primary's twist ``(v_P, w_P)``
and accelerations ``(a_P, alpha_P)``::

    R_S = R_P R_PS                   w_S = w_P                 alpha_S = alpha_P
    p_S = p_P + r                    v_S = v_P + w_P x r
    a_S = a_P + alpha_P x r + w_P x (w_P x r)

(the paper's ``v_S = v_M + R_W_M v_M_S`` with the relative velocity of the rigid grasp
``R_W_M v_M_S = w_P x r``). This is the *coordinated* mode. In the *independent* mode each
hand simply follows its own trajectory (for example one
:class:`~wholebody.planning.dmp.DMPTrajectory` per hand); no class is needed for it.
"""

from __future__ import annotations

import numpy as np

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_pose
from wholebody.planning.trajectory import Trajectory, TrajectoryArrays

__all__ = ["CoordinatedTrajectory", "secondary_pose"]


def _inverse(T: np.ndarray) -> np.ndarray:
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


_NEXT, _PREV = [1, 2, 0], [2, 0, 1]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a x b`` of (N, 3) arrays (np.cross costs several times more on a few rows)."""
    return a[:, _NEXT] * b[:, _PREV] - a[:, _PREV] * b[:, _NEXT]


def secondary_pose(
    primary_pose: np.ndarray, T_primary_object: np.ndarray, T_secondary_object: np.ndarray
) -> np.ndarray:
    """``T_W_S = T_W_P T_PO T_SO^-1`` (4, 4) for one primary pose (4, 4)."""
    TP = as_pose(primary_pose, "secondary_pose: primary_pose")
    TPO = as_pose(T_primary_object, "secondary_pose: T_primary_object")
    TSO = as_pose(T_secondary_object, "secondary_pose: T_secondary_object")
    return TP @ TPO @ _inverse(TSO)


class CoordinatedTrajectory(Trajectory):
    """The secondary hand's trajectory while both hands carry one rigid object.

    Parameters
    ----------
    primary
        The primary hand's trajectory.
    T_primary_object, T_secondary_object
        Grasp transforms (4, 4): the object's pose in the primary and in the secondary hand's
        frame, fixed while carrying.

    Attributes
    ----------
    T_primary_secondary
        The constant ``T_PS = T_PO T_SO^-1`` (4, 4).
    """

    def __init__(
        self,
        primary: Trajectory,
        T_primary_object: np.ndarray,
        T_secondary_object: np.ndarray,
    ) -> None:
        if not isinstance(primary, Trajectory):
            raise DimensionError(
                f"CoordinatedTrajectory: primary must be a Trajectory, got {type(primary).__name__}"
            )
        self.primary = primary
        self.T_primary_object = as_pose(T_primary_object, "CoordinatedTrajectory: T_primary_object")
        self.T_secondary_object = as_pose(
            T_secondary_object, "CoordinatedTrajectory: T_secondary_object"
        )
        self.T_primary_secondary = self.T_primary_object @ _inverse(self.T_secondary_object)

    @property
    def duration(self) -> float:
        return self.primary.duration

    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        P = self.primary._evaluate(times)
        R_PS, p_PS = self.T_primary_secondary[:3, :3], self.T_primary_secondary[:3, 3]
        r = P.rotations @ p_PS  # (N, 3) world
        w, alpha = P.angular_velocities, P.angular_accelerations
        w_x_r = _cross(w, r)
        return TrajectoryArrays(
            times=times,
            positions=P.positions + r,
            rotations=P.rotations @ R_PS,
            linear_velocities=P.linear_velocities + w_x_r,
            angular_velocities=w.copy(),
            linear_accelerations=P.linear_accelerations + _cross(alpha, r) + _cross(w, w_x_r),
            angular_accelerations=alpha.copy(),
        )

    @property
    def start_pose(self) -> np.ndarray:
        return self.primary.start_pose @ self.T_primary_secondary

    @property
    def end_pose(self) -> np.ndarray:
        return self.primary.end_pose @ self.T_primary_secondary
