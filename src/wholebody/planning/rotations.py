"""SO(3) maths for orientation interpolation: exponential, logarithm and slerp.

Rotations are 3x3 matrices; rotation vectors ``phi = theta * axis`` (rad). The slerp from
``R0`` to ``R1`` at progress ``sigma`` in [0, 1] is the geodesic

    R(sigma) = R0 Exp(sigma phi),        phi = Log(R0^T R1)   (body axes of R0),

a rotation at constant rate about the fixed world axis ``R0 phi`` (the axis is the same in
every ``R(sigma)``'s body axes, since ``R0 Exp(sigma phi) phi = R0 phi``). So if the progress
follows a time scaling ``sigma(t)``, the world angular velocity and acceleration are exactly

    omega(t) = sigma'(t) R0 phi,         alpha(t) = sigma''(t) R0 phi.

``Log`` is Pinocchio's ``log3``, the SO(3) logarithm every other module uses.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = ["Slerp", "exp_so3", "hat", "log_so3", "slerp"]


def hat(w: np.ndarray) -> np.ndarray:
    """Skew matrices ``[w]x`` (..., 3, 3) of vectors ``w`` (..., 3): ``[w]x y = w x y``."""
    w = np.asarray(w, dtype=float)
    K = np.zeros((*w.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2] = -w[..., 2], w[..., 1]
    K[..., 1, 0], K[..., 1, 2] = w[..., 2], -w[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -w[..., 1], w[..., 0]
    return K


def exp_so3(phi: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors ``phi`` (..., 3) (Rodrigues).

    ``Exp(phi) = I + (sin t / t) K + ((1 - cos t) / t^2) K^2`` with ``K = [phi]x``,
    ``t = |phi|``; Taylor series below ``t = 1e-4``.
    """
    phi = np.asarray(phi, dtype=float)
    t2 = np.sum(phi * phi, axis=-1)
    t = np.sqrt(t2)
    small = t < 1e-4
    ts = np.where(small, 1.0, t)
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(ts) / ts)
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(ts)) / (ts * ts))
    K = hat(phi)
    R = a[..., None, None] * K + b[..., None, None] * (K @ K)
    R[..., 0, 0] += 1.0
    R[..., 1, 1] += 1.0
    R[..., 2, 2] += 1.0
    return R


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of one rotation matrix, ``theta`` in [0, pi] (rad): Pinocchio's
    ``log3`` (accurate near 0 and pi; at exactly pi the sign of the axis is arbitrary)."""
    return pin.log3(np.asarray(R, dtype=float))


def slerp(R0: np.ndarray, R1: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Geodesic interpolation ``R0 Exp(sigma Log(R0^T R1))``.

    Parameters
    ----------
    R0, R1
        Start and end rotations (3, 3).
    sigma
        Progress (N,), 0 at ``R0`` and 1 at ``R1``.

    Returns
    -------
    rotations
        (N, 3, 3).
    axis
        The world rotation vector ``R0 Log(R0^T R1)`` (3,) (rad): the angular velocity is
        ``sigma'(t) * axis`` and the angular acceleration ``sigma''(t) * axis``.
    """
    return Slerp(R0, R1)(np.asarray(sigma, dtype=float))


class Slerp:
    """The geodesic from ``R0`` to ``R1`` (see :func:`slerp`), with ``phi = Log(R0^T R1)``
    worked out once, for trajectories sampled every control step.

    With ``theta = |phi|`` and ``K = [phi / theta]x``, Rodrigues' formula gives
    ``R0 Exp(sigma phi) = R0 + sin(sigma theta) R0 K + (1 - cos(sigma theta)) R0 K^2``: two
    constant matrices, a sine and a cosine per sample (``K = 0`` when ``R0 = R1``).

    Attributes
    ----------
    axis
        The world rotation vector ``R0 phi`` (3,) (rad), read-only.
    """

    __slots__ = ("_R0", "_R0K", "_R0K2", "angle", "axis")

    def __init__(self, R0: np.ndarray, R1: np.ndarray) -> None:
        R0 = np.array(R0, dtype=float)
        phi = log_so3(R0.T @ np.asarray(R1, dtype=float))
        self.angle = float(np.linalg.norm(phi))
        K = hat(phi / self.angle) if self.angle > 0.0 else np.zeros((3, 3))
        self._R0 = R0
        self._R0K = R0 @ K
        self._R0K2 = self._R0K @ K
        self.axis = R0 @ phi
        self.axis.setflags(write=False)  # returned by every call: shared, so read-only

    def __call__(self, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(rotations (N, 3, 3), axis (3,))`` at the progress values ``sigma`` (N,)."""
        a = sigma * self.angle
        sin = np.sin(a)[:, None, None]
        vers = (1.0 - np.cos(a))[:, None, None]
        return self._R0 + sin * self._R0K + vers * self._R0K2, self.axis
